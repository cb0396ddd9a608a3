// The unified pressure-viscosity (Stokes) solve of eq. (8) with stress reduction (section 4.4.2).
#include <catch2/catch.hpp>
#include <Eigen/Dense>
#include <cmath>
#include <cstring>
#include <omp.h>

#include "reference/fluid/deformation_rate.hpp"
#include "reference/fluid/gradient.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/grid/stress_weights.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/oracle/cholmod_solver.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using monolith::testing::random_vector;
using monolith::testing::stokes_weights;
using monolith::testing::TestBall;
using monolith::testing::TestBox;

namespace {

/// A small Stokes problem: grid, weights of eq. (8) and a random u*.
template <int Dim>
struct StokesCase {
  MacGrid<Dim> grid;
  StokesWeights w;
  VectorX u_star;
  double dt = 0.01;
};

struct CaseOptions {
  int n = 8;
  bool periodic_x = false;
  bool free_surface = true;  ///< liquid blob below a wavy surface; false: the box is full
  bool solid = true;         ///< a solid ball in the liquid
  double eta = 2.0;          ///< mean viscosity, Pa s (varies in space around it)
  bool vary_density = true;
  unsigned seed = 1;
};

template <int Dim>
StokesCase<Dim> make_case(const CaseOptions& o) {
  StokesCase<Dim> sc;
  std::array<bool, Dim> periodic{};
  periodic[0] = o.periodic_x;
  sc.grid = MacGrid<Dim>(Vec<Dim>::Zero(), 1.0 / o.n, VecI<Dim>::Constant(o.n), periodic);
  const MacGrid<Dim>& grid = sc.grid;
  const StressGrid<Dim> stress(grid);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  if (o.periodic_x) boundary[0] = boundary[1] = BoundaryType::periodic;
  boundary[3] = BoundaryType::open;  // top
  // solids and liquid
  std::vector<ShapePtr<Dim>> solids;
  if (o.solid) solids.push_back(std::make_shared<TestBall<Dim>>(Vec<Dim>::Constant(0.37), 0.16));
  const VectorX solid_phi = solid_phi_on_lattice<Dim>(grid, lattice, solids, 0.0);
  VectorX liquid_phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) {
    const Vec<Dim> x = lattice.position(lattice.coord(k));
    liquid_phi[k] = o.free_surface ? x[1] - 0.62 - 0.08 * std::sin(2.0 * M_PI * x[0]) : -1.0;
  }
  // the weights of eq. (8)
  sc.w = stokes_weights(grid, solid_phi, liquid_phi, boundary, 1000.0, o.eta);
  if (o.vary_density)
    sc.w.pressure.face_density += 200.0 * random_vector(grid.num_faces(), o.seed + 7);
  // eta smooth in space, the same for all components at one position
  for (int d = 0; d < stress.num_dofs(); ++d) {
    const auto [k, c] = stress.coord(d);
    const Vec<Dim> x = stress.position(k, c);
    sc.w.viscosity[d] = o.eta * (1.0 + 0.5 * std::sin(3.0 * x[0] + 2.0 * x[1]));
  }
  sc.u_star = random_vector(grid.num_faces(), o.seed);
  return sc;
}

double rel_diff(const VectorX& a, const VectorX& b) {
  const double scale = std::max(a.cwiseAbs().maxCoeff(), b.cwiseAbs().maxCoeff());
  return scale > 0.0 ? (a - b).cwiseAbs().maxCoeff() / scale : 0.0;
}

/// The exact solution of the explicit system (CHOLMOD) and the updated velocity.
template <int Dim>
struct DirectSolution {
  VectorX x, u, tau, p;
  StokesDofs dofs;
};

