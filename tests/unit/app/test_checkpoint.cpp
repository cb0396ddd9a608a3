// Runs that survive (docs/checkpoints.md, docs/cli.md): checkpoints and `resume` continue bit for
// bit, SIGINT / SIGTERM stop cleanly with a checkpoint, damaged or foreign checkpoints are refused
// without touching the run folder, solves that do not converge are reported, outputs are atomic.
#include <catch2/catch.hpp>

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "reference/app/checkpoint.hpp"
#include "reference/app/cli.hpp"
#include "reference/core/errors.hpp"
#include "tests/support/cli_helpers.hpp"

extern char** environ;

using namespace monolith;
using nlohmann::json;
namespace fs = std::filesystem;

namespace {

fs::path temp_dir() {
  const fs::path d = fs::temp_directory_path() / ("monolith_test_checkpoint_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

using Result = test::CliResult;
using test::cli;

std::string read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

/// stats.jsonl parsed line by line (every line must be whole JSON), without the wall times:
/// `timing` and the seconds of solver.phases.
std::vector<json> stats_rows(const fs::path& dir) {
  std::vector<json> rows;
  std::ifstream in(dir / "stats.jsonl");
  std::string line;
  while (std::getline(in, line)) {
    REQUIRE_FALSE(in.eof());  // the file ends with a whole line
    json j = json::parse(line);
    j.erase("timing");
    if (j.contains("solver") && j["solver"].contains("phases"))
      for (auto& phase : j["solver"]["phases"]) phase.erase("seconds");
    rows.push_back(j);
  }
  return rows;
}

/// Every file of a run folder (frames, stats, summary, checkpoint) with its bytes.
std::map<std::string, std::string> folder_bytes(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) files[fs::relative(e.path(), dir).string()] = read_bytes(e.path());
  return files;
}

/// The two runs wrote the same rows (without wall times) and the same pictures for frames 0..n.
void check_same_run(const fs::path& a, const fs::path& b, int n) {
  const auto ra = stats_rows(a), rb = stats_rows(b);
  REQUIRE(ra.size() == static_cast<std::size_t>(n + 1));
  REQUIRE(rb.size() == ra.size());
  for (int k = 0; k <= n; ++k) {
    INFO("frame " << k);
    CHECK(ra[k] == rb[k]);
    char name[32];
    std::snprintf(name, sizeof name, "frame_%05d.ppm", k);
    REQUIRE(fs::exists(a / "frames" / name));
    CHECK(read_bytes(a / "frames" / name) == read_bytes(b / "frames" / name));
  }
}

json summary(const fs::path& dir) {
  std::ifstream in(dir / "summary.json");
  return json::parse(in);
}

/// Runs the built binary (MONOLITH_BIN) with args; returns its pid (stdout and stderr to files).
pid_t spawn_binary(const std::vector<std::string>& args, const fs::path& log) {
  const char* bin = std::getenv("MONOLITH_BIN");
  std::vector<std::string> all{bin};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, (log.string() + ".out").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&actions, 2, (log.string() + ".err").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, bin, &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  REQUIRE(rc == 0);
  return pid;
}

int wait_exit(pid_t pid) {
  int status = 0;
  REQUIRE(waitpid(pid, &status, 0) == pid);
  REQUIRE(WIFEXITED(status));  // an exit code, never death by a signal
  return WEXITSTATUS(status);
}

int run_binary(const std::vector<std::string>& args, const fs::path& log) { return wait_exit(spawn_binary(args, log)); }

std::size_t line_count(const fs::path& p) {
  std::ifstream in(p);
  return static_cast<std::size_t>(std::count(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>(), '\n'));
}

bool have_binary() {
  const char* bin = std::getenv("MONOLITH_BIN");
  return bin && fs::exists(bin);
}

/// A small version of a built-in scene: its own cells, small pictures.
std::vector<std::string> small(const std::string& scene, const std::string& cells) {
  return {scene, "--set", "domain.cells=" + cells, "--set", "render.size=[48,48]", "--quiet"};
}

/// `run` of a small version of a built-in scene with more flags after it.
std::vector<std::string> run_small(const std::string& scene, const std::string& cells,
                                   const std::vector<std::string>& more) {
  std::vector<std::string> args = small(scene, cells);
  args.insert(args.begin(), "run");
  args.insert(args.end(), more.begin(), more.end());
  return args;
}

}  // namespace

TEST_CASE("run N frames with checkpoints and resume to 2N: the same rows and frames as 2N straight", "[unit]") {
  struct Case {
    const char* scene;
    const char* cells;
    int settle_steps = 0;
  };
  // a liquid, a coupled scene with friction (and a viscous one), a non-Newtonian liquid; 2D and 3D;
  // a settled start (particles.settle_steps), which resume does not run again: the checkpoint's
  // state replaces what the settling steps would build
  const Case cases[] = {
      {"dam-break-2d", "[32,16]"},
      {"bunnies-onto-pool-2d", "[32,32]"},
      {"bunnies-into-floating-bowl-viscous-2d", "[32,32]"},
      {"liquid-drop-bingham-2d", "[24,24]"},
      {"dam-break-3d", "[16,8,8]"},
      {"bunnies-onto-pool-3d", "[12,12,12]"},
      {"liquid-drop-bingham-3d", "[12,12,12]"},
      {"bunnies-onto-pool-2d", "[32,32]", 4},
  };
  const int n = 2;
  for (const auto& c : cases) {
    INFO(c.scene << " settle_steps " << c.settle_steps);
    const std::string tag = std::string(c.scene) + (c.settle_steps > 0 ? "-settled" : "");
    const fs::path straight = temp_dir() / (tag + "-straight");
    const fs::path resumed = temp_dir() / (tag + "-resumed");
    fs::remove_all(straight);
    fs::remove_all(resumed);
    std::vector<std::string> a{"run"}, b{"run"};
    for (const auto& s : small(c.scene, c.cells)) {
      a.push_back(s);
      b.push_back(s);
    }
    if (c.settle_steps > 0)
      for (auto* v : {&a, &b}) v->insert(v->end(), {"--set", "particles.settle_steps=" + std::to_string(c.settle_steps)});
    a.insert(a.end(), {"--frames", std::to_string(2 * n), "--out", straight.string()});
    b.insert(b.end(), {"--frames", std::to_string(n), "--out", resumed.string(), "--checkpoint-every", std::to_string(n)});
    const Result ra = cli(a);
    INFO(ra.err);
    REQUIRE(ra.code == 0);
    const Result rb = cli(b);
    INFO(rb.err);
    REQUIRE(rb.code == 0);
    REQUIRE(fs::exists(checkpoint_path(resumed)));
    const Result rr = cli({"resume", resumed.string(), "--frames", std::to_string(2 * n), "--quiet"});
    INFO(rr.err);
    REQUIRE(rr.code == 0);
    check_same_run(straight, resumed, 2 * n);
    const json s = summary(resumed);
    CHECK(s["status"] == "completed");
    CHECK(s["totals"]["frames"] == 2 * n);
    CHECK(s["totals"]["steps"] == summary(straight)["totals"]["steps"]);
    CHECK(s["scene"]["time"]["frames"] == 2 * n);
  }
}

TEST_CASE("checkpoints every N frames: resume from the last one after a longer run was cut short", "[unit]") {
  // a run of 3 frames with a checkpoint every 2 (and at the end): the checkpoint is the end's
  const fs::path dir = temp_dir() / "every";
  fs::remove_all(dir);
  auto args = run_small("dam-break-2d", "[32,16]", {"--frames", "3", "--out", dir.string(), "--checkpoint-every", "2"});
  REQUIRE(cli(args).code == 0);
  // resuming a finished run with no more frames to go changes nothing and completes
  const auto before = stats_rows(dir);
  const Result r = cli({"resume", dir.string(), "--quiet"});
  CHECK(r.code == 0);
  CHECK(stats_rows(dir) == before);
  // --frames below the checkpoint's frame is refused
  const Result low = cli({"resume", dir.string(), "--frames", "1"});
  CHECK(low.code == 2);
  CHECK(low.err.find("--frames 1") != std::string::npos);
  // flags that would change the scene or folder are refused
  CHECK(cli({"resume", dir.string(), "--set", "gravity=[0,0]"}).code == 2);
  CHECK(cli({"run", "dam-break-2d", "--checkpoint-every", "0"}).code == 2);
  CHECK(cli({"resume"}).code == 2);
}

TEST_CASE("resume --any-build continues a checkpoint of another build, says so, and is refused for run", "[unit]") {
  // The "other build" is this build with the checkpoint's build id rewritten, so the state is
  // exactly what this build writes: the continuation must then equal the straight run, and the
  // only differences are the stderr line and summary.json's totals.earlier_build.
  const fs::path straight = temp_dir() / "any-build-straight";
  const fs::path resumed = temp_dir() / "any-build-resumed";
  fs::remove_all(straight);
  fs::remove_all(resumed);
  REQUIRE(cli(run_small("bunnies-onto-pool-2d", "[32,32]", {"--frames", "3", "--out", straight.string()})).code == 0);
  REQUIRE(cli(run_small("bunnies-onto-pool-2d", "[32,32]",
                        {"--frames", "1", "--out", resumed.string(), "--checkpoint-every", "1"}))
              .code == 0);
  const fs::path file = checkpoint_path(resumed);
  CheckpointRecord record = read_checkpoint(file);
  record.build_id = "0.0.0+another";
  write_checkpoint(file, record);

  // without the flag: refused, and the message names the flag
  const auto files = folder_bytes(resumed);
  const Result refused = cli({"resume", resumed.string(), "--frames", "3"});
  CHECK(refused.code == 2);
  CHECK(refused.err.find("another build") != std::string::npos);
  CHECK(refused.err.find("--any-build") != std::string::npos);
  CHECK(folder_bytes(resumed) == files);
  // the flag is resume's only, and takes no value
  CHECK(cli({"run", "dam-break-2d", "--any-build", "--frames", "0", "--out", (temp_dir() / "any-build-run").string()}).code == 2);
  CHECK(cli({"resume", resumed.string(), "--any-build=yes"}).code == 2);
  CHECK(folder_bytes(resumed) == files);

  // with it, even under --quiet: the line on stderr, the earlier build in the summary, the run
  // continued
  const Result r = cli({"resume", resumed.string(), "--frames", "3", "--any-build", "--quiet"});
  INFO(r.err);
  REQUIRE(r.code == 0);
  CHECK(r.err.find("0.0.0+another") != std::string::npos);
  CHECK(r.err.find("not bit for bit") != std::string::npos);
  check_same_run(straight, resumed, 3);
  const json s = summary(resumed);
  CHECK(s["status"] == "completed");
  CHECK(s["totals"]["earlier_build"] == "0.0.0+another");
  CHECK_FALSE(summary(straight)["totals"].contains("earlier_build"));
  // the checkpoint it wrote is this build's again: a plain resume takes it, with no earlier build
  CHECK(read_checkpoint(file).build_id == build_id());
  const Result again = cli({"resume", resumed.string(), "--frames", "4", "--quiet"});
  INFO(again.err);
  REQUIRE(again.code == 0);
  CHECK(again.err.find("another build") == std::string::npos);
  CHECK_FALSE(summary(resumed)["totals"].contains("earlier_build"));
}

TEST_CASE("damaged, truncated, foreign or missing checkpoints are refused with 2 and nothing is overwritten", "[unit]") {
  const fs::path dir = temp_dir() / "damaged";
  const fs::path other = temp_dir() / "other-scene";
  fs::remove_all(dir);
  fs::remove_all(other);
  auto args = run_small("dam-break-2d", "[32,16]", {"--frames", "2", "--out", dir.string(), "--checkpoint-every", "1"});
  REQUIRE(cli(args).code == 0);
  auto other_args = run_small("liquid-drop-bingham-2d", "[24,24]", {"--frames", "1", "--out", other.string(), "--checkpoint-every", "1"});
  REQUIRE(cli(other_args).code == 0);
  const fs::path file = checkpoint_path(dir);
  const std::string good = read_bytes(file);
  REQUIRE(good.size() > 1000);

  auto refused = [&](const std::string& bytes, const std::string& message) {
    std::ofstream(file, std::ios::binary | std::ios::trunc) << bytes;
    const auto files = folder_bytes(dir);
    const Result r = cli({"resume", dir.string(), "--frames", "4", "--quiet"});
    INFO(r.err);
    CHECK(r.code == 2);
    CHECK(r.err.find(message) != std::string::npos);
    CHECK(r.err.find(file.string()) != std::string::npos);
    CHECK(folder_bytes(dir) == files);  // nothing overwritten, nothing added
  };
  SECTION("a flipped byte in the state") {
    std::string bad = good;
    bad[bad.size() / 2] ^= 0x10;
    refused(bad, "corrupted");
  }
  SECTION("cut short") { refused(good.substr(0, good.size() - 100), "truncated"); }
  SECTION("only the header") { refused(good.substr(0, 20), "not a monolith checkpoint"); }
  SECTION("not a checkpoint") { refused("{\"format\": 1}", "not a monolith checkpoint"); }
  SECTION("another scene's checkpoint in this run's folder") {
    refused(read_bytes(checkpoint_path(other)), "another scene");
  }
  SECTION("an older format version") {
    // version 5 (before the frame's largest step count joined the step statistics), the rest of
    // the file as it was
    std::string old = good;
    const std::uint32_t version = 5;
    std::memcpy(&old[8], &version, 4);
    refused(old, "checkpoint format version 5 (this build reads version 7");
  }
  SECTION("written by another build") {
    CheckpointRecord record = read_checkpoint(file);
    record.build_id = "0.0.0+another";
    write_checkpoint(file, record);
    refused(read_bytes(file), "another build");
  }
  SECTION("none") {
    fs::remove(file);
    const Result r = cli({"resume", dir.string()});
    CHECK(r.code == 2);
    CHECK(r.err.find("no checkpoint") != std::string::npos);
  }
  SECTION("the scene file changed since the checkpoint") {
    const fs::path scene = temp_dir() / "changing.json";
    const fs::path run = temp_dir() / "changing";
    fs::remove_all(run);
    json j = json::parse(R"({"format": "monolith-scene/1", "name": "changing", "dim": 2,
      "domain": {"lower": [0, 0], "upper": [1, 1], "cells": [16, 16]}, "time": {"fps": 20},
      "liquids": [{"shape": {"type": "box", "center": [0.5, 0.3], "half_size": [0.2, 0.2]}, "density": 1000}],
      "render": {"enabled": false}})");
    std::ofstream(scene) << j.dump();
    REQUIRE(cli({"run", scene.string(), "--frames", "1", "--out", run.string(), "--checkpoint-every", "1", "--quiet"}).code == 0);
    j["liquids"][0]["density"] = 900;
    std::ofstream(scene, std::ios::trunc) << j.dump();
    const auto files = folder_bytes(run);
    const Result r = cli({"resume", run.string(), "--frames", "2"});
    CHECK(r.code == 2);
    CHECK(r.err.find("changed since the checkpoint") != std::string::npos);
    CHECK(folder_bytes(run) == files);
  }
  SECTION("a mesh file the scene reads changed since the checkpoint") {
    const fs::path scene = temp_dir() / "mesh-scene.json";
    const fs::path mesh = temp_dir() / "block.obj";
    const fs::path run = temp_dir() / "mesh-run";
    fs::remove_all(run);
    const std::string cube =
        "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n"
        "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
    std::ofstream(mesh) << cube;
    const json j = json::parse(R"({"format": "monolith-scene/1", "name": "mesh-scene", "dim": 3,
      "domain": {"lower": [0, 0, 0], "upper": [1, 1, 1], "cells": [8, 8, 8]}, "time": {"fps": 20},
      "liquids": [{"shape": {"type": "box", "center": [0.5, 0.7, 0.5], "half_size": [0.2, 0.1, 0.2]}, "density": 1000}],
      "bodies": [{"name": "block", "motion": "static",
                  "shape": {"type": "mesh", "file": "block.obj", "scale": 0.15, "translate": [0.5, 0.2, 0.5]}}],
      "render": {"enabled": false}})");
    std::ofstream(scene) << j.dump();
    REQUIRE(cli({"run", scene.string(), "--frames", "1", "--out", run.string(), "--checkpoint-every", "1", "--quiet"}).code == 0);
    // the scene file itself is unchanged; its mesh grows
    std::string bigger = cube;
    bigger.replace(bigger.find("v 1 1 1"), 7, "v 1 2 1");
    std::ofstream(mesh, std::ios::trunc) << bigger;
    const auto files = folder_bytes(run);
    const Result r = cli({"resume", run.string(), "--frames", "2"});
    INFO(r.err);
    CHECK(r.code == 2);
    CHECK(r.err.find("block.obj") != std::string::npos);
    CHECK(r.err.find("changed") != std::string::npos);
    CHECK(folder_bytes(run) == files);
    // put back, the run continues
    std::ofstream(mesh, std::ios::trunc) << cube;
    CHECK(cli({"resume", run.string(), "--frames", "2", "--quiet"}).code == 0);
  }
}

