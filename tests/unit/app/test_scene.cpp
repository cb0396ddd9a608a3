// Tests of scene parsing and validation (reference/app/scene.cpp, docs/scene-format.md).
#include <catch2/catch.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <unistd.h>

#include "reference/app/embedded_scenes.hpp"
#include "reference/app/scene_file.hpp"
#include "reference/core/errors.hpp"

using namespace monolith;
using nlohmann::json;

namespace {

const char* kBase2 = R"({
  "format": "monolith-scene/1", "name": "t", "dim": 2,
  "domain": {"lower": [0, 0], "upper": [1, 1], "cells": [16, 16]},
  "liquids": [{"shape": {"type": "box", "center": [0.5, 0.3], "half_size": [0.2, 0.2]}, "density": 1000}],
  "bodies": [{"motion": "static", "shape": {"type": "sphere", "center": [0.5, 0.8], "radius": 0.1}}],
  "probes": [{"position": [0.5, 0.5]}]
})";

const char* kBase3 = R"({
  "format": "monolith-scene/1", "name": "t3", "dim": 3,
  "domain": {"lower": [0, 0, 0], "upper": [1, 1, 1], "cells": [8, 8, 8]},
  "liquids": [{"shape": {"type": "box", "center": [0.5, 0.3, 0.5], "half_size": [0.2, 0.2, 0.2]}, "density": 1000}],
  "bodies": [{"motion": "static", "shape": {"type": "sphere", "center": [0.5, 0.8, 0.5], "radius": 0.1}}],
  "probes": [{"position": [0.5, 0.5, 0.5]}]
})";

/// One bad input: a JSON merge patch applied to a valid base scene (base 2 or 3), or a raw
/// document (base 0), and the key path its error message must name.
struct BadCase {
  int base;
  const char* text;
  const char* path;
};

