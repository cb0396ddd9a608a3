/// \file oracle.cpp
/// `monolith export` and `monolith verify` (oracle.hpp, docs/oracle.md).

#include "reference/app/oracle.hpp"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <memory>
#include <sstream>

#include "reference/app/matrix_market.hpp"
#include "reference/app/scene_file.hpp"
#include "reference/core/errors.hpp"

namespace monolith {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

bool parse_count(const std::string& s, long long max, long long& out) {
  if (s.empty() || s.size() > 12) return false;
  for (char c : s)
    if (c < '0' || c > '9') return false;
  out = std::stoll(s);
  return out <= max;
}

/// The files of the export, in manifest order: the paper's objects, the blocks, A, b, x.
std::string file_of(const std::string& name) { return name + ".mtx"; }

json file_entry(const std::string& name, const std::string& equation, const std::string& meaning,
                long rows, long cols, long nonzeros, const char* kind) {
  json f;
  f["name"] = file_of(name);
  f["object"] = name;
  f["kind"] = kind;
  f["equation"] = equation;
  f["rows"] = rows;
  f["columns"] = cols;
  if (nonzeros >= 0) f["nonzeros"] = nonzeros;
  f["meaning"] = meaning;
  return f;
}

/// True when the manifest records that the reference x itself missed the tolerance.
bool manifest_reference_failed(const std::string& dir) {
  std::ifstream f(fs::path(dir) / "manifest.json");
  const json m = json::parse(f, nullptr, false);
  return m.is_object() && m.contains("x_check") && m["x_check"].is_object() &&
         m["x_check"].value("passed", true) == false;
}

}  // namespace

void write_system_export(const SystemExport& e, const std::string& dir, const json& context) {
  json files = json::array();
  try {
    for (const auto& m : e.matrices) {
      write_market_matrix((fs::path(dir) / file_of(m.name)).string(), m.value,
                          {m.name + ", eq. " + m.equation + ": " + m.meaning});
      files.push_back(file_entry(m.name, m.equation, m.meaning, m.value.rows(), m.value.cols(),
                                 m.value.nonZeros(), "matrix"));
    }
    for (const auto& v : e.vectors) {
      write_market_vector((fs::path(dir) / file_of(v.name)).string(), v.value,
                          {v.name + ", eq. " + v.equation + ": " + v.meaning});
      files.push_back(file_entry(v.name, v.equation, v.meaning, v.value.size(), 1, -1, "vector"));
    }
  } catch (const std::runtime_error& err) {
    throw InputError(std::string(err.what()) + " (a writable output folder)");
  }
  json m = context;
  m["format"] = "monolith-oracle/1";
  m["dim"] = e.dim;
  m["dx"] = e.dx;
  m["dt"] = e.dt;
  m["alpha"] = e.alpha;
  m["backend"] = e.backend;
  m["stress_form"] = e.stress_form;
  m["diagonal_boost"] = e.diagonal_boost;
  m["convention"] = "w = A x - b";
  m["conditions"] = {
      {"tau", "free: w = 0"},
      {"p", "free: w = 0"},
      {"lambda", "complementary: lambda >= 0, w >= 0, lambda w = 0"},
      {"z", "boxed: |z_k| <= mu_c lambda_c (c = rows.z.contact[k]); w_k = 0 inside the box, "
            "w_k <= 0 where z_k = +mu_c lambda_c, w_k >= 0 where z_k = -mu_c lambda_c"}};
  m["unknowns"] = {{"tau", e.num_tau}, {"p", e.num_p}, {"lambda", e.num_lambda}, {"z", e.num_z}};
  m["offsets"] = {{"tau", 0},
                  {"p", e.num_tau},
                  {"lambda", e.num_tau + e.num_p},
                  {"z", e.num_tau + e.num_p + e.num_lambda}};
  m["x_source"] = e.x_source;
  m["tolerance"] = e.tolerance;
  m["residual_scaling"] = e.jacobi_scaled ? "jacobi" : "none";
  m["backend_difference"] = e.backend_difference;
  m["x_check"] = {{"free_residual", e.x_check.free_residual},
                  {"complementarity", e.x_check.complementarity},
                  {"friction", e.x_check.friction},
                  {"bound_violation", e.x_check.bound_violation},
                  {"cone_violation", e.x_check.cone_violation},
                  {"passed", e.x_check.passed}};
  m["files"] = files;
  json rows;
  rows["tau"] = {{"component", e.tau_component}, {"name", e.tau_name}, {"location", e.tau_location},
                 {"stress_dof", e.tau_dof}, {"coord", e.tau_coord}};
  rows["p"] = {{"cell", e.p_cell}, {"coord", e.p_coord}};
  std::vector<double> mu(e.mu.data(), e.mu.data() + e.mu.size());
  rows["lambda"] = {{"body_a", e.contact_body_a}, {"body_b", e.contact_body_b},
                    {"wall_face", e.contact_wall_face}, {"mu", mu},
                    {"normal", e.contact_normal}, {"point", e.contact_point}};
  rows["z"] = {{"contact", e.z_contact}, {"direction", e.z_direction}, {"tangent", e.z_tangent}};
  m["rows"] = rows;
  const fs::path path = fs::path(dir) / "manifest.json";
  std::ofstream f(path, std::ios::trunc);
  f << std::setw(1) << m << "\n";
  f.close();
  if (!f) throw InputError(path.string() + ": cannot write (a writable output folder)");
}

