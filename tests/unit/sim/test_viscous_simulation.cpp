// Viscous liquids in the whole simulation (particles, Algorithm 1): a rigidly rotating free blob
// keeps its angular velocity, a film on a wall under gravity along it stays attached with the
// half-parabolic profile, two liquids of different viscosity in one scene each behave as their
// own viscosity says, and the scheme picks the solves (2D and 3D).
#include <catch2/catch.hpp>
#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/fluid/viscosity_field.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/particles/particles.hpp"
#include "reference/sim/simulation.hpp"

using namespace monolith;

namespace {

nlohmann::json base_scene(int dim, const std::vector<double>& upper, const std::vector<int>& cells) {
  nlohmann::json j;
  j["format"] = "monolith-scene/1";
  j["dim"] = dim;
  j["domain"]["lower"] = std::vector<double>(dim, 0.0);
  j["domain"]["upper"] = upper;
  j["domain"]["cells"] = cells;
  j["solver"] = {{"tolerance", 1e-8}, {"max_iterations", 20000}, {"backend", "matrixfree"}};
  j["render"] = {{"enabled", false}};
  j["probes"] = nlohmann::json::array();
  return j;
}

std::unique_ptr<AnySimulation> build(const nlohmann::json& j) {
  return make_simulation(parse_scene(j, "test.json", "."));
}

/// A free blob (disk / ball of radius 0.2 at the centre of the unit box, no gravity) in rigid
/// rotation at omega about z; probes on a ring of radius 0.1 in the plane z = 0.5. Returns the
/// mean angular velocity sum (r x v)_z / r^2 over the probes after each frame.
std::vector<double> rotating_blob(int dim, int n, const std::string& scheme, int frames,
                                  double eta, double omega) {
  nlohmann::json j = base_scene(dim, std::vector<double>(dim, 1.0), std::vector<int>(dim, n));
  j["gravity"] = std::vector<double>(dim, 0.0);
  j["time"] = {{"fps", 50}, {"frames", frames}, {"cfl", 1.0}, {"max_dt", 0.02}};
  j["solver"]["scheme"] = scheme;
  nlohmann::json spin = omega;
  if (dim == 3) spin = std::vector<double>{0.0, 0.0, omega};
  j["liquids"] = {{{"name", "blob"},
                   {"shape", {{"type", "sphere"}, {"center", std::vector<double>(dim, 0.5)}, {"radius", 0.2}}},
                   {"density", 1000.0},
                   {"angular_velocity", spin},
                   {"viscosity", {{"eta", eta}}}}};
  const double r = 0.1;
  for (int k = 0; k < 8; ++k) {
    std::vector<double> x(dim, 0.5);
    x[0] += r * std::cos(k * 3.14159265358979 / 4);
    x[1] += r * std::sin(k * 3.14159265358979 / 4);
    j["probes"].push_back({{"name", "p" + std::to_string(k)}, {"position", x}});
  }
  auto sim = build(j);
  std::vector<double> omegas;
  for (int f = 0; f < frames; ++f) {
    const FrameStats s = sim->advance_frame();
    REQUIRE(s.solver.converged);
    double sum = 0.0;
    for (const auto& p : s.probes) {
      const double dx = p.position[0] - 0.5, dy = p.position[1] - 0.5;
      sum += (dx * p.velocity[1] - dy * p.velocity[0]) / (dx * dx + dy * dy);
    }
    omegas.push_back(sum / s.probes.size());
  }
  return omegas;
}

}  // namespace

