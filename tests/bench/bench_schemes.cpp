// Benchmark of the nine coupling schemes of section 6 at solve level (not a test): one step's
// pressure / viscosity / contact solves (solve_coupled_step) on a scene like the paper's
// Fig. 3 / Fig. 7: a dynamic bowl (density 500) floating on liquid with a heavy box (density 2000)
// resting in it and a second heavy box on the tank floor, the liquid falling with 0.3 m/s plus one
// step of gravity; the PV variants with eta = 10 Pa s. Tolerance 1e-6, staggered cap 200 (the
// paper's settings for Fig. 3 / Fig. 7). Prints the columns of Tables 1-3 and the ratios
// PC-iterative / PC-unified and PVC-iterative / PVC-unified (the goal: >= 5x), the iterative
// schemes warm-started (the default) and cold (every solve from zero, rows marked "(cold)").
// T is the sum of the solve timers (operators, norm estimates and solves; not the assembly of
// eq. (24), which every scheme shares).
//
// Run: OMP_NUM_THREADS=1 build/bench/bench_schemes [2d|3d|all (default all)] [small|large|both]
//
// Second mode, `bench_schemes grid [eta (default 5000)] [n ...]`: the 3D bowl scene's PVC-unified
// system with the block preconditioner (coupled_preconditioner.hpp) at growing grids, with its
// parts switched off one at a time, to see which part's iterations grow with the grid
// (docs/preconditioners.md, section 17): the MLCP (26) by MPRGP (bodies, contacts; CG,
// expansion and proportioning steps) with the contact rows eliminated by their Schur complement
// (the default) and with the Jacobi contact rows, the latter without the Woodbury body term, the
// fluid-body block A_ff without the contact rows by PCG and by MPRGP (no bound: the two must
// agree within one step), and the fluid block F alone (the bodies' weights kept as static
// solids, no body unknowns) by PCG with P. Matrix-free back end, tolerance 1e-6, x0 = 0.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "reference/contact/collision.hpp"
#include "reference/coupling/coupled_preconditioner.hpp"
#include "reference/coupling/coupled_schemes.hpp"
#include "reference/coupling/monolithic_system.hpp"
#include "reference/solvers/pcg.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/grid/stress_weights.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/rigid/mass_properties.hpp"
#include "tests/support/body_helpers.hpp"

using namespace monolith;
using monolith::testing::make_body;

namespace {

constexpr double kRho = 1000.0, kGravity = -9.81, kDt = 0.01, kEta = 10.0, kLevel = 0.45;

template <int Dim>
std::vector<double> point(double x, double y) {
  std::vector<double> p = {x, y};
  if (Dim == 3) p.push_back(0.5);
  return p;
}

/// The bowl scene on n^Dim cells with viscosity eta.
template <int Dim>
CoupledStepInput<Dim> bowl_scene(int n, double eta) {
  std::array<bool, Dim> periodic{};
  CoupledStepInput<Dim> in{MacGrid<Dim>(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), periodic),
                           {}, kDt, {}, {}, {}, {}, {}};
  const double dx = in.grid.dx();
  // the bowl: outer radius 0.2, wall 0.04, centre at y = 0.5 (its bottom 0.15 under the surface)
  ShapeSpec bowl;
  bowl.type = ShapeType::bowl;
  bowl.center = point<Dim>(0.55, 0.5);
  bowl.radius = 0.2;
  bowl.thickness = 0.04;
  const double r_in = bowl.radius - bowl.thickness;
  // a box resting on the inside of the bowl: its bottom corners on the inner sphere
  ShapeSpec inner;
  inner.type = ShapeType::box;
  inner.half_size = std::vector<double>(Dim, 0.05);
  inner.half_size[1] = 0.04;
  const double corner = std::sqrt((Dim - 1) * 0.05 * 0.05);
  inner.center = point<Dim>(0.55, 0.5 - std::sqrt(r_in * r_in - corner * corner) + 0.04 - 0.05 * dx);
  // a box on the tank floor, 0.1 dx into it
  ShapeSpec floor_box;
  floor_box.type = ShapeType::box;
  floor_box.half_size = std::vector<double>(Dim, 0.06);
  floor_box.center = point<Dim>(0.2, 0.06 - 0.1 * dx);
  in.bodies = {make_body<Dim>(bowl, 500.0), make_body<Dim>(inner, 2000.0),
               make_body<Dim>(floor_box, 2000.0)};
  BodyVec<Dim> gv = BodyVec<Dim>::Zero();
  gv[1] = kGravity * kDt;
  for (RigidBody<Dim>& b : in.bodies) b.set_generalized_velocity(gv);
  // weights: liquid below the level and outside the bowl's inner sphere
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  in.solids = solid_weights<Dim>(in.grid, coupling_bodies(in.bodies), {}, boundary, 0.01 * dx);
  Vec<Dim> bowl_centre;
  for (int a = 0; a < Dim; ++a) bowl_centre[a] = bowl.center[a];
  const SampleLattice<Dim> lattice = half_lattice(in.grid);
  VectorX phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) {
    const Vec<Dim> x = lattice.position(lattice.coord(k));
    phi[k] = std::max(x[1] - kLevel, r_in - (x - bowl_centre).norm());
  }
  in.weights = coupled_stokes_weights<Dim>(in.grid, in.solids, phi, kRho, eta);
  in.u_star = VectorX::Zero(in.grid.num_faces());
  in.u_star.segment(in.grid.face_offset(1), in.grid.num_faces(1)).setConstant(-0.3 + kGravity * kDt);
  // contacts as the rigid world finds them (margin 0.1 dx), no friction or restitution
  const Walls<Dim> walls = testing::unit_box_walls<Dim>();
  const double search = 0.1 * dx + 2.0 * kDt * 0.4 + 0.1 * dx;
  in.contacts = detect_contacts<Dim>(in.bodies, walls, search);
  for (Contact<Dim>& c : in.contacts) c.friction = c.restitution = 0.0;
  in.contact_params.dt = kDt;
  in.contact_params.dx = dx;
  in.contact_params.restitution_threshold = 2.0 * -kGravity * kDt;
  return in;
}

