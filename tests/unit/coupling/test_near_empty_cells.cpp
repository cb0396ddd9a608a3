// Near-empty pressure cells in the coupled block preconditioner (docs/preconditioners.md sections
// 21 and 23). A liquid cell almost closed between a light floating body and a static solid has a
// Poisson diagonal A22_kk many orders of magnitude below the median, and the body term
// d_k = (B_f^T W B_f)_kk of A_ff = F + B_f^T W B_f dwarfs it (the body's motion changes the cell's
// volume). Such cells E are left out of P (P = blkdiag(P_r, 0)) and solved exactly with the body
// term: Q^-1 = blkdiag(P_r^-1, F_EE) + B_f^T W B_f by block elimination of E. Here such cells are
// made in the unit tank (the top faces of one or three cells in a row under a floating box of
// density 500 given to the box up to 1e-10, their other faces to a static solid) and the
// preconditioner is checked densely: the cells are detected, Q^-1 equals A_ff on E's columns
// exactly (without the floor of F_EE's diagonal),
// M is symmetric and positive definite, the spectrum of M^-1 A stays in a narrow band, PCG
// converges in a few iterations; the contact rows eliminated in face (with a ball on the floor)
// give M_FF^-1; 1 and 2 threads give the same bits. With three cells in a row the body term seen
// from E has rank 2 (v_y and the rotation): section 21's Jacobi term r_k / (A22_kk + d_k) cannot
// see the third mode, which A_ff holds at A22's scale, and M^-1 A gets an eigenvalue near 1e-9
// (the stall of bunny-into-block-shear-thinning-2d frame 31). A cell closed by the body alone
// keeps its volume under any rigid motion (d_k = 0): it is not left out.
#include <omp.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <vector>

#include "reference/contact/collision.hpp"
#include "reference/contact/contact_system.hpp"
#include "reference/coupling/coupled_preconditioner.hpp"
#include "reference/coupling/coupled_schemes.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/coupling/monolithic_system.hpp"
#include "reference/solvers/pcg.hpp"
#include "tests/support/body_helpers.hpp"
#include "tests/support/coupled_helpers.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;

