// The multigrid block preconditioner of eq. (8) (reference/fluid/stokes_preconditioner.hpp) and
// its parts: the Woodbury identity it is built on, the multigrid hierarchies, symmetry and
// positive definiteness, agreement with CHOLMOD and between the back ends, thread independence.
#include <catch2/catch.hpp>
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <omp.h>

#include "reference/oracle/cholmod_solver.hpp"
#include "reference/fluid/mac_hierarchy.hpp"
#include "reference/fluid/stokes_preconditioner.hpp"
#include "reference/fluid/velocity_operator.hpp"
#include "reference/solvers/pcg.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/fluid/stokes_warm_start.hpp"
#include "tests/support/sparse_helpers.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using monolith::testing::random_vector;
using monolith::testing::TestBall;

namespace {

/// A Stokes problem of eq. (8) in the unit box: walls, an open top, liquid below a wavy surface
/// (free surface) or filling a ball in the air, optionally around a solid ball (cut cells), rho
/// 1000 (varying by +-20 % when asked), dt 0.01, viscosity eta varying smoothly by +-50 %.
template <int Dim>
struct Case {
  MacGrid<Dim> grid;
  StokesWeights w;
  VectorX u_star;
  double dt = 0.01;
};

struct CaseOptions {
  int n = 8;
  bool blob = false;    ///< a liquid ball in the air instead of a pool
  bool solid = true;    ///< a solid ball in the pool
  double eta = 10.0;
  bool vary = true;     ///< density and viscosity vary in space
  double level = 0.62;  ///< the pool's surface height
  double wave = 0.08;   ///< the amplitude of its sine wave
};

template <int Dim>
Case<Dim> make_case(const CaseOptions& o) {
  Case<Dim> sc;
  sc.grid = MacGrid<Dim>(Vec<Dim>::Zero(), 1.0 / o.n, VecI<Dim>::Constant(o.n), {});
  const MacGrid<Dim>& grid = sc.grid;
  const StressGrid<Dim> stress(grid);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  boundary[3] = BoundaryType::open;
  std::vector<ShapePtr<Dim>> solids;
  if (o.solid && !o.blob) solids.push_back(std::make_shared<TestBall<Dim>>(Vec<Dim>::Constant(0.37), 0.16));
  const VectorX solid_phi = solid_phi_on_lattice<Dim>(grid, lattice, solids, 0.0);
  VectorX liquid_phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) {
    const Vec<Dim> x = lattice.position(lattice.coord(k));
    liquid_phi[k] = o.blob ? (x - Vec<Dim>::Constant(0.5)).norm() - 0.3
                           : x[1] - o.level - o.wave * std::sin(2.0 * M_PI * x[0]);
  }
  sc.w = uniform_stokes_weights(grid, solid_phi, liquid_phi, boundary, 1000.0, o.eta);
  if (o.vary) {
    sc.w.pressure.face_density += 200.0 * random_vector(grid.num_faces(), 7);
    for (int d = 0; d < stress.num_dofs(); ++d) {
      const auto [k, c] = stress.coord(d);
      const Vec<Dim> x = stress.position(k, c);
      sc.w.viscosity[d] = o.eta * (1.0 + 0.5 * std::sin(3.0 * x[0] + 2.0 * x[1]));
    }
  }
  sc.u_star = random_vector(grid.num_faces(), 1);
  return sc;
}

/// The system of a case in both back ends.
template <int Dim>
struct System {
  StressLayout<Dim> layout;
  StokesDofs dofs;
  ExplicitStokesSystem sys;
  std::unique_ptr<MatrixFreeStokesOperator<Dim>> mf;
  std::unique_ptr<SparseMatrixOperator> ex;
};

template <int Dim>
System<Dim> make_system(const Case<Dim>& sc) {
  System<Dim> s{StressLayout<Dim>(StressGrid<Dim>(sc.grid), StressForm::reduced), {}, {}, nullptr, nullptr};
  s.dofs = select_stokes_dofs(sc.grid, s.layout, sc.w, sc.dt, StokesUnknowns::pressure_and_stress);
  s.sys = assemble_explicit_stokes(sc.grid, s.layout, sc.w, s.dofs, sc.dt, sc.u_star);
  s.mf = std::make_unique<MatrixFreeStokesOperator<Dim>>(sc.grid, s.layout, sc.w, s.dofs, sc.dt);
  s.ex = std::make_unique<SparseMatrixOperator>(s.sys.A, s.dofs.null_space);
  return s;
}

/// The preconditioner as a dense matrix, column by column.
Eigen::MatrixXd dense(const Preconditioner& m) {
  const int n = m.size();
  Eigen::MatrixXd out(n, n);
  VectorX e = VectorX::Zero(n), z;
  for (int j = 0; j < n; ++j) {
    e[j] = 1.0;
    m.apply(e, z);
    out.col(j) = z;
    e[j] = 0.0;
  }
  return out;
}

/// P symmetric to 1e-9 of its largest entry and positive definite: the eigenvalues of
/// D^1/2 sym(P) D^1/2 (D the operator's diagonal, so that their scale is 1) all positive.
void check_symmetric_positive_definite(const Preconditioner& m, const VectorX& diagonal) {
  const Eigen::MatrixXd p = dense(m);
  CHECK((p - p.transpose()).cwiseAbs().maxCoeff() < 1e-9 * p.cwiseAbs().maxCoeff());
  const VectorX scale = diagonal.cwiseSqrt();
  const Eigen::MatrixXd scaled = scale.asDiagonal() * (0.5 * (p + p.transpose())) * scale.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(scaled, Eigen::EigenvaluesOnly);
  CHECK(es.eigenvalues().minCoeff() > 0.0);
}

double rel_diff(const VectorX& a, const VectorX& b) {
  const double scale = std::max(a.cwiseAbs().maxCoeff(), b.cwiseAbs().maxCoeff());
  return scale > 0.0 ? (a - b).cwiseAbs().maxCoeff() / scale : 0.0;
}

/// Small multigrid hierarchies even on small grids (the default coarsest size would make the
/// small test cases a single, directly solved level).
StokesPreconditionerOptions small_options() {
  StokesPreconditionerOptions o;
  o.max_coarse = 40;
  return o;
}

/// small_options without the lean-share rule (P9) (for the tests of the other cycle rules).
StokesPreconditionerOptions no_lean_options() {
  StokesPreconditionerOptions o = small_options();
  o.lean_share = 0.0;
  return o;
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("the factors B, C, K reproduce A on both back ends", "[unit]", ((int Dim), Dim), 2, 3) {
  for (bool solid : {false, true}) {
    CaseOptions o;
    o.n = Dim == 2 ? 12 : 6;
    o.solid = solid;
    const auto sc = make_case<Dim>(o);
    const auto s = make_system(sc);
    const StokesFactors fe = stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, s.sys);
    const StokesFactors fm = stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf);
    REQUIRE(fe.face == fm.face);
    CHECK(rel_diff(fe.c, fm.c) < 1e-14);
    CHECK((Eigen::MatrixXd(fe.b) - Eigen::MatrixXd(fm.b)).cwiseAbs().maxCoeff() <
          1e-12 * Eigen::MatrixXd(fe.b).cwiseAbs().maxCoeff());
    // A = B^T C B + blkdiag(K, 0)
    Eigen::MatrixXd a = Eigen::MatrixXd(fe.b_transpose) * fe.c.asDiagonal() * Eigen::MatrixXd(fe.b);
    a.topLeftCorner(fe.num_stress, fe.num_stress) += Eigen::MatrixXd(fe.compliance);
    const Eigen::MatrixXd ref(s.sys.A);
    CHECK((a - ref).cwiseAbs().maxCoeff() < 1e-12 * ref.cwiseAbs().maxCoeff());
    // the matrix-free diagonal agrees (K is read from the weights, not from the operator)
    CHECK(rel_diff(VectorX(a.diagonal()), s.mf->diagonal()) < 1e-12);
  }
}

