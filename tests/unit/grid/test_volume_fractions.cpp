// Volume fractions (section 3.1.2) and the solid shrinkage of section 4.4.6.
#include <omp.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <random>

#include "reference/core/huge_pages.hpp"
#include "reference/core/parallel.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using monolith::testing::all_boundaries;
using monolith::testing::sample_lattice;
using monolith::testing::unit_grid;

namespace {

template <int Dim>
double ball_volume(double r) {
  return Dim == 2 ? M_PI * r * r : 4.0 / 3.0 * M_PI * r * r * r;
}

/// A ball SDF off the grid symmetry lines.
template <int Dim>
struct Ball {
  Vec<Dim> centre = Vec<Dim>::Constant(0.5) + Vec<Dim>::LinSpaced(0.013, 0.031);
  double radius = 0.31;
  double operator()(const Vec<Dim>& x) const { return (x - centre).norm() - radius; }
};

}  // namespace

TEST_CASE("simplex fractions: known values and complement", "[unit][property]") {
  // a triangle with one negative corner at -1, the others at +1: corner triangle of scale 1/2
  CHECK(simplex_negative_fraction<2>({-1.0, 1.0, 1.0}) == Approx(0.25).epsilon(1e-14));
  CHECK(simplex_negative_fraction<2>({1.0, -1.0, -1.0}) == Approx(0.75).epsilon(1e-14));
  // a tetrahedron split through the midpoints of four edges: half by symmetry
  CHECK(simplex_negative_fraction<3>({-1.0, -1.0, 1.0, 1.0}) == Approx(0.5).epsilon(1e-14));
  CHECK(simplex_negative_fraction<3>({-1.0, 1.0, 1.0, 1.0}) == Approx(0.125).epsilon(1e-14));
  // f(phi) + f(-phi) = 1 for every sign pattern
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 2000; ++trial) {
    std::array<double, 3> t{u(rng), u(rng), u(rng)};
    std::array<double, 3> tn{-t[0], -t[1], -t[2]};
    REQUIRE(simplex_negative_fraction<2>(t) + simplex_negative_fraction<2>(tn) ==
            Approx(1.0).margin(1e-12));
    std::array<double, 4> q{u(rng), u(rng), u(rng), u(rng)};
    std::array<double, 4> qn{-q[0], -q[1], -q[2], -q[3]};
    const double f = simplex_negative_fraction<3>(q);
    REQUIRE(f >= -1e-15);
    REQUIRE(f <= 1.0 + 1e-15);
    REQUIRE(f + simplex_negative_fraction<3>(qn) == Approx(1.0).margin(1e-12));
  }
}

TEST_CASE("tetrahedron fraction matches a fine quadrature of the linear function",
          "[unit][dense-reference]") {
  // midpoint rule on a 60^3 lattice of the reference tetrahedron x, y, z >= 0, x + y + z <= 1
  const std::array<std::array<double, 4>, 3> cases{
      {{-0.7, -0.2, 0.5, 0.9}, {-0.3, 0.8, -0.6, 0.1}, {0.4, -0.9, 0.2, -0.1}}};
  for (const auto& phi : cases) {
    const int n = 60;
    long inside = 0, negative = 0;
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j)
        for (int k = 0; k < n; ++k) {
          const double x = (i + 0.5) / n, y = (j + 0.5) / n, z = (k + 0.5) / n;
          if (x + y + z > 1.0) continue;
          ++inside;
          const double v = phi[0] * (1 - x - y - z) + phi[1] * x + phi[2] * y + phi[3] * z;
          negative += v < 0.0;
        }
    CHECK(simplex_negative_fraction<3>(phi) == Approx(double(negative) / inside).margin(0.01));
  }
}