template <int Dim>
DirectSolution<Dim> direct_solve(const StokesCase<Dim>& sc, StokesUnknowns unknowns, StressForm form) {
  DirectSolution<Dim> s;
  const StressLayout<Dim> layout(StressGrid<Dim>(sc.grid), form);
  s.dofs = select_stokes_dofs(sc.grid, layout, sc.w, sc.dt, unknowns);
  REQUIRE(s.dofs.null_space.empty());
  const ExplicitStokesSystem sys = assemble_explicit_stokes(sc.grid, layout, sc.w, s.dofs, sc.dt, sc.u_star);
  s.x = cholmod_solve(sys.A, sys.b);
  s.tau = scatter_stress(layout, s.dofs, s.x);
  s.p = scatter_stokes_pressure(s.dofs, s.x, sc.grid.num_cells());
  s.u = sc.u_star;
  apply_stokes_update(sc.grid, layout, sc.w, sc.dt, s.p, s.tau, s.u);
  return s;
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("the Stokes system is symmetric positive definite", "[dense-reference]",
                       ((int Dim), Dim), 2, 3) {
  CaseOptions o;
  o.n = Dim == 2 ? 8 : 4;
  const auto sc = make_case<Dim>(o);
  for (StressForm form : {StressForm::full, StressForm::reduced})
    for (StokesUnknowns unknowns : {StokesUnknowns::pressure_and_stress, StokesUnknowns::stress_only}) {
      const StressLayout<Dim> layout(StressGrid<Dim>(sc.grid), form);
      const StokesDofs dofs = select_stokes_dofs(sc.grid, layout, sc.w, sc.dt, unknowns);
      const ExplicitStokesSystem sys = assemble_explicit_stokes(sc.grid, layout, sc.w, dofs, sc.dt, sc.u_star);
      REQUIRE(dofs.num_stress() > 0);
      REQUIRE((unknowns == StokesUnknowns::stress_only) == (dofs.num_pressure() == 0));
      const Eigen::MatrixXd A(sys.A);
      REQUIRE(A.rows() == dofs.size());
      const double scale = A.cwiseAbs().maxCoeff();
      CHECK((A - A.transpose()).cwiseAbs().maxCoeff() <= 1e-14 * scale);
      const Eigen::VectorXd eig = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(A).eigenvalues();
      INFO("form " << int(form) << " unknowns " << int(unknowns) << " eigenvalues " << eig.minCoeff()
                   << " .. " << eig.maxCoeff());
      CHECK(eig.minCoeff() > 1e-10 * eig.maxCoeff());
      // the blocks are what A is made of
      const int ns = dofs.num_stress();
      CHECK((A.topLeftCorner(ns, ns) - Eigen::MatrixXd(sys.A11)).cwiseAbs().maxCoeff() == 0.0);
      if (dofs.num_pressure() > 0) {
        CHECK((A.topRightCorner(ns, dofs.num_pressure()) - Eigen::MatrixXd(sys.A12)).cwiseAbs().maxCoeff() == 0.0);
        CHECK((A.bottomRightCorner(dofs.num_pressure(), dofs.num_pressure()) - Eigen::MatrixXd(sys.A22))
                  .cwiseAbs().maxCoeff() == 0.0);
      }
    }
}

TEMPLATE_TEST_CASE_SIG("explicit and matrix-free Stokes operators agree", "[unit]", ((int Dim), Dim), 2, 3) {
  for (bool periodic : {false, true}) {
    CaseOptions o;
    o.n = Dim == 2 ? 10 : 5;  // 5: an odd periodic axis (serial sweeps)
    o.periodic_x = periodic;
    const auto sc = make_case<Dim>(o);
    for (StressForm form : {StressForm::full, StressForm::reduced})
      for (StokesUnknowns unknowns : {StokesUnknowns::pressure_and_stress, StokesUnknowns::stress_only}) {
        const StressLayout<Dim> layout(StressGrid<Dim>(sc.grid), form);
        const StokesDofs dofs = select_stokes_dofs(sc.grid, layout, sc.w, sc.dt, unknowns);
        const ExplicitStokesSystem sys = assemble_explicit_stokes(sc.grid, layout, sc.w, dofs, sc.dt, sc.u_star);
        const MatrixFreeStokesOperator<Dim> op(sc.grid, layout, sc.w, dofs, sc.dt);
        REQUIRE(op.size() == sys.A.rows());
        const SparseMatrixOperator ref(sys.A);
        for (unsigned seed = 1; seed <= 3; ++seed) {
          const VectorX x = random_vector(op.size(), 100 + seed);
          VectorX y_mf, y_ex;
          op.apply(x, y_mf);
          ref.apply(x, y_ex);
          CHECK(rel_diff(y_mf, y_ex) < 1e-12);
        }
        // one SSOR application is symmetric: <M^-1 a, b> = <a, M^-1 b>
        const VectorX a = random_vector(op.size(), 11), b = random_vector(op.size(), 12);
        VectorX za, zb;
        ssor_precondition(op, a, za, 1.0);
        ssor_precondition(op, b, zb, 1.0);
        CHECK(std::abs(za.dot(b) - a.dot(zb)) < 1e-10 * std::abs(za.dot(b)));
        CHECK(rel_diff(op.diagonal(), VectorX(sys.A.diagonal())) < 1e-13);
        // B x is the force of the update: G W_L^p p + D^T M W_L^s tau
        {
          const VectorX x = random_vector(op.size(), 200);
          const VectorX tau = scatter_stress(layout, dofs, x);
          const VectorX p = scatter_stokes_pressure(dofs, x, sc.grid.num_cells());
          const VectorX force = sys.G * (sys.W_L_p * p) + sys.D.transpose() * (sys.M * (sys.W_L_s * tau));
          CHECK(rel_diff(op.face_force(x), force) < 1e-13);
          int entries = 0;
          for (int i = 0; i < op.size(); ++i) entries += static_cast<int>(op.stencil(i).size());
          CHECK(entries > op.size());
        }
        CHECK(rel_diff(op.rhs(sc.u_star), sys.b) < 1e-13);
      }
  }
}

TEMPLATE_TEST_CASE_SIG("matrix-free Stokes operator: even periodic axis, same results on 1 and 2 threads",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // an even periodic axis keeps the red-black colouring, so every colour group is relaxed in
  // parallel (the odd case above runs serially); apply and SSOR must not depend on the threads
  CaseOptions o;
  o.n = Dim == 2 ? 12 : 6;
  o.periodic_x = true;
  const auto sc = make_case<Dim>(o);
  for (StressForm form : {StressForm::full, StressForm::reduced}) {
    const StressLayout<Dim> layout(StressGrid<Dim>(sc.grid), form);
    const StokesDofs dofs = select_stokes_dofs(sc.grid, layout, sc.w, sc.dt, StokesUnknowns::pressure_and_stress);
    const ExplicitStokesSystem sys = assemble_explicit_stokes(sc.grid, layout, sc.w, dofs, sc.dt, sc.u_star);
    const MatrixFreeStokesOperator<Dim> op(sc.grid, layout, sc.w, dofs, sc.dt);
    const SparseMatrixOperator ref(sys.A);
    const VectorX x = random_vector(op.size(), 300);
    VectorX y_ex;
    ref.apply(x, y_ex);
    std::array<VectorX, 2> y, z;
    const int threads = omp_get_max_threads();
    for (int t = 0; t < 2; ++t) {
      omp_set_num_threads(t + 1);
      op.apply(x, y[t]);
      ssor_precondition(op, x, z[t], 1.0);
    }
    omp_set_num_threads(threads);
    CHECK(rel_diff(y[0], y_ex) < 1e-12);
    CHECK((y[0] - y[1]).cwiseAbs().maxCoeff() == 0.0);
    CHECK((z[0] - z[1]).cwiseAbs().maxCoeff() == 0.0);
    // SSOR is symmetric here too
    const VectorX b = random_vector(op.size(), 301);
    VectorX zb;
    ssor_precondition(op, b, zb, 1.0);
    CHECK(std::abs(z[0].dot(b) - x.dot(zb)) < 1e-10 * std::abs(z[0].dot(b)));
    CHECK(rel_diff(op.rhs(sc.u_star), sys.b) < 1e-13);
  }
}

TEMPLATE_TEST_CASE_SIG("SSOR-PCG agrees with CHOLMOD on both back ends and both forms",
                       "[dense-reference]", ((int Dim), Dim), 2, 3) {
  CaseOptions o;
  o.n = Dim == 2 ? 12 : 6;
  const auto sc = make_case<Dim>(o);
  PcgSettings settings;
  settings.tolerance = 1e-10;
  for (StressForm form : {StressForm::full, StressForm::reduced})
    for (StokesUnknowns unknowns : {StokesUnknowns::pressure_and_stress, StokesUnknowns::stress_only}) {
      const DirectSolution<Dim> exact = direct_solve(sc, unknowns, form);
      for (const Backend backend : {Backend::explicit_matrices, Backend::matrix_free}) {
        VectorX u = sc.u_star;
        const StokesSolveResult r = solve_stokes(sc.grid, sc.w, sc.dt, unknowns, form, backend, settings, u);
        INFO(enum_name(backend) << " form " << int(form) << " unknowns " << int(unknowns) << " iterations "
                     << r.pcg.iterations);
        REQUIRE(r.pcg.converged);
        CHECK(r.stress_dofs == exact.dofs.num_stress());
        CHECK(r.pressure_dofs == exact.dofs.num_pressure());
        // residual 1e-10 relative: the solution to ~cond * 1e-10; measured below 1e-7
        CHECK(rel_diff(u, exact.u) < 1e-7);
        CHECK(rel_diff(r.stress, exact.tau) < 1e-6);
        if (exact.p.size() > 0 && unknowns == StokesUnknowns::pressure_and_stress)
          CHECK(rel_diff(r.pressure, exact.p) < 1e-6);
      }
    }
}

TEMPLATE_TEST_CASE_SIG("stress reduction: reduced and full forms give the same velocity update",
                       "[dense-reference]", ((int Dim), Dim), 2, 3) {
  // The reduced form is eq. (8) restricted to traceless tau (tau = E tau_r). It reproduces the
  // full optimum exactly iff that optimum is traceless at every cell with diagonal stress DOFs.
  // At the full optimum tau_aa = 2 eta (D W_F^u u)_aa / W_F^s (all diagonal DOFs of a cell share
  // eta and W^s), so its trace is 2 eta / W_F^s times the weighted divergence of the new
  // velocity, which the pressure optimality makes zero on every pressure DOF (and which is zero
  // on a cell with no open face). Hence: exact for the PV solve, with solids and free surfaces
  // alike; not for the stress-only (VC) solve, whose velocity is not divergence free.
  for (bool solid : {false, true})
    for (bool free_surface : {false, true}) {
      CaseOptions o;
      o.n = Dim == 2 ? 10 : 5;
      o.solid = solid;
      o.free_surface = free_surface;
      const auto sc = make_case<Dim>(o);
      const auto full = direct_solve(sc, StokesUnknowns::pressure_and_stress, StressForm::full);
      const auto reduced = direct_solve(sc, StokesUnknowns::pressure_and_stress, StressForm::reduced);
      INFO("solid " << solid << " free surface " << free_surface);
      // measured: 1e-15 .. 1e-13 (round-off)
      CHECK(rel_diff(full.u, reduced.u) < 1e-11);
      CHECK(rel_diff(full.tau, reduced.tau) < 1e-11);
      CHECK(rel_diff(full.p, reduced.p) < 1e-11);
      // the full optimum's trace, relative to its largest diagonal stress
      const StressGrid<Dim> stress(sc.grid);
      VectorX trace = VectorX::Zero(sc.grid.num_cells());
      for (int a = 0; a < Dim; ++a) trace += full.tau.segment(stress.offset(a), sc.grid.num_cells());
      CHECK(trace.cwiseAbs().maxCoeff() < 1e-11 * full.tau.head(Dim * sc.grid.num_cells()).cwiseAbs().maxCoeff());
    }
  // the VC step: the full optimum has a trace and the reduced form differs (measured, reported)
  CaseOptions o;
  o.n = Dim == 2 ? 10 : 5;
  const auto sc = make_case<Dim>(o);
  const auto full = direct_solve(sc, StokesUnknowns::stress_only, StressForm::full);
  const auto reduced = direct_solve(sc, StokesUnknowns::stress_only, StressForm::reduced);
  const double difference = rel_diff(full.u, reduced.u);
  WARN("stress-only (VC) solve, " << Dim << "D: reduced vs full velocity update differ by "
                                 << difference << " (relative max norm)");
  CHECK(difference > 1e-6);
}

TEMPLATE_TEST_CASE_SIG("D of a rigid motion gives no stress right-hand side on interior DOFs",
                       "[property]", ((int Dim), Dim), 2, 3) {
  // b1 = W_L^s M D W_F^u u* vanishes wherever all faces of the DOF's stencil are fully fluid
  CaseOptions o;
  o.n = Dim == 2 ? 12 : 6;
  auto sc = make_case<Dim>(o);
  const MacGrid<Dim>& grid = sc.grid;
  // u = t + omega x (x - c): translation plus rotation (about z in 2D, a general axis in 3D)
  const Vec<Dim> t = Vec<Dim>::LinSpaced(0.3, -0.7);
  Mat<Dim> W = Mat<Dim>::Zero();
  W(0, 1) = 0.8, W(1, 0) = -0.8;
  if constexpr (Dim == 3) W(0, 2) = -0.4, W(2, 0) = 0.4, W(1, 2) = 0.25, W(2, 1) = -0.25;
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [a, c] = grid.face_coord(f);
    const Vec<Dim> x = grid.face_center(a, c);
    sc.u_star[f] = (t + W * (x - Vec<Dim>::Constant(0.5)))[a];
  }
  for (StressForm form : {StressForm::full, StressForm::reduced}) {
    const StressLayout<Dim> layout(StressGrid<Dim>(grid), form);
    const StokesDofs dofs = select_stokes_dofs(grid, layout, sc.w, sc.dt, StokesUnknowns::stress_only);
    const ExplicitStokesSystem sys = assemble_explicit_stokes(grid, layout, sc.w, dofs, sc.dt, sc.u_star);
    int interior = 0;
    for (int k = 0; k < dofs.num_stress(); ++k) {
      // the faces this unknown acts on (its column of D^T M E)
      const VectorX e = VectorX::Unit(layout.num_unknowns(), dofs.unknown_of_dof[k]);
      const VectorX faces = sys.D.transpose() * (sys.M * layout.expand(e));
      bool full_fluid = true;
      for (int f = 0; f < faces.size(); ++f)
        if (faces[f] != 0.0 && sc.w.pressure.fluid_face[f] != 1.0) full_fluid = false;
      if (!full_fluid) continue;
      ++interior;
      CHECK(std::abs(sys.b1[k]) < 1e-12);
    }
    CHECK(interior > dofs.num_stress() / 4);
  }
}

