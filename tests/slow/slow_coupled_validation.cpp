// Physical validation of the rigid-liquid coupling, finer 2D grids and 3D (label `slow`): the
// cases of test_coupled_validation.cpp at higher resolution, and their 3D versions. Sources and
// helpers: tests/support/coupled_validation.hpp; measured numbers: docs/validation.md.
#include <catch2/catch.hpp>

#include <cmath>

#include "tests/support/coupled_validation.hpp"

using namespace monolith;
using namespace monolith::validation;
using nlohmann::json;

TEST_CASE("slow: floating boxes and disks at Archimedes' draft on 64^2 (2D)", "[validation][coupling][slow]") {
  // source: Archimedes (run_floating). 64^2 cells, released 0.5 dx above equilibrium, 3 s.
  // Measured (mean - prediction): box s = 0.3 +0.024 dx, 0.5 +0.057 dx, 0.8 +0.021 dx;
  // disk s = 0.3 +0.002 dx, 0.8 -0.035 dx (66 s). Tolerance 0.25 dx, as at 32^2.
  const int n = 64;
  const double dx = 1.0 / n;
  struct Case {
    bool box;
    double s;
  };
  for (const Case c : {Case{true, 0.3}, Case{true, 0.5}, Case{true, 0.8}, Case{false, 0.3}, Case{false, 0.8}}) {
    CAPTURE(c.box, c.s);
    const FloatBody body = c.box ? FloatBody::box(2, 0.12, 0.08, c.s) : FloatBody::ball(2, 0.1, c.s);
    const BuoyancyResult r = run_floating<2>(body, n, 0.5 * dx, 60, 20, "PC-unified");
    WARN("2D " << (c.box ? "box" : "disk") << " s = " << c.s << " on 64^2: mean - Archimedes = "
               << r.error / dx << " dx (range " << r.range / dx << " dx)");
    CHECK(r.converged);
    CHECK(std::abs(r.error) <= 0.25 * dx);
  }
}

TEST_CASE("slow: a plate and a ball at Archimedes' draft (3D)", "[validation][coupling][slow]") {
  // source: Archimedes (run_floating). Plate 0.24 x 0.16 x 0.24 at s = 0.3 and 0.8 on 16^3, ball
  // r = 0.15 at s = 0.5 on 24^3 (3.6 dx), released 0.5 dx above equilibrium, 2 s.
  // Measured: plate s = 0.3 -0.014 dx, s = 0.8 -0.137 dx, ball +0.016 dx (400 s in all).
  // Tolerance 0.25 dx.
  {
    const int n = 16;
    const double dx = 1.0 / n;
    for (double s : {0.3, 0.8}) {
      CAPTURE(s);
      const BuoyancyResult r = run_floating<3>(FloatBody::box(3, 0.12, 0.08, s), n, 0.5 * dx, 40, 20, "PC-unified");
      WARN("3D plate s = " << s << ": mean - Archimedes = " << r.error / dx << " dx (range " << r.range / dx << " dx)");
      CHECK(r.converged);
      CHECK(std::abs(r.error) <= 0.25 * dx);
    }
  }
  {
    const int n = 24;
    const double dx = 1.0 / n;
    const BuoyancyResult r = run_floating<3>(FloatBody::ball(3, 0.15, 0.5), n, 0.5 * dx, 40, 20, "PC-unified");
    WARN("3D ball s = 0.5 on 24^3: mean - Archimedes = " << r.error / dx << " dx (range " << r.range / dx << " dx)");
    CHECK(r.converged);
    CHECK(std::abs(r.error) <= 0.25 * dx);
  }
}

TEST_CASE("slow: a disk settling between two walls on 64 cells per metre (2D)", "[validation][coupling][slow]") {
  // source: Faxen (faxen_terminal_velocity), as the 32-cell case; a = 8 dx. Measured
  // +7.7 % (32 cells: +14.2 %): first-order convergence (61 s). Tolerance 12 %.
  const SettlingResult r = run_settling_disk(64, 0.1);
  const double exact = faxen_terminal_velocity(0.125, 0.5, 1000.0, 1000.0, kG);
  WARN("2D settling disk, a = 8 dx: " << r.velocity << " m/s, Faxen " << exact << " ("
                                      << 100 * (r.velocity / exact - 1) << " %)");
  CHECK(r.converged);
  CHECK(r.velocity == Approx(exact).epsilon(0.12));
}

TEST_CASE("slow: spin-down on 64^2 (2D) and of a ball in a spherical shell on 24^3 (3D)",
          "[validation][coupling][slow]") {
  // source: radial_spin_down (the axisymmetric reduction; steady states are the Couette torques
  // 4 pi mu omega R1^2 R2^2 / (R2^2 - R1^2) and 8 pi mu omega R1^3 R2^3 / (R2^3 - R1^3)).
  // Measured spin lost by 0.2 s against the reference: 2D 64^2 -5.4 % (32^2: -12.4 %),
  // 3D 24^3 (R1 = 3.6 dx) -8.3 % (61 s for both). Tolerances: 8 % (2D, first order from
  // 12.4 %), 15 % (3D, a resolution like the 2D 32^2 case's).
  {
    const SpinResult r = run_spin_down(2, 64, 0.2);
    const double err = (1 - r.omega) / (1 - r.reference) - 1;
    WARN("2D spin-down 64^2: omega " << r.omega << ", reference " << r.reference << ", spin lost "
                                     << 100 * err << " % off");
    CHECK(r.converged);
    CHECK(std::abs(err) <= 0.08);
  }
  {
    const SpinResult r = run_spin_down(3, 24, 0.2);
    const double err = (1 - r.omega) / (1 - r.reference) - 1;
    WARN("3D spin-down 24^3: omega " << r.omega << ", reference " << r.reference << ", spin lost "
                                     << 100 * err << " % off");
    CHECK(r.converged);
    CHECK(std::abs(err) <= 0.15);
  }
}

