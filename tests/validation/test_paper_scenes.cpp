// The paper's scenes (section 6: Figs. 2-8, 15-18) as built-in scenes, 2D and 3D
// (docs/scenes.md). Every one parses and validates (what `monolith check` does); the 2D ones
// run their first frames at their own resolution under PVC-unified and under the scheme the
// paper compares against in that figure, so that between them the nine schemes are exercised.
// The 3D ones are only parsed and validated here; slow_paper_scenes.cpp builds and runs them.
#include <catch2/catch.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include <map>
#include <nlohmann/json.hpp>

#include "reference/app/embedded_scenes.hpp"
#include "reference/app/scene_file.hpp"
#include "reference/sim/simulation.hpp"

using namespace monolith;

namespace {

/// One paper figure: the stem of its built-in scenes (NAME-2d, NAME-3d) and the scheme the
/// paper compares PC-/PVC-unified with in that figure.
struct PaperScene {
  const char* stem;
  const char* figure;
  const char* other_scheme;
};

const std::vector<PaperScene> kPaperScenes = {
    {"liquid-bunny-into-bowl", "Fig. 2", "P-C"},
    {"bunny-onto-floating-bowl", "Fig. 3", "C-P"},
    {"viscous-sphere-bunny-wall", "Fig. 4", "PC-VC-PC-unified"},
    {"bunny-on-viscous-hemisphere", "Fig. 5", "PC-VC-PC-unified"},
    {"viscous-blob-into-bowl", "Fig. 6", "PV-C"},
    {"bunnies-into-floating-bowl-viscous", "Fig. 7", "C-PV"},
    {"viscous-sphere-bunny-air", "Fig. 8", "PC-unified"},
    {"boat-on-waves", "Fig. 15", "PC-iterative"},
    {"bunnies-onto-pool", "Fig. 16", "PC-unified"},
    {"hollow-spheres-inviscid", "Fig. 17", "PC-iterative"},
    {"hollow-spheres-viscous", "Fig. 18", "PVC-iterative"},
};

bool is_builtin(const std::string& name) {
  for (const auto& f : embedded_scenes())
    if (f.name == name) return true;
  return false;
}

/// The text of a built-in scene (empty if there is none).
std::string builtin_text(const std::string& name) {
  for (const auto& f : embedded_scenes())
    if (f.name == name) return std::string(f.data);
  return {};
}

/// The paper-resolution variants NAME-3d-paper of the 3D paper scenes and the grid each figure
/// used in the paper (Tables 1-3, sections 6.4.1, 6.4.2, 6.5). Figs. 15 (240x96x96) and 16
/// (225x150x150) also change their box to the grid's proportions (checked below).
const std::map<std::string, std::array<int, 3>> kPaperGrids = {
    {"liquid-bunny-into-bowl-3d", {256, 128, 256}},
    {"bunny-onto-floating-bowl-3d", {128, 128, 128}},
    {"viscous-sphere-bunny-wall-3d", {128, 128, 128}},
    {"bunny-on-viscous-hemisphere-3d", {128, 128, 128}},
    {"viscous-blob-into-bowl-3d", {128, 128, 128}},
    {"bunnies-into-floating-bowl-viscous-3d", {64, 64, 64}},
    {"liquid-drop-newtonian-3d", {128, 128, 128}},
    {"liquid-drop-shear-thinning-3d", {128, 128, 128}},
    {"liquid-drop-shear-thickening-3d", {128, 128, 128}},
    {"liquid-drop-bingham-3d", {128, 128, 128}},
    {"bunny-into-block-newtonian-3d", {64, 64, 64}},
    {"bunny-into-block-shear-thinning-3d", {64, 64, 64}},
    {"bunny-into-block-shear-thickening-3d", {64, 64, 64}},
    {"bunny-into-block-bingham-3d", {64, 64, 64}},
    {"hollow-spheres-inviscid-3d", {256, 256, 256}},
    {"hollow-spheres-viscous-3d", {128, 128, 128}},
    {"boat-on-waves-3d", {240, 96, 96}},
    {"bunnies-onto-pool-3d", {225, 150, 150}},
};

/// The top of a liquid box (its surface at rest).
double box_top(const nlohmann::json& box) {
  return box["center"][1].get<double>() + box["half_size"][1].get<double>();
}

/// The particles seeded for a single liquid box: per_cell (8 in 3D) times its cells.
double box_particles(const nlohmann::json& box, double dx) {
  double cells = 1.0;
  for (int a = 0; a < 3; ++a) cells *= 2.0 * box["half_size"][a].get<double>() / dx;
  return 8.0 * cells;
}

/// Every box of a body's shape (a box or a union of boxes, or the one shape itself).
std::vector<nlohmann::json*> shape_parts(nlohmann::json& shape) {
  std::vector<nlohmann::json*> v;
  if (shape["type"] == "union")
    for (auto& s : shape["shapes"]) v.push_back(&s);
  else
    v.push_back(&shape);
  return v;
}

bool all_finite(const std::vector<double>& v) {
  return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
}

}  // namespace