const BadCase kBadCases[] = {
    // syntax and root
    {0, R"({"format": "monolith-scene/1", "dim": )", "(json)"},
    {0, R"([1, 2, 3])", "(root)"},
    {0, R"({"format": "monolith-scene/1", "dim": 2, "gravity": [0, -1e999],
            "domain": {"lower": [0, 0], "upper": [1, 1], "cells": [4, 4]}})", "(json)"},
    // a key given twice in one object (probe22): the later value would win without a word
    {0, R"({"format": "monolith-scene/1", "dim": 2, "domain": {"lower": [0, 0], "upper": [1, 1], "cells": [4, 4]},
            "bodies": [{"motion": "static", "shape": {"type": "sphere", "center": [0.5, 0.5], "radius": 0.1}},
                       {"motion": "static", "shape": {"type": "sphere", "center": [0.5, 0.5], "radius": 0.1, "radius": 0.2}}]})",
     "bodies[1].shape.radius"},
    {0, R"({"format": "monolith-scene/1", "dim": 2, "dim": 3})", "dim"},
    {2, R"({"gravity": [0, "NaN"]})", "gravity[1]"},
    {2, R"({"gravty": [0, -9.81]})", "gravty"},
    {2, R"({"name": ""})", "name"},
    // format and dim
    {2, R"({"format": "monolith-scene/2"})", "format"},
    {2, R"({"format": null})", "format"},
    {2, R"({"dim": 4})", "dim"},
    {2, R"({"dim": "2"})", "dim"},
    // domain
    {2, R"({"domain": {"cells": [0, 16]}})", "domain.cells[0]"},
    {2, R"({"domain": {"cells": [16]}})", "domain.cells"},
    {2, R"({"domain": {"cells": [16.5, 16]}})", "domain.cells[0]"},
    {2, R"({"domain": {"upper": [1, 2]}})", "domain.cells"},
    {2, R"({"domain": {"lower": [0, 0, 0]}})", "domain.lower"},
    {2, R"({"domain": {"upper": [0, 1]}})", "domain.upper[0]"},
    {2, R"({"domain": {"lower": null}})", "domain.lower"},
    {2, R"({"domain": {"boundary": {"x-": "periodic"}}})", "domain.boundary.x+"},
    {2, R"({"domain": {"boundary": {"y+": "sticky"}}})", "domain.boundary.y+"},
    {2, R"({"domain": {"boundary": {"z-": "wall"}}})", "domain.boundary.z-"},
    {2, R"({"domain": {"wall_friction": -1}})", "domain.wall_friction"},
    {2, R"({"domain": {"wall_restitution": 1.5}})", "domain.wall_restitution"},
    {2, R"({"domain": {"cells": [100000, 100000], "upper": [1, 1]}})", "domain.cells"},
    {2, R"({"domain": {"cells": [20000, 20000]}})", "domain.cells"},
    // gravity and time
    {2, R"({"gravity": [0, -9.81, 0]})", "gravity"},
    {2, R"({"time": {"fps": 0}})", "time.fps"},
    {2, R"({"time": {"frames": -1}})", "time.frames"},
    {2, R"({"time": {"cfl": -3}})", "time.cfl"},
    {2, R"({"time": {"max_dt": 0}})", "time.max_dt"},
    {2, R"({"time": 5})", "time"},
    // solver
    {2, R"({"solver": {"tolerance": 1}})", "solver.tolerance"},
    {2, R"({"solver": {"tolerence": 1e-6}})", "solver.tolerence"},
    {2, R"({"solver": {"scheme": "PVC"}})", "solver.scheme"},
    {2, R"({"solver": {"backend": "gpu"}})", "solver.backend"},
    {2, R"({"solver": {"preconditioner": "amg"}})", "solver.preconditioner"},
    {2, R"({"solver": {"max_iterations": 0}})", "solver.max_iterations"},
    {2, R"({"solver": {"contact_margin": -0.1}})", "solver.contact_margin"},
    // particles and render
    {2, R"({"particles": {"per_cell": 65}})", "particles.per_cell"},
    {2, R"({"particles": {"seed": -1}})", "particles.seed"},
    {2, R"({"particles": {"position_correction": "yes"}})", "particles.position_correction"},
    {2, R"({"particles": {"settle_steps": -1}})", "particles.settle_steps"},
    {2, R"({"particles": {"settle_steps": 2.5}})", "particles.settle_steps"},
    {2, R"({"render": {"size": [8, 512]}})", "render.size[0]"},
    {2, R"({"render": {"color_by": "rainbow"}})", "render.color_by"},
    {2, R"({"render": {"enabled": "true"}})", "render.enabled"},
    // liquids
    {2, R"({"liquids": {"shape": {}}})", "liquids"},
    {2, R"({"liquids": [{"shape": {"type": "box", "center": [0.5, 0.3], "half_size": [0.2, 0.2]}}]})", "liquids[0].density"},
    {2, R"({"liquids": [{"shape": {"type": "box", "center": [0.5, 0.3], "half_size": [0.2, 0.2]}, "density": -5}]})", "liquids[0].density"},
    {2, R"({"liquids": [{"shape": {"type": "box", "center": [0.5, 0.3], "half_size": [0.2, -0.1]}, "density": 1}]})", "liquids[0].shape.half_size[1]"},
    {2, R"({"liquids": [{"shape": {"type": "box", "center": [5, 5], "half_size": [0.2, 0.2]}, "density": 1}]})", "liquids[0].shape"},
    {2, R"({"liquids": [{"shape": {"type": "cube", "center": [0.5, 0.3]}, "density": 1}]})", "liquids[0].shape.type"},
    {2, R"({"liquids": [{"shape": {"type": "sphere", "center": [0.5, 0.3], "radius": 0.1}, "density": 1,
                          "viscosity": {"model": "bingham"}}]})", "liquids[0].viscosity.model"},
    {2, R"({"liquids": [{"shape": {"type": "sphere", "center": [0.5, 0.3], "radius": 0.1}, "density": 1,
                          "viscosity": {"model": "newtonian", "k": 1}}]})", "liquids[0].viscosity.k"},
    {2, R"({"liquids": [{"shape": {"type": "sphere", "center": [0.5, 0.3], "radius": 0.1}, "density": 1,
                          "angular_velocity": [1]}]})", "liquids[0].angular_velocity"},
    {2, R"({"liquids": [{"name": "w", "shape": {"type": "sphere", "center": [0.5, 0.3], "radius": 0.1}, "density": 1},
                        {"name": "w", "shape": {"type": "sphere", "center": [0.3, 0.3], "radius": 0.1}, "density": 1}]})",
     "liquids[1].name"},
    {3, R"({"liquids": [{"shape": {"type": "sphere", "center": [0.5, 0.3, 0.5], "radius": 0.1}, "density": 1,
                          "angular_velocity": 2.0}]})", "liquids[0].angular_velocity"},
    // bodies
    {2, R"({"bodies": [{"shape": {"type": "sphere", "center": [0.5, 0.8], "radius": 0.1}}]})", "bodies[0].density"},
    {2, R"({"bodies": [{"motion": "static", "restitution": 2, "shape": {"type": "sphere", "center": [0.5, 0.8], "radius": 0.1}}]})", "bodies[0].restitution"},
    {2, R"({"bodies": [{"motion": "static", "friction": -0.1, "shape": {"type": "sphere", "center": [0.5, 0.8], "radius": 0.1}}]})", "bodies[0].friction"},
    {2, R"({"bodies": [{"motion": "floating", "shape": {"type": "sphere", "center": [0.5, 0.8], "radius": 0.1}}]})", "bodies[0].motion"},
    {2, R"({"bodies": [{"motion": "kinematic", "density": 1, "shape": {"type": "sphere", "center": [0.5, 0.8], "radius": 0.1}}]})", "bodies[0].path"},
    {2, R"({"bodies": [{"motion": "static", "shape": {"type": "sphere", "center": [0.5, 0.8], "radius": 0.1},
                        "path": {"axis": [1, 0], "amplitude": 0.1, "frequency": 1}}]})", "bodies[0].path"},
    {2, R"({"bodies": [{"motion": "kinematic", "density": 1, "shape": {"type": "sphere", "center": [0.5, 0.8], "radius": 0.1},
                        "path": {"axis": [0, 0], "amplitude": 0.1, "frequency": 1}}]})", "bodies[0].path.axis"},
    {2, R"({"bodies": [{"motion": "static", "shape": {"type": "bowl", "center": [0.5, 0.8], "radius": 0.1, "thickness": 0.1}}]})", "bodies[0].shape.thickness"},
    {2, R"({"bodies": [{"motion": "static", "shape": {"type": "sphere", "center": [0.5, 0.8], "radius": 0}}]})", "bodies[0].shape.radius"},
    {2, R"({"bodies": [{"motion": "static", "shape": {"type": "halfspace", "normal": [0, 0], "offset": 0.1}}]})", "bodies[0].shape.normal"},
    {2, R"({"bodies": [{"motion": "static", "shape": {"type": "polygon", "points": [[0, 0], [1, 1]]}}]})", "bodies[0].shape.points"},
    // a body that moves needs a finite volume: `check` refuses what `run` refused (probe22)
    {2, R"({"bodies": [{"density": 500, "shape": {"type": "halfspace", "normal": [0, 1], "offset": 0.1}}]})", "bodies[0].shape"},
    {3, R"({"bodies": [{"motion": "kinematic", "density": 500, "path": {"axis": [1, 0, 0], "amplitude": 0.1, "frequency": 1},
                        "shape": {"type": "union", "shapes": [{"type": "sphere", "center": [0.5, 0.5, 0.5], "radius": 0.1},
                                                              {"type": "halfspace", "normal": [0, 1, 0], "offset": 0.1}]}}]})",
     "bodies[0].shape"},
    {2, R"({"bodies": [{"motion": "static", "shape": {"type": "mesh", "file": "a.obj"}}]})", "bodies[0].shape.type"},
    {2, R"({"bodies": [{"motion": "static", "shape": {"type": "union", "shapes": []}}]})", "bodies[0].shape.shapes"},
    {2, R"({"bodies": [{"motion": "static", "shape": {"type": "sphere", "center": [0.5, 0.8], "radius": 0.1, "radis": 1}}]})", "bodies[0].shape.radis"},
    {3, R"({"bodies": [{"motion": "static", "shape": {"type": "polygon", "points": [[0, 0], [1, 0], [0, 1]]}}]})", "bodies[0].shape.type"},
    {3, R"({"bodies": [{"motion": "static", "shape": {"type": "mesh", "file": "a.obj", "scale": -1}}]})", "bodies[0].shape.scale"},
    {3, R"({"bodies": [{"motion": "static", "shape": {"type": "sphere", "center": [0.5, 0.8], "radius": 0.1}}]})", "bodies[0].shape.center"},
    // probes
    {2, R"({"probes": [{"position": [1.5, 0.5]}]})", "probes[0].position"},
    {2, R"({"probes": [{"name": "p", "position": [0.5, 0.5]}, {"name": "p", "position": [0.2, 0.5]}]})", "probes[1].name"},
    {2, R"({"probes": [{"position": [0.5, 0.5, 0.5]}]})", "probes[0].position"},
    {2, R"({"probes": [{}]})", "probes[0].position"},
};

