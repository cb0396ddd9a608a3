/// \file runner.cpp
/// The `run` command: the frame loop and the outputs of docs/cli.md (frames, stats.jsonl,
/// summary.json), with progress on stderr.

#include "reference/app/runner.hpp"

#include <omp.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>

#include "reference/app/stats_json.hpp"
#include "reference/core/errors.hpp"
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

/// Writes summary.json (the scene as run, the version, totals, the status).
void write_summary(const fs::path& dir, const SceneFile& scene, const json& totals, bool failed, int failed_frame,
                   const std::string& message) {
  json s;
  s["format"] = "monolith-summary/1";
  s["version"] = MONOLITH_VERSION;
  s["scene"] = scene.as_run;
  s["source"] = scene.source_label;
  s["totals"] = totals;
  s["status"] = failed ? "failed" : "ok";
  s["failed_frame"] = failed ? json(failed_frame) : json(nullptr);
  if (failed) s["message"] = message;
  std::ofstream f(dir / "summary.json");
  f << s.dump(2) << "\n";
  if (!f) throw InputError(dir.string() + ": (output): cannot write summary.json (a writable output folder)");
}

/// Renders the current state into frames/frame_NNNNN.ppm; a file that cannot be written is an
/// input error (the output folder), not an internal one. The wall times of the picture and of
/// its file are added to the frame's `render` and `output` phases and to its `total`.
void write_frame(const AnySimulation& sim, const FrameRenderer& render, const SceneFile& scene,
                 const fs::path& dir, int k, FrameStats& stats) {
  const fs::path path = dir / "frames" / frame_file(k);
  ScopedTimer total(stats.timing[FramePhase::total]);
  Image image;
  {
    ScopedTimer timer(stats.timing[FramePhase::render]);
    image = render(sim, scene.render);
  }
  ScopedTimer timer(stats.timing[FramePhase::output]);
  try {
    image.write_ppm(path.string());
  } catch (const std::runtime_error& e) {
    throw InputError(path.string() + ": (output): cannot write the picture: " + e.what() + " (a writable output folder)");
  }
}

}  // namespace

int run_scene(const RunOptions& o, std::ostream& err, const SimulationFactory& factory,
              const FrameRenderer& renderer) {
  // --no-render acts as a last --set render.enabled=false
  std::vector<std::string> overrides = o.overrides;
  if (o.no_render) overrides.push_back("render.enabled=false");
  if (o.threads > 0) omp_set_num_threads(o.threads);

  // scene and simulation
  const SceneFile scene = load_scene(o.scene, overrides);
  const fs::path dir = o.out_dir.empty() ? fs::path("out") / scene.name : fs::path(o.out_dir);
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir, ec))
    throw InputError(dir.string() + ": (output): cannot create the output folder (a writable folder path for --out)");
  // outputs of an earlier run into the same folder would be mistaken for this one's
  fs::remove(dir / "summary.json", ec);
  if (fs::is_directory(dir / "frames", ec)) {
    std::vector<fs::path> stale;
    for (const auto& entry : fs::directory_iterator(dir / "frames", ec)) {
      const std::string f = entry.path().filename().string();
      if (f.size() == 15 && f.rfind("frame_", 0) == 0 && entry.path().extension() == ".ppm") stale.push_back(entry.path());
    }
    for (const auto& f : stale) fs::remove(f, ec);
  }
  const bool render = scene.render.enabled;
  if (render) {
    fs::create_directories(dir / "frames", ec);
    if (ec) throw InputError((dir / "frames").string() + ": (output): cannot create the folder (a writable output folder)");
  }
  std::ofstream stats(dir / "stats.jsonl", std::ios::trunc);
  if (!stats) throw InputError((dir / "stats.jsonl").string() + ": (output): cannot write (a writable output folder)");

  const bool live = !o.quiet && &err == &std::cerr && isatty(STDERR_FILENO);
  const bool lines = !o.quiet && !live;
  const int frames = scene.time.frames;
  const Stopwatch watch;
  auto elapsed = [&] { return watch.seconds(); };

  // totals, kept up to date for summary.json
  long total_steps = 0;
  double volume0 = 0.0, volume = 0.0;
  int done = 0;
  auto totals = [&] {
    json t;
    t["frames"] = done;
    t["steps"] = total_steps;
    t["wall_time"] = elapsed();
    t["initial_liquid_volume"] = volume0;
    t["final_liquid_volume"] = volume;
    t["volume_drift"] = volume0 > 0.0 ? (volume - volume0) / volume0 : 0.0;
    return t;
  };

  int frame = 0;
  try {
    auto sim = factory(scene);
    // frame 0: the initial state
    FrameStats st = sim->current_stats();
    volume0 = volume = st.liquid_volume;
    if (render) write_frame(*sim, renderer, scene, dir, 0, st);
    stats << frame_stats_json(st).dump() << "\n" << std::flush;
    for (frame = 1; frame <= frames; ++frame) {
      st = sim->advance_frame();
      st.frame = frame;
      total_steps += st.steps;
      volume = st.liquid_volume;
      if (render) write_frame(*sim, renderer, scene, dir, frame, st);
      stats << frame_stats_json(st).dump() << "\n" << std::flush;
      done = frame;
      // progress
      const double el = elapsed();
      const double eta = el / frame * (frames - frame);
      std::ostringstream line;
      line << "frame " << frame << "/" << frames << "  t=" << std::setprecision(4) << st.time << "s  steps "
           << st.steps << "  elapsed " << seconds_text(el) << "  ETA " << seconds_text(eta);
      if (live)
        err << "\r" << line.str() << "   " << std::flush;
      else if (lines)
        err << line.str() << "\n" << std::flush;
    }
    if (live) err << "\n";
  } catch (const SimulationError& e) {
    if (live) err << "\n";
    write_summary(dir, scene, totals(), true, frame, e.what());
    err << scene.source_label << ": simulation failed at frame " << frame << ": " << e.what() << "\n";
    return 3;
  }
  write_summary(dir, scene, totals(), false, -1, "");
  if (!o.quiet) err << "wrote " << done << " frames to " << dir.string() << " in " << seconds_text(elapsed()) << "\n";
  return 0;
}

}  // namespace monolith