TEMPLATE_TEST_CASE_SIG("the penalised inverse is the Woodbury identity: exact with an exact V solve",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // with one multigrid level the V-cycle is the exact (LDL^T) solve with V, so
  // apply_penalised_inverse must be (A + blkdiag(0, Pi))^-1 to round-off
  CaseOptions o;
  o.n = Dim == 2 ? 10 : 5;
  o.eta = 50.0;
  const auto sc = make_case<Dim>(o);
  const auto s = make_system(sc);
  StokesPreconditionerOptions po;
  po.max_coarse = 1 << 30;
  po.min_fluid_fraction = 0.0;  // the preconditioner's K equals the system's
  const StokesPreconditioner<Dim> m(sc.grid, *s.ex, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, s.sys), po);
  REQUIRE(m.velocity_multigrid().num_levels() == 1);
  Eigen::MatrixXd ap(s.sys.A);
  const int ns = s.dofs.num_stress();
  for (int k = 0; k < s.dofs.num_pressure(); ++k) ap(ns + k, ns + k) += m.penalty()[k];
  const VectorX g = random_vector(m.size(), 5);
  VectorX y;
  m.apply_penalised_inverse(g, y);
  const VectorX ref = ap.ldlt().solve(g);
  CHECK(rel_diff(y, ref) < 1e-9);
}

TEMPLATE_TEST_CASE_SIG("multigrid hierarchies: colours are independent, the V-cycle is SPD and below A^-1",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  CaseOptions o;
  o.n = Dim == 2 ? 16 : 8;
  o.eta = 100.0;
  const auto sc = make_case<Dim>(o);
  const auto s = make_system(sc);
  const StokesPreconditioner<Dim> m(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf),
                                    small_options());
  for (const Multigrid* mg : {&m.velocity_multigrid(), &m.pressure_multigrid()}) {
    REQUIRE(mg->num_levels() >= 3);
    for (int l = 0; l + 1 < mg->num_levels(); ++l) {
      CHECK(patches_independent(mg->level(l).a, mg->level(l).patches));
      // every unknown is smoothed
      std::vector<char> covered(mg->level(l).a.rows(), 0);
      for (int i : mg->level(l).patches.index) covered[i] = 1;
      CHECK(std::count(covered.begin(), covered.end(), 0) == 0);
    }
    // Q (one V-cycle) is symmetric, and the eigenvalues of Q A lie in (0, 1]: E = I - Q A is
    // A-self-adjoint and positive semi-definite (symmetric smoothing, Galerkin coarse levels)
    const SparseMatrix a = mg->finest_operator();
    const int n = static_cast<int>(a.rows());
    Eigen::MatrixXd q(n, n);
    VectorX e = VectorX::Zero(n), x;
    for (int j = 0; j < n; ++j) {
      e[j] = 1.0;
      mg->apply(e, x, 1);
      q.col(j) = x;
      e[j] = 0.0;
    }
    CHECK((q - q.transpose()).cwiseAbs().maxCoeff() < 1e-10 * q.cwiseAbs().maxCoeff());
    const Eigen::MatrixXd ad(a);
    Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> ges(ad, Eigen::MatrixXd(q.inverse()));
    // eigenvalues of (Q^-1)^-1 A = Q A
    CHECK(ges.eigenvalues().minCoeff() > 0.0);
    CHECK(ges.eigenvalues().maxCoeff() <= 1.0 + 1e-9);
  }
}

TEMPLATE_TEST_CASE_SIG("multigrid renumbering for locality: the same V-cycles bit for bit, on 1 and 2 threads",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // Multigrid renumbers every smoothed level in its sweep order (rows keep their entries in
  // their stored order), which must change nothing but the memory layout: the velocity and the
  // cell hierarchies with and without it give the same bits, 1 and 2 V-cycles, 1 and 2 threads
  CaseOptions o;
  o.n = Dim == 2 ? 24 : 10;
  o.eta = 1000.0;
  const auto sc = make_case<Dim>(o);
  const auto s = make_system(sc);
  const StokesFactors f = stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf, 0.01);
  const VectorX penalty = VectorX::Constant(f.num_pressure, 1e-3);
  const SparseMatrix v = velocity_operator(f, penalty);
  const ExtraPatches<Dim> extra = stress_element_patches<Dim>(f);
  MacMultigridOptions mo;
  mo.max_coarse = 40;
  const SparseMatrix a22 = SparseMatrix(SparseMatrix(f.b_transpose.bottomRows(f.num_pressure) *
                                                     sparse_diagonal(f.c)) * f.b.rightCols(f.num_pressure));
  for (bool cells : {false, true}) {
    std::array<Multigrid, 2> mg;
    for (int r = 0; r < 2; ++r) {
      mo.renumber = r == 1;
      mg[r] = cells ? cell_multigrid<Dim>(sc.grid, f.pressure_cell, a22, mo)
                    : face_multigrid<Dim>(sc.grid, f.face, v, mo, &extra);
    }
    REQUIRE(mg[1].num_levels() >= 3);
    // the numbering did change, and the finest operator in the caller's numbering is the given one
    const std::vector<int>& order = mg[1].order(0);
    REQUIRE(static_cast<int>(order.size()) == mg[1].size());
    bool identity = true;
    for (int i = 0; i < mg[1].size(); ++i) identity = identity && order[i] == i;
    CHECK(!identity);
    const SparseMatrix& given = cells ? a22 : v;
    CHECK(Eigen::MatrixXd(mg[1].finest_operator()) == Eigen::MatrixXd(given));
    CHECK(patches_independent(mg[1].level(0).a, mg[1].level(0).patches));
    const VectorX b = random_vector(mg[0].size(), 9);
    for (int cycles : {1, 2}) {
      VectorX x0, x1, x2;
      mg[0].apply(b, x0, cycles);
      const int threads = omp_get_max_threads();
      omp_set_num_threads(1);
      mg[1].apply(b, x1, cycles);
      omp_set_num_threads(2);
      mg[1].apply(b, x2, cycles);
      omp_set_num_threads(threads);
      INFO("cells " << cells << ", cycles " << cycles);
      CHECK((x0.array() == x1.array()).all());
      CHECK((x1.array() == x2.array()).all());
      CHECK(x0.cwiseAbs().maxCoeff() > 0.0);
    }
  }
}

TEMPLATE_TEST_CASE_SIG("the block preconditioner is symmetric positive definite", "[unit]", ((int Dim), Dim), 2, 3) {
  for (bool blob : {false, true})
    for (double eta : {0.01, 10.0, 5000.0}) {
      CaseOptions o;
      o.n = Dim == 2 ? 10 : 5;
      o.blob = blob;
      o.eta = eta;
      const auto sc = make_case<Dim>(o);
      const auto s = make_system(sc);
      // additive, then the two-term form with each approximation of Sigma^-1
      for (int form : {-1, 0, 1, 2}) {
        const bool two_term = form >= 0;
        StokesPreconditionerOptions po = small_options();
        po.schur_correction = two_term;
        po.additive_pressure = !two_term;
        if (two_term) po.schur = static_cast<SchurApproximation>(form);
        const StokesPreconditioner<Dim> m(sc.grid, *s.mf,
                                          stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf), po);
        const Eigen::MatrixXd p = dense(m);
        INFO("blob " << blob << " eta " << eta << " form " << form);
        CHECK((p - p.transpose()).cwiseAbs().maxCoeff() < 1e-9 * p.cwiseAbs().maxCoeff());
        // PCG applies the preconditioner between projections onto the complement of A's null
        // space (constant pressure of enclosed liquid, the blob): it must be SPD there
        Eigen::MatrixXd q = Eigen::MatrixXd::Identity(m.size(), m.size());
        for (const VectorX& v : s.dofs.null_space) q -= v * v.transpose();
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> basis(q);
        const int k = static_cast<int>(s.dofs.null_space.size());
        const Eigen::MatrixXd z = basis.eigenvectors().rightCols(m.size() - k);  // eigenvalue 1
        // congruence with diag(A)^1/2 (definiteness unchanged): an unknown with a tiny diagonal
        // (a liquid sliver; 1e-48 in the 3D blob) has a huge preconditioner entry, and the
        // eigenvalues of the scaled matrix are O(1) rather than spread over 90 decades
        const VectorX scale = s.mf->diagonal().cwiseSqrt();
        const Eigen::MatrixXd scaled = scale.asDiagonal() * (0.5 * (p + p.transpose())) * scale.asDiagonal();
        const Eigen::MatrixXd sym = z.transpose() * scaled * z;
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(sym, Eigen::EigenvaluesOnly);
        INFO("null space " << k << ", eigenvalues " << es.eigenvalues().minCoeff() << " .. "
                           << es.eigenvalues().maxCoeff());
        CHECK(es.eigenvalues().minCoeff() > 0.0);
      }
    }
}