TEST_CASE("a rigidly rotating free viscous blob keeps its angular velocity (2D and 3D)",
          "[validation]") {
  // source: a rigid rotation has zero strain rate, so the viscous stress of eq. (5) vanishes and
  // a free liquid body keeps its angular momentum (docs/validation.md lists the measured losses;
  // the paper's claim is that the unified solve has no artificial damping of rigid motion).
  const double omega = 2.0, eta = 10.0;
  for (int dim : {2, 3}) {
    const int n = dim == 2 ? 40 : 24, frames = 10;
    const auto unified = rotating_blob(dim, n, "PVC-unified", frames, eta, omega);
    const auto decoupled = rotating_blob(dim, n, "PC-VC-PC-unified", frames, eta, omega);
    const auto inviscid = rotating_blob(dim, n, "PVC-unified", frames, 0.0, omega);
    const double loss_unified = 1.0 - unified.back() / omega;
    const double loss_decoupled = 1.0 - decoupled.back() / omega;
    const double loss_inviscid = 1.0 - inviscid.back() / omega;
    WARN(dim << "D rotating blob, eta " << eta << ", " << frames << " frames: angular velocity lost "
             << 100 * loss_unified << " % (PVC-unified), " << 100 * loss_decoupled
             << " % (PC-VC-PC-unified), " << 100 * loss_inviscid << " % (inviscid)");
    // the transfers, advection and the discrete surface lose some rotation with or without
    // viscosity (the inviscid run); the viscous stress adds only a little to that. Measured over
    // 10 frames (0.2 s at 2 rad/s: 0.4 rad of rotation): inviscid 0.65 % (2D) and
    // 4.74 % (3D); viscous (eta 10) PVC-unified 0.90 % / 4.81 %, PC-VC-PC-unified 0.90 % / 4.79 %.
    // The extra 0.25 % / 0.07 % comes from the surface: stress DOFs straddling it read the air
    // faces, whose u* is extrapolated (simulation.cpp, kAirVelocityLayers; the first layer exact
    // for a linear field since spin23, before it 0.26 % / 0.08 %). Without that extrapolation
    // (air faces at rest) the extra loss was 0.40 % / 0.20 %. With the dry faces of the surface
    // stencils clamped (departures item 23; surf24): 0.87 % / 4.89 %, extra 0.22 % / 0.16 %.
    // Bound: 0.4 %.
    CHECK(loss_unified - loss_inviscid < 0.004);
  }
}

TEST_CASE("a very viscous rotating blob loses little more spin than an inviscid one (2D)",
          "[validation]") {
  // source: as above (zero strain rate under rigid rotation), at a large eta where the air faces'
  // u* dominates: the surface's stress DOFs read the first air layer (b1 of eq. (24)), filled by
  // extrapolate_air_velocity exactly for a linear field (departures item 22). With neighbour
  // averaging there (before spin23) the excess loss here was 2.76 %; after it 1.77 %. The dry
  // faces those DOFs read were prescribed velocities (W_L^u = 0); with W_L^u clamped on them
  // (clamp_stressed_face_weights, departures item 23: no traction at the surface) 1.41 %.
  const double omega = 3.0;
  const int n = 32, frames = 10;
  const auto viscous = rotating_blob(2, n, "PVC-unified", frames, 200.0, omega);
  const auto inviscid = rotating_blob(2, n, "PVC-unified", frames, 0.0, omega);
  const double excess = (1.0 - viscous.back() / omega) - (1.0 - inviscid.back() / omega);
  WARN("2D rotating blob, eta 200, " << frames << " frames at " << n
                                     << "^2: angular velocity lost beyond the inviscid run "
                                     << 100 * excess << " %");
  CHECK(excess < 0.016);
}

namespace {

/// A film of thickness h on the floor of a domain periodic along x (and z), open at the top,
/// gravity tilted by angle theta towards +x. Probes on a vertical line; returns the probe speeds
/// along x at the last frame and their heights.
struct FilmResult {
  std::vector<double> y, u;
  double top = 0.0;  ///< highest particle (the film surface)
  double depth = 0.0;  ///< the liquid's volume over the floor's area (the film's mean depth)
  double kinetic = 0.0;  ///< the liquid's kinetic energy at the last frame
  double width = 0.0;  ///< the domain's extent along x (and z)
};

FilmResult film(int dim, int n, double h, double eta, double sin_theta, double seconds,
                const std::string& backend = "matrixfree") {
  // the flow does not depend on x (and z): 4 periodic cells along them are enough
  const double width = 4 * 0.5 / n;
  std::vector<double> upper(dim, width);
  upper[1] = 0.5;
  std::vector<int> cells(dim, 4);
  cells[1] = n;
  nlohmann::json j = base_scene(dim, upper, cells);
  j["solver"]["backend"] = backend;
  j["domain"]["boundary"] = {{"x-", "periodic"}, {"x+", "periodic"}, {"y-", "wall"}, {"y+", "open"}};
  if (dim == 3) {
    j["domain"]["boundary"]["z-"] = "periodic";
    j["domain"]["boundary"]["z+"] = "periodic";
  }
  const double g = 9.81, cos_theta = std::sqrt(1 - sin_theta * sin_theta);
  std::vector<double> gravity(dim, 0.0);
  gravity[0] = g * sin_theta;
  gravity[1] = -g * cos_theta;
  j["gravity"] = gravity;
  const int fps = 10;
  j["time"] = {{"fps", fps}, {"frames", 1}, {"cfl", 2.0}, {"max_dt", 0.02}};
  std::vector<double> centre(dim, width / 2), half(dim, width);
  centre[1] = h / 2;
  half[1] = h / 2;
  j["liquids"] = {{{"name", "film"},
                   {"shape", {{"type", "box"}, {"center", centre}, {"half_size", half}}},
                   {"density", 1000.0},
                   {"viscosity", {{"eta", eta}}}}};
  const double dx = 0.5 / n;
  FilmResult r;
  for (int k = 0; (k + 0.5) * dx < h - dx; ++k) {
    std::vector<double> x(dim, width / 2 + 0.5 * dx);
    x[1] = (k + 0.5) * dx;
    r.y.push_back(x[1]);
    j["probes"].push_back({{"name", "y" + std::to_string(k)}, {"position", x}});
  }
  auto sim = build(j);
  FrameStats s;
  for (int f = 0; f < static_cast<int>(std::lround(seconds * fps)); ++f) {
    s = sim->advance_frame();
    REQUIRE(s.solver.converged);
    REQUIRE(s.solver.dofs_stress > 0);
  }
  for (const auto& p : s.probes) r.u.push_back(p.velocity[0]);
  r.top = s.liquid_bounds_upper[1];
  r.width = width;
  r.depth = s.liquid_volume / std::pow(width, dim - 1);
  r.kinetic = s.kinetic_energy_liquid;
  return r;
}

}  // namespace