json base_scene(int dim) { return json::parse(dim == 2 ? kBase2 : kBase3); }

json bad_document(const BadCase& c) {
  if (c.base == 0) return json::parse(c.text, nullptr, false);
  json j = base_scene(c.base);
  j.merge_patch(json::parse(c.text));
  return j;
}

/// All problem lines of the InputError thrown by parsing `j` (empty if none is thrown).
std::vector<std::string> problems_of(const json& j) {
  try {
    parse_scene(j, "test.json", ".");
  } catch (const InputError& e) {
    return e.problems();
  }
  return {};
}

std::string temp_dir() {
  const auto d = std::filesystem::temp_directory_path() / ("monolith_test_scene_" + std::to_string(::getpid()));
  std::filesystem::create_directories(d);
  return d.string();
}

std::string write_file(const std::string& name, const std::string& text) {
  const std::string path = temp_dir() + "/" + name;
  std::ofstream(path) << text;
  return path;
}

bool mentions(const std::vector<std::string>& lines, const std::string& s) {
  for (const auto& l : lines)
    if (l.find(s) != std::string::npos) return true;
  return false;
}

}  // namespace

TEST_CASE("the base scenes are valid in 2D and 3D", "[unit]") {
  for (int dim : {2, 3}) {
    CAPTURE(dim);
    REQUIRE(problems_of(base_scene(dim)).empty());
  }
}

TEST_CASE("every bad input is refused with its key path in the message", "[unit][validation]") {
  std::set<std::string> distinct;
  for (const auto& c : kBadCases) {
    CAPTURE(c.text, c.path);
    if (c.base == 0) {
      // raw documents go through load_scene, which reports JSON syntax errors
      const std::string path = write_file("bad.json", c.text);
      try {
        load_scene(path, {});
        FAIL("no InputError for " << c.text);
      } catch (const InputError& e) {
        const std::string msg = e.problems().front();
        CHECK(msg.find(path) == 0);
        CHECK(msg.find(std::string(": ") + c.path + ":") != std::string::npos);
      }
    } else {
      const auto lines = problems_of(bad_document(c));
      REQUIRE_FALSE(lines.empty());
      bool found = false;
      for (const auto& l : lines) {
        CHECK(l.rfind("test.json: ", 0) == 0);
        if (l.find(std::string("test.json: ") + c.path + ":") == 0) found = true;
      }
      CAPTURE(lines);
      CHECK(found);
    }
    distinct.insert(std::to_string(c.base) + c.text);
  }
  CHECK(distinct.size() >= 35);
  CHECK(distinct.size() == sizeof(kBadCases) / sizeof(kBadCases[0]));
}

TEST_CASE("messages say what is allowed and suggest the closest key", "[unit]") {
  json j = base_scene(2);
  j["solver"] = {{"tolerence", 1e-6}, {"scheme", "PVC-unifed"}};
  const auto lines = problems_of(j);
  REQUIRE(lines.size() == 2);
  CHECK(mentions(lines, "did you mean \"tolerance\""));
  CHECK(mentions(lines, "did you mean \"PVC-unified\""));
  CHECK(mentions(lines, "\"PC-VC-PC-unified\""));  // the allowed values are listed
  // every line has the form LABEL: path: what (allowed)
  for (const auto& l : lines) CHECK(l.back() == ')');
}

