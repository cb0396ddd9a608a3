#include "reference/grid/volume_fractions.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

namespace monolith {

namespace {

/// Reference vertices of the unit simplex (origin and the unit vectors), 3D.
Eigen::Vector3d tet_vertex(int k) {
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  if (k > 0) v[k - 1] = 1.0;
  return v;
}

double abs_det(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
               const Eigen::Vector3d& d) {
  Eigen::Matrix3d m;
  m << b - a, c - a, d - a;
  return std::abs(m.determinant());
}

/// Fraction of a triangle where phi < 0 (phi = 0 counts as outside).
double triangle_fraction(const std::array<double, 3>& phi) {
  int negatives = 0;
  for (double p : phi) negatives += p < 0.0;
  if (negatives == 0) return 0.0;
  if (negatives == 3) return 1.0;
  // the lonely vertex (the one whose sign differs) cuts off a similar corner triangle
  const bool lonely_negative = negatives == 1;
  int k = 0;
  while ((phi[k] < 0.0) != lonely_negative) ++k;
  const double a = phi[k], b = phi[(k + 1) % 3], c = phi[(k + 2) % 3];
  const double corner = a * a / ((a - b) * (a - c));
  return lonely_negative ? corner : 1.0 - corner;
}

/// Fraction of a tetrahedron where phi < 0 (phi = 0 counts as outside).
double tetrahedron_fraction(const std::array<double, 4>& phi) {
  int negatives = 0;
  for (double p : phi) negatives += p < 0.0;
  if (negatives == 0) return 0.0;
  if (negatives == 4) return 1.0;
  if (negatives == 1 || negatives == 3) {
    // one vertex of the other sign: a corner tetrahedron scaled by the three edge ratios
    const bool lonely_negative = negatives == 1;
    int k = 0;
    while ((phi[k] < 0.0) != lonely_negative) ++k;
    double corner = 1.0;
    for (int j = 0; j < 4; ++j)
      if (j != k) corner *= phi[k] / (phi[k] - phi[j]);
    return lonely_negative ? corner : 1.0 - corner;
  }
  // two negatives (i, j), two positives (k, l): the negative part is a prism with triangles
  // (V_i, P_ik, P_il) and (V_j, P_jk, P_jl), split into three tetrahedra
  std::array<int, 2> neg{}, pos{};
  int n = 0, p = 0;
  for (int v = 0; v < 4; ++v) (phi[v] < 0.0 ? neg[n++] : pos[p++]) = v;
  auto cut = [&](int a, int b) {
    const double t = phi[a] / (phi[a] - phi[b]);
    return Eigen::Vector3d(tet_vertex(a) + t * (tet_vertex(b) - tet_vertex(a)));
  };
  const Eigen::Vector3d a0 = tet_vertex(neg[0]), a1 = cut(neg[0], pos[0]), a2 = cut(neg[0], pos[1]);
  const Eigen::Vector3d b0 = tet_vertex(neg[1]), b1 = cut(neg[1], pos[0]), b2 = cut(neg[1], pos[1]);
  // reference tetrahedron volume is 1/6, each |det| is 6 times a volume
  return abs_det(a0, a1, a2, b2) + abs_det(a0, a1, b1, b2) + abs_det(a0, b0, b1, b2);
}

}  // namespace

template <>
double simplex_negative_fraction<2>(const std::array<double, 3>& phi) {
  return triangle_fraction(phi);
}

template <>
double simplex_negative_fraction<3>(const std::array<double, 4>& phi) {
  return tetrahedron_fraction(phi);
}

template <int Dim>
double lattice_cell_negative_fraction(const std::array<double, (1 << Dim)>& corner_phi) {
  // all one sign: exact without splitting
  int negatives = 0;
  for (double p : corner_phi) negatives += p < 0.0;
  if (negatives == 0) return 0.0;
  if (negatives == (1 << Dim)) return 1.0;
  // Kuhn split: one simplex per axis permutation, walking from corner 0 to the opposite corner
  std::array<int, Dim> perm;
  std::iota(perm.begin(), perm.end(), 0);
  double sum = 0.0;
  int count = 0;
  do {
    std::array<double, Dim + 1> simplex;
    int corner = 0;
    simplex[0] = corner_phi[corner];
    for (int m = 0; m < Dim; ++m) {
      corner |= 1 << perm[m];
      simplex[m + 1] = corner_phi[corner];
    }
    sum += simplex_negative_fraction<Dim>(simplex);
    ++count;
  } while (std::next_permutation(perm.begin(), perm.end()));
  return sum / count;
}

template <int Dim>
VectorX solid_phi_on_lattice(const MacGrid<Dim>& /*grid*/, const SampleLattice<Dim>& lattice,
                             const std::vector<ShapePtr<Dim>>& solids, double shrink_in_metres) {
  VectorX phi(lattice.size());
  // min over solids of the signed distance, then shifted inward by zeta (section 4.4.6)
#pragma omp parallel for schedule(static)
  for (int k = 0; k < lattice.size(); ++k) {
    const Vec<Dim> x = lattice.position(lattice.coord(k));
    double d = std::numeric_limits<double>::infinity();
    for (const auto& s : solids) d = std::min(d, s->distance(x));
    phi[k] = d + shrink_in_metres;
  }
  return phi;
}

int map_lattice_cell(int l, int cells2, bool periodic) {
  if (periodic) return ((l % cells2) + cells2) % cells2;
  if (l < 0) return -l - 1;
  if (l >= cells2) return 2 * cells2 - l - 1;
  return l;
}

template <int Dim>
double lattice_cube_negative_fraction(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                      const VecI<Dim>& lower, const VectorX& phi) {
  constexpr int kCorners = 1 << Dim;
  // per axis, the lattice coordinate of corner bit k of sub-cube bit s (after wrapping or
  // mirroring the sub-cube) times the axis stride: 2 x 2 offsets, summed into point indices
  std::array<std::array<std::array<int, 2>, 2>, Dim> offset;
  int stride = 1;
  for (int a = 0; a < Dim; ++a) {
    for (int s = 0; s < 2; ++s) {
      const int l = map_lattice_cell(lower[a] + s, 2 * grid.cells()[a], grid.periodic(a));
      offset[a][s] = {l * stride, (l + 1) * stride};
    }
    stride *= lattice.dims[a];
  }
  // the corner values of every sub-cube; all of one sign (the cube away from the surface, most
  // of the domain) gives 0 or 1 without the Kuhn split (the same value as summing the 2^Dim
  // sub-cubes' 0s or 1s)
  std::array<std::array<double, kCorners>, kCorners> corners;
  int negatives = 0;
  for (int sub = 0; sub < kCorners; ++sub)
    for (int k = 0; k < kCorners; ++k) {
      int index = 0;
      for (int a = 0; a < Dim; ++a) index += offset[a][(sub >> a) & 1][(k >> a) & 1];
      const double v = phi[index];
      corners[sub][k] = v;
      negatives += v < 0.0;
    }
  if (negatives == 0) return 0.0;
  if (negatives == kCorners * kCorners) return 1.0;
  double sum = 0.0;
  for (int sub = 0; sub < kCorners; ++sub) sum += lattice_cell_negative_fraction<Dim>(corners[sub]);
  return sum / kCorners;
}

template <int Dim>
VectorX cell_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                const VectorX& phi) {
  VectorX w(grid.num_cells());
  // the cell control volume is the 2^Dim lattice cells starting at lattice point 2c
#pragma omp parallel for schedule(static)
  for (int i = 0; i < grid.num_cells(); ++i) {
    const VecI<Dim> lower = 2 * grid.cell_coord(i);
    w[i] = lattice_cube_negative_fraction<Dim>(grid, lattice, lower, phi);
  }
  return w;
}