int export_command(const std::vector<std::string>& args, std::ostream& out,
                   const SimulationFactory& factory) {
  std::string scene_name, out_dir;
  std::vector<std::string> overrides, problems;
  long long frame = -1, step = 1;
  for (std::size_t i = 0; i < args.size(); ++i) {
    std::string a = args[i], value;
    bool inline_value = false;
    if (a.rfind("--", 0) == 0 && a.find('=') != std::string::npos) {
      value = a.substr(a.find('=') + 1);
      a = a.substr(0, a.find('='));
      inline_value = true;
    }
    auto take = [&]() {
      if (inline_value) return true;
      if (i + 1 >= args.size()) {
        problems.push_back("export: " + a + ": missing value (see monolith --help)");
        return false;
      }
      value = args[++i];
      return true;
    };
    if (a == "--frame") {
      if (take() && (!parse_count(value, 100000000, frame) || frame < 1))
        problems.push_back("export: --frame: bad value \"" + value.substr(0, 40) + "\" (an integer >= 1)");
    } else if (a == "--step") {
      if (take() && (!parse_count(value, 100000000, step) || step < 1))
        problems.push_back("export: --step: bad value \"" + value.substr(0, 40) + "\" (an integer >= 1; 1 = the frame's first step)");
    } else if (a == "--out") {
      if (take()) out_dir = value;
    } else if (a == "--set") {
      if (take()) overrides.push_back(value);
    } else if (a.size() > 1 && a[0] == '-') {
      problems.push_back("export: unknown option \"" + args[i].substr(0, 80) + "\" (--frame, --step, --out, --set)");
    } else if (scene_name.empty()) {
      scene_name = a;
    } else {
      problems.push_back("export: unexpected argument \"" + a.substr(0, 80) + "\" (one SCENE only)");
    }
  }
  if (scene_name.empty()) problems.push_back("export: missing SCENE (a scene file or a built-in scene name; see monolith list)");
  if (frame < 0) problems.push_back("export: missing --frame N (the frame whose step is exported, 1 = the first)");
  if (out_dir.empty()) problems.push_back("export: missing --out DIR (the folder for the .mtx files and manifest.json)");
  if (!problems.empty()) throw InputError(problems);

  const SceneFile scene = load_scene(scene_name, overrides);
  const bool has_dynamic = std::any_of(scene.bodies.begin(), scene.bodies.end(),
                                       [](const BodySpec& b) { return b.motion == BodyMotion::dynamic; });
  if (scene.liquids.empty() || !has_dynamic)
    throw InputError(scene.source_label + ": no coupled system to export: eq. (24) needs a liquid and at least one dynamic body (the scene has " +
                     std::to_string(scene.liquids.size()) + " liquid(s) and " +
                     (has_dynamic ? std::string("dynamic bodies") : std::string("no dynamic body")) + ")");
  if (frame > scene.time.frames)
    throw InputError("export: --frame " + std::to_string(frame) + ": beyond the end of " + scene.source_label +
                     " (time.frames = " + std::to_string(scene.time.frames) + "; frames 1.." +
                     std::to_string(scene.time.frames) + " allowed)");
  // the output folder, checked before the simulation runs
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  const fs::path probe = fs::path(out_dir) / ".monolith-write-test";
  {
    std::ofstream f(probe);
    if (ec || !f) throw InputError(out_dir + ": (output): cannot create or write the folder (a writable output folder)");
  }
  fs::remove(probe, ec);

  auto sim = factory(scene);
  for (long long k = 1; k < frame; ++k) sim->advance_frame();
  std::unique_ptr<SystemExport> captured;
  sim->request_system_export(static_cast<int>(step), [&](const SystemExport& e) {
    captured = std::make_unique<SystemExport>(e);
  });
  const FrameStats st = sim->advance_frame();
  if (!captured) {
    if (step > st.steps)
      throw InputError("export: --step " + std::to_string(step) + ": frame " + std::to_string(frame) + " of " +
                       scene.source_label + " has " + std::to_string(st.steps) + " step(s) (1.." +
                       std::to_string(st.steps) + " allowed)");
    throw InputError("export: frame " + std::to_string(frame) + " step " + std::to_string(step) + " of " +
                     scene.source_label + " has no coupled solve to export (no moving body next to the liquid)");
  }
  json context;
  context["scene"] = scene.name;
  context["source"] = scene.source_label;
  context["frame"] = frame;
  context["step"] = step;
  context["steps_in_frame"] = st.steps;
  context["scheme"] = enum_name(scene.solver.scheme);
  json bodies = json::array();
  for (std::size_t i = 0; i < scene.bodies.size(); ++i)
    bodies.push_back({{"index", i}, {"name", scene.bodies[i].name}, {"motion", enum_name(scene.bodies[i].motion)}});
  context["bodies"] = bodies;
  write_system_export(*captured, out_dir, context);
  out << "wrote " << captured->matrices.size() + captured->vectors.size() << " Matrix Market files and manifest.json to "
      << out_dir << ": frame " << frame << " step " << step << " of " << scene.name << ", " << enum_name(scene.solver.scheme)
      << ", unknowns tau " << captured->num_tau << ", p " << captured->num_p << ", lambda " << captured->num_lambda
      << ", z " << captured->num_z << "\n";
  const SolutionCheck& c = captured->x_check;
  if (!c.passed)
    out << "note: x.mtx itself misses the tolerance " << captured->tolerance << " (free rows " << c.free_residual
        << ", complementarity " << c.complementarity << ", friction " << c.friction
        << "): the step stopped after solver.staggered_iterations friction rounds or its solver did not converge; "
           "raise solver.staggered_iterations (--set) for a tighter reference\n";
  return 0;
}