TEMPLATE_TEST_CASE_SIG("eta = 0 everywhere reduces the Stokes solve to solve_pressure",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  CaseOptions o;
  o.n = Dim == 2 ? 12 : 6;
  o.eta = 0.0;
  const auto sc = make_case<Dim>(o);
  PcgSettings settings;
  settings.tolerance = 1e-12;
  for (const Backend backend : {Backend::explicit_matrices, Backend::matrix_free})
    for (StressForm form : {StressForm::full, StressForm::reduced}) {
      VectorX u_stokes = sc.u_star, u_pressure = sc.u_star;
      const auto rs = solve_stokes(sc.grid, sc.w, sc.dt, StokesUnknowns::pressure_and_stress, form, backend,
                                   settings, u_stokes);
      const auto rp = solve_pressure(sc.grid, sc.w.pressure, sc.dt, backend, settings, u_pressure);
      CHECK(rs.stress_dofs == 0);
      CHECK(rs.pressure_dofs == rp.dofs);
      CHECK(rs.stress.cwiseAbs().maxCoeff() == 0.0);
      // explicit: the same A22 and b2 (assembled by the pressure code), so the same PCG run bit for
      // bit; matrix-free: the same operator by a different stencil, equal to round-off
      CHECK(rs.pcg.iterations == rp.pcg.iterations);
      if (backend == Backend::explicit_matrices) {
        CHECK((u_stokes - u_pressure).cwiseAbs().maxCoeff() == 0.0);
        CHECK((rs.pressure - rp.pressure).cwiseAbs().maxCoeff() == 0.0);
      } else {
        CHECK(rel_diff(u_stokes, u_pressure) < 1e-13);
        CHECK(rel_diff(rs.pressure, rp.pressure) < 1e-12);
      }
    }
  // and the explicit blocks are the pressure system's
  const StressLayout<Dim> layout(StressGrid<Dim>(sc.grid), StressForm::reduced);
  const StokesDofs dofs = select_stokes_dofs(sc.grid, layout, sc.w, sc.dt, StokesUnknowns::pressure_and_stress);
  const auto stokes = assemble_explicit_stokes(sc.grid, layout, sc.w, dofs, sc.dt, sc.u_star);
  const auto pressure = assemble_explicit_pressure(sc.grid, sc.w.pressure, dofs.pressure, sc.dt, sc.u_star);
  CHECK(Eigen::MatrixXd(stokes.A - pressure.A).cwiseAbs().maxCoeff() == 0.0);
  CHECK((stokes.b - pressure.b).cwiseAbs().maxCoeff() == 0.0);
}