TEMPLATE_TEST_CASE_SIG("ball fractions converge to the exact volume at second order",
                       "[convergence]", ((int Dim), Dim), 2, 3) {
  const Ball<Dim> ball;
  const double exact = ball_volume<Dim>(ball.radius);
  const std::vector<int> levels =
      Dim == 2 ? std::vector<int>{16, 32, 64} : std::vector<int>{8, 16, 32};
  std::vector<double> cell_err, face_err;
  for (int n : levels) {
    const auto grid = unit_grid<Dim>(n);
    const auto lattice = half_lattice(grid);
    const VectorX phi = sample_lattice<Dim>(lattice, ball);
    const VectorX wc = cell_negative_fractions(grid, lattice, phi);
    const VectorX wf = face_negative_fractions(grid, lattice, phi);
    REQUIRE(wc.minCoeff() >= 0.0);
    REQUIRE(wc.maxCoeff() <= 1.0);
    REQUIRE(wf.minCoeff() >= 0.0);
    REQUIRE(wf.maxCoeff() <= 1.0);
    cell_err.push_back(std::abs(wc.sum() * grid.cell_volume() - exact));
    // each axis' face control volumes also tile the domain
    double worst = 0.0;
    for (int a = 0; a < Dim; ++a)
      worst = std::max(worst, std::abs(wf.segment(grid.face_offset(a), grid.num_faces(a)).sum() *
                                           grid.cell_volume() -
                                       exact));
    face_err.push_back(worst);
  }
  const double order_cell = std::log2(cell_err[1] / cell_err[2]);
  const double order_face = std::log2(face_err[1] / face_err[2]);
  INFO("cell errors " << cell_err[0] << " " << cell_err[1] << " " << cell_err[2] << " order "
                      << order_cell);
  INFO("face errors " << face_err[0] << " " << face_err[1] << " " << face_err[2] << " order "
                      << order_face);
  CHECK(order_cell > 1.7);
  CHECK(order_face > 1.7);
  CHECK(std::log2(cell_err[0] / cell_err[2]) / 2.0 > 1.7);
}

TEMPLATE_TEST_CASE_SIG("lattice-aligned box: exact fractions, full and empty cells exact", "[unit]",
                       ((int Dim), Dim), 2, 3) {
  const int n = 8;
  const auto grid = unit_grid<Dim>(n);
  const auto lattice = half_lattice(grid);
  // box [0.25, 0.6875]^Dim: lower side on cell faces, upper side through cell centres; the
  // sides sit 1e-10 outside the lattice planes so that no lattice triangle has phi = 0 at all
  // its corners (a zero-measure ambiguity of phi = 0 counted as outside)
  const Vec<Dim> lo = Vec<Dim>::Constant(0.25 - 1e-10), hi = Vec<Dim>::Constant(0.6875 + 1e-10);
  const VectorX phi = sample_lattice<Dim>(
      lattice, [&](const Vec<Dim>& x) { return ((lo - x).cwiseMax(x - hi)).maxCoeff(); });
  const VectorX wc = cell_negative_fractions(grid, lattice, phi);
  CHECK(wc.sum() * grid.cell_volume() == Approx(std::pow(hi[0] - lo[0], Dim)).epsilon(1e-8));
  for (int c = 0; c < grid.num_cells(); ++c) {
    const Vec<Dim> centre = grid.cell_center(grid.cell_coord(c));
    // expected per cell: product over axes of the covered length of the cell
    double expected = 1.0;
    for (int a = 0; a < Dim; ++a) {
      const double l = centre[a] - 0.5 * grid.dx(), h = centre[a] + 0.5 * grid.dx();
      expected *= std::max(0.0, std::min(h, hi[a]) - std::max(l, lo[a])) / grid.dx();
    }
    REQUIRE(wc[c] == Approx(expected).margin(1e-8));
    if (expected == 0.0 || expected == 1.0) REQUIRE(wc[c] == expected);
  }
}

TEMPLATE_TEST_CASE_SIG("weights: W_F^u without solids from the walls alone, the same bits as "
                       "from a level set of no solid",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // every wall/open combination of the first two axes' sides, with x periodic or not, on a
  // grid that is not a cube (the boundary planes of each axis differ in size)
  for (const bool periodic : {false, true}) {
    VecI<Dim> cells = VecI<Dim>::Constant(5);
    cells[0] = 7;
    if (Dim == 3) cells[Dim - 1] = 4;
    std::array<bool, Dim> periodic_axes{};
    periodic_axes[0] = periodic;
    const MacGrid<Dim> grid(Vec<Dim>::Zero(), 0.1, cells, periodic_axes);
    const auto lattice = half_lattice(grid);
    const VectorX no_solid = solid_phi_on_lattice(grid, lattice, {}, 0.01 * grid.dx());
    for (int mask = 0; mask < 16; ++mask) {
      auto boundary = all_boundaries<Dim>(BoundaryType::wall);
      for (int side = 0; side < 4; ++side)
        if (mask & (1 << side)) boundary[side] = BoundaryType::open;
      if (periodic) boundary[0] = boundary[1] = BoundaryType::periodic;
      const VectorX expected = fluid_face_weights(grid, lattice, no_solid, boundary);
      const VectorX w = fluid_face_weights_without_solids(grid, boundary);
      REQUIRE(w.size() == expected.size());
      int walls = 0;
      for (int f = 0; f < grid.num_faces(); ++f) {
        REQUIRE(std::signbit(w[f]) == std::signbit(expected[f]));
        REQUIRE(w[f] == expected[f]);
        walls += w[f] == 0.0;
      }
      // (the comparison means something: faces are walls exactly when some side is a wall)
      const bool any_wall = std::find(boundary.begin(), boundary.end(), BoundaryType::wall) !=
                            boundary.end();
      CHECK((walls > 0) == any_wall);
    }
  }
}