TEST_CASE("SIGINT and SIGTERM stop a run with a checkpoint; resume finishes it like a straight run", "[unit]") {
  if (!have_binary()) {
    WARN("MONOLITH_BIN not set or missing: signal test skipped");
    return;
  }
  const auto scene = small("bunnies-into-floating-bowl-viscous-2d", "[32,32]");
  const fs::path straight = temp_dir() / "sig-straight";
  fs::remove_all(straight);
  std::vector<std::string> a{"run"};
  a.insert(a.end(), scene.begin(), scene.end());
  a.insert(a.end(), {"--frames", "10", "--out", straight.string()});
  REQUIRE(run_binary(a, temp_dir() / "sig-straight") == 0);

  for (const int sig : {SIGINT, SIGTERM}) {
    INFO("signal " << sig);
    const fs::path dir = temp_dir() / ("sig-" + std::to_string(sig));
    fs::remove_all(dir);
    std::vector<std::string> b{"run"};
    b.insert(b.end(), scene.begin(), scene.end());
    b.insert(b.end(), {"--frames", "10", "--out", dir.string()});
    const pid_t pid = spawn_binary(b, dir.string() + "-log");
    // wait for frame 2, then signal (the run stops at the next step boundary, often inside a frame)
    for (int k = 0; k < 6000 && line_count(dir / "stats.jsonl") < 3; ++k)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    REQUIRE(::kill(pid, sig) == 0);
    const int code = wait_exit(pid);
    CHECK(code == 128 + sig);
    const json s = summary(dir);
    CHECK(s["status"] == "interrupted");
    CHECK(s["message"].get<std::string>().find(sig == SIGINT ? "SIGINT" : "SIGTERM") != std::string::npos);
    const auto rows = stats_rows(dir);  // parses line by line, whole lines only
    CHECK(rows.size() >= 3);
    CHECK(s["totals"]["frames"] == static_cast<int>(rows.size()) - 1);
    REQUIRE(fs::exists(checkpoint_path(dir)));
    for (const auto& e : fs::recursive_directory_iterator(dir)) CHECK(e.path().extension() != ".tmp");
    if (code != 128 + sig) continue;
    REQUIRE(run_binary({"resume", dir.string(), "--quiet"}, dir.string() + "-resume") == 0);
    check_same_run(straight, dir, 10);
    CHECK(summary(dir)["status"] == "completed");
  }
}