TEMPLATE_TEST_CASE_SIG("stress-only solve with eta -> infinity drives D u to zero (rigidification)",
                       "[property]", ((int Dim), Dim), 2, 3) {
  // the VC step of PC-VC-PC: as eta grows the optimum approaches the rigid motion; once
  // nu dt / dx^2 >> 1 (here 6.4 at eta = 1e4) the remaining strain rate shrinks like 1/eta
  CaseOptions o;
  o.n = Dim == 2 ? 8 : 4;
  o.free_surface = false;
  o.solid = false;
  o.periodic_x = true;
  o.vary_density = false;
  std::vector<double> strain;
  for (double eta : {1e4, 1e6, 1e8}) {
    o.eta = eta;
    const auto sc = make_case<Dim>(o);
    const auto s = direct_solve(sc, StokesUnknowns::stress_only, StressForm::full);
    const StressGrid<Dim> stress(sc.grid);
    const SparseMatrix D = deformation_rate_matrix(stress);
    // strain rate on the DOFs with stress, relative to that of u*
    const VectorX active = (sc.w.fluid_stress.cwiseProduct(sc.w.liquid_stress).array() > 0.0).template cast<double>();
    const VectorX du = active.cwiseProduct(D * sc.w.pressure.fluid_face.cwiseProduct(s.u));
    const VectorX du0 = active.cwiseProduct(D * sc.w.pressure.fluid_face.cwiseProduct(sc.u_star));
    strain.push_back(du.norm() / du0.norm());
  }
  INFO("relative strain rate " << strain[0] << " " << strain[1] << " " << strain[2]);
  // observed order in eta over each factor 100 (1 = 1/eta)
  const double order_low = std::log10(strain[0] / strain[1]) / 2.0;
  const double order_high = std::log10(strain[1] / strain[2]) / 2.0;
  INFO("orders " << order_low << " " << order_high);
  // measured at eta = 1e8: 4.9e-6 (2D), 1.2e-5 (3D) of the strain rate of u*
  CHECK(strain[2] < 5e-5);
  CHECK(order_low > 0.9);
  CHECK(order_high > 0.95);
}

TEMPLATE_TEST_CASE_SIG("Couette profile: tau_xy = eta s in the interior and on the no-slip wall",
                       "[validation]", ((int Dim), Dim), 2, 3) {
  // Source: plane Couette flow u = s y, v = 0 (y from a no-slip wall at y = 0) has the shear
  // stress tau_xy = eta du/dy = eta s everywhere (eq. (2)). Set-up: periodic in x (and z), no-slip
  // walls at y = 0 and y = 1, full of liquid, u* = s y. The static top wall disturbs the profile
  // only within a few cells of it: with r = nu dt / dx^2 = 0.01 the backward-Euler disturbance
  // decays by ~1/r per cell, so the lower quarter (at least 6 cells from the top wall) is exact
  // to round-off. Measured over the lower quarter: max relative error of tau_xy 1.4e-11 (2D) and
  // 6e-13 (3D), of u 5e-14 (the PCG tolerance is 1e-13); over the lower half of the 3D grid (4 cells from the top) 1.5e-7, the
  // top wall's disturbance. Tolerance 1e-10.
  const int n = Dim == 2 ? 16 : 8;
  std::array<bool, Dim> periodic;
  periodic.fill(true);
  periodic[1] = false;
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), periodic);
  const StressGrid<Dim> stress(grid);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::periodic);
  boundary[2] = boundary[3] = BoundaryType::wall;
  const double rho = 1000.0, eta = 1.0, s = 2.0;
  const double dt = 0.01 * rho * grid.dx() * grid.dx() / eta;
  const VectorX no_solid = solid_phi_on_lattice<Dim>(grid, lattice, {}, 0.0);
  const VectorX full = VectorX::Constant(lattice.size(), -1.0);
  const StokesWeights w = stokes_weights(grid, no_solid, full, boundary, rho, eta);
  VectorX u_star = VectorX::Zero(grid.num_faces());
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [a, c] = grid.face_coord(f);
    if (a == 0) u_star[f] = s * grid.face_center(a, c)[1];
  }
  PcgSettings settings;
  settings.tolerance = 1e-13;
  for (StressForm form : {StressForm::full, StressForm::reduced})
    for (const Backend backend : {Backend::explicit_matrices, Backend::matrix_free}) {
      VectorX u = u_star;
      const auto r = solve_stokes(grid, w, dt, StokesUnknowns::pressure_and_stress, form, backend, settings, u);
      REQUIRE(r.pcg.converged);
      const int xy = StressGrid<Dim>::component(0, 1);
      double tau_err = 0.0, u_err = 0.0;
      int wall_nodes = 0;
      for (int i = stress.offset(xy); i < stress.offset(xy) + stress.num_dofs(xy); ++i) {
        const VecI<Dim> c = stress.coord(i).second;
        if (c[1] > n / 4) continue;
        tau_err = std::max(tau_err, std::abs(r.stress[i] - eta * s) / (eta * s));
        wall_nodes += c[1] == 0;
      }
      for (int f = 0; f < grid.num_faces(); ++f) {
        const auto [a, c] = grid.face_coord(f);
        if (c[1] < n / 4) u_err = std::max(u_err, std::abs(u[f] - u_star[f]) / (s * 0.5));
      }
      INFO(enum_name(backend) << " form " << int(form) << ": tau_xy error " << tau_err << ", u error " << u_err);
      CHECK(wall_nodes > 0);
      CHECK(tau_err < 1e-10);
      CHECK(u_err < 1e-10);
    }
}

TEMPLATE_TEST_CASE_SIG("PCG iterations of the reduced and the full form", "[unit]", ((int Dim), Dim), 2, 3) {
  // the reduced form has fewer unknowns (2/3 in 2D, 5/6 in 3D); report its iteration count
  CaseOptions o;
  o.n = Dim == 2 ? 24 : 10;
  o.eta = 5.0;
  const auto sc = make_case<Dim>(o);
  PcgSettings settings;
  settings.tolerance = 1e-8;
  int iterations[2] = {0, 0}, unknowns[2] = {0, 0};
  for (StressForm form : {StressForm::full, StressForm::reduced}) {
    VectorX u = sc.u_star;
    const auto r = solve_stokes(sc.grid, sc.w, sc.dt, StokesUnknowns::pressure_and_stress, form,
                                Backend::matrix_free, settings, u);
    REQUIRE(r.pcg.converged);
    iterations[int(form)] = r.pcg.iterations;
    unknowns[int(form)] = r.stress_dofs + r.pressure_dofs;
  }
  WARN(Dim << "D " << o.n << "^" << Dim << ": full form " << unknowns[0] << " unknowns, "
           << iterations[0] << " PCG iterations; reduced form " << unknowns[1] << " unknowns, "
           << iterations[1] << " iterations");
  CHECK(unknowns[1] < unknowns[0]);
}