template <int Dim>
VectorX face_negative_fractions(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                const VectorX& phi) {
  VectorX w(grid.num_faces());
  // the face control volume starts half a cell before the face along its normal
#pragma omp parallel for schedule(static)
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    VecI<Dim> lower = 2 * coord;
    lower[axis] -= 1;
    w[f] = lattice_cube_negative_fraction<Dim>(grid, lattice, lower, phi);
  }
  return w;
}

template <int Dim>
VectorX fluid_face_weights(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                           const VectorX& solid_phi,
                           const std::array<BoundaryType, 2 * Dim>& boundary) {
  // fluid = not solid
  VectorX w = VectorX::Ones(grid.num_faces()) - face_negative_fractions(grid, lattice, solid_phi);
  // wall faces carry no fluid; open faces keep the (mirrored) non-solid fraction
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    if (!grid.is_boundary_face(axis, coord)) continue;
    const int side = coord[axis] == 0 ? 0 : 1;
    if (boundary[2 * axis + side] == BoundaryType::wall) w[f] = 0.0;
  }
  return w;
}

VectorX solid_face_weights(const VectorX& fluid_face_weights) {
  return VectorX::Ones(fluid_face_weights.size()) - fluid_face_weights;
}

template <int Dim>
VectorX liquid_cell_weights(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                            const VectorX& liquid_phi) {
  return cell_negative_fractions(grid, lattice, liquid_phi);
}

