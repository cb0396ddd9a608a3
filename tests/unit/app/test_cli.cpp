// Tests of the command line (reference/app/cli.cpp, reference/app/runner.cpp, docs/cli.md): exit codes,
// messages, outputs of `run` with a stand-in simulation, and robustness against garbage input.
#include <omp.h>

#include <catch2/catch.hpp>

#include <sys/resource.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "reference/app/cli.hpp"
#include "reference/app/embedded_scenes.hpp"
#include "reference/app/runner.hpp"
#include "reference/app/stats_json.hpp"
#include "reference/core/errors.hpp"
#include "tests/support/cli_helpers.hpp"
#include "reference/sim/frame_stats.hpp"

using namespace monolith;
using nlohmann::json;
namespace fs = std::filesystem;

namespace {

const char* kGood2 = R"({
  "format": "monolith-scene/1", "name": "cli-test", "dim": 2,
  "domain": {"lower": [0, 0], "upper": [1, 1], "cells": [16, 16]},
  "time": {"fps": 10, "frames": 3},
  "liquids": [{"shape": {"type": "box", "center": [0.5, 0.3], "half_size": [0.2, 0.2]}, "density": 1000}],
  "bodies": [{"motion": "static", "shape": {"type": "sphere", "center": [0.5, 0.8], "radius": 0.1}}],
  "probes": [{"name": "p", "position": [0.5, 0.5]}],
  "render": {"size": [32, 32]}
})";

const char* kGood3 = R"({
  "format": "monolith-scene/1", "name": "cli-test-3d", "dim": 3,
  "domain": {"lower": [0, 0, 0], "upper": [1, 1, 1], "cells": [8, 8, 8]},
  "time": {"fps": 10, "frames": 3},
  "liquids": [{"shape": {"type": "sphere", "center": [0.5, 0.5, 0.5], "radius": 0.2}, "density": 1000}],
  "render": {"size": [32, 32]}
})";

