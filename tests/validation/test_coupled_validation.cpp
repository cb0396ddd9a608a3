// Physical validation of the rigid-liquid coupling: whole simulations (particles,
// Algorithm 1, eq. (24) solved by PC-unified / PVC-unified) with dynamic and static bodies,
// compared with known answers from outside the project. Every case states its source, the
// measured error and the tolerance; docs/validation.md ("Coupled rigid-liquid") has the table.
// Finer and 3D-heavy versions are in slow_coupled_validation.cpp.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/sim/simulation.hpp"
#include "tests/support/coupled_validation.hpp"

using namespace monolith;
using namespace monolith::validation;
using nlohmann::json;

TEST_CASE("buoyancy: floating boxes and a disk settle at Archimedes' draft (2D)", "[validation][coupling]") {
  // source: Archimedes; a body of density s rho floats with s of its volume below the free
  // surface; the surface height follows from the measured liquid volume plus the displaced
  // volume (run_floating). Bodies released at rest 0.5 dx above equilibrium oscillate with
  // little damping: the mean height over t in [1, 3] s is compared.
  // Box 0.24 x 0.16 (stable flat for every s: B^2 / H^2 = 2.25 > 6 s (1 - s)), disk r = 0.1,
  // tank 1 m wide filled to 0.5 m, 32^2 cells, PC-unified, explicit back end.
  // Measured (mean - prediction): box s = 0.3: +0.034 dx, 0.5: +0.065 dx, 0.8: +0.039 dx;
  // disk s = 0.5: -0.008 dx; box s = 0.5 in a liquid of eta = 1 Pa s under PVC-unified (the
  // stress unknowns at rest must not move the equilibrium): +0.011 dx. The shrinkage
  // zeta = 0.01 dx (section 4.4.6) alone lowers a box by P zeta / B = 0.03 dx; a residual
  // oscillation of 0.4 dx amplitude averaged over 2.5 periods leaves up to ~0.05 dx.
  // Tolerance 0.25 dx.
  const int n = 32;
  const double dx = 1.0 / n;
  struct Case {
    const char* shape;
    double s, eta;
  };
  for (const Case c : {Case{"box", 0.3, 0.0}, Case{"box", 0.5, 0.0}, Case{"box", 0.8, 0.0},
                       Case{"disk", 0.5, 0.0}, Case{"box", 0.5, 1.0}}) {
    CAPTURE(c.shape, c.s, c.eta);
    const FloatBody body = c.shape == std::string("box") ? FloatBody::box(2, 0.12, 0.08, c.s)
                                                         : FloatBody::ball(2, 0.1, c.s);
    const char* scheme = c.eta > 0.0 ? "PVC-unified" : "PC-unified";
    const BuoyancyResult r = run_floating<2>(body, n, 0.5 * dx, 60, 20, scheme, c.eta);
    WARN("2D " << c.shape << " s = " << c.s << ", eta = " << c.eta << " (" << scheme
               << "): mean height - Archimedes = " << r.error / dx << " dx (oscillation range "
               << r.range / dx << " dx), all solves converged " << r.converged);
    CHECK(r.converged);
    CHECK(std::abs(r.error) <= 0.25 * dx);
    // it floats: the oscillation stays within a cell
    CHECK(r.range <= 1.5 * dx);
  }
}

