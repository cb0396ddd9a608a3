// The variational pressure system of eq. (8) (A22 and b2 of eq. (24)): both back ends, SPD-ness,
// the CHOLMOD oracle, the velocity update and enclosed liquids.
#include <omp.h>

#include <Eigen/Dense>
#include <catch2/catch.hpp>
#include <random>

#include "reference/core/parallel.hpp"
#include "reference/fluid/pressure_projection.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/oracle/cholmod_solver.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using namespace monolith::testing;

namespace {

/// A small scene: unit box of n^Dim cells, walls (top open unless `enclosed`), a solid ball,
/// liquid below y = 0.55 (everywhere if `enclosed`), density varying along x.
template <int Dim>
struct Setup {
  MacGrid<Dim> grid;
  PressureWeights w;
  VectorX u_star;
  double dt = 0.01;

  Setup(int n, bool enclosed, bool periodic_x = false) {
    std::array<bool, Dim> periodic{};
    periodic[0] = periodic_x;
    grid = MacGrid<Dim>(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), periodic);
    const auto lattice = half_lattice(grid);
    std::array<BoundaryType, 2 * Dim> boundary;
    boundary.fill(BoundaryType::wall);
    if (periodic_x) boundary[0] = boundary[1] = BoundaryType::periodic;
    if (!enclosed) boundary[3] = BoundaryType::open;
    std::vector<ShapePtr<Dim>> solids{
        std::make_shared<TestBall<Dim>>(Vec<Dim>::Constant(0.3) + Vec<Dim>::Unit(0) * 0.31, 0.17)};
    const VectorX solid_phi = solid_phi_on_lattice(grid, lattice, solids, 0.01 * grid.dx());
    w.fluid_face = fluid_face_weights(grid, lattice, solid_phi, boundary);
    VectorX liquid_phi(lattice.size());
    for (int k = 0; k < lattice.size(); ++k)
      liquid_phi[k] = enclosed ? -1.0 : lattice.position(lattice.coord(k))[1] - 0.55;
    w.liquid_cell = liquid_cell_weights(grid, lattice, liquid_phi);
    w.liquid_face = liquid_face_weights(grid, lattice, liquid_phi, w.liquid_cell);
    // densities only where liquid reaches the face (as P2G would give), the rest filled
    VectorX rho = VectorX::Zero(grid.num_faces());
    for (int f = 0; f < grid.num_faces(); ++f) {
      const auto [axis, coord] = grid.face_coord(f);
      if (w.liquid_face[f] > 0.05) rho[f] = 1000.0 + 300.0 * grid.face_center(axis, coord)[0];
    }
    w.face_density = density_diagonal(grid, rho, 1000.0);
    u_star = random_vector(grid.num_faces(), 5);
  }
};

double relative(const VectorX& a, const VectorX& b) {
  return (a - b).norm() / b.norm();
}

}  // namespace

TEMPLATE_TEST_CASE_SIG(
    "A of eq. (8) is symmetric positive definite with a free surface and a solid",
    "[property][dense-reference]", ((int Dim), Dim), 2, 3) {
  const Setup<Dim> s(Dim == 2 ? 8 : 4, false);
  const PressureDofs dofs = select_pressure_dofs(s.grid, s.w, s.dt);
  REQUIRE(dofs.size() > 0);
  REQUIRE(dofs.null_space.empty());
  const ExplicitPressureSystem sys = assemble_explicit_pressure(s.grid, s.w, dofs, s.dt, s.u_star);
  REQUIRE(sys.A.rows() == dofs.size());
  REQUIRE(sys.G.rows() == s.grid.num_faces());
  REQUIRE(sys.G.cols() == s.grid.num_cells());
  const Eigen::MatrixXd a = Eigen::MatrixXd(sys.A);
  CHECK((a - a.transpose()).norm() <= 1e-14 * a.norm());
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(a);
  const double lo = eig.eigenvalues().minCoeff(), hi = eig.eigenvalues().maxCoeff();
  INFO("dofs " << dofs.size() << " eigenvalues in [" << lo << ", " << hi << "]");
  CHECK(lo > 1e-10 * hi);
}