TEMPLATE_TEST_CASE_SIG("the scaled commutator: V0 and its diagonal, a symmetric positive S, the cycle rule",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // docs/preconditioners.md section 19: V0 = C^-1 + B_tau K^-1 B_tau^T, r_f = C_f (V0)_ff - 1,
  // S = L^-1 B_p^T W V0 W B_p L^-1 + Pi^-1 (W = diag(V0)^-1), cycles = 2 + floor(log4(median r /
  // cycle_ratio)) capped
  for (double eta : {0.01, 10.0, 5000.0}) {
    CaseOptions o;
    o.n = Dim == 2 ? 16 : 8;
    o.eta = eta;
    const auto sc = make_case<Dim>(o);
    const auto s = make_system(sc);
    const StokesPreconditioner<Dim> m(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf),
                                      small_options());
    const StokesFactors& f = m.factors();
    const int ns = f.num_stress, np = f.num_pressure, nf = static_cast<int>(f.face.size());
    REQUIRE(ns > 0);
    REQUIRE(np > 0);
    // V0 densely from the factors
    const Eigen::MatrixXd b(f.b);
    const Eigen::MatrixXd kinv = Eigen::MatrixXd(f.compliance).inverse();
    Eigen::MatrixXd v0 = b.leftCols(ns) * kinv * b.leftCols(ns).transpose();
    for (int i = 0; i < nf; ++i) v0(i, i) += 1.0 / f.c[i];
    const VectorX x = random_vector(nf, 3);
    VectorX y(nf);
    m.apply_unpenalised_velocity(x, y);
    INFO("eta " << eta);
    CHECK(rel_diff(y, v0 * x) < 1e-12);
    // the median viscous-to-mass ratio and the cycle count it sets
    std::vector<double> r(nf);
    for (int i = 0; i < nf; ++i) r[i] = f.c[i] * v0(i, i) - 1.0;
    std::sort(r.begin(), r.end());
    const double median = r[(nf - 1) / 2];
    CHECK(std::abs(m.viscous_ratio() - median) <= 1e-10 * median);
    const StokesPreconditionerOptions def;
    int expected = median > def.cycle_ratio
                       ? std::min(def.max_velocity_cycles,
                                  def.velocity_cycles + static_cast<int>(std::floor(std::log(median / def.cycle_ratio) / std::log(4.0))))
                       : def.velocity_cycles;
    // (P9): the share of pressure unknowns with W_L^p < 1; in 3D one cycle fewer below lean_share
    int surface = 0;
    for (int k = 0; k < np; ++k) surface += f.pressure_liquid[k] < 1.0 ? 1 : 0;
    CHECK(m.free_surface_share() == static_cast<double>(surface) / np);
    CHECK(m.free_surface_share() > 0.0);
    if (Dim == 3 && m.free_surface_share() < def.lean_share) expected = std::max(1, expected - 1);
    CHECK(m.velocity_cycles() == expected);
    if (eta <= 10.0 && m.free_surface_share() >= def.lean_share) CHECK(m.velocity_cycles() == def.velocity_cycles);
    // a threshold 20x below the median: floor(log4 20) = 2 more cycles, or the cap
    StokesPreconditionerOptions po = no_lean_options();
    po.cycle_ratio = median / 20.0;
    const StokesPreconditioner<Dim> m4(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf), po);
    CHECK(m4.velocity_cycles() == po.velocity_cycles + 2);
    po.max_velocity_cycles = po.velocity_cycles + 1;
    const StokesPreconditioner<Dim> m3(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf), po);
    CHECK(m3.velocity_cycles() == po.velocity_cycles + 1);
    // the one-cycle rule of section 24 (1 cycle, ratio 67.5: 1 + floor(log4(r / 67.5)) =
    // 2 + floor(log4(r / 270))) gives section 19's counts (2 cycles, ratio 270) wherever the
    // median ratio is at least 270, and one cycle below it
    StokesPreconditionerOptions one_cycle = no_lean_options();
    one_cycle.velocity_cycles = 1;
    one_cycle.cycle_ratio = 67.5;
    const StokesPreconditioner<Dim> m1(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf), one_cycle);
    StokesPreconditionerOptions section19 = no_lean_options();
    section19.velocity_cycles = 2;
    section19.cycle_ratio = 270.0;
    const StokesPreconditioner<Dim> m2(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf), section19);
    INFO("median ratio " << median);
    if (median >= 270.0) CHECK(m1.velocity_cycles() == m2.velocity_cycles());
    else CHECK(m1.velocity_cycles() == 1);
    // S as a dense matrix: symmetric, and positive definite (Pi^-1 > 0 plus a semi-definite term)
    Eigen::MatrixXd sd(np, np);
    VectorX e = VectorX::Zero(np), col;
    for (int j = 0; j < np; ++j) {
      e[j] = 1.0;
      m.apply_schur(e, col);
      sd.col(j) = col;
      e[j] = 0.0;
    }
    CHECK((sd - sd.transpose()).cwiseAbs().maxCoeff() < 1e-10 * sd.cwiseAbs().maxCoeff());
    const VectorX pinv = m.penalty().cwiseInverse();
    const Eigen::MatrixXd rest = 0.5 * (sd + sd.transpose()) - Eigen::MatrixXd(pinv.asDiagonal());
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(rest, Eigen::EigenvaluesOnly);
    CHECK(es.eigenvalues().minCoeff() > -1e-10 * es.eigenvalues().cwiseAbs().maxCoeff());
    CHECK(es.eigenvalues().maxCoeff() > 0.0);
  }
}

TEST_CASE("the lean-share rule (P9): one V-cycle fewer in 3D where the liquid fills its box", "[unit]") {
  // a deep pool (liquid below the flat y = 0.92 around the solid ball) at 16^3 has few cells with
  // W_L^p < 1; a liquid ball in the air has many. The rule takes one cycle off the pool only,
  // never below one, and does nothing with lean_share 0 or in 2D
  for (double eta : {100.0, 5000.0}) {
    for (bool blob : {false, true}) {
      CaseOptions o;
      o.n = 16;
      o.eta = eta;
      o.blob = blob;
      o.level = 0.92;
      o.wave = 0.0;
      const auto sc = make_case<3>(o);
      const auto s = make_system(sc);
      StokesPreconditionerOptions lean = small_options(), off = no_lean_options();
      lean.lean_share = 0.15;
      const StokesPreconditioner<3> ml(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf), lean);
      const StokesPreconditioner<3> mo(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf), off);
      INFO("eta " << eta << (blob ? ", ball in the air" : ", deep pool") << ", share " << ml.free_surface_share());
      CHECK(ml.free_surface_share() == mo.free_surface_share());
      if (blob) {
        CHECK(ml.free_surface_share() > 0.15);
        CHECK(ml.velocity_cycles() == mo.velocity_cycles());
      } else {
        CHECK(ml.free_surface_share() < 0.15);
        CHECK(mo.velocity_cycles() >= 2);
        CHECK(ml.velocity_cycles() == mo.velocity_cycles() - 1);
      }
      // never below one cycle
      StokesPreconditionerOptions one = lean;
      one.velocity_cycles = 1;
      one.cycle_ratio = 0.0;
      const StokesPreconditioner<3> m1(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf), one);
      CHECK(m1.velocity_cycles() == 1);
    }
  }
}