TEST_CASE("paper scenes are built in, in 2D and 3D, and name their figure", "[unit]") {
  for (const auto& p : kPaperScenes) {
    for (int dim : {2, 3}) {
      const std::string name = std::string(p.stem) + (dim == 2 ? "-2d" : "-3d");
      INFO(name);
      REQUIRE(is_builtin(name));
      const SceneFile s = load_scene(name, {});
      CHECK(s.name == name);
      CHECK(s.dim == dim);
      // the description (the line of `monolith list`) starts with the figure it reproduces
      CHECK(s.description.rfind(std::string(p.figure) + " in " + std::to_string(dim) + "D", 0) == 0);
      // sized to run in minutes on two cores: 2D 48-96 cells, 3D 12-40 cells per axis
      const int lo = *std::min_element(s.domain.cells.begin(), s.domain.cells.end());
      const int hi = *std::max_element(s.domain.cells.begin(), s.domain.cells.end());
      CHECK(lo >= (dim == 2 ? 48 : 12));
      CHECK(hi <= (dim == 2 ? 96 : 48));
      // every paper scene couples a liquid with at least one dynamic body
      CHECK(!s.liquids.empty());
      CHECK(std::any_of(s.bodies.begin(), s.bodies.end(),
                        [](const BodySpec& b) { return b.motion == BodyMotion::dynamic; }));
    }
  }
}

TEST_CASE("2D paper scenes run their first frames under PVC-unified and the paper's other scheme",
          "[unit][property]") {
  // One frame (0.04 s at 25 fps) of each scene at its own resolution. What is checked holds
  // for any scheme over so short a time: the state stays finite, no liquid is lost (the bodies
  // are still falling or just touching: the largest drift measured over the first frame was
  // 0.26 %, Fig. 18; tolerance 2 %), no particle leaves, and contacts stay shallower than half a
  // cell (measured: at most 0.28 dx over whole runs under PC-/PVC-unified, docs/scenes.md).
  for (const auto& p : kPaperScenes) {
    for (const std::string& scheme : {std::string("PVC-unified"), std::string(p.other_scheme)}) {
      const std::string name = std::string(p.stem) + "-2d";
      INFO(name << " under " << scheme);
      const SceneFile s = load_scene(name, {"render.enabled=false", "solver.scheme=" + scheme});
      auto sim = make_simulation(s);
      const FrameStats initial = sim->current_stats();
      FrameStats f;
      REQUIRE_NOTHROW(f = sim->advance_frame());
      INFO("volume " << initial.liquid_volume << " -> " << f.liquid_volume << ", penetration "
                     << f.max_penetration / s.dx() << " dx, iterations " << f.solver.iterations
                     << ", converged " << f.solver.converged);
      CHECK(enum_name(f.solver.scheme) == scheme);
      CHECK(f.particles == initial.particles);
      CHECK(std::isfinite(f.kinetic_energy_liquid));
      CHECK(std::isfinite(f.kinetic_energy_bodies));
      CHECK(std::abs(f.liquid_volume / initial.liquid_volume - 1.0) < 0.02);
      CHECK(f.max_penetration < 0.5 * s.dx());
      REQUIRE(f.bodies.size() == s.bodies.size());
      for (const auto& b : f.bodies) {
        INFO(b.name);
        CHECK(all_finite(b.position));
        CHECK(all_finite(b.velocity));
        // no body left the domain (lower corner at the origin in every paper scene)
        for (int a = 0; a < s.dim; ++a) {
          CHECK(b.position[a] > s.domain.lower[a]);
          CHECK(b.position[a] < s.domain.upper[a]);
        }
      }
    }
  }
}

