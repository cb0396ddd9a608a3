/// \file cli.cpp
/// The command line of docs/cli.md: `monolith run | check | list | --help | --version`.
/// Every exception is caught here: InputError -> exit 2, SimulationError -> exit 3, anything
/// else -> "internal error" and exit 1.

#include "reference/cli.hpp"

#include <omp.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>

#include "reference/embedded_data.hpp"
#include "reference/errors.hpp"
#include "reference/scene.hpp"
#include "reference/simulation.hpp"
#include "reference/stats.hpp"

#ifndef MONOLITH_VERSION
#define MONOLITH_VERSION "0.0.0"
#endif

namespace monolith {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

const char* kUsage =
    "usage:\n"
    "  monolith run SCENE [--frames N] [--out DIR] [--scheme NAME] [--backend matrixfree|explicit]\n"
    "                     [--threads N] [--no-render] [--quiet] [--set KEY=VALUE]...\n"
    "  monolith check SCENE [--set KEY=VALUE]...\n"
    "  monolith list\n"
    "  monolith --help | --version\n";

const char* kHelp =
    "monolith: a reference implementation of \"Monolith: a monolithic pressure-viscosity-contact\n"
    "solver for strong two-way rigid-rigid rigid-fluid coupling\" (Takahashi & Batty 2020).\n"
    "\n"
    "commands:\n"
    "  run SCENE     simulate SCENE (a JSON scene file or a built-in scene name) and write\n"
    "                frames/frame_NNNNN.ppm, stats.jsonl and summary.json into the output folder\n"
    "  check SCENE   validate SCENE and print every problem found (exit 0 if valid, 2 if not)\n"
    "  list          the built-in scenes: name, dimension, description\n"
    "\n"
    "options of run (check takes --set too):\n"
    "  --frames N        number of frames to simulate (same as --set time.frames=N)\n"
    "  --out DIR         output folder (default out/<scene name>; created if missing)\n"
    "  --scheme NAME     coupling scheme (same as --set solver.scheme=NAME): P-C, C-P,\n"
    "                    PC-iterative, PC-unified, PC-VC-PC-unified, PV-C, C-PV, PVC-iterative,\n"
    "                    PVC-unified\n"
    "  --backend NAME    matrixfree or explicit (same as --set solver.backend=NAME)\n"
    "  --threads N       number of OpenMP threads\n"
    "  --no-render       write no pictures (same as --set render.enabled=false)\n"
    "  --quiet           no progress output\n"
    "  --set KEY=VALUE   override a scene key by its dotted path, e.g. solver.tolerance=1e-8,\n"
    "                    liquids.0.density=800, gravity=[0,-9.81]; VALUE is JSON or a string\n"
    "\n"
    "exit codes: 0 success, 2 invalid input, 3 simulation failure (outputs so far are kept).\n"
    "documentation: docs/cli.md and docs/scene-format.md\n";

/// Parsed arguments of `run` and `check`.
struct Options {
  std::string scene;
  std::vector<std::string> overrides;
  std::string out_dir;
  int threads = 0;
  bool no_render = false;
  bool quiet = false;
};

bool parse_nonneg_int(const std::string& s, long long max, long long& out) {
  if (s.empty() || s.size() > 12) return false;
  for (char c : s)
    if (c < '0' || c > '9') return false;
  out = std::stoll(s);
  return out <= max;
}

/// Parses the arguments after the command name; throws InputError on a bad flag.
Options parse_options(const std::string& command, const std::vector<std::string>& args, bool run_flags) {
  Options o;
  std::vector<std::string> problems;
  for (std::size_t i = 0; i < args.size(); ++i) {
    std::string a = args[i];
    std::string value;
    bool has_inline = false;
    // --flag=value is the same as --flag value
    if (a.rfind("--", 0) == 0) {
      const std::size_t eq = a.find('=');
      if (eq != std::string::npos) {
        value = a.substr(eq + 1);
        a = a.substr(0, eq);
        has_inline = true;
      }
    }
    auto take_value = [&](const std::string& flag) -> bool {
      if (has_inline) return true;
      if (i + 1 >= args.size()) {
        problems.push_back(command + ": " + flag + ": missing value (see monolith --help)");
        return false;
      }
      value = args[++i];
      return true;
    };
    const bool is_flag = a.size() > 1 && a[0] == '-';
    if (!is_flag) {
      if (o.scene.empty())
        o.scene = a;
      else
        problems.push_back(command + ": unexpected argument \"" + a.substr(0, 80) + "\" (one SCENE only)");
    } else if (a == "--set") {
      if (take_value(a)) o.overrides.push_back(value);
    } else if (run_flags && a == "--frames") {
      long long n = 0;
      if (take_value(a)) {
        if (parse_nonneg_int(value, 100000000, n))
          o.overrides.push_back("time.frames=" + std::to_string(n));
        else
          problems.push_back(command + ": --frames: bad value \"" + value.substr(0, 40) + "\" (an integer in 0..100000000)");
      }
    } else if (run_flags && a == "--out") {
      if (take_value(a)) {
        if (value.empty())
          problems.push_back(command + ": --out: empty folder name (a folder path)");
        else
          o.out_dir = value;
      }
    } else if (run_flags && a == "--scheme") {
      if (take_value(a)) o.overrides.push_back("solver.scheme=" + json(value).dump());
    } else if (run_flags && a == "--backend") {
      if (take_value(a)) o.overrides.push_back("solver.backend=" + json(value).dump());
    } else if (run_flags && a == "--threads") {
      long long n = 0;
      if (take_value(a)) {
        if (parse_nonneg_int(value, 1024, n) && n >= 1)
          o.threads = static_cast<int>(n);
        else
          problems.push_back(command + ": --threads: bad value \"" + value.substr(0, 40) + "\" (an integer in 1..1024)");
      }
    } else if (run_flags && a == "--no-render" && !has_inline) {
      o.no_render = true;
    } else if (run_flags && a == "--quiet" && !has_inline) {
      o.quiet = true;
    } else {
      problems.push_back(command + ": unknown option \"" + args[i].substr(0, 80) + "\" (see monolith --help)");
    }
  }
  if (o.scene.empty()) problems.push_back(command + ": missing SCENE (a scene file or a built-in scene name; see monolith list)");
  if (!problems.empty()) throw InputError(problems);
  return o;
}

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
void write_summary(const fs::path& dir, const SceneDesc& scene, const json& totals, bool failed, int failed_frame,
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

int cmd_run(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  (void)out;
  const Options o = parse_options("run", args, true);
  // --no-render acts as a last --set render.enabled=false
  std::vector<std::string> overrides = o.overrides;
  if (o.no_render) overrides.push_back("render.enabled=false");
  if (o.threads > 0) omp_set_num_threads(o.threads);

  // scene and simulation
  const SceneDesc scene = load_scene(o.scene, overrides);
  require_supported(scene);
  const fs::path dir = o.out_dir.empty() ? fs::path("out") / scene.name : fs::path(o.out_dir);
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir, ec))
    throw InputError(dir.string() + ": (output): cannot create the output folder (a writable folder path for --out)");
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
  const auto t0 = std::chrono::steady_clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };

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
    auto sim = make_simulation(scene);
    // frame 0: the initial state
    FrameStats st = sim->current_stats();
    volume0 = volume = st.liquid_volume;
    stats << st.to_json().dump() << "\n" << std::flush;
    if (render) sim->render(scene.render).write_ppm((dir / "frames" / frame_file(0)).string());
    for (frame = 1; frame <= frames; ++frame) {
      st = sim->advance_frame();
      st.frame = frame;
      total_steps += st.steps;
      volume = st.liquid_volume;
      stats << st.to_json().dump() << "\n" << std::flush;
      if (render) sim->render(scene.render).write_ppm((dir / "frames" / frame_file(frame)).string());
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

int cmd_check(const std::vector<std::string>& args, std::ostream& out) {
  const Options o = parse_options("check", args, false);
  const SceneDesc scene = load_scene(o.scene, o.overrides);
  require_supported(scene);
  long long cells = 1;
  for (int c : scene.domain.cells) cells *= c;
  out << scene.source_label << ": ok: \"" << scene.name << "\", " << scene.dim << "D, " << cells << " cells, "
      << scene.liquids.size() << " liquid(s), " << scene.bodies.size() << " body(ies), " << scene.time.frames
      << " frames at " << scene.time.fps << " fps\n";
  return 0;
}

int cmd_list(const std::vector<std::string>& args, std::ostream& out) {
  if (!args.empty()) throw InputError("list: unexpected argument \"" + args[0].substr(0, 80) + "\" (list takes no arguments)");
  for (const auto& f : embedded_scenes()) {
    // dim and description from the scene itself
    std::string dim = "?", description;
    const json j = json::parse(f.data, nullptr, false);
    if (j.is_object()) {
      if (j.contains("dim") && j["dim"].is_number_integer()) dim = std::to_string(j["dim"].get<int>()) + "D";
      if (j.contains("description") && j["description"].is_string()) description = j["description"].get<std::string>();
    }
    out << std::left << std::setw(20) << std::string(f.name) << " " << dim << "  " << description << "\n";
  }
  return 0;
}

}  // namespace

int run_cli(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  try {
    if (args.empty()) {
      err << "monolith: missing command\n" << kUsage;
      return 2;
    }
    const std::string& command = args[0];
    const std::vector<std::string> rest(args.begin() + 1, args.end());
    if (command == "--help" || command == "-h" || command == "help") {
      out << kHelp << "\n" << kUsage;
      return 0;
    }
    if (command == "--version") {
      out << "monolith " << MONOLITH_VERSION << "\n";
      return 0;
    }
    if (command == "run") return cmd_run(rest, out, err);
    if (command == "check") return cmd_check(rest, out);
    if (command == "list") return cmd_list(rest, out);
    err << "monolith: unknown command \"" << command.substr(0, 80) << "\" (run, check, list, --help, --version)\n"
        << kUsage;
    return 2;
  } catch (const InputError& e) {
    for (const auto& line : e.problems()) err << line << "\n";
    return 2;
  } catch (const SimulationError& e) {
    err << "simulation failed: " << e.what() << "\n";
    return 3;
  } catch (const std::exception& e) {
    err << "internal error: " << e.what() << "\n";
    return 1;
  } catch (...) {
    err << "internal error: unknown exception\n";
    return 1;
  }
}

}  // namespace monolith