VerifyReport verify_solution(const std::string& dir, const std::string& candidate, double tolerance) {
  const fs::path base(dir);
  json manifest;
  {
    std::ifstream f(base / "manifest.json");
    if (!f) throw InputError((base / "manifest.json").string() + ": cannot read (a folder written by monolith export)");
    manifest = json::parse(f, nullptr, false);
    if (manifest.is_discarded() || !manifest.is_object() || !manifest.contains("unknowns"))
      throw InputError((base / "manifest.json").string() + ": not a manifest of monolith export");
  }
  int counts[4] = {0, 0, 0, 0};
  const char* names[4] = {"tau", "p", "lambda", "z"};
  try {
    for (int i = 0; i < 4; ++i) counts[i] = manifest.at("unknowns").at(names[i]).get<int>();
  } catch (const json::exception&) {
    throw InputError((base / "manifest.json").string() + ": unknowns: needs integer tau, p, lambda, z");
  }
  const bool jacobi = manifest.value("residual_scaling", std::string("none")) == "jacobi";
  if (tolerance <= 0.0) tolerance = manifest.value("tolerance", 0.0);
  if (!(tolerance > 0.0)) throw InputError((base / "manifest.json").string() + ": tolerance: missing (give --tolerance T)");
  SparseMatrix a;
  VectorX b, x_ref, mu, x;
  try {
    a = read_market_matrix((base / "A.mtx").string());
    b = read_market_vector((base / "b.mtx").string());
    x_ref = read_market_vector((base / "x.mtx").string());
    mu = read_market_vector((base / "mu.mtx").string());
    x = read_market_vector(candidate);
  } catch (const std::runtime_error& e) {
    throw InputError(e.what());
  }
  const long n = counts[0] + counts[1] + counts[2] + counts[3];
  if (a.rows() != n || a.cols() != n || b.size() != n || x_ref.size() != n || mu.size() != counts[2])
    throw InputError(dir + ": A.mtx, b.mtx, x.mtx, mu.mtx disagree with manifest.json's unknowns (" + std::to_string(n) + " rows)");
  if (x.size() != n)
    throw InputError(candidate + ": " + std::to_string(x.size()) + " values, the system has " + std::to_string(n) +
                     " unknowns (tau " + std::to_string(counts[0]) + ", p " + std::to_string(counts[1]) + ", lambda " +
                     std::to_string(counts[2]) + ", z " + std::to_string(counts[3]) + ")");
  VerifyReport r;
  r.check = check_solution(a, b, counts[0], counts[1], counts[2], counts[3], mu, x, x_ref, jacobi, tolerance);
  r.tolerance = tolerance;
  r.size = static_cast<int>(n);
  return r;
}