TEMPLATE_TEST_CASE_SIG("on a stiff pool around a solid the scaled commutator beats the Cahouet-Chabard "
                       "and additive pressure terms",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // sections 17 and 19: the Cahouet-Chabard-type S (and the additive pressure term before it)
  // lose quality with the stiffness next to free surfaces and walls; the scaled least-squares
  // commutator less so. The pool with a wavy free surface around a solid ball, eta 5000, default
  // options (multigrid hierarchies as in the scenes).
  CaseOptions o;
  o.n = Dim == 2 ? 64 : 16;
  o.eta = 5000.0;
  const auto sc = make_case<Dim>(o);
  const auto s = make_system(sc);
  std::array<int, 3> its{};
  for (int form = 0; form < 3; ++form) {
    StokesPreconditionerOptions po;
    po.schur_correction = form > 0;
    po.additive_pressure = form == 0;
    po.schur = form == 1 ? SchurApproximation::cahouet_chabard : SchurApproximation::commutator_scaled;
    const StokesPreconditioner<Dim> m(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf), po);
    PcgSettings settings;
    settings.max_iterations = 5000;
    VectorX x;
    const PcgResult r = pcg_solve(*s.mf, s.mf->rhs(sc.u_star), x, settings, m);
    CHECK(r.converged);
    its[form] = r.iterations;
  }
  INFO("additive " << its[0] << ", Cahouet-Chabard " << its[1] << ", scaled commutator " << its[2]);
  CHECK(its[2] < its[1]);
  CHECK(its[1] < its[0]);
}

TEMPLATE_TEST_CASE_SIG("PCG with the block preconditioner reaches CHOLMOD's solution on both back ends",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  for (double eta : {0.1, 100.0, 5000.0}) {
    CaseOptions o;
    o.n = Dim == 2 ? 24 : 10;
    o.eta = eta;
    const auto sc = make_case<Dim>(o);
    const auto s = make_system(sc);
    REQUIRE(s.dofs.null_space.empty());
    const VectorX exact = cholmod_solve(s.sys.A, s.sys.b);
    PcgSettings settings;
    settings.tolerance = 1e-10;
    settings.max_iterations = 200;
    const StokesPreconditioner<Dim> me(sc.grid, *s.ex, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, s.sys),
                                       small_options());
    const StokesPreconditioner<Dim> mm(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf),
                                       small_options());
    // the two back ends build and apply the same preconditioner: M r at the first iteration
    // (r = b) agrees to round-off. (Before the explicit A was swept in the matrix-free order,
    // stokes_sweep_order, its outer SOR sweeps ran in index order: M r differed by 1e-3..5e-2
    // and with one V-cycle the 2D solve at eta 5000 took 14 against 17 iterations;
    // docs/preconditioners.md section 24.)
    VectorX ze, zm;
    me.apply(s.sys.b, ze);
    mm.apply(s.mf->rhs(sc.u_star), zm);
    CHECK(rel_diff(ze, zm) < 1e-9);
    VectorX xe, xm;
    const PcgResult re = pcg_solve(*s.ex, s.sys.b, xe, settings, me);
    const PcgResult rm = pcg_solve(*s.mf, s.mf->rhs(sc.u_star), xm, settings, mm);
    INFO("eta " << eta << ": explicit " << re.iterations << ", matrix-free " << rm.iterations);
    CHECK(re.converged);
    CHECK(rm.converged);
    CHECK(rel_diff(xe, exact) < 1e-7);
    CHECK(rel_diff(xm, exact) < 1e-7);
    // so they need the same number of iterations within one (round-off in the Krylov recurrence)
    CHECK(std::abs(re.iterations - rm.iterations) <= 1);
    // and far fewer than SSOR
    PcgSettings ssor = settings;
    ssor.max_iterations = 100000;
    VectorX xs;
    const PcgResult rs = pcg_solve(*s.mf, s.mf->rhs(sc.u_star), xs, ssor);
    CHECK(rm.iterations < rs.iterations);
  }
}

TEMPLATE_TEST_CASE_SIG("stokes_sweep_order is the matrix-free operator's SOR order",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // an SOR sweep of the explicit A over the rows in that order (backward: reversed) is the
  // matrix-free sweep to round-off; in index order (SparseMatrixOperator's own) it is another SOR
  for (bool blob : {false, true}) {
    CaseOptions o;
    o.n = Dim == 2 ? 16 : 8;
    o.blob = blob;
    o.eta = 100.0;
    const auto sc = make_case<Dim>(o);
    const auto s = make_system(sc);
    const std::vector<int> order = stokes_sweep_order(sc.grid, s.layout, s.dofs);
    const int n = s.mf->size();
    REQUIRE(static_cast<int>(order.size()) == n);
    std::vector<int> sorted = order;
    std::sort(sorted.begin(), sorted.end());
    for (int i = 0; i < n; ++i) REQUIRE(sorted[i] == i);
    const SparseMatrix& a = s.ex->matrix();
    const VectorX diagonal = s.ex->diagonal();
    auto ordered_sweep = [&](bool reverse, const VectorX& rhs, VectorX& x) {
      for (int q = 0; q < n; ++q) {
        const int i = order[reverse ? n - 1 - q : q];
        if (diagonal[i] == 0.0) continue;
        double off = 0.0;
        for (SparseMatrix::InnerIterator it(a, i); it; ++it)
          if (it.col() != i) off += it.value() * x[it.col()];
        x[i] = (rhs[i] - off) / diagonal[i];
      }
    };
    const VectorX rhs = random_vector(n, 3);
    for (bool reverse : {false, true}) {
      VectorX xo = random_vector(n, 4), xm = xo, xi = xo;
      ordered_sweep(reverse, rhs, xo);
      if (reverse) {
        s.mf->backward_sweep(rhs, xm, 1.0);
        s.ex->backward_sweep(rhs, xi, 1.0);
      } else {
        s.mf->forward_sweep(rhs, xm, 1.0);
        s.ex->forward_sweep(rhs, xi, 1.0);
      }
      INFO("blob " << blob << " reverse " << reverse);
      CHECK(rel_diff(xo, xm) < 1e-12);
      CHECK(rel_diff(xi, xm) > 1e-6);
    }
  }
}

TEMPLATE_TEST_CASE_SIG("the block preconditioner and its solve are the same on 1 and 2 threads",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // large enough that the row loops (> 4096 rows) and the patch colours run in parallel
  CaseOptions o;
  o.n = Dim == 2 ? 64 : 20;
  o.eta = 1000.0;
  const auto sc = make_case<Dim>(o);
  const auto s = make_system(sc);
  const VectorX r = random_vector(s.mf->size(), 9);
  std::array<VectorX, 2> z, x;
  std::array<int, 2> iterations{};
  const int threads = omp_get_max_threads();
  for (int t = 0; t < 2; ++t) {
    omp_set_num_threads(t + 1);
    const StokesPreconditioner<Dim> m(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf));
    m.apply(r, z[t]);
    PcgSettings settings;
    iterations[t] = pcg_solve(*s.mf, s.mf->rhs(sc.u_star), x[t], settings, m).iterations;
  }
  omp_set_num_threads(threads);
  CHECK((z[0] - z[1]).cwiseAbs().maxCoeff() == 0.0);
  CHECK((x[0] - x[1]).cwiseAbs().maxCoeff() == 0.0);
  CHECK(iterations[0] == iterations[1]);
}

TEMPLATE_TEST_CASE_SIG("velocity V-cycle convergence factor on smooth and rough errors", "[unit]",
                       ((int Dim), Dim), 2, 3) {
  // the stationary iteration x <- x + Q (b - V x) on V x = 0 from a rough (random) and a smooth
  // (one sine period) error: the A-norm of the error shrinks by at least the bound per cycle
  for (double eta : {1.0, 1000.0}) {
    CaseOptions o;
    o.n = Dim == 2 ? 32 : 12;
    o.eta = eta;
    const auto sc = make_case<Dim>(o);
    const auto s = make_system(sc);
    StokesPreconditionerOptions po = small_options();
    po.max_coarse = 100;
    const StokesPreconditioner<Dim> m(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf), po);
    const Multigrid& mg = m.velocity_multigrid();
    const SparseMatrix a = mg.finest_operator();
    const int n = static_cast<int>(a.rows());
    VectorX smooth(n);
    for (int i = 0; i < n; ++i) {
      const auto [axis, c] = sc.grid.face_coord(m.factors().face[i]);
      const Vec<Dim> x = sc.grid.face_center(axis, c);
      smooth[i] = std::sin(M_PI * x[0]) * std::sin(M_PI * x[1]) * (axis + 1);
    }
    for (const VectorX& start : {VectorX(random_vector(n, 3)), smooth}) {
      VectorX e = start, d, r;
      double factor = 0.0, norm = std::sqrt(e.dot(a * e));
      for (int k = 0; k < 6; ++k) {
        r = -(a * e);
        mg.apply(r, d, 1);
        e += d;
        const double next = std::sqrt(e.dot(a * e));
        factor = std::max(factor, next / norm);
        norm = next;
      }
      INFO("eta " << eta << ", worst factor per cycle " << factor);
      CHECK(factor < 0.5);
    }
  }
}