TEST_CASE("buoyancy across a periodic face: a floating disk crosses it afloat (2D)",
          "[validation][coupling]") {
  // source: Archimedes, as the case above, in a tank periodic along x (probe22, twenty-first
  // session). The disk (r = 0.1, s = 0.5) starts on the seam x = 0 at its draft, drifting at
  // -0.3 m/s, so that for the whole run part of it lies beyond a periodic face. Before the fix
  // the body was neither seen at its periodic image nor wrapped: the part beyond the face lost
  // its buoyancy, the disk sank to the floor (mean height 11.6 dx below Archimedes), its centre
  // left the domain (x = -0.35 at the end) and the liquid lost 16 % of its volume. Measured
  // after the fix: mean height - Archimedes -0.04 dx, range 0.33 dx, centre always in [0, 1),
  // final x 0.64. Tolerances as above (0.25 dx, 1.5 dx); volume within 1 %.
  const int n = 32;
  const double dx = 1.0 / n;
  const FloatBody body = FloatBody::ball(2, 0.1, 0.5);
  nlohmann::json j = base_scene(2, {1.0, 1.0}, n, "PC-unified", 20);
  j["domain"]["boundary"]["x-"] = "periodic";
  j["domain"]["boundary"]["x+"] = "periodic";
  j["liquids"].push_back(pool(2, 0.5));
  nlohmann::json shape = body.shape(body.centre_at(0.5) + 0.5 * dx);
  shape["center"][0] = 0.0;
  j["bodies"].push_back({{"name", "floater"}, {"density", 0.5 * 1000.0}, {"shape", shape},
                         {"velocity", {-0.3, 0.0}}});
  const std::vector<FrameStats> s = run_frames(j, 60);
  bool inside = true, crossed = false;
  for (std::size_t f = 1; f < s.size(); ++f) {
    const double x = s[f].bodies[0].position[0];
    inside = inside && x >= 0.0 && x < 1.0;
    crossed = crossed || x > 0.5;  // came back in through x+
  }
  const BuoyancyResult r = floating_result(body, s);
  WARN("periodic seam: mean height - Archimedes = " << r.error / dx << " dx (range " << r.range / dx
                                                    << " dx), final x " << s.back().bodies[0].position[0]);
  CHECK(r.converged);
  CHECK(inside);
  CHECK(crossed);
  CHECK(std::abs(r.error) <= 0.25 * dx);
  CHECK(r.range <= 1.5 * dx);
  CHECK(std::abs(s.back().liquid_volume / s.front().liquid_volume - 1.0) < 0.01);
}

TEST_CASE("Couette flow under a kinematic plate sliding along a periodic channel (2D)",
          "[validation][coupling]") {
  // source: plane Couette flow, u(y) = U y / h between a wall at rest and a plate at speed U
  // (e.g. Batchelor, An Introduction to Fluid Dynamics, section 4.2). The plate is a kinematic
  // box wider than the channel's period (0.6 m in 0.5 m) moving at U = 0.1 m/s without a path
  // offset; the liquid (eta = 100 Pa s, nu = 0.1 m^2/s) fills h = 0.2 m below it, 32 x 16
  // cells, PVC-unified. The start-up decays as exp(-pi^2 nu t / h^2) (0.04 s): after 2 s the
  // profile is steady. Before the periodic images (probe22) the plate slid out of the domain
  // through x+ and no image came in through x-: at 2 s the probes read 19 % (y = 0.05), 13 %
  // and 7 % below U y / h and falling (main 8e47e7b's binary on this scene at cfl 3). Measured
  // after: within 0.07 % at the three probes. Tolerance 2 %.
  nlohmann::json j = base_scene(2, {0.5, 0.25}, 64, "PVC-unified", 20, true, false);
  j["domain"]["boundary"]["x-"] = "periodic";
  j["domain"]["boundary"]["x+"] = "periodic";
  j["solver"]["backend"] = "matrixfree";
  j["liquids"].push_back({{"name", "oil"},
                          {"shape", {{"type", "box"}, {"center", {0.25, 0.1}}, {"half_size", {0.25, 0.1}}}},
                          {"density", 1000.0},
                          {"viscosity", {{"eta", 100.0}}}});
  j["bodies"].push_back({{"name", "plate"}, {"motion", "kinematic"}, {"density", 1000.0},
                         {"shape", {{"type", "box"}, {"center", {0.25, 0.225}}, {"half_size", {0.3, 0.025}}}},
                         {"velocity", {0.1, 0.0}},
                         {"path", {{"axis", {1.0, 0.0}}, {"amplitude", 0.0}, {"frequency", 0.0}}}});
  for (double y : {0.05, 0.1, 0.15})
    j["probes"].push_back({{"name", "y" + std::to_string(y)}, {"position", {0.25, y}}});
  const std::vector<FrameStats> s = run_frames(j, 40);
  bool converged = true;
  for (std::size_t f = 1; f < s.size(); ++f) converged = converged && s[f].solver.converged;
  CHECK(converged);
  for (const auto& probe : s.back().probes) {
    const double expected = 0.1 * probe.position[1] / 0.2;
    WARN("Couette: u(" << probe.position[1] << ") = " << probe.velocity[0] << ", U y / h = " << expected);
    CHECK(std::abs(probe.velocity[0] - expected) <= 0.02 * expected);
  }
}