int verify_command(const std::vector<std::string>& args, std::ostream& out) {
  std::vector<std::string> positional, problems;
  double tolerance = 0.0;
  for (std::size_t i = 0; i < args.size(); ++i) {
    std::string a = args[i], value;
    if (a.rfind("--tolerance", 0) == 0) {
      if (a.size() > 11 && a[11] == '=')
        value = a.substr(12);
      else if (a.size() == 11 && i + 1 < args.size())
        value = args[++i];
      else {
        problems.push_back("verify: --tolerance: missing value (a positive number)");
        continue;
      }
      char* end = nullptr;
      tolerance = std::strtod(value.c_str(), &end);
      if (value.empty() || *end != '\0' || !(tolerance > 0.0) || !std::isfinite(tolerance))
        problems.push_back("verify: --tolerance: bad value \"" + value.substr(0, 40) + "\" (a positive number)");
    } else if (a.size() > 1 && a[0] == '-') {
      problems.push_back("verify: unknown option \"" + a.substr(0, 80) + "\" (--tolerance)");
    } else {
      positional.push_back(a);
    }
  }
  if (positional.size() != 2)
    problems.push_back("verify: expected DIR CANDIDATE.mtx (got " + std::to_string(positional.size()) + " arguments)");
  if (!problems.empty()) throw InputError(problems);
  const VerifyReport r = verify_solution(positional[0], positional[1], tolerance);
  const SolutionCheck& c = r.check;
  auto line = [&](const char* what, double v, bool judged) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "  %-28s %.3e%s\n", what, v,
                  judged ? (v <= r.tolerance ? "  ok" : "  FAILED") : "  (not judged)");
    out << buf;
  };
  out << "verify " << positional[1] << " against " << positional[0] << " (" << r.size
      << " unknowns, tolerance " << r.tolerance << "):\n";
  line("free-row residual", c.free_residual, true);
  line("complementarity (lambda)", c.complementarity, true);
  line("friction conditions (z)", c.friction, true);
  line("bound violation (lambda<0)", c.bound_violation, true);
  line("friction-cone violation", c.cone_violation, true);
  line("difference from x.mtx", c.difference, false);
  if (manifest_reference_failed(positional[0]))
    out << "  (x.mtx itself does not meet the tolerance: see manifest.json x_check)\n";
  out << (c.passed ? "passed\n" : "FAILED\n");
  return c.passed ? 0 : 1;
}

}  // namespace monolith
