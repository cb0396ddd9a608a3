#include "reference/grid/mac_grid.hpp"

#include <algorithm>
#include <cmath>

namespace monolith {

namespace {
int wrap(int i, int n) { return ((i % n) + n) % n; }
}  // namespace

template <int Dim>
MacGrid<Dim>::MacGrid(const Vec<Dim>& origin, double dx, const VecI<Dim>& cells,
                      const std::array<bool, Dim>& periodic)
    : origin_(origin), dx_(dx), cells_(cells), periodic_(periodic) {
  num_cells_ = cells_.prod();
  face_offset_[0] = 0;
  for (int a = 0; a < Dim; ++a) {
    // one more face than cells along the face normal, unless that axis is periodic
    face_dims_[a] = cells_;
    if (!periodic_[a]) face_dims_[a][a] += 1;
    face_count_[a] = face_dims_[a].prod();
    face_offset_[a + 1] = face_offset_[a] + face_count_[a];
  }
}

template <int Dim>
Box<Dim> MacGrid<Dim>::domain_box() const {
  return Box<Dim>(origin_, origin_ + cells_.template cast<double>() * dx_);
}

template <int Dim>
double MacGrid<Dim>::cell_volume() const {
  return std::pow(dx_, Dim);
}

template <int Dim>
Vec<Dim> MacGrid<Dim>::cell_center(const VecI<Dim>& c) const {
  return origin_ + (c.template cast<double>().array() + 0.5).matrix() * dx_;
}

template <int Dim>
VecI<Dim> MacGrid<Dim>::cell_containing(const Vec<Dim>& x) const {
  VecI<Dim> c;
  for (int a = 0; a < Dim; ++a) {
    const int i = static_cast<int>(std::floor((x[a] - origin_[a]) / dx_));
    c[a] = std::clamp(i, 0, cells_[a] - 1);
  }
  return c;
}

template <int Dim>
Vec<Dim> MacGrid<Dim>::wrap_position(Vec<Dim> x) const {
  for (int a = 0; a < Dim; ++a) {
    if (!periodic_[a]) continue;
    const double length = cells_[a] * dx_;
    x[a] = origin_[a] + std::fmod(std::fmod(x[a] - origin_[a], length) + length, length);
    if (x[a] >= origin_[a] + length) x[a] = origin_[a];  // fmod round-off at the upper end
  }
  return x;
}

template <int Dim>
void MacGrid<Dim>::stencil(const Vec<Dim>& x, const Vec<Dim>& shift, const VecI<Dim>& dims,
                           std::array<int, (1 << Dim)>& idx, std::array<double, (1 << Dim)>& w,
                           std::array<Vec<Dim>, (1 << Dim)>* grad) const {
  // per axis: the two sample indices and the linear weights (and their derivatives)
  std::array<std::array<int, 2>, Dim> i01;
  std::array<std::array<double, 2>, Dim> w01, dw01;
  for (int a = 0; a < Dim; ++a) {
    const double s = (x[a] - origin_[a]) / dx_ - shift[a];
    if (periodic_[a]) {
      const int i0 = static_cast<int>(std::floor(s));
      const double t = s - i0;
      i01[a] = {wrap(i0, dims[a]), wrap(i0 + 1, dims[a])};
      w01[a] = {1.0 - t, t};
      dw01[a] = {-1.0 / dx_, 1.0 / dx_};
    } else if (dims[a] == 1) {
      i01[a] = {0, 0};
      w01[a] = {1.0, 0.0};
      dw01[a] = {0.0, 0.0};
    } else {
      // constant extrapolation beyond the outermost samples
      const double sc = std::clamp(s, 0.0, static_cast<double>(dims[a] - 1));
      const int i0 = std::min(static_cast<int>(std::floor(sc)), dims[a] - 2);
      const double t = sc - i0;
      const bool inside = s > 0.0 && s < dims[a] - 1;
      i01[a] = {i0, i0 + 1};
      w01[a] = {1.0 - t, t};
      dw01[a] = inside ? std::array<double, 2>{-1.0 / dx_, 1.0 / dx_}
                       : std::array<double, 2>{0.0, 0.0};
    }
  }
  for (int corner = 0; corner < (1 << Dim); ++corner) {
    VecI<Dim> c;
    double weight = 1.0;
    for (int a = 0; a < Dim; ++a) {
      const int bit = (corner >> a) & 1;
      c[a] = i01[a][bit];
      weight *= w01[a][bit];
    }
    idx[corner] = lattice_index<Dim>(c, dims);
    w[corner] = weight;
    if (grad) {
      Vec<Dim> g;
      for (int a = 0; a < Dim; ++a) {
        double ga = dw01[a][(corner >> a) & 1];
        for (int b = 0; b < Dim; ++b)
          if (b != a) ga *= w01[b][(corner >> b) & 1];
        g[a] = ga;
      }
      (*grad)[corner] = g;
    }
  }
}

template <int Dim>
double MacGrid<Dim>::interpolate_face(const VectorX& u, int axis, const Vec<Dim>& x) const {
  std::array<int, (1 << Dim)> idx;
  std::array<double, (1 << Dim)> w;
  stencil(wrap_position(x), face_shift(axis), face_dims_[axis], idx, w);
  double value = 0.0;
  for (int k = 0; k < (1 << Dim); ++k) value += w[k] * u[face_offset_[axis] + idx[k]];
  return value;
}

template <int Dim>
Vec<Dim> MacGrid<Dim>::interpolate_velocity(const VectorX& u, const Vec<Dim>& x) const {
  Vec<Dim> v;
  for (int a = 0; a < Dim; ++a) v[a] = interpolate_face(u, a, x);
  return v;
}

template <int Dim>
double MacGrid<Dim>::interpolate_cell(const VectorX& q, const Vec<Dim>& x) const {
  std::array<int, (1 << Dim)> idx;
  std::array<double, (1 << Dim)> w;
  stencil(wrap_position(x), Vec<Dim>::Constant(0.5), cells_, idx, w);
  double value = 0.0;
  for (int k = 0; k < (1 << Dim); ++k) value += w[k] * q[idx[k]];
  return value;
}

template <int Dim>
double SampleLattice<Dim>::interpolate(const VectorX& q, const Vec<Dim>& x) const {
  std::array<int, Dim> i0;
  std::array<double, Dim> t;
  for (int a = 0; a < Dim; ++a) {
    const double s = std::clamp((x[a] - origin[a]) / spacing, 0.0, double(dims[a] - 1));
    i0[a] = std::min(static_cast<int>(s), std::max(dims[a] - 2, 0));
    t[a] = dims[a] > 1 ? s - i0[a] : 0.0;
  }
  double value = 0.0;
  for (int corner = 0; corner < (1 << Dim); ++corner) {
    VecI<Dim> c;
    double w = 1.0;
    for (int a = 0; a < Dim; ++a) {
      const int bit = (corner >> a) & 1;
      c[a] = std::min(i0[a] + bit, dims[a] - 1);
      w *= bit ? t[a] : 1.0 - t[a];
    }
    if (w != 0.0) value += w * q[index(c)];
  }
  return value;
}

template <int Dim>
SampleLattice<Dim> half_lattice(const MacGrid<Dim>& grid) {
  SampleLattice<Dim> lattice;
  lattice.origin = grid.origin();
  lattice.spacing = 0.5 * grid.dx();
  lattice.dims = (2 * grid.cells().array() + 1).matrix();
  return lattice;
}

template class MacGrid<2>;
template class MacGrid<3>;
template struct SampleLattice<2>;
template struct SampleLattice<3>;
template SampleLattice<2> half_lattice(const MacGrid<2>&);
template SampleLattice<3> half_lattice(const MacGrid<3>&);

}  // namespace monolith
