#pragma once
/// \file mac_grid.hpp
/// The staggered (MAC) grid of section 3.1.2 and the DOF numbering of the unknowns.
///
/// Layout, for cells c in [0, cells) along every axis, with dx the (cubic) cell width:
///  - pressure p and the liquid fraction W_L^p live at cell centres, origin + (c + 1/2) dx;
///  - velocity component a lives on the faces normal to axis a, at origin + (f + 1/2 - e_a/2) dx,
///    with f[a] in [0, cells[a]] (one more face than cells; on a periodic axis face cells[a] is
///    face 0 and is not stored, so f[a] in [0, cells[a])).
///
/// Numbering: cell index = c[0] + cells[0] (c[1] + cells[1] c[2]) (x fastest). Faces of all axes are
/// numbered in one vector, axis 0 first: face index = face_offset(a) + linear index within axis a.
/// This is the order of the velocity vector u of the paper, so G is num_faces x num_cells.
/// The stress DOFs (stress_grid.hpp: cell centres for diagonal components, nodes in 2D / edges in
/// 3D for off-diagonal ones) extend this numbering in the same way.

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

#include "reference/core/common.hpp"

namespace monolith {

/// Linear index of coordinate c in a lattice of size dims, x fastest: the one numbering used for
/// cells, faces of each axis, half-lattice samples and stress DOFs alike.
template <int Dim>
inline int lattice_index(const VecI<Dim>& c, const VecI<Dim>& dims) {
  int index = 0;
  for (int a = Dim - 1; a >= 0; --a) index = index * dims[a] + c[a];
  return index;
}

/// Inverse of lattice_index.
template <int Dim>
inline VecI<Dim> lattice_coord(int index, const VecI<Dim>& dims) {
  VecI<Dim> c;
  for (int a = 0; a < Dim; ++a) {
    c[a] = index % dims[a];
    index /= dims[a];
  }
  return c;
}

template <int Dim>
class MacGrid {
 public:
  MacGrid() = default;
  MacGrid(const Vec<Dim>& origin, double dx, const VecI<Dim>& cells,
          const std::array<bool, Dim>& periodic);

  const Vec<Dim>& origin() const { return origin_; }
  double dx() const { return dx_; }
  const VecI<Dim>& cells() const { return cells_; }
  bool periodic(int axis) const { return periodic_[axis]; }
  const std::array<bool, Dim>& periodic() const { return periodic_; }
  /// The domain [origin, origin + cells dx].
  Box<Dim> domain_box() const;
  /// Cell volume dx^Dim.
  double cell_volume() const;

  // --- cells (pressure DOFs) -------------------------------------------------------------------
  int num_cells() const { return num_cells_; }
  int cell_index(const VecI<Dim>& c) const;
  VecI<Dim> cell_coord(int index) const;
  bool cell_in_range(const VecI<Dim>& c) const;
  Vec<Dim> cell_center(const VecI<Dim>& c) const;
  /// Wraps periodic axes into range; non-periodic axes are left as they are.
  VecI<Dim> wrap_cell(VecI<Dim> c) const;
  /// Index of cell c after periodic wrapping, or -1 if it lies outside the domain.
  int cell_index_or_outside(const VecI<Dim>& c) const;
  /// The cell containing point x (clamped to the domain).
  VecI<Dim> cell_containing(const Vec<Dim>& x) const;

  // --- faces (velocity DOFs) -------------------------------------------------------------------
  /// Number of faces normal to `axis` along each direction.
  VecI<Dim> face_dims(int axis) const { return face_dims_[axis]; }
  int num_faces(int axis) const { return face_count_[axis]; }
  int num_faces() const { return face_offset_[Dim]; }
  int face_offset(int axis) const { return face_offset_[axis]; }
  int face_index(int axis, const VecI<Dim>& f) const;
  /// Index of the face normal to `axis` at f after periodic wrapping (face_dims(axis) per axis),
  /// or -1 if it lies outside the domain.
  int face_index_or_outside(int axis, VecI<Dim> f) const;
  /// (axis, coordinate) of a global face index.
  std::pair<int, VecI<Dim>> face_coord(int index) const;
  Vec<Dim> face_center(int axis, const VecI<Dim>& f) const;
  /// True for faces on the domain boundary (never on a periodic axis).
  bool is_boundary_face(int axis, const VecI<Dim>& f) const;
  /// The cell on the minus side (f - e_axis) and plus side (f) of a face, wrapped on periodic
  /// axes; -1 where that cell is outside the domain.
  int face_cell_minus(int axis, const VecI<Dim>& f) const;
  int face_cell_plus(int axis, const VecI<Dim>& f) const;