TEMPLATE_TEST_CASE_SIG("weights: solid shrinkage, walls, open and periodic boundaries, clamp",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  const int n = 6;
  // no solid: W_F^u is 1 inside, 0 on walls, 1 on open faces
  {
    const auto grid = unit_grid<Dim>(n);
    const auto lattice = half_lattice(grid);
    const VectorX solid_phi = solid_phi_on_lattice(grid, lattice, {}, 0.01 * grid.dx());
    REQUIRE(std::isinf(solid_phi[0]));
    auto boundary = all_boundaries<Dim>(BoundaryType::wall);
    boundary[3] = BoundaryType::open;  // y+
    const VectorX wf = fluid_face_weights(grid, lattice, solid_phi, boundary);
    const VectorX ws = solid_face_weights(wf);
    for (int f = 0; f < grid.num_faces(); ++f) {
      const auto [axis, coord] = grid.face_coord(f);
      double expected = 1.0;
      if (grid.is_boundary_face(axis, coord)) expected = axis == 1 && coord[1] == n ? 1.0 : 0.0;
      REQUIRE(wf[f] == expected);
      REQUIRE(ws[f] == 1.0 - expected);
    }
  }
  // periodic x: the face at x = 0 sees both ends of the domain; a liquid slab through it
  {
    const auto grid = unit_grid<Dim>(n, true);
    const auto lattice = half_lattice(grid);
    // liquid where x < 0.25 or x > 0.75 (distance to the periodic slab)
    const VectorX phi = sample_lattice<Dim>(lattice, [](const Vec<Dim>& x) {
      return std::min(x[0] - 0.25, 0.75 - x[0]) < 0.0 ? -1.0 : 1.0;
    });
    const VectorX wlp = liquid_cell_weights(grid, lattice, phi);
    const VectorX wlu = liquid_face_weights(grid, lattice, phi, wlp);
    const int face0 = grid.face_index(0, VecI<Dim>::Zero());
    CHECK(wlu[face0] == Approx(1.0));
    CHECK(grid.num_faces(0) == grid.num_cells());
  }
  // the shrinkage moves a solid's surface inward by zeta, and the clamp applies next to liquid
  {
    const auto grid = unit_grid<Dim>(n);
    const auto lattice = half_lattice(grid);
    const double zeta = 0.01 * grid.dx();
    const VectorX plain = sample_lattice<Dim>(lattice, [](const Vec<Dim>& x) { return x[1] - 0.5; });
    const VectorX shifted = plain.array() + zeta;
    const VectorX wf0 =
        VectorX::Ones(grid.num_faces()) - face_negative_fractions(grid, lattice, plain);
    const VectorX wf1 =
        VectorX::Ones(grid.num_faces()) - face_negative_fractions(grid, lattice, shifted);
    CHECK(wf1.sum() > wf0.sum());
    // a liquid layer that fills only the lower half of the cell row j = 2: faces y = 3 dx have
    // W_L^u = 0 geometrically but sit beside liquid cells, so they are clamped
    const double h = 2.5 / n - 1e-9;
    const VectorX phi = sample_lattice<Dim>(lattice, [h](const Vec<Dim>& x) { return x[1] - h; });
    const VectorX wlp = liquid_cell_weights(grid, lattice, phi);
    const VectorX raw = face_negative_fractions(grid, lattice, phi);
    const VectorX wlu = liquid_face_weights(grid, lattice, phi, wlp);
    VecI<Dim> f = VecI<Dim>::Zero();
    f[1] = 3;
    const int face = grid.face_index(1, f);
    CHECK(raw[face] == Approx(0.0).margin(1e-6));
    CHECK(wlu[face] == kMinLiquidFaceFraction);
    f[1] = 5;
    CHECK(wlu[grid.face_index(1, f)] == 0.0);
    for (int k = 0; k < wlu.size(); ++k) REQUIRE(wlu[k] >= raw[k]);
  }
}