TEMPLATE_TEST_CASE_SIG("explicit and matrix-free back ends give the same A x, diagonal and b",
                       "[property]", ((int Dim), Dim), 2, 3) {
  for (bool enclosed : {false, true}) {
    const Setup<Dim> s(Dim == 2 ? 16 : 8, enclosed);
    const PressureDofs dofs = select_pressure_dofs(s.grid, s.w, s.dt);
    const ExplicitPressureSystem sys =
        assemble_explicit_pressure(s.grid, s.w, dofs, s.dt, s.u_star);
    const MatrixFreePressureOperator<Dim> mf(s.grid, s.w, dofs, s.dt);
    REQUIRE(mf.size() == dofs.size());
    for (unsigned seed = 0; seed < 3; ++seed) {
      const VectorX x = random_vector(dofs.size(), 40 + seed);
      VectorX y;
      mf.apply(x, y);
      const VectorX y_explicit = sys.A * x;
      REQUIRE(relative(y, y_explicit) <= 1e-12);
    }
    CHECK(relative(mf.diagonal(), VectorX(sys.A.diagonal())) <= 1e-12);
    CHECK(relative(mf.rhs(s.u_star), sys.b) <= 1e-12);
  }
}

TEMPLATE_TEST_CASE_SIG("SSOR-PCG agrees with CHOLMOD on both back ends", "[dense-reference]",
                       ((int Dim), Dim), 2, 3) {
  const Setup<Dim> s(Dim == 2 ? 24 : 10, false);
  const PressureDofs dofs = select_pressure_dofs(s.grid, s.w, s.dt);
  const ExplicitPressureSystem sys = assemble_explicit_pressure(s.grid, s.w, dofs, s.dt, s.u_star);
  const VectorX exact = cholmod_solve(sys.A, sys.b);
  CHECK(relative(sys.A * exact, sys.b) <= 1e-10);
  PcgSettings settings;
  settings.tolerance = 1e-12;
  VectorX p_explicit, p_matrixfree;
  const SparseMatrixOperator op(sys.A);
  const PcgResult r1 = pcg_solve(op, sys.b, p_explicit, settings);
  const MatrixFreePressureOperator<Dim> mf(s.grid, s.w, dofs, s.dt);
  const PcgResult r2 = pcg_solve(mf, mf.rhs(s.u_star), p_matrixfree, settings);
  INFO("dofs " << dofs.size() << " iterations explicit " << r1.iterations << " matrix-free "
               << r2.iterations);
  REQUIRE(r1.converged);
  REQUIRE(r2.converged);
  CHECK(relative(p_explicit, exact) <= 1e-8);
  CHECK(relative(p_matrixfree, exact) <= 1e-8);
  CHECK(relative(p_matrixfree, p_explicit) <= 1e-8);
}

TEMPLATE_TEST_CASE_SIG("the velocity update makes u weighted-divergence free", "[property]",
                       ((int Dim), Dim), 2, 3) {
  for (const Backend backend : {Backend::explicit_matrices, Backend::matrix_free}) {
    const Setup<Dim> s(Dim == 2 ? 16 : 8, false);
    PcgSettings settings;
    settings.tolerance = 1e-10;
    VectorX u = s.u_star;
    const PressureSolveResult result = solve_pressure(s.grid, s.w, s.dt, backend, settings, u);
    REQUIRE(result.pcg.converged);
    // b(u) = W_L^p G^T W_F^u u on the DOFs is the residual b - A p: near zero after the update
    const PressureDofs dofs = select_pressure_dofs(s.grid, s.w, s.dt);
    const MatrixFreePressureOperator<Dim> mf(s.grid, s.w, dofs, s.dt);
    const double before = mf.rhs(s.u_star).template lpNorm<Eigen::Infinity>();
    const double after = mf.rhs(u).template lpNorm<Eigen::Infinity>();
    INFO(enum_name(backend) << ": divergence before " << before << " after " << after);
    CHECK(after <= 1e-9 * before);
    // faces outside the fluid are untouched
    for (int f = 0; f < s.grid.num_faces(); ++f)
      if (s.w.fluid_face[f] == 0.0) REQUIRE(u[f] == s.u_star[f]);
  }
}