  // --- positions -------------------------------------------------------------------------------
  /// Wraps x into the domain along periodic axes.
  Vec<Dim> wrap_position(Vec<Dim> x) const;

  // --- interpolation (multilinear; constant beyond the outermost samples; periodic wrap) -------
  /// Component `axis` of a face field u at x.
  double interpolate_face(const VectorX& u, int axis, const Vec<Dim>& x) const;
  /// The full velocity vector of face field u at x.
  Vec<Dim> interpolate_velocity(const VectorX& u, const Vec<Dim>& x) const;
  /// A cell-centred field q at x.
  double interpolate_cell(const VectorX& q, const Vec<Dim>& x) const;

  /// Multilinear stencil of a sample lattice at origin + (index + shift) dx with `dims` samples
  /// per axis: writes the 2^Dim (linear sample index, weight) pairs into idx and w. Used by
  /// interpolation and the particle transfers. `shift` is 0.5 on cell-centred axes, 0 on
  /// node-aligned ones. The gradient of the weights (per unit length) goes into grad if not null.
  void stencil(const Vec<Dim>& x, const Vec<Dim>& shift, const VecI<Dim>& dims,
               std::array<int, (1 << Dim)>& idx, std::array<double, (1 << Dim)>& w,
               std::array<Vec<Dim>, (1 << Dim)>* grad = nullptr) const;
  /// shift vector of the faces normal to `axis` (0.5 everywhere but 0 along axis).
  static Vec<Dim> face_shift(int axis);

  /// One axis of stencil(): the two sample indices, their linear weights and the weights'
  /// derivatives at the lattice coordinate s = (x - origin) / dx - shift on an axis of n samples.
  /// stencil()'s corner k takes entry bit a of k on axis a; its weight is the product of the
  /// axes' weights in axis order (1.0 times axis 0's, times axis 1's, ...).
  struct AxisStencil {
    std::array<int, 2> index;
    std::array<double, 2> weight, slope;
  };
  AxisStencil axis_stencil(int axis, double s, int n) const;

 private:
  /// Component `axis` of u from the grid coordinates q = (x - origin) / dx of a wrapped point.
  double interpolate_face_at(const VectorX& u, int axis, const Vec<Dim>& q) const;