TEST_CASE("all problems are collected, not only the first", "[unit]") {
  json j = base_scene(2);
  j["time"] = {{"fps", -1}, {"frames", 1.5}};
  j["render"] = {{"color_by", "x"}};
  j["liquids"][0]["density"] = 0;
  const auto lines = problems_of(j);
  CHECK(lines.size() == 4);
  CHECK(mentions(lines, "time.fps"));
  CHECK(mentions(lines, "time.frames"));
  CHECK(mentions(lines, "render.color_by"));
  CHECK(mentions(lines, "liquids[0].density"));
}

TEST_CASE("non-finite numbers are refused", "[unit]") {
  for (int dim : {2, 3}) {
    json j = base_scene(dim);
    j["gravity"] = json::array({0.0, -std::numeric_limits<double>::infinity()});
    if (dim == 3) j["gravity"].push_back(0.0);
    j["liquids"][0]["density"] = std::numeric_limits<double>::quiet_NaN();
    const auto lines = problems_of(j);
    CHECK(lines.size() == 2);
    CHECK(mentions(lines, "test.json: gravity[1]: not a finite number"));
    CHECK(mentions(lines, "test.json: liquids[0].density: not a finite number"));
  }
}

TEST_CASE("defaults are filled in 2D and 3D", "[unit]") {
  for (int dim : {2, 3}) {
    CAPTURE(dim);
    json j = base_scene(dim);
    j.erase("name");
    const SceneFile s = parse_scene(j, "some/dir/my-scene.json", "some/dir");
    CHECK(s.dim == dim);
    CHECK(s.name == "my-scene");
    CHECK(s.source_label == "some/dir/my-scene.json");
    REQUIRE(s.gravity.size() == static_cast<std::size_t>(dim));
    CHECK(s.gravity[0] == 0.0);
    CHECK(s.gravity[1] == -9.81);
    if (dim == 3) CHECK(s.gravity[2] == 0.0);
    for (int f = 0; f < 2 * dim; ++f) CHECK(s.domain.boundary[f] == BoundaryType::wall);
    CHECK(s.domain.wall_friction == 0.0);
    CHECK(s.domain.wall_restitution == 0.0);
    CHECK(s.time.fps == 50.0);
    CHECK(s.time.frames == 100);
    CHECK(s.time.cfl == 3.0);
    CHECK(s.time.max_dt == 0.02);
    CHECK(s.solver.scheme == CouplingScheme::pvc_unified);
    CHECK(s.solver.backend == Backend::matrix_free);
    CHECK(s.solver.tolerance == 1e-6);
    CHECK(s.solver.max_iterations == 2000);
    CHECK(s.solver.staggered_iterations == 2);
    CHECK(s.solver.contact_margin == 0.1);
    CHECK(s.solver.shrink == 0.01);
    CHECK(s.solver.diagonal_boost == 1e-4);
    CHECK(s.solver.baumgarte == 0.2);
    CHECK(s.solver.max_recovery_speed == 0.0);  // the default rule (RigidWorldSettings::from_scene)
    CHECK(s.particles.per_cell == 0);
    CHECK(s.particles.position_correction);
    CHECK(s.render.enabled);
    CHECK(s.render.size[0] == 512);
    CHECK(s.render.color_by == ColorBy::speed);
    REQUIRE(s.liquids.size() == 1);
    CHECK(s.liquids[0].name == "liquid0");
    CHECK(s.liquids[0].velocity == std::vector<double>(dim, 0.0));
    CHECK(s.liquids[0].angular_velocity.size() == (dim == 2 ? 1u : 3u));
    CHECK_FALSE(s.liquids[0].viscosity.is_viscous());
    REQUIRE(s.bodies.size() == 1);
    CHECK(s.bodies[0].name == "body0");
    CHECK(s.bodies[0].motion == BodyMotion::fixed);
    CHECK(s.bodies[0].restitution == 0.0);
    CHECK(s.bodies[0].friction == 0.0);
    CHECK_FALSE(s.bodies[0].has_path);
    REQUIRE(s.probes.size() == 1);
    CHECK(s.probes[0].name == "probe0");
    CHECK(s.dx() == Approx(1.0 / (dim == 2 ? 16 : 8)));
    CHECK(s.as_run == j);
  }
}

TEST_CASE("the contract's example scene is accepted with every key", "[unit]") {
  // the example of the interface contract, verbatim
  const char* example = R"({
    "format": "monolith-scene/1", "name": "bunny-into-bowl", "dim": 2,
    "domain": {"lower": [0, 0], "upper": [1, 1], "cells": [128, 128],
      "boundary": {"x-": "wall", "x+": "wall", "y-": "wall", "y+": "open"},
      "wall_friction": 0.0, "wall_restitution": 0.0},
    "gravity": [0, -9.81],
    "time": {"fps": 50, "frames": 100, "cfl": 3.0, "max_dt": 0.02},
    "solver": {"scheme": "PVC-unified", "tolerance": 1e-6, "max_iterations": 2000, "staggered_iterations": 2,
      "backend": "matrixfree", "baumgarte": 0.2, "contact_margin": 0.1, "shrink": 0.01, "diagonal_boost": 1e-4},
    "liquids": [{"name": "water", "shape": {"type": "box", "center": [0.3, 0.5], "half_size": [0.1, 0.2]},
      "density": 1000, "velocity": [0, 0], "angular_velocity": 0,
      "viscosity": {"model": "newtonian", "eta": 0.0}}],
    "bodies": [{"name": "bowl", "motion": "dynamic",
      "shape": {"type": "bowl", "center": [0.5, 0.2], "radius": 0.15, "thickness": 0.02},
      "density": 500, "velocity": [0, 0], "angular_velocity": 0, "restitution": 0.0, "friction": 0.1}],
    "probes": [{"name": "mid", "position": [0.5, 0.5]}],
    "render": {"enabled": true, "size": [512, 512], "color_by": "speed"}
  })";
  const SceneFile s = parse_scene(json::parse(example), "example.json", ".");
  CHECK(s.name == "bunny-into-bowl");
  CHECK(s.domain.boundary[3] == BoundaryType::open);
  CHECK(s.bodies[0].name == "bowl");
  CHECK(s.bodies[0].motion == BodyMotion::dynamic);
  CHECK(s.bodies[0].density == 500.0);
  CHECK(s.bodies[0].friction == 0.1);
  CHECK(s.bodies[0].shape.thickness == 0.02);
  CHECK(s.probes[0].name == "mid");
}