TEST_CASE("slow: a floating square log takes the energy-minimising tilt (3D, 16^3)",
          "[validation][coupling][slow]") {
  // source: metacentric stability (docs/validation.md): 45 deg for 9/32 < s < 23/32. A square
  // prism L = 0.25 (4 dx), 0.9 m long along z between the end walls, s = 0.5, released at
  // 25 deg in eta = 10 Pa s, 3 s. Measured 43.6 deg (146 s). Tolerance 5 deg (L is only 4 dx).
  const auto [tilt, converged] = square_log(3, 16, 0.5, 25.0, 10.0, 3.0);
  WARN("3D square log s = 0.5 from 25 deg: " << tilt << " deg (energy minimum 45)");
  CHECK(converged);
  CHECK(std::abs(std::abs(tilt) - 45.0) <= 5.0);
}

TEST_CASE("slow: a stone dropped into a pool keeps the volume and the margin (3D, 24^3)",
          "[validation][coupling][slow]") {
  // source: incompressibility and the contact margin (as the 2D case). Ball r = 0.08 (1.9 dx),
  // density 3000, 1.5 s. Measured volume drift 0.22 %, max penetration 0.100 dx,
  // rests at r - epsilon (120 s). Tolerances 1 %, 0.11 dx.
  const int n = 24;
  const double dx = 1.0 / n;
  const DropResult r = run_drop(3, n, 30);
  WARN("3D stone into a pool: volume drift " << 100 * r.volume_drift << " %, max penetration "
                                            << r.penetration / dx << " dx, final height " << r.final_height);
  CHECK(r.converged);
  CHECK(r.landed);
  CHECK(r.volume_drift <= 0.01);
  CHECK(r.penetration <= 0.11 * dx);
}

TEST_CASE("slow: a ball settling at the centre of a spherical container (3D, 24^3)",
          "[validation][coupling][slow]") {
  // source: Stokes drag with the concentric-sphere wall factor (concentric_sphere_factor,
  // checked against the stream-function solution in test_coupled_validation.cpp): a = 0.15 in a
  // container of radius 0.36 (lambda = 0.4167, K = 4.482), density 2000 in eta = 1000 Pa s:
  // U = 2 a^2 (rho_b - rho) g / (9 eta K) = 0.01094 m/s, Reynolds number 0.003. The liquid's
  // start-up (rho (b - a)^2 / eta = 0.044 s) is over by 0.06 s; the ball moves 1.1 mm (0.03 dx) in
  // the 0.1 s run. Measured +14.7 % (12 s); at 32^3 (a = 4.8 dx) +9.6 %, first order as in 2D.
  // Tolerance 20 % (the 2D case has +14.2 % at a = 4 dx).
  const SettlingResult r = run_settling_ball(24, 0.1);
  const double K = concentric_sphere_factor(0.15 / 0.36);
  const double exact = 2 * 0.15 * 0.15 * (2000.0 - kRho) * kG / (9 * 1000.0 * K);
  WARN("3D settling ball, a = 3.6 dx: " << r.velocity << " m/s, Stokes with the wall factor " << exact
                                        << " (" << 100 * (r.velocity / exact - 1) << " %), sideways " << r.sideways);
  CHECK(r.converged);
  CHECK(r.velocity == Approx(exact).epsilon(0.20));
}

TEST_CASE("slow: a ball of the liquid's density stays put up to its buoyancy deficit (3D, 16^3)",
          "[validation][coupling][slow]") {
  // source: Archimedes with the discrete deficit of the 2D case (run_neutral): a ball r = 0.15
  // (2.4 dx) at mid depth; with the added mass of a sphere (rho V / 2; Lamb, Hydrodynamics)
  // it accelerates at 2 g deficit / 3 and sinks by g deficit t^2 / 3 at most.
  // Measured (22 s): deficit 3.4 % (1.25 % the shrinkage 3 zeta / r, the rest the sampling of
  // a 2.4 dx ball), drift 1.70 dx against 1.77 dx predicted, sideways 0.006 dx. Asserted:
  // drift <= predicted + 0.25 dx, as in 2D.
  const int n = 16;
  const double dx = 1.0 / n, seconds = 1.0;
  const NeutralResult res = run_neutral<3>(n, 0.15, 0.01, seconds);
  const double predicted = kG * res.deficit * seconds * seconds / 3.0;
  WARN("3D neutral ball: deficit " << res.deficit << ", drift over 1 s " << res.drift / dx
                                   << " dx (free sinking from the deficit: " << predicted / dx
                                   << " dx), sideways " << res.sideways / dx << " dx");
  CHECK(res.deficit > 0.0);
  CHECK(std::abs(res.drift) <= predicted + 0.25 * dx);
  CHECK(res.sideways <= 0.2 * dx);
}