fs::path temp_dir() {
  const fs::path d = fs::temp_directory_path() / ("monolith_test_cli_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

std::string write_file(const std::string& name, const std::string& text) {
  const fs::path p = temp_dir() / name;
  std::ofstream(p, std::ios::binary) << text;
  return p.string();
}

using Result = test::CliResult;
using test::cli;

/// A stand-in simulation: one step per frame, constant volume, fails at frame `fail_at`.
class FakeSimulation : public AnySimulation {
 public:
  FakeSimulation(const SceneDesc& s, int fail_at) : scene_(s), fail_at_(fail_at) {}
  FrameStats current_stats() const override {
    FrameStats st;
    st.frame = frame_;
    st.time = frame_ / scene_.time.fps;
    st.steps = frame_ ? 2 : 0;
    st.dt_min = st.dt_max = frame_ ? 0.5 / scene_.time.fps : 0.0;
    st.liquid_volume = 0.16 * (1.0 + 0.001 * frame_);
    st.particles = 100;
    st.liquid_bounds_lower.assign(scene_.dim, 0.1);
    st.liquid_bounds_upper.assign(scene_.dim, 0.5);
    st.solver.scheme = scene_.solver.scheme;
    for (const auto& p : scene_.probes) st.probes.push_back({p.name, p.position, std::vector<double>(scene_.dim, 0.0), 1.0});
    return st;
  }
  FrameStats advance_frame() override {
    ++frame_;
    if (frame_ == fail_at_) throw SimulationError("non-finite velocity in step 1");
    return current_stats();
  }

 private:
  SceneDesc scene_;
  int fail_at_;
  int frame_ = 0;
};

Result fake_cli(const std::vector<std::string>& args, int fail_at = -1) {
  std::ostringstream out, err;
  const int code = run_cli_with(
      args, out, err,
      [fail_at](const SceneDesc& s) { return std::unique_ptr<AnySimulation>(new FakeSimulation(s, fail_at)); },
      [](const AnySimulation&, const RenderSpec& spec) { return Image(spec.size[0], spec.size[1], {10, 20, 30}); });
  return {code, out.str(), err.str()};
}

std::vector<json> read_jsonl(const fs::path& p) {
  std::vector<json> lines;
  std::ifstream in(p);
  std::string line;
  while (std::getline(in, line)) lines.push_back(json::parse(line));
  return lines;
}

}  // namespace

TEST_CASE("--version, --help and list", "[unit]") {
  Result r = cli({"--version"});
  CHECK(r.code == 0);
  CHECK(r.out == std::string("monolith ") + MONOLITH_VERSION + "\n");
  r = cli({"--help"});
  CHECK(r.code == 0);
  for (const char* s : {"run SCENE", "check SCENE", "list", "--frames", "--out", "--scheme", "--backend", "--threads",
                        "--no-render", "--quiet", "--set", "resume DIR", "--checkpoint-every"})
    CHECK(r.out.find(s) != std::string::npos);
  r = cli({"list"});
  CHECK(r.code == 0);
  std::istringstream lines(r.out);
  std::string line;
  int n = 0;
  std::size_t dim_column = std::string::npos;
  while (std::getline(lines, line)) {
    std::istringstream words(line);
    std::string name, dim;
    words >> name >> dim;
    CHECK((dim == "2D" || dim == "3D"));
    // the columns line up: the dimension starts at the same offset on every line
    const std::size_t column = line.find(" " + dim + "  ");
    if (dim_column == std::string::npos) dim_column = column;
    CHECK(column == dim_column);
    CHECK(line.size() > name.size() + 10);  // a description follows
    ++n;
  }
  CHECK(n == static_cast<int>(embedded_scenes().size()));
  CHECK(r.out.find("dam-break-2d") != std::string::npos);
  CHECK(cli({"list", "extra"}).code == 2);
}

TEST_CASE("bad commands and flags exit with 2 and a message", "[unit]") {
  const std::string good = write_file("good.json", kGood2);
  const std::vector<std::vector<std::string>> bad = {
      {},
      {"frobnicate"},
      {"run"},
      {"check"},
      {"run", good, "--bogus"},
      {"run", good, "--frames"},
      {"run", good, "--frames", "abc"},
      {"run", good, "--frames", "-1"},
      {"run", good, "--threads", "0"},
      {"run", good, "--threads"},
      {"run", good, "--threads", "all"},
      {"run", good, "--threads", "1025"},
      {"run", good, "--out"},
      {"run", good, "--set"},
      {"run", good, "--set", "noequals"},
      {"run", good, "--scheme", "fastest"},
      {"run", good, "--backend", "gpu"},
      {"run", good, "other.json"},
      {"check", good, "--frames", "3"},
      {"check", good, "--set", "time.fps=-1"},
      {"run", good, "--set", "solver.preconditioner=fastest"},
      {"check", good, "--set", "solver.preconditioner=amg"},
      {"check", (temp_dir() / "missing.json").string()},
      {"run", (temp_dir() / "missing.json").string()},
      {"check", temp_dir().string()},
  };
  for (const auto& args : bad) {
    CAPTURE(args);
    const Result r = fake_cli(args);
    CHECK(r.code == 2);
    CHECK_FALSE(r.err.empty());
  }
  // the message names the file and the key
  const Result r = cli({"check", good, "--set", "time.fps=-1"});
  CHECK(r.err.find(good + ": time.fps: out of range") == 0);
}

TEST_CASE("--threads auto and MONOLITH_THREADS: accepted values run, bad ones exit 2 naming the source",
          "[unit]") {
  const std::string good = write_file("good.json", kGood2);
  const fs::path out = temp_dir() / "threads_out";
  const int saved = omp_get_max_threads();
  for (const char* value : {"auto", "1", "2"}) {
    CAPTURE(value);
    CHECK(fake_cli({"run", good, "--out", out.string(), "--frames", "1", "--quiet", "--no-render",
                    "--threads", value})
              .code == 0);
  }
  // --threads 1 is applied
  CHECK(fake_cli({"run", good, "--out", out.string(), "--frames", "1", "--quiet", "--no-render",
                  "--threads", "1"}).code == 0);
  CHECK(omp_get_max_threads() == 1);
  // the message of a bad --threads lists what is allowed
  Result r = fake_cli({"run", good, "--threads", "many"});
  CHECK(r.code == 2);
  CHECK(r.err.find("--threads: bad value \"many\" (auto or an integer in 1..1024)") != std::string::npos);
  // MONOLITH_THREADS: used without --threads, refused with exit 2 when bad, overridden by --threads
  setenv("MONOLITH_THREADS", "1", 1);
  omp_set_num_threads(2);
  CHECK(fake_cli({"run", good, "--out", out.string(), "--frames", "1", "--quiet", "--no-render"}).code == 0);
  CHECK(omp_get_max_threads() == 1);
  setenv("MONOLITH_THREADS", "lots", 1);
  r = fake_cli({"run", good, "--out", out.string(), "--frames", "1", "--quiet", "--no-render"});
  CHECK(r.code == 2);
  CHECK(r.err.find("MONOLITH_THREADS: bad value \"lots\" (auto or an integer in 1..1024)") != std::string::npos);
  CHECK(fake_cli({"run", good, "--out", out.string(), "--frames", "1", "--quiet", "--no-render",
                  "--threads", "2"}).code == 0);
  CHECK(omp_get_max_threads() == 2);
  unsetenv("MONOLITH_THREADS");
  omp_set_num_threads(saved);
}

TEST_CASE("check accepts good scenes and lists every problem of bad ones", "[unit]") {
  for (const char* text : {kGood2, kGood3}) {
    const std::string good = write_file("good.json", text);
    const Result r = cli({"check", good});
    CHECK(r.code == 0);
    CHECK(r.out.find("ok") != std::string::npos);
    CHECK(r.err.empty());
  }
  for (const auto& f : embedded_scenes()) {
    CAPTURE(f.name);
    CHECK(cli({"check", std::string(f.name)}).code == 0);
  }
  json j = json::parse(kGood2);
  j["time"]["fps"] = 0;
  j["bodies"][0]["friction"] = -1;
  j["solver"] = {{"tolerence", 1e-3}};
  const std::string bad = write_file("bad.json", j.dump());
  const Result r = cli({"check", bad});
  CHECK(r.code == 2);
  CHECK(r.err.find(bad + ": time.fps:") != std::string::npos);
  CHECK(r.err.find(bad + ": bodies[0].friction:") != std::string::npos);
  CHECK(r.err.find(bad + ": solver.tolerence: unknown key") != std::string::npos);
  CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 3);
  // every physics of the format is supported: a dynamic body next to a herschel-bulkley liquid
  // (two-way coupling, Algorithm 2) checks fine
  j = json::parse(kGood2);
  j["bodies"][0]["motion"] = "dynamic";
  j["bodies"][0]["density"] = 500;
  j["liquids"][0]["viscosity"] = {{"model", "herschel-bulkley"}, {"k", 1.0}, {"tau0", 5.0}};
  const Result u = cli({"check", write_file("supported.json", j.dump())});
  CHECK(u.code == 0);
  CHECK(u.err.find("bodies[0].motion") == std::string::npos);
  CHECK(u.err.find("herschel-bulkley") == std::string::npos);
}

