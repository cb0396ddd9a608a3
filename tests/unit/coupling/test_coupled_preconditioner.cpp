// The block preconditioner of the coupled systems (24)/(26) (reference/coupling/
// coupled_preconditioner.hpp): SPD on small 2D and 3D cases with bodies, walls, a free surface
// and several viscosities; its body correction is the Woodbury identity; PCG on A_ff with it
// gives the dense solution and the SSOR solution; MPRGP on (26) with it preconditioning in face
// reaches the same KKT point as with SSOR (with the contact rows eliminated exactly in face and
// with the Jacobi contact rows); the exact elimination is M_FF^-1 of A with Q^-1 in the fluid
// block's place; both back ends agree; 1 and 2 threads are bitwise
// identical; solve_coupled_step with "multigrid" equals the SSOR step to tolerance (PVC-unified,
// PV-C, C-PV, PC-VC-PC-unified).
#include <omp.h>

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
#include "reference/grid/volume_fractions.hpp"
#include "reference/solvers/mprgp.hpp"
#include "reference/solvers/pcg.hpp"
#include "tests/support/body_helpers.hpp"
#include "tests/support/coupled_helpers.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using monolith::testing::make_body;

namespace {

constexpr double kRho = 1000.0;
constexpr double kDt = 0.01;

/// A coupled step in the unit tank (walls, open top): a liquid of viscosity eta below y = 0.55
/// with a random u* plus gravity; a dynamic box floating half in the liquid, a dynamic ball on
/// the floor 0.1 dx into it (contacts with the floor wall), friction mu.
template <int Dim>
CoupledStepInput<Dim> tank(int n, double eta, double mu) {
  CoupledStepInput<Dim> in{testing::unit_grid<Dim>(n), {}, kDt, {}, {}, {}, {}, {}};
  const double dx = in.grid.dx();
  ShapeSpec ball;
  ball.type = ShapeType::sphere;
  ball.radius = 0.15;
  ball.center = testing::as_std<Dim>(testing::centre_at<Dim>(0.7, 0.15 - 0.1 * dx));
  in.bodies = {testing::make_box<Dim>(testing::centre_at<Dim>(0.3, 0.55), Vec<Dim>::Constant(0.12),
                                      600.0, mu),
               make_body<Dim>(ball, 2500.0, mu)};
  for (int b = 0; b < 2; ++b) {
    BodyVec<Dim> v = BodyVec<Dim>::Zero();
    v[0] = 0.05 * (b + 1);
    v[1] = -9.81 * kDt - 0.1;
    in.bodies[b].set_generalized_velocity(v);
  }
  std::array<BoundaryType, 2 * Dim> boundary = testing::all_boundaries<Dim>(BoundaryType::wall);
  boundary[3] = BoundaryType::open;
  in.solids = solid_weights<Dim>(in.grid, coupling_bodies(in.bodies), {}, boundary, 0.01 * dx);
  testing::fill_tank_liquid(in, kRho, eta);
  in.contacts = detect_contacts<Dim>(in.bodies, testing::unit_box_walls<Dim>(mu), 0.3 * dx);
  return in;
}

template <int Dim>
void check_spd(int n, double eta) {
  INFO(Dim << "D n=" << n << " eta " << eta);
  const CoupledStepInput<Dim> in = tank<Dim>(n, eta, 0.0);
  const MonolithicSystem<Dim> s = testing::make_system(in, Backend::matrix_free);
  REQUIRE(s.num_stress() > 0);
  REQUIRE(s.num_contacts() > 0);
  REQUIRE(s.num_body_dofs() == 2 * kBodyDofs<Dim>);
  const MonolithicOperator<Dim> op(s, 1e-4);
  const VectorX contact_diagonal = op.diagonal().tail(s.num_contacts());
  CoupledPreconditionerOptions with, without;
  without.body_correction = false;
  const CoupledPreconditioner<Dim> mc(s, true, contact_diagonal, with);
  const CoupledPreconditioner<Dim> mp(s, true, contact_diagonal, without);
  REQUIRE(mc.body_correction());
  REQUIRE(!mp.body_correction());
  const Eigen::MatrixXd dc = testing::dense(mc), dp = testing::dense(mp);
  for (const Eigen::MatrixXd* d : {&dc, &dp}) {
    const double asym = (*d - d->transpose()).norm() / d->norm();
    CHECK(asym < 1e-9);
    const Eigen::MatrixXd sym = 0.5 * (*d + d->transpose());
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(sym, Eigen::EigenvaluesOnly);
    const double lo = es.eigenvalues().minCoeff(), hi = es.eigenvalues().maxCoeff();
    CHECK(lo > 0.0);
    CHECK(lo > 1e-14 * hi);
    std::printf("coupled preconditioner %dD n=%d eta %g: %d unknowns, asymmetry %.1e, eigenvalues"
                " of M^-1 in [%.2e, %.2e]\n", Dim, n, eta, mc.size(), asym, lo, hi);
  }
  // the body correction is Woodbury: (M_c)^-1 - (M_p)^-1 = dt alpha B_f^T M_r^-1 B_f on the fluid
  // rows, 0 elsewhere
  const int nf = s.num_fluid();
  const Eigen::MatrixXd diff = dc.inverse() - dp.inverse();
  Eigen::MatrixXd rigid = Eigen::MatrixXd::Zero(mc.size(), mc.size());
  const Eigen::MatrixXd mr(s.contacts().m_r_inverse);
  Eigen::MatrixXd b(s.num_body_dofs(), nf);
  for (int k = 0; k < nf; ++k) {
    VectorX e = VectorX::Zero(nf);
    e[k] = 1.0;
    b.col(k) = s.fluid_body_force(e);
  }
  REQUIRE(b.norm() > 0.0);
  rigid.topLeftCorner(nf, nf) = s.dt() * s.alpha() * b.transpose() * mr * b;
  const double werr = (diff - rigid).norm() / rigid.norm();
  CHECK(werr < 1e-6);
  std::printf("  Woodbury: ||M_c^-1 - M_p^-1 - dt alpha B^T M_r^-1 B|| / ||.|| = %.1e\n", werr);
}

/// PCG on A_ff with the block preconditioner against the dense solution and SSOR-PCG; both
/// back ends; 1 and 2 threads bitwise.
/// correction: CoupledPreconditionerOptions::contact_free_correction (false: Q = P on these
/// contact-free systems without near-empty cells, docs/preconditioners.md section 30).
template <int Dim>
void check_fluid_body_solve(int n, double eta, bool correction) {
  INFO(Dim << "D n=" << n << " eta " << eta << " body correction " << correction);
  CoupledPreconditionerOptions options;
  options.contact_free_correction = correction;
  const CoupledStepInput<Dim> in = tank<Dim>(n, eta, 0.0);
  const MonolithicSystem<Dim> e = testing::make_system(in, Backend::explicit_matrices);
  const MonolithicSystem<Dim> m = testing::make_system(in, Backend::matrix_free);
  const FluidBodyOperator<Dim> oe(e), om(m);
  const VectorX b = m.fluid_rhs(VectorX(), VectorX());
  // the dense solution (A_ff is SPD here: open top)
  const Eigen::MatrixXd a = om.dense_matrix();
  const VectorX exact = a.ldlt().solve(b);
  REQUIRE((a * exact - b).norm() <= 1e-9 * b.norm());
  PcgSettings settings;
  settings.tolerance = 1e-10;
  settings.max_iterations = 20000;
  VectorX x_ssor, x_e, x_m, x_m2;
  const PcgResult rs = pcg_solve(om, b, x_ssor, settings);
  const CoupledPreconditioner<Dim> pe(e, false, VectorX(), options), pm(m, false, VectorX(), options);
  // (P11): on without the option only where P marks near-empty cells (kept exactly with (P4))
  const bool on = correction || !pm.fluid().empty_cells().empty();
  REQUIRE(pe.fluid().empty_cells() == pm.fluid().empty_cells());
  REQUIRE(pm.body_correction() == on);
  REQUIRE(pe.body_correction() == on);
  const PcgResult re = pcg_solve(oe, b, x_e, settings, pe);
  const PcgResult rm = pcg_solve(om, b, x_m, settings, pm);
  CHECK(rs.converged);
  CHECK(re.converged);
  CHECK(rm.converged);
  const double scale = exact.cwiseAbs().maxCoeff();
  CHECK((x_m - exact).cwiseAbs().maxCoeff() <= 1e-6 * scale);
  CHECK((x_m - x_ssor).cwiseAbs().maxCoeff() <= 1e-6 * scale);
  CHECK((x_e - x_m).cwiseAbs().maxCoeff() <= 1e-8 * scale);
  CHECK(std::abs(re.iterations - rm.iterations) <= 1);
  // far fewer iterations than SSOR on the stiff cases
  if (eta >= 100.0) CHECK(4 * rm.iterations < rs.iterations);
  // the two back ends apply the same preconditioner: P's outer SOR sweeps of F run in the
  // matrix-free operator's colour order on the explicit matrix too (ExplicitStokesOperator
  // exposes its matrix; docs/preconditioners.md section 25), so M r agrees to round-off (in
  // index order the two differed by 1e-3..1e-1 relative)
  const VectorX r = testing::random_vector(m.num_fluid(), 3);
  VectorX zm, ze;
  pm.apply(r, zm);
  pe.apply(r, ze);
  REQUIRE(e.stokes_operator().explicit_matrix() != nullptr);
  REQUIRE(m.stokes_operator().explicit_matrix() == nullptr);
  const double agree = (ze - zm).cwiseAbs().maxCoeff() / zm.cwiseAbs().maxCoeff();
  CHECK(agree < 1e-9);
  // 1 vs 2 threads, matrix-free: bitwise
  const int threads = omp_get_max_threads();
  omp_set_num_threads(2);
  const CoupledPreconditioner<Dim> pm2(m, false, VectorX(), options);
  VectorX zm2;
  pm2.apply(r, zm2);
  const PcgResult rm2 = pcg_solve(om, b, x_m2, settings, pm2);
  omp_set_num_threads(threads);
  CHECK((zm2 - zm).cwiseAbs().maxCoeff() == 0.0);
  CHECK((x_m2 - x_m).cwiseAbs().maxCoeff() == 0.0);
  CHECK(rm2.iterations == rm.iterations);
  std::printf("A_ff solve %dD n=%d eta %g, body correction %s (%d near-empty cells): %d unknowns, SSOR %d"
              " iterations, block %d (explicit %d), error vs dense %.1e, back ends' M r apart %.1e\n", Dim,
              n, eta, on ? "on" : "off", static_cast<int>(pm.fluid().empty_cells().size()), m.num_fluid(),
              rs.iterations, rm.iterations, re.iterations, (x_m - exact).cwiseAbs().maxCoeff() / scale,
              agree);
}

/// KKT conditions of the MLCP (26) (no friction) at x = (tau, p, lambda) for the dense A (boost
/// included) and b: fluid rows A x = b, lambda >= 0, w = A x - b >= 0 on the contact rows,
/// lambda_i w_i = 0. Returns the largest violation relative to ||b||_inf.
double kkt_violation(const Eigen::MatrixXd& a, const VectorX& b, const VectorX& x, int nf) {
  const VectorX w = a * x - b;
  const double scale = b.cwiseAbs().maxCoeff();
  double worst = w.head(nf).cwiseAbs().maxCoeff();
  for (int i = nf; i < x.size(); ++i) {
    worst = std::max(worst, -x[i] * std::sqrt(a(i, i)));
    worst = std::max(worst, -w[i]);
    worst = std::max(worst, std::min(std::abs(w[i]), x[i] * std::sqrt(a(i, i))));
  }
  return worst / scale;
}

template <int Dim>
void check_mprgp(int n, double eta) {
  INFO(Dim << "D n=" << n << " eta " << eta);
  const CoupledStepInput<Dim> in = tank<Dim>(n, eta, 0.0);
  double worst_diff = 0.0;
  for (Backend backend : {Backend::explicit_matrices, Backend::matrix_free}) {
    const MonolithicSystem<Dim> s = testing::make_system(in, backend);
    REQUIRE(s.num_contacts() > 0);
    StaggeredSettings settings;
    settings.mprgp.tolerance = 1e-9;
    settings.mprgp.max_iterations = 50000;
    PvcUnifiedOptions ssor, block, jacobi;
    ssor.jacobi_scaling = block.jacobi_scaling = jacobi.jacobi_scaling = true;
    block.preconditioner = jacobi.preconditioner = PreconditionerKind::multigrid;
    jacobi.exact_contacts = false;
    const PvcUnifiedResult rs = solve_pvc_unified(s, settings, ssor);
    const PvcUnifiedResult rb = solve_pvc_unified(s, settings, block);
    const PvcUnifiedResult rj = solve_pvc_unified(s, settings, jacobi);
    CHECK(rj.converged);
    CHECK((rj.x - rs.x).cwiseAbs().maxCoeff() < 1e-5 * rs.x.cwiseAbs().maxCoeff());
    CHECK(rs.converged);
    CHECK(rb.converged);
    CHECK(!rb.breakdown);
    const MonolithicOperator<Dim> op(s, settings.diagonal_boost);
    const Eigen::MatrixXd a = op.dense_matrix();
    const VectorX b = s.mlcp_rhs(VectorX::Zero(s.num_friction()));
    const double kkt_s = kkt_violation(a, b, rs.x, s.num_fluid());
    const double kkt_b = kkt_violation(a, b, rb.x, s.num_fluid());
    CHECK(kkt_b < 1e-6);
    CHECK(kkt_s < 1e-6);
    // the QP is strictly convex (A SPD with the boost): one KKT point
    const double diff = (rb.x - rs.x).cwiseAbs().maxCoeff() / rs.x.cwiseAbs().maxCoeff();
    CHECK(diff < 1e-5);
    worst_diff = std::max(worst_diff, diff);
    // some contact is active and some force positive (the case tests the bounds)
    CHECK(rb.lambda.maxCoeff() > 0.0);
    if (eta >= 100.0) CHECK(2 * rb.mprgp_iterations < rs.mprgp_iterations);
    std::printf("MPRGP (26) %dD n=%d eta %g %s: %d unknowns, %d contacts, SSOR %ld iterations, "
                "block %ld (Jacobi contact rows %ld); KKT violation %.1e / %.1e\n", Dim, n, eta,
                enum_name(backend).c_str(), op.size(), s.num_contacts(), rs.mprgp_iterations,
                rb.mprgp_iterations, rj.mprgp_iterations, kkt_s, kkt_b);
  }
  std::printf("  largest relative difference block vs SSOR %.1e\n", worst_diff);
}

/// The exact contact elimination in face (CoupledPreconditioner::apply_in_face): S_c is the
/// Schur complement A33' - A_3f Q A_f3 of M = [Q^-1 A_f3; A_3f A33'] (Q the fluid-body block's
/// preconditioner, densely), apply_in_face equals M_FF^-1 on free sets with some contacts
/// active, the map is SPD on the face, and 1 and 2 threads give the same bits.
template <int Dim>
void check_exact_contacts(int n, double eta) {
  INFO(Dim << "D n=" << n << " eta " << eta);
  const CoupledStepInput<Dim> in = tank<Dim>(n, eta, 0.0);
  const MonolithicSystem<Dim> s = testing::make_system(in, Backend::matrix_free);
  const int nf = s.num_fluid(), nc = s.num_contacts(), nt = nf + nc;
  REQUIRE(nc >= 1);
  const MonolithicOperator<Dim> op(s, 1e-4);
  const Eigen::MatrixXd a = op.dense_matrix();
  const VectorX contact_diagonal = op.diagonal().tail(nc);
  const CoupledPreconditioner<Dim> m(s, true, contact_diagonal);
  REQUIRE(m.body_correction());
  REQUIRE(m.has_exact_contacts());
  // M = A with Q^-1 in the fluid block's place (Q with the body correction, which a contact-free
  // system without near-empty cells leaves out by default: section 30)
  CoupledPreconditionerOptions with_correction;
  with_correction.contact_free_correction = true;
  const CoupledPreconditioner<Dim> q(s, false, VectorX(), with_correction);
  REQUIRE(q.body_correction());
  const testing::ContactElimination ref = testing::contact_elimination(a, testing::dense(q), nf);
  const double serr = (m.contact_schur() - ref.schur).norm() / ref.schur.norm();
  CHECK(serr < 1e-8);
  // free sets: every contact, none, every other one (the same as none with one contact)
  double worst = 0.0;
  for (int pattern = 0; pattern < 3; ++pattern) {
    std::vector<char> free(nt, 1);
    for (int i = 0; i < nc; ++i)
      free[nf + i] = pattern == 0 ? 1 : pattern == 1 ? 0 : static_cast<char>(i % 2);
    worst = std::max(worst, testing::check_in_face_inverse(m, ref.m, free));
  }
  // 1 vs 2 threads: bitwise
  std::vector<char> free(nt, 1);
  free[nf] = 0;
  const VectorX r = testing::random_vector(nt, 5);
  VectorX z1, z2;
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const CoupledPreconditioner<Dim> m1(s, true, contact_diagonal);
  m1.apply_in_face(r, free, z1);
  omp_set_num_threads(2);
  const CoupledPreconditioner<Dim> m2(s, true, contact_diagonal);
  m2.apply_in_face(r, free, z2);
  omp_set_num_threads(threads);
  CHECK((z1 - z2).cwiseAbs().maxCoeff() == 0.0);
  std::printf("exact contacts %dD n=%d eta %g: %d fluid rows, %d contacts, S_c error %.1e, "
              "M_FF^-1 error %.1e\n", Dim, n, eta, nf, nc, serr, worst);
}

}  // namespace