TEST_CASE("bodies collide across a periodic face: momentum kept, centres wrapped (2D)",
          "[validation][contact]") {
  // source: conservation of momentum in frictionless impacts. Two disks (r = 0.05) and a box
  // (0.1 x 0.1) of density 500 slide on the floor of a channel periodic along x (no liquid):
  // disk a at x = 0.1 moving at -1 m/s crosses the face x = 0 and hits disk b (x = 0.8, at rest)
  // from the right, which then meets the box coming at 0.8 m/s. Before the periodic images
  // (probe22) disk a left the domain and never met b (it ended at x = -0.86 with its -1 m/s).
  // Measured after: a rebounds at +0.352 m/s, b -0.049, the box -0.223; the x momentum
  // 0.0730092 kg m/s per m before and after (frame 1 and 25); tolerance 0.01 of |m v| of one
  // disk.
  nlohmann::json j = base_scene(2, {1.0, 0.5}, 64, "PC-unified", 25, true, false);
  j["domain"]["boundary"]["x-"] = "periodic";
  j["domain"]["boundary"]["x+"] = "periodic";
  auto disk = [](double x, double v) {
    return nlohmann::json{{"density", 500.0}, {"restitution", 0.5}, {"velocity", {v, 0.0}},
                          {"shape", {{"type", "sphere"}, {"center", {x, 0.06}}, {"radius", 0.05}}}};
  };
  j["bodies"].push_back(disk(0.1, -1.0));
  j["bodies"].push_back(disk(0.8, 0.0));
  j["bodies"].push_back({{"density", 500.0}, {"velocity", {0.8, 0.0}},
                         {"shape", {{"type", "box"}, {"center", {0.5, 0.06}}, {"half_size", {0.05, 0.05}}}}});
  const std::vector<FrameStats> s = run_frames(j, 25);
  const double m_disk = 500.0 * kPi * 0.05 * 0.05, m_box = 500.0 * 0.1 * 0.1;
  auto momentum = [&](const FrameStats& f) {
    return m_disk * (f.bodies[0].velocity[0] + f.bodies[1].velocity[0]) + m_box * f.bodies[2].velocity[0];
  };
  bool inside = true;
  for (std::size_t f = 1; f < s.size(); ++f)
    for (const auto& b : s[f].bodies) inside = inside && b.position[0] >= 0.0 && b.position[0] < 1.0;
  const FrameStats& last = s.back();
  WARN("across the seam: velocities " << last.bodies[0].velocity[0] << ", " << last.bodies[1].velocity[0]
                                      << ", " << last.bodies[2].velocity[0] << "; momentum "
                                      << momentum(s[1]) << " -> " << momentum(last));
  CHECK(inside);
  CHECK(last.bodies[0].velocity[0] > 0.1);   // disk a rebounded off b across the seam
  CHECK(last.bodies[2].velocity[0] < 0.0);   // and b passed the impact on to the box
  CHECK(std::abs(momentum(last) - momentum(s[1])) <= 0.01 * m_disk);
}

