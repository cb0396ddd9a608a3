// The two back ends of the coupled step (reference/coupling/monolithic_system.hpp, "explicit" and
// "matrixfree"): the operator of eq. (24), its blocks, the MLCP (26) and A_ff operators
// and the right-hand sides agree to round-off; solve_coupled_step agrees under all nine schemes
// of section 6 to the solver tolerance; a whole simulator step agrees; the matrix-free step is
// deterministic for a fixed thread count (and across thread counts). 2D and 3D, small grids.
#include <omp.h>

#include <algorithm>
#include <atomic>
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/contact/collision.hpp"
#include "reference/contact/contact_system.hpp"
#include "reference/coupling/coupled_preconditioner.hpp"
#include "reference/coupling/coupled_schemes.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/coupling/monolithic_system.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/sim/simulation.hpp"
#include "reference/solvers/mprgp.hpp"
#include "reference/solvers/pcg.hpp"
#include "tests/support/body_helpers.hpp"
#include "tests/support/test_helpers.hpp"

// AddressSanitizer replaces malloc itself; a second definition here would take the sanitizer's
// place (it then fails at start-up), so under MONOLITH_SANITIZE / MONOLITH_FUZZ the counting
// and the test that needs it are left out.
#if defined(__SANITIZE_ADDRESS__)
#define MONOLITH_UNDER_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define MONOLITH_UNDER_ASAN 1
#endif
#endif

#if defined(__GLIBC__) && !defined(MONOLITH_UNDER_ASAN)
// Every malloc of this executable is counted (glibc's allocator underneath), so a test can
// assert that an operator's apply allocates nothing beyond what its fluid part does (Eigen
// allocates through malloc, not operator new).
extern "C" void* __libc_malloc(std::size_t size);
namespace {
std::atomic<long> g_mallocs{0};
}  // namespace
extern "C" void* malloc(std::size_t size) {
  g_mallocs.fetch_add(1, std::memory_order_relaxed);
  return __libc_malloc(size);
}
#define MONOLITH_COUNTS_MALLOC 1
#endif

using namespace monolith;
using monolith::testing::make_body;