TEST_CASE("the contact rows eliminated exactly in face: M_FF^-1 of A with Q^-1 in the fluid block", "[coupled_preconditioner]") {
  for (double eta : {0.1, 1000.0}) check_exact_contacts<2>(10, eta);
  check_exact_contacts<3>(6, 1000.0);
}

TEST_CASE("the coupled block preconditioner is SPD and its body correction is Woodbury", "[coupled_preconditioner]") {
  for (double eta : {0.1, 10.0, 1000.0}) check_spd<2>(10, eta);
  check_spd<3>(6, 1000.0);
}

TEST_CASE("PCG on A_ff with the coupled block preconditioner: dense and SSOR solution, back ends, threads", "[coupled_preconditioner]") {
  for (bool correction : {false, true}) {
    for (double eta : {1.0, 1000.0}) check_fluid_body_solve<2>(24, eta, correction);
    check_fluid_body_solve<3>(8, 500.0, correction);
  }
}

TEST_CASE("MPRGP on (26) preconditioned in face by the coupled block preconditioner: the KKT point of SSOR", "[coupled_preconditioner]") {
  for (double eta : {1.0, 1000.0}) check_mprgp<2>(16, eta);
  check_mprgp<3>(8, 500.0);
}

TEST_CASE("solve_coupled_step with the coupled block preconditioner equals the SSOR step", "[coupled_preconditioner]") {
  auto run = [](auto dim_tag, int n) {
    constexpr int Dim = decltype(dim_tag)::value;
    const CoupledStepInput<Dim> in = tank<Dim>(n, 500.0, 0.3);
    StaggeredSettings settings;
    settings.max_iterations = 20;
    settings.tolerance = 1e-8;
    settings.mprgp.tolerance = 1e-9;
    settings.mprgp.max_iterations = 50000;
    for (CouplingScheme scheme : {CouplingScheme::pvc_unified, CouplingScheme::pv_c,
                                  CouplingScheme::pc_vc_pc_unified, CouplingScheme::c_pv}) {
      INFO(Dim << "D " << enum_name(scheme));
      CoupledSchemeOptions ssor, block;
      block.preconditioner = PreconditionerChoice::multigrid;
      const CoupledSolveResult rs = solve_coupled_step<Dim>(in, scheme, Backend::matrix_free, settings, ssor);
      const CoupledSolveResult rb = solve_coupled_step<Dim>(in, scheme, Backend::matrix_free, settings, block);
      CHECK(rs.converged);
      CHECK(rb.converged);
      CHECK(rb.multigrid_systems >= 1);
      CHECK(rb.ssor_systems == 0);
      CHECK(rs.multigrid_systems == 0);
      const double du = (rb.u - rs.u).cwiseAbs().maxCoeff() / rs.u.cwiseAbs().maxCoeff();
      const double dv = (rb.body_velocity - rs.body_velocity).cwiseAbs().maxCoeff() /
                        rs.body_velocity.cwiseAbs().maxCoeff();
      CHECK(du < 1e-5);
      CHECK(dv < 1e-5);
      // 1 vs 2 threads: bitwise
      const int threads = omp_get_max_threads();
      omp_set_num_threads(1);
      const CoupledSolveResult r1 = solve_coupled_step<Dim>(in, scheme, Backend::matrix_free, settings, block);
      omp_set_num_threads(2);
      const CoupledSolveResult r2 = solve_coupled_step<Dim>(in, scheme, Backend::matrix_free, settings, block);
      omp_set_num_threads(threads);
      CHECK((r1.u - r2.u).cwiseAbs().maxCoeff() == 0.0);
      CHECK((r1.body_velocity - r2.body_velocity).cwiseAbs().maxCoeff() == 0.0);
      CHECK((r1.lambda - r2.lambda).cwiseAbs().maxCoeff() == 0.0);
      std::printf("step %dD %s: iterations SSOR %ld, block %ld; relative difference u %.1e, v %.1e\n",
                  Dim, enum_name(scheme).c_str(), rs.fluid_iterations + rs.coupled_iterations + rs.contact_iterations,
                  rb.fluid_iterations + rb.coupled_iterations + rb.contact_iterations, du, dv);
    }
  };
  run(std::integral_constant<int, 2>{}, 16);
  run(std::integral_constant<int, 3>{}, 8);
}