namespace {

constexpr double kRho = 1000.0;
constexpr double kDt = 0.01;

/// The unit tank (walls, open top), liquid of viscosity eta below y = 0.55, a light box
/// (density 500) floating at y = 0.5; then `count` liquid cells in a row right under the box's
/// centre are closed up to `open` (W_F^u = open): their top faces given to the box and their
/// other faces to a static solid (`box_only`: all four faces of one cell to the box). With `ball`,
/// a heavy ball resting on the floor at x = 0.8 (contacts with the floor wall). `cells`: the
/// closed cells' indices.
CoupledStepInput<2> tank_with_closed_cells(int n, double eta, double open, int count, bool box_only,
                                           bool ball, std::vector<int>& cells) {
  CoupledStepInput<2> in{testing::unit_grid<2>(n), {}, kDt, {}, {}, {}, {}, {}};
  const double dx = in.grid.dx();
  in.bodies = {testing::make_box<2>(Vec<2>(0.5, 0.5), Vec<2>(0.12, 0.12), 500.0, 0.0)};
  if (ball) {
    ShapeSpec sphere;
    sphere.type = ShapeType::sphere;
    sphere.radius = 0.1;
    sphere.center = testing::as_std<2>(Vec<2>(0.8, 0.1 - 0.1 * dx));
    in.bodies.push_back(testing::make_body<2>(sphere, 2500.0, 0.0));
  }
  for (std::size_t b = 0; b < in.bodies.size(); ++b) {
    BodyVec<2> v = BodyVec<2>::Zero();
    v[0] = 0.05 * static_cast<double>(b);
    v[1] = -9.81 * kDt;
    in.bodies[b].set_generalized_velocity(v);
  }
  std::array<BoundaryType, 4> boundary = testing::all_boundaries<2>(BoundaryType::wall);
  boundary[3] = BoundaryType::open;
  in.solids = solid_weights<2>(in.grid, coupling_bodies(in.bodies), {}, boundary, 0.01 * dx);
  REQUIRE(in.solids.static_face.size() == static_cast<Eigen::Index>(in.grid.num_faces()));
  // the cells under the box's bottom (y = 0.38), from x = 0.5 to the right
  cells.clear();
  for (int q = 0; q < count; ++q) {
    const VecI<2> c(static_cast<int>(0.5 / dx) + q, static_cast<int>(0.38 / dx) - 1);
    cells.push_back(in.grid.cell_index(c));
    const int faces[4] = {in.grid.face_index(0, c), in.grid.face_index(0, VecI<2>(c[0] + 1, c[1])),
                          in.grid.face_index(1, c), in.grid.face_index(1, VecI<2>(c[0], c[1] + 1))};
    for (int side = 0; side < 4; ++side) {
      const int f = faces[side];
      const bool to_box = box_only || side == 3;
      for (std::size_t b = 0; b < in.bodies.size(); ++b) in.solids.body_face[b][f] = 0.0;
      in.solids.body_face[0][f] = to_box ? 1.0 - open : 0.0;
      in.solids.static_face[f] = to_box ? 0.0 : 1.0 - open;
      in.solids.solid_face[f] = 1.0 - open;
      in.solids.fluid_face[f] = open;
    }
  }
  testing::fill_tank_liquid(in, kRho, eta);
  if (ball) in.contacts = detect_contacts<2>(in.bodies, testing::unit_box_walls<2>(0.0), 0.3 * dx);
  return in;
}

struct Quality {
  double asymmetry = 0.0;         ///< ||M - M^T|| / ||M||
  double min_eig = 0.0, max_eig = 0.0;  ///< of (M + M^T) / 2, relative to its largest |.|
  double lo = 0.0, hi = 0.0;      ///< spectrum of M^-1 A (when M is positive definite)
  int pcg_iterations = 0;
  bool pcg_converged = false;
};

Quality measure(const MonolithicSystem<2>& s, const CoupledPreconditioner<2>& m) {
  Quality q;
  const FluidBodyOperator<2> op(s);
  const Eigen::MatrixXd a = op.dense_matrix();
  const Eigen::MatrixXd d = testing::dense(m);
  q.asymmetry = (d - d.transpose()).norm() / d.norm();
  const Eigen::MatrixXd sym = 0.5 * (d + d.transpose());
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(sym, Eigen::EigenvaluesOnly);
  const double top = es.eigenvalues().cwiseAbs().maxCoeff();
  q.min_eig = es.eigenvalues().minCoeff() / top;
  q.max_eig = es.eigenvalues().maxCoeff() / top;
  const Eigen::LLT<Eigen::MatrixXd> llt(sym);
  if (llt.info() == Eigen::Success && q.min_eig > 0.0) {
    const Eigen::MatrixXd l = llt.matrixL();
    const Eigen::MatrixXd g = l.transpose() * a * l;
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eg(0.5 * (g + g.transpose()), Eigen::EigenvaluesOnly);
    q.lo = eg.eigenvalues().minCoeff();
    q.hi = eg.eigenvalues().maxCoeff();
  }
  PcgSettings settings;
  settings.tolerance = 1e-8;
  settings.max_iterations = 1000;
  VectorX x;
  const PcgResult r = pcg_solve(op, s.fluid_rhs(VectorX(), VectorX()), x, settings, m);
  q.pcg_iterations = r.iterations;
  q.pcg_converged = r.converged;
  return q;
}

/// The fluid indices of the near-empty cells of m (E).
std::vector<int> empty_rows(const MonolithicSystem<2>& s, const CoupledPreconditioner<2>& m) {
  std::vector<int> rows;
  for (int k : m.fluid().empty_cells()) rows.push_back(s.num_stress() + k);
  return rows;
}

/// max |Q X - I_E| with X = the columns E of Q^-1 as the exact elimination defines it,
/// [B_r^T W B_E; F_EE + B_E^T W B_E] = A_ff's columns E without F's couplings of E to the rest.
double exactness_error(const MonolithicSystem<2>& s, const CoupledPreconditioner<2>& m) {
  const FluidBodyOperator<2> op(s);
  const std::vector<int> rows = empty_rows(s, m);
  double worst = 0.0;
  VectorX e = VectorX::Zero(s.num_fluid()), a, f, z;
  for (int k : rows) {
    e[k] = 1.0;
    op.apply(e, a);
    s.stokes_operator().apply(e, f);
    e[k] = 0.0;
    VectorX x = a - f;
    for (int j : rows) x[j] = a[j];
    m.apply(x, z);
    z[k] -= 1.0;
    worst = std::max(worst, z.cwiseAbs().maxCoeff());
  }
  return worst;
}

}  // namespace