TEST_CASE("a viscous film on a wall under gravity along it stays attached with the film-flow profile",
          "[validation]") {
  // source: steady gravity-driven film flow down an incline (Nusselt film; e.g. Bird, Stewart &
  // Lightfoot, Transport Phenomena, section 2.2): u(y) = (g sin(theta) / nu) (h y - y^2 / 2),
  // no slip at the wall (y = 0), no shear at the free surface (y = h). After 5 viscous times
  // h^2 / nu the start-up transient has decayed to exp(-4 pi^2 / 4) = 5e-5.
  const double h = 0.125, eta = 20.0, sin_theta = 0.1, nu = eta / 1000.0;
  const double seconds = 4 * h * h / nu;
  for (int dim : {2, 3}) {
    CAPTURE(dim);
    const int n = 64;
    const FilmResult r = film(dim, n, h, eta, sin_theta, seconds);
    const double g = 9.81 * sin_theta;
    double err = 0.0, u_max = 0.0;
    for (std::size_t k = 0; k < r.y.size(); ++k) {
      const double exact = g / nu * (h * r.y[k] - r.y[k] * r.y[k] / 2);
      err = std::max(err, std::abs(r.u[k] - exact));
      u_max = std::max(u_max, exact);
    }
    WARN(dim << "D film flow: relative max error of the profile " << err / u_max
             << ", bottom probe speed " << r.u.front() << " m/s (exact "
             << g / nu * (h * r.y.front() - r.y.front() * r.y.front() / 2) << "), film top "
             << r.top);
    // attached: the liquid stays a film on the floor
    CHECK(r.top < 1.5 * h);
    CHECK(err / u_max < 0.05);
  }
}

TEST_CASE("a film whose depth is not a whole number of cells flows at Nusselt's speed: no "
          "traction at its surface (both back ends)",
          "[validation]") {
  // source: the Nusselt film as above, u(y) = (g sin(theta) / nu) (h y - y^2 / 2), with h the
  // film's mean depth (its measured volume over the floor: the seeding and the level set leave
  // it 0.7 % above the box it was seeded in). At 12.8 cells the stress DOFs straddling the
  // surface read dry faces above it (W_L^u = 0, no liquid cell beside them); without
  // clamp_stressed_face_weights those faces were prescribed velocities (u* of the air), a lid
  // that dragged the film: main a10d2ef ran +5.8 % at the top probe, +4.2 % at mid-depth, kinetic
  // energy +10.1 % (both back ends; 64 cells wide instead of 4: +30 %). With the clamp: -0.13 %,
  // -0.08 %, -0.73 % (docs/derivations.md, departures item 23). 2 s are 2.5 viscous times
  // h^2 / nu: the start-up has decayed to 2e-3 of the profile.
  const double h = 0.2, eta = 50.0, sin_theta = 0.2, nu = eta / 1000.0, g = 9.81 * sin_theta;
  for (const std::string backend : {"matrixfree", "explicit"}) {
    CAPTURE(backend);
    const FilmResult r = film(2, 32, h, eta, sin_theta, 2.0, backend);
    const double d = r.depth;
    const auto exact = [&](double y) { return g / nu * (d * y - y * y / 2); };
    // the highest probe (1.5 dx below the seeded top) and the one nearest mid-depth
    const std::size_t top = r.y.size() - 1, mid = r.y.size() / 2;
    const double top_err = r.u[top] / exact(r.y[top]) - 1, mid_err = r.u[mid] / exact(r.y[mid]) - 1;
    // 1/2 rho W (g/nu)^2 (2/15) d^5 per unit length along z
    const double kinetic = 0.5 * 1000.0 * r.width * (g / nu) * (g / nu) * 2.0 / 15.0 * std::pow(d, 5);
    const double ke_err = r.kinetic / kinetic - 1;
    WARN("film at 12.8 cells (" << backend << "): depth " << d << ", top probe " << 100 * top_err
                                << " %, mid-depth " << 100 * mid_err << " %, kinetic energy "
                                << 100 * ke_err << " % off Nusselt");
    CHECK(std::abs(top_err) < 0.02);
    CHECK(std::abs(mid_err) < 0.02);
    CHECK(std::abs(ke_err) < 0.03);
  }
}