TEST_CASE("buoyancy: a body of the liquid's density stays put, up to its discrete buoyancy deficit (2D)",
          "[validation][coupling]") {
  // source: Archimedes (zero net force). Section 4.4.7 gives the body its true-geometry mass
  // while the liquid pushes on W_S^u, the shrunk (section 4.4.6) and linearly sampled solid: the
  // buoyancy falls short by rho g (V - V_h), V_h = dx^2 sum over y-faces of W_S^u (exactly the
  // buoyancy of a hydrostatic pressure, docs/coupling.md). A disk r = 0.1 (3.2 dx) at mid depth
  // of a 0.5 m pool, 32^2 cells: (V - V_h) / V = deficit printed below; with the added mass of a
  // circular cylinder (rho pi r^2; Lamb, Hydrodynamics) the body accelerates at
  // g deficit / 2 and sinks by g deficit t^2 / 4 (drag neglected: an upper bound).
  // Measured over 1 s: deficit 1.04 % (zeta = 0.01 dx) and 0.42 % (zeta = 0; the 2D disk's
  // second-order sampling error, docs/coupling.md); drift 0.96 dx and 0.52 dx against the
  // predicted 0.82 dx and 0.33 dx. The deficit explains the drift and its change with zeta; the
  // remaining 0.15-0.19 dx (an extra 0.1 % g, the same with and without shrinkage) is not
  // explained (docs/validation.md). Asserted: drift <= predicted + 0.25 dx, and below 1.2 dx.
  const int n = 32;
  const double dx = 1.0 / n, r = 0.1, seconds = 1.0;
  for (double shrink : {0.01, 0.0}) {
    CAPTURE(shrink);
    const NeutralResult res = run_neutral<2>(n, r, shrink, seconds);
    const double predicted = kG * res.deficit * seconds * seconds / 4.0;
    WARN("2D neutral disk, zeta = " << shrink << " dx: buoyancy deficit (V - V_h) / V = "
                                    << res.deficit << ", drift over 1 s " << res.drift / dx
                                    << " dx (free sinking from the deficit: " << predicted / dx
                                    << " dx), sideways " << res.sideways / dx << " dx");
    CHECK(res.deficit > 0.0);
    CHECK(std::abs(res.drift) <= predicted + 0.25 * dx);
    CHECK(std::abs(res.drift) <= 1.2 * dx);
    CHECK(std::abs(res.sideways) <= 0.2 * dx);
  }
}

TEST_CASE("a floating square log takes the tilt that minimises its potential energy (2D)",
          "[validation][coupling]") {
  // source: metacentric stability (docs/validation.md derives it; e.g. Erdos, Schibler & Herndon,
  // Am. J. Phys. 60 (1992) 335): flat is stable for s < (3 - sqrt 3) / 6 = 0.2113 or
  // s > 0.7887, a corner down (45 deg) for 9/32 < s < 23/32. Released 20 deg off the prediction
  // in a liquid of eta = 10 Pa s (damping: the roll settles in about 2.5 s), 40^2 cells
  // (L = 10 dx), 3 s. Measured: s = 0.5 from 25 deg -> 45.19 deg; s = 0.15 from 20 deg -> 0.01
  // deg. A tilt error e moves the centre of buoyancy by about L e / 6 (a fraction of a cell for
  // a few degrees) and the discrete buoyancy of a box is sampled with errors of ~1 % (docs/
  // coupling.md): tolerance 3 deg.
  const int n = 40;
  {
    const auto [tilt, converged] = square_log(2, n, 0.5, 25.0, 10.0, 3.0);
    WARN("square log s = 0.5 released at 25 deg: settles at " << tilt << " deg (energy minimum 45)");
    CHECK(converged);
    CHECK(std::abs(std::abs(tilt) - 45.0) <= 3.0);
  }
  {
    const auto [tilt, converged] = square_log(2, n, 0.15, 20.0, 10.0, 3.0);
    WARN("square log s = 0.15 released at 20 deg: settles at " << tilt << " deg (energy minimum 0)");
    CHECK(converged);
    CHECK(std::abs(tilt) <= 3.0);
  }
}