TEMPLATE_TEST_CASE_SIG("enclosed and periodic liquid: the (0, n_p) null space, PCG converges",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // a closed box full of liquid (walls everywhere) and a fully periodic box: A22 has the constant
  // W_L^p p as null vector and A12 n_p = 0, so (0, n_p) spans the null space of the whole A
  for (bool periodic : {false, true}) {
    const int n = Dim == 2 ? 8 : 4;
    std::array<bool, Dim> per;
    per.fill(periodic);
    const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), per);
    const StressGrid<Dim> stress(grid);
    const SampleLattice<Dim> lattice = half_lattice(grid);
    std::array<BoundaryType, 2 * Dim> boundary;
    boundary.fill(periodic ? BoundaryType::periodic : BoundaryType::wall);
    const VectorX no_solid = solid_phi_on_lattice<Dim>(grid, lattice, {}, 0.0);
    const VectorX full = VectorX::Constant(lattice.size(), -1.0);
    const StokesWeights w = stokes_weights(grid, no_solid, full, boundary, 1000.0, 3.0);
    const double dt = 0.01;
    const VectorX u_star = random_vector(grid.num_faces(), 4);
    for (StressForm form : {StressForm::full, StressForm::reduced}) {
      const StressLayout<Dim> layout(stress, form);
      const StokesDofs dofs = select_stokes_dofs(grid, layout, w, dt, StokesUnknowns::pressure_and_stress);
      REQUIRE(dofs.null_space.size() == 1);
      const ExplicitStokesSystem sys = assemble_explicit_stokes(grid, layout, w, dofs, dt, u_star);
      const VectorX& nv = dofs.null_space[0];
      CHECK(std::abs(nv.norm() - 1.0) < 1e-14);
      CHECK(nv.head(dofs.num_stress()).cwiseAbs().maxCoeff() == 0.0);
      CHECK((sys.A * nv).cwiseAbs().maxCoeff() < 1e-12 * Eigen::MatrixXd(sys.A).cwiseAbs().maxCoeff());
      PcgSettings settings;
      settings.tolerance = 1e-10;
      VectorX u_ex = u_star, u_mf = u_star;
      const auto re = solve_stokes(grid, w, dt, StokesUnknowns::pressure_and_stress, form, Backend::explicit_matrices, settings, u_ex);
      const auto rm = solve_stokes(grid, w, dt, StokesUnknowns::pressure_and_stress, form, Backend::matrix_free, settings, u_mf);
      INFO("periodic " << periodic << " form " << int(form) << " iterations " << re.pcg.iterations << " "
                       << rm.pcg.iterations);
      CHECK(re.pcg.converged);
      CHECK(rm.pcg.converged);
      CHECK(rel_diff(u_ex, u_mf) < 1e-8);
      // the new velocity is weighted-divergence free: the pressure rows of the residual are
      // W_L^p G^T W_F^u u_new, so their size is bounded by the PCG tolerance times ||b||_inf
      const VectorX div = w.pressure.liquid_cell.cwiseProduct(
          apply_gradient_transpose(grid, VectorX(w.pressure.fluid_face.cwiseProduct(u_ex))));
      CHECK(div.cwiseAbs().maxCoeff() <= 1.01e-10 * sys.b.cwiseAbs().maxCoeff());
    }
  }
}

TEMPLATE_TEST_CASE_SIG("a rigidly rotating free blob keeps its velocity exactly", "[property]",
                       ((int Dim), Dim), 2, 3) {
  // u* = t + W (x - c), W skew, on every face (the air faces carry the same rigid field, as
  // velocity extrapolation gives them). D u* = 0 on every DOF whose four faces are inside the
  // domain and G^T u* = 0 (a rigid field is discretely divergence free on the MAC grid), so
  // b = 0, the solution is (0, 0) and u is unchanged: no spurious viscous damping of rigid
  // motion. This relies on b1 reading u* on the dry faces of the surface stencils
  // (docs/stokes.md section 3); measured: |b| and |u - u*| at round-off (below 1e-15).
  const int n = Dim == 2 ? 16 : 8;
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), {});
  const StressGrid<Dim> stress(grid);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  const Vec<Dim> centre = Vec<Dim>::Constant(0.5) + Vec<Dim>::Constant(0.03);
  VectorX phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) phi[k] = (lattice.position(lattice.coord(k)) - centre).norm() - 0.3;
  const VectorX no_solid = solid_phi_on_lattice<Dim>(grid, lattice, {}, 0.0);
  const StokesWeights w = stokes_weights(grid, no_solid, phi, boundary, 1000.0, 50.0);
  Mat<Dim> W = Mat<Dim>::Zero();
  W(0, 1) = 2.0, W(1, 0) = -2.0;
  if constexpr (Dim == 3) W(0, 2) = 1.0, W(2, 0) = -1.0;
  const Vec<Dim> t = Vec<Dim>::LinSpaced(0.2, 0.5);
  VectorX u_star(grid.num_faces());
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [a, c] = grid.face_coord(f);
    u_star[f] = (t + W * (grid.face_center(a, c) - centre))[a];
  }
  for (StressForm form : {StressForm::full, StressForm::reduced}) {
    const StressLayout<Dim> layout(stress, form);
    const StokesDofs dofs = select_stokes_dofs(grid, layout, w, 0.01, StokesUnknowns::pressure_and_stress);
    const ExplicitStokesSystem sys = assemble_explicit_stokes(grid, layout, w, dofs, 0.01, u_star);
    REQUIRE(dofs.num_stress() > 0);
    CHECK(sys.b.cwiseAbs().maxCoeff() < 1e-12 * u_star.cwiseAbs().maxCoeff() / grid.dx());
    VectorX u = u_star;
    const auto r = solve_stokes(grid, w, 0.01, StokesUnknowns::pressure_and_stress, form, Backend::matrix_free,
                                PcgSettings{}, u);
    CHECK(r.pcg.converged);
    CHECK((u - u_star).cwiseAbs().maxCoeff() < 1e-12);
  }
}

TEMPLATE_TEST_CASE_SIG("apply_stokes_update: D^T M W_L^s tau by the stencil is Eigen's product with D bit for bit",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // the update used to assemble D over the whole grid in every step; the stencil version must
  // give the same bits (the paper's SSOR runs stay bitwise those of before), also across a
  // periodic axis (wrapped faces), with a periodic axis of 2 cells (where the two faces of an
  // off-diagonal row along it coincide and are merged), and with stresses that are zero
  for (int periodic_cells : {0, 7, 2}) {
    std::array<bool, Dim> periodic{};
    VecI<Dim> cells = VecI<Dim>::Constant(Dim == 2 ? 9 : 5);
    if (periodic_cells > 0) {
      periodic[0] = true;
      cells[0] = periodic_cells;
    }
    const MacGrid<Dim> grid(Vec<Dim>::Zero(), 0.1, cells, periodic);
    const StressGrid<Dim> stress(grid);
    VectorX tau = random_vector(stress.num_dofs(), 41);
    VectorX liquid = random_vector(stress.num_dofs(), 42).cwiseAbs();
    for (int d = 0; d < stress.num_dofs(); d += 3) tau[d] = 0.0;
    for (int d = 1; d < stress.num_dofs(); d += 5) liquid[d] = 0.0;
    const SparseMatrix D = deformation_rate_matrix(stress);
    const VectorX s = stress_multiplicity(stress).cwiseProduct(liquid).cwiseProduct(tau);
    const VectorX g = random_vector(grid.num_faces(), 43);
    VectorX expected = VectorX::Zero(grid.num_faces());
    expected += g;
    expected += D.transpose() * s;  // the former apply_stokes_update, verbatim
    VectorX got = VectorX::Zero(grid.num_faces());
    got += g;
    got += deformation_rate_transpose_product(stress, liquid, tau);
    CHECK((got.array() == expected.array()).all());
    CHECK(got.cwiseAbs().maxCoeff() > 0.0);
  }
}

