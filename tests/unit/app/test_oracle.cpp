// Tests of the oracle commands (reference/app/oracle.cpp, matrix_market.cpp, docs/oracle.md):
// `monolith export` writes the step's system of eq. (24) so that reading it back gives the
// in-memory objects bit for bit (2D and 3D, explicit and matrix-free), A is the blocks A_ij put
// together, x meets the convention's conditions; `monolith verify` accepts x, rejects a
// perturbed x (exit 1), a mis-sized or garbled candidate (exit 2); bad input to export exits 2.
#include <catch2/catch.hpp>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>

#include "reference/app/cli.hpp"
#include "reference/app/matrix_market.hpp"
#include "reference/app/oracle.hpp"
#include "reference/app/scene_file.hpp"
#include "reference/sim/simulation.hpp"

using namespace monolith;
using nlohmann::json;
namespace fs = std::filesystem;

namespace {

/// Two boxes stacked on the floor of a pool (the lower one pressed slightly into the floor and
/// sliding, the upper one landing on it), a viscous liquid, friction and restitution; enough staggered rounds that
/// the friction conditions converge to the tolerance.
json stack_scene(int dim, const std::string& backend) {
  const bool d3 = dim == 3;
  auto vec = [&](double x, double y, double z) { return d3 ? json::array({x, y, z}) : json::array({x, y}); };
  json j = {
      {"format", "monolith-scene/1"},
      {"name", "oracle-stack-" + std::to_string(dim) + "d"},
      {"dim", dim},
      {"domain",
       {{"lower", vec(0, 0, 0)},
        {"upper", vec(1, 1, 1)},
        {"cells", d3 ? json::array({10, 10, 10}) : json::array({20, 20})},
        {"boundary", d3 ? json{{"x-", "wall"}, {"x+", "wall"}, {"y-", "wall"}, {"y+", "open"}, {"z-", "wall"}, {"z+", "wall"}}
                        : json{{"x-", "wall"}, {"x+", "wall"}, {"y-", "wall"}, {"y+", "open"}}},
        {"wall_friction", 0.4},
        {"wall_restitution", 0.5}}},
      {"time", {{"fps", 25}, {"frames", 3}, {"cfl", 3.0}, {"max_dt", 0.01}}},
      {"solver",
       {{"scheme", "PVC-unified"},
        {"backend", backend},
        {"tolerance", 1e-8},
        {"max_iterations", 4000},
        {"staggered_iterations", 200}}},
      {"liquids",
       json::array({{{"name", "water"},
                     {"shape", {{"type", "box"}, {"center", vec(0.5, 0.15, 0.5)}, {"half_size", vec(0.5, 0.15, 0.5)}}},
                     {"density", 1000},
                     {"viscosity", {{"model", "newtonian"}, {"eta", 1.0}}}}})},
      {"bodies",
       json::array({{{"name", "low"},
                     {"motion", "dynamic"},
                     {"shape", {{"type", "box"}, {"center", vec(0.4, d3 ? 0.045 : 0.054, 0.45)}, {"half_size", vec(0.14, 0.06, 0.14)}}},
                     {"density", 2000},
                     {"friction", 0.5},
                     {"restitution", 0.3},
                     {"velocity", vec(0.3, 0, 0)}},
                    {{"name", "top"},
                     {"motion", "dynamic"},
                     {"shape", {{"type", "box"}, {"center", vec(0.42, 0.2, 0.47)}, {"half_size", vec(0.08, 0.05, 0.08)}}},
                     {"density", 1500},
                     {"friction", 0.5},
                     {"restitution", 0.3},
                     {"velocity", vec(0, -1.5, 0)}}})},
      {"render", {{"enabled", false}}}};
  return j;
}

struct TempDir {
  fs::path path;
  explicit TempDir(const std::string& tag)
      : path(fs::temp_directory_path() / ("monolith_test_oracle_" + tag + "_" + std::to_string(::getpid()))) {
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

int cli(const std::vector<std::string>& args, std::string* out_text = nullptr, std::string* err_text = nullptr) {
  std::ostringstream out, err;
  const int rc = run_cli(args, out, err);
  if (out_text) *out_text = out.str();
  if (err_text) *err_text = err.str();
  return rc;
}

std::string write_scene(const TempDir& d, const json& j) {
  const fs::path p = d.path / "scene.json";
  std::ofstream(p) << j.dump(1);
  return p.string();
}

/// The in-memory SystemExport of frame `frame` step 1, from the simulation directly.
std::unique_ptr<SystemExport> capture(const json& scene_json, int frame) {
  const SceneFile scene = parse_scene(scene_json, "test", ".");
  auto sim = make_simulation(scene);
  for (int k = 1; k < frame; ++k) sim->advance_frame();
  std::unique_ptr<SystemExport> e;
  sim->request_system_export(1, [&](const SystemExport& s) { e = std::make_unique<SystemExport>(s); });
  sim->advance_frame();
  return e;
}

double max_abs_difference(const SparseMatrix& a, const SparseMatrix& b) {
  if (a.rows() != b.rows() || a.cols() != b.cols()) return std::numeric_limits<double>::infinity();
  const SparseMatrix d = a - b;
  double m = 0.0;
  for (int k = 0; k < d.outerSize(); ++k)
    for (SparseMatrix::InnerIterator it(d, k); it; ++it) m = std::max(m, std::abs(it.value()));
  return m;
}

void check_export_round_trip(int dim, const std::string& backend) {
  INFO(dim << "D " << backend);
  TempDir d(std::to_string(dim) + backend);
  const json scene = stack_scene(dim, backend);
  // 2D explicit: the top box lands on the lower one in frame 2; elsewhere frame 1 (the lower
  // box already rests on the floor)
  const std::unique_ptr<SystemExport> e = capture(scene, dim == 2 && backend == "explicit" ? 2 : 1);
  REQUIRE(e);
  CHECK(e->backend == backend);
  REQUIRE(e->num_tau > 0);
  REQUIRE(e->num_p > 0);
  REQUIRE(e->num_lambda > 0);
  CHECK(e->num_z == (dim - 1) * e->num_lambda);
  // the reference solution has active contacts with friction, and meets the conditions
  const VectorX lambda = e->x.segment(e->num_tau + e->num_p, e->num_lambda);
  CHECK(lambda.maxCoeff() > 0.0);
  CHECK(e->x.tail(e->num_z).cwiseAbs().maxCoeff() > 0.0);
  INFO("x itself: free " << e->x_check.free_residual << " compl " << e->x_check.complementarity << " friction "
                         << e->x_check.friction << " cone " << e->x_check.cone_violation);
  const double tol = e->tolerance;
  CHECK(e->x_check.free_residual <= tol);
  CHECK(e->x_check.complementarity <= tol);
  CHECK(e->x_check.bound_violation <= tol);
  CHECK(e->x_check.cone_violation <= tol);
  CHECK(e->x_check.friction <= tol);
  CHECK(e->x_check.passed);
  if (backend == "matrixfree") CHECK(e->backend_difference < 1e-12);

  // written and read back: every object bit for bit
  write_system_export(*e, d.path.string(), json{{"scene", "test"}});
  for (const auto& m : e->matrices) {
    INFO(m.name);
    const SparseMatrix back = read_market_matrix((d.path / (m.name + ".mtx")).string());
    CHECK(back.rows() == m.value.rows());
    CHECK(back.cols() == m.value.cols());
    CHECK(max_abs_difference(back, m.value) == 0.0);
  }
  for (const auto& v : e->vectors) {
    INFO(v.name);
    const VectorX back = read_market_vector((d.path / (v.name + ".mtx")).string());
    REQUIRE(back.size() == v.value.size());
    CHECK((back.array() == v.value.array()).all());
  }
  // A is the sixteen blocks put together, b the four right-hand sides
  const int size[4] = {e->num_tau, e->num_p, e->num_lambda, e->num_z};
  std::vector<Triplet> t;
  int r0 = 0;
  VectorX b(e->size());
  for (int i = 0; i < 4; ++i) {
    int c0 = 0;
    for (int j = 0; j < 4; ++j) {
      const SparseMatrix blk = read_market_matrix((d.path / ("A" + std::to_string(i + 1) + std::to_string(j + 1) + ".mtx")).string());
      REQUIRE(blk.rows() == size[i]);
      REQUIRE(blk.cols() == size[j]);
      for (int k = 0; k < blk.outerSize(); ++k)
        for (SparseMatrix::InnerIterator it(blk, k); it; ++it) t.emplace_back(r0 + it.row(), c0 + it.col(), it.value());
      c0 += size[j];
    }
    b.segment(r0, size[i]) = read_market_vector((d.path / ("b" + std::to_string(i + 1) + ".mtx")).string());
    r0 += size[i];
  }
  SparseMatrix blocks(e->size(), e->size());
  blocks.setFromTriplets(t.begin(), t.end());
  const SparseMatrix a = read_market_matrix((d.path / "A.mtx").string());
  CHECK(max_abs_difference(blocks, a) == 0.0);
  CHECK(max_abs_difference(a, SparseMatrix(a.transpose())) == 0.0);
  CHECK((b.array() == read_market_vector((d.path / "b.mtx").string()).array()).all());

  // the manifest says what every file and row is
  std::ifstream mf(d.path / "manifest.json");
  const json m = json::parse(mf);
  CHECK(m["convention"] == "w = A x - b");
  CHECK(m["unknowns"]["tau"] == e->num_tau);
  CHECK(m["unknowns"]["z"] == e->num_z);
  CHECK(m["dim"] == dim);
  CHECK(m["rows"]["tau"]["name"].size() == static_cast<std::size_t>(e->num_tau));
  CHECK(m["rows"]["p"]["cell"].size() == static_cast<std::size_t>(e->num_p));
  CHECK(m["rows"]["lambda"]["body_a"].size() == static_cast<std::size_t>(e->num_lambda));
  CHECK(m["rows"]["z"]["contact"].size() == static_cast<std::size_t>(e->num_z));
  for (const auto& f : m["files"]) {
    CHECK(fs::exists(d.path / f["name"].get<std::string>()));
    CHECK(f.contains("equation"));
    CHECK(f.contains("meaning"));
    CHECK(f["rows"].get<long>() >= 0);
  }
  // the headers and 17 significant digits
  std::ifstream af(d.path / "A.mtx"), xf(d.path / "x.mtx");
  std::string line;
  std::getline(af, line);
  CHECK(line == "%%MatrixMarket matrix coordinate real general");
  std::getline(xf, line);
  CHECK(line == "%%MatrixMarket matrix array real general");
  while (std::getline(xf, line) && (line[0] == '%' || line.find(' ') != std::string::npos)) {
  }
  const std::string mantissa = line.substr(0, line.find('e'));
  CHECK(std::count_if(mantissa.begin(), mantissa.end(), ::isdigit) == 17);

  // verify: x passes, a perturbed x fails
  const std::string dir = d.path.string(), x_path = (d.path / "x.mtx").string();
  std::string out;
  CHECK(cli({"verify", dir, x_path}, &out) == 0);
  std::ostringstream loose;
  loose << 10.0 * tol;
  CHECK(cli({"verify", dir, x_path, "--tolerance", loose.str()}, &out) == 0);
  INFO(out);
  VectorX perturbed = e->x;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < perturbed.size(); ++i) perturbed[i] += 1e-3 * e->x.cwiseAbs().maxCoeff() * u(rng);
  write_market_vector((d.path / "perturbed.mtx").string(), perturbed);
  CHECK(cli({"verify", dir, (d.path / "perturbed.mtx").string()}, &out) == 1);
  // only the fluid rows perturbed, relatively: still caught
  perturbed = e->x;
  perturbed.head(e->num_tau + e->num_p) *= 1.0 + 1e-3;
  write_market_vector((d.path / "perturbed_fluid.mtx").string(), perturbed);
  CHECK(cli({"verify", dir, (d.path / "perturbed_fluid.mtx").string()}, &out) == 1);
}

}  // namespace

TEST_CASE("export writes the step's system so that it reads back bit for bit; verify judges x, 2D",
          "[app][oracle]") {
  check_export_round_trip(2, "explicit");
  check_export_round_trip(2, "matrixfree");
}

TEST_CASE("export and verify in 3D, both back ends", "[app][oracle]") {
  check_export_round_trip(3, "matrixfree");
  check_export_round_trip(3, "explicit");
}

TEST_CASE("the export of the two back ends is the same system", "[app][oracle]") {
  // the first step: the same inputs (later steps differ by the round-off of earlier ones)
  const auto ex = capture(stack_scene(2, "explicit"), 1);
  const auto mf = capture(stack_scene(2, "matrixfree"), 1);
  REQUIRE(ex);
  REQUIRE(mf);
  REQUIRE(ex->size() == mf->size());
  const SparseMatrix& a = ex->matrix("A")->value;
  const double scale = a.coeffs().abs().maxCoeff();
  CHECK(max_abs_difference(a, mf->matrix("A")->value) <= 1e-10 * scale);
}

TEST_CASE("monolith export and verify: bad input exits 2 with a message", "[app][oracle]") {
  TempDir d("bad");
  const std::string scene = write_scene(d, stack_scene(2, "explicit"));
  const std::string out_dir = (d.path / "out").string();
  std::string out, err;
  // frame beyond the scene's end
  CHECK(cli({"export", scene, "--frame", "9", "--out", out_dir}, &out, &err) == 2);
  CHECK(err.find("beyond the end") != std::string::npos);
  // a step the frame does not have
  CHECK(cli({"export", scene, "--frame", "1", "--step", "500", "--out", out_dir}, &out, &err) == 2);
  CHECK(err.find("step") != std::string::npos);
  // missing --frame, unknown option, unknown scene
  CHECK(cli({"export", scene, "--out", out_dir}, &out, &err) == 2);
  CHECK(err.find("--frame") != std::string::npos);
  CHECK(cli({"export", scene, "--frame", "1", "--out", out_dir, "--bogus"}, &out, &err) == 2);
  CHECK(cli({"export", "no-such-scene", "--frame", "1", "--out", out_dir}, &out, &err) == 2);
  // an unwritable folder: a path under a regular file
  std::ofstream(d.path / "file") << "x";
  CHECK(cli({"export", scene, "--frame", "1", "--out", (d.path / "file" / "sub").string()}, &out, &err) == 2);
  CHECK(err.find("writable") != std::string::npos);
  // scenes without liquid or without bodies
  json dry = stack_scene(2, "explicit");
  dry["liquids"] = json::array();
  CHECK(cli({"export", write_scene(d, dry), "--frame", "1", "--out", out_dir}, &out, &err) == 2);
  CHECK(err.find("no coupled system") != std::string::npos);
  json bare = stack_scene(2, "explicit");
  bare["bodies"] = json::array();
  CHECK(cli({"export", write_scene(d, bare), "--frame", "1", "--out", out_dir}, &out, &err) == 2);
  CHECK(err.find("dynamic body") != std::string::npos);

  // verify: a good export, then mis-sized, garbled and missing candidates, a missing folder
  const std::string good = write_scene(d, stack_scene(2, "explicit"));
  REQUIRE(cli({"export", good, "--frame", "1", "--out", out_dir}, &out, &err) == 0);
  const VectorX x = read_market_vector(out_dir + "/x.mtx");
  write_market_vector((d.path / "short.mtx").string(), x.head(x.size() - 1));
  CHECK(cli({"verify", out_dir, (d.path / "short.mtx").string()}, &out, &err) == 2);
  CHECK(err.find("unknowns") != std::string::npos);
  std::ofstream(d.path / "garbled.mtx") << "%%MatrixMarket matrix array real general\n2 1\n1.0\nnot-a-number\n";
  CHECK(cli({"verify", out_dir, (d.path / "garbled.mtx").string()}, &out, &err) == 2);
  CHECK(err.find("garbled.mtx:4") != std::string::npos);
  std::ofstream(d.path / "header.mtx") << "hello\n";
  CHECK(cli({"verify", out_dir, (d.path / "header.mtx").string()}, &out, &err) == 2);
  CHECK(cli({"verify", out_dir, (d.path / "missing.mtx").string()}, &out, &err) == 2);
  CHECK(cli({"verify", (d.path / "nowhere").string(), out_dir + "/x.mtx"}, &out, &err) == 2);
  CHECK(cli({"verify", out_dir, out_dir + "/x.mtx", "--tolerance", "-1"}, &out, &err) == 2);
}

TEST_CASE("Matrix Market reader: entries out of range and wrong counts are errors", "[app][oracle]") {
  TempDir d("mm");
  const std::string p = (d.path / "m.mtx").string();
  std::ofstream(p) << "%%MatrixMarket matrix coordinate real general\n2 2 1\n3 1 1.0\n";
  CHECK_THROWS_WITH(read_market_matrix(p), Catch::Contains("outside the 2 x 2"));
  std::ofstream(p) << "%%MatrixMarket matrix coordinate real general\n2 2 2\n1 1 1.0\n";
  CHECK_THROWS_WITH(read_market_matrix(p), Catch::Contains("the size line says 2"));
  std::ofstream(p) << "%%MatrixMarket matrix coordinate real symmetric\n2 2 2\n1 1 1.0\n2 1 0.5\n";
  const SparseMatrix s = read_market_matrix(p);
  CHECK(s.coeff(0, 1) == 0.5);
  CHECK(s.coeff(1, 0) == 0.5);
}