namespace {

/// face_negative_fractions as it was before the band (issue 20): every face's cube through
/// lattice_cube_negative_fraction, the reference the band version must equal bit for bit.
template <int Dim>
VectorX every_face_fraction(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                            const VectorX& phi) {
  VectorX w(grid.num_faces());
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    VecI<Dim> lower = 2 * coord;
    lower[axis] -= 1;
    w[f] = lattice_cube_negative_fraction<Dim>(grid, lattice, lower, phi);
  }
  return w;
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("band fractions equal every control volume's cube fraction bit for bit",
                       "[unit][property]", ((int Dim), Dim), 2, 3) {
  // Level sets whose sign changes in a small region (a ball near a wall, a ball across the
  // periodic seam, a thin sheet, a level set negative everywhere, one with no negative sample,
  // random signs): the fractions of cells and faces from the lattice-cell classes equal the
  // direct evaluation of every cube (0 and 1 included), and the box of the classes holds every
  // cell of class != 0.
  const int n = Dim == 2 ? 20 : 10;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int periodic_x = 0; periodic_x < 2; ++periodic_x) {
    std::array<bool, Dim> periodic{};
    periodic[0] = periodic_x == 1;
    const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), periodic);
    const SampleLattice<Dim> lattice = half_lattice(grid);
    std::vector<VectorX> cases;
    Vec<Dim> near_wall = Vec<Dim>::Constant(0.5);
    near_wall[0] = 0.08;
    cases.push_back(sample_lattice<Dim>(lattice, [&](const Vec<Dim>& x) { return (x - near_wall).norm() - 0.15; }));
    Vec<Dim> at_seam = Vec<Dim>::Constant(0.37);
    at_seam[0] = 0.99;
    cases.push_back(sample_lattice<Dim>(lattice, [&](const Vec<Dim>& x) { return (x - at_seam).norm() - 0.2; }));
    cases.push_back(sample_lattice<Dim>(lattice, [&](const Vec<Dim>& x) { return std::abs(x[Dim - 1] - 0.52) - 0.035; }));
    cases.push_back(VectorX::Constant(lattice.size(), -1.0));
    cases.push_back(VectorX::Constant(lattice.size(), 2.0));
    VectorX random(lattice.size());
    for (int k = 0; k < random.size(); ++k) random[k] = u(rng);
    cases.push_back(random);
    for (std::size_t c = 0; c < cases.size(); ++c) {
      INFO("periodic x " << periodic_x << ", case " << c);
      const VectorX& phi = cases[c];
      LatticeSigns<Dim> signs;
      classify_lattice_cells(grid, lattice, phi, signs);
      VectorX faces, cells;
      face_negative_fractions(grid, lattice, phi, signs, faces);
      cell_negative_fractions(grid, lattice, phi, signs, cells);
      const VectorX direct = every_face_fraction(grid, lattice, phi);
      int differ = 0;
      for (int f = 0; f < grid.num_faces(); ++f) differ += faces[f] != direct[f];
      CHECK(differ == 0);
      differ = 0;
      for (int i = 0; i < grid.num_cells(); ++i)
        differ += cells[i] != lattice_cube_negative_fraction<Dim>(grid, lattice, 2 * grid.cell_coord(i), phi);
      CHECK(differ == 0);
      // the classes and their box
      int outside_box = 0, non_zero = 0;
      const std::vector<std::uint8_t> classes = signs.all_classes();
      for (std::size_t l = 0; l < classes.size(); ++l) {
        if (classes[l] == LatticeSigns<Dim>::kPositive) continue;
        ++non_zero;
        const VecI<Dim> lc = lattice_coord<Dim>(static_cast<int>(l), signs.cells);
        outside_box += (lc.array() < signs.lo.array()).any() || (lc.array() > signs.hi.array()).any();
      }
      CHECK(outside_box == 0);
      CHECK(signs.any_negative() == (non_zero > 0));
      CHECK(signs.any_negative() == (c != 4));
    }
  }
}