TEST_CASE("uniform free fall of liquid and a body: zero pressure, body acceleration g (Fig. 8)",
          "[validation][coupling]") {
  // source: section 4.4.1 (Fig. 8): with everything falling at one velocity, b1 = b2 = 0 and the
  // solve returns zero pressure and stress; the body accelerates at exactly g. A liquid disk /
  // ball (r = 0.25) holding a box (density 700) in a domain open on every side, 0.25 s.
  // Viscous (eta = 10, PVC-unified) and inviscid (PC-unified): measured |p| <= 2.0e-12 Pa (2D),
  // 5.4e-13 Pa (3D), body velocity g t to 4e-17 / 1.1e-16 relative. Tolerances: 1e-9 rho g dx on
  // p, 1e-12 on the velocity. (Before u* was extrapolated into the air for the pressure-only path
  // too, the inviscid runs read air at rest on the surface cells' faces towards the air and felt
  // 0.039 Pa / 0.025 Pa, ~1e-4 rho g dx, with a velocity error of 2.6e-5.)
  for (int dim : {2, 3}) {
    for (const char* scheme : {"PVC-unified", "PC-unified"}) {
      CAPTURE(dim, scheme);
      const bool viscous = std::string(scheme) == "PVC-unified";
      const int n = dim == 2 ? 32 : 16;
      const double dx = 1.0 / n, fps = 20;
      json j = base_scene(dim, std::vector<double>(dim, 1.0), n, scheme, fps);
      for (const char* side : {"x-", "x+", "y-", "y+", "z-", "z+"})
        if (j["domain"]["boundary"].contains(side)) j["domain"]["boundary"][side] = "open";
      j["liquids"].push_back({{"name", "blob"},
                              {"shape", {{"type", "sphere"}, {"center", point(dim, 0.5, 0.6)}, {"radius", 0.25}}},
                              {"density", kRho},
                              {"viscosity", {{"eta", viscous ? 10.0 : 0.0}}}});
      j["bodies"].push_back({{"name", "box"},
                             {"density", 700.0},
                             {"shape", {{"type", "box"}, {"center", point(dim, 0.5, 0.6)},
                                        {"half_size", dim == 2 ? json{0.08, 0.05} : json{0.08, 0.05, 0.08}}}}});
      for (int k = 0; k < 5; ++k)
        j["probes"].push_back({{"name", "p" + std::to_string(k)}, {"position", point(dim, 0.35 + 0.075 * k, 0.5)}});
      const std::vector<FrameStats> s = run_frames(j, 4);
      double p_max = 0.0, v_err = 0.0;
      for (std::size_t f = 1; f < s.size(); ++f) {
        REQUIRE(s[f].solver.converged);
        for (const auto& p : s[f].probes) p_max = std::max(p_max, std::abs(p.pressure));
        const double expected = -kG * s[f].time;
        v_err = std::max(v_err, std::abs(s[f].bodies[0].velocity[1] / expected - 1.0));
        for (int a = 0; a < dim; ++a)
          if (a != 1) v_err = std::max(v_err, std::abs(s[f].bodies[0].velocity[a] / expected));
      }
      WARN(dim << "D free fall, " << scheme << ": max |p| at the probes " << p_max
               << " Pa (rho g dx = " << kRho * kG * dx << "), body velocity relative error " << v_err);
      CHECK(p_max <= 1e-9 * kRho * kG * dx);
      CHECK(v_err <= 1e-12);
    }
  }
}

TEST_CASE("a heavy disk dropped into a tank: liquid volume kept, penetration within the margin (2D)",
          "[validation][coupling]") {
  // source: incompressibility (the volume), and the contact margin epsilon = 0.1 dx of section
  // 3.2.4 (no deeper penetration). A disk r = 0.08 of density 3000 falls 0.17 m onto a pool
  // 0.4 m deep, sinks and lands on the floor, PC-unified, 32^2 cells, 1.5 s. Measured: worst
  // volume drift 0.30 %, max penetration 0.100 dx. Tolerances: 1 % (the bound of the liquid-only
  // runs, docs/validation.md "Volume"), 0.11 dx (the margin plus 10 %).
  const int n = 32;
  const double dx = 1.0 / n;
  const DropResult r = run_drop(2, n, 30);
  WARN("2D stone into a pool: worst volume drift " << 100 * r.volume_drift << " %, max penetration "
                                                  << r.penetration / dx << " dx, final height "
                                                  << r.final_height);
  CHECK(r.converged);
  CHECK(r.landed);
  CHECK(r.volume_drift <= 0.01);
  CHECK(r.penetration <= 0.11 * dx);
  // it rests on the floor: centre at r minus at most the margin
  CHECK(std::abs(r.final_height - 0.08) <= 0.11 * dx);
}