namespace {

/// Two columns collapsing on either side of a static dividing wall, liquid A on the left with
/// viscosity eta_left, B on the right with eta_right; a probe in each at the same place relative
/// to its column. Returns the two probes' speeds after `frames` frames.
std::pair<double, double> two_columns(int dim, int n, double eta_left, double eta_right, int frames) {
  nlohmann::json j = base_scene(dim, std::vector<double>(dim, 1.0), std::vector<int>(dim, n));
  j["time"] = {{"fps", 50}, {"frames", frames}, {"cfl", 2.0}, {"max_dt", 0.02}};
  std::vector<double> wall_c(dim, 0.5), wall_h(dim, 0.5);
  wall_c[1] = 0.4;
  wall_h[0] = 0.04;
  wall_h[1] = 0.4;
  j["bodies"] = {{{"name", "divider"}, {"motion", "static"},
                  {"shape", {{"type", "box"}, {"center", wall_c}, {"half_size", wall_h}}}}};
  nlohmann::json liquids = nlohmann::json::array();
  for (int side = 0; side < 2; ++side) {
    std::vector<double> c(dim, 0.5), half(dim, 0.5);
    c[0] = side == 0 ? 0.1 : 0.9;
    c[1] = 0.25;
    half[0] = 0.1;
    half[1] = 0.25;
    liquids.push_back({{"name", side == 0 ? "left" : "right"},
                       {"shape", {{"type", "box"}, {"center", c}, {"half_size", half}}},
                       {"density", 1000.0},
                       {"viscosity", {{"eta", side == 0 ? eta_left : eta_right}}}});
    // the probe sits at the foot of the column, on the side the column collapses towards
    std::vector<double> x(dim, 0.5);
    x[0] = side == 0 ? 0.3 : 0.7;
    x[1] = 0.03;
    j["probes"].push_back({{"name", side == 0 ? "left" : "right"}, {"position", x}});
  }
  j["liquids"] = liquids;
  auto sim = build(j);
  FrameStats s;
  for (int f = 0; f < frames; ++f) s = sim->advance_frame();
  auto speed = [&](int k) {
    double v2 = 0.0;
    for (double v : s.probes[k].velocity) v2 += v * v;
    return std::sqrt(v2);
  };
  return {speed(0), speed(1)};
}

}  // namespace

TEST_CASE("two liquids of different viscosity in one scene each follow their own viscosity",
          "[validation]") {
  // two columns separated by a static wall: with eta 0.05 Pa s on the left and 50 Pa s on the
  // right, the left column must behave as in a scene where both are 0.05, the right one as where
  // both are 50 (eta sampled per stress DOF from the particles' liquid index), and the two sides
  // must differ clearly (the thin liquid collapses faster)
  const double thin = 0.05, thick = 50.0;
  for (int dim : {2, 3}) {
    CAPTURE(dim);
    const int n = dim == 2 ? 40 : 20, frames = 6;
    const auto mixed = two_columns(dim, n, thin, thick, frames);
    const auto all_thin = two_columns(dim, n, thin, thin, frames);
    const auto all_thick = two_columns(dim, n, thick, thick, frames);
    WARN(dim << "D two columns: left/right probe speed " << mixed.first << " / " << mixed.second
             << " (all thin: " << all_thin.first << ", all thick: " << all_thick.second << ")");
    CHECK(mixed.first > 2 * mixed.second);
    CHECK(mixed.first == Approx(all_thin.first).epsilon(0.02));
    CHECK(mixed.second == Approx(all_thick.second).epsilon(0.02));
  }
}

