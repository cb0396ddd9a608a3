/// \file runner.cpp
/// The `run` command: the frame loop and the outputs of docs/cli.md (frames, stats.jsonl,
/// summary.json), with progress on stderr.

#include "reference/app/runner.hpp"

#include <omp.h>
#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>

#include "reference/app/checkpoint.hpp"
#include "reference/app/stats_json.hpp"
#include "reference/core/errors.hpp"
#include "reference/core/parallel.hpp"
#include "reference/core/timer.hpp"

#ifndef MONOLITH_VERSION
#define MONOLITH_VERSION "0.0.0"
#endif

namespace monolith {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string frame_file(int k) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "frame_%05d.ppm", k);
  return buf;
}

std::string seconds_text(double s) {
  std::ostringstream o;
  if (s < 60.0)
    o << std::fixed << std::setprecision(1) << s << "s";
  else if (s < 3600.0)
    o << static_cast<int>(s / 60.0) << "m" << std::setw(2) << std::setfill('0') << static_cast<int>(s) % 60 << "s";
  else
    o << static_cast<int>(s / 3600.0) << "h" << std::setw(2) << std::setfill('0') << static_cast<int>(s / 60.0) % 60 << "m";
  return o.str();
}

// SIGINT / SIGTERM: the handler only records the signal (async-signal-safe); the simulation
// stops at its next step boundary (AnySimulation::set_stop_flag) and the runner finishes the
// outputs. A second signal while stopping ends the process at once, as the default would.
volatile std::sig_atomic_t g_stop_signal = 0;

extern "C" void on_stop_signal(int sig) {
  if (g_stop_signal != 0) {
    std::signal(sig, SIG_DFL);
    std::raise(sig);
    return;
  }
  g_stop_signal = sig;
}

/// Installs the handler for the lifetime of a run and restores the previous one after it.
class StopSignals {
 public:
  StopSignals() {
    g_stop_signal = 0;
    struct sigaction sa {};
    sa.sa_handler = on_stop_signal;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = 0;
    sigaction(SIGINT, &sa, &old_int_);
    sigaction(SIGTERM, &sa, &old_term_);
  }
  ~StopSignals() {
    sigaction(SIGINT, &old_int_, nullptr);
    sigaction(SIGTERM, &old_term_, nullptr);
    g_stop_signal = 0;
  }
  StopSignals(const StopSignals&) = delete;
  StopSignals& operator=(const StopSignals&) = delete;

 private:
  struct sigaction old_int_ {}, old_term_ {};
};

const char* signal_name(int sig) { return sig == SIGINT ? "SIGINT" : sig == SIGTERM ? "SIGTERM" : "a signal"; }

/// The counters of a run that summary.json and checkpoints carry.
struct RunTotals {
  int done = 0;  ///< frames completed after frame 0
  long steps = 0;
  double volume0 = 0.0, volume = 0.0;
  double earlier_wall_time = 0.0;  ///< of the run before a resume
  std::string earlier_build;       ///< a resume --any-build: the build that wrote the checkpoint
};

/// The `totals` object of summary.json after `wall` seconds of this process's run.
json totals_json(const RunTotals& t, double wall) {
  json j;
  j["frames"] = t.done;
  j["steps"] = t.steps;
  j["wall_time"] = t.earlier_wall_time + wall;
  j["initial_liquid_volume"] = t.volume0;
  j["final_liquid_volume"] = t.volume;
  j["volume_drift"] = t.volume0 > 0.0 ? (t.volume - t.volume0) / t.volume0 : 0.0;
  if (!t.earlier_build.empty()) j["earlier_build"] = t.earlier_build;
  return j;
}

/// How a run ended, for summary.json.
struct RunEnd {
  std::string status;   ///< "running", "completed", "failed", "interrupted"
  int frame = -1;       ///< the failed or interrupted frame
  std::string message;  ///< the reason (failed, interrupted)
};