TEST_CASE("run writes frames, stats.jsonl and summary.json (2D and 3D)", "[unit]") {
  for (const char* text : {kGood2, kGood3}) {
    const std::string scene = write_file("run.json", text);
    const fs::path out = temp_dir() / "run-out";
    fs::remove_all(out);
    const Result r = fake_cli({"run", scene, "--out", out.string(), "--frames", "4", "--quiet", "--scheme", "PC-unified",
                               "--backend", "explicit", "--threads", "1", "--set", "solver.tolerance=1e-7"});
    CAPTURE(r.err);
    REQUIRE(r.code == 0);
    CHECK(r.err.empty());  // --quiet
    for (int k = 0; k <= 4; ++k) {
      char name[32];
      std::snprintf(name, sizeof name, "frame_%05d.ppm", k);
      CHECK(fs::exists(out / "frames" / name));
    }
    CHECK_FALSE(fs::exists(out / "frames" / "frame_00005.ppm"));
    const Image img = Image::read_ppm((out / "frames" / "frame_00004.ppm").string());
    CHECK(img.width == 32);
    // stats.jsonl: frame 0 and one line per frame, with the contract's keys
    const auto stats = read_jsonl(out / "stats.jsonl");
    REQUIRE(stats.size() == 5);
    for (int k = 0; k <= 4; ++k) CHECK(stats[k]["frame"] == k);
    for (const char* key : {"frame", "time", "steps", "dt_min", "dt_max", "liquid_volume", "particles", "liquid_bounds",
                            "kinetic_energy", "potential_energy", "bodies", "contacts", "probes", "solver",
                            "timing"})
      CHECK(stats[1].contains(key));
    // the timing breakdown: every phase, the picture's inside the frame's total
    for (const char* key : {"total", "solve", "particles", "weights", "extrapolation", "render", "output"})
      CHECK(stats[1]["timing"].contains(key));
    CHECK(stats[1]["timing"]["render"].get<double>() > 0.0);
    // frame 0 times the set-up, which holds the first level set and weights
    CHECK(stats[0]["timing"]["total"].get<double>() >=
          stats[0]["timing"]["particles"].get<double>() + stats[0]["timing"]["weights"].get<double>());
    CHECK(stats[1]["timing"]["total"].get<double>() >=
          stats[1]["timing"]["render"].get<double>() + stats[1]["timing"]["particles"].get<double>() +
              stats[1]["timing"]["solve"].get<double>());
    // summary.json
    std::ifstream in(out / "summary.json");
    const json s = json::parse(in);
    CHECK(s["status"] == "completed");
    CHECK(s["failed_frame"].is_null());
    CHECK(s["version"] == MONOLITH_VERSION);
    CHECK(s["totals"]["frames"] == 4);
    CHECK(s["totals"]["steps"] == 8);
    CHECK(s["totals"]["volume_drift"].get<double>() == Approx(0.004));
    CHECK(s["scene"]["solver"]["scheme"] == "PC-unified");
    CHECK(s["scene"]["solver"]["backend"] == "explicit");
    CHECK(s["scene"]["solver"]["tolerance"] == 1e-7);
    CHECK(s["scene"]["time"]["frames"] == 4);
  }
}