TEST_CASE("a solve that stops at max_iterations is reported per frame, even with --quiet", "[unit]") {
  const fs::path dir = temp_dir() / "unconverged";
  fs::remove_all(dir);
  auto args = run_small("dam-break-2d", "[32,16]", {"--frames", "2", "--out", dir.string(), "--set", "solver.max_iterations=3"});
  Result r = cli(args);
  CHECK(r.code == 0);
  // one line per frame: the frame, the solve, its iterations and the residual reached
  CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 2);
  CHECK(r.err.find("frame 1: solver did not converge: pressure solve") != std::string::npos);
  CHECK(r.err.find("frame 2: solver did not converge") != std::string::npos);
  CHECK(r.err.find("after 3 iterations at relative residual") != std::string::npos);
  auto rows = stats_rows(dir);
  REQUIRE(rows.size() == 3);
  CHECK(rows[0]["solver"]["converged"] == true);
  CHECK(rows[1]["solver"]["converged"] == false);
  CHECK(summary(dir)["status"] == "completed");
  // a converged run prints nothing with --quiet
  auto ok = run_small("dam-break-2d", "[32,16]", {"--frames", "1", "--out", dir.string()});
  r = cli(ok);
  CHECK(r.code == 0);
  CHECK(r.err.empty());
  // "fail": exit 3 after the frame's outputs, the reason in summary.json
  args.insert(args.end(), {"--set", "solver.on_nonconvergence=fail"});
  r = cli(args);
  CHECK(r.code == 3);
  rows = stats_rows(dir);
  CHECK(rows.size() == 2);  // frames 0 and 1
  CHECK(fs::exists(dir / "frames" / "frame_00001.ppm"));
  const json s = summary(dir);
  CHECK(s["status"] == "failed");
  CHECK(s["failed_frame"] == 1);
  CHECK(s["message"].get<std::string>().find("did not converge") != std::string::npos);
  // coupled scenes name the coupled solve
  auto coupled = run_small("bunnies-onto-pool-2d", "[32,32]", {"--frames", "1", "--out", dir.string(), "--set", "solver.max_iterations=2"});
  r = cli(coupled);
  CHECK(r.code == 0);
  CHECK(r.err.find("frame 1: solver did not converge: coupled PC-unified solve") != std::string::npos);
  // an unknown policy is refused with the allowed names
  r = cli({"check", "dam-break-2d", "--set", "solver.on_nonconvergence=ignore"});
  CHECK(r.code == 2);
  CHECK(r.err.find("solver.on_nonconvergence") != std::string::npos);
  CHECK(r.err.find("\"warn\", \"fail\"") != std::string::npos);
}