TEMPLATE_TEST_CASE_SIG("enclosed and periodic liquid: null space detected, PCG converges",
                       "[property]", ((int Dim), Dim), 2, 3) {
  // (odd cell counts on a periodic axis break the red-black colouring: sweeps then run serially)
  for (int variant = 0; variant < 3; ++variant) {
    const bool periodic = variant > 0;
    const int n = (Dim == 2 ? 16 : 8) + (variant == 2 ? 1 : 0);
    const Setup<Dim> s(n, true, periodic);
    const PressureDofs dofs = select_pressure_dofs(s.grid, s.w, s.dt);
    REQUIRE(dofs.null_space.size() == 1);
    // the null vector really is one: A n = 0
    const MatrixFreePressureOperator<Dim> mf(s.grid, s.w, dofs, s.dt);
    VectorX an;
    mf.apply(dofs.null_space[0], an);
    const VectorX x = random_vector(dofs.size(), 3);
    VectorX ax;
    mf.apply(x, ax);
    CHECK(an.norm() <= 1e-12 * ax.norm());
    // the SSOR preconditioner of the matrix-free operator is symmetric, odd periodic axes too
    const VectorX s1 = random_vector(dofs.size(), 8), s2 = random_vector(dofs.size(), 9);
    VectorX z1, z2;
    ssor_precondition(mf, s1, z1, 1.0);
    ssor_precondition(mf, s2, z2, 1.0);
    CHECK(z1.dot(s2) == Approx(s1.dot(z2)).epsilon(1e-10));
    PcgSettings settings;
    settings.tolerance = 1e-10;
    VectorX u_explicit = s.u_star, u_matrixfree = s.u_star;
    const auto r1 = solve_pressure(s.grid, s.w, s.dt, Backend::explicit_matrices, settings, u_explicit);
    const auto r2 = solve_pressure(s.grid, s.w, s.dt, Backend::matrix_free, settings, u_matrixfree);
    INFO("periodic " << periodic << " n " << n << " iterations " << r1.pcg.iterations << " / "
                     << r2.pcg.iterations);
    REQUIRE(r1.pcg.converged);
    REQUIRE(r2.pcg.converged);
    CHECK(relative(u_matrixfree, u_explicit) <= 1e-8);
    CHECK(mf.rhs(u_explicit).template lpNorm<Eigen::Infinity>() <=
          1e-8 * mf.rhs(s.u_star).template lpNorm<Eigen::Infinity>());
  }
}

namespace {

/// psi = cos(pi x) [cos(pi z)] sin(pi (h - y) / (2 h)): zero normal derivative on the walls and
/// the floor, zero on the free surface y = h.
template <int Dim>
double psi(const Vec<Dim>& x, double h) {
  double v = std::cos(M_PI * x[0]) * std::sin(M_PI * (h - x[1]) / (2.0 * h));
  if constexpr (Dim == 3) v *= std::cos(M_PI * x[2]);
  return v;
}

template <int Dim>
Vec<Dim> grad_psi(const Vec<Dim>& x, double h) {
  const double k = M_PI / (2.0 * h);
  const double cx = std::cos(M_PI * x[0]), sx = std::sin(M_PI * x[0]);
  const double sy = std::sin(k * (h - x[1])), cy = std::cos(k * (h - x[1]));
  double cz = 1.0, sz = 0.0;
  if constexpr (Dim == 3) {
    cz = std::cos(M_PI * x[2]);
    sz = std::sin(M_PI * x[2]);
  }
  Vec<Dim> g;
  g[0] = -M_PI * sx * sy * cz;
  g[1] = -k * cx * cy * cz;
  if constexpr (Dim == 3) g[2] = -M_PI * cx * sy * sz;
  return g;
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("projection of a gradient field converges to the analytic pressure",
                       "[convergence]", ((int Dim), Dim), 2, 3) {
  // u* = grad psi with psi = 0 on the free surface y = h and d psi / dn = 0 on the walls: the
  // projection removes all of u*, so p = rho psi / dt exactly in the continuum
  const double h = 0.6 + 0.013, rho = 1000.0, dt = 0.01;
  const std::vector<int> levels =
      Dim == 2 ? std::vector<int>{16, 32, 64} : std::vector<int>{8, 16, 32};
  std::vector<double> errors, velocity;
  for (int n : levels) {
    const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), {});
    std::array<BoundaryType, 2 * Dim> boundary;
    boundary.fill(BoundaryType::wall);
    const PressureWeights w = flat_surface_weights<Dim>(grid, boundary, h, rho);
    VectorX u(grid.num_faces());
    for (int f = 0; f < grid.num_faces(); ++f) {
      const auto [axis, coord] = grid.face_coord(f);
      u[f] = grad_psi<Dim>(grid.face_center(axis, coord), h)[axis];
    }
    PcgSettings settings;
    settings.tolerance = 1e-12;
    const PressureSolveResult r = solve_pressure(grid, w, dt, Backend::matrix_free, settings, u);
    REQUIRE(r.pcg.converged);
    double err = 0.0, u_max = 0.0;
    for (int c = 0; c < grid.num_cells(); ++c) {
      if (w.liquid_cell[c] < 1.0) continue;
      const double exact = rho * psi<Dim>(grid.cell_center(grid.cell_coord(c)), h) / dt;
      err = std::max(err, std::abs(r.pressure[c] - exact) * dt / rho);
    }
    for (int f = 0; f < grid.num_faces(); ++f)
      if (w.fluid_face[f] > 0.0 && w.liquid_face[f] >= 0.5) u_max = std::max(u_max, std::abs(u[f]));
    errors.push_back(err);
    velocity.push_back(u_max);
  }
  const double order = std::log2(errors[1] / errors[2]);
  INFO("pressure errors (max over full cells, relative to max psi = 1) "
       << errors[0] << " " << errors[1] << " " << errors[2] << ", order " << order
       << "; residual velocity " << velocity[0] << " " << velocity[1] << " " << velocity[2]);
  CHECK(errors[2] < errors[1]);
  CHECK(order > 1.7);
  CHECK(errors[2] < 1e-3);
}