namespace {

/// Section 6.4's scenes (Figs. 9-11): one scene per model for Figs. 10 and 11, so that each
/// model's run time per frame is that of its own run (docs/non-newtonian.md).
struct NonNewtonianScene {
  std::string stem;
  const char* figure;
  const char* preset;  ///< the liquid's viscosity preset
  bool body;           ///< a dynamic rigid bunny
};

std::vector<NonNewtonianScene> non_newtonian_scenes() {
  std::vector<NonNewtonianScene> v = {{"thinning-bunny-drop", "Fig. 9", "shear-thinning", false}};
  for (const char* preset : {"newtonian", "shear-thinning", "shear-thickening", "bingham"}) {
    v.push_back({std::string("liquid-drop-") + preset, "Fig. 10", preset, false});
    v.push_back({std::string("bunny-into-block-") + preset, "Fig. 11", preset, true});
  }
  return v;
}

}  // namespace

TEST_CASE("non-Newtonian scenes (Figs. 9-11) are built in, 2D and 3D, with the presets",
          "[unit]") {
  for (const auto& p : non_newtonian_scenes()) {
    for (int dim : {2, 3}) {
      const std::string name = p.stem + (dim == 2 ? "-2d" : "-3d");
      INFO(name);
      REQUIRE(is_builtin(name));
      const SceneFile s = load_scene(name, {});
      CHECK(s.dim == dim);
      CHECK(s.description.rfind(std::string(p.figure) + " in " + std::to_string(dim) + "D", 0) == 0);
      REQUIRE(s.liquids.size() == 1);
      const ViscositySpec& v = s.liquids[0].viscosity;
      CHECK(v.model == ViscosityModel::herschel_bulkley);
      REQUIRE(v.preset.has_value());
      CHECK(enum_name(*v.preset) == p.preset);
      // Fig. 11 (section 6.4.2) differs from the presets (Fig. 10's sets) in k only
      if (p.body && v.preset == ViscosityPreset::newtonian) CHECK(v.k == 10.0);
      if (p.body && v.preset == ViscosityPreset::bingham) CHECK(v.k == 100.0);
      CHECK(s.render.color_by == ColorBy::viscosity);
      CHECK(s.solver.scheme == CouplingScheme::pvc_unified);
      CHECK(std::count_if(s.bodies.begin(), s.bodies.end(), [](const BodySpec& b) {
              return b.motion == BodyMotion::dynamic;
            }) == (p.body ? 1 : 0));
    }
  }
}

TEST_CASE("2D non-Newtonian scenes run their first frame through Algorithm 2", "[unit][property]") {
  // One frame of 0.01 s (fps overridden to 100: one step; the files' 1/30 s frames of all nine
  // took 60-75 s) of each at its own resolution (48^2): finite state, no particle lost,
  // volume kept (the liquid is falling or just landing; tolerance 2 %), the viscosity rounds of
  // the scene's staggered_iterations (2) recorded in the frame statistics, and contacts of the
  // bunny (Fig. 11) shallower than half a cell.
  for (const auto& p : non_newtonian_scenes()) {
    const std::string name = p.stem + "-2d";
    INFO(name);
    const SceneFile s = load_scene(name, {"render.enabled=false", "time.fps=100"});
    auto sim = make_simulation(s);
    const FrameStats initial = sim->current_stats();
    FrameStats f;
    REQUIRE_NOTHROW(f = sim->advance_frame());
    INFO("volume " << initial.liquid_volume << " -> " << f.liquid_volume << ", residuals "
                   << f.solver.viscosity_residuals.size() << ", last " << f.solver.max_viscosity_residual);
    CHECK(f.particles == initial.particles);
    CHECK(std::isfinite(f.kinetic_energy_liquid));
    CHECK(f.kinetic_energy_liquid > 0.0);
    CHECK(std::abs(f.liquid_volume / initial.liquid_volume - 1.0) < 0.02);
    CHECK(f.solver.viscosity_residuals.size() == 2);
    CHECK(std::isfinite(f.solver.max_viscosity_residual));
    CHECK(f.max_penetration < 0.5 * s.dx());
    for (const auto& b : f.bodies) CHECK(all_finite(b.position));
  }
}