namespace {

constexpr double kRho = 1000.0;
constexpr double kGravity = -9.81;
constexpr double kDt = 0.01;

/// A pseudo-random number in [-1, 1] from a seed and an index (deterministic, no state).
double jitter(unsigned seed, int k) {
  return testing::random_vector(k + 1, seed)[k];
}

template <int Dim>
Vec<Dim> point(double x, double y, double z = 0.5) {
  Vec<Dim> p;
  p[0] = x;
  p[1] = y;
  if constexpr (Dim == 3) p[2] = z;
  return p;
}

template <int Dim>
ShapeSpec box_shape(const Vec<Dim>& centre, double half) {
  ShapeSpec s;
  s.type = ShapeType::box;
  s.half_size = std::vector<double>(Dim, half);
  s.center = testing::as_std<Dim>(centre);
  return s;
}

/// A random coupled step in the unit tank (walls on every side): a viscous liquid (eta) below
/// a jittered level with a random u* (plus one step of gravity) and, all jittered by `seed`:
/// a heavy dynamic box on the floor 0.1 dx into it, a light dynamic box resting on it, a
/// dynamic ball touching the heavy box's side, a static box touching the ball, and with
/// `kinematic` a kinematic box moving down onto the light box. Contacts as the rigid world finds
/// them (box-floor, box-box, ball-box, ball-static box, kinematic-box), friction mu.
template <int Dim>
CoupledStepInput<Dim> random_scene(int n, unsigned seed, double eta, double mu, bool kinematic,
                                   bool overlap_round_off = false) {
  CoupledStepInput<Dim> in{testing::unit_grid<Dim>(n), {}, kDt, {}, {}, {}, {}, {}};
  const double dx = in.grid.dx();
  const double j0 = 0.02 * jitter(seed, 0), j1 = 0.02 * jitter(seed, 1), j2 = 0.3 * jitter(seed, 2);
  const double h0 = 0.14, h1 = 0.1, r = 0.09, hs = 0.1;
  const Vec<Dim> c0 = point<Dim>(0.35 + j0, h0 - 0.1 * dx, 0.5 + j1);
  const Vec<Dim> c1 = point<Dim>(0.35 + j0 + 0.02 * j2, 2.0 * h0 + h1 - 0.15 * dx, 0.5 + j1);
  ShapeSpec ball;
  ball.type = ShapeType::sphere;
  ball.radius = r;
  ball.center =
      testing::as_std<Dim>(point<Dim>(0.35 + j0 + h0 + r - 0.05 * dx, 0.3 + j1, 0.5 + j1));
  const Vec<Dim> cs = point<Dim>(0.35 + j0 + h0 + 2.0 * r + hs - 0.1 * dx, 0.3 + j1, 0.5 + j1);
  in.bodies = {make_body<Dim>(box_shape<Dim>(c0, h0), 2000.0, mu),
               make_body<Dim>(box_shape<Dim>(c1, h1), 600.0, mu), make_body<Dim>(ball, 1200.0, mu),
               make_body<Dim>(box_shape<Dim>(cs, hs), 1000.0, mu, BodyMotion::fixed)};
  for (int b = 0; b < 3; ++b) {
    BodyVec<Dim> v = BodyVec<Dim>::Zero();
    for (int k = 0; k < kBodyDofs<Dim>; ++k) v[k] = 0.05 * jitter(seed + 7 * b, 3 + k);
    v[1] += kGravity * kDt;
    in.bodies[b].set_generalized_velocity(v);
  }
  if (kinematic) {
    const Vec<Dim> ck = point<Dim>(0.35 + j0, 2.0 * h0 + 2.0 * h1 + 0.08 - 0.1 * dx, 0.5 + j1);
    in.bodies.push_back(
        make_body<Dim>(box_shape<Dim>(ck, 0.08), 1000.0, mu, BodyMotion::kinematic));
    BodyVec<Dim> v = BodyVec<Dim>::Zero();
    v[1] = -0.2;
    in.bodies.back().set_generalized_velocity(v);
  }
  const auto boundary = testing::all_boundaries<Dim>(BoundaryType::wall);
  in.solids = solid_weights<Dim>(in.grid, coupling_bodies(in.bodies), {}, boundary, 0.01 * dx);
  if (overlap_round_off) {
    // The weights as the overlap rule left them before energy15's fix (docs/coupling.md,
    // "Overlap"): on a face two bodies cover, W_S^u was the sum of the scaled parts, 1 - 1.1e-16
    // on some faces, so W_F^u = 1.1e-16 and a cell inside the overlap became a pressure DOF held
    // by the bodies alone (a row whose sparse diagonal is round-off beside A's). Recomputed here
    // the old way, as a hard input for the solver.
    for (int f = 0; f < in.grid.num_faces(); ++f) {
      int covering = 0;
      for (const VectorX& body : in.solids.body_face) covering += body[f] > 0.0 ? 1 : 0;
      if (covering < 2 || in.solids.fluid_face[f] != 0.0) continue;
      double solid = in.solids.static_face.size() > 0 ? in.solids.static_face[f] : 0.0;
      for (const VectorX& body : in.solids.body_face) solid += body[f];
      solid = std::min(solid, 1.0);
      in.solids.fluid_face[f] = 1.0 - solid;
      if (in.solids.solid_face.size() > 0) in.solids.solid_face[f] = solid;
    }
  }
  const double level = 0.62 + 0.05 * jitter(seed, 20);
  const VectorX phi = testing::sample_lattice<Dim>(half_lattice(in.grid),
                                                   [&](const Vec<Dim>& x) { return x[1] - level; });
  in.weights = coupled_stokes_weights<Dim>(in.grid, in.solids, phi, kRho, eta);
  in.u_star = 0.3 * testing::random_vector(in.grid.num_faces(), seed + 100);
  in.u_star.segment(in.grid.face_offset(1), in.grid.num_faces(1)).array() += kGravity * kDt;
  in.contacts = detect_contacts<Dim>(in.bodies, testing::unit_box_walls<Dim>(mu), 0.3 * dx);
  in.contact_params.dt = kDt;
  in.contact_params.dx = dx;
  return in;
}

template <int Dim>
MonolithicSystem<Dim> make_system(const CoupledStepInput<Dim>& in, Backend backend,
                                  StressForm form = StressForm::reduced,
                                  StokesUnknowns unknowns = StokesUnknowns::pressure_and_stress) {
  const ContactSystem<Dim> contacts(in.bodies, in.contacts, in.contact_params);
  return MonolithicSystem<Dim>(in.grid, form, in.weights, in.dt, in.u_star, in.bodies, in.solids,
                               contacts, backend, unknowns);
}

/// ||a - b||_2 / ||b||_2 (0 when both vanish).
double relative_l2(const VectorX& a, const VectorX& b) {
  REQUIRE(a.size() == b.size());
  const double d = (a - b).norm(), s = b.norm();
  if (s == 0.0) return d;
  return d / s;
}

double relative_inf(const VectorX& a, const VectorX& b) {
  REQUIRE(a.size() == b.size());
  if (a.size() == 0) return 0.0;
  const double s = b.cwiseAbs().maxCoeff();
  const double d = (a - b).cwiseAbs().maxCoeff();
  return s == 0.0 ? d : d / s;
}

/// The largest relative difference found by a check, printed by the test cases.
struct Worst {
  double value = 0.0;
  void operator()(double v) { value = std::max(value, v); }
};

template <int Dim>
void check_operators_agree(int n, unsigned seed, bool kinematic, StressForm form,
                           StokesUnknowns unknowns) {
  const CoupledStepInput<Dim> in = random_scene<Dim>(n, seed, 0.8, 0.4, kinematic);
  const MonolithicSystem<Dim> e = make_system<Dim>(in, Backend::explicit_matrices, form, unknowns);
  const MonolithicSystem<Dim> m = make_system<Dim>(in, Backend::matrix_free, form, unknowns);
  CHECK(e.backend() == Backend::explicit_matrices);
  CHECK(!e.matrix_free());
  CHECK(m.backend() == Backend::matrix_free);
  CHECK(m.matrix_free());
  // the scene has what the comparison is meant to cover
  REQUIRE(e.num_stress() > 0);
  if (unknowns == StokesUnknowns::stress_only)
    REQUIRE(e.num_pressure() == 0);
  else
    REQUIRE(e.num_pressure() > 0);
  REQUIRE(e.num_contacts() >= 4);
  REQUIRE(e.num_body_dofs() == 3 * kBodyDofs<Dim>);
  REQUIRE(e.fluid_body_jacobian().nonZeros() > 0);
  REQUIRE(m.num_fluid() == e.num_fluid());
  REQUIRE(m.num_contacts() == e.num_contacts());
  // the matrix-free system forms neither the Stokes matrices nor B_f
  CHECK(m.stokes().A.nonZeros() == 0);
  CHECK(m.fluid_body_jacobian().nonZeros() == 0);
  Worst worst;
  const double tol = 1e-12;
  // right-hand sides
  worst(relative_l2(m.b1(), e.b1()));
  CHECK(relative_l2(m.b1(), e.b1()) <= tol);
  if (e.num_pressure() > 0) CHECK(relative_l2(m.b2(), e.b2()) <= tol);
  worst(relative_l2(m.b2(), e.b2()));
  CHECK(relative_l2(m.rhs(), e.rhs()) <= tol);
  // every block A_ij of eq. (24) on a random x
  for (int i = 1; i <= 4; ++i)
    for (int j = 1; j <= 4; ++j) {
      if (e.block_size(i) == 0 || e.block_size(j) == 0) continue;
      INFO("block A" << i << j);
      const VectorX x = testing::random_vector(e.block_size(j), seed + 10 * i + j);
      const VectorX ye = e.apply_block(i, j, x), ym = m.apply_block(i, j, x);
      worst(relative_l2(ym, ye));
      CHECK(relative_l2(ym, ye) <= tol);
    }
  // the MLCP operator (26) with the diagonal boost, and A_ff
  const MonolithicOperator<Dim> oe(e, 1e-4), om(m, 1e-4);
  const FluidBodyOperator<Dim> fe(e), fm(m);
  for (int trial = 0; trial < 2; ++trial) {
    const VectorX x = testing::random_vector(oe.size(), seed + 50 + trial);
    VectorX ye, ym;
    oe.apply(x, ye);
    om.apply(x, ym);
    worst(relative_l2(ym, ye));
    CHECK(relative_l2(ym, ye) <= tol);
    const VectorX xf = x.head(e.num_fluid());
    fe.apply(xf, ye);
    fm.apply(xf, ym);
    worst(relative_l2(ym, ye));
    CHECK(relative_l2(ym, ye) <= tol);
    // the right-hand sides of the partial solves and the updates
    const VectorX z = testing::random_vector(e.num_friction(), seed + 60 + trial);
    const VectorX lambda = x.tail(e.num_contacts());
    CHECK(relative_l2(m.mlcp_rhs(z), e.mlcp_rhs(z)) <= tol);
    CHECK(relative_l2(m.friction_rhs(x), e.friction_rhs(x)) <= tol);
    CHECK(relative_l2(m.fluid_rhs(lambda, z), e.fluid_rhs(lambda, z)) <= tol);
    CHECK(relative_l2(m.contact_rhs(xf, z), e.contact_rhs(xf, z)) <= tol);
    CHECK(relative_l2(m.fluid_body_force(xf), e.fluid_body_force(xf)) <= tol);
    const VectorX f = testing::random_vector(e.num_body_dofs(), seed + 70 + trial);
    CHECK(relative_l2(m.fluid_body_force_transpose(f), e.fluid_body_force_transpose(f)) <= tol);
    CHECK(relative_l2(m.fluid_velocities(xf), e.fluid_velocities(xf)) <= tol);
    CHECK(relative_l2(m.body_velocities(xf, lambda, z), e.body_velocities(xf, lambda, z)) <= tol);
  }
  worst(relative_l2(om.diagonal(), oe.diagonal()));
  CHECK(relative_l2(om.diagonal(), oe.diagonal()) <= tol);
  CHECK(relative_l2(fm.diagonal(), fe.diagonal()) <= tol);
  CHECK(om.null_space().size() == oe.null_space().size());
  // the sparse part exists only as operators under matrixfree
  CHECK_THROWS_AS(om.sparse_part(), std::logic_error);
  CHECK(oe.sparse_part().rows() == oe.size());
  std::printf("backends %dD n=%d seed %u%s%s: largest relative difference %.2e\n", Dim, n, seed,
              kinematic ? " kinematic" : "",
              unknowns == StokesUnknowns::stress_only ? " stress-only" : "", worst.value);
}

}  // namespace