TEST_CASE("a heavy disk settling between two walls reaches Faxen's terminal velocity (2D)",
          "[validation][coupling]") {
  // source: Faxen's drag on a cylinder midway between two plane walls (Faxen 1946, as quoted by
  // Happel & Brenner 1965; faxen_terminal_velocity): a = 0.125 between walls 1 m apart (k = 0.25), density 2000 in
  // eta = 1000 Pa s: U = 0.02192 m/s, Reynolds number rho U 2a / eta = 0.005. Liquid 1.8 m deep,
  // disk centre at 1 m. The liquid's own start-up (rho h^2 / eta = 0.25 s) is mostly over by
  // 0.05 s; the mean velocity over the frames t = 0.07 .. 0.1 s is compared. Measured: 32 cells per metre
  // (a = 4 dx) +3.9 % since the cut faces hold the liquid to the body (docs/derivations.md
  // departures item 24; +11.7 % before it, +13.6 % in older trees; 64 cells per metre +9 % before
  // it, slow_coupled_validation.cpp). An error of 0.3 dx in the effective radius changes K by 13 %
  // at a = 4 dx. Tolerance 8 %. (Without the walls' correction, i.e. K = ln(1/k) - 0.9157 alone,
  // U would be 0.0180 m/s, 18 % lower: the walls matter at this k.)
  const SettlingResult r = run_settling_disk(32, 0.1);
  const double exact = faxen_terminal_velocity(0.125, 0.5, 1000.0, 1000.0, kG);
  WARN("2D settling disk, a = 4 dx: terminal velocity " << r.velocity << " m/s, Faxen " << exact
                                                        << " (" << 100 * (r.velocity / exact - 1)
                                                        << " %), sideways drift " << r.sideways);
  CHECK(r.converged);
  CHECK(r.velocity == Approx(exact).epsilon(0.08));
  CHECK(std::abs(r.sideways) <= 1e-3 * r.velocity);
}

TEST_CASE("a disk spinning in a viscous liquid inside a ring spins down as the Couette flow says (2D)",
          "[validation][coupling]") {
  // source: the axisymmetric Navier-Stokes reduction (radial_spin_down: body, liquid initially
  // at rest, fixed container; its steady state is the Couette torque 4 pi mu omega R1^2 R2^2 /
  // (R2^2 - R1^2)). Disk R1 = 0.15 (density 1e5, so the spin-down time 0.5 s is long against the
  // viscous time rho (R2 - R1)^2 / mu = 0.08 s), static shell of inner radius R2 = 0.35, liquid
  // eta = 500 filling the gap, gravity off, 32^2 cells (R1 = 4.8 dx, gap 6.4 dx), 0.2 s.
  // Measured: omega(0.2 s) = 0.653 against the reference 0.641, i.e. spin lost 0.347 against
  // 0.359 (-3.3 %) since the cut faces hold the liquid to the body (docs/derivations.md
  // departures item 24; before it 0.682, -11.3 %, and -5.4 % at 64^2, slow_coupled_validation.cpp).
  // Tolerance on the spin lost: 8 % at 32^2.
  const SpinResult r = run_spin_down(2, 32, 0.2);
  WARN("2D spin-down, 32^2: omega(" << r.time << " s) = " << r.omega << ", reference " << r.reference
                                   << ": spin lost " << 1 - r.omega << " against " << 1 - r.reference
                                   << " (" << 100 * ((1 - r.omega) / (1 - r.reference) - 1) << " %)");
  CHECK(r.converged);
  CHECK((1 - r.omega) == Approx(1 - r.reference).epsilon(0.08));
  // the disk stays centred
  CHECK(r.offset <= 0.05 / 32);
}