/// Writes summary.json atomically (the scene as run, the version, totals, the status).
void write_summary(const fs::path& dir, const SceneFile& scene, const json& totals, const RunEnd& end) {
  json s;
  s["format"] = "monolith-summary/1";
  s["version"] = MONOLITH_VERSION;
  s["scene"] = scene.as_run;
  s["source"] = scene.source_label;
  s["totals"] = totals;
  s["status"] = end.status;
  s["failed_frame"] = end.status == "failed" ? json(end.frame) : json(nullptr);
  if (end.status == "interrupted") s["interrupted_frame"] = end.frame;
  if (!end.message.empty()) s["message"] = end.message;
  write_file_atomic(dir / "summary.json", s.dump(2) + "\n");
}

/// Renders the current state into frames/frame_NNNNN.ppm (atomically: a temporary name, then
/// rename). The wall times of the picture and of its file are added to the frame's `render` and
/// `output` phases and to its `total`.
void write_frame(const AnySimulation& sim, const FrameRenderer& render, const SceneFile& scene,
                 const fs::path& dir, int k, FrameStats& stats) {
  ScopedTimer total(stats.timing[FramePhase::total]);
  Image image;
  {
    ScopedTimer timer(stats.timing[FramePhase::render]);
    image = render(sim, scene.render);
  }
  ScopedTimer timer(stats.timing[FramePhase::output]);
  write_file_atomic(dir / "frames" / frame_file(k), image.ppm_bytes());
}

/// The frame's picture (when the scene renders), then its stats line, so that the line holds the
/// picture's `render` and `output` time. A picture that cannot be written still leaves the
/// frame's stats line behind before the error goes on.
void write_frame_and_stats(const AnySimulation& sim, const FrameRenderer& render,
                           const SceneFile& scene, const fs::path& dir, int k, FrameStats& stats,
                           LineFile& lines) {
  if (scene.render.enabled) {
    try {
      write_frame(sim, render, scene, dir, k, stats);
    } catch (const OutputError&) {
      lines.append_line(frame_stats_json(stats).dump());
      throw;
    }
  }
  lines.append_line(frame_stats_json(stats).dump());
}

/// The scene JSON without its frame count (resume may change it).
json without_frames(json j) {
  if (j.is_object() && j.contains("time") && j["time"].is_object()) j["time"].erase("frames");
  return j;
}

/// Everything a run needs besides the simulation: the scene, the folder, the options.
struct RunContext {
  const SceneFile& scene;
  fs::path dir;
  const RunOptions& options;
  std::string source_path;
  std::vector<std::string> overrides;
  int checkpoint_every = 0;
};

