// The stress DOF layout (stress_grid.hpp) and the deformation rate operator D of eq. (8).
#include <catch2/catch.hpp>
#include <cmath>
#include <set>

#include "reference/fluid/deformation_rate.hpp"
#include "reference/grid/stress_grid.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using namespace monolith::testing;

namespace {

/// Unequal cell counts catch index mix-ups; axis 0 periodic or not.
template <int Dim>
MacGrid<Dim> make_grid(bool periodic_x) {
  VecI<Dim> cells;
  for (int a = 0; a < Dim; ++a) cells[a] = 4 + a;
  std::array<bool, Dim> periodic{};
  periodic[0] = periodic_x;
  return MacGrid<Dim>(Vec<Dim>::Constant(-0.3), 0.125, cells, periodic);
}

/// Samples the affine field u(x) = A x + t on the faces (component a on faces normal to a).
template <int Dim>
VectorX sample_affine(const MacGrid<Dim>& grid, const Mat<Dim>& A, const Vec<Dim>& t) {
  VectorX u(grid.num_faces());
  for (int i = 0; i < grid.num_faces(); ++i) {
    const auto [axis, f] = grid.face_coord(i);
    const Vec<Dim> x = grid.face_center(axis, f);
    u[i] = (A * x + t)[axis];
  }
  return u;
}

/// A random matrix whose column 0 is zero when axis 0 is periodic, so that A x + t is periodic
/// along x and the seam DOFs are checked as well.
template <int Dim>
Mat<Dim> random_matrix(unsigned seed, bool periodic_x) {
  const VectorX r = random_vector(Dim * Dim, seed);
  Mat<Dim> A = Eigen::Map<const Mat<Dim>>(r.data());
  if (periodic_x) A.col(0).setZero();
  return A;
}

/// Rigid rotation rate: the skew matrix W with W y = omega x y (3D) or omega (-y1, y0) (2D),
/// |omega components| in [0.5, 1]. With axis 0 periodic only rotations independent of x remain:
/// none in 2D (W = 0, translation only), rotation about the x axis in 3D.
template <int Dim>
Mat<Dim> random_skew(unsigned seed, bool periodic_x) {
  const VectorX r = random_vector(3, seed);
  const Eigen::Vector3d omega = (0.5 + 0.5 * r.array().abs()).matrix();
  Mat<Dim> W = Mat<Dim>::Zero();
  if constexpr (Dim == 2) {
    if (!periodic_x) {
      W(0, 1) = -omega[2];
      W(1, 0) = omega[2];
    }
  } else {
    W(1, 2) = -omega[0];
    W(2, 1) = omega[0];
    if (!periodic_x) {
      W(0, 1) = -omega[2];
      W(1, 0) = omega[2];
      W(0, 2) = omega[1];
      W(2, 0) = -omega[1];
    }
  }
  return W;
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("stress DOF numbering round-trips and matches the documented layout",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  for (bool periodic : {false, true}) {
    const auto grid = make_grid<Dim>(periodic);
    const StressGrid<Dim> stress(grid);
    const SampleLattice<Dim> half = half_lattice(grid);
    REQUIRE(stress.num_components() == Dim * (Dim + 1) / 2);
    int expected_total = 0;
    for (int k = 0; k < stress.num_components(); ++k) {
      const auto [a, b] = StressGrid<Dim>::component_axes(k);
      CHECK(StressGrid<Dim>::component(a, b) == k);
      CHECK(StressGrid<Dim>::component(b, a) == k);
      CHECK(StressGrid<Dim>::is_diagonal(k) == (a == b));
      CHECK(stress.offset(k) == expected_total);
      // cells along cell-centred axes, cells + 1 along node-aligned non-periodic axes
      int count = 1;
      for (int axis = 0; axis < Dim; ++axis) {
        const bool node = (a != b) && (axis == a || axis == b);
        const int n = grid.cells()[axis] + ((node && !grid.periodic(axis)) ? 1 : 0);
        CHECK(stress.dims(k)[axis] == n);
        CHECK(StressGrid<Dim>::shift(k)[axis] == (node ? 0.0 : 0.5));
        count *= n;
      }
      CHECK(stress.num_dofs(k) == count);
      expected_total += count;
    }
    REQUIRE(stress.num_dofs() == expected_total);

    std::set<std::pair<int, int>> seen;  // (component, half-lattice index)
    for (int i = 0; i < stress.num_dofs(); ++i) {
      const auto [k, c] = stress.coord(i);
      REQUIRE(stress.in_range(k, c));
      CHECK(stress.index(k, c) == i);
      CHECK(stress.index_or_outside(k, c) == i);
      // position -> half-lattice point -> same coordinate
      const Vec<Dim> x = stress.position(k, c);
      const Vec<Dim> lat = (x - half.origin) / half.spacing;
      VecI<Dim> li;
      for (int a = 0; a < Dim; ++a) li[a] = static_cast<int>(std::lround(lat[a]));
      CHECK((lat - li.template cast<double>()).norm() < 1e-12);
      CHECK((li - 2 * c - (2.0 * StressGrid<Dim>::shift(k)).template cast<int>()).isZero());
      CHECK(grid.domain_box().exteriorDistance(x) < 1e-12);
      CHECK(seen.insert({k, half.index(li)}).second);
      // a shift by the period lands on the same DOF; a step out of a wall is outside
      for (int a = 0; a < Dim; ++a) {
        VecI<Dim> far = c;
        far[a] += grid.periodic(a) ? grid.cells()[a] : 0;
        CHECK(stress.index_or_outside(k, far) == i);
        far[a] -= 2 * grid.cells()[a];
        CHECK(stress.index_or_outside(k, far) == (grid.periodic(a) ? i : -1));
      }
    }
    // on a walled axis the last node layer exists, on a periodic axis it is the first layer
    const int xy = StressGrid<Dim>::component(0, 1);
    VecI<Dim> last = VecI<Dim>::Zero();
    last[0] = grid.cells()[0];
    const VecI<Dim> first = VecI<Dim>::Zero();
    if (periodic)
      CHECK(stress.index_or_outside(xy, last) == stress.index(xy, first));
    else
      CHECK(stress.index_or_outside(xy, last) == stress.index(xy, last));
  }
}

TEMPLATE_TEST_CASE_SIG("D is num_stress_dofs x num_faces with the documented stencil", "[unit]",
                       ((int Dim), Dim), 2, 3) {
  for (bool periodic : {false, true}) {
    const auto grid = make_grid<Dim>(periodic);
    const StressGrid<Dim> stress(grid);
    const SparseMatrix d = deformation_rate_matrix(stress);
    REQUIRE(d.rows() == stress.num_dofs());
    REQUIRE(d.cols() == grid.num_faces());
    CHECK((SparseMatrix(deformation_rate_matrix(grid)) - d).norm() == 0.0);
    for (int i = 0; i < stress.num_dofs(); ++i) {
      const auto [k, c] = stress.coord(i);
      // interior rows: 2 entries +-1/dx (diagonal) or 4 entries +-1/(2 dx) (off-diagonal), sum 0
      double sum = 0.0, abs_sum = 0.0;
      int nnz = 0;
      for (SparseMatrix::InnerIterator it(d, i); it; ++it) {
        sum += it.value();
        abs_sum += std::abs(it.value());
        ++nnz;
      }
      if (stress.is_boundary(k, c)) {
        CHECK(nnz < 4);
      } else {
        CHECK(nnz == (StressGrid<Dim>::is_diagonal(k) ? 2 : 4));
        CHECK(std::abs(sum) < 1e-12);
        CHECK(abs_sum == Approx(2.0 / grid.dx()));
      }
    }
  }
}

TEMPLATE_TEST_CASE_SIG("D of a rigid motion vanishes on interior DOFs", "[property]",
                       ((int Dim), Dim), 2, 3) {
  for (bool periodic : {false, true}) {
    const auto grid = make_grid<Dim>(periodic);
    const StressGrid<Dim> stress(grid);
    const SparseMatrix d = deformation_rate_matrix(stress);
    for (unsigned seed = 1; seed <= 3; ++seed) {
      // translation t plus rotation about an arbitrary centre: u = t + W (x - centre)
      const Mat<Dim> W = random_skew<Dim>(seed, periodic);
      const Vec<Dim> t = random_vector(Dim, seed + 10);
      const Vec<Dim> centre = random_vector(Dim, seed + 20);
      REQUIRE((W + W.transpose()).norm() == 0.0);
      if (!(periodic && Dim == 2)) REQUIRE(W.norm() >= 0.5);
      const VectorX u = sample_affine(grid, W, Vec<Dim>(t - W * centre));
      const VectorX e = d * u;
      int interior = 0;
      double worst = 0.0;
      for (int i = 0; i < stress.num_dofs(); ++i) {
        const auto [k, c] = stress.coord(i);
        if (stress.is_boundary(k, c)) continue;
        ++interior;
        worst = std::max(worst, std::abs(e[i]));
      }
      REQUIRE(interior > stress.num_dofs() / 2);
      CHECK(worst <= 1e-12);
    }
  }
}

TEMPLATE_TEST_CASE_SIG("D of u = A x + t is (A + A^T)/2 on interior DOFs", "[property]",
                       ((int Dim), Dim), 2, 3) {
  for (bool periodic : {false, true}) {
    const auto grid = make_grid<Dim>(periodic);
    const StressGrid<Dim> stress(grid);
    const SparseMatrix d = deformation_rate_matrix(stress);
    for (unsigned seed = 1; seed <= 3; ++seed) {
      const Mat<Dim> A = random_matrix<Dim>(seed, periodic);
      const Mat<Dim> sym = 0.5 * (A + A.transpose());
      const VectorX u = sample_affine(grid, A, Vec<Dim>(random_vector(Dim, seed + 30)));
      const VectorX e = d * u;
      double worst = 0.0;
      int seam = 0;
      for (int i = 0; i < stress.num_dofs(); ++i) {
        const auto [k, c] = stress.coord(i);
        if (stress.is_boundary(k, c)) continue;
        const auto [a, b] = StressGrid<Dim>::component_axes(k);
        worst = std::max(worst, std::abs(e[i] - sym(a, b)));
        if (periodic && (c[0] == 0 || c[0] == grid.cells()[0] - 1)) ++seam;
      }
      CHECK(worst <= 1e-12);
      if (periodic) CHECK(seam > 0);  // the wrapped stencils were part of the check
    }
    // walled: the boundary rows see zero velocity outside, so they differ from (A + A^T)/2
    if (!periodic) {
      const Mat<Dim> A = random_matrix<Dim>(7, false);
      const VectorX e = d * sample_affine(grid, A, Vec<Dim>(Vec<Dim>::Ones()));
      const int xy = StressGrid<Dim>::component(0, 1);
      const VecI<Dim> corner = VecI<Dim>::Zero();
      CHECK(std::abs(e[stress.index(xy, corner)] - 0.5 * (A(0, 1) + A(1, 0))) > 1e-3);
    }
  }
}

TEMPLATE_TEST_CASE_SIG("D^T M of a constant symmetric stress is zero on interior faces",
                       "[property]", ((int Dim), Dim), 2, 3) {
  for (bool periodic : {false, true}) {
    const auto grid = make_grid<Dim>(periodic);
    const StressGrid<Dim> stress(grid);
    const SparseMatrix d = deformation_rate_matrix(stress);
    const VectorX r = random_vector(Dim * Dim, 5);
    Mat<Dim> S = Eigen::Map<const Mat<Dim>>(r.data());
    S = (S + S.transpose()).eval();
    VectorX tau(stress.num_dofs());
    for (int i = 0; i < stress.num_dofs(); ++i) {
      const int k = stress.coord(i).first;
      const auto [a, b] = StressGrid<Dim>::component_axes(k);
      tau[i] = StressGrid<Dim>::multiplicity(k) * S(a, b);
    }
    const VectorX force = d.transpose() * tau;
    double worst = 0.0, boundary = 0.0;
    for (int f = 0; f < grid.num_faces(); ++f) {
      const auto [axis, fc] = grid.face_coord(f);
      if (grid.is_boundary_face(axis, fc))
        boundary = std::max(boundary, std::abs(force[f]));
      else
        worst = std::max(worst, std::abs(force[f]));
    }
    CHECK(worst <= 1e-12 / grid.dx());
    // on walls the missing outside DOFs leave the traction of the constant stress
    if (!periodic) CHECK(boundary > 1e-3);
  }
}

TEMPLATE_TEST_CASE_SIG("D^T M of a linear stress is minus its divergence on interior faces",
                       "[property]", ((int Dim), Dim), 2, 3) {
  const auto grid = make_grid<Dim>(false);
  const StressGrid<Dim> stress(grid);
  const SparseMatrix d = deformation_rate_matrix(stress);
  // tau_ab(x) = S_ab + sum_c L[c](a, b) x_c with every L[c] symmetric
  std::array<Mat<Dim>, Dim> L;
  for (int c = 0; c < Dim; ++c) {
    const VectorX r = random_vector(Dim * Dim, 40 + c);
    L[c] = Eigen::Map<const Mat<Dim>>(r.data());
    L[c] = (L[c] + L[c].transpose()).eval();
  }
  VectorX tau(stress.num_dofs());
  for (int i = 0; i < stress.num_dofs(); ++i) {
    const auto [k, c] = stress.coord(i);
    const auto [a, b] = StressGrid<Dim>::component_axes(k);
    const Vec<Dim> x = stress.position(k, c);
    double v = 0.3;
    for (int e = 0; e < Dim; ++e) v += L[e](a, b) * x[e];
    tau[i] = StressGrid<Dim>::multiplicity(k) * v;
  }
  const VectorX force = d.transpose() * tau;
  double worst = 0.0;
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, fc] = grid.face_coord(f);
    if (grid.is_boundary_face(axis, fc)) continue;
    // (div tau)_axis = sum_b d tau_{axis b} / d x_b
    double div = 0.0;
    for (int b = 0; b < Dim; ++b) div += L[b](axis, b);
    worst = std::max(worst, std::abs(force[f] + div));
  }
  CHECK(worst <= 1e-10);
}