TEMPLATE_TEST_CASE_SIG("a divergence source in the Stokes solve: eta = 0 gives solve_pressure's",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // StokesSolveOptions::divergence_source adds W_L^p d to b2 as solve_pressure's does
  CaseOptions o;
  o.n = Dim == 2 ? 12 : 6;
  o.eta = 0.0;
  const auto sc = make_case<Dim>(o);
  PcgSettings settings;
  settings.tolerance = 1e-12;
  VectorX d = VectorX::Zero(sc.grid.num_cells());
  for (int c = 0; c < sc.grid.num_cells(); ++c) d[c] = 3.0 * std::sin(1.0 + 0.7 * c);
  for (const Backend backend : {Backend::explicit_matrices, Backend::matrix_free}) {
    VectorX u_stokes = sc.u_star, u_pressure = sc.u_star, u_plain = sc.u_star;
    StokesSolveOptions options;
    options.divergence_source = &d;
    solve_stokes(sc.grid, sc.w, sc.dt, StokesUnknowns::pressure_and_stress, StressForm::reduced,
                 backend, settings, u_stokes, options);
    solve_pressure(sc.grid, sc.w.pressure, sc.dt, backend, settings, u_pressure,
                   PreconditionerKind::ssor, &d);
    solve_pressure(sc.grid, sc.w.pressure, sc.dt, backend, settings, u_plain);
    INFO(enum_name(backend));
    CHECK(rel_diff(u_stokes, u_pressure) < 1e-11);
    CHECK(rel_diff(u_plain, u_pressure) > 1e-3);  // the source changed the velocity
  }
}

TEMPLATE_TEST_CASE_SIG("a liquid in free fall: its unified solve takes no iteration on either back end",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // docs/preconditioners.md section 33: a ball of very viscous liquid away from every wall,
  // u* uniform up to two ulps per face (the particle transfer's round-off): b = B^T W_F^u u* is
  // zero in exact arithmetic and its round-off differs between the back ends. The relative
  // stopping rule solved that noise to 1e-6 of itself (8-9 block-PCG iterations and a set-up per
  // step on viscous-bunny-into-sphere-3d while the bunny falls). At or below
  // liquid_rhs_round_off it is zero: x = 0 without an iteration, u* kept bit for bit.
  const int n = Dim == 2 ? 24 : 12;
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), std::array<bool, Dim>{});
  const SampleLattice<Dim> lattice = half_lattice(grid);
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  const VectorX solid_phi = solid_phi_on_lattice<Dim>(grid, lattice, {}, 0.0);
  VectorX liquid_phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k)
    liquid_phi[k] = (lattice.position(lattice.coord(k)) - Vec<Dim>::Constant(0.5)).norm() - 0.3;
  const StokesWeights w = stokes_weights(grid, solid_phi, liquid_phi, boundary, 1000.0, 5000.0);
  const double dt = 0.01;
  // u*: (1.5, -0.7981[, 0.3]) m/s, each face moved by -2..2 ulps
  const Vec<Dim> common = Vec<3>(1.5, -0.7981, 0.3).head<Dim>();
  const VectorX flight = testing::uniform_face_velocity_with_ulps<Dim>(grid, common, 11);
  const double level = liquid_rhs_round_off(grid, w.pressure.fluid_face, flight, nullptr);
  const StressLayout<Dim> layout(StressGrid<Dim>(grid), StressForm::reduced);
  const StokesDofs dofs = select_stokes_dofs(grid, layout, w, dt, StokesUnknowns::pressure_and_stress);
  REQUIRE(dofs.num_stress() > 0);
  REQUIRE(dofs.num_pressure() > 0);
  const double be = assemble_explicit_stokes(grid, layout, w, dofs, dt, flight).b.cwiseAbs().maxCoeff();
  const double bm = MatrixFreeStokesOperator<Dim>(grid, layout, w, dofs, dt).rhs(flight).cwiseAbs().maxCoeff();
  std::printf("free fall %dD: ||b|| explicit %.2e, matrixfree %.2e, round-off level %.2e\n", Dim, be,
              bm, level);
  // the noise case: b is not exactly zero, and below the level on both back ends
  CHECK(std::max(be, bm) > 0.0);
  CHECK(be <= level);
  CHECK(bm <= level);
  PcgSettings settings;  // tolerance 1e-6, as in the scenes
  for (const PreconditionerKind kind : {PreconditionerKind::multigrid, PreconditionerKind::ssor}) {
    std::vector<VectorX> us;
    for (const Backend backend : {Backend::explicit_matrices, Backend::matrix_free}) {
      StokesSolveOptions options;
      options.preconditioner = kind;
      VectorX u = flight;
      const StokesSolveResult s = solve_stokes(grid, w, dt, StokesUnknowns::pressure_and_stress,
                                               StressForm::reduced, backend, settings, u, options);
      INFO(enum_name(kind) << " " << enum_name(backend));
      CHECK(s.pcg.converged);
      CHECK(s.pcg.iterations == 0);
      CHECK(s.pressure.cwiseAbs().maxCoeff() == 0.0);
      CHECK(s.stress.cwiseAbs().maxCoeff() == 0.0);
      us.push_back(u);
    }
    CHECK((us[0].array() == us[1].array()).all());
  }
  // a real right-hand side (a random u*) lies far above the level and is solved
  const VectorX real = random_vector(grid.num_faces(), 12);
  const double real_level = liquid_rhs_round_off(grid, w.pressure.fluid_face, real, nullptr);
  VectorX u = real;
  StokesSolveOptions options;
  options.preconditioner = PreconditionerKind::multigrid;
  const StokesSolveResult s = solve_stokes(grid, w, dt, StokesUnknowns::pressure_and_stress,
                                           StressForm::reduced, Backend::matrix_free, settings, u, options);
  CHECK(MatrixFreeStokesOperator<Dim>(grid, layout, w, dofs, dt).rhs(real).cwiseAbs().maxCoeff() >= 1e6 * real_level);
  CHECK(s.pcg.converged);
  CHECK(s.pcg.iterations > 0);
}