TEST_CASE("cells closed between a light floating body and a static solid: solved exactly with the body term",
          "[coupled_preconditioner][near_empty]") {
  const double eta = GENERATE(1.0, 100.0);
  const double cut = GENERATE(0.0, 0.5);
  const int count = GENERATE(1, 3);
  INFO("eta " << eta << " cut " << cut << " cells " << count);
  std::vector<int> cells;
  const CoupledStepInput<2> in = tank_with_closed_cells(24, eta, 1e-10, count, false, false, cells);
  const MonolithicSystem<2> s = testing::make_system(in, Backend::matrix_free);
  REQUIRE(s.num_stress() > 0);
  REQUIRE(s.num_body_dofs() == kBodyDofs<2>);
  CoupledPreconditionerOptions exact, jacobi, kept;
  // a coarsest level far below the system (at this size the default one would be the finest
  // level itself, an exact V^-1, as it never is on a scene's grid)
  exact.fluid.max_coarse = jacobi.fluid.max_coarse = kept.fluid.max_coarse = 40;
  exact.fluid.cut_threshold = jacobi.fluid.cut_threshold = kept.fluid.cut_threshold = cut;
  jacobi.exact_empty_cells = false;  // section 21: r_k / (A22_kk + d_k)
  kept.empty_cell_ratio = 0.0;       // before section 21
  kept.contact_free_correction = true;  // (P4) without near-empty cells too (section 30)
  const CoupledPreconditioner<2> me(s, false, VectorX(), exact);
  const CoupledPreconditioner<2> mj(s, false, VectorX(), jacobi);
  const CoupledPreconditioner<2> mk(s, false, VectorX(), kept);
  REQUIRE(me.body_correction());
  // the closed cells (and only cells like them) are left out
  CHECK(me.fluid().empty_cells().size() == static_cast<std::size_t>(count));
  CHECK(mj.fluid().empty_cells() == me.fluid().empty_cells());
  CHECK(mk.fluid().empty_cells().empty());
  // without the floor of F_EE's diagonal, Q^-1 is A_ff on E's columns (without F's couplings of
  // E to the rest, which are of A22_kk's size)
  CoupledPreconditionerOptions unfloored = exact;
  unfloored.empty_cell_floor = 0.0;
  const CoupledPreconditioner<2> mu(s, false, VectorX(), unfloored);
  REQUIRE(mu.fluid().empty_cells() == me.fluid().empty_cells());
  const double exactness = exactness_error(s, mu);
  CHECK(exactness < 1e-6);
  const Quality qe = measure(s, me), qj = measure(s, mj), qk = measure(s, mk);
  std::printf("closed cells %d, eta %g cut %g: exact: Q X - I %.1e, asymmetry %.1e, eig(M) in [%.1e, %.1e], "
              "eig(M^-1 A) in [%.2e, %.2e], PCG %d; Jacobi: eig(M^-1 A) in [%.2e, %.2e], PCG %d (%s); kept: "
              "asymmetry %.1e, eig(M^-1 A) in [%.2e, %.2e], PCG %d (%s)\n",
              count, eta, cut, exactness, qe.asymmetry, qe.min_eig, qe.max_eig, qe.lo, qe.hi, qe.pcg_iterations,
              qj.lo, qj.hi, qj.pcg_iterations, qj.pcg_converged ? "converged" : "not converged", qk.asymmetry,
              qk.lo, qk.hi, qk.pcg_iterations, qk.pcg_converged ? "converged" : "not converged");
  // exact: symmetric to round-off, positive definite, M^-1 A bounded
  CHECK(qe.asymmetry < 1e-9);
  CHECK(qe.min_eig > 0.0);
  CHECK(qe.lo > 0.05);
  CHECK(qe.hi < 10.0);
  CHECK(qe.pcg_converged);
  CHECK(qe.pcg_iterations <= 40);
  // the Jacobi term: SPD, but blind to the mode of three cells that the body's v_y and rotation
  // cannot move (A_ff holds it at A22's scale, the Jacobi term at the body term's)
  CHECK(qj.min_eig > 0.0);
  if (count == 3) CHECK(qj.lo < 1e-4);
}