TEST_CASE("run without rendering, with progress lines, and into the default folder", "[unit]") {
  const std::string scene = write_file("run2.json", kGood2);
  const fs::path out = temp_dir() / "norender";
  fs::remove_all(out);
  const Result r = fake_cli({"run", scene, "--out", out.string(), "--no-render"});
  REQUIRE(r.code == 0);
  CHECK_FALSE(fs::exists(out / "frames"));
  CHECK(read_jsonl(out / "stats.jsonl").size() == 4);
  // not a terminal: at most one progress line per frame
  CHECK(r.err.find("frame 1/3") != std::string::npos);
  CHECK(r.err.find("frame 3/3") != std::string::npos);
  CHECK(std::count(r.err.begin(), r.err.end(), '\n') <= 4);
  // render.enabled=false in the scene has the same effect
  fs::remove_all(out);
  CHECK(fake_cli({"run", scene, "--out", out.string(), "--set", "render.enabled=false", "--quiet"}).code == 0);
  CHECK_FALSE(fs::exists(out / "frames"));
  // frames of an earlier, longer run into the same folder are removed
  fs::remove_all(out);
  CHECK(fake_cli({"run", scene, "--out", out.string(), "--frames", "3", "--quiet"}).code == 0);
  CHECK(fs::exists(out / "frames" / "frame_00003.ppm"));
  CHECK(fake_cli({"run", scene, "--out", out.string(), "--frames", "1", "--quiet"}).code == 0);
  CHECK_FALSE(fs::exists(out / "frames" / "frame_00003.ppm"));
  CHECK(fs::exists(out / "frames" / "frame_00001.ppm"));
  // --flag=value is the same as --flag value
  fs::remove_all(out);
  CHECK(fake_cli({"run", scene, "--out=" + out.string(), "--frames=2", "--quiet", "--set=time.fps=20"}).code == 0);
  CHECK(read_jsonl(out / "stats.jsonl").size() == 3);
  CHECK(read_jsonl(out / "stats.jsonl")[2]["time"].get<double>() == Approx(0.1));
  // default folder out/<scene name>, relative to the working directory
  const fs::path cwd = fs::current_path();
  fs::current_path(temp_dir());
  const Result d = fake_cli({"run", scene, "--quiet", "--frames", "1"});
  fs::current_path(cwd);
  CHECK(d.code == 0);
  CHECK(fs::exists(temp_dir() / "out" / "cli-test" / "summary.json"));
  CHECK(fs::exists(temp_dir() / "out" / "cli-test" / "frames" / "frame_00001.ppm"));
}

