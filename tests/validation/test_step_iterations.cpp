// Issue 15's goal of at most 60 iterations is per solve (per step here), while stats.jsonl's
// `solver.iterations` is a frame's sum over its steps (docs/cli.md). Fig. 4 in 2D
// (`viscous-sphere-bunny-wall-2d`) books 122 iterations in its third frame, which reads like a
// miss of the goal; the frame has 23 steps of 4-7 iterations each (docs/preconditioners.md
// section 43). These tests take the count step by step (the stop flag of advance_frame ends every
// call at a step boundary) and bound every step, on Fig. 4 in 2D (the ball on the wall before and
// after the bunny's contacts) and Fig. 5 in 2D (the bunny landing on the eta 5000 hemisphere).
// The largest counts of the viscous built-in scenes, per solve, are 44 in 2D and 31 in 3D
// (section 43's tables).
#include <algorithm>
#include <csignal>

#include <catch2/catch.hpp>

#include "reference/app/scene_file.hpp"
#include "reference/sim/simulation.hpp"

using namespace monolith;

namespace {

/// What one step booked (the difference of the frame's running statistics).
struct StepCount {
  int frame = 0;  ///< the frame the step belongs to (1-based)
  long iterations = 0;
  long fallbacks = 0;
  bool converged = true;
  double relative_residual = 0.0;
};

struct SteppedRun {
  std::vector<StepCount> steps;
  std::vector<FrameStats> frames;  ///< each frame's statistics at its end
};

/// Frames 1..frames of a built-in scene, one step per advance_frame call.
SteppedRun run_by_steps(const std::string& name, int frames,
                        std::vector<std::string> overrides = {}) {
  static volatile std::sig_atomic_t always_stop = 1;
  overrides.push_back("render.enabled=false");
  auto sim = make_simulation(load_scene(name, overrides));
  sim->set_stop_flag(&always_stop);
  SteppedRun run;
  long before_iterations = 0, before_fallbacks = 0;
  while (static_cast<int>(run.frames.size()) < frames) {
    const FrameStats s = sim->advance_frame();
    StepCount c;
    c.frame = static_cast<int>(run.frames.size()) + 1;
    c.iterations = s.solver.iterations - before_iterations;
    c.fallbacks = s.solver.preconditioner_fallbacks - before_fallbacks;
    c.converged = s.solver.converged;
    c.relative_residual = s.solver.max_relative_residual;
    run.steps.push_back(c);
    if (sim->mid_frame()) {
      before_iterations = s.solver.iterations;
      before_fallbacks = s.solver.preconditioner_fallbacks;
    } else {
      run.frames.push_back(s);
      before_iterations = before_fallbacks = 0;
    }
  }
  return run;
}

/// Frames 1..frames of a built-in scene, a frame per call (as `monolith run`).
std::vector<FrameStats> run_by_frames(const std::string& name, int frames) {
  auto sim = make_simulation(load_scene(name, {"render.enabled=false"}));
  std::vector<FrameStats> out;
  for (int f = 1; f <= frames; ++f) out.push_back(sim->advance_frame());
  return out;
}

/// Every step within `bound` iterations, converged, without a fallback; returns the largest.
long check_steps(const std::string& name, const SteppedRun& run, long bound) {
  long largest = 0;
  for (const StepCount& c : run.steps) {
    INFO(name << " frame " << c.frame << ": a step of " << c.iterations << " iterations");
    CHECK(c.iterations <= bound);
    CHECK(c.converged);
    CHECK(c.relative_residual <= 1e-6);
    CHECK(c.fallbacks == 0);
    largest = std::max(largest, c.iterations);
  }
  return largest;
}

}  // namespace