TEMPLATE_TEST_CASE_SIG("k V-cycles per velocity solve: the stationary iteration, and two cut PCG iterations",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // Multigrid::apply with k cycles is x_1 = Q b, x_{j+1} = x_j + Q (b - V x_j) (its scratch
  // reused from one call to the next; V the operator the finest sweeps use: rounded in single
  // precision, (P12)), and 2 cycles (docs/preconditioners.md section 10) need
  // fewer iterations than 1 cycle on a stiff liquid ball in the air (free surface everywhere:
  // the case where one cycle was weakest)
  CaseOptions o;
  o.n = Dim == 2 ? 32 : 12;
  o.blob = true;
  o.eta = 5000.0;
  const auto sc = make_case<Dim>(o);
  const auto s = make_system(sc);
  StokesPreconditionerOptions po = small_options();
  po.velocity_cycles = 2;  // fixed counts: no rule
  po.cycle_ratio = 0.0;
  const StokesPreconditioner<Dim> m2(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf), po);
  const Multigrid& mg = m2.velocity_multigrid();
  REQUIRE(mg.num_levels() >= 2);
  const SparseMatrix a = mg.finest_operator(true);
  const VectorX b = random_vector(static_cast<int>(a.rows()), 5);
  for (int k : {2, 3}) {
    VectorX x, manual, d;
    mg.apply(b, x, k);
    mg.apply(b, manual, 1);
    for (int j = 1; j < k; ++j) {
      const VectorX r = b - a * manual;
      mg.apply(r, d, 1);
      manual += d;
    }
    INFO("cycles " << k);
    CHECK(rel_diff(x, manual) < 1e-12);
  }
  po.velocity_cycles = 1;
  const StokesPreconditioner<Dim> m1(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf), po);
  PcgSettings settings;
  settings.max_iterations = 5000;
  VectorX x1, x2;
  const PcgResult r1 = pcg_solve(*s.mf, s.mf->rhs(sc.u_star), x1, settings, m1);
  const PcgResult r2 = pcg_solve(*s.mf, s.mf->rhs(sc.u_star), x2, settings, m2);
  INFO("iterations: 1 cycle " << r1.iterations << ", 2 cycles " << r2.iterations);
  CHECK(r1.converged);
  CHECK(r2.converged);
  CHECK(r2.iterations < r1.iterations);
}

TEMPLATE_TEST_CASE_SIG("solve_stokes with the multigrid preconditioner: same update as SSOR, warm start",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  CaseOptions o;
  o.n = Dim == 2 ? 24 : 10;
  o.eta = 500.0;
  const auto sc = make_case<Dim>(o);
  PcgSettings settings;
  settings.tolerance = 1e-9;
  settings.max_iterations = 100000;
  VectorX u_ssor = sc.u_star, u_mg = sc.u_star, u_warm = sc.u_star;
  StokesSolveOptions ssor;
  ssor.preconditioner = PreconditionerKind::ssor;
  const auto a = solve_stokes(sc.grid, sc.w, sc.dt, StokesUnknowns::pressure_and_stress, StressForm::reduced,
                              Backend::matrix_free, settings, u_ssor, ssor);
  const StokesPreconditionerOptions small = small_options();
  StokesSolveOptions mg;
  mg.preconditioner = PreconditionerKind::multigrid;
  mg.multigrid = &small;
  const auto b = solve_stokes(sc.grid, sc.w, sc.dt, StokesUnknowns::pressure_and_stress, StressForm::reduced,
                              Backend::matrix_free, settings, u_mg, mg);
  CHECK(a.pcg.converged);
  CHECK(b.pcg.converged);
  CHECK(b.pcg.iterations < a.pcg.iterations);
  CHECK(rel_diff(u_mg, u_ssor) < 1e-7);
  // warm start from the solution itself: converged at once, same update
  mg.initial_stress = &b.stress;
  mg.initial_pressure = &b.pressure;
  const auto c = solve_stokes(sc.grid, sc.w, sc.dt, StokesUnknowns::pressure_and_stress, StressForm::reduced,
                              Backend::matrix_free, settings, u_warm, mg);
  CHECK(c.pcg.converged);
  CHECK(c.pcg.iterations <= 1);
  CHECK(rel_diff(u_warm, u_mg) < 1e-8);
}

TEMPLATE_TEST_CASE_SIG("the warm start's conditioning: never a larger energy than zero, a solution kept",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // condition_stokes_warm_start (docs/preconditioners.md section 46) on both back ends: a start
  // far worse than zero (another u*'s solution with spikes of 1e4 times its size, as the floating
  // pressures of near-empty cells) ends with an energy 1/2 x.A x - b.x at most zero's; the
  // negated solution without the sweeps gives x = 0; the solution itself stays (to round-off)
  CaseOptions o;
  o.n = Dim == 2 ? 24 : 10;
  o.eta = 5000.0;
  const auto sc = make_case<Dim>(o);
  const auto s = make_system(sc);
  const StokesPreconditioner<Dim> m(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf),
                                    small_options());
  PcgSettings settings;
  settings.tolerance = 1e-10;
  settings.max_iterations = 100000;
  const VectorX b = s.mf->rhs(sc.u_star);
  const VectorX b_other = s.mf->rhs(VectorX(0.5 * sc.u_star + random_vector(sc.grid.num_faces(), 3)));
  VectorX x_star, x_other;
  REQUIRE(pcg_solve(*s.mf, b, x_star, settings, m).converged);
  REQUIRE(pcg_solve(*s.mf, b_other, x_other, settings, m).converged);
  const double spike = 1e4 * x_other.cwiseAbs().maxCoeff();
  for (Eigen::Index i = 0; i < x_other.size(); i += 7) x_other[i] += spike;
  for (const LinearOperator* a : {static_cast<const LinearOperator*>(s.mf.get()),
                                  static_cast<const LinearOperator*>(s.ex.get())}) {
    auto energy = [&](const VectorX& x) {
      VectorX ax;
      a->apply(x, ax);
      return 0.5 * x.dot(ax) - b.dot(x);
    };
    auto residual = [&](const VectorX& x) {
      VectorX ax;
      a->apply(x, ax);
      return (b - ax).cwiseAbs().maxCoeff() / b.cwiseAbs().maxCoeff();
    };
    VectorX x = x_other;
    const double before = energy(x);
    INFO("relative residual of the start " << residual(x) << ", energy " << before);
    REQUIRE(residual(x) > 1e3);
    condition_stokes_warm_start(*a, b, x);
    CHECK(x.allFinite());
    CHECK(energy(x) <= 0.0);
    CHECK(energy(x) < 1e-6 * before);
    VectorX negated = -x_star;  // without the sweeps (rounds 0): a negative best multiple
    condition_stokes_warm_start(*a, b, negated, 0);
    CHECK(negated.isZero(0.0));
    VectorX kept = x_star;
    condition_stokes_warm_start(*a, b, kept);
    CHECK(rel_diff(kept, x_star) < 1e-12);
    CHECK(residual(kept) < 1e-8);
  }
}