TEST_CASE("a simulation failure exits with 3 and keeps what was written", "[unit]") {
  const std::string scene = write_file("fail.json", kGood2);
  const fs::path out = temp_dir() / "fail";
  fs::remove_all(out);
  const Result r = fake_cli({"run", scene, "--out", out.string(), "--frames", "5"}, 3);
  CHECK(r.code == 3);
  CHECK(r.err.find("failed at frame 3") != std::string::npos);
  CHECK(r.err.find("non-finite velocity") != std::string::npos);
  const auto stats = read_jsonl(out / "stats.jsonl");
  CHECK(stats.size() == 3);  // frames 0, 1, 2
  CHECK(fs::exists(out / "frames" / "frame_00002.ppm"));
  CHECK_FALSE(fs::exists(out / "frames" / "frame_00003.ppm"));
  std::ifstream in(out / "summary.json");
  const json s = json::parse(in);
  CHECK(s["status"] == "failed");
  CHECK(s["failed_frame"] == 3);
  CHECK(s["totals"]["frames"] == 2);
}

TEST_CASE("run accepts herschel-bulkley liquids and refuses unwritable output with exit 2", "[unit]") {
  json j = json::parse(kGood2);
  j["liquids"][0]["viscosity"] = {{"model", "herschel-bulkley"}, {"k", 1.0}, {"tau0", 5.0}};
  const std::string scene = write_file("hb.json", j.dump());
  const Result r = fake_cli({"run", scene, "--out", (temp_dir() / "hb").string(), "--frames", "1", "--quiet"});
  CHECK(r.code == 0);
  CHECK(r.err.find("herschel-bulkley") == std::string::npos);
  // an output path under a regular file cannot be created
  const std::string file = write_file("plain-file", "x");
  const std::string good = write_file("good.json", kGood2);
  CHECK(fake_cli({"run", good, "--out", file + "/sub", "--quiet"}).code == 2);
}