TEST_CASE("Back ends: the scene names of both back ends, parsed in one place", "[unit][backends]") {
  // solver.backend is an enum past the scene parser (parse_enum on the EnumNames table)
  CHECK(enum_names<Backend>() == std::vector<std::string>{"matrixfree", "explicit"});
  CHECK(parse_enum<Backend>("explicit") == Backend::explicit_matrices);
  CHECK(parse_enum<Backend>("matrixfree") == Backend::matrix_free);
  CHECK_FALSE(parse_enum<Backend>("matrix-free").has_value());
  CHECK_FALSE(parse_enum<Backend>("sparse").has_value());
  for (const Backend b : enum_values<Backend>()) CHECK(parse_enum<Backend>(enum_name(b)) == b);
}

TEST_CASE("Back ends: eq. (24) blocks, (26), A_ff and right-hand sides agree to round-off, 2D",
          "[unit][backends]") {
  for (unsigned seed : {3u, 11u})
    check_operators_agree<2>(16, seed, seed == 11u, StressForm::reduced,
                             StokesUnknowns::pressure_and_stress);
  // the VC system of PC-VC-PC-unified: stress only, full form
  check_operators_agree<2>(16, 5, true, StressForm::full, StokesUnknowns::stress_only);
}

TEST_CASE("Back ends: eq. (24) blocks, (26), A_ff and right-hand sides agree to round-off, 3D",
          "[unit][backends]") {
  check_operators_agree<3>(10, 4, false, StressForm::reduced, StokesUnknowns::pressure_and_stress);
  check_operators_agree<3>(10, 9, true, StressForm::full, StokesUnknowns::stress_only);
}

TEST_CASE("Back ends: dense_matrix of eq. (24) agrees under both back ends, 2D",
          "[unit][backends]") {
  const CoupledStepInput<2> in = random_scene<2>(10, 2, 0.8, 0.4, true);
  const MonolithicSystem<2> e = make_system<2>(in, Backend::explicit_matrices);
  const MonolithicSystem<2> m = make_system<2>(in, Backend::matrix_free);
  const Eigen::MatrixXd de = e.dense_matrix(), dm = m.dense_matrix();
  const double scale = de.cwiseAbs().maxCoeff();
  INFO("size " << de.rows() << ", largest entry " << scale);
  CHECK((dm - de).cwiseAbs().maxCoeff() <= 1e-12 * scale);
  // symmetric under both
  CHECK((dm - dm.transpose()).cwiseAbs().maxCoeff() <= 1e-12 * scale);
}