TEST_CASE("every key, shape type and enum value is accepted", "[unit]") {
  // a 3D scene with every shape type, a mesh file, a kinematic body and herschel-bulkley
  const std::string obj = write_file("tet.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n");
  const std::string scene3 = R"({
    "format": "monolith-scene/1", "name": "all-keys", "description": "every key", "dim": 3,
    "domain": {"lower": [0, 0, 0], "upper": [1, 1, 1], "cells": [8, 8, 8],
      "boundary": {"x-": "periodic", "x+": "periodic", "y-": "wall", "y+": "open", "z-": "wall", "z+": "wall"},
      "wall_friction": 0.3, "wall_restitution": 0.5},
    "gravity": [0, -9.81, 0],
    "time": {"fps": 30, "frames": 0, "cfl": 1.0, "max_dt": 0.01},
    "solver": {"scheme": "PC-unified", "backend": "explicit", "tolerance": 1e-8, "max_iterations": 10,
      "staggered_iterations": 3, "preconditioner": "ssor", "baumgarte": 0.1, "contact_margin": 0.2, "shrink": 0.02, "diagonal_boost": 0},
    "particles": {"per_cell": 27, "seed": 42, "position_correction": false, "settle_steps": 3},
    "liquids": [
      {"name": "hb", "shape": {"type": "bunny", "center": [0.5, 0.5, 0.5], "size": 0.3, "rotation": [0, 1, 0]},
       "density": 1200, "velocity": [1, 0, 0], "angular_velocity": [0, 0, 1],
       "viscosity": {"model": "herschel-bulkley", "k": 2, "n": 0.5, "tau0": 10, "gamma0": 0.01}},
      {"name": "in-shell", "shape": {"type": "shell", "center": [0.2, 0.5, 0.5], "radius": 0.1, "thickness": 0.02},
       "density": 1000}],
    "bodies": [
      {"name": "floor", "motion": "static", "shape": {"type": "halfspace", "normal": [0, 1, 0], "offset": 0.05}},
      {"name": "mesh", "motion": "static", "shape": {"type": "mesh", "file": "tet.obj", "scale": [0.1, 0.2, 0.1], "translate": [0.5, 0.5, 0.5]}},
      {"name": "mesh2", "motion": "static", "shape": {"type": "mesh", "file": "tet.obj", "scale": 0.1}},
      {"name": "shaker", "motion": "kinematic", "density": 700, "restitution": 0.3, "friction": 0.4,
       "shape": {"type": "union", "shapes": [{"type": "box", "center": [0.7, 0.7, 0.7], "half_size": [0.05, 0.05, 0.05]},
                                              {"type": "sphere", "center": [0.8, 0.7, 0.7], "radius": 0.05}]},
       "path": {"type": "oscillate", "axis": [1, 0, 0], "amplitude": 0.05, "frequency": 1.0}},
      {"name": "cup", "motion": "dynamic", "density": 300, "velocity": [0, -1, 0], "angular_velocity": [0, 1, 0],
       "shape": {"type": "difference", "shapes": [{"type": "box", "center": [0.3, 0.8, 0.3], "half_size": [0.1, 0.1, 0.1]},
                                                   {"type": "bowl", "center": [0.3, 0.85, 0.3], "radius": 0.08, "thickness": 0.01}]}}],
    "probes": [{"name": "a", "position": [0.1, 0.1, 0.1]}, {"position": [1, 1, 1]}],
    "render": {"enabled": false, "size": [16, 8192], "color_by": "viscosity"}
  })";
  const std::string path = write_file("all-keys.json", scene3);
  const SceneFile s = load_scene(path, {});
  CHECK(s.description == "every key");
  CHECK(s.domain.boundary[0] == BoundaryType::periodic);
  CHECK(s.domain.boundary[3] == BoundaryType::open);
  CHECK(s.particles.per_cell == 27);
  CHECK(s.particles.seed == 42u);
  CHECK_FALSE(s.particles.position_correction);
  CHECK(s.particles.settle_steps == 3);
  CHECK(s.liquids[0].viscosity.model == ViscosityModel::herschel_bulkley);
  CHECK(s.liquids[0].viscosity.tau0 == 10.0);
  CHECK(s.liquids[0].viscosity.is_viscous());
  CHECK(s.liquids[0].shape.rotation == std::vector<double>{0, 1, 0});
  CHECK(s.bodies[1].shape.scale == std::vector<double>{0.1, 0.2, 0.1});
  CHECK(s.bodies[2].shape.scale == std::vector<double>{0.1});
  CHECK(s.bodies[1].shape.file == std::filesystem::path(temp_dir()) / "tet.obj");
  CHECK(s.bodies[3].has_path);
  CHECK(s.bodies[3].path.amplitude == 0.05);
  CHECK(s.bodies[4].shape.shapes.size() == 2);
  CHECK(s.probes[1].name == "probe1");
  CHECK(s.render.size[1] == 8192);
  (void)obj;

  CHECK(s.bodies[0].shape.type == ShapeType::halfspace);
  CHECK(s.bodies[1].shape.type == ShapeType::mesh);
  CHECK(s.bodies[3].shape.type == ShapeType::set_union);
  CHECK(s.bodies[3].motion == BodyMotion::kinematic);
  CHECK(s.bodies[3].path.type == PathType::oscillate);
  CHECK(s.bodies[4].shape.type == ShapeType::set_difference);
  CHECK(s.render.color_by == ColorBy::viscosity);
  CHECK(s.solver.scheme == CouplingScheme::pc_unified);
  CHECK(s.solver.backend == Backend::explicit_matrices);
  CHECK(s.solver.preconditioner == PreconditionerChoice::ssor);

  // every enum value, in 2D and 3D
  for (int dim : {2, 3}) {
    for (const char* scheme : {"P-C", "C-P", "PC-iterative", "PC-unified", "PC-VC-PC-unified", "PV-C", "C-PV",
                               "PVC-iterative", "PVC-unified"})
      for (const char* backend : {"matrixfree", "explicit"}) {
        json j = base_scene(dim);
        j["solver"] = {{"scheme", scheme}, {"backend", backend}};
        const SceneFile t = parse_scene(j, "e.json", ".");
        CHECK(enum_name(t.solver.scheme) == scheme);
        CHECK(enum_name(t.solver.backend) == backend);
      }
    for (const char* color : {"none", "speed", "pressure", "viscosity"}) {
      json j = base_scene(dim);
      j["render"] = {{"color_by", color}};
      CHECK(enum_name(parse_scene(j, "e.json", ".").render.color_by) == color);
    }
    json j = base_scene(dim);
    j["liquids"][0]["viscosity"] = {{"model", "newtonian"}, {"eta", 0.5}};
    CHECK(parse_scene(j, "e.json", ".").liquids[0].viscosity.eta == 0.5);
  }

  // 2D-only shapes: polygon and rotation angle
  json j = base_scene(2);
  j["bodies"][0]["shape"] = {{"type", "polygon"}, {"points", {{0.1, 0.6}, {0.4, 0.6}, {0.3, 0.9}}}, {"rotation", 0.3}};
  const SceneFile t = parse_scene(j, "p.json", ".");
  CHECK(t.bodies[0].shape.points.size() == 3);
  CHECK(t.bodies[0].shape.rotation == std::vector<double>{0.3});
}

