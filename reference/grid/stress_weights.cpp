#include "reference/grid/stress_weights.hpp"

#include "reference/grid/volume_fractions.hpp"

namespace monolith {

template <int Dim>
VecI<Dim> stress_control_volume_lower(const StressGrid<Dim>& stress, int index) {
  const auto [k, c] = stress.coord(index);
  const Vec<Dim> shift = StressGrid<Dim>::shift(k);
  VecI<Dim> lower;
  // the DOF is lattice point 2 c + 2 shift; the cube of side dx spans one lattice step each way
  for (int a = 0; a < Dim; ++a) lower[a] = 2 * c[a] + static_cast<int>(2.0 * shift[a]) - 1;
  return lower;
}

template <int Dim>
void stress_negative_fractions(const StressGrid<Dim>& stress, const SampleLattice<Dim>& lattice,
                               const VectorX& phi, const LatticeSigns<Dim>& signs, VectorX& out) {
  stress_negative_fractions<Dim>(stress, lattice, whole_lattice_values(lattice, phi), signs, out);
}

template <int Dim>
void stress_negative_fractions(const StressGrid<Dim>& stress, const SampleLattice<Dim>& lattice,
                               const LatticeValues<Dim>& phi, const LatticeSigns<Dim>& signs,
                               VectorX& out) {
  if (out.size() != stress.num_dofs()) out.resize(stress.num_dofs());
  // component k's control volumes start at lattice point 2 c + 2 shift(k) - 1: offset -1 on its
  // node-aligned axes, 0 on the cell-centred ones (every component in one parallel region)
  std::vector<VecI<Dim>> dims, offsets;
  std::vector<double*> outs;
  for (int k = 0; k < StressGrid<Dim>::num_components(); ++k) {
    const Vec<Dim> shift = StressGrid<Dim>::shift(k);
    VecI<Dim> offset;
    for (int a = 0; a < Dim; ++a) offset[a] = static_cast<int>(2.0 * shift[a]) - 1;
    dims.push_back(stress.dims(k));
    offsets.push_back(offset);
    outs.push_back(out.data() + stress.offset(k));
  }
  control_volume_negative_fractions<Dim>(stress.grid(), lattice, phi, signs, dims, offsets, outs);
}

template <int Dim>
VectorX stress_negative_fractions(const StressGrid<Dim>& stress, const SampleLattice<Dim>& lattice,
                                  const VectorX& phi) {
  LatticeSigns<Dim> signs;
  classify_lattice_cells(stress.grid(), lattice, phi, signs);
  VectorX w;
  stress_negative_fractions(stress, lattice, phi, signs, w);
  return w;
}

template <int Dim>
void stress_fluid_weights(const StressGrid<Dim>& stress, const SampleLattice<Dim>& lattice,
                          const VectorX& solid_phi, const LatticeSigns<Dim>& signs,
                          const std::array<BoundaryType, 2 * Dim>& boundary, VectorX& w) {
  const MacGrid<Dim>& grid = stress.grid();
  // fluid = not solid (mirrored / wrapped outside the domain)
  stress_negative_fractions(stress, lattice, solid_phi, signs, w);
  w = VectorX::Ones(stress.num_dofs()) - w;  // element-wise into the same storage
  // boundary DOFs: beyond a wall is solid (keep the inside half), an open side has no shear DOF.
  // Only the boundary layers of each shear component are visited, axis a's before axis b's (a
  // DOF on two of them, at an edge, gets both rules in that order)
  for (int k = Dim; k < StressGrid<Dim>::num_components(); ++k) {
    const auto [a, b] = StressGrid<Dim>::component_axes(k);
    const VecI<Dim> dims = stress.dims(k);
    for (int axis : {a, b}) {
      if (grid.periodic(axis)) continue;
      for (int side = 0; side < 2; ++side) {
        const int layer = side == 0 ? 0 : grid.cells()[axis];
        if (layer >= dims[axis]) continue;
        const bool wall = boundary[2 * axis + side] == BoundaryType::wall;
        VecI<Dim> layer_dims = dims;
        layer_dims[axis] = 1;
        const int count = layer_dims.prod();
        for (int j = 0; j < count; ++j) {
          VecI<Dim> c = lattice_coord<Dim>(j, layer_dims);
          c[axis] = layer;
          const int i = stress.offset(k) + lattice_index<Dim>(c, dims);
          if (wall)
            w[i] *= 0.5;
          else
            w[i] = 0.0;
        }
      }
    }
  }
}

template <int Dim>
VectorX stress_fluid_weights(const StressGrid<Dim>& stress, const SampleLattice<Dim>& lattice,
                             const VectorX& solid_phi,
                             const std::array<BoundaryType, 2 * Dim>& boundary) {
  LatticeSigns<Dim> signs;
  classify_lattice_cells(stress.grid(), lattice, solid_phi, signs);
  VectorX w;
  stress_fluid_weights(stress, lattice, solid_phi, signs, boundary, w);
  return w;
}

template <int Dim>
VectorX stress_liquid_weights(const StressGrid<Dim>& stress, const SampleLattice<Dim>& lattice,
                              const VectorX& liquid_phi) {
  return stress_negative_fractions(stress, lattice, liquid_phi);
}

#define MONOLITH_INSTANTIATE(D)                                                                \
  template VecI<D> stress_control_volume_lower<D>(const StressGrid<D>&, int);                  \
  template VectorX stress_negative_fractions<D>(const StressGrid<D>&, const SampleLattice<D>&, \
                                                const VectorX&);                               \
  template VectorX stress_fluid_weights<D>(const StressGrid<D>&, const SampleLattice<D>&,      \
                                           const VectorX&,                                     \
                                           const std::array<BoundaryType, 2 * D>&);            \
  template VectorX stress_liquid_weights<D>(const StressGrid<D>&, const SampleLattice<D>&,     \
                                            const VectorX&);                                   \
  template void stress_negative_fractions<D>(const StressGrid<D>&, const SampleLattice<D>&,    \
                                             const VectorX&, const LatticeSigns<D>&, VectorX&); \
  template void stress_negative_fractions<D>(const StressGrid<D>&, const SampleLattice<D>&,    \
                                             const LatticeValues<D>&, const LatticeSigns<D>&,  \
                                             VectorX&);                                        \
  template void stress_fluid_weights<D>(const StressGrid<D>&, const SampleLattice<D>&,         \
                                        const VectorX&, const LatticeSigns<D>&,                \
                                        const std::array<BoundaryType, 2 * D>&, VectorX&);
MONOLITH_INSTANTIATE(2)
MONOLITH_INSTANTIATE(3)
#undef MONOLITH_INSTANTIATE

}  // namespace monolith