/// The frame loop shared by run and resume, from totals.done (or inside frame done + 1 when
/// the simulation stopped there) to the scene's frame count.
int run_frames(const RunContext& c, AnySimulation& sim, RunTotals totals, std::ostream& err,
               const FrameRenderer& renderer, bool append_stats) {
  const SceneFile& scene = c.scene;
  const fs::path& dir = c.dir;
  const RunOptions& o = c.options;
  const bool live = !o.quiet && &err == &std::cerr && isatty(STDERR_FILENO);
  const bool lines = !o.quiet && !live;
  const int frames = scene.time.frames;
  const Stopwatch watch;
  const int first = totals.done;
  auto elapsed = [&] { return watch.seconds(); };
  auto checkpoint = [&] {
    CheckpointRecord r;
    r.state = sim.save_state();
    if (r.state.empty()) return false;  // a simulation without a saveable state
    r.build_id = build_id();
    r.scene_json = scene.as_run.dump();
    r.source_label = scene.source_label;
    r.base_dir = scene.base_dir.string();
    r.source_path = c.source_path;
    r.overrides = c.overrides;
    r.frame = totals.done;
    r.mid_frame = sim.mid_frame();
    r.total_steps = totals.steps;
    r.initial_volume = totals.volume0;
    r.volume = totals.volume;
    r.wall_time = totals.earlier_wall_time + elapsed();
    r.checkpoint_every = c.checkpoint_every;
    r.threads = omp_get_max_threads();
    for (const auto& f : scene.input_files) {
      r.input_files.push_back(f.string());
      r.input_digests.push_back(file_digest(f));
    }
    write_checkpoint(checkpoint_path(dir), r);
    return true;
  };

  // the handler is installed by the caller before the simulation is built (a signal during a
  // long set-up, a mesh's distance field, stops the run before frame 1 with the same outputs)
  sim.set_stop_flag(&g_stop_signal);
  int frame = totals.done;
  RunEnd end{"completed", -1, ""};
  try {
    LineFile stats(dir / "stats.jsonl", !append_stats);
    write_summary(dir, scene, totals_json(totals, elapsed()), {"running", -1, ""});
    if (!append_stats) {
      // frame 0: the initial state
      FrameStats st = sim.current_stats();
      totals.volume0 = totals.volume = st.liquid_volume;
      write_frame_and_stats(sim, renderer, scene, dir, 0, st, stats);
    }
    for (frame = totals.done + 1; frame <= frames && g_stop_signal == 0; ++frame) {
      FrameStats st = sim.advance_frame();
      if (sim.mid_frame()) break;  // stopped between two steps by a signal
      st.frame = frame;
      totals.steps += st.steps;
      totals.volume = st.liquid_volume;
      write_frame_and_stats(sim, renderer, scene, dir, frame, st, stats);
      totals.done = frame;
      // a solve that stopped short of the tolerance is never silent, even with --quiet
      if (!st.solver.converged) {
        if (live) err << "\n";
        std::ostringstream w;
        w << "solver did not converge: ";
        const auto& u = st.solver.unconverged;
        if (u.empty()) {
          w << "max relative residual " << st.solver.max_relative_residual;
        } else {
          // the worst solve of the frame
          std::size_t worst = 0;
          for (std::size_t i = 1; i < u.size(); ++i)
            if (!(u[i].relative_residual <= u[worst].relative_residual)) worst = i;
          w << u[worst].solve << " solve at t = " << u[worst].time << " s stopped after " << u[worst].iterations
            << " iterations at relative residual " << u[worst].relative_residual;
          if (u.size() > 1) w << " (" << u.size() << " unconverged solves in the frame)";
        }
        w << " (solver.tolerance " << scene.solver.tolerance << ", solver.max_iterations "
          << scene.solver.max_iterations << ")";
        err << scene.source_label << ": frame " << frame << ": " << w.str() << "\n" << std::flush;
        if (scene.solver.on_nonconvergence == NonconvergencePolicy::fail)
          throw SimulationError(w.str() + "; solver.on_nonconvergence is \"fail\"");
      }
      if (c.checkpoint_every > 0 && (frame % c.checkpoint_every == 0 || frame == frames)) checkpoint();
      // progress
      const double el = elapsed();
      const double eta = el / (frame - first) * (frames - frame);
      std::ostringstream line;
      line << "frame " << frame << "/" << frames << "  t=" << std::setprecision(4) << st.time << "s  steps "
           << st.steps << "  elapsed " << seconds_text(el) << "  ETA " << seconds_text(eta);
      if (live)
        err << "\r" << line.str() << "   " << std::flush;
      else if (lines)
        err << line.str() << "\n" << std::flush;
    }
    if (live) err << "\n";
    if (g_stop_signal != 0 && (totals.done < frames || sim.mid_frame())) {
      const int sig = g_stop_signal;
      const bool saved = checkpoint();
      end = {"interrupted", totals.done + 1,
             std::string("stopped by ") + signal_name(sig) + (sim.mid_frame() ? " inside frame " : " before frame ") +
                 std::to_string(totals.done + 1) +
                 (saved ? "; continue with: monolith resume " + dir.string() : "")};
      write_summary(dir, scene, totals_json(totals, elapsed()), end);
      err << scene.source_label << ": " << end.message << "\n";
      sim.set_stop_flag(nullptr);
      return 128 + sig;
    }
  } catch (const SimulationError& e) {
    end = {"failed", frame, e.what()};
  } catch (const OutputError& e) {
    end = {"failed", frame, std::string("cannot write the outputs: ") + e.what()};
  }
  sim.set_stop_flag(nullptr);
  if (end.status == "failed") {
    if (live) err << "\n";
    err << scene.source_label << ": simulation failed at frame " << end.frame << ": " << end.message << "\n";
    try {
      write_summary(dir, scene, totals_json(totals, elapsed()), end);
    } catch (const OutputError& e) {
      err << e.what() << "\n";
    }
    return 3;
  }
  try {
    write_summary(dir, scene, totals_json(totals, elapsed()), end);
  } catch (const OutputError& e) {
    err << e.what() << "\n";
    return 3;
  }
  if (!o.quiet) err << "wrote " << totals.done << " frames to " << dir.string() << " in " << seconds_text(elapsed()) << "\n";
  return 0;
}