TEST_CASE("overrides by dotted path", "[unit]") {
  const std::string path = write_file("ov.json", kBase2);
  const SceneFile s = load_scene(path, {"solver.tolerance=1e-8", "liquids.0.density=800", "liquids[0].name=oil",
                                        "gravity=[0,-1]", "render.enabled=false", "time.frames=3",
                                        "bodies[0].shape.radius=0.05"});
  CHECK(s.solver.tolerance == 1e-8);
  CHECK(s.liquids[0].density == 800.0);
  CHECK(s.liquids[0].name == "oil");
  CHECK(s.gravity == std::vector<double>{0, -1});
  CHECK_FALSE(s.render.enabled);
  CHECK(s.time.frames == 3);
  CHECK(s.bodies[0].shape.radius == 0.05);
  CHECK(s.as_run["liquids"][0]["density"] == 800);
  CHECK(s.as_run["solver"]["tolerance"] == 1e-8);

  // bad overrides name the key
  for (const char* bad : {"liquids.3.density=1", "liquids[x].density=1", "format.x=1", "=1", "noequals",
                          "solver..tolerance=1", "time.frames=abc"}) {
    CAPTURE(bad);
    try {
      load_scene(path, {bad});
      FAIL("override accepted");
    } catch (const InputError& e) {
      CHECK(e.problems().front().find(path) == 0);
    }
  }
  // a typo in an override is an unknown key
  try {
    load_scene(path, {"solver.tolerence=1e-8"});
    FAIL("typo accepted");
  } catch (const InputError& e) {
    CHECK(mentions(e.problems(), "solver.tolerence: unknown key (did you mean \"tolerance\"?"));
  }
}

TEST_CASE("files that cannot be read are input errors naming the file", "[unit]") {
  const std::string missing = temp_dir() + "/does-not-exist.json";
  try {
    load_scene(missing, {});
    FAIL("missing file accepted");
  } catch (const InputError& e) {
    CHECK(e.problems().front().find(missing) == 0);
    CHECK(e.problems().front().find("dam-break-2d") != std::string::npos);  // built-ins are listed
  }
  CHECK_THROWS_AS(load_scene(temp_dir(), {}), InputError);
  CHECK_THROWS_AS(load_scene("no-such-builtin", {}), InputError);
  // a syntax error gives line and column
  const std::string bad = write_file("syntax.json", "{\n  \"format\": \"monolith-scene/1\",\n  \"dim\": 2,,\n}");
  try {
    load_scene(bad, {});
    FAIL("syntax error accepted");
  } catch (const InputError& e) {
    CHECK(e.problems().front().find("line 3") != std::string::npos);
    CHECK(e.problems().front().find("column") != std::string::npos);
  }
}