TEST_CASE("the scheme decides the solves: unified, decoupled or pressure only", "[unit]") {
  using S = CouplingScheme;
  CHECK(solve_sequence(S::pvc_unified, true) == SolveSequence::unified);
  CHECK(solve_sequence(S::pv_c, true) == SolveSequence::unified);
  CHECK(solve_sequence(S::c_pv, true) == SolveSequence::unified);
  CHECK(solve_sequence(S::pvc_iterative, true) == SolveSequence::unified);
  CHECK(solve_sequence(S::pc_vc_pc_unified, true) == SolveSequence::decoupled);
  for (const S s : {S::p_c, S::c_p, S::pc_iterative, S::pc_unified})
    CHECK(solve_sequence(s, true) == SolveSequence::pressure);
  for (const S s : enum_values<CouplingScheme>()) CHECK(solve_sequence(s, false) == SolveSequence::pressure);

  // statistics: stress DOFs and the number of solves per step follow the scheme
  for (int dim : {2, 3}) {
    const int n = dim == 2 ? 16 : 8;
    nlohmann::json j = base_scene(dim, std::vector<double>(dim, 1.0), std::vector<int>(dim, n));
    j["domain"]["boundary"] = {{"y+", "open"}};
    j["time"] = {{"fps", 50}, {"frames", 1}, {"cfl", 3.0}, {"max_dt", 0.02}};
    // a block resting on the floor (a free-falling one would need no pressure or stress at all)
    std::vector<double> c(dim, 0.5), half(dim, 0.25);
    c[1] = 0.25;
    j["liquids"] = {{{"name", "a"},
                     {"shape", {{"type", "box"}, {"center", c}, {"half_size", half}}},
                     {"density", 1000.0},
                     {"viscosity", {{"eta", 1.0}}}}};
    for (const auto& [scheme, solves, stress] :
         {std::tuple{"PVC-unified", 1, true}, std::tuple{"PC-VC-PC-unified", 3, true},
          std::tuple{"PC-unified", 1, false}}) {
      CAPTURE(dim, scheme);
      j["solver"]["scheme"] = scheme;
      auto sim = build(j);
      const FrameStats s = sim->advance_frame();
      CHECK(s.solver.staggered_iterations == solves * s.steps);
      CHECK((s.solver.dofs_stress > 0) == stress);
      CHECK(s.solver.dofs_pressure > 0);
      CHECK(s.solver.iterations > 0);
    }
    // an inviscid liquid under a PV scheme has no stress unknowns
    j["liquids"][0]["viscosity"]["eta"] = 0.0;
    j["solver"]["scheme"] = "PVC-unified";
    const FrameStats s = build(j)->advance_frame();
    CHECK(s.solver.dofs_stress == 0);
    CHECK(s.solver.staggered_iterations == s.steps);
  }
}