TEMPLATE_TEST_CASE_SIG("lattice-cell classes in a box: one buffer across level sets equals a fresh "
                       "classification of every cell",
                       "[unit][property]", ((int Dim), Dim), 2, 3) {
  // One LatticeSigns reused for a sequence of level sets whose negative regions move, grow,
  // shrink and vanish (as the simulation's buffers are across steps): after each call every
  // class equals the count of its negative corners, the box is that of the non-positive cells,
  // negative_point_box is the box of the negative points, and a classification in a larger box
  // given by the caller gives the same classes. NaN counts as not negative.
  const int n = Dim == 2 ? 16 : 8;
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  std::vector<VectorX> cases;
  for (double cx : {0.2, 0.8, 0.5})
    for (double r : {0.05, 0.3}) {
      Vec<Dim> c = Vec<Dim>::Constant(0.45);
      c[0] = cx;
      cases.push_back(sample_lattice<Dim>(lattice, [&](const Vec<Dim>& x) { return (x - c).norm() - r; }));
    }
  cases.push_back(VectorX::Constant(lattice.size(), 1.0));   // nothing negative
  cases.push_back(VectorX::Constant(lattice.size(), -1.0));  // everything
  VectorX point = VectorX::Constant(lattice.size(), 0.5);    // one negative point, one NaN
  point[lattice.index(VecI<Dim>::Constant(3))] = -0.1;
  point[lattice.index(VecI<Dim>::Constant(9))] = std::nan("");
  cases.push_back(point);
  cases.push_back(cases[1]);
  const VecI<Dim> cells = 2 * grid.cells();
  LatticeSigns<Dim> reused, boxed;
  for (std::size_t k = 0; k < cases.size(); ++k) {
    INFO("case " << k);
    const VectorX& phi = cases[k];
    // the reference: every cell's corners counted, every negative point boxed
    std::vector<std::uint8_t> expected(cells.prod());
    VecI<Dim> clo = cells, chi = -VecI<Dim>::Ones(), plo = lattice.dims, phi_hi = -VecI<Dim>::Ones();
    for (int l = 0; l < cells.prod(); ++l) {
      const VecI<Dim> lc = lattice_coord<Dim>(l, cells);
      int negatives = 0;
      for (int corner = 0; corner < (1 << Dim); ++corner) {
        VecI<Dim> p = lc;
        for (int a = 0; a < Dim; ++a) p[a] += (corner >> a) & 1;
        negatives += phi[lattice.index(p)] < 0.0;
      }
      expected[l] = negatives == 0 ? 0 : negatives == (1 << Dim) ? 1 : 2;
      if (expected[l] != 0) clo = clo.cwiseMin(lc), chi = chi.cwiseMax(lc);
    }
    for (int p = 0; p < lattice.size(); ++p)
      if (phi[p] < 0.0) plo = plo.cwiseMin(lattice.coord(p)), phi_hi = phi_hi.cwiseMax(lattice.coord(p));
    const auto [lo, hi] = negative_point_box(lattice, phi);
    CHECK(lo == plo);
    CHECK(hi == phi_hi);
    classify_lattice_cells(grid, lattice, phi, reused);
    CHECK(reused.all_classes() == expected);
    // only the written box is stored (the band, not the whole lattice)
    const bool written = (reused.written_lo.array() <= reused.written_hi.array()).all();
    CHECK(reused.cls.size() ==
          (written ? static_cast<std::size_t>(
                         (reused.written_hi - reused.written_lo + VecI<Dim>::Ones()).prod())
                   : 0u));
    if (k == 0) CHECK(reused.cls.size() < static_cast<std::size_t>(cells.prod()));  // a small ball
    CHECK(reused.lo == clo);
    CHECK(reused.hi == chi);
    // a box two points larger than the negative points (clamped by the call)
    const VecI<Dim> box_lo = plo - 2 * VecI<Dim>::Ones(), box_hi = phi_hi + 2 * VecI<Dim>::Ones();
    classify_lattice_cells_in_box(grid, lattice, phi, box_lo, box_hi, boxed);
    CHECK(boxed.all_classes() == expected);
    CHECK(boxed.lo == clo);
    CHECK(boxed.hi == chi);
  }
}

TEMPLATE_TEST_CASE_SIG("liquid extended into solids in the solids' box equals the whole-lattice rule",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  const int n = Dim == 2 ? 16 : 8;
  const MacGrid<Dim> grid = unit_grid<Dim>(n);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  Vec<Dim> c = Vec<Dim>::Constant(0.5);
  const VectorX liquid = sample_lattice<Dim>(lattice, [&](const Vec<Dim>& x) { return (x - c).norm() - 0.3; });
  c[0] = 0.75;
  const VectorX solid = sample_lattice<Dim>(lattice, [&](const Vec<Dim>& x) { return (x - c).norm() - 0.15; });
  VectorX whole, boxed = VectorX::Constant(3, 7.0);  // a buffer of another size
  extend_liquid_into_solids(grid, liquid, solid, grid.dx(), whole);
  const auto [lo, hi] = negative_point_box(lattice, solid);
  REQUIRE((lo.array() <= hi.array()).all());
  extend_liquid_into_solids_in_box(grid, liquid, solid, grid.dx(), lo, hi, boxed);
  int differ = 0, extended = 0;
  for (int k = 0; k < whole.size(); ++k) {
    differ += boxed[k] != whole[k];
    extended += whole[k] != liquid[k];
  }
  CHECK(differ == 0);
  CHECK(extended > 0);  // the rule changed some points
}

