// The main of test_core_links_alone (CMakeLists.txt): a program that links the solver core
// (monolith_core) and nothing else, compiled together with a translation unit that includes
// every header of the core behind a poison include folder (tests/layers/poison). It describes a
// scene in plain C++ (no scene file, no JSON), a liquid column beside a floating box in 2D,
// runs one frame and checks that the state is sane, so the core is shown to build, link and run
// on its own.

#include <cmath>
#include <cstdio>

#include "reference/sim/scene_desc.hpp"
#include "reference/sim/simulation.hpp"

int main() {
  using namespace monolith;
  SceneDesc scene;
  scene.name = "core-alone";
  scene.dim = 2;
  scene.domain.lower = {0.0, 0.0};
  scene.domain.upper = {1.0, 1.0};
  scene.domain.cells = {16, 16};
  scene.time.fps = 50.0;
  LiquidSpec liquid;
  liquid.name = "water";
  liquid.density = 1000.0;
  liquid.shape.type = ShapeType::box;
  liquid.shape.center = {0.25, 0.25};
  liquid.shape.half_size = {0.25, 0.25};
  scene.liquids.push_back(liquid);
  BodySpec box;
  box.name = "box";
  box.motion = BodyMotion::dynamic;
  box.density = 500.0;
  box.shape.type = ShapeType::box;
  box.shape.center = {0.75, 0.3};
  box.shape.half_size = {0.1, 0.1};
  scene.bodies.push_back(box);

  const auto sim = make_simulation(scene);
  const double volume0 = sim->current_stats().liquid_volume;
  const FrameStats frame = sim->advance_frame();
  const bool ok = frame.frame == 1 && frame.steps >= 1 && frame.bodies.size() == 1 &&
                  std::isfinite(frame.liquid_volume) && volume0 > 0.0 &&
                  std::abs(frame.liquid_volume - volume0) < 0.05 * volume0 && frame.solver.converged;
  std::printf("core alone: frame %d, %d steps, liquid volume %.6g -> %.6g m^2, %s scheme: %s\n",
              frame.frame, frame.steps, volume0, frame.liquid_volume,
              enum_name(frame.solver.scheme).c_str(), ok ? "ok" : "FAILED");
  return ok ? 0 : 1;
}