TEST_CASE("solver.preconditioner auto: SSOR where its estimated count is within 60 iterations, "
          "multigrid above; the choice is booked per solve",
          "[unit]") {
  // source: docs/preconditioners.md section 29 ((P10): SSOR iff c_d n (1 + k_d sqrt(s)) <= 60,
  // c_2 = 1.75, k_2 = 5, c_3 = 3, k_3 = 10, n the grid's largest cell count)
  CHECK(estimated_ssor_iterations(3, 0.0, 16) == Approx(48.0));
  CHECK(estimated_ssor_iterations(2, 0.04, 10) == Approx(17.5 * 2.0));
  CHECK(choose_preconditioner(PreconditionerChoice::automatic, 3, 0.0, 20) == PreconditionerKind::ssor);
  CHECK(choose_preconditioner(PreconditionerChoice::automatic, 3, 0.0, 21) == PreconditionerKind::multigrid);
  CHECK(choose_preconditioner(PreconditionerChoice::automatic, 3, 0.01, 8) == PreconditionerKind::ssor);
  CHECK(choose_preconditioner(PreconditionerChoice::automatic, 3, 0.29, 8) == PreconditionerKind::multigrid);
  CHECK(choose_preconditioner(PreconditionerChoice::automatic, 3, 0.05, 24) == PreconditionerKind::multigrid);
  CHECK(choose_preconditioner(PreconditionerChoice::automatic, 2, 0.0, 34) == PreconditionerKind::ssor);
  CHECK(choose_preconditioner(PreconditionerChoice::automatic, 2, 0.0, 35) == PreconditionerKind::multigrid);
  CHECK(choose_preconditioner(PreconditionerChoice::ssor, 3, 1e6, 64) == PreconditionerKind::ssor);
  CHECK(choose_preconditioner(PreconditionerChoice::multigrid, 3, 0.0, 8) == PreconditionerKind::multigrid);

  struct Case {
    int dim;
    double eta;
    const char* preconditioner;  // nullptr: the default
    const char* scheme;
    PreconditionerKind expected;
  };
  const Case cases[] = {
      {3, 0.1, nullptr, "PVC-unified", PreconditionerKind::ssor},
      {3, 5000.0, nullptr, "PVC-unified", PreconditionerKind::multigrid},
      {3, 5000.0, "auto", "PC-VC-PC-unified", PreconditionerKind::multigrid},
      {3, 0.1, "auto", "PC-VC-PC-unified", PreconditionerKind::ssor},
      {2, 0.1, nullptr, "PVC-unified", PreconditionerKind::ssor},
      {2, 100.0, nullptr, "PVC-unified", PreconditionerKind::multigrid},
      {3, 5000.0, "ssor", "PVC-unified", PreconditionerKind::ssor},
      {3, 0.1, "multigrid", "PVC-unified", PreconditionerKind::multigrid},
  };
  for (const Case& c : cases) {
    CAPTURE(c.dim, c.eta, c.preconditioner ? c.preconditioner : "(default)", c.scheme);
    const int n = c.dim == 2 ? 16 : 8;
    nlohmann::json j = base_scene(c.dim, std::vector<double>(c.dim, 1.0), std::vector<int>(c.dim, n));
    j["domain"]["boundary"] = {{"y+", "open"}};
    j["time"] = {{"fps", 50}, {"frames", 2}, {"cfl", 3.0}, {"max_dt", 0.02}};
    std::vector<double> centre(c.dim, 0.5), half(c.dim, 0.25);
    centre[1] = 0.25;
    j["liquids"] = {{{"name", "a"},
                     {"shape", {{"type", "box"}, {"center", centre}, {"half_size", half}}},
                     {"density", 1000.0},
                     {"viscosity", {{"eta", c.eta}}}}};
    j["solver"]["scheme"] = c.scheme;
    if (c.preconditioner) j["solver"]["preconditioner"] = c.preconditioner;
    auto sim = build(j);
    for (int f = 0; f < 2; ++f) {
      const FrameStats s = sim->advance_frame();
      REQUIRE(s.solver.converged);
      // one unified (PVC) or viscosity (PC-VC-PC) solve per step, all with the expected choice
      const long mg = s.solver.stokes_solves_multigrid, ssor = s.solver.stokes_solves_ssor;
      CHECK(mg + ssor == s.steps);
      CHECK((c.expected == PreconditionerKind::multigrid ? mg : ssor) == s.steps);
      // the booked stiffness is eta dt / (rho dx^2) of the step with the largest dt
      const double dx = 1.0 / n;
      CHECK(s.solver.max_stokes_stiffness == Approx(c.eta * s.dt_max / (1000.0 * dx * dx)).epsilon(1e-12));
    }
  }
  // pressure-only solves book no Stokes preconditioner
  nlohmann::json j = base_scene(3, {1.0, 1.0, 1.0}, {8, 8, 8});
  j["time"] = {{"fps", 50}, {"frames", 1}, {"cfl", 3.0}, {"max_dt", 0.02}};
  j["liquids"] = {{{"shape", {{"type", "box"}, {"center", {0.5, 0.25, 0.5}}, {"half_size", {0.25, 0.25, 0.25}}}},
                   {"density", 1000.0},
                   {"viscosity", {{"eta", 5000.0}}}}};
  j["solver"]["scheme"] = "PC-unified";
  const FrameStats s = build(j)->advance_frame();
  CHECK(s.solver.stokes_solves_multigrid + s.solver.stokes_solves_ssor == 0);
  CHECK(s.solver.max_stokes_stiffness == 0.0);
}