/// Removes frames/frame_NNNNN.ppm with NNNNN > `keep` (all with keep = -1).
void remove_frames_after(const fs::path& dir, int keep) {
  std::error_code ec;
  if (!fs::is_directory(dir / "frames", ec)) return;
  std::vector<fs::path> stale;
  for (const auto& entry : fs::directory_iterator(dir / "frames", ec)) {
    const std::string f = entry.path().filename().string();
    if (f.size() == 15 && f.rfind("frame_", 0) == 0 && entry.path().extension() == ".ppm" &&
        std::atoi(f.substr(6, 5).c_str()) > keep)
      stale.push_back(entry.path());
  }
  for (const auto& f : stale) fs::remove(f, ec);
}

/// Creates the output folders (InputError naming the path when that is impossible).
void make_output_folders(const fs::path& dir, bool render) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir, ec))
    throw InputError(dir.string() + ": (output): cannot create the output folder (a writable folder path for --out)");
  if (render) {
    fs::create_directories(dir / "frames", ec);
    if (ec) throw InputError((dir / "frames").string() + ": (output): cannot create the folder (a writable output folder)");
  }
  // the folder must take new files (a read-only folder is refused before the run starts)
  if (::access(dir.c_str(), W_OK) != 0)
    throw InputError(dir.string() + ": (output): the folder is not writable (a writable output folder)");
}

}  // namespace

void apply_thread_option(int threads) {
  if (threads == RunOptions::kAutoThreads) threads = automatic_thread_count();
  if (threads > 0) omp_set_num_threads(threads);
}

int run_scene(const RunOptions& o, std::ostream& err, const SimulationFactory& factory,
              const FrameRenderer& renderer) {
  // --no-render acts as a last --set render.enabled=false
  std::vector<std::string> overrides = o.overrides;
  if (o.no_render) overrides.push_back("render.enabled=false");
  apply_thread_option(o.threads);

  // scene and simulation
  const SceneFile scene = load_scene(o.scene, overrides);
  const fs::path dir = o.out_dir.empty() ? fs::path("out") / scene.name : fs::path(o.out_dir);
  make_output_folders(dir, scene.render.enabled);
  // outputs of an earlier run into the same folder would be mistaken for this one's
  std::error_code ec;
  fs::remove(dir / "summary.json", ec);
  fs::remove(checkpoint_path(dir), ec);
  remove_frames_after(dir, -1);

  RunContext c{scene, dir, o, "", overrides, o.checkpoint_every};
  // a scene file (not a built-in) is remembered so that resume can tell if it changed
  if (fs::is_regular_file(o.scene, ec)) c.source_path = fs::absolute(o.scene, ec).string();
  StopSignals signals;
  std::unique_ptr<AnySimulation> sim;
  try {
    sim = factory(scene);
  } catch (const SimulationError& e) {
    write_summary(dir, scene, totals_json(RunTotals{}, 0.0), {"failed", 0, e.what()});
    err << scene.source_label << ": simulation failed at frame 0: " << e.what() << "\n";
    return 3;
  }
  return run_frames(c, *sim, RunTotals{}, err, renderer, false);
}