TEST_CASE("outputs are written whole or not at all; write failures name the path", "[unit]") {
  // an atomic write into a missing folder: OutputError with the path, no temporary left
  const fs::path missing = temp_dir() / "no-such-folder" / "x.json";
  try {
    write_file_atomic(missing, "{}");
    FAIL("no error");
  } catch (const OutputError& e) {
    CHECK(std::string(e.what()).find(missing.string()) != std::string::npos);
  }
  CHECK_FALSE(fs::exists(missing.string() + ".tmp"));
  // a full device: the line is not appended (and the error names the file)
  if (fs::exists("/dev/full")) {
    LineFile full("/dev/full", false);
    try {
      full.append_line("{\"frame\": 0}");
      FAIL("no error");
    } catch (const OutputError& e) {
      CHECK(std::string(e.what()).find("/dev/full") != std::string::npos);
    }
  }
  // a frame that cannot be written mid-run: exit 3, the path in the message, whole stats lines
  const fs::path dir = temp_dir() / "blocked";
  fs::remove_all(dir);
  fs::create_directories(dir / "frames" / "frame_00002.ppm.tmp");  // a folder where the file goes
  auto args = run_small("dam-break-2d", "[32,16]", {"--frames", "3", "--out", dir.string()});
  const Result r = cli(args);
  CHECK(r.code == 3);
  CHECK(r.err.find("frame_00002.ppm") != std::string::npos);
  const json s = summary(dir);
  CHECK(s["status"] == "failed");
  CHECK(s["failed_frame"] == 2);
  CHECK(stats_rows(dir).size() == 3);  // frame 2's row was written before its picture
  CHECK(fs::exists(dir / "frames" / "frame_00001.ppm"));
}