TEMPLATE_TEST_CASE_SIG(
    "density_diagonal_in_place over ~1e5 faces (the faces near a ball of densities found and "
    "sorted on several threads): identical with 1, 2, 3 and 5 threads",
    "[density]", ((int Dim), Dim), 2, 3) {
  const int n = Dim == 2 ? 200 : 40;
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  std::mt19937 rng(5 + Dim);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  // densities on most faces inside a ball (its surface's faces without one: the near list)
  VectorX rho = VectorX::Zero(grid.num_faces());
  std::array<VecI<Dim>, Dim> lo, hi;
  for (int a = 0; a < Dim; ++a) {
    lo[a] = grid.face_dims(a);
    hi[a] = -VecI<Dim>::Ones();
  }
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    if ((grid.face_center(axis, coord) - Vec<Dim>::Constant(0.5)).norm() < 0.35 && u(rng) < 0.9) {
      rho[f] = 500.0 + 1000.0 * u(rng);
      lo[axis] = lo[axis].cwiseMin(coord);
      hi[axis] = hi[axis].cwiseMax(coord);
    }
  }
  long box_faces = 0;
  for (int a = 0; a < Dim; ++a) box_faces += (hi[a] - lo[a] + VecI<Dim>::Ones()).prod();
  REQUIRE(box_faces > kParallelMinWork);
  // the team exactly t threads (the core monitor would take fewer on a busy machine)
  const bool monitor = core_monitor();
  set_core_monitor(false);
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  VectorX one = rho, one_boxed = rho;
  density_diagonal_in_place(grid, one, 777.0);
  density_diagonal_in_place<Dim>(grid, one_boxed, 777.0, lo, hi);
  CHECK(differing(one_boxed, one) == 0);
  for (int t : {2, 3, 5}) {
    INFO(t << " threads");
    omp_set_num_threads(t);
    VectorX other = rho, other_boxed = rho;
    density_diagonal_in_place(grid, other, 777.0);
    density_diagonal_in_place<Dim>(grid, other_boxed, 777.0, lo, hi);
    omp_set_num_threads(threads);
    CHECK(differing(other, one) == 0);
    CHECK(differing(other_boxed, one) == 0);
  }
  set_core_monitor(monitor);
}