TEST_CASE("frame_stats_json has every key of the contract", "[unit]") {
  FrameStats st;
  st.frame = 7;
  st.bodies.push_back({"b", {1, 2}, {0.5}, {0, 0}, {0.1}});
  st.probes.push_back({"p", {0.5, 0.5}, {1, 2}, 3.0});
  st.solver.scheme = CouplingScheme::pc_vc_pc_unified;
  st.solver.dofs_pressure = 12;
  st.timing[FramePhase::total] = 0.5;
  st.timing[FramePhase::solve] = 0.25;
  st.timing[FramePhase::particles] = 0.125;
  st.potential_energy_liquid = -2.5;
  st.potential_energy_bodies = 4.0;
  st.line15_banked_energy = 0.75;
  st.max_penetration = std::numeric_limits<double>::quiet_NaN();
  const json j = frame_stats_json(st);
  CHECK(j["frame"] == 7);
  for (const char* k : {"lower", "upper"}) CHECK(j["liquid_bounds"].contains(k));
  for (const char* k : {"liquid", "bodies"}) CHECK(j["kinetic_energy"].contains(k));
  CHECK(j["potential_energy"]["liquid"] == -2.5);
  CHECK(j["potential_energy"]["bodies"] == 4.0);
  CHECK(j["line15_banked_energy"] == 0.75);
  for (const char* k : {"name", "position", "orientation", "velocity", "angular_velocity"}) CHECK(j["bodies"][0].contains(k));
  CHECK(j["contacts"]["count"] == 0);
  CHECK(j["contacts"]["max_penetration"].is_null());  // non-finite numbers become null
  for (const char* k : {"name", "position", "velocity", "pressure"}) CHECK(j["probes"][0].contains(k));
  for (const char* k : {"scheme", "iterations", "max_step_iterations", "staggered_iterations", "max_relative_residual", "converged", "dofs"})
    CHECK(j["solver"].contains(k));
  for (const char* k : {"pressure", "stress", "contact", "friction"}) CHECK(j["solver"]["dofs"].contains(k));
  CHECK(j["solver"]["dofs"]["pressure"] == 12);
  CHECK(j["solver"]["scheme"] == "PC-VC-PC-unified");  // the paper's name
  CHECK(j["timing"].size() == 7);
  CHECK(j["timing"]["total"] == 0.5);
  CHECK(j["timing"]["solve"] == 0.25);
  CHECK(j["timing"]["particles"] == 0.125);
  for (const char* k : {"weights", "extrapolation", "render", "output"}) CHECK(j["timing"][k] == 0.0);
  CHECK(j.dump().find('\n') == std::string::npos);  // one line
  // PC-/PVC-iterative rounds stopped at their cap: counted, and left out when 0
  CHECK_FALSE(j["solver"].contains("unsettled_steps"));
  st.solver.unsettled_steps = 3;
  CHECK(frame_stats_json(st)["solver"]["unsettled_steps"] == 3);
}

TEST_CASE("PC-iterative steps whose rounds stop at their cap are counted in stats.jsonl", "[unit]") {
  // A stack of three light boxes dropped into a tank (probe22's p05): from its fifth frame the
  // fluid-contact rounds of PC-iterative stop at solver.staggered_iterations (2) before
  // (lambda, x_f) settle. The inner solves converge, so the frames stay converged, but
  // "unsettled_steps" says how many of their steps ended at the cap; with rounds to spare no
  // step does.
  const std::string scene = write_file("stack.json", R"({
    "format": "monolith-scene/1", "name": "stack-into-water", "dim": 2,
    "domain": {"lower": [0, 0], "upper": [1.5, 1], "cells": [96, 64],
               "boundary": {"x-": "wall", "x+": "wall", "y-": "wall", "y+": "open"}, "wall_friction": 0.3},
    "time": {"fps": 30, "frames": 6},
    "solver": {"scheme": "PC-iterative"},
    "liquids": [{"shape": {"type": "box", "center": [0.75, 0.15], "half_size": [0.75, 0.15]}, "density": 1000}],
    "bodies": [
      {"shape": {"type": "box", "center": [0.75, 0.5], "half_size": [0.12, 0.05]}, "density": 800, "friction": 0.6},
      {"shape": {"type": "box", "center": [0.75, 0.6], "half_size": [0.1, 0.05]}, "density": 800, "friction": 0.6},
      {"shape": {"type": "box", "center": [0.75, 0.7], "half_size": [0.08, 0.05]}, "density": 800, "friction": 0.6}],
    "render": {"enabled": false}
  })");
  auto unsettled = [&](const std::string& rounds, const std::string& name) {
    const fs::path out = temp_dir() / name;
    const Result r = cli({"run", scene, "--out", out.string(), "--quiet", "--threads", "1", "--set",
                          "solver.staggered_iterations=" + rounds});
    REQUIRE(r.code == 0);
    long total = 0;
    for (const json& row : read_jsonl(out / "stats.jsonl")) {
      CHECK(row["solver"]["converged"] == true);
      if (row["solver"].contains("unsettled_steps")) {
        const long n = row["solver"]["unsettled_steps"];
        CHECK(n >= 1);
        CHECK(n <= row["steps"].get<long>());
        total += n;
      }
    }
    return total;
  };
  CHECK(unsettled("2", "stack-2") >= 1);
  CHECK(unsettled("100", "stack-100") == 0);
}

