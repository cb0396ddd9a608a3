/// \file cli.cpp
/// The command line of docs/cli.md: `monolith run | check | list | --help | --version`.
/// Every exception is caught here: InputError -> exit 2, SimulationError -> exit 3, anything
/// else -> "internal error" and exit 1.

#include "reference/app/cli.hpp"

#include "reference/app/runner.hpp"

#include <algorithm>
#include <iomanip>

#include "reference/app/embedded_scenes.hpp"
#include "reference/app/oracle.hpp"
#include "reference/app/scene_file.hpp"
#include "reference/core/errors.hpp"
#include "reference/core/parallel.hpp"
#include "reference/sim/simulation.hpp"

#ifndef MONOLITH_VERSION
#define MONOLITH_VERSION "0.0.0"
#endif

namespace monolith {

namespace {

using nlohmann::json;

const char* kUsage =
    "usage:\n"
    "  monolith run SCENE [--frames N] [--out DIR] [--scheme NAME] [--backend matrixfree|explicit]\n"
    "                     [--threads N|auto] [--no-render] [--quiet] [--set KEY=VALUE]...\n"
    "                     [--checkpoint-every N]\n"
    "  monolith resume DIR [--frames N] [--threads N|auto] [--quiet] [--checkpoint-every N] [--any-build]\n"
    "  monolith check SCENE [--set KEY=VALUE]...\n"
    "  monolith list\n"
    "  monolith convert IN.ppm OUT.png\n"
    "  monolith export SCENE --frame N [--step K] --out DIR [--set KEY=VALUE]...\n"
    "  monolith verify DIR CANDIDATE.mtx [--tolerance T]\n"
    "  monolith --help | --version\n";

const char* kHelp =
    "monolith: a reference implementation of \"Monolith: a monolithic pressure-viscosity-contact\n"
    "solver for strong two-way rigid-rigid rigid-fluid coupling\" (Takahashi & Batty 2020).\n"
    "\n"
    "commands:\n"
    "  run SCENE     simulate SCENE (a JSON scene file or a built-in scene name) and write\n"
    "                frames/frame_NNNNN.ppm, stats.jsonl and summary.json into the output folder\n"
    "  resume DIR    continue the run in the output folder DIR from its last checkpoint (written\n"
    "                by --checkpoint-every or when a run is interrupted), bit for bit as if it\n"
    "                had not stopped; --frames N sets a new total frame count; --any-build\n"
    "                continues a checkpoint of another build (not bit for bit)\n"
    "  check SCENE   validate SCENE and print every problem found (exit 0 if valid, 2 if not)\n"
    "  list          the built-in scenes: name, dimension, description\n"
    "  convert       re-encode a PPM picture (a frame or a plot) as PNG for web pages\n"
    "  export SCENE  run SCENE to frame N and write its step K's coupled system of eq. (24)\n"
    "                (every named matrix, A, b and the reference solution x) as Matrix Market\n"
    "                files with manifest.json into DIR (docs/oracle.md)\n"
    "  verify DIR X  check a candidate solution X.mtx of an exported system: residual of the\n"
    "                free rows, complementarity, bound and friction-cone violations (exit 0 ok,\n"
    "                1 outside the tolerance, 2 unreadable or mis-sized input)\n"
    "\n"
    "options of run (check takes --set too):\n"
    "  --frames N        number of frames to simulate (same as --set time.frames=N)\n"
    "  --out DIR         output folder (default out/<scene name>; created if missing)\n"
    "  --scheme NAME     coupling scheme (same as --set solver.scheme=NAME): P-C, C-P,\n"
    "                    PC-iterative, PC-unified, PC-VC-PC-unified, PV-C, C-PV, PVC-iterative,\n"
    "                    PVC-unified\n"
    "  --backend NAME    matrixfree or explicit (same as --set solver.backend=NAME)\n"
    "  --threads N|auto  at most N OpenMP threads, N in 1..1024, or auto = the cores of the\n"
    "                    affinity mask that are idle at the start (sampled for 0.1 s; at least 1).\n"
    "                    Without the flag: MONOLITH_THREADS (same values), else OMP_NUM_THREADS,\n"
    "                    else auto. The solver kernels measure themselves and run with fewer\n"
    "                    threads while that is faster (another process on a core;\n"
    "                    MONOLITH_ADAPTIVE_THREADS=0: always N). Results do not depend on the\n"
    "                    thread count. Idle threads spin briefly\n"
    "                    then sleep (GOMP_SPINCOUNT=10000 unless OMP_WAIT_POLICY or\n"
    "                    GOMP_SPINCOUNT is set; docs/cli.md, \"Threads\")\n"
    "  --no-render       write no pictures (same as --set render.enabled=false)\n"
    "  --quiet           no progress output\n"
    "  --set KEY=VALUE   override a scene key by its dotted path, e.g. solver.tolerance=1e-8,\n"
    "                    liquids.0.density=800, gravity=[0,-9.81]; VALUE is JSON or a string\n"
    "  --checkpoint-every N  write DIR/checkpoint.mckpt every N frames and at the end\n"
    "\n"
    "SIGINT (Ctrl-C) or SIGTERM stops a run at the next step boundary: the outputs so far, a\n"
    "checkpoint and summary.json (status \"interrupted\") are written; a second signal quits at once.\n"
    "exit codes: 0 success, 2 invalid input, 3 simulation failure (outputs so far are kept),\n"
    "130 / 143 interrupted by SIGINT / SIGTERM.\n"
    "documentation: docs/cli.md and docs/scene-format.md\n";

bool parse_nonneg_int(const std::string& s, long long max, long long& out) {
  if (s.empty() || s.size() > 12) return false;
  for (char c : s)
    if (c < '0' || c > '9') return false;
  out = std::stoll(s);
  return out <= max;
}

/// Parses the arguments after the command name; throws InputError on a bad flag. `run_flags`:
/// the flags of run; for resume the positional argument is the run folder and only --frames,
/// --threads, --quiet, --checkpoint-every and (resume's own) --any-build are taken.
RunOptions parse_options(const std::string& command, const std::vector<std::string>& args, bool run_flags) {
  const bool resume = command == "resume";
  RunOptions o;
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
    } else if (resume && (a == "--set" || a == "--out" || a == "--scheme" || a == "--backend" || a == "--no-render")) {
      problems.push_back(command + ": " + a + ": a resumed run keeps the scene and folder of its checkpoint (start a new run to change them)");
    } else if (a == "--set") {
      if (take_value(a)) o.overrides.push_back(value);
    } else if (run_flags && a == "--frames") {
      long long n = 0;
      if (take_value(a)) {
        if (parse_nonneg_int(value, 100000000, n) && resume)
          o.resume_frames = static_cast<int>(n);
        else if (parse_nonneg_int(value, 100000000, n))
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
      if (take_value(a)) {
        const ThreadSpec spec = parse_thread_spec(value);
        if (spec.valid)
          o.threads = spec.automatic ? RunOptions::kAutoThreads : spec.count;
        else
          problems.push_back(command + ": --threads: bad value \"" + value.substr(0, 40) +
                             "\" (auto or an integer in 1..1024)");
      }
    } else if (run_flags && a == "--checkpoint-every") {
      long long n = 0;
      if (take_value(a)) {
        if (parse_nonneg_int(value, 100000000, n) && n >= 1)
          o.checkpoint_every = static_cast<int>(n);
        else
          problems.push_back(command + ": --checkpoint-every: bad value \"" + value.substr(0, 40) +
                             "\" (an integer in 1..100000000: frames between checkpoints)");
      }
    } else if (run_flags && a == "--no-render" && !has_inline) {
      o.no_render = true;
    } else if (run_flags && a == "--quiet" && !has_inline) {
      o.quiet = true;
    } else if (resume && a == "--any-build" && !has_inline) {
      o.any_build = true;
    } else {
      problems.push_back(command + ": unknown option \"" + args[i].substr(0, 80) + "\" (see monolith --help)");
    }
  }
  if (resume) {
    o.resume_dir = o.scene;
    if (o.scene.empty()) problems.push_back(command + ": missing DIR (the output folder of a run with a checkpoint)");
  } else if (o.scene.empty()) {
    problems.push_back(command + ": missing SCENE (a scene file or a built-in scene name; see monolith list)");
  }
  if (run_flags && o.threads == 0) {
    // no --threads: MONOLITH_THREADS, else OMP_NUM_THREADS (OpenMP's own), else auto
    if (const char* env = std::getenv("MONOLITH_THREADS")) {
      const ThreadSpec spec = parse_thread_spec(env);
      if (spec.valid)
        o.threads = spec.automatic ? RunOptions::kAutoThreads : spec.count;
      else
        problems.push_back(command + ": environment variable MONOLITH_THREADS: bad value \"" +
                           std::string(env).substr(0, 40) + "\" (auto or an integer in 1..1024)");
    } else if (!std::getenv("OMP_NUM_THREADS")) {
      o.threads = RunOptions::kAutoThreads;
    }
  }
  if (!problems.empty()) throw InputError(problems);
  return o;
}

int cmd_check(const std::vector<std::string>& args, std::ostream& out) {
  const RunOptions o = parse_options("check", args, false);
  const SceneFile scene = load_scene(o.scene, o.overrides);
  long long cells = 1;
  for (int c : scene.domain.cells) cells *= c;
  out << scene.source_label << ": ok: \"" << scene.name << "\", " << scene.dim << "D, " << cells << " cells, "
      << scene.liquids.size() << " liquid(s), " << scene.bodies.size() << " body(ies), " << scene.time.frames
      << " frames at " << scene.time.fps << " fps\n";
  return 0;
}

int cmd_list(const std::vector<std::string>& args, std::ostream& out) {
  if (!args.empty()) throw InputError("list: unexpected argument \"" + args[0].substr(0, 80) + "\" (list takes no arguments)");
  // names padded to the longest one, so the columns line up
  std::size_t width = 0;
  for (const auto& f : embedded_scenes()) width = std::max(width, std::string(f.name).size());
  for (const auto& f : embedded_scenes()) {
    // dim and description from the scene itself
    std::string dim = "?", description;
    const json j = json::parse(f.data, nullptr, false);
    if (j.is_object()) {
      if (j.contains("dim") && j["dim"].is_number_integer()) dim = std::to_string(j["dim"].get<int>()) + "D";
      if (j.contains("description") && j["description"].is_string()) description = j["description"].get<std::string>();
    }
    out << std::left << std::setw(static_cast<int>(width)) << std::string(f.name) << " " << dim << "  " << description << "\n";
  }
  return 0;
}

int cmd_convert(const std::vector<std::string>& args, std::ostream& out) {
  if (args.size() != 2)
    throw InputError("convert: expected IN.ppm OUT.png (got " + std::to_string(args.size()) + " arguments)");
  Image image;
  try {
    image = Image::read_ppm(args[0]);
  } catch (const std::runtime_error& e) {
    throw InputError(args[0] + ": " + e.what() + " (a binary P6 PPM with maxval 255 is allowed)");
  }
  try {
    image.write_png(args[1]);
  } catch (const std::runtime_error& e) {
    throw InputError(args[1] + ": " + e.what());
  }
  out << "wrote " << args[1] << " (" << image.width << " x " << image.height << ")\n";
  return 0;
}

}  // namespace

int run_cli(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  return run_cli_with(args, out, err, [](const SceneDesc& scene) { return make_simulation(scene); });
}

int run_cli_with(const std::vector<std::string>& args, std::ostream& out, std::ostream& err,
                 const SimulationFactory& factory, const FrameRenderer& render) {
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
    if (command == "run") return run_scene(parse_options("run", rest, true), err, factory, render);
    if (command == "resume") return resume_run(parse_options("resume", rest, true), err, factory, render);
    if (command == "check") return cmd_check(rest, out);
    if (command == "list") return cmd_list(rest, out);
    if (command == "convert") return cmd_convert(rest, out);
    if (command == "export") return export_command(rest, out, factory);
    if (command == "verify") return verify_command(rest, out);
    err << "monolith: unknown command \"" << command.substr(0, 80)
        << "\" (run, resume, check, list, convert, export, verify, --help, --version)\n"
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