TEST_CASE("Fig. 4 in 2D: every step within 60 iterations; the frame's count sums its steps",
          "[validation][preconditioner]") {
  const std::string name = "viscous-sphere-bunny-wall-2d";
  // frames 1-25: the ball reaches the wall in frame 2, the bunny's contacts start in frame 23
  const int frames = 25;
  const SteppedRun run = run_by_steps(name, frames);
  const long largest = check_steps(name, run, 60);
  // the frames run step by step are the frames of an ordinary run, bit for bit
  const std::vector<FrameStats> whole = run_by_frames(name, frames);
  REQUIRE(whole.size() == run.frames.size());
  for (std::size_t f = 0; f < whole.size(); ++f) {
    INFO("frame " << f + 1);
    CHECK(run.frames[f].steps == whole[f].steps);
    CHECK(run.frames[f].solver.iterations == whole[f].solver.iterations);
    CHECK(run.frames[f].kinetic_energy_liquid == whole[f].kinetic_energy_liquid);
    long summed = 0, frame_largest = 0;
    for (const StepCount& c : run.steps)
      if (c.frame == static_cast<int>(f) + 1) {
        summed += c.iterations;
        frame_largest = std::max(frame_largest, c.iterations);
      }
    CHECK(summed == whole[f].solver.iterations);
    // stats.jsonl's per-step view (solver.max_step_iterations), also across a frame run step by step
    CHECK(whole[f].solver.max_step_iterations == frame_largest);
    CHECK(run.frames[f].solver.max_step_iterations == frame_largest);
  }
  // frame 3: about two dozen steps that all iterate, so its total (measured 122) is many times
  // its largest step (measured 7) and says nothing about the per-solve goal
  CHECK(whole[2].steps >= 20);
  long frame3_largest = 0;
  for (const StepCount& c : run.steps)
    if (c.frame == 3) frame3_largest = std::max(frame3_largest, c.iterations);
  CHECK(whole[2].solver.iterations >= 10 * frame3_largest);
  CHECK(whole.back().contact_count > 0);
  // the bound has teeth: the paper's SSOR takes hundreds per step once the ball is at the wall
  const SteppedRun ssor = run_by_steps(name, 2, {"solver.preconditioner=ssor"});
  long ssor_largest = 0;
  for (const StepCount& c : ssor.steps) ssor_largest = std::max(ssor_largest, c.iterations);
  CHECK(ssor_largest > 60);  // measured 420
  WARN(name << ": largest step " << largest << " iterations; frame 3 " << whole[2].solver.iterations
            << " in " << whole[2].steps << " steps");
}

TEST_CASE("Fig. 5 in 2D (eta 5000): every step of the landing within 60 iterations",
          "[validation][preconditioner]") {
  const std::string name = "bunny-on-viscous-hemisphere-2d";
  const SteppedRun run = run_by_steps(name, 8);
  const long largest = check_steps(name, run, 60);
  CHECK(largest > 0);  // the solves iterate (not only round-off right-hand sides)
  WARN(name << ": largest step " << largest << " iterations");
}

TEST_CASE("hollow spheres in a viscous liquid (3D): the cut block is built where the cut faces' "
          "raised stress DOFs fill it, every step within 8 iterations",
          "[validation][preconditioner]") {
  // The spheres' cut faces tie their liquid to the solid through raised stress DOFs (departures
  // item 24, W_F^s = 0.01), which join the cut block's seed (W_F^s < 1/2): in frame 1 the block's
  // factor holds 9-10.3x the entries of the finest velocity operator. Under the former cap of 8x
  // no block was built and the steps took 15-21 iterations (80 in the frame); under
  // StokesPreconditionerOptions::cut_factor_cap = 16 they take 3-4 (docs/preconditioners.md
  // section 47).
  const std::string name = "hollow-spheres-viscous-3d";
  const SteppedRun run = run_by_steps(name, 1);
  const long largest = check_steps(name, run, 8);
  CHECK(largest > 0);
  CHECK(run.steps.size() >= 3);  // measured 5 steps in frame 1
  WARN(name << ": largest step " << largest << " iterations in frame 1");
}