TEMPLATE_TEST_CASE_SIG("matrix-free Stokes operator: rhs and the velocity update on their face rows equal every row bit for bit",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // issue 20: rhs writes W_F^u u* only on the face rows grid_from_faces reads, and
  // updated_velocities_into computes B x only on the face rows with an updated face; the liquid
  // below a wavy surface leaves the upper rows without liquid, so both lists are shorter than the
  // grid's rows. The test switch gives the passes over every face row (the former code).
  auto same_bits = [](const VectorX& a, const VectorX& b) {
    return a.size() == b.size() &&
           std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<std::size_t>(a.size())) == 0;
  };
  for (double eta : {0.0, 2.0}) {
    CaseOptions o;
    o.n = Dim == 2 ? 16 : 8;
    o.eta = eta;
    const auto sc = make_case<Dim>(o);
    int faces_without_liquid = 0;
    for (int f = 0; f < sc.grid.num_faces(); ++f) faces_without_liquid += sc.w.pressure.liquid_face[f] == 0.0;
    // (a fifth: the dry faces the surface stress reads are clamped since surf24, 414 of 1728 left
    // in 3D)
    REQUIRE(faces_without_liquid > sc.grid.num_faces() / 5);
    for (StressForm form : {StressForm::full, StressForm::reduced}) {
      const StressLayout<Dim> layout(StressGrid<Dim>(sc.grid), form);
      const StokesDofs dofs = select_stokes_dofs(sc.grid, layout, sc.w, sc.dt,
                                                 StokesUnknowns::pressure_and_stress);
      REQUIRE(dofs.num_pressure() > 0);
      CHECK((dofs.num_stress() > 0) == (eta > 0.0));
      const MatrixFreeStokesOperator<Dim> op(sc.grid, layout, sc.w, dofs, sc.dt);
      const VectorX x = random_vector(op.size(), 300);
      stokes_operator_every_face_row() = true;
      const VectorX b_every = op.rhs(sc.u_star);
      VectorX u_every;
      op.updated_velocities_into(x, sc.u_star, sc.dt, u_every);
      stokes_operator_every_face_row() = false;
      const VectorX b_rows = op.rhs(sc.u_star);
      VectorX u_rows = VectorX::Constant(sc.grid.num_faces(), 7.0);  // stale values
      op.updated_velocities_into(x, sc.u_star, sc.dt, u_rows);
      CHECK(same_bits(b_every, b_rows));
      CHECK(same_bits(u_every, u_rows));
      // the update changed faces, and rhs leaves the scratch as it found it: a second call
      // gives the same bits
      CHECK(!same_bits(u_rows, sc.u_star));
      CHECK(same_bits(op.rhs(sc.u_star), b_rows));
      // and apply still agrees with the explicit system after the calls
      const ExplicitStokesSystem sys =
          assemble_explicit_stokes(sc.grid, layout, sc.w, dofs, sc.dt, sc.u_star);
      VectorX y;
      op.apply(x, y);
      CHECK(rel_diff(y, sys.A * x) < 1e-12);
      CHECK(rel_diff(b_rows, sys.b) < 1e-13);
    }
  }
}

TEMPLATE_TEST_CASE_SIG("matrix-free Stokes operator: the passes on the rows' spans give the bits of whole rows (box26)",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // Two liquid balls in a box four times as long along x as across, a solid ball in the first:
  // each row's span of C_f != 0 faces and of unknowns is shorter than the row, and the rows
  // through both balls hold a gap without liquid inside their span. An operator made under the
  // test switch visits whole rows (the former passes); every pass must give the same bits, and
  // so must the face force the sweeps keep between calls.
  auto same_bits = [](const VectorX& a, const VectorX& b) {
    return a.size() == b.size() &&
           std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<std::size_t>(a.size())) == 0;
  };
  const int n = Dim == 2 ? 12 : 8;
  VecI<Dim> cells = VecI<Dim>::Constant(n);
  cells[0] = 4 * n;
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, cells, std::array<bool, Dim>{});
  const SampleLattice<Dim> lattice = half_lattice(grid);
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  boundary[3] = BoundaryType::open;
  Vec<Dim> c1 = Vec<Dim>::Constant(0.45), c2 = Vec<Dim>::Constant(0.5);
  c1[0] = 0.9;
  c2[0] = 2.6;
  std::vector<ShapePtr<Dim>> solids{std::make_shared<TestBall<Dim>>(c1, 0.12)};
  const VectorX solid_phi = solid_phi_on_lattice<Dim>(grid, lattice, solids, 0.0);
  VectorX liquid_phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) {
    const Vec<Dim> x = lattice.position(lattice.coord(k));
    liquid_phi[k] = std::min((x - c1).norm() - 0.33, (x - c2).norm() - 0.3);
  }
  const double dt = 0.01;
  const VectorX u_star = random_vector(grid.num_faces(), 41);
  for (double eta : {0.0, 2.0}) {
    StokesWeights w = stokes_weights(grid, solid_phi, liquid_phi, boundary, 1000.0, eta);
    w.pressure.face_density += 200.0 * random_vector(grid.num_faces(), 42);
    // a face row along x with liquid in both balls and none at its ends
    bool gap_row = false;
    const int n0 = grid.face_dims(0)[0], rows0 = grid.face_dims(0).prod() / n0;
    for (int r = 0; r < rows0 && !gap_row; ++r) {
      auto wet = [&](int x) { return w.pressure.liquid_face[grid.face_offset(0) + r * n0 + x] > 0.0; };
      bool first = false, middle = false, second = false;
      for (int x = 0; x < n0 / 2 - 2; ++x) first = first || wet(x);
      for (int x = n0 / 2 - 2; x < n0 / 2 + 2; ++x) middle = middle || wet(x);
      for (int x = n0 / 2 + 2; x < n0; ++x) second = second || wet(x);
      gap_row = first && !middle && second && !wet(0) && !wet(n0 - 1);
    }
    REQUIRE(gap_row);
    for (StressForm form : {StressForm::full, StressForm::reduced}) {
      const StressLayout<Dim> layout(StressGrid<Dim>(grid), form);
      const StokesDofs dofs =
          select_stokes_dofs(grid, layout, w, dt, StokesUnknowns::pressure_and_stress);
      REQUIRE(dofs.num_pressure() > 0);
      CHECK((dofs.num_stress() > 0) == (eta > 0.0));
      stokes_operator_every_face_row() = true;
      const MatrixFreeStokesOperator<Dim> whole(grid, layout, w, dofs, dt);
      stokes_operator_every_face_row() = false;
      const MatrixFreeStokesOperator<Dim> spans(grid, layout, w, dofs, dt);
      const VectorX x = random_vector(whole.size(), 43);
      VectorX y_whole, y_spans;
      whole.apply(x, y_whole);
      spans.apply(x, y_spans);
      CHECK(same_bits(y_whole, y_spans));
      const VectorX b_whole = whole.rhs(u_star), b_spans = spans.rhs(u_star);
      CHECK(same_bits(b_whole, b_spans));
      VectorX u_whole = VectorX::Constant(grid.num_faces(), 7.0), u_spans = u_whole;
      whole.updated_velocities_into(x, u_star, dt, u_whole);
      spans.updated_velocities_into(x, u_star, dt, u_spans);
      CHECK(same_bits(u_whole, u_spans));
      CHECK(!same_bits(u_spans, u_star));
      // sweeps from zero and from x, single and consecutive (the kept face force), then apply
      // after them (the face scratch as the sweeps left it)
      VectorX s_whole = VectorX::Zero(whole.size()), s_spans = s_whole;
      whole.forward_sweep(b_whole, s_whole, 1.2, nullptr);
      spans.forward_sweep(b_spans, s_spans, 1.2, nullptr);
      CHECK(same_bits(s_whole, s_spans));
      whole.backward_sweep(b_whole, s_whole, 1.2, nullptr);
      spans.backward_sweep(b_spans, s_spans, 1.2, nullptr);
      CHECK(same_bits(s_whole, s_spans));
      whole.forward_sweeps(b_whole, s_whole, 1.0, 3);
      spans.forward_sweeps(b_spans, s_spans, 1.0, 3);
      CHECK(same_bits(s_whole, s_spans));
      whole.backward_sweeps(b_whole, s_whole, 1.0, 3);
      spans.backward_sweeps(b_spans, s_spans, 1.0, 3);
      CHECK(same_bits(s_whole, s_spans));
      CHECK(!same_bits(s_spans, VectorX::Zero(spans.size())));
      whole.apply(s_whole, y_whole);
      spans.apply(s_spans, y_spans);
      CHECK(same_bits(y_whole, y_spans));
      // and the explicit system agrees with both
      const ExplicitStokesSystem sys = assemble_explicit_stokes(grid, layout, w, dofs, dt, u_star);
      CHECK(rel_diff(y_spans, sys.A * s_spans) < 1e-12);
    }
  }
}