TEMPLATE_TEST_CASE_SIG("the mixed lattice cells' fractions made with the classes are each cell's "
                       "Kuhn split, and a level set other than the classified one is not read "
                       "from them",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  const int n = Dim == 2 ? 16 : 8;
  const MacGrid<Dim> grid = unit_grid<Dim>(n, true);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  Vec<Dim> c = Vec<Dim>::Constant(0.41);
  c[0] = 0.93;  // across the periodic seam
  const VectorX phi =
      sample_lattice<Dim>(lattice, [&](const Vec<Dim>& x) { return (x - c).norm() - 0.27; });
  LatticeSigns<Dim> signs;
  classify_lattice_cells(grid, lattice, phi, signs);
  REQUIRE(signs.any_negative());
  // every mixed cell is in the table with its own fraction, and only those
  int mixed = 0, differ = 0;
  const std::vector<std::uint8_t> classes = signs.all_classes();
  for (int l = 0; l < static_cast<int>(classes.size()); ++l) {
    if (classes[l] != LatticeSigns<Dim>::kMixed) continue;
    ++mixed;
    const VecI<Dim> lc = lattice_coord<Dim>(l, signs.cells);
    std::array<double, (1 << Dim)> corners;
    for (int k = 0; k < (1 << Dim); ++k) {
      VecI<Dim> p = lc;
      for (int a = 0; a < Dim; ++a) p[a] += (k >> a) & 1;
      corners[k] = phi[lattice.index(p)];
    }
    differ += signs.mixed_fraction_of(lc) != lattice_cell_negative_fraction<Dim>(corners);
  }
  CHECK(mixed > 0);
  CHECK(static_cast<int>(signs.mixed_fraction.size()) == mixed);
  CHECK(differ == 0);
  // the same classes with another vector of the same signs but other values (phi^3): its
  // fractions come from its own corners, not from the table of phi
  const VectorX scaled = phi.array().cube().matrix();
  VectorX cells_scaled;
  cell_negative_fractions(grid, lattice, scaled, signs, cells_scaled);
  int other = 0;
  for (int i = 0; i < grid.num_cells(); ++i)
    other += cells_scaled[i] !=
             lattice_cube_negative_fraction<Dim>(grid, lattice, 2 * grid.cell_coord(i), scaled);
  CHECK(other == 0);
  VectorX cells_phi;
  cell_negative_fractions(grid, lattice, phi, signs, cells_phi);
  CHECK(cells_phi != cells_scaled);  // the check above can tell the two apart
}