int resume_run(const RunOptions& o, std::ostream& err, const SimulationFactory& factory,
               const FrameRenderer& renderer) {
  apply_thread_option(o.threads);
  const fs::path dir(o.resume_dir);
  const fs::path file = checkpoint_path(dir);
  // every check before anything in the folder changes
  const CheckpointRecord r = read_checkpoint(file, o.any_build);
  const bool other_build = r.build_id != build_id();
  const std::string label = file.string() + ": ";
  json as_run = json::parse(r.scene_json, nullptr, false);
  if (as_run.is_discarded() || !as_run.is_object()) throw InputError(label + "the scene it holds is not valid JSON");
  // the scene of the folder's run and the scene file, if it is still there, must be the checkpoint's
  {
    std::ifstream in(dir / "summary.json");
    const json summary = in ? json::parse(in, nullptr, false) : json();
    if (summary.is_object() && summary.contains("scene") &&
        without_frames(summary["scene"]) != without_frames(as_run))
      throw InputError(label + "the checkpoint is of another scene than the run in " + dir.string() +
                       " (its summary.json): refusing to mix them");
  }
  std::error_code ec;
  if (!r.source_path.empty() && fs::is_regular_file(r.source_path, ec)) {
    SceneFile now;
    try {
      now = load_scene(r.source_path, r.overrides);
    } catch (const InputError&) {
      throw InputError(label + "the scene file " + r.source_path + " changed since the checkpoint and is no longer valid");
    }
    if (without_frames(now.as_run) != without_frames(as_run))
      throw InputError(label + "the scene file " + r.source_path +
                       " changed since the checkpoint (a checkpoint continues only the scene it was taken of)");
  }
  if (o.resume_frames >= 0) {
    if (o.resume_frames < r.frame + (r.mid_frame ? 1 : 0))
      throw InputError("resume: --frames " + std::to_string(o.resume_frames) + ": the checkpoint is at frame " +
                       std::to_string(r.frame) + " (a total frame count of at least that)");
    as_run["time"]["frames"] = o.resume_frames;
  }
  const SceneFile scene = parse_scene(as_run, r.source_label, r.base_dir);
  // stats.jsonl must hold the rows 0..frame of the checkpoint
  std::vector<std::string> rows;
  {
    std::ifstream in(dir / "stats.jsonl");
    std::string line;
    while (static_cast<int>(rows.size()) <= r.frame && std::getline(in, line) && !in.eof()) {
      const json j = json::parse(line, nullptr, false);
      if (j.is_discarded() || !j.contains("frame") || j["frame"] != static_cast<int>(rows.size())) break;
      rows.push_back(line);
    }
    if (static_cast<int>(rows.size()) != r.frame + 1)
      throw InputError((dir / "stats.jsonl").string() + ": holds " + std::to_string(rows.size()) +
                       " whole rows from frame 0, the checkpoint needs rows 0.." + std::to_string(r.frame));
  }
  // the meshes the scene reads must be the ones it was run with
  for (std::size_t i = 0; i < r.input_files.size() && i < r.input_digests.size(); ++i)
    if (file_digest(r.input_files[i]) != r.input_digests[i])
      throw InputError(label + "the mesh file " + r.input_files[i] +
                       " changed (or went missing) since the checkpoint (a checkpoint continues only the scene it was taken of)");
  StopSignals signals;
  // The simulation is built from the scene and then replaced by the checkpoint's state, so a
  // settled start (particles.settle_steps) is not run again: its steps would be thrown away by
  // load_state (the checkpoint holds the settled particles, the bodies' poses and what they
  // carry). The run keeps the scene as given (its JSON, the summary, later checkpoints).
  SceneFile built = scene;
  built.particles.settle_steps = 0;
  std::unique_ptr<AnySimulation> sim = factory(built);
  sim->load_state(r.state);
  // now the folder: stats rows and frames after the checkpoint belong to the stopped run
  make_output_folders(dir, scene.render.enabled);
  std::string kept;
  for (const auto& row : rows) kept += row + "\n";
  write_file_atomic(dir / "stats.jsonl", kept);
  remove_frames_after(dir, r.frame);

  RunContext c{scene, dir, o, r.source_path, r.overrides, o.checkpoint_every > 0 ? o.checkpoint_every : r.checkpoint_every};
  RunTotals totals;
  totals.done = r.frame;
  totals.steps = r.total_steps;
  totals.volume0 = r.initial_volume;
  totals.volume = r.volume;
  totals.earlier_wall_time = r.wall_time;
  if (other_build) {
    totals.earlier_build = r.build_id;
    err << file.string() << ": written by another build (" << r.build_id << "; this is " << build_id()
        << "): continued with --any-build, not bit for bit\n";
  }
  if (!o.quiet) err << "resuming " << scene.source_label << " at frame " << r.frame << (r.mid_frame ? " (inside the next frame)" : "") << "\n";
  return run_frames(c, *sim, totals, err, renderer, true);
}

}  // namespace monolith
