// The paper's claims about the partitioned schemes (section 6.1.1, Fig. 2), measured on whole
// simulations: liquid poured into a light dynamic bowl that rests on the floor. P-C (pressure,
// then contact) loses liquid volume, C-P (contact, then pressure) lets the bowl sink into the
// floor, PC-unified keeps both. Solver-level versions of the same claims (one step, divergence
// and contact residuals) are in test_coupled_schemes.cpp and notebooks_cpp/11_nine_schemes.cpp;
// the scenes' per-scheme table is in docs/scenes.md.
#include <catch2/catch.hpp>

#include <algorithm>
#include <initializer_list>
#include <map>
#include <string>

#include "reference/app/scene_file.hpp"
#include "reference/sim/simulation.hpp"

using namespace monolith;
using nlohmann::json;

namespace {

struct Outcome {
  double volume_drift = 0.0;     ///< liquid volume at the end / at frame 0 - 1
  double max_penetration = 0.0;  ///< max over frames of contacts.max_penetration (m)
  bool converged = true;
};

/// A 2D analogue of Fig. 2 at 32^2: a block of water (0.24 x 0.3 m) falls into a bowl of
/// density 200 (outer radius 0.28 m, 0.04 m thick) resting on the floor, under `scheme`. The
/// particle position correction is off: its grid density projection (docs/particles.md)
/// restores the particle volume whatever the solve did, which would hide the schemes' own
/// volume drift.
Outcome run(const std::string& scheme, double eta = 0.0) {
  json j = json::parse(R"({
    "format": "monolith-scene/1", "name": "scheme-claims", "dim": 2,
    "domain": {"lower": [0, 0], "upper": [1, 1], "cells": [32, 32]},
    "time": {"fps": 25, "frames": 10, "cfl": 2.0, "max_dt": 0.01},
    "solver": {"backend": "explicit", "staggered_iterations": 2},
    "particles": {"position_correction": false},
    "liquids": [{"name": "water", "density": 1000,
                 "shape": {"type": "box", "center": [0.5, 0.55], "half_size": [0.12, 0.15]}}],
    "bodies": [{"name": "bowl", "motion": "dynamic", "density": 200,
                "shape": {"type": "bowl", "center": [0.5, 0.3], "radius": 0.28, "thickness": 0.04}}],
    "render": {"enabled": false}
  })");
  j["solver"]["scheme"] = scheme;
  j["liquids"][0]["viscosity"] = {{"model", "newtonian"}, {"eta", eta}};
  const SceneDesc scene = parse_scene(j, "scheme-claims.json", ".");
  auto sim = make_simulation(scene);
  Outcome o;
  const double v0 = sim->current_stats().liquid_volume;
  for (int f = 0; f < scene.time.frames; ++f) {
    const FrameStats s = sim->advance_frame();
    o.max_penetration = std::max(o.max_penetration, s.max_penetration);
    o.converged = o.converged && s.solver.converged;
    o.volume_drift = s.liquid_volume / v0 - 1.0;
  }
  return o;
}

constexpr double kDx = 1.0 / 32;

/// run() under each of `schemes` with viscosity eta, each outcome printed (drift, penetration).
std::map<std::string, Outcome> run_schemes(std::initializer_list<const char*> schemes, double eta = 0.0) {
  std::map<std::string, Outcome> r;
  for (const char* scheme : schemes) r[scheme] = run(scheme, eta);
  for (const auto& [name, o] : r)
    WARN(name << ": volume drift " << 100 * o.volume_drift << " %, max penetration "
              << o.max_penetration / kDx << " dx, converged " << o.converged);
  return r;
}

}  // namespace

TEST_CASE("P-C loses liquid volume, C-P lets the bowl penetrate the floor, PC-unified keeps both (2D, Fig. 2)",
          "[validation][coupling][schemes]") {
  std::map<std::string, Outcome> r = run_schemes({"P-C", "C-P", "PC-unified"});
  const double dx = kDx;
  // Measured (10 frames, 0.4 s; the splash into the bowl starts at frame 6):
  //   P-C -61.0 %, C-P -18.2 %, PC-unified -23.3 % volume; penetration P-C 0.102 dx,
  //   C-P 1.74 dx, PC-unified 0.103 dx (the contact margin is 0.1 dx).
  // The drift common to all three is the particle surface of the splash without position
  // correction; P-C adds the volume its concluding contact solve removes from the liquid
  // (the bowl is pushed back up against liquid made divergence-free for the old bowl velocity).
  CHECK(r["PC-unified"].converged);
  // P-C: at least 20 points more volume lost than PC-unified (measured 38)
  CHECK(r["P-C"].volume_drift < r["PC-unified"].volume_drift - 0.20);
  // C-P: the bowl ends up more than a cell inside the floor (measured 1.74 dx); P-C and
  // PC-unified stay within the margin plus round-off of the contact solve (0.1 dx + 0.05 dx)
  CHECK(r["C-P"].max_penetration > 1.0 * dx);
  CHECK(r["P-C"].max_penetration < 0.15 * dx);
  CHECK(r["PC-unified"].max_penetration < 0.15 * dx);
}

TEST_CASE("PV-C loses liquid volume, C-PV lets the bowl penetrate the floor, PVC-unified keeps both (2D, Fig. 6)",
          "[validation][coupling][schemes]") {
  // the same scene with a viscous liquid (eta = 2 Pa s), as Fig. 6 drops a viscous shape into a
  // light bowl on the ground (section 6.3.1)
  std::map<std::string, Outcome> r = run_schemes({"PV-C", "C-PV", "PVC-unified"}, 2.0);
  const double dx = kDx;
  // Measured (10 frames): PV-C -56.4 %, C-PV -19.4 %, PVC-unified -23.7 % volume;
  // penetration PV-C 0.102 dx, C-PV 1.56 dx, PVC-unified 0.104 dx.
  CHECK(r["PVC-unified"].converged);
  // PV-C: at least 20 points more volume lost than PVC-unified (measured 33)
  CHECK(r["PV-C"].volume_drift < r["PVC-unified"].volume_drift - 0.20);
  CHECK(r["C-PV"].max_penetration > 1.0 * dx);
  CHECK(r["PV-C"].max_penetration < 0.15 * dx);
  CHECK(r["PVC-unified"].max_penetration < 0.15 * dx);
}