TEMPLATE_TEST_CASE_SIG("no traction at the free surface: the stress's net force on the dry faces a "
                       "surface stress DOF reads is ~0 (eq. (8) with W_L^u clamped there)",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // Eq. (8) weighs face f's kinetic energy by W_L^u; its optimum gives u_f = u*_f - dt / (rho
  // W_L^u) F_f with F = G W_L^p p + D^T M W_L^s tau. On a dry face above the surface that a
  // surface stress DOF reads (no liquid cell beside it, so G W_L^p p = 0 there) W_L^u -> 0 makes
  // F_f -> 0: the liquid's surface feels no traction. clamp_stressed_face_weights keeps W_L^u =
  // kMinLiquidFaceFraction there, a penalty that leaves F_f of the order of the clamp; with W_L^u
  // = 0 (main a10d2ef) the face is a prescribed velocity (u* kept), and F_f is whatever the
  // surface DOFs' stress makes it. Measured (largest |F| on the dry faces over the largest on
  // faces with W_L^u >= 0.5): clamped 3.7e-4 (2D) and 5.2e-4 (3D), unclamped 0.017 and 0.040
  // (both back ends alike). Wavy surface at a height that is no whole number of cells, a smooth
  // u* on every face.
  const int n = Dim == 2 ? 16 : 8;
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), {});
  const StressGrid<Dim> stress(grid);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  boundary[3] = BoundaryType::open;
  VectorX phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) {
    const Vec<Dim> x = lattice.position(lattice.coord(k));
    phi[k] = x[1] - 0.57 - 0.06 * std::sin(2.0 * M_PI * x[0]);
  }
  const VectorX no_solid = solid_phi_on_lattice<Dim>(grid, lattice, {}, 0.0);
  const StokesWeights w = stokes_weights(grid, no_solid, phi, boundary, 1000.0, 50.0);
  // the dry faces of the stencils: raw fraction 0, no liquid cell beside, not a wall's (W_F^u > 0),
  // read by a stress DOF with W_F^s W_L^s > 0
  const VectorX raw = face_negative_fractions(grid, lattice, phi);
  std::vector<char> dry(grid.num_faces(), 0);
  for (int d = 0; d < stress.num_dofs(); ++d) {
    if (!(w.fluid_stress[d] * w.liquid_stress[d] > 0.0)) continue;
    for_each_deformation_rate_entry(stress, d, [&](int f, double) {
      const auto [a, c] = grid.face_coord(f);
      VecI<Dim> minus = c;
      minus[a] -= 1;
      const bool beside = (c[a] < n && w.pressure.liquid_cell[grid.cell_index(c)] > 0.0) ||
                          (minus[a] >= 0 && w.pressure.liquid_cell[grid.cell_index(minus)] > 0.0);
      if (raw[f] == 0.0 && !beside && w.pressure.fluid_face[f] > 0.0) dry[f] = 1;
    });
  }
  int count = 0;
  for (int f = 0; f < grid.num_faces(); ++f) {
    if (!dry[f]) continue;
    ++count;
    CHECK(w.pressure.liquid_face[f] == kMinLiquidFaceFraction);
  }
  REQUIRE(count > 0);
  // a smooth u* on every face (air faces too, as the extrapolation fills them): a shear along
  // the surface and a swirl
  VectorX u_star(grid.num_faces());
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [a, c] = grid.face_coord(f);
    const Vec<Dim> x = grid.face_center(a, c);
    u_star[f] = a == 0 ? 0.4 * x[1] + 0.2 * std::sin(2.0 * x[0] + 3.0 * x[1])
                       : 0.3 * std::cos(2.5 * x[0] - x[1]);
  }
  PcgSettings settings;
  settings.tolerance = 1e-12;
  const double dt = 0.01;
  const VectorX m = stress_multiplicity(stress);
  // the same weights without the stress's clamp (main a10d2ef's): the contrast
  StokesWeights unclamped = w;
  unclamped.pressure.liquid_face =
      liquid_face_weights(grid, lattice, phi, w.pressure.liquid_cell);
  for (const bool clamped : {true, false})
  for (const Backend backend : {Backend::explicit_matrices, Backend::matrix_free}) {
    const StokesWeights& weights = clamped ? w : unclamped;
    VectorX u = u_star;
    const auto r = solve_stokes(grid, weights, dt, StokesUnknowns::pressure_and_stress,
                                StressForm::reduced, backend, settings, u);
    REQUIRE(r.pcg.converged);
    // F on every face and the sum of the magnitudes of its terms
    const VectorX force = deformation_rate_transpose_product(stress, w.liquid_stress, r.stress);
    VectorX terms = VectorX::Zero(grid.num_faces());
    for (int d = 0; d < stress.num_dofs(); ++d)
      for_each_deformation_rate_entry(stress, d, [&](int f, double v) {
        terms[f] += std::abs(v * m[d] * w.liquid_stress[d] * r.stress[d]);
      });
    // the dry faces' largest |F| against the largest force on the liquid's faces
    double dry_force = 0.0, liquid_force = 0.0;
    for (int f = 0; f < grid.num_faces(); ++f) {
      if (dry[f]) dry_force = std::max(dry_force, std::abs(force[f]));
      if (w.pressure.liquid_face[f] >= 0.5) liquid_force = std::max(liquid_force, std::abs(force[f]));
    }
    double largest_term = 0.0;
    for (int f = 0; f < grid.num_faces(); ++f)
      if (dry[f]) largest_term = std::max(largest_term, terms[f]);
    const double worst = dry_force / liquid_force;
    WARN(Dim << "D, " << enum_name(backend) << (clamped ? ", clamped" : ", unclamped") << ": "
             << count << " dry faces; their largest |F| " << dry_force << " (largest term "
             << largest_term << "), the liquid faces' " << liquid_force);
    CHECK(largest_term > 0.0);
    if (clamped)
      CHECK(worst < 2e-3);
    else
      CHECK(worst > 1e-2);  // the check can fail: without the clamp the surface is dragged
  }
}