TEMPLATE_TEST_CASE_SIG(
    "density_diagonal: a face without a density gets the mean of its cells' faces that have one, "
    "else the fallback (the band pass equals every face's own mean bit for bit)",
    "[density]", ((int Dim), Dim), 2, 3) {
  for (const bool periodic_x : {false, true}) {
    std::array<bool, Dim> periodic{};
    periodic[0] = periodic_x;
    const int n = Dim == 2 ? 13 : 7;
    const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), periodic);
    // a few faces with a density (some at the box's ends and seam), zeros and negatives elsewhere
    std::mt19937 rng(11 + Dim);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    VectorX rho = VectorX::Zero(grid.num_faces());
    for (int f = 0; f < grid.num_faces(); ++f) {
      const double r = u(rng);
      if (r < 0.08) rho[f] = 500.0 + 1000.0 * u(rng);
      else if (r < 0.1) rho[f] = -1.0;
    }
    rho[0] = 900.0;
    rho[grid.num_faces() - 1] = 1100.0;
    const double fallback = 777.0;
    const VectorX got = density_diagonal(grid, rho, fallback);
    REQUIRE(got.size() == grid.num_faces());
    int means = 0, fallbacks = 0;
    for (int f = 0; f < grid.num_faces(); ++f) {
      if (rho[f] > 0.0) {
        CHECK(got[f] == rho[f]);
        continue;
      }
      // every face's own mean over the faces of the cells on either side
      const auto [axis, coord] = grid.face_coord(f);
      double sum = 0.0;
      int count = 0;
      for (int cell : {grid.face_cell_minus(axis, coord), grid.face_cell_plus(axis, coord)}) {
        if (cell < 0) continue;
        const VecI<Dim> c = grid.cell_coord(cell);
        for (int a = 0; a < Dim; ++a) {
          VecI<Dim> upper = c;
          upper[a] += 1;
          for (int g : {grid.face_index(a, c),
                        grid.face_index(a, grid.periodic(a) ? grid.wrap_cell(upper) : upper)})
            if (rho[g] > 0.0) {
              sum += rho[g];
              ++count;
            }
        }
      }
      const double want = count > 0 ? sum / count : fallback;
      (count > 0 ? means : fallbacks) += 1;
      CHECK(got[f] == want);
    }
    CHECK(means > 0);
    CHECK(fallbacks > 0);
    // in place (the simulator's P over the faces' densities): the same values
    VectorX in_place = rho;
    density_diagonal_in_place(grid, in_place, fallback);
    REQUIRE(in_place.size() == got.size());
    for (int f = 0; f < grid.num_faces(); ++f) CHECK(in_place[f] == got[f]);
    // with boxes that hold every face with a density (issue 20: particles_to_grid's faces) the
    // same bits: densities only in a box of each axis's face lattice (one at the seam of a
    // periodic x, one at the upper end), the whole lattice and those boxes as the given boxes;
    // boxes that leave out one face with a density give other values
    VectorX boxed_rho = VectorX::Zero(grid.num_faces());
    std::array<VecI<Dim>, Dim> lo, hi, all_lo, all_hi;
    for (int a = 0; a < Dim; ++a) {
      const VecI<Dim> fdims = grid.face_dims(a);
      all_lo[a] = VecI<Dim>::Zero();
      all_hi[a] = fdims - VecI<Dim>::Ones();
      lo[a] = VecI<Dim>::Constant(a == 0 ? 0 : 2);
      hi[a] = (fdims - VecI<Dim>::Ones()).cwiseMin(lo[a] + VecI<Dim>::Constant(a == 1 ? 20 : 3));
    }
    for (int f = 0; f < grid.num_faces(); ++f) {
      const auto [axis, coord] = grid.face_coord(f);
      const bool in = !((coord.array() < lo[axis].array()).any() || (coord.array() > hi[axis].array()).any());
      if (in && rho[f] != 0.0) boxed_rho[f] = rho[f];
    }
    const int top_density = grid.face_index(0, hi[0]);  // the box's far corner has a density
    boxed_rho[top_density] = 950.0;
    VectorX dense = boxed_rho;
    density_diagonal_in_place(grid, dense, fallback);
    for (const bool whole : {false, true}) {
      VectorX boxed = boxed_rho;
      density_diagonal_in_place<Dim>(grid, boxed, fallback, whole ? all_lo : lo, whole ? all_hi : hi);
      CHECK(monolith::testing::differing(boxed, dense) == 0);
    }
    // a box one layer short along the last axis of axis 0's lattice misses a face with a density
    std::array<VecI<Dim>, Dim> short_hi = hi;
    short_hi[0][Dim - 1] -= 1;
    VectorX single = VectorX::Zero(grid.num_faces());
    single[top_density] = boxed_rho[top_density];
    VectorX single_dense = single, missed = single;
    density_diagonal_in_place(grid, single_dense, fallback);
    density_diagonal_in_place<Dim>(grid, missed, fallback, lo, short_hi);
    CHECK(monolith::testing::differing(missed, single_dense) > 0);
  }
}