TEMPLATE_TEST_CASE_SIG("a warm start far from the solution: the cold solve's solution, the same bits on 1 and 2 threads",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // solve_stokes from the previous (tau, p) of another u* with spiked pressures (near-empty
  // cells' floating values): converged to the cold start's measure, the same update as cold,
  // and bitwise the same on 1 and 2 threads
  CaseOptions o;
  o.n = Dim == 2 ? 24 : 10;
  o.eta = 5000.0;
  const auto sc = make_case<Dim>(o);
  PcgSettings settings;
  settings.tolerance = 1e-9;
  settings.max_iterations = 100000;
  const StokesPreconditionerOptions small = small_options();
  StokesSolveOptions mg;
  mg.preconditioner = PreconditionerKind::multigrid;
  mg.multigrid = &small;
  VectorX u_cold = sc.u_star, u_other = 0.5 * sc.u_star + random_vector(sc.grid.num_faces(), 3);
  const auto cold = solve_stokes(sc.grid, sc.w, sc.dt, StokesUnknowns::pressure_and_stress, StressForm::reduced,
                                 Backend::matrix_free, settings, u_cold, mg);
  const auto other = solve_stokes(sc.grid, sc.w, sc.dt, StokesUnknowns::pressure_and_stress, StressForm::reduced,
                                  Backend::matrix_free, settings, u_other, mg);
  REQUIRE(cold.pcg.converged);
  REQUIRE(other.pcg.converged);
  VectorX pressure = other.pressure;
  const double spike = 1e6 * std::max(1.0, pressure.cwiseAbs().maxCoeff());
  for (Eigen::Index c = 0; c < pressure.size(); c += 5) pressure[c] += spike;
  mg.initial_stress = &other.stress;
  mg.initial_pressure = &pressure;
  const int threads = omp_get_max_threads();
  std::vector<VectorX> u(2, sc.u_star);
  std::vector<int> iterations(2);
  for (int t = 0; t < 2; ++t) {
    omp_set_num_threads(t + 1);
    const auto warm = solve_stokes(sc.grid, sc.w, sc.dt, StokesUnknowns::pressure_and_stress, StressForm::reduced,
                                   Backend::matrix_free, settings, u[t], mg);
    CHECK(warm.pcg.converged);
    CHECK(warm.pcg.relative_residual <= settings.tolerance);
    iterations[t] = warm.pcg.iterations;
  }
  omp_set_num_threads(threads);
  INFO("iterations cold " << cold.pcg.iterations << ", warm " << iterations[0]);
  CHECK(rel_diff(u[0], u_cold) < 1e-6);
  CHECK(iterations[0] == iterations[1]);
  CHECK(std::memcmp(u[0].data(), u[1].data(), sizeof(double) * u[0].size()) == 0);
}

TEMPLATE_TEST_CASE_SIG("at eta = 5000 the block preconditioner needs at most 60 iterations, SSOR more",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // the goal of docs/preconditioners.md (at most 60 iterations at any eta) on the pool around a
  // solid ball with varying density and viscosity, where the paper's SSOR needs far more
  CaseOptions o;
  o.n = Dim == 2 ? 32 : 12;
  o.eta = 5000.0;
  const auto sc = make_case<Dim>(o);
  const auto s = make_system(sc);
  PcgSettings settings;  // tolerance 1e-6, as in the scenes
  settings.max_iterations = 100000;
  const StokesPreconditioner<Dim> m(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf));
  VectorX xm, xs;
  const PcgResult rm = pcg_solve(*s.mf, s.mf->rhs(sc.u_star), xm, settings, m);
  const PcgResult rs = pcg_solve(*s.mf, s.mf->rhs(sc.u_star), xs, settings);
  INFO("multigrid " << rm.iterations << ", SSOR " << rs.iterations);
  CHECK(rm.converged);
  CHECK(rs.converged);
  CHECK(rm.iterations <= 60);
  CHECK(rs.iterations > 60);
}

TEMPLATE_TEST_CASE_SIG("the lazy block preconditioner: no set-up when PCG stops at once, else the eager result",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  CaseOptions o;
  o.n = Dim == 2 ? 24 : 10;
  o.eta = 500.0;
  const auto sc = make_case<Dim>(o);
  const auto s = make_system(sc);
  const StokesPreconditionerOptions small = small_options();
  int builds = 0;
  const LazyPreconditioner lazy(s.mf->size(), "block", [&]() -> std::unique_ptr<Preconditioner> {
    ++builds;
    return std::make_unique<StokesPreconditioner<Dim>>(
        sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf), small);
  });
  PcgSettings settings;
  settings.max_iterations = 10000;
  // a zero right-hand side: converged before the first iteration, nothing built
  VectorX x0;
  const PcgResult r0 = pcg_solve(*s.mf, VectorX::Zero(s.mf->size()), x0, settings, lazy);
  CHECK(r0.converged);
  CHECK(r0.iterations == 0);
  CHECK(builds == 0);
  CHECK(lazy.built() == nullptr);
  // a real solve builds it once and gives the eager preconditioner's iterates bit for bit
  const VectorX b = s.mf->rhs(sc.u_star);
  VectorX xl, xe;
  const PcgResult rl = pcg_solve(*s.mf, b, xl, settings, lazy);
  const StokesPreconditioner<Dim> eager(sc.grid, *s.mf, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf),
                                        small);
  const PcgResult re = pcg_solve(*s.mf, b, xe, settings, eager);
  CHECK(builds == 1);
  REQUIRE(lazy.built() != nullptr);
  CHECK(rl.converged);
  CHECK(rl.iterations == re.iterations);
  CHECK((xl - xe).lpNorm<Eigen::Infinity>() == 0.0);
  // reused for a second solve without a second set-up
  VectorX x2;
  pcg_solve(*s.mf, b, x2, settings, lazy);
  CHECK(builds == 1);
  CHECK((x2 - xe).lpNorm<Eigen::Infinity>() == 0.0);
}

TEMPLATE_TEST_CASE_SIG("MGPCG pressure solves: the stencil matrix is the assembled A, same update as SSOR, "
                       "fewer iterations, thread-count independent, enclosed liquid",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  for (const bool enclosed : {false, true}) {
    CAPTURE(enclosed);
    CaseOptions o;
    o.n = Dim == 2 ? 64 : 16;  // more liquid cells than the coarsest level holds: a real V-cycle
    auto sc = make_case<Dim>(o);
    if (enclosed) {
      // liquid fills a box with walls on every side: A is singular on constants
      const SampleLattice<Dim> lattice = half_lattice(sc.grid);
      std::array<BoundaryType, 2 * Dim> boundary;
      boundary.fill(BoundaryType::wall);
      const VectorX solid_phi = solid_phi_on_lattice<Dim>(sc.grid, lattice, {}, 0.0);
      sc.w = uniform_stokes_weights(sc.grid, solid_phi, VectorX::Constant(lattice.size(), -1.0), boundary,
                                    1000.0, 0.0);
    }
    const PressureWeights& w = sc.w.pressure;
    const PressureDofs dofs = select_pressure_dofs(sc.grid, w, sc.dt);
    CHECK(dofs.null_space.empty() != enclosed);
    // the matrix-free operator's stencils as a matrix equal the explicit back end's A
    const MatrixFreePressureOperator<Dim> mf(sc.grid, w, dofs, sc.dt);
    const ExplicitPressureSystem ex = assemble_explicit_pressure(sc.grid, w, dofs, sc.dt, sc.u_star);
    const SparseMatrix diff = mf.matrix(dofs) - ex.A;
    CHECK(Eigen::MatrixXd(diff).cwiseAbs().maxCoeff() <= 1e-12 * Eigen::MatrixXd(ex.A).cwiseAbs().maxCoeff());
    PcgSettings settings;
    settings.tolerance = 1e-9;
    settings.max_iterations = 10000;
    for (const Backend backend : {Backend::matrix_free, Backend::explicit_matrices}) {
      VectorX u_ssor = sc.u_star, u_mg = sc.u_star, u_mg2 = sc.u_star;
      const auto rs = solve_pressure(sc.grid, w, sc.dt, backend, settings, u_ssor);
      const auto rm = solve_pressure(sc.grid, w, sc.dt, backend, settings, u_mg, PreconditionerKind::multigrid);
      INFO("SSOR " << rs.pcg.iterations << ", MGPCG " << rm.pcg.iterations);
      CHECK(rs.pcg.converged);
      CHECK(rm.pcg.converged);
      // a V-cycle is worth many SSOR sweeps: if the hierarchy breaks, this fails
      CHECK(rm.pcg.iterations * 4 <= rs.pcg.iterations);
      CHECK(rm.pcg.iterations <= 20);
      CHECK(rel_diff(u_mg, u_ssor) < 1e-7);
      const int threads = omp_get_max_threads();
      omp_set_num_threads(2);
      solve_pressure(sc.grid, w, sc.dt, backend, settings, u_mg2, PreconditionerKind::multigrid);
      omp_set_num_threads(threads);
      CHECK((u_mg2 - u_mg).lpNorm<Eigen::Infinity>() == 0.0);
    }
  }
}