TEST_CASE("the radial spin-down reference reaches the Couette torque in the quasi-steady limit",
          "[unit][validation]") {
  // source: the steady Couette torques (Landau & Lifshitz, Fluid Mechanics, Couette flow): 2D 4 pi mu R1^2 R2^2 /
  // (R2^2 - R1^2), 3D 8 pi mu R1^3 R2^3 / (R2^3 - R1^3) per unit omega. With a body much heavier
  // than the liquid the decay is exp(-T t / (I + I_L)), I_L the angular momentum of the Couette
  // liquid per unit omega (2D: pi rho R1^2 (R2^2 - R1^2) / 2; 3D: evaluated from the steady
  // profile f = A r + B / r^2 numerically here). The reference's decay rate after the start-up
  // agrees to 0.2 % (measured 2D 0.02 %, 3D 0.03 %).
  const double r1 = 0.15, r2 = 0.35, rho = 1000.0, mu = 500.0;
  for (int dim : {2, 3}) {
    CAPTURE(dim);
    const double inertia = dim == 2 ? 1e7 * kPi * std::pow(r1, 4) / 2 : 1e7 * 8.0 / 15.0 * kPi * std::pow(r1, 5);
    double torque = 0.0, liquid = 0.0;
    if (dim == 2) {
      torque = 4 * kPi * mu * r1 * r1 * r2 * r2 / (r2 * r2 - r1 * r1);
      liquid = kPi * rho * r1 * r1 * (r2 * r2 - r1 * r1) / 2;
    } else {
      torque = 8 * kPi * mu * std::pow(r1 * r2, 3) / (std::pow(r2, 3) - std::pow(r1, 3));
      // f = A r + B / r^2 with f(r1) = r1, f(r2) = 0; L = int rho f sin(theta) r sin(theta) dV
      const double B = std::pow(r1 * r2, 3) / (std::pow(r2, 3) - std::pow(r1, 3));
      const double A = -B / std::pow(r2, 3);
      const int m = 20000;
      for (int k = 0; k < m; ++k) {
        const double r = r1 + (k + 0.5) * (r2 - r1) / m;
        liquid += rho * (A * r + B / (r * r)) * r * r * r * (8.0 * kPi / 3.0) * (r2 - r1) / m;
      }
    }
    const double rate = torque / (inertia + liquid);
    const std::vector<double> w = radial_spin_down(dim, r1, r2, rho, mu, inertia, 1.0, {1.0, 2.0}, 200, 1e-3);
    const double measured = std::log(w[0] / w[1]);
    WARN(dim << "D radial reference: decay rate " << measured << " against " << rate);
    CHECK(measured == Approx(rate).epsilon(0.002));
  }
}

TEST_CASE("buoyancy: a floating plate settles at Archimedes' draft (3D, 16^3)", "[validation][coupling]") {
  // source: Archimedes, as the 2D case (run_floating): a plate 0.24 x 0.16 x 0.24 of density
  // 500 in a 1 m^3 tank filled to 0.5 m, 16^3 cells (the plate 2.6 dx thick), released 0.5 dx
  // above equilibrium, 2 s; mean over t in [0.7, 2] s. Measured -0.004 dx (oscillation range
  // 0.74 dx; -0.07 dx over 3 s). Tolerance 0.25 dx, as in 2D.
  const int n = 16;
  const double dx = 1.0 / n;
  const BuoyancyResult r = run_floating<3>(FloatBody::box(3, 0.12, 0.08, 0.5), n, 0.5 * dx, 40, 20, "PC-unified");
  WARN("3D plate s = 0.5: mean height - Archimedes = " << r.error / dx << " dx (range " << r.range / dx << " dx)");
  CHECK(r.converged);
  CHECK(std::abs(r.error) <= 0.25 * dx);
  CHECK(r.range <= 1.5 * dx);
}

TEST_CASE("the concentric-sphere wall factor equals the stream-function solution", "[unit][validation]") {
  // source: Stokes flow between concentric spheres, the inner one translating (Happel & Brenner
  // 1965, chapter 4): the closed form of concentric_sphere_factor against the 4 x 4 solve of
  // the stream function's boundary-value problem; lambda -> 0 gives Stokes' drag. Measured
  // agreement 1e-15 relative; bound 1e-12.
  for (double lambda : {0.1, 0.25, 0.375, 0.5}) {
    CAPTURE(lambda);
    CHECK(concentric_sphere_factor(lambda) ==
          Approx(concentric_sphere_factor_from_stream_function(lambda)).epsilon(1e-12));
  }
  CHECK(concentric_sphere_factor(1e-6) == Approx(1.0).epsilon(1e-5));
}