TEMPLATE_TEST_CASE_SIG("a divergence source: the new velocity's weighted divergence is the target",
                       "[property]", ((int Dim), Dim), 2, 3) {
  // solve_pressure's divergence_source d: W_L^p G^T W_F^u u = -W_L^p d on the DOFs after the
  // update (the volume correction through the solve, docs/particles.md); without it 0
  for (const Backend backend : {Backend::explicit_matrices, Backend::matrix_free})
    for (const PreconditionerKind pre : {PreconditionerKind::ssor, PreconditionerKind::multigrid}) {
      const Setup<Dim> s(Dim == 2 ? 16 : 8, false);
      PcgSettings settings;
      settings.tolerance = 1e-11;
      const VectorX d = 10.0 * random_vector(s.grid.num_cells(), 11);
      VectorX u = s.u_star;
      const PressureSolveResult result =
          solve_pressure(s.grid, s.w, s.dt, backend, settings, u, pre, &d);
      REQUIRE(result.pcg.converged);
      const PressureDofs dofs = select_pressure_dofs(s.grid, s.w, s.dt);
      REQUIRE(dofs.size() > 0);
      const MatrixFreePressureOperator<Dim> mf(s.grid, s.w, dofs, s.dt);
      const VectorX b = mf.rhs(u);
      double worst = 0.0, scale = 0.0;
      for (int k = 0; k < dofs.size(); ++k) {
        const int c = dofs.cell_of_dof[k];
        worst = std::max(worst, std::abs(b[k] + s.w.liquid_cell[c] * d[c]));
        scale = std::max(scale, std::abs(s.w.liquid_cell[c] * d[c]));
      }
      INFO(enum_name(backend) << ", " << enum_name(pre) << ": largest |b(u) + W d| " << worst
                              << " of " << scale);
      CHECK(worst <= 1e-8 * scale);
      // a null or empty source is no source: the same velocity bit for bit
      VectorX u_none = s.u_star, u_empty = s.u_star;
      const VectorX empty;
      solve_pressure(s.grid, s.w, s.dt, backend, settings, u_none, pre);
      solve_pressure(s.grid, s.w, s.dt, backend, settings, u_empty, pre, &empty);
      CHECK((u_none - u_empty).cwiseAbs().maxCoeff() == 0.0);
    }
}