TEMPLATE_TEST_CASE_SIG("the cut block: the stress unknowns cut by the solid, their pressures and two layers, "
                       "solved exactly; SPD, both back ends, fewer iterations",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  CaseOptions o;
  o.n = Dim == 2 ? 32 : 12;
  o.eta = 5000.0;
  const auto sc = make_case<Dim>(o);
  const auto s = make_system(sc);
  // the factors as solve_stokes builds them: K floored at W_F^s = 0.01, the block uses the exact K
  const StokesPreconditionerOptions po;
  const StokesFactors fm = stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf, po.min_fluid_fraction);
  const StokesFactors fe = stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, s.sys, po.min_fluid_fraction);
  // the exact K is kept exactly when the floor changes K (some W_F^s strictly inside (0, floor))
  const bool floored = (sc.w.fluid_stress.array() > 0.0 && sc.w.fluid_stress.array() < po.min_fluid_fraction).any();
  CHECK((fm.compliance_exact.size() > 0) == floored);
  CHECK((fe.compliance_exact.size() > 0) == floored);
  const StokesPreconditioner<Dim> mm(sc.grid, *s.mf, fm, po);
  const StokesPreconditioner<Dim> me(sc.grid, *s.ex, fe, po);
  const std::vector<int>& cut = mm.cut_unknowns();
  // the seed: every stress unknown with 0 < W_F^s < 1/2 (the solid ball cuts some), pressures, layers
  int seed = 0, pressure = 0, layer = 0;
  std::vector<char> in(s.mf->size(), 0);
  for (int i : cut) in[i] = 1;
  for (int i = 0; i < fm.num_stress; ++i)
    if (fm.stress_fluid[i] > 0.0 && fm.stress_fluid[i] < po.cut_threshold) {
      ++seed;
      CHECK(in[i]);
    }
  for (int i : cut) {
    if (i >= fm.num_stress) ++pressure;
    else if (fm.stress_fluid[i] >= po.cut_threshold) ++layer;
  }
  INFO("block " << cut.size() << ": seed " << seed << ", pressure " << pressure << ", full stress " << layer
                << " of " << s.mf->size());
  CHECK(seed > 0);
  CHECK(pressure > 0);
  CHECK(layer > 0);
  CHECK(static_cast<int>(cut.size()) < s.mf->size() / 2);
  CHECK(std::is_sorted(cut.begin(), cut.end()));
  CHECK(me.cut_unknowns() == cut);  // both back ends pick the same block
  // each back end's preconditioned solve reaches CHOLMOD's solution, the block saves iterations
  const VectorX exact = cholmod_solve(s.sys.A, s.sys.b);
  PcgSettings settings;
  settings.tolerance = 1e-10;
  settings.max_iterations = 1000;
  StokesPreconditionerOptions off = po;
  off.cut_threshold = 0.0;
  const StokesPreconditioner<Dim> mo(sc.grid, *s.mf, fm, off);
  CHECK(mo.cut_unknowns().empty());
  VectorX xm, xe, xo;
  const PcgResult rm = pcg_solve(*s.mf, s.mf->rhs(sc.u_star), xm, settings, mm);
  const PcgResult re = pcg_solve(*s.ex, s.sys.b, xe, settings, me);
  const PcgResult ro = pcg_solve(*s.mf, s.mf->rhs(sc.u_star), xo, settings, mo);
  INFO("iterations: block " << rm.iterations << " (explicit " << re.iterations << "), without " << ro.iterations);
  CHECK(rm.converged);
  CHECK(re.converged);
  CHECK(rel_diff(xm, exact) < 1e-7);
  CHECK(rel_diff(xe, exact) < 1e-7);
  CHECK(std::abs(rm.iterations - re.iterations) <= 1);
  CHECK(rm.iterations < ro.iterations);
  // the layer limit: a block above cut_layer_limit unknowns after its first layer gets no second
  // one (this block is below the default limit, so the default keeps both)
  StokesPreconditionerOptions one = po, limited = po, unlimited = po;
  one.cut_layers = 1;
  limited.cut_layer_limit = 1;
  unlimited.cut_layer_limit = 0;
  const StokesPreconditioner<Dim> m1(sc.grid, *s.mf, fm, one);
  const StokesPreconditioner<Dim> ml(sc.grid, *s.mf, fm, limited);
  const StokesPreconditioner<Dim> mu(sc.grid, *s.mf, fm, unlimited);
  CHECK(static_cast<int>(cut.size()) <= po.cut_layer_limit);
  CHECK(mu.cut_unknowns() == cut);
  CHECK(m1.cut_unknowns().size() < cut.size());
  CHECK(ml.cut_unknowns() == m1.cut_unknowns());
  CHECK(ml.cut_factor_entries() < mm.cut_factor_entries());
}

TEMPLATE_TEST_CASE_SIG("the cut block keeps the preconditioner symmetric positive definite (pool around a "
                       "solid, low and high viscosity)",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  for (double eta : {0.01, 5000.0}) {
    CaseOptions o;
    o.n = Dim == 2 ? 10 : 6;
    o.eta = eta;
    auto sc = make_case<Dim>(o);
    const auto s = make_system(sc);
    const StokesPreconditionerOptions po = small_options();
    const StokesPreconditioner<Dim> m(sc.grid, *s.mf,
                                      stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf, po.min_fluid_fraction), po);
    INFO("eta " << eta << ", block " << m.cut_unknowns().size() << " of " << m.size());
    REQUIRE(!m.cut_unknowns().empty());
    check_symmetric_positive_definite(m, s.mf->diagonal());
  }
}