namespace {

StaggeredSettings solve_settings(double tol) {
  StaggeredSettings s;
  s.max_iterations = 400;
  s.tolerance = tol;
  s.mprgp.tolerance = tol;
  s.mprgp.max_iterations = 20000;
  return s;
}

/// Relative differences (inf-norm, relative to the explicit result's largest entry) of two
/// results: `state` the largest over u, p, tau and the body velocities (`which` names it),
/// `lambda` that of the contact forces.
struct Difference {
  double state = 0.0, lambda = 0.0;
  std::string which;
};

Difference result_difference(const CoupledSolveResult& m, const CoupledSolveResult& e) {
  const std::vector<std::pair<const char*, double>> fields = {
      {"u", relative_inf(m.u, e.u)},
      {"p", relative_inf(m.pressure, e.pressure)},
      {"tau", relative_inf(m.stress, e.stress)},
      {"v", relative_inf(m.body_velocity, e.body_velocity)}};
  Difference d;
  for (const auto& [name, value] : fields)
    if (value >= d.state) {
      d.state = value;
      d.which = name;
    }
  d.lambda = relative_inf(m.lambda, e.lambda);
  return d;
}

bool bitwise_equal(const VectorX& a, const VectorX& b) {
  return a.size() == b.size() &&
         (a.size() == 0 || std::memcmp(a.data(), b.data(), sizeof(double) * a.size()) == 0);
}

bool bitwise_equal(const CoupledSolveResult& a, const CoupledSolveResult& b) {
  return bitwise_equal(a.u, b.u) && bitwise_equal(a.pressure, b.pressure) &&
         bitwise_equal(a.stress, b.stress) && bitwise_equal(a.body_velocity, b.body_velocity) &&
         bitwise_equal(a.lambda, b.lambda) && bitwise_equal(a.z, b.z) &&
         a.coupled_iterations == b.coupled_iterations && a.fluid_iterations == b.fluid_iterations &&
         a.contact_iterations == b.contact_iterations;
}

/// Both back ends under all nine schemes at solver tolerance `tol`: the largest differences.
template <int Dim>
Difference schemes_difference(const CoupledStepInput<Dim>& in, double tol) {
  Difference worst;
  for (CouplingScheme scheme : enum_values<CouplingScheme>()) {
    INFO(enum_name(scheme) << " at tolerance " << tol);
    const CoupledSolveResult e =
        solve_coupled_step<Dim>(in, scheme, Backend::explicit_matrices, solve_settings(tol));
    const CoupledSolveResult m =
        solve_coupled_step<Dim>(in, scheme, Backend::matrix_free, solve_settings(tol));
    REQUIRE(e.converged);
    REQUIRE(m.converged);
    const Difference d = result_difference(m, e);
    std::printf(
        "  %dD tol %.0e %-17s explicit %4ld + %4ld + %4ld iterations, matrixfree %4ld + %4ld + "
        "%4ld: "
        "difference %.1e (%s), lambda %.1e\n",
        Dim, tol, enum_name(scheme).c_str(), e.fluid_iterations, e.contact_iterations,
        e.coupled_iterations, m.fluid_iterations, m.contact_iterations, m.coupled_iterations,
        d.state, d.which.c_str(), d.lambda);
    if (d.state > worst.state) {
      worst.state = d.state;
      worst.which = enum_name(scheme) + " " + d.which;
    }
    worst.lambda = std::max(worst.lambda, d.lambda);
  }
  return worst;
}

}  // namespace

TEST_CASE("Back ends: solve_coupled_step agrees under all nine schemes to the solver tolerance",
          "[unit][backends]") {
  // Both back ends solve the same equations (the operators agree to 3e-16, above) but their
  // SSOR sweeps run in different orders (explicit: row order; matrixfree: red-black groups per
  // stress component and pressure, Welsh-Powell colours of the contacts), so their iterates
  // differ and each stops on its own residual test ||r||_inf <= tol ||b||_inf: the results
  // differ by the solver error, not by round-off. Asserted: (1) the difference falls with the
  // tolerance (by 1e-2 or more from 1e-7 to 1e-10; a discrepancy in the equations would not
  // fall); (2) u, p, tau and v differ by at most 1e3 tol (measured at most 34 tol: 3D PC-unified's
  // body velocities at 1e-7, 26 tol at 1e-10, 2D PC-unified); (3) lambda by at most
  // 10 tol / gamma: in 3D a box's four coplanar floor contacts span three body directions, so
  // A33 has a null direction that only the boost gamma = 1e-4 of section 4.4.5 fixes, and the
  // load split among them is determined to tol / gamma only (measured 1.3e-3 = 1.3 tol / gamma,
  // 3D PC-VC-PC-unified at 1e-7).
  const double gamma = StaggeredSettings().diagonal_boost;
  for (int dim : {2, 3}) {
    Difference loose, tight;
    if (dim == 2) {
      const CoupledStepInput<2> in = random_scene<2>(16, 21, 0.8, 0.4, true);
      loose = schemes_difference<2>(in, 1e-7);
      tight = schemes_difference<2>(in, 1e-10);
    } else {
      const CoupledStepInput<3> in = random_scene<3>(8, 22, 0.8, 0.4, true);
      loose = schemes_difference<3>(in, 1e-7);
      tight = schemes_difference<3>(in, 1e-10);
    }
    INFO(dim << "D: largest difference " << loose.state << " (" << loose.which << ") at 1e-7, "
             << tight.state << " (" << tight.which << ") at 1e-10; lambda " << loose.lambda << ", "
             << tight.lambda);
    CHECK(tight.state <= 1e3 * 1e-10);
    CHECK(loose.state <= 1e3 * 1e-7);
    CHECK(tight.lambda <= 10.0 * 1e-10 / gamma);
    CHECK(loose.lambda <= 10.0 * 1e-7 / gamma);
    CHECK(tight.state <= 1e-2 * loose.state);
    CHECK(tight.lambda <= 1e-2 * loose.lambda);
  }
}

namespace {

std::string number(double x) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g", x);
  return text;
}

/// One frame of bunny-onto-floating-bowl-2d (Fig. 3) made small: 32^2 cells, one frame of 0.02 s
/// (two steps at max_dt 0.01), solver tolerance `tol`, PVC-unified with a viscous liquid.
FrameStats simulate_small(const std::string& backend, double tol) {
  const SceneDesc s = load_scene(
      "bunny-onto-floating-bowl-2d",
      {"render.enabled=false", "domain.cells=[32,32]", "time.fps=50", "solver.scheme=PVC-unified",
       "liquids.0.viscosity={\"model\":\"newtonian\",\"eta\":0.5}",
       "solver.tolerance=" + number(tol), "solver.backend=" + backend});
  auto sim = make_simulation(s);
  return sim->advance_frame();
}