TEST_CASE("every built-in scene parses, is supported and is labelled builtin:NAME", "[unit]") {
  std::set<std::string> names;
  for (const auto& f : embedded_scenes()) {
    const std::string name(f.name);
    CAPTURE(name);
    names.insert(name);
    const SceneFile s = load_scene(name, {});
    CHECK(s.name == name);
    CHECK(s.source_label == "builtin:" + name);
    CHECK_FALSE(s.description.empty());
    // scenes colour by speed unless they show viscosity (a scene with several viscosities)
    CHECK((s.render.color_by == ColorBy::speed || s.render.color_by == ColorBy::viscosity));
  }
  for (const char* required :
       {"default", "dam-break-2d", "dam-break-3d", "pour-into-bowl-2d", "pour-into-bowl-3d",
        "viscous-sphere-wall-2d", "viscous-sphere-wall-3d", "viscous-pour-2d", "viscous-pour-3d",
        "viscous-coiling-2d", "viscous-coiling-3d", "box-stack-2d", "box-stack-3d",
        "box-pyramid-2d", "box-pyramid-3d", "incline-2d", "incline-3d", "bouncing-balls-2d",
        "bouncing-balls-3d", "bunny-into-bowl-2d", "bunny-into-bowl-3d"})
    CHECK(names.count(required) == 1);
  // the specified sizes
  const SceneFile d = load_scene("default", {});
  CHECK(d.domain.cells == std::vector<int>{96, 64});
  CHECK(d.time.frames == 80);
  CHECK(d.time.fps == 40.0);
  CHECK(d.bodies.size() == 1);
  const SceneFile m = load_scene("dam-break-2d", {});
  CHECK(m.domain.cells == std::vector<int>{128, 64});
  CHECK(m.domain.upper == std::vector<double>{0.8, 0.4});
  CHECK(m.liquids[0].shape.half_size == std::vector<double>{0.1, 0.2});
  CHECK(m.time.frames == 60);
  CHECK(m.time.fps == 50.0);
  CHECK(load_scene("dam-break-3d", {}).domain.cells == std::vector<int>{64, 32, 32});
  CHECK(load_scene("pour-into-bowl-2d", {}).domain.cells == std::vector<int>{96, 96});
  CHECK(load_scene("pour-into-bowl-3d", {}).domain.cells == std::vector<int>{48, 48, 48});
}

TEST_CASE("the memory estimate grows with cells and particles", "[unit][property]") {
  const double a = estimate_memory_bytes(2, {64, 64}, 0);
  const double b = estimate_memory_bytes(2, {128, 128}, 0);
  const double c = estimate_memory_bytes(2, {128, 128}, 1e5);
  CHECK(b > 3.9 * a);
  CHECK(c > b);
  CHECK(estimate_memory_bytes(3, {64, 64, 64}, 0) > estimate_memory_bytes(2, {64, 64}, 0) * 60);
}

TEST_CASE("a scene over the memory limit is refused with its estimate; MONOLITH_MEMORY_LIMIT_GIB sets the limit",
          "[unit]") {
  // restores the test environment's value (CMakeLists.txt sets it for every test) on every exit
  struct Restore {
    std::string old;
    bool had;
    Restore() : had(std::getenv("MONOLITH_MEMORY_LIMIT_GIB") != nullptr) {
      if (had) old = std::getenv("MONOLITH_MEMORY_LIMIT_GIB");
    }
    ~Restore() {
      if (had)
        setenv("MONOLITH_MEMORY_LIMIT_GIB", old.c_str(), 1);
      else
        unsetenv("MONOLITH_MEMORY_LIMIT_GIB");
    }
  } restore;
  const std::vector<int> cells{64, 32, 32};
  const double need = estimate_memory_bytes(3, cells, 0) / (1024.0 * 1024.0 * 1024.0);  // GiB, without particles
  // a limit below the grid alone: refused at domain.cells with the estimate and the limit's source
  setenv("MONOLITH_MEMORY_LIMIT_GIB", std::to_string(0.5 * need).c_str(), 1);
  try {
    load_scene("dam-break-3d", {});
    FAIL("dam-break-3d was accepted under a limit of half its grid's estimate");
  } catch (const InputError& e) {
    REQUIRE(e.problems().size() == 1);
    const std::string& m = e.problems()[0];
    CHECK(m.find("domain.cells") != std::string::npos);
    CHECK(m.find("would need about") != std::string::npos);
    CHECK(m.find("set by MONOLITH_MEMORY_LIMIT_GIB") != std::string::npos);
  }
  // a generous limit: the same scene and the paper-size Fig. 2 parse
  setenv("MONOLITH_MEMORY_LIMIT_GIB", "1000", 1);
  CHECK(load_scene("dam-break-3d", {}).domain.cells == cells);
  CHECK(load_scene("liquid-bunny-into-bowl-3d-paper", {}).domain.cells == std::vector<int>{256, 128, 256});
  // not a positive number: refused with the variable's name
  for (const char* bad : {"", "abc", "0", "-2", "4GiB", "nan", "inf"}) {
    setenv("MONOLITH_MEMORY_LIMIT_GIB", bad, 1);
    INFO("MONOLITH_MEMORY_LIMIT_GIB='" << bad << "'");
    try {
      load_scene("dam-break-3d", {});
      FAIL("accepted");
    } catch (const InputError& e) {
      CHECK(std::string(e.what()).find("MONOLITH_MEMORY_LIMIT_GIB") != std::string::npos);
    }
  }
}

