#include "reference/grid/mac_grid.hpp"

#include <algorithm>
#include <cmath>

namespace monolith {

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