/// Largest relative difference over the bodies' positions and velocities and the liquid's
/// kinetic energy and volume.
double frame_difference(const FrameStats& m, const FrameStats& e) {
  double d = std::abs(m.kinetic_energy_liquid - e.kinetic_energy_liquid) /
             std::abs(e.kinetic_energy_liquid);
  d = std::max(d, std::abs(m.liquid_volume - e.liquid_volume) / e.liquid_volume);
  REQUIRE(m.bodies.size() == e.bodies.size());
  for (std::size_t b = 0; b < e.bodies.size(); ++b) {
    double vscale = 1e-3;  // m/s: velocities are compared relative to at least 1 mm/s
    for (double v : e.bodies[b].velocity) vscale = std::max(vscale, std::abs(v));
    for (std::size_t k = 0; k < e.bodies[b].velocity.size(); ++k) {
      d = std::max(d, std::abs(m.bodies[b].velocity[k] - e.bodies[b].velocity[k]) / vscale);
      d = std::max(
          d, std::abs(m.bodies[b].position[k] - e.bodies[b].position[k]));  // m, domain of 1 m
    }
  }
  return d;
}

}  // namespace

TEST_CASE("Back ends: a simulator frame with bodies agrees between the back ends",
          "[unit][backends]") {
  // Fig. 3's scene at 32^2 under PVC-unified with viscosity: two coupled steps (contacts of the
  // bunny with the bowl and of the bowl with the liquid). (Before section 25 of
  // docs/preconditioners.md the difference was solver error and fell with the tolerance.) (The
  // loose solve at 1e-4: with the two-term block preconditioner of docs/preconditioners.md section
  // 19 a solve to 1e-7 already lands at round-off, 2.7e-13, and the difference could not fall
  // further.)
  const FrameStats e7 = simulate_small("explicit", 1e-4), m7 = simulate_small("matrixfree", 1e-4);
  const FrameStats e10 = simulate_small("explicit", 1e-10),
                   m10 = simulate_small("matrixfree", 1e-10);
  REQUIRE(e10.solver.converged);
  REQUIRE(m10.solver.converged);
  CHECK(e10.steps == m10.steps);
  CHECK(e10.particles == m10.particles);
  const double d7 = frame_difference(m7, e7), d10 = frame_difference(m10, e10);
  std::printf(
      "simulator frame: explicit %ld iterations, matrixfree %ld at 1e-10; difference %.2e at "
      "1e-4, %.2e at 1e-10\n",
      static_cast<long>(e10.solver.iterations), static_cast<long>(m10.solver.iterations), d7, d10);
  // Since the coupled explicit path sweeps F in the matrix-free order inside the block
  // preconditioner (docs/preconditioners.md section 25), both back ends apply the same
  // preconditioner and their iterates agree to round-off at any tolerance (6.5e-14 at 1e-4,
  // 1.7e-13 at 1e-10; in index order the loose solve's difference was solver error, 2.8e-9, above
  // the tight one's): the difference no longer falls with the tolerance, it is round-off at both
  CHECK(d7 <= 1e-10);
  CHECK(d10 <= 1e-10);
}