TEST_CASE("herschel-bulkley presets give the section 6.4.1 sets; explicit keys override them",
          "[unit]") {
  struct Expected {
    const char* name;
    double k, n, tau0, gamma0;
  };
  // section 6.4.1 (Fig. 10): (r, gamma0, tau0, k)
  for (const Expected e : {Expected{"newtonian", 11.0, 1.0, 0.0, 1.0}, Expected{"shear-thinning", 10.0, 0.5, 1.0, 1.0},
                           Expected{"shear-thickening", 10.0, 2.0, 1.0, 1.0}, Expected{"bingham", 10.0, 1.0, 1e3, 1.0}}) {
    CAPTURE(e.name);
    for (int dim : {2, 3}) {
      json j = base_scene(dim);
      j["liquids"][0]["viscosity"] = {{"model", "herschel-bulkley"}, {"preset", e.name}};
      const ViscositySpec v = parse_scene(j, "test.json", ".").liquids[0].viscosity;
      CHECK(v.model == ViscosityModel::herschel_bulkley);
      REQUIRE(v.preset.has_value());
      CHECK(enum_name(*v.preset) == e.name);
      CHECK(v.k == e.k);
      CHECK(v.n == e.n);
      CHECK(v.tau0 == e.tau0);
      CHECK(v.gamma0 == e.gamma0);
      CHECK(v.is_viscous());
    }
  }
  // Fig. 11's Bingham liquid: the preset with k = 100
  json j = base_scene(2);
  j["liquids"][0]["viscosity"] = {{"model", "herschel-bulkley"}, {"preset", "bingham"}, {"k", 100}};
  const ViscositySpec b = parse_scene(j, "test.json", ".").liquids[0].viscosity;
  CHECK(b.k == 100.0);
  CHECK(b.tau0 == 1e3);
  CHECK(b.n == 1.0);
  // the key order does not matter: an explicit key wins wherever it stands
  j["liquids"][0]["viscosity"] = json::parse(R"({"tau0": 5, "model": "herschel-bulkley", "preset": "shear-thinning"})");
  CHECK(parse_scene(j, "test.json", ".").liquids[0].viscosity.tau0 == 5.0);
  // without a preset the defaults are unchanged (k = 0, n = 1, tau0 = 0, gamma0 = 1e-3)
  j["liquids"][0]["viscosity"] = {{"model", "herschel-bulkley"}, {"k", 2}};
  const ViscositySpec plain = parse_scene(j, "test.json", ".").liquids[0].viscosity;
  CHECK_FALSE(plain.preset.has_value());
  CHECK(plain.gamma0 == 1e-3);
  CHECK(plain.tau0 == 0.0);
}

TEST_CASE("solver.preconditioner: auto (the default), multigrid, ssor; anything else is refused",
          "[unit][validation]") {
  json j = base_scene(3);
  CHECK(parse_scene(j, "test.json", ".").solver.preconditioner == PreconditionerChoice::automatic);
  const std::pair<const char*, PreconditionerChoice> good[] = {{"auto", PreconditionerChoice::automatic},
                                                               {"multigrid", PreconditionerChoice::multigrid},
                                                               {"ssor", PreconditionerChoice::ssor}};
  for (const auto& [name, value] : good) {
    j["solver"] = {{"preconditioner", name}};
    CHECK(parse_scene(j, "test.json", ".").solver.preconditioner == value);
  }
  j["solver"] = {{"preconditioner", "automatic"}};
  const auto lines = problems_of(j);
  REQUIRE(lines.size() == 1);
  CHECK(lines[0].rfind("test.json: solver.preconditioner:", 0) == 0);
  for (const char* name : {"\"auto\"", "\"multigrid\"", "\"ssor\""}) CHECK(mentions(lines, name));
  // "auto" is a choice of the unified solves only, not of the pressure-only ones
  j["solver"] = {{"pressure_preconditioner", "auto"}};
  CHECK(mentions(problems_of(j), "solver.pressure_preconditioner"));
  // the recovery cap is a speed > 0
  j["solver"] = {{"max_recovery_speed", 0.0}};
  CHECK(mentions(problems_of(j), "solver.max_recovery_speed"));
  j["solver"] = {{"max_recovery_speed", 0.5}};
  CHECK(problems_of(j).empty());
}

TEST_CASE("an unknown viscosity preset names the file, the key path and the allowed names",
          "[unit][validation]") {
  json j = base_scene(3);
  j["liquids"][0]["viscosity"] = {{"model", "herschel-bulkley"}, {"preset", "shear-thining"}};
  const auto lines = problems_of(j);
  REQUIRE(lines.size() == 1);
  CHECK(lines[0].rfind("test.json: liquids[0].viscosity.preset:", 0) == 0);
  CHECK(mentions(lines, "did you mean \"shear-thinning\""));
  for (const char* name : {"\"newtonian\"", "\"shear-thinning\"", "\"shear-thickening\"", "\"bingham\""})
    CHECK(mentions(lines, name));
  // a preset is a herschel-bulkley key: next to a newtonian model it is an unknown key
  j["liquids"][0]["viscosity"] = {{"model", "newtonian"}, {"preset", "bingham"}};
  CHECK(mentions(problems_of(j), "liquids[0].viscosity.preset"));
  // not a string
  j["liquids"][0]["viscosity"] = {{"model", "herschel-bulkley"}, {"preset", 3}};
  CHECK(mentions(problems_of(j), "liquids[0].viscosity.preset"));
  // the sets themselves (liquid_spec.hpp): each carries its name
  for (const ViscosityPreset preset : enum_values<ViscosityPreset>())
    CHECK(viscosity_preset(preset).preset == preset);
}