template <int Dim>
void run(int n) {
  StaggeredSettings settings;
  settings.max_iterations = 200;
  settings.tolerance = 1e-6;
  settings.mprgp.tolerance = 1e-6;
  settings.mprgp.max_iterations = 20000;
  const CoupledStepInput<Dim> inviscid = bowl_scene<Dim>(n, 0.0);
  const CoupledStepInput<Dim> viscous = bowl_scene<Dim>(n, kEta);
  std::printf("\n%dD %d^%d, %zu contacts\n", Dim, n, Dim, inviscid.contacts.size());
  std::printf("| scheme | T (s) | P/PV (s) | C (s) | unified (s) | s_iter | p_iter | c_iter | pc_iter | "
              "p_dof | s_dof | c_dof | converged |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  double t_pc_it = 0, t_pc_un = 0, t_pvc_it = 0, t_pvc_un = 0, t_pc_cold = 0, t_pvc_cold = 0;
  auto row = [&](CouplingScheme s, bool warm) {
    const CoupledStepInput<Dim>& in = scheme_uses_viscosity(s) ? viscous : inviscid;
    CoupledSchemeOptions options;
    options.warm_start = warm;
    const CoupledSolveResult r = solve_coupled_step<Dim>(in, s, Backend::explicit_matrices, settings, options);
    const double solve_seconds = r.fluid_seconds + r.contact_seconds + r.coupled_seconds;
    const std::string name = enum_name(s) + (warm ? "" : " (cold)");
    std::printf("| %s | %.3f | %.3f | %.3f | %.3f | %d | %ld | %ld | %ld | %ld | %ld | %ld | %s |\n",
                name.c_str(), solve_seconds, r.fluid_seconds, r.contact_seconds, r.coupled_seconds,
                r.staggered_iterations, r.fluid_iterations, r.contact_iterations,
                r.coupled_iterations, r.pressure_dofs, r.stress_dofs, r.contact_dofs,
                r.converged ? "yes" : "no");
    std::fflush(stdout);
    return solve_seconds;
  };
  for (CouplingScheme s : enum_values<CouplingScheme>()) {
    const double t = row(s, true);
    if (s == CouplingScheme::pc_iterative) t_pc_it = t;
    if (s == CouplingScheme::pc_unified) t_pc_un = t;
    if (s == CouplingScheme::pvc_iterative) t_pvc_it = t;
    if (s == CouplingScheme::pvc_unified) t_pvc_un = t;
  }
  // the iterative schemes with every solve started from zero (CoupledSchemeOptions::warm_start)
  t_pc_cold = row(CouplingScheme::pc_iterative, false);
  t_pvc_cold = row(CouplingScheme::pvc_iterative, false);
  std::printf("PC-iterative / PC-unified = %.2f (cold %.2f), PVC-iterative / PVC-unified = %.2f "
              "(cold %.2f)\n",
              t_pc_it / t_pc_un, t_pc_cold / t_pc_un, t_pvc_it / t_pvc_un, t_pvc_cold / t_pvc_un);
}

/// Mode `grid`: one row per (grid, part) of the bowl scene's PVC-unified system.
void run_grid(int n, double eta) {
  constexpr int Dim = 3;
  using Clock = std::chrono::steady_clock;
  auto seconds_since = [](Clock::time_point t0) {
    return std::chrono::duration<double>(Clock::now() - t0).count();
  };
  StaggeredSettings settings;
  settings.max_iterations = 1;  // no friction in this scene: one MLCP solve
  settings.mprgp.tolerance = 1e-6;
  settings.mprgp.max_iterations = 20000;
  const CoupledStepInput<Dim> in = bowl_scene<Dim>(n, eta);
  const double stiffness = eta * kDt / (kRho * in.grid.dx() * in.grid.dx());
  auto system = [&](bool bodies, bool contacts) {
    const std::vector<RigidBody<Dim>> b = bodies ? in.bodies : std::vector<RigidBody<Dim>>();
    const ContactSystem<Dim> c(b, contacts ? in.contacts : std::vector<Contact<Dim>>(),
                               in.contact_params);
    return std::make_unique<MonolithicSystem<Dim>>(in.grid, StressForm::reduced, in.weights, in.dt,
                                                   in.u_star, b, in.solids, c,
                                                   Backend::matrix_free);
  };
  auto mlcp_row = [&](const char* part, const MonolithicSystem<Dim>& s, bool body_correction,
                      bool exact_contacts = true) {
    PvcUnifiedOptions o;
    o.exact_contacts = exact_contacts;
    o.jacobi_scaling = true;
    o.compute_updates = false;
    o.preconditioner = PreconditionerKind::multigrid;
    o.body_correction = body_correction;
    const auto t0 = Clock::now();
    const PvcUnifiedResult r = solve_pvc_unified(s, settings, o);
    std::printf("| %d | %.0f | %s | %d | %d | MPRGP %ld (%ld / %ld / %ld) | %.2e | %s | %.2f |\n", n,
                stiffness, part, s.num_fluid(), s.num_contacts(), r.mprgp_iterations, r.cg_steps,
                r.expansion_steps, r.proportioning_steps, r.max_relative_residual,
                r.converged ? "yes" : "no", seconds_since(t0));
    std::fflush(stdout);
  };
  auto pcg_row = [&](const char* part, const MonolithicSystem<Dim>& s) {
    const FluidBodyOperator<Dim> op(s);
    const auto t0 = Clock::now();
    const CoupledPreconditioner<Dim> m(s, false, VectorX());
    VectorX x = VectorX::Zero(s.num_fluid());
    PcgSettings pcg;
    pcg.tolerance = settings.mprgp.tolerance;
    pcg.max_iterations = settings.mprgp.max_iterations;
    const PcgResult r = pcg_solve(op, s.fluid_rhs(VectorX::Zero(s.num_contacts()),
                                                  VectorX::Zero(s.num_friction())),
                                  x, pcg, m);
    std::printf("| %d | %.0f | %s | %d | 0 | PCG %d | %.2e | %s | %.2f |\n", n, stiffness, part,
                s.num_fluid(), r.iterations, r.relative_residual, r.converged ? "yes" : "no",
                seconds_since(t0));
    std::fflush(stdout);
  };
  const auto full = system(true, true);
  mlcp_row("(26): bodies, contacts, Woodbury term, contacts by S_c", *full, true);
  mlcp_row("(26): bodies, contacts, Woodbury term, Jacobi contact rows", *full, true, false);
  mlcp_row("(26): bodies, contacts, Q = P, Jacobi contact rows", *full, false, false);
  const auto no_contacts = system(true, false);
  pcg_row("A_ff: bodies, no contacts", *no_contacts);
  mlcp_row("A_ff: bodies, no contacts", *no_contacts, true);
  const auto fluid = system(false, false);
  pcg_row("F: no bodies (static solids), P only", *fluid);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc > 1 && std::strcmp(argv[1], "grid") == 0) {
    const double eta = argc > 2 ? std::atof(argv[2]) : 5000.0;
    std::vector<int> grids;
    for (int k = 3; k < argc; ++k) grids.push_back(std::atoi(argv[k]));
    if (grids.empty()) grids = {16, 24, 32};
    std::printf("bowl scene 3D, PVC-unified system, eta %g, block preconditioner, matrix-free\n", eta);
    std::printf("| n | stiffness | part | fluid rows | contacts | iterations (CG / expansion / proportioning) | residual | converged | s |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|\n");
    for (int n : grids) run_grid(n, eta);
    return 0;
  }
  const std::string dims = argc > 1 ? argv[1] : "all";
  const std::string sizes = argc > 2 ? argv[2] : "both";
  const bool small = sizes != "large", large = sizes != "small";
  if (dims != "3d") {
    if (small) run<2>(64);
    if (large) run<2>(128);
  }
  if (dims != "2d") {
    if (small) run<3>(24);
    if (large) run<3>(32);
  }
  return 0;
}