TEST_CASE("a document nested 10^5 deep is refused without memory to match its depth", "[unit]") {
  // The duplicate-key callback once kept a key path per level, each as long as the depth: this
  // input took 17.8 GB and 93 s before its refusal. The peak resident size of the process may
  // not grow by more than 256 MB (it grows by about 10 MB: the parser's own tree).
  auto peak_bytes = [] {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return static_cast<double>(u.ru_maxrss) * 1024.0;  // kilobytes on Linux
  };
  const double before = peak_bytes();
  const std::string path = write_file("deep.json", std::string(100000, '[') + std::string(100000, ']'));
  const Result r = cli({"check", path});
  CHECK(r.code == 2);
  CHECK(r.err.find("nested too deeply") != std::string::npos);
  CHECK(peak_bytes() - before < 256.0 * 1024 * 1024);
}

TEST_CASE("garbage input never crashes: exit 0 or 2", "[unit][property]") {
  std::mt19937 rng(12345);
  auto check_text = [&](const std::string& text) {
    const std::string path = write_file("fuzz.json", text);
    const Result r = cli({"check", path});
    const bool ok = r.code == 0 || r.code == 2;
    if (!ok) FAIL("exit " << r.code << " for input of " << text.size() << " bytes: " << r.err);
    if (r.code == 2) CHECK_FALSE(r.err.empty());
    return r.code;
  };
  int tried = 0;

  // random binary
  for (int i = 0; i < 30; ++i) {
    std::string s(rng() % 300, '\0');
    for (char& c : s) c = static_cast<char>(rng() % 256);
    CHECK(check_text(s) == 2);
    ++tried;
  }
  // truncated JSON: every 7th prefix of a valid scene
  const std::string full = json::parse(kGood2).dump();
  for (std::size_t n = 0; n < full.size(); n += 7) {
    CHECK(check_text(full.substr(0, n)) == 2);
    ++tried;
  }
  // deeply nested arrays, alone and inside a scene
  CHECK(check_text(std::string(100000, '[') + std::string(100000, ']')) == 2);
  CHECK(check_text(R"({"format": "monolith-scene/1", "dim": 2, "liquids": )" + std::string(50000, '[') +
                   std::string(50000, ']') + "}") == 2);
  // huge numbers and NaN-like strings
  for (const char* v : {"1e999", "-1e999", "1e308", "123456789012345678901234567890", "\"NaN\"", "\"Infinity\"",
                        "NaN", "-0", "4294967296", "2147483648"}) {
    const std::string text = json::parse(kGood2).dump();
    const std::vector<std::pair<std::string, std::string>> slots = {
        {"\"fps\":10", std::string("\"fps\":") + v},
        {"\"density\":1000", std::string("\"density\":") + v},
        {"\"cells\":[16,16]", std::string("\"cells\":[") + v + ",16]"}};
    for (const auto& [from, to] : slots) {
      const std::size_t at = text.find(from);
      REQUIRE(at != std::string::npos);
      std::string t = text;
      t.replace(at, from.size(), to);
      check_text(t);  // some of these are valid values (1e308 kg/m^3): only 0 or 2 is asserted
      ++tried;
    }
  }
  // wrong-typed everything: a few hundred random mutations of a valid scene
  const std::vector<json> pool = {nullptr, true, false, 0, -1, 1, 1.5, 1e308, -1e308, 1e30, 4294967296.0, "", "x", "NaN",
                                  "wall", "box", json::array(), json::object(), json::array({1, 2, 3}),
                                  json::array({0.5, 0.5}), json::object({{"type", "sphere"}}), json::array({"a", nullptr})};
  for (int m = 0; m < 400; ++m) {
    json j = json::parse(m % 2 ? kGood2 : kGood3);
    const int edits = 1 + static_cast<int>(rng() % 3);
    for (int e = 0; e < edits; ++e) {
      // walk to a random node
      json* node = &j;
      while (node->is_structured() && !node->empty() && rng() % 3 != 0) {
        auto it = node->begin();
        std::advance(it, rng() % node->size());
        node = &*it;
      }
      switch (rng() % 4) {
        case 0: *node = pool[rng() % pool.size()]; break;                      // replace the value
        case 1: if (node->is_object() && !node->empty()) node->erase(node->begin()); break;  // drop a key
        case 2: if (node->is_object()) (*node)["extra"] = pool[rng() % pool.size()]; break;  // unknown key
        default: if (node->is_array()) node->push_back(pool[rng() % pool.size()]); break;    // longer array
      }
    }
    check_text(j.dump());
    ++tried;
  }
  // random byte flips of the valid text
  for (int m = 0; m < 100; ++m) {
    std::string t = full;
    for (int e = 0; e < 3; ++e) t[rng() % t.size()] = static_cast<char>(rng() % 128);
    check_text(t);
    ++tried;
  }
  CHECK(tried > 500);
}