TEMPLATE_TEST_CASE_SIG("the free-surface sweeps (P17): the partly filled cells and the stress on their faces, "
                       "P symmetric positive definite, fewer PCG iterations on the stiff pool",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // the set: every pressure unknown of a cell with W_L^p < 1 and only the stress unknowns their
  // rows of A reach besides them (no other pressure)
  {
    CaseOptions o;
    o.n = Dim == 2 ? 10 : 6;
    o.eta = 5000.0;
    const auto sc = make_case<Dim>(o);
    const auto s = make_system(sc);
    const StokesPreconditionerOptions po = small_options();
    const StokesFactors f = stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf, po.min_fluid_fraction);
    const int ns = f.num_stress;
    std::vector<char> partly(f.num_pressure, 0);
    int num_partly = 0;
    for (int k = 0; k < f.num_pressure; ++k) num_partly += partly[k] = f.pressure_liquid[k] < 1.0;
    const StokesPreconditioner<Dim> m(sc.grid, *s.mf, f, po);
    const std::vector<int>& set = m.surface_unknowns();
    REQUIRE(num_partly > 0);
    std::vector<char> in(m.size(), 0);
    for (int i : set) in[i] = 1;
    int pressures = 0, stresses = 0, reached = 0;
    for (int i : set) (i < ns ? stresses : pressures) += 1;
    CHECK(pressures == num_partly);
    for (int k = 0; k < f.num_pressure; ++k)
      if (partly[k]) CHECK(in[ns + k]);
    // every stress unknown of the set shares a face (a row of B) with a partly filled cell
    for (int i : set) {
      if (i >= ns) continue;
      bool shares = false;
      for (SparseMatrix::InnerIterator it(f.b_transpose, i); it && !shares; ++it)
        for (SparseMatrix::InnerIterator jt(f.b, it.col()); jt && !shares; ++jt)
          shares = jt.col() >= ns && partly[jt.col() - ns] && jt.value() != 0.0;
      reached += shares;
    }
    CHECK(stresses > 0);
    CHECK(reached == stresses);
    CHECK(static_cast<int>(set.size()) < m.size());
    // symmetric positive definite with the sweeps (the pool: no null space)
    check_symmetric_positive_definite(m, s.mf->diagonal());
    // off: no set
    StokesPreconditionerOptions off = po;
    off.surface_sweeps = 0;
    const StokesPreconditioner<Dim> m0(sc.grid, *s.mf, f, off);
    CHECK(m0.surface_unknowns().empty());
  }
  // the pool and a liquid ball in the air (a free surface all round), stiff to very stiff: never
  // more iterations with the sweeps than without and fewer over the six cases, the same solution
  // to tolerance, on both back ends alike
  int total_with = 0, total_without = 0;
  for (int blob = 0; blob < 2; ++blob)
    for (double eta : {5000.0, 1e5, 1e6}) {
      CaseOptions o;
      o.n = Dim == 2 ? 32 : 12;
      o.blob = blob;
      o.eta = eta;
      const auto sc = make_case<Dim>(o);
      const auto s = make_system(sc);
      PcgSettings settings;
      settings.max_iterations = 1000;
      const StokesPreconditionerOptions on = small_options();
      StokesPreconditionerOptions off = on;
      off.surface_sweeps = 0;
      const StokesFactors f = stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf);
      const StokesPreconditioner<Dim> with(sc.grid, *s.mf, f, on), without(sc.grid, *s.mf, f, off);
      const StokesPreconditioner<Dim> with_ex(sc.grid, *s.ex, stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, s.sys), on);
      VectorX x1, x0, xe;
      const PcgResult r1 = pcg_solve(*s.mf, s.mf->rhs(sc.u_star), x1, settings, with);
      const PcgResult r0 = pcg_solve(*s.mf, s.mf->rhs(sc.u_star), x0, settings, without);
      const PcgResult re = pcg_solve(*s.ex, s.sys.b, xe, settings, with_ex);
      INFO("with the sweeps " << r1.iterations << " (explicit " << re.iterations << "), without " << r0.iterations
                              << ", set " << with.surface_unknowns().size() << " of " << with.size());
      CHECK(r1.converged);
      CHECK(r0.converged);
      CHECK(re.converged);
      CHECK(r1.iterations <= r0.iterations);
      total_with += r1.iterations;
      total_without += r0.iterations;
      CHECK(std::abs(re.iterations - r1.iterations) <= 1);
      // (to the PCG tolerance: since surf24 the dry faces the surface stress reads carry W_L^u =
      // 1e-4, stiff rows of A, so equal residuals leave up to 3.1e-4 between the two solutions)
      CHECK(rel_diff(x1, x0) < 1e-3);
      CHECK(rel_diff(x1, xe) < 1e-3);
    }
  INFO("over the six cases: with the sweeps " << total_with << ", without " << total_without);
  CHECK(total_with < total_without);
}

TEST_CASE("the set-up's assembly: B^T, V and A22's diagonal the bits of the plain assembly, on 1 and 2 threads",
          "[unit]") {
  // stokes_factors and velocity_operator assemble through one buffer per thread
  // (velocity_operator.cpp, assemble_rows), the block preconditioner forms only A22's diagonal
  // under the scaled commutator (docs/preconditioners.md section 36): B^T equals the matrix built
  // from the stencils by setFromTriplets, V does not depend on the thread count or on K^-1 being
  // passed in and equals C^-1 + B D^-1 B^T to round-off, and Pi is the one of Eigen's A22, bit for bit
  constexpr int Dim = 3;
  CaseOptions o;
  o.n = 14;  // more than 4096 faces and rows: the parallel paths
  o.eta = 1000.0;
  const auto sc = make_case<Dim>(o);
  const auto s = make_system(sc);
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const StokesFactors f1 = stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf, 0.01);
  omp_set_num_threads(2);
  const StokesFactors f2 = stokes_factors(sc.grid, s.layout, sc.w, s.dofs, sc.dt, *s.mf, 0.01);
  omp_set_num_threads(threads);
  REQUIRE(f1.face.size() > 4096);
  REQUIRE(f1.size() > 4096);
  CHECK(testing::same_sparse_bits(f1.b_transpose, f2.b_transpose));
  CHECK(testing::same_sparse_bits(f1.b, f2.b));
  // B^T from the stencils by triplets (repeated faces summed in the stencil's order)
  std::vector<int> active(sc.grid.num_faces(), -1);
  for (std::size_t q = 0; q < f1.face.size(); ++q) active[f1.face[q]] = static_cast<int>(q);
  std::vector<Triplet> t;
  for (int i = 0; i < f1.size(); ++i)
    for (const auto& [face, coef] : s.mf->stencil(i))
      if (active[face] >= 0 && coef != 0.0) t.emplace_back(i, active[face], coef);
  SparseMatrix bt(f1.size(), static_cast<int>(f1.face.size()));
  bt.setFromTriplets(t.begin(), t.end());
  bt.makeCompressed();
  CHECK(testing::same_sparse_bits(f1.b_transpose, bt));
  // V on 1 and 2 threads, with and without K^-1 given, against Eigen's products
  const VectorX penalty = VectorX::LinSpaced(f1.num_pressure, 1e-4, 1e-2);
  const SparseMatrix kinv = block_diagonal_inverse(f1.compliance);
  omp_set_num_threads(1);
  const SparseMatrix v1 = velocity_operator(f1, penalty);
  omp_set_num_threads(2);
  const SparseMatrix v2 = velocity_operator(f1, penalty);
  const SparseMatrix v3 = velocity_operator(f1, penalty, &kinv);
  omp_set_num_threads(threads);
  CHECK(testing::same_sparse_bits(v1, v2));
  CHECK(testing::same_sparse_bits(v1, v3));
  VectorX dinv_p = penalty.cwiseInverse();
  SparseMatrix dinv(f1.size(), f1.size());
  {
    std::vector<Triplet> d;
    for (int i = 0; i < kinv.outerSize(); ++i)
      for (SparseMatrix::InnerIterator it(kinv, i); it; ++it) d.emplace_back(i, static_cast<int>(it.col()), it.value());
    for (int k = 0; k < f1.num_pressure; ++k) d.emplace_back(f1.num_stress + k, f1.num_stress + k, dinv_p[k]);
    dinv.setFromTriplets(d.begin(), d.end());
  }
  const SparseMatrix v_ref =
      SparseMatrix(sparse_diagonal(f1.c.cwiseInverse())) + SparseMatrix(SparseMatrix(f1.b * dinv) * f1.b_transpose);
  const SparseMatrix diff = v1 - v_ref;
  double scale = 0.0, worst = 0.0;
  for (int e = 0; e < v_ref.nonZeros(); ++e) scale = std::max(scale, std::abs(v_ref.valuePtr()[e]));
  for (int e = 0; e < diff.nonZeros(); ++e) worst = std::max(worst, std::abs(diff.valuePtr()[e]));
  CHECK(scale > 0.0);
  CHECK(worst <= 1e-12 * scale);
  // Pi from A22's diagonal alone (the default scaled commutator) and from Eigen's A22
  StokesPreconditionerOptions po = small_options();
  REQUIRE(po.schur == SchurApproximation::commutator_scaled);
  StokesFactors f = f1;
  const SparseMatrix a22 = SparseMatrix(SparseMatrix(f.b_transpose.bottomRows(f.num_pressure) * sparse_diagonal(f.c)) *
                                        f.b.rightCols(f.num_pressure));
  const StokesPreconditioner<Dim> m(sc.grid, *s.mf, std::move(f), po);
  REQUIRE(m.penalty().size() == f1.num_pressure);
  int checked = 0;
  for (int k = 0; k < f1.num_pressure; ++k) {
    const double visc = f1.pressure_viscosity[k] / f1.pressure_liquid[k];
    const double expected = 1.0 / (po.penalty_factor * (visc + 1.0 / a22.coeff(k, k)));
    if (std::memcmp(&expected, &m.penalty()[k], sizeof(double)) == 0) ++checked;
  }
  CHECK(checked == f1.num_pressure);
}