TEST_CASE("solver.preconditioner auto: every unified solve of a low-stiffness 3D box within 60 "
          "iterations, where SSOR needs more",
          "[unit]") {
  // source: issue 15's goal (at most 60 iterations per solve) and docs/preconditioners.md
  // section 29. A 3D box of liquid at stiffness s = eta dt / (rho dx^2) of about 0.04, below
  // the former 3D threshold 0.3 (which took SSOR here), on 20^3 cells: (P10) estimates SSOR at
  // 3 * 20 * (1 + 10 sqrt(0.04)) = 180 iterations, so auto takes the block preconditioner.
  // On 8^3 with eta 0.1 (s about 1e-4) the estimate is 27 and auto keeps SSOR, within 60.
  struct Case {
    int n;
    double eta;
    PreconditionerKind expected;
  };
  for (const Case& c : {Case{20, 5.0, PreconditionerKind::multigrid}, Case{8, 0.1, PreconditionerKind::ssor}}) {
    CAPTURE(c.n, c.eta);
    auto run = [&](const char* preconditioner) {
      nlohmann::json j = base_scene(3, {1.0, 1.0, 1.0}, {c.n, c.n, c.n});
      j["domain"]["boundary"] = {{"y+", "open"}};
      j["time"] = {{"fps", 50}, {"frames", 2}, {"cfl", 100.0}, {"max_dt", 0.02}};
      j["solver"]["tolerance"] = 1e-6;
      j["solver"]["preconditioner"] = preconditioner;
      j["liquids"] = {{{"name", "a"},
                       {"shape", {{"type", "box"}, {"center", {0.5, 0.25, 0.5}}, {"half_size", {0.3, 0.2, 0.3}}}},
                       {"density", 1000.0},
                       {"viscosity", {{"eta", c.eta}}}}};
      auto sim = build(j);
      long worst = 0;  // the most iterations of one solve (one unified solve per step)
      for (int f = 0; f < 2; ++f) {
        const FrameStats s = sim->advance_frame();
        REQUIRE(s.solver.converged);
        REQUIRE(s.steps == 1);
        CHECK(s.solver.stokes_solves_multigrid + s.solver.stokes_solves_ssor == 1);
        if (std::string(preconditioner) == "auto")
          CHECK((c.expected == PreconditionerKind::multigrid ? s.solver.stokes_solves_multigrid
                                                             : s.solver.stokes_solves_ssor) == 1);
        worst = std::max(worst, s.solver.iterations);
      }
      return worst;
    };
    CHECK(run("auto") <= kAutoSsorIterationLimit);
    // the choice matters: on 20^3 SSOR needs more than 60 (on 8^3 it stays within them)
    const long ssor = run("ssor");
    if (c.expected == PreconditionerKind::multigrid) CHECK(ssor > kAutoSsorIterationLimit);
    else CHECK(ssor <= kAutoSsorIterationLimit);
  }
}

TEMPLATE_TEST_CASE_SIG("eta per stress DOF from the particles: exact for one liquid, split between two",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // particles filling the lower half of a periodic-in-x box: liquid 0 (eta 2) at x < 0.5,
  // liquid 1 (eta 8) at x > 0.5
  const int n = 8;
  std::array<bool, Dim> periodic{};
  periodic[0] = true;
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), periodic);
  Particles<Dim> p;
  for (int c = 0; c < grid.num_cells(); ++c) {
    const Vec<Dim> x = grid.cell_center(grid.cell_coord(c));
    if (x[1] > 0.5) continue;
    p.x.push_back(x);
    p.v.push_back(Vec<Dim>::Zero());
    p.c.push_back(Mat<Dim>::Zero());
    p.mass.push_back(1.0);
    p.density.push_back(1000.0);
    p.liquid.push_back(x[0] < 0.5 ? 0 : 1);
  }
  const StressGrid<Dim> stress(grid);
  // one viscosity everywhere: reproduced exactly on every DOF (reached or filled)
  const VectorX same = stress_viscosity(stress, p, {3.0, 3.0});
  CHECK((same.array() - 3.0).abs().maxCoeff() < 1e-14);
  // two: each DOF whose stencil only reaches one liquid takes its eta; the rest lie between
  const VectorX two = stress_viscosity(stress, p, {2.0, 8.0});
  CHECK(two.minCoeff() >= 2.0 - 1e-14);
  CHECK(two.maxCoeff() <= 8.0 + 1e-14);
  int left = 0, right = 0;
  for (int i = 0; i < stress.num_dofs(); ++i) {
    const auto [k, c] = stress.coord(i);
    const Vec<Dim> x = stress.position(k, c);
    if (x[1] > 0.45) continue;
    // more than a cell from the interfaces at x = 0.5 and at the periodic seam x = 0 = 1
    if (x[0] > 0.15 && x[0] < 0.35) {
      CHECK(two[i] == Approx(2.0).epsilon(1e-12));
      ++left;
    }
    if (x[0] > 0.65 && x[0] < 0.85) {
      CHECK(two[i] == Approx(8.0).epsilon(1e-12));
      ++right;
    }
  }
  CHECK(left > 0);
  CHECK(right > 0);
  // per cell for the renderer: the same rule on the cell centres
  const VectorX cells = cell_viscosity(grid, p, {2.0, 8.0});
  CHECK(cells[grid.cell_index(VecI<Dim>::Constant(1))] == Approx(2.0));
  CHECK(cells[grid.cell_index(VecI<Dim>::Unit(0) * 5 + VecI<Dim>::Constant(1) - VecI<Dim>::Unit(0))] ==
        Approx(8.0));
}