TEST_CASE("a cell closed by the body alone keeps its volume under rigid motion: not left out",
          "[coupled_preconditioner][near_empty]") {
  std::vector<int> cells;
  const CoupledStepInput<2> in = tank_with_closed_cells(24, 100.0, 1e-10, 1, true, false, cells);
  const MonolithicSystem<2> s = testing::make_system(in, Backend::matrix_free);
  CoupledPreconditionerOptions options, any;
  options.fluid.max_coarse = any.fluid.max_coarse = 40;
  any.empty_cell_body_ratio = 0.0;  // section 21's rule: every cell below 1e-4 of the median
  options.contact_free_correction = true;  // Q with (P4), as before section 30
  const CoupledPreconditioner<2> m(s, false, VectorX(), options);
  const CoupledPreconditioner<2> ma(s, false, VectorX(), any);
  CHECK(m.fluid().empty_cells().empty());
  CHECK(ma.fluid().empty_cells().size() == 1);
  const Quality q = measure(s, m);
  CHECK(q.min_eig > 0.0);
  CHECK(q.pcg_converged);
}

TEST_CASE("near-empty cells with contacts in face: M_FF^-1 of A with Q^-1 in the fluid block",
          "[coupled_preconditioner][near_empty]") {
  std::vector<int> cells;
  const CoupledStepInput<2> in = tank_with_closed_cells(16, 100.0, 1e-10, 3, false, true, cells);
  const MonolithicSystem<2> s = testing::make_system(in, Backend::matrix_free);
  const int nf = s.num_fluid(), nc = s.num_contacts(), nt = nf + nc;
  REQUIRE(nc >= 1);
  const MonolithicOperator<2> op(s, 1e-4);
  const Eigen::MatrixXd a = op.dense_matrix();
  const VectorX contact_diagonal = op.diagonal().tail(nc);
  const CoupledPreconditioner<2> m(s, true, contact_diagonal);
  REQUIRE(m.has_exact_contacts());
  REQUIRE(m.fluid().empty_cells().size() == 3);
  const CoupledPreconditioner<2> q(s, false, VectorX());
  const testing::ContactElimination ref = testing::contact_elimination(a, testing::dense(q), nf);
  CHECK((m.contact_schur() - ref.schur).norm() / ref.schur.norm() < 1e-8);
  double worst = 0.0;
  for (int pattern = 0; pattern < 2; ++pattern) {
    std::vector<char> free(nt, 1);
    if (pattern == 1) free[nf] = 0;
    worst = std::max(worst, testing::check_in_face_inverse(m, ref.m, free));
  }
  std::printf("near-empty cells with %d contacts in face: M_FF^-1 error %.1e\n", nc, worst);
}

TEST_CASE("near-empty cells: 1 and 2 threads give the same bits", "[coupled_preconditioner][near_empty]") {
  std::vector<int> cells;
  const CoupledStepInput<2> in = tank_with_closed_cells(24, 100.0, 1e-10, 3, false, true, cells);
  const MonolithicSystem<2> s = testing::make_system(in, Backend::matrix_free);
  const int nt = s.num_fluid() + s.num_contacts();
  const MonolithicOperator<2> op(s, 1e-4);
  const VectorX contact_diagonal = op.diagonal().tail(s.num_contacts());
  const VectorX r = testing::random_vector(nt, 5);
  std::vector<char> free(nt, 1);
  const int threads = omp_get_max_threads();
  VectorX z[2], y[2];
  for (int t = 0; t < 2; ++t) {
    omp_set_num_threads(t + 1);
    const CoupledPreconditioner<2> m(s, true, contact_diagonal);
    REQUIRE(m.fluid().empty_cells().size() == 3);
    m.apply(r, z[t]);
    m.apply_in_face(r, free, y[t]);
  }
  omp_set_num_threads(threads);
  CHECK((z[0] - z[1]).cwiseAbs().maxCoeff() == 0.0);
  CHECK((y[0] - y[1]).cwiseAbs().maxCoeff() == 0.0);
}