TEMPLATE_TEST_CASE_SIG("fraction buffers kept across level sets are reset where the last call "
                       "wrote them (WrittenBox) and equal fresh ones bit for bit",
                       "[unit][property]", ((int Dim), Dim), 2, 3) {
  // W_L^p and W_L^u as update_liquid_weights keeps them (issue 20): one cell buffer and one face
  // buffer with their boxes across a sequence of level sets whose negative region moves, grows,
  // vanishes and covers everything (periodic x too), the faces clamped over the cells' box.
  // After each call both equal a fresh evaluation with the plain clamp, and every non-zero value
  // lies in the recorded boxes. A value planted outside the boxes stays (the reset is sparse).
  const int n = Dim == 2 ? 16 : 8;
  for (int periodic_x = 0; periodic_x < 2; ++periodic_x) {
    const MacGrid<Dim> grid = unit_grid<Dim>(n, periodic_x == 1);
    const SampleLattice<Dim> lattice = half_lattice(grid);
    std::vector<VectorX> cases;
    for (double cx : {0.2, 0.8, 0.97, 0.5})
      for (double r : {0.06, 0.3}) {
        Vec<Dim> c = Vec<Dim>::Constant(0.45);
        c[0] = cx;
        cases.push_back(sample_lattice<Dim>(lattice, [&](const Vec<Dim>& x) { return (x - c).norm() - r; }));
      }
    cases.push_back(VectorX::Constant(lattice.size(), 2.0));
    cases.push_back(VectorX::Constant(lattice.size(), -1.0));
    cases.push_back(cases[2]);
    VectorX cells, faces;
    WrittenBox<Dim> cell_box;
    std::array<WrittenBox<Dim>, Dim> face_boxes;
    for (std::size_t k = 0; k < cases.size(); ++k) {
      INFO("periodic x " << periodic_x << ", case " << k);
      const VectorX& phi = cases[k];
      LatticeSigns<Dim> signs;
      classify_lattice_cells(grid, lattice, phi, signs);
      cell_negative_fractions(grid, lattice, phi, signs, cells, &cell_box);
      face_negative_fractions<Dim>(grid, lattice, phi, signs, faces, &face_boxes);
      clamp_liquid_face_weights_in_place<Dim>(grid, faces, cells, cell_box, face_boxes);
      VectorX fresh_cells, fresh_faces;
      cell_negative_fractions(grid, lattice, phi, signs, fresh_cells);
      face_negative_fractions(grid, lattice, phi, signs, fresh_faces);
      clamp_liquid_face_weights_in_place(grid, fresh_faces, fresh_cells);
      CHECK(monolith::testing::differing(cells, fresh_cells) == 0);
      CHECK(monolith::testing::differing(faces, fresh_faces) == 0);
      REQUIRE(cell_box.valid);
      int outside = 0;
      for (int i = 0; i < grid.num_cells(); ++i) {
        const VecI<Dim> c = grid.cell_coord(i);
        const bool in = !((c.array() < cell_box.lo.array()).any() || (c.array() > cell_box.hi.array()).any());
        outside += !in && cells[i] != 0.0;
      }
      for (int f = 0; f < grid.num_faces(); ++f) {
        const auto [axis, c] = grid.face_coord(f);
        REQUIRE(face_boxes[axis].valid);
        const bool in = !((c.array() < face_boxes[axis].lo.array()).any() ||
                          (c.array() > face_boxes[axis].hi.array()).any());
        outside += !in && faces[f] != 0.0;
      }
      CHECK(outside == 0);
    }
    // the last level set again, with a value planted outside the cells' box: the sparse reset
    // does not reach it (the contract: the caller keeps the buffer 0 there)
    int planted = -1;
    for (int i = 0; i < grid.num_cells() && planted < 0; ++i) {
      const VecI<Dim> c = grid.cell_coord(i);
      if ((c.array() < cell_box.lo.array()).any() || (c.array() > cell_box.hi.array()).any())
        planted = i;
    }
    REQUIRE(planted >= 0);
    cells[planted] = 0.5;
    const VectorX& phi = cases.back();
    LatticeSigns<Dim> signs;
    classify_lattice_cells(grid, lattice, phi, signs);
    cell_negative_fractions(grid, lattice, phi, signs, cells, &cell_box);
    CHECK(cells[planted] == 0.5);
    // another buffer (a different storage) is filled whole
    VectorX other = VectorX::Constant(grid.num_cells(), 0.25);
    cell_negative_fractions(grid, lattice, phi, signs, other, &cell_box);
    VectorX fresh;
    cell_negative_fractions(grid, lattice, phi, signs, fresh);
    CHECK(monolith::testing::differing(other, fresh) == 0);
  }
}