TEMPLATE_TEST_CASE_SIG("a liquid in free fall: its pressure solve takes no iteration on either back end",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // docs/preconditioners.md section 35, (P16): a ball of liquid away from every wall, u* uniform
  // up to two ulps per face (the particle transfer's round-off). b = W_L^p G^T W_F^u u* is zero
  // in exact arithmetic; the relative stopping rule solved its round-off to 1e-6 of itself. At or
  // below liquid_rhs_round_off it is zero: p = 0 without an iteration, u* kept bit for bit.
  const int n = Dim == 2 ? 24 : 12;
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), std::array<bool, Dim>{});
  const SampleLattice<Dim> lattice = half_lattice(grid);
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  const VectorX solid_phi = solid_phi_on_lattice<Dim>(grid, lattice, {}, 0.0);
  auto weights = [&](auto&& phi) {
    VectorX liquid_phi(lattice.size());
    for (int k = 0; k < lattice.size(); ++k) liquid_phi[k] = phi(lattice.position(lattice.coord(k)));
    PressureWeights w;
    w.fluid_face = fluid_face_weights(grid, lattice, solid_phi, boundary);
    w.liquid_cell = liquid_cell_weights(grid, lattice, liquid_phi);
    w.liquid_face = liquid_face_weights(grid, lattice, liquid_phi, w.liquid_cell);
    VectorX rho = VectorX::Zero(grid.num_faces());
    for (int f = 0; f < grid.num_faces(); ++f)
      if (w.liquid_face[f] > 0.05) rho[f] = 1000.0;
    w.face_density = density_diagonal(grid, rho, 1000.0);
    return w;
  };
  const PressureWeights ball =
      weights([](const Vec<Dim>& x) { return (x - Vec<Dim>::Constant(0.5)).norm() - 0.3; });
  const double dt = 0.01;
  // u*: (1.5, -0.7981[, 0.3]) m/s, each face moved by -2..2 ulps
  const Vec<Dim> common = Vec<3>(1.5, -0.7981, 0.3).head<Dim>();
  const VectorX flight = uniform_face_velocity_with_ulps<Dim>(grid, common, 11);
  const double level = liquid_rhs_round_off(grid, ball.fluid_face, flight, nullptr);
  const PressureDofs dofs = select_pressure_dofs(grid, ball, dt);
  REQUIRE(dofs.size() > 0);
  const ExplicitPressureSystem sys = assemble_explicit_pressure(grid, ball, dofs, dt, flight);
  const MatrixFreePressureOperator<Dim> mf(grid, ball, dofs, dt);
  const double be = sys.b.cwiseAbs().maxCoeff();
  const double bm = mf.rhs(flight).cwiseAbs().maxCoeff();
  std::printf("pressure free fall %dD: ||b|| explicit %.2e, matrixfree %.2e, round-off level %.2e\n",
              Dim, be, bm, level);
  // the noise case: b is not exactly zero, and below the level on both back ends
  CHECK(std::max(be, bm) > 0.0);
  CHECK(be <= level);
  CHECK(bm <= level);
  // without the rule the relative test solves that noise (what the rule removes)
  {
    VectorX p;
    CHECK(pcg_solve(SparseMatrixOperator(sys.A, dofs.null_space), sys.b, p, PcgSettings{}).iterations > 0);
  }
  const PcgSettings settings{};  // tolerance 1e-6, as in the scenes
  for (const PreconditionerKind kind : {PreconditionerKind::ssor, PreconditionerKind::multigrid})
    for (const Backend backend : {Backend::explicit_matrices, Backend::matrix_free}) {
      INFO(enum_name(kind) << " " << enum_name(backend));
      VectorX u = flight;
      const PressureSolveResult s = solve_pressure(grid, ball, dt, backend, settings, u, kind);
      CHECK(s.pcg.converged);
      CHECK(s.pcg.iterations == 0);
      CHECK(s.pressure.cwiseAbs().maxCoeff() == 0.0);
      CHECK((u.array() == flight.array()).all());
    }
  // real right-hand sides lie far above the level and are solved as before (the same bits as
  // PCG without the rule): a random u* on the ball, and a liquid at rest in a tank under gravity
  // (u* = g dt on every face: the walls hold it, so b is the hydrostatic load, not round-off)
  const PressureWeights tank = weights([](const Vec<Dim>& x) { return x[1] - 0.55; });
  VectorX still = VectorX::Zero(grid.num_faces());
  for (int f = 0; f < grid.num_faces(); ++f)
    if (grid.face_coord(f).first == 1) still[f] = -9.81 * dt;
  const std::pair<const PressureWeights*, VectorX> reals[] = {{&ball, random_vector(grid.num_faces(), 12)},
                                                              {&tank, still}};
  for (const auto& [w, u_star] : reals) {
    const PressureDofs d = select_pressure_dofs(grid, *w, dt);
    const MatrixFreePressureOperator<Dim> op(grid, *w, d, dt);
    const VectorX b = op.rhs(u_star);
    CHECK(b.cwiseAbs().maxCoeff() >= 1e6 * liquid_rhs_round_off(grid, w->fluid_face, u_star, nullptr));
    VectorX u = u_star;
    const PressureSolveResult s = solve_pressure(grid, *w, dt, Backend::matrix_free, settings, u);
    VectorX p_plain;
    const PcgResult plain = pcg_solve(op, b, p_plain, settings);
    CHECK(s.pcg.converged);
    CHECK(s.pcg.iterations > 0);
    CHECK(s.pcg.iterations == plain.iterations);
    CHECK((s.pressure.array() == scatter_pressure(d, p_plain, grid.num_cells()).array()).all());
  }
}