TEST_CASE("the built binary answers like the library (MONOLITH_BIN)", "[unit]") {
  const char* bin = std::getenv("MONOLITH_BIN");
  if (!bin || !fs::exists(bin)) {
    WARN("MONOLITH_BIN not set or missing: binary test skipped");
    CHECK(true);
    return;
  }
  const std::string out = (temp_dir() / "bin-version.txt").string();
  int status = std::system((std::string("\"") + bin + "\" --version > \"" + out + "\"").c_str());
  CHECK(WEXITSTATUS(status) == 0);
  std::ifstream in(out);
  std::string line;
  std::getline(in, line);
  CHECK(line == std::string("monolith ") + MONOLITH_VERSION);
  const std::string bad = write_file("bin-bad.json", "{\"format\": 1}");
  status = std::system((std::string("\"") + bin + "\" check \"" + bad + "\" 2> /dev/null").c_str());
  CHECK(WEXITSTATUS(status) == 2);
}

TEST_CASE("convert re-encodes a PPM as PNG and refuses bad input with 2", "[unit]") {
  const fs::path dir = temp_dir();
  Image img(12, 7, {10, 200, 30});
  img.write_ppm((dir / "in.ppm").string());
  const Result ok = cli({"convert", (dir / "in.ppm").string(), (dir / "out.png").string()});
  CHECK(ok.code == 0);
  REQUIRE(fs::exists(dir / "out.png"));
  CHECK(fs::file_size(dir / "out.png") > 12 * 7 * 3);
  CHECK(cli({"convert", (dir / "missing.ppm").string(), (dir / "x.png").string()}).code == 2);
  CHECK(cli({"convert", (dir / "in.ppm").string()}).code == 2);
  const std::string not_ppm = write_file("not_a_picture.ppm", "P3\n1 1\n255\n0 0 0\n");
  const Result bad = cli({"convert", not_ppm, (dir / "y.png").string()});
  CHECK(bad.code == 2);
  CHECK(bad.err.find("not_a_picture.ppm") != std::string::npos);
}