TEMPLATE_TEST_CASE_SIG("fraction buffers zeroed by release with boxes of nothing written, as the "
                       "simulation reserves them, equal fresh ones bit for bit (huge21)",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // reserve_step_buffers (issue 20, huge21) makes W_L^p and W_L^u with their zeros from the
  // kernel (zero_by_release) and valid, empty WrittenBoxes, so the first fill writes its band
  // only. Buffers above the release threshold (2D 512^2, 3D 64^3 cells); a disc/ball that moves
  // and shrinks over three calls, then vanishes: each call equals a fresh whole evaluation.
  const int n = Dim == 2 ? 512 : 64;
  const MacGrid<Dim> grid = unit_grid<Dim>(n, false);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  VectorX cells(grid.num_cells()), faces(grid.num_faces());
  cells.setConstant(0.75);  // what the heap may hold before the release
  faces.setConstant(-2.0);
  CHECK(zero_by_release(cells.data(), sizeof(double) * static_cast<std::size_t>(cells.size())) > 0);
  CHECK(zero_by_release(faces.data(), sizeof(double) * static_cast<std::size_t>(faces.size())) > 0);
  WrittenBox<Dim> cell_box;
  cell_box.data = cells.data();
  cell_box.size = cells.size();
  cell_box.valid = true;
  std::array<WrittenBox<Dim>, Dim> face_boxes;
  for (int a = 0; a < Dim; ++a) {
    face_boxes[a].data = faces.data() + grid.face_offset(a);
    face_boxes[a].size = grid.face_dims(a).prod();
    face_boxes[a].valid = true;
  }
  int calls = 0;
  for (const auto& [cx, r] : std::vector<std::pair<double, double>>{{0.3, 0.2}, {0.6, 0.1}, {0.62, 0.05}, {0.5, -1.0}}) {
    INFO("centre " << cx << ", radius " << r);
    Vec<Dim> c = Vec<Dim>::Constant(0.45);
    c[0] = cx;
    const VectorX phi =
        r > 0 ? sample_lattice<Dim>(lattice, [&](const Vec<Dim>& x) { return (x - c).norm() - r; })
              : VectorX::Constant(lattice.size(), 1.0);
    LatticeSigns<Dim> signs;
    classify_lattice_cells(grid, lattice, phi, signs);
    cell_negative_fractions(grid, lattice, phi, signs, cells, &cell_box);
    face_negative_fractions<Dim>(grid, lattice, phi, signs, faces, &face_boxes);
    VectorX fresh_cells, fresh_faces;
    cell_negative_fractions(grid, lattice, phi, signs, fresh_cells);
    face_negative_fractions(grid, lattice, phi, signs, fresh_faces);
    CHECK(monolith::testing::differing(cells, fresh_cells) == 0);
    CHECK(monolith::testing::differing(faces, fresh_faces) == 0);
    if (r > 0) CHECK(fresh_cells.sum() > 0.0);  // the check above can fail
    ++calls;
  }
  CHECK(calls == 4);
}

TEMPLATE_TEST_CASE_SIG("the boxed clamp of the faces' liquid fractions above its serial fall-back: "
                       "the plain clamp's bits with 1, 2, 3 and 5 threads",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // a ball of liquid (and a drop cut by the periodic seam of x) whose cells' box holds more face
  // rows times row length than kParallelMinWork, so the raise runs on the team
  const int n = Dim == 2 ? 240 : 48;
  for (int periodic_x = 0; periodic_x < 2; ++periodic_x) {
    INFO("periodic x " << periodic_x);
    const MacGrid<Dim> grid = unit_grid<Dim>(n, periodic_x == 1);
    const SampleLattice<Dim> lattice = half_lattice(grid);
    const VectorX phi = sample_lattice<Dim>(lattice, [&](const Vec<Dim>& x) {
      Vec<Dim> c = Vec<Dim>::Constant(0.45), d = Vec<Dim>::Constant(0.5);
      d[0] = 0.99;
      return std::min((x - c).norm() - 0.3, (x - d).norm() - 0.05);
    });
    LatticeSigns<Dim> signs;
    classify_lattice_cells(grid, lattice, phi, signs);
    VectorX cells, faces_plain;
    WrittenBox<Dim> cell_box;
    cell_negative_fractions(grid, lattice, phi, signs, cells, &cell_box);
    face_negative_fractions(grid, lattice, phi, signs, faces_plain);
    const VectorX unclamped = faces_plain;
    clamp_liquid_face_weights_in_place(grid, faces_plain, cells);
    REQUIRE(cell_box.valid);
    const VecI<Dim> box = cell_box.hi - cell_box.lo + VecI<Dim>::Ones();
    REQUIRE(static_cast<long>(box.prod()) * Dim > kParallelMinWork);
    CHECK(monolith::testing::differing(faces_plain, unclamped) > 0);  // the clamp raised faces
    const bool monitor = core_monitor();
    set_core_monitor(false);
    const int threads = omp_get_max_threads();
    for (int t : {1, 2, 3, 5}) {
      INFO(t << " threads");
      omp_set_num_threads(t);
      VectorX faces;
      std::array<WrittenBox<Dim>, Dim> face_boxes;
      face_negative_fractions<Dim>(grid, lattice, phi, signs, faces, &face_boxes);
      clamp_liquid_face_weights_in_place<Dim>(grid, faces, cells, cell_box, face_boxes);
      omp_set_num_threads(threads);
      CHECK(monolith::testing::differing(faces, faces_plain) == 0);
    }
    set_core_monitor(monitor);
  }
}