namespace {

/// The matrix-free step of `in` under `scheme` with 1 thread twice and 2 threads twice: all four
/// bitwise equal.
template <int Dim>
void check_deterministic(const CoupledStepInput<Dim>& in, CouplingScheme scheme) {
  INFO(Dim << "D " << enum_name(scheme));
  const auto t0 = std::chrono::steady_clock::now();
  const int threads = omp_get_max_threads();
  const Backend mf = Backend::matrix_free;
  omp_set_num_threads(1);
  const CoupledSolveResult a = solve_coupled_step<Dim>(in, scheme, mf, solve_settings(1e-6));
  const CoupledSolveResult b = solve_coupled_step<Dim>(in, scheme, mf, solve_settings(1e-6));
  omp_set_num_threads(2);
  const CoupledSolveResult c = solve_coupled_step<Dim>(in, scheme, mf, solve_settings(1e-6));
  const CoupledSolveResult d = solve_coupled_step<Dim>(in, scheme, mf, solve_settings(1e-6));
  omp_set_num_threads(threads);
  CHECK(a.coupled_iterations + a.fluid_iterations > 0);
  CHECK(bitwise_equal(a, b));
  CHECK(bitwise_equal(c, d));
  CHECK(bitwise_equal(a, c));
  std::printf("determinism %dD %s: %ld iterations, 4 runs in %.2f s\n", Dim,
              enum_name(scheme).c_str(), a.coupled_iterations + a.fluid_iterations,
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
}

}  // namespace

TEST_CASE("Back ends: the matrix-free coupled step is deterministic, for 1 and 2 threads",
          "[unit][backends]") {
  // Every parallel loop of the matrix-free path writes each entry from one thread (face and
  // unknown gathers, colour groups of independent rows) and every reduction is serial (the
  // rigid sums over the body surface, Eigen's dot products in PCG and MPRGP), so the result does
  // not depend on the number of threads at all: 1 and 2 threads give the same bits.
  // small and at tolerance 1e-6: with 2 threads on a shared machine every parallel region's
  // barrier may wait for a descheduled thread, so the 2-thread runs cost far more than their
  // arithmetic (measured under load: a 2D 12^2 PVC-unified step with 30 friction rounds, 0.06 s
  // on 1 thread, 0.7-60 s on 2). The stencil loops (apply, rhs, face force) are parallel at any
  // size; the colour-group sweeps only above 512 rows per group, which these grids do not reach
  // (a 2D 48^2 PV-C step, which does, was bitwise equal too but took 35 s under load).
  check_deterministic<2>(random_scene<2>(12, 32, 0.8, 0.4, true), CouplingScheme::pv_c);
  check_deterministic<3>(random_scene<3>(6, 33, 0.8, 0.4, true), CouplingScheme::pvc_unified);
}

#ifdef MONOLITH_COUNTS_MALLOC
namespace {

/// mallocs made by f().
template <class F>
long mallocs_of(const F& f) {
  const long before = g_mallocs.load();
  f();
  return g_mallocs.load() - before;
}

template <int Dim>
void check_no_allocation(int n) {
  const CoupledStepInput<Dim> in = random_scene<Dim>(n, 41, 0.8, 0.4, true);
  const MonolithicSystem<Dim> m = make_system<Dim>(in, Backend::matrix_free);
  const MonolithicOperator<Dim> op(m, 1e-4);
  const FluidBodyOperator<Dim> fluid_body(m);
  const JacobiScaledOperator scaled(op);
  const LinearOperator& stokes = m.stokes_operator();
  const VectorX x = testing::random_vector(op.size(), 5), xf = x.head(m.num_fluid());
  const VectorX b = testing::random_vector(op.size(), 6), bf = b.head(m.num_fluid());
  std::vector<char> active(op.size(), 1);
  active[1] = 0;
  std::vector<char> active_f(active.begin(), active.begin() + m.num_fluid());
  VectorX y(op.size()), yf(m.num_fluid()), z = x, zf = xf;
  // warm up (first calls may size buffers), then count: the coupled operators may allocate only
  // what their fluid part F allocates itself (none of the rigid part, the contact block or the
  // splitting into blocks)
  op.apply(x, y);
  fluid_body.apply(xf, yf);
  scaled.apply(x, y);
  stokes.apply(xf, yf);
  const long fluid_apply = mallocs_of([&] { stokes.apply(xf, yf); });
  const long fluid_sweeps = mallocs_of([&] {
    stokes.forward_sweep(bf, zf, 1.0, &active_f);
    stokes.backward_sweep(bf, zf, 1.0, &active_f);
  });
  CHECK(mallocs_of([&] { op.apply(x, y); }) == fluid_apply);
  CHECK(mallocs_of([&] { fluid_body.apply(xf, yf); }) == fluid_apply);
  CHECK(mallocs_of([&] { scaled.apply(x, y); }) == fluid_apply);
  CHECK(mallocs_of([&] {
          op.forward_sweep(b, z, 1.0, &active);
          op.backward_sweep(b, z, 1.0, &active);
        }) == fluid_sweeps);
  CHECK(mallocs_of([&] {
          scaled.forward_sweep(b, z, 1.0, &active);
          scaled.backward_sweep(b, z, 1.0, &active);
        }) == fluid_sweeps);
  std::printf("%dD: mallocs per apply: fluid part %ld, coupled operators the same\n", Dim,
              fluid_apply);
}

}  // namespace

TEST_CASE("Back ends: the matrix-free coupled operators allocate nothing per apply or sweep",
          "[unit][backends]") {
  // the counter sees Eigen's allocations
  REQUIRE(mallocs_of([] {
            VectorX v = VectorX::Ones(1000);
            REQUIRE(v.sum() == 1000.0);
          }) >= 1);
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  // The core monitor (ProcessTeam, core/parallel.hpp) reads /proc/stat through a stream at the
  // first team query after each 100 ms window, and that read allocates: a count that happens to
  // straddle a window would hold it (seen once under load). It is the process's service, not the
  // operators', so it is off while counting.
  const bool monitor = core_monitor();
  set_core_monitor(false);
  check_no_allocation<2>(16);
  check_no_allocation<3>(8);
  set_core_monitor(monitor);
  omp_set_num_threads(threads);
}
#endif

namespace {

/// z = SSOR^-1 r of an operator (forward then backward sweep from zero), as PCG and MPRGP apply it.
VectorX ssor(const LinearOperator& a, const VectorX& r, const std::vector<char>* active) {
  VectorX z = VectorX::Zero(r.size());
  a.forward_sweep(r, z, 1.0, active);
  a.backward_sweep(r, z, 1.0, active);
  return z;
}

/// |r2^T M^-1 r1 - r1^T M^-1 r2| relative: the SSOR preconditioner M^-1 must be symmetric for CG.
template <int Dim>
void check_ssor_symmetric(Backend backend, int n) {
  const CoupledStepInput<Dim> in = random_scene<Dim>(n, 61, 0.8, 0.4, true);
  const MonolithicSystem<Dim> s = make_system<Dim>(in, backend);
  const MonolithicOperator<Dim> op(s, 1e-4);
  const JacobiScaledOperator scaled(op);
  std::vector<char> active(op.size(), 1);
  for (int i = 0; i < op.size(); i += 7) active[i] = 0;
  active[op.size() - 1] = 0;  // a contact at its bound
  const VectorX r1 = testing::random_vector(op.size(), 1),
                r2 = testing::random_vector(op.size(), 2);
  for (const LinearOperator* a :
       {static_cast<const LinearOperator*>(&op), static_cast<const LinearOperator*>(&scaled)})
    for (const std::vector<char>* mask : {static_cast<const std::vector<char>*>(nullptr),
                                          static_cast<const std::vector<char>*>(&active)}) {
      const VectorX z1 = ssor(*a, r1, mask), z2 = ssor(*a, r2, mask);
      const double d = std::abs(r2.dot(z1) - r1.dot(z2)) / (r1.norm() * z2.norm());
      INFO(enum_name(backend) << (a == &op ? " unscaled" : " scaled") << (mask ? " masked" : ""));
      CHECK(d <= 1e-12);
      if (mask)
        for (int i = 0; i < op.size(); ++i)
          if (!active[i]) REQUIRE(z1[i] == 0.0);
    }
}

}  // namespace

TEST_CASE("Back ends: the SSOR preconditioner of the coupled operators is symmetric",
          "[unit][backends]") {
  for (const Backend backend : {Backend::explicit_matrices, Backend::matrix_free}) {
    check_ssor_symmetric<2>(backend, 16);
    check_ssor_symmetric<3>(backend, 8);
  }
}

TEST_CASE("Back ends: Jacobi rows keep SSOR-preconditioned MPRGP on (26) below plain MPRGP",
          "[unit][backends]") {
  // Regression: the coupled operators sweep only the sparse part S of (24) (CoupledOperator),
  // and on this 3D 20^3 scene diag(A) / diag(S) reaches 3.7e11 on 5 rows; masked SSOR of S then
  // made MPRGP slower than without a preconditioner (165 explicit, 348 matrixfree, against 99),
  // and on 24^3 catastrophically (741 / 5733 against 130 / 135). mprgp_solve now gives the rows
  // whose sweep diagonal is below half of A's a Jacobi step (sweep_diagonal_mismatch).
  // Measured after the fix: 46 explicit, 60 matrixfree, against 99 unpreconditioned.
  // Those rows came from the overlap rule's round-off (W_F^u = 1.1e-16 on faces two bodies
  // cover), which solid_weights no longer leaves (energy15); the scene puts it back
  // (overlap_round_off) so that the rows this case is about are there, and checks they are.
  // The scene as solid_weights now gives it (largest ratio about 2.8) must not make SSOR lose
  // to plain MPRGP either.
  for (const bool round_off : {true, false}) {
    const CoupledStepInput<3> in = random_scene<3>(20, 51, 0.8, 0.0, false, round_off);
    for (const Backend backend : {Backend::explicit_matrices, Backend::matrix_free}) {
      const MonolithicSystem<3> s = make_system<3>(in, backend);
      const MonolithicOperator<3> op(s, 1e-4);
      const JacobiScaledOperator scaled(op);
      const VectorX diagonal = op.diagonal(), swept = op.sweep_diagonal();
      double largest_ratio = 0.0;
      for (int i = 0; i < diagonal.size(); ++i)
        if (diagonal[i] > 0.0 && swept[i] > 0.0)
          largest_ratio = std::max(largest_ratio, diagonal[i] / swept[i]);
      INFO(enum_name(backend) << (round_off ? " (round-off rows)" : " (solid_weights)")
                              << ": largest diag(A) / diag(S) " << largest_ratio);
      if (round_off) REQUIRE(largest_ratio > 1e6);
      const int n = op.size(), nc = s.num_contacts();
      VectorX lower = VectorX::Constant(n, -std::numeric_limits<double>::infinity());
      VectorX upper = VectorX::Constant(n, std::numeric_limits<double>::infinity());
      lower.tail(nc).setZero();
      const VectorX b = scaled.scale().cwiseProduct(s.mlcp_rhs(VectorX::Zero(s.num_friction())));
      int steps[2] = {0, 0};
      VectorX sol[2];
      for (int pre = 0; pre < 2; ++pre) {
        MprgpSettings ms;
        ms.max_iterations = 2000;
        ms.precondition = pre == 1;
        sol[pre] = VectorX::Zero(n);
        const MprgpResult m = mprgp_solve(scaled, b, lower, upper, sol[pre], ms);
        REQUIRE(m.converged);
        steps[pre] = m.iterations;
      }
      INFO(enum_name(backend) << ": plain " << steps[0] << ", SSOR " << steps[1]);
      CHECK(steps[1] <= steps[0]);
      if (round_off) CHECK(steps[1] <= 80);
    }
  }
}

namespace {

/// A viscous liquid disk (eta 10, centre (0.5, 0.45), radius 0.25) in the walled unit square at
/// n^2 with a dynamic box (half size 0.08, density 700) half immersed in its top: the liquid and
/// the box both move with the velocity `common` (a rigid translation: b1 = b2 = 0 in exact
/// arithmetic, docs/coupling.md "Consistent force exchange"), every face's u* moved by up to
/// two ulps as a particle transfer leaves it (`noise`), or, with `common` empty, a random u*
/// and box velocity (a real right-hand side). No contacts (the box is far from the walls).
CoupledStepInput<2> flight_scene(int n, bool rigid, unsigned seed) {
  CoupledStepInput<2> in{testing::unit_grid<2>(n), {}, kDt, {}, {}, {}, {}, {}};
  const double dx = in.grid.dx();
  const Vec<2> common(1.5, -0.7 + kGravity * kDt);
  in.bodies = {make_body<2>(box_shape<2>(Vec<2>(0.5, 0.68), 0.08), 700.0, 0.3)};
  BodyVec<2> v = BodyVec<2>::Zero();
  if (rigid) {
    v.head<2>() = common;
  } else {
    for (int k = 0; k < kBodyDofs<2>; ++k) v[k] = 0.5 * jitter(seed, k);
  }
  in.bodies[0].set_generalized_velocity(v);
  const auto boundary = testing::all_boundaries<2>(BoundaryType::wall);
  in.solids = solid_weights<2>(in.grid, coupling_bodies(in.bodies), {}, boundary, 0.01 * dx);
  const VectorX phi = testing::sample_lattice<2>(
      half_lattice(in.grid), [](const Vec<2>& x) { return (x - Vec<2>(0.5, 0.45)).norm() - 0.25; });
  in.weights = coupled_stokes_weights<2>(in.grid, in.solids, phi, kRho, 10.0);
  if (rigid) {
    in.u_star = testing::uniform_face_velocity_with_ulps<2>(in.grid, common, seed);
  } else {
    in.u_star = 0.3 * testing::random_vector(in.grid.num_faces(), seed + 1);
  }
  in.contacts = detect_contacts<2>(in.bodies, testing::unit_box_walls<2>(0.3), 0.3 * dx);
  in.contact_params.dt = kDt;
  in.contact_params.dx = dx;
  return in;
}

}  // namespace

TEST_CASE("Back ends: a liquid in free flight beside a body is solved by neither back end",
          "[unit][backends]") {
  // docs/preconditioners.md section 26: where the liquid and the body touching it translate
  // together, b1 and b2 are zero in exact arithmetic and only round-off remains, different on the
  // two back ends (their sums run in different orders). PCG's relative test then solved that
  // noise to 1e-6 of itself, in a different number of iterations on each back end (2 against 3
  // on viscous-sphere-bunny-wall-2d's free-flight steps). A right-hand side at or below
  // MonolithicSystem::rhs_round_off is zero: x = 0 without iterations on both.
  const CoupledStepInput<2> in = flight_scene(24, true, 31);
  REQUIRE(in.contacts.empty());
  const MonolithicSystem<2> e = make_system<2>(in, Backend::explicit_matrices);
  const MonolithicSystem<2> m = make_system<2>(in, Backend::matrix_free);
  REQUIRE(e.num_stress() > 0);
  REQUIRE(e.num_pressure() > 0);
  // the box touches the liquid: its columns of B_f are not all zero
  const VectorX f = e.fluid_body_force_transpose(VectorX::Ones(e.num_body_dofs()));
  REQUIRE(f.cwiseAbs().maxCoeff() > 0.0);
  // one formula from the inputs: the same bits on both back ends
  CHECK(e.rhs_round_off() == m.rhs_round_off());
  CHECK(e.rhs_round_off() > 0.0);
  const double be = e.rhs().cwiseAbs().maxCoeff(), bm = m.rhs().cwiseAbs().maxCoeff();
  std::printf("free flight: ||b|| explicit %.2e, matrixfree %.2e, round-off level %.2e\n", be, bm,
              e.rhs_round_off());
  // the case is the noise case: b is not exactly zero, and different on the two back ends
  CHECK(std::max(be, bm) > 0.0);
  CHECK(be <= e.rhs_round_off());
  CHECK(bm <= m.rhs_round_off());
  // solved by neither: no iteration, the same step on both back ends bit for bit
  const CoupledSolveResult re = solve_coupled_step<2>(
      in, CouplingScheme::pvc_unified, Backend::explicit_matrices, solve_settings(1e-6));
  const CoupledSolveResult rm = solve_coupled_step<2>(in, CouplingScheme::pvc_unified,
                                                      Backend::matrix_free, solve_settings(1e-6));
  CHECK(re.converged);
  CHECK(rm.converged);
  CHECK(re.coupled_iterations == 0);
  CHECK(rm.coupled_iterations == 0);
  CHECK(bitwise_equal(re.u, rm.u));
  CHECK(bitwise_equal(re.body_velocity, rm.body_velocity));
  CHECK(bitwise_equal(re.pressure, rm.pressure));
  // and the same system with a real right-hand side is far above the round-off level
  const CoupledStepInput<2> real = flight_scene(24, false, 31);
  const MonolithicSystem<2> er = make_system<2>(real, Backend::explicit_matrices);
  CHECK(er.rhs().cwiseAbs().maxCoeff() >= 1e6 * er.rhs_round_off());
}

TEST_CASE("Back ends: a coupled viscous system with a body: the same preconditioned solve",
          "[unit][backends]") {
  // The fluid-body block A_ff of a viscous liquid with a body touching it (no contacts: the PCG
  // solve of PVC-unified), a real right-hand side: both back ends' block preconditioners agree to
  // round-off on b (docs/preconditioners.md sections 24-25), PCG takes the same iterations
  // within one and reaches the same solution to the tolerance.
  const CoupledStepInput<2> in = flight_scene(24, false, 7);
  const MonolithicSystem<2> e = make_system<2>(in, Backend::explicit_matrices);
  const MonolithicSystem<2> m = make_system<2>(in, Backend::matrix_free);
  const FluidBodyOperator<2> oe(e), om(m);
  // (P4) on this contact-free system although P marks no near-empty cell (docs/preconditioners.md
  // section 30: off there by default)
  CoupledPreconditionerOptions with_correction;
  with_correction.contact_free_correction = true;
  const CoupledPreconditioner<2> pe(e, false, VectorX(), with_correction),
      pm(m, false, VectorX(), with_correction);
  REQUIRE(pe.body_correction());
  REQUIRE(pm.body_correction());
  const VectorX b = e.rhs();
  REQUIRE(relative_inf(m.rhs(), b) <= 1e-12);
  VectorX ze, zm;
  pe.apply(b, ze);
  pm.apply(b, zm);
  const double mr = relative_inf(zm, ze);
  PcgSettings settings;
  settings.tolerance = 1e-8;
  settings.zero_rhs = e.rhs_round_off();
  VectorX xe, xm;
  const PcgResult se = pcg_solve(oe, b, xe, settings, pe);
  const PcgResult sm = pcg_solve(om, m.rhs(), xm, settings, pm);
  std::printf("A_ff with a body: M b differs by %.1e; PCG %d / %d iterations, x differs by %.1e\n",
              mr, se.iterations, sm.iterations, relative_inf(xm, xe));
  CHECK(mr <= 1e-9);
  REQUIRE(se.converged);
  REQUIRE(sm.converged);
  CHECK(se.iterations >= 3);
  CHECK(std::abs(se.iterations - sm.iterations) <= 1);
  CHECK(relative_inf(xm, xe) <= 1e-6);
}

namespace {

/// Frames 1..frames of a built-in scene on one back end (no pictures).
std::vector<FrameStats> scene_frames(const std::string& scene, const std::string& backend,
                                     int frames) {
  const SceneDesc s = load_scene(scene, {"render.enabled=false", "solver.backend=" + backend});
  auto sim = make_simulation(s);
  std::vector<FrameStats> out;
  for (int k = 0; k < frames; ++k) out.push_back(sim->advance_frame());
  return out;
}

}  // namespace

TEST_CASE("Back ends: the coupled 2D viscous scenes take the same iterations frame by frame",
          "[unit][backends]") {
  // The observation (docs/preconditioners.md section 26): from the same start the two
  // back ends took different iteration counts from frame 1 on (viscous-sphere-bunny-wall-2d 49
  // against 43, viscous-sphere-bunny-air-2d 40 against 36), all of the difference in the
  // free-flight steps whose right-hand side is round-off. With those steps unsolved, every frame
  // takes the same iterations on both back ends and the states agree to round-off.
  for (const auto& [scene, frames] : std::vector<std::pair<std::string, int>>{
           {"viscous-sphere-bunny-wall-2d", 2}, {"viscous-sphere-bunny-air-2d", 3}}) {
    const std::vector<FrameStats> e = scene_frames(scene, "explicit", frames);
    const std::vector<FrameStats> m = scene_frames(scene, "matrixfree", frames);
    long total = 0;
    for (int k = 0; k < frames; ++k) {
      INFO(scene << " frame " << k + 1);
      REQUIRE(e[k].solver.converged);
      REQUIRE(m[k].solver.converged);
      CHECK(e[k].steps == m[k].steps);
      CHECK(e[k].solver.iterations == m[k].solver.iterations);
      CHECK(frame_difference(m[k], e[k]) <= 1e-10);
      total += m[k].solver.iterations;
      std::printf("%s frame %d: explicit %ld, matrixfree %ld iterations; difference %.1e\n",
                  scene.c_str(), k + 1, static_cast<long>(e[k].solver.iterations),
                  static_cast<long>(m[k].solver.iterations), frame_difference(m[k], e[k]));
    }
    // the frames compared include real solves
    CHECK(total > 0);
  }
}