namespace {

/// sample_viscosity's fill as a sweep over the whole lattice (the definition, ring by ring):
/// the reference for the frontier version in viscosity_field.cpp.
template <int Dim>
VectorX fill_by_sweeps(const MacGrid<Dim>& grid, const VecI<Dim>& dims, VectorX eta, std::vector<char> known,
                       double mean) {
  const int n = dims.prod();
  for (int layer = 0; layer < kViscosityFillLayers; ++layer) {
    std::vector<int> filled;
    VectorX next = eta;
    for (int i = 0; i < n; ++i) {
      if (known[i]) continue;
      const VecI<Dim> c = lattice_coord<Dim>(i, dims);
      double sum = 0.0;
      int count = 0;
      for (int a = 0; a < Dim; ++a)
        for (int s : {-1, 1}) {
          VecI<Dim> d = c;
          d[a] += s;
          if (grid.periodic(a))
            d[a] = (d[a] % dims[a] + dims[a]) % dims[a];
          else if (d[a] < 0 || d[a] >= dims[a])
            continue;
          const int j = lattice_index<Dim>(d, dims);
          if (!known[j]) continue;
          sum += eta[j];
          ++count;
        }
      if (count > 0) {
        next[i] = sum / count;
        filled.push_back(i);
      }
    }
    if (filled.empty()) break;
    eta = next;
    for (int i : filled) known[i] = 1;
  }
  for (int i = 0; i < n; ++i)
    if (!known[i]) eta[i] = mean;
  return eta;
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("sample_viscosity's frontier fill equals the ring-by-ring sweep over the whole lattice, "
                       "bit for bit",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // a random blob of two liquids in a box periodic along x, sampled on a stress lattice; away
  // from the walls (a box of samples inside the lattice) and against the lower walls (the box
  // cut by the lattice's end)
  const double base = GENERATE(0.3, 0.0);
  const int n = Dim == 2 ? 24 : 12;
  std::array<bool, Dim> periodic{};
  periodic[0] = true;
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), periodic);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Particles<Dim> p;
  for (int k = 0; k < 40 * (Dim == 2 ? 4 : 8); ++k) {
    Vec<Dim> x;
    for (int a = 0; a < Dim; ++a) x[a] = a == 0 ? u(rng) : base + 0.3 * u(rng);  // crosses the seam
    p.x.push_back(x);
    p.v.push_back(Vec<Dim>::Zero());
    p.c.push_back(Mat<Dim>::Zero());
    p.mass.push_back(0.5 + u(rng));
    p.density.push_back(1000.0);
    p.liquid.push_back(k % 3 == 0 ? 1 : 0);
  }
  const std::vector<double> liquid_eta{2.0, 8.0};
  const StressGrid<Dim> stress(grid);
  for (int k = 0; k < StressGrid<Dim>::num_components(); ++k) {
    const VecI<Dim> dims = stress.dims(k);
    const Vec<Dim> shift = StressGrid<Dim>::shift(k);
    const VectorX got = sample_viscosity(grid, shift, dims, p, liquid_eta);
    // the reached samples and the overall mean, recomputed as sample_viscosity defines them
    const int m = dims.prod();
    VectorX mass = VectorX::Zero(m), mass_eta = VectorX::Zero(m);
    double total = 0.0, total_eta = 0.0;
    std::array<int, (1 << Dim)> idx;
    std::array<double, (1 << Dim)> w;
    for (std::size_t q = 0; q < p.size(); ++q) {
      const double eta = liquid_eta[p.liquid[q]];
      total += p.mass[q];
      total_eta += p.mass[q] * eta;
      grid.stencil(grid.wrap_position(p.x[q]), shift, dims, idx, w);
      for (int c = 0; c < (1 << Dim); ++c) {
        if (w[c] == 0.0) continue;
        mass[idx[c]] += w[c] * p.mass[q];
        mass_eta[idx[c]] += w[c] * p.mass[q] * eta;
      }
    }
    VectorX eta0 = VectorX::Zero(m);
    std::vector<char> known(m, 0);
    int reached = 0, far = 0;
    for (int i = 0; i < m; ++i)
      if (mass[i] > 0.0) {
        eta0[i] = mass_eta[i] / mass[i];
        known[i] = 1;
        ++reached;
      }
    const VectorX want = fill_by_sweeps<Dim>(grid, dims, eta0, known, total_eta / total);
    REQUIRE(got.size() == want.size());
    CHECK((got - want).cwiseAbs().maxCoeff() == 0.0);
    for (int i = 0; i < m; ++i) far += want[i] == total_eta / total && !known[i];
    // the case exercises all three kinds of samples: reached, filled, far
    CHECK(reached > 0);
    CHECK(far > 0);
    CHECK(reached + far < m);
  }
}