  Vec<Dim> origin_ = Vec<Dim>::Zero();
  double dx_ = 1.0;
  VecI<Dim> cells_ = VecI<Dim>::Ones();
  std::array<bool, Dim> periodic_{};
  int num_cells_ = 1;
  std::array<VecI<Dim>, Dim> face_dims_{};
  std::array<int, Dim> face_count_{};
  std::array<int, Dim + 1> face_offset_{};
};

// --- index arithmetic, inline: the inner loops of the transfers and weights call these per
// face and per particle

template <int Dim>
inline int MacGrid<Dim>::cell_index(const VecI<Dim>& c) const {
  return lattice_index<Dim>(c, cells_);
}

template <int Dim>
inline VecI<Dim> MacGrid<Dim>::cell_coord(int index) const {
  return lattice_coord<Dim>(index, cells_);
}

template <int Dim>
inline bool MacGrid<Dim>::cell_in_range(const VecI<Dim>& c) const {
  for (int a = 0; a < Dim; ++a)
    if (c[a] < 0 || c[a] >= cells_[a]) return false;
  return true;
}

template <int Dim>
inline VecI<Dim> MacGrid<Dim>::wrap_cell(VecI<Dim> c) const {
  for (int a = 0; a < Dim; ++a)
    if (periodic_[a]) c[a] = ((c[a] % cells_[a]) + cells_[a]) % cells_[a];
  return c;
}

template <int Dim>
inline int MacGrid<Dim>::cell_index_or_outside(const VecI<Dim>& c) const {
  const VecI<Dim> w = wrap_cell(c);
  return cell_in_range(w) ? cell_index(w) : -1;
}

template <int Dim>
inline int MacGrid<Dim>::face_index(int axis, const VecI<Dim>& f) const {
  return face_offset_[axis] + lattice_index<Dim>(f, face_dims_[axis]);
}

template <int Dim>
inline int MacGrid<Dim>::face_index_or_outside(int axis, VecI<Dim> f) const {
  const VecI<Dim>& dims = face_dims_[axis];
  for (int a = 0; a < Dim; ++a) {
    if (periodic_[a]) f[a] = ((f[a] % dims[a]) + dims[a]) % dims[a];
    if (f[a] < 0 || f[a] >= dims[a]) return -1;
  }
  return face_index(axis, f);
}

template <int Dim>
inline std::pair<int, VecI<Dim>> MacGrid<Dim>::face_coord(int index) const {
  int axis = 0;
  while (index >= face_offset_[axis + 1]) ++axis;
  return {axis, lattice_coord<Dim>(index - face_offset_[axis], face_dims_[axis])};
}

template <int Dim>
inline Vec<Dim> MacGrid<Dim>::face_center(int axis, const VecI<Dim>& f) const {
  return origin_ + (f.template cast<double>() + face_shift(axis)) * dx_;
}

template <int Dim>
inline bool MacGrid<Dim>::is_boundary_face(int axis, const VecI<Dim>& f) const {
  return !periodic_[axis] && (f[axis] == 0 || f[axis] == cells_[axis]);
}

template <int Dim>
inline int MacGrid<Dim>::face_cell_minus(int axis, const VecI<Dim>& f) const {
  VecI<Dim> c = f;
  c[axis] -= 1;
  return cell_index_or_outside(c);
}

template <int Dim>
inline int MacGrid<Dim>::face_cell_plus(int /*axis*/, const VecI<Dim>& f) const {
  return cell_index_or_outside(f);
}

template <int Dim>
inline Vec<Dim> MacGrid<Dim>::face_shift(int axis) {
  Vec<Dim> s = Vec<Dim>::Constant(0.5);
  s[axis] = 0.0;
  return s;
}

// --- positions and interpolation, inline: advection, the transfers and the viscosity samples
// call these per particle (the out-of-line stencil was 4 % of a 64^3 drop's profile)

template <int Dim>
inline Vec<Dim> MacGrid<Dim>::wrap_position(Vec<Dim> x) const {
  for (int a = 0; a < Dim; ++a) {
    if (!periodic_[a]) continue;
    const double length = cells_[a] * dx_;
    x[a] = origin_[a] + std::fmod(std::fmod(x[a] - origin_[a], length) + length, length);
    if (x[a] >= origin_[a] + length) x[a] = origin_[a];  // fmod round-off at the upper end
  }
  return x;
}

template <int Dim>
inline typename MacGrid<Dim>::AxisStencil MacGrid<Dim>::axis_stencil(int a, double s,
                                                                     int n) const {
  AxisStencil st;
  if (periodic_[a]) {
    const int i0 = static_cast<int>(std::floor(s));
    const double t = s - i0;
    st.index = {((i0 % n) + n) % n, (((i0 + 1) % n) + n) % n};
    st.weight = {1.0 - t, t};
    st.slope = {-1.0 / dx_, 1.0 / dx_};
  } else if (n == 1) {
    st.index = {0, 0};
    st.weight = {1.0, 0.0};
    st.slope = {0.0, 0.0};
  } else {
    // constant extrapolation beyond the outermost samples
    // (sc >= 0: the conversion's truncation is the floor, without floor's SSE2 sequence for
    // any sign and magnitude, inlined at every stencil of the transfers and advection)
    const double sc = std::clamp(s, 0.0, static_cast<double>(n - 1));
    const int i0 = std::min(static_cast<int>(sc), n - 2);
    const double t = sc - i0;
    const bool inside = s > 0.0 && s < n - 1;
    st.index = {i0, i0 + 1};
    st.weight = {1.0 - t, t};
    st.slope = inside ? std::array<double, 2>{-1.0 / dx_, 1.0 / dx_}
                      : std::array<double, 2>{0.0, 0.0};
  }
  return st;
}

template <int Dim>
inline void MacGrid<Dim>::stencil(const Vec<Dim>& x, const Vec<Dim>& shift, const VecI<Dim>& dims,
                                  std::array<int, (1 << Dim)>& idx,
                                  std::array<double, (1 << Dim)>& w,
                                  std::array<Vec<Dim>, (1 << Dim)>* grad) const {
  // per axis: the two sample indices and the linear weights (and their derivatives)
  std::array<AxisStencil, Dim> st;
  for (int a = 0; a < Dim; ++a) st[a] = axis_stencil(a, (x[a] - origin_[a]) / dx_ - shift[a], dims[a]);
  for (int corner = 0; corner < (1 << Dim); ++corner) {
    int index = 0;
    double weight = 1.0;
    for (int a = Dim - 1; a >= 0; --a) index = index * dims[a] + st[a].index[(corner >> a) & 1];
    for (int a = 0; a < Dim; ++a) weight *= st[a].weight[(corner >> a) & 1];
    idx[corner] = index;
    w[corner] = weight;
    if (grad) {
      Vec<Dim> g;
      for (int a = 0; a < Dim; ++a) {
        double ga = st[a].slope[(corner >> a) & 1];
        for (int b = 0; b < Dim; ++b)
          if (b != a) ga *= st[b].weight[(corner >> b) & 1];
        g[a] = ga;
      }
      (*grad)[corner] = g;
    }
  }
}

template <int Dim>
inline double MacGrid<Dim>::interpolate_face_at(const VectorX& u, int axis,
                                                const Vec<Dim>& q) const {
  // stencil() at the face lattice of `axis` (shift 0.5 but 0 along axis), summed as it would be
  const VecI<Dim>& dims = face_dims_[axis];
  std::array<AxisStencil, Dim> st;
  for (int a = 0; a < Dim; ++a) st[a] = axis_stencil(a, q[a] - (a == axis ? 0.0 : 0.5), dims[a]);
  const double* base = u.data() + face_offset_[axis];
  double value = 0.0;
  for (int corner = 0; corner < (1 << Dim); ++corner) {
    int index = 0;
    double weight = 1.0;
    for (int a = Dim - 1; a >= 0; --a) index = index * dims[a] + st[a].index[(corner >> a) & 1];
    for (int a = 0; a < Dim; ++a) weight *= st[a].weight[(corner >> a) & 1];
    value += weight * base[index];
  }
  return value;
}

template <int Dim>
inline double MacGrid<Dim>::interpolate_face(const VectorX& u, int axis, const Vec<Dim>& x) const {
  const Vec<Dim> xw = wrap_position(x);
  Vec<Dim> q;
  for (int a = 0; a < Dim; ++a) q[a] = (xw[a] - origin_[a]) / dx_;
  return interpolate_face_at(u, axis, q);
}

template <int Dim>
inline Vec<Dim> MacGrid<Dim>::interpolate_velocity(const VectorX& u, const Vec<Dim>& x) const {
  // one wrap and one division per axis for the Dim components
  const Vec<Dim> xw = wrap_position(x);
  Vec<Dim> q;
  for (int a = 0; a < Dim; ++a) q[a] = (xw[a] - origin_[a]) / dx_;
  Vec<Dim> v;
  for (int a = 0; a < Dim; ++a) v[a] = interpolate_face_at(u, a, q);
  return v;
}

template <int Dim>
inline double MacGrid<Dim>::interpolate_cell(const VectorX& q, const Vec<Dim>& x) const {
  std::array<int, (1 << Dim)> idx;
  std::array<double, (1 << Dim)> w;
  stencil(wrap_position(x), Vec<Dim>::Constant(0.5), cells_, idx, w);
  double value = 0.0;
  for (int k = 0; k < (1 << Dim); ++k) value += w[k] * q[idx[k]];
  return value;
}

/// A regular lattice of sample points origin + index * spacing, index in [0, dims) (x fastest).
/// The canonical one is the half lattice of a MacGrid (spacing dx/2, dims 2 cells + 1): it holds
/// every cell centre, face centre, node and (3D) edge centre, so the corners of every control
/// volume (cell, face, and the stress control volumes of stress_grid.hpp) are lattice points, and level
/// sets sampled on it give all volume fractions (volume_fractions.hpp) without re-sampling.
template <int Dim>
struct SampleLattice {
  Vec<Dim> origin = Vec<Dim>::Zero();
  double spacing = 1.0;
  VecI<Dim> dims = VecI<Dim>::Ones();

  int size() const { return dims.prod(); }
  int index(const VecI<Dim>& i) const { return lattice_index<Dim>(i, dims); }
  VecI<Dim> coord(int k) const { return lattice_coord<Dim>(k, dims); }
  Vec<Dim> position(const VecI<Dim>& i) const {
    return origin + i.template cast<double>() * spacing;
  }
  /// Multilinear interpolation of samples q at x (clamped to the lattice).
  double interpolate(const VectorX& q, const Vec<Dim>& x) const;
};

/// The half lattice of a grid: spacing dx/2, dims 2 cells + 1, origin at the grid origin.
template <int Dim>
SampleLattice<Dim> half_lattice(const MacGrid<Dim>& grid);

}  // namespace monolith