template <int Dim>
VectorX liquid_face_weights(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                            const VectorX& liquid_phi, const VectorX& liquid_cell_weights) {
  return clamp_liquid_face_weights(grid, face_negative_fractions(grid, lattice, liquid_phi),
                                   liquid_cell_weights);
}

template <int Dim>
VectorX clamp_liquid_face_weights(const MacGrid<Dim>& grid, VectorX w,
                                  const VectorX& liquid_cell_weights) {
  // clamp from below beside every cell with a liquid fraction, so (W_L^u)^-1 exists there
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, coord] = grid.face_coord(f);
    const int minus = grid.face_cell_minus(axis, coord);
    const int plus = grid.face_cell_plus(axis, coord);
    const bool beside_liquid = (minus >= 0 && liquid_cell_weights[minus] > 0.0) ||
                               (plus >= 0 && liquid_cell_weights[plus] > 0.0);
    if (beside_liquid) w[f] = std::max(w[f], kMinLiquidFaceFraction);
  }
  return w;
}

template <int Dim>
VectorX extend_liquid_into_solids(const MacGrid<Dim>& grid, const VectorX& liquid_phi,
                                  const VectorX& solid_phi, double reach) {
  VectorX phi = liquid_phi;
  if (solid_phi.size() != liquid_phi.size()) return phi;
  const double inside = -0.5 * grid.dx();
  // lattice points inside a solid with liquid within reach count as liquid
  for (int k = 0; k < phi.size(); ++k)
    if (solid_phi[k] < 0.0 && liquid_phi[k] < reach) phi[k] = std::min(phi[k], inside);
  return phi;
}

#define MONOLITH_INSTANTIATE(D)                                                                   \
  template double lattice_cell_negative_fraction<D>(const std::array<double, (1 << D)>&);         \
  template double lattice_cube_negative_fraction<D>(const MacGrid<D>&, const SampleLattice<D>&,   \
                                                    const VecI<D>&, const VectorX&);              \
  template VectorX solid_phi_on_lattice<D>(const MacGrid<D>&, const SampleLattice<D>&,            \
                                           const std::vector<ShapePtr<D>>&, double);              \
  template VectorX cell_negative_fractions<D>(const MacGrid<D>&, const SampleLattice<D>&,         \
                                              const VectorX&);                                    \
  template VectorX face_negative_fractions<D>(const MacGrid<D>&, const SampleLattice<D>&,         \
                                              const VectorX&);                                    \
  template VectorX fluid_face_weights<D>(const MacGrid<D>&, const SampleLattice<D>&,              \
                                         const VectorX&, const std::array<BoundaryType, 2 * D>&); \
  template VectorX liquid_cell_weights<D>(const MacGrid<D>&, const SampleLattice<D>&,             \
                                          const VectorX&);                                        \
  template VectorX liquid_face_weights<D>(const MacGrid<D>&, const SampleLattice<D>&,             \
                                          const VectorX&, const VectorX&);                        \
  template VectorX clamp_liquid_face_weights<D>(const MacGrid<D>&, VectorX, const VectorX&);      \
  template VectorX extend_liquid_into_solids<D>(const MacGrid<D>&, const VectorX&,                \
                                                const VectorX&, double);
MONOLITH_INSTANTIATE(2)
MONOLITH_INSTANTIATE(3)
#undef MONOLITH_INSTANTIATE

}  // namespace monolith