TEST_CASE("paper-resolution variants are their scenes at the paper's grid", "[unit]") {
  // Only parsed and compared here: one frame of the largest takes minutes and gigabytes
  // (docs/benchmarks.md). Every built-in NAME-paper is listed, and differs from NAME only in its
  // name, description and grid (for Fig. 2 also the box, widened at the same cell width; for
  // Fig. 3 a shallower pool; for Figs. 15 and 16 the box's proportions and the liquid's depth).
  int variants = 0;
  for (const auto& f : embedded_scenes()) {
    const std::string name(f.name);
    if (name.size() < 6 || name.compare(name.size() - 6, 6, "-paper") != 0) continue;
    ++variants;
    const std::string base = name.substr(0, name.size() - 6);
    INFO(name);
    REQUIRE(kPaperGrids.count(base) == 1);
    REQUIRE(is_builtin(base));
    const SceneFile paper = load_scene(name, {});
    const SceneFile own = load_scene(base, {});
    CHECK(paper.name == name);
    const std::array<int, 3> grid = kPaperGrids.at(base);
    for (int a = 0; a < 3; ++a) CHECK(paper.domain.cells[a] == grid[a]);
    // cubic cells, and the description names the figure as the base scene's does
    for (int a = 0; a < 3; ++a)
      CHECK((paper.domain.upper[a] - paper.domain.lower[a]) / paper.domain.cells[a] ==
            Approx(paper.dx()).epsilon(1e-12));
    const std::string figure = own.description.substr(0, own.description.find(" in 3D"));
    CHECK(paper.description.rfind(figure + " in 3D", 0) == 0);
    CHECK(paper.description.find("paper's grid") != std::string::npos);
    // everything else as in the base scene
    nlohmann::json a = nlohmann::json::parse(builtin_text(name));
    nlohmann::json b = nlohmann::json::parse(builtin_text(base));
    for (nlohmann::json* j : {&a, &b}) {
      j->erase("name");
      j->erase("description");
      (*j)["domain"].erase("cells");
    }
    if (base == "liquid-bunny-into-bowl-3d") {
      // the paper's 2:1:2 box at the base scene's cell width, its liquid and bowl unmoved
      CHECK(paper.dx() == Approx(1.0 / 128.0).epsilon(1e-12));
      for (int ax : {0, 2}) {
        CHECK(paper.domain.lower[ax] == -0.5);
        CHECK(paper.domain.upper[ax] == 1.5);
      }
      for (nlohmann::json* j : {&a, &b}) {
        (*j)["domain"].erase("lower");
        (*j)["domain"].erase("upper");
      }
    }
    if (base == "bunny-onto-floating-bowl-3d") {
      // Fig. 3: the pool 0.175 m shallower, the bowl and the bunny lowered with it (the bowl as
      // deep in the water), so that 8 particles per cell make about Table 1's 2,697.9k
      // (docs/benchmarks.md, "Memory at the paper grid (sixth part)"); the rest as the base's
      const double drop = 0.175;
      nlohmann::json& pool_a = a["liquids"][0]["shape"]["shapes"];
      const nlohmann::json& pool_b = b["liquids"][0]["shape"]["shapes"];
      CHECK(pool_a[0]["half_size"][1].get<double>() ==
            Approx(pool_b[0]["half_size"][1].get<double>() - 0.5 * drop));
      CHECK(pool_a[0]["center"][1].get<double>() ==
            Approx(pool_b[0]["center"][1].get<double>() - 0.5 * drop));
      CHECK(pool_a[1]["center"][1].get<double>() ==
            Approx(pool_b[1]["center"][1].get<double>() - drop));
      for (int i = 0; i < 2; ++i)
        CHECK(a["bodies"][i]["shape"]["center"][1].get<double>() ==
              Approx(b["bodies"][i]["shape"]["center"][1].get<double>() - drop));
      for (nlohmann::json* j : {&a, &b}) {
        for (int k = 0; k < 2; ++k) (*j)["liquids"][0]["shape"]["shapes"][k].erase("center");
        (*j)["liquids"][0]["shape"]["shapes"][0].erase("half_size");
        for (int i = 0; i < 2; ++i) (*j)["bodies"][i]["shape"].erase("center");
      }
    }
    if (base == "boat-on-waves-3d" || base == "bunnies-onto-pool-3d") {
      // Figs. 15 and 16 (section 6.5): the box of the paper's grid proportions (2.5:1:1 and
      // 1.5:1:1, 1 m high as the base's) and a shallower liquid, so that 8 particles per cell
      // make about the paper's 2.8M and 8.2M; the dynamic bodies keep their place against the
      // box's centre (x, z) and the liquid's surface (y). Fig. 15's board stays at the x- wall
      // with the base's bottom and height above the surface, across the new width.
      const bool boat = base == "boat-on-waves-3d";
      CHECK(paper.dx() == Approx(boat ? 1.0 / 96.0 : 1.0 / 150.0).epsilon(1e-12));
      for (int ax = 0; ax < 3; ++ax) CHECK(paper.domain.lower[ax] == own.domain.lower[ax]);
      CHECK(paper.domain.upper[1] == own.domain.upper[1]);
      const nlohmann::json& liquid_a = a["liquids"][0]["shape"];
      const nlohmann::json& liquid_b = b["liquids"][0]["shape"];
      CHECK(liquid_a["type"] == "box");
      // the liquid fills the floor of the new box
      for (int ax : {0, 2}) {
        CHECK(liquid_a["center"][ax].get<double>() == Approx(0.5 * paper.domain.upper[ax]));
        CHECK(liquid_a["half_size"][ax].get<double>() == Approx(0.5 * paper.domain.upper[ax]));
      }
      CHECK(liquid_a["center"][1].get<double>() == Approx(liquid_a["half_size"][1].get<double>()));
      const double paper_particles = boat ? 2.8e6 : 8.2e6;
      CHECK(std::abs(box_particles(liquid_a, paper.dx()) / paper_particles - 1.0) < 0.05);
      const double drop = box_top(liquid_b) - box_top(liquid_a);
      CHECK(drop > 0.0);
      std::array<double, 3> shift = {
          0.5 * (paper.domain.upper[0] - own.domain.upper[0]), -drop,
          0.5 * (paper.domain.upper[2] - own.domain.upper[2])};
      REQUIRE(a["bodies"].size() == b["bodies"].size());
      for (size_t i = 0; i < a["bodies"].size(); ++i) {
        nlohmann::json& sa = a["bodies"][i]["shape"];
        nlohmann::json& sb = b["bodies"][i]["shape"];
        INFO(a["bodies"][i]["name"].get<std::string>());
        if (a["bodies"][i]["motion"] == "kinematic") {
          // the board: same x, bottom and height above the surface; the whole new width
          const auto bottom = [](const nlohmann::json& s) {
            return s["center"][1].get<double>() - s["half_size"][1].get<double>();
          };
          const auto top = [](const nlohmann::json& s) {
            return s["center"][1].get<double>() + s["half_size"][1].get<double>();
          };
          CHECK(sa["center"][0] == sb["center"][0]);
          CHECK(sa["half_size"][0] == sb["half_size"][0]);
          CHECK(bottom(sa) == Approx(bottom(sb)));
          CHECK(top(sa) - box_top(liquid_a) == Approx(top(sb) - box_top(liquid_b)));
          CHECK(sa["center"][2].get<double>() == Approx(0.5 * paper.domain.upper[2]));
          CHECK(sa["half_size"][2].get<double>() == Approx(0.5 * paper.domain.upper[2]));
          for (nlohmann::json* s : {&sa, &sb}) {
            s->erase("center");
            s->erase("half_size");
          }
          continue;
        }
        const auto parts_a = shape_parts(sa);
        const auto parts_b = shape_parts(sb);
        REQUIRE(parts_a.size() == parts_b.size());
        for (size_t k = 0; k < parts_a.size(); ++k) {
          for (int ax = 0; ax < 3; ++ax)
            CHECK((*parts_a[k])["center"][ax].get<double>() ==
                  Approx((*parts_b[k])["center"][ax].get<double>() + shift[ax]).margin(1e-12));
          parts_a[k]->erase("center");
          parts_b[k]->erase("center");
        }
      }
      for (nlohmann::json* j : {&a, &b}) {
        (*j)["domain"].erase("upper");
        (*j)["liquids"][0]["shape"].erase("center");
        (*j)["liquids"][0]["shape"].erase("half_size");
      }
    }
    CHECK(a == b);
  }
  CHECK(variants == static_cast<int>(kPaperGrids.size()));
}
