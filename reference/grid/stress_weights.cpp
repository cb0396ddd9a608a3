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
VectorX stress_negative_fractions(const StressGrid<Dim>& stress, const SampleLattice<Dim>& lattice,
                                  const VectorX& phi) {
  const MacGrid<Dim>& grid = stress.grid();
  VectorX w(stress.num_dofs());
#pragma omp parallel for schedule(static)
  for (int i = 0; i < stress.num_dofs(); ++i)
    w[i] = lattice_cube_negative_fraction<Dim>(grid, lattice, stress_control_volume_lower(stress, i),
                                              phi);
  return w;
}

template <int Dim>
VectorX stress_fluid_weights(const StressGrid<Dim>& stress, const SampleLattice<Dim>& lattice,
                             const VectorX& solid_phi,
                             const std::array<BoundaryType, 2 * Dim>& boundary) {
  const MacGrid<Dim>& grid = stress.grid();
  // fluid = not solid (mirrored / wrapped outside the domain)
  VectorX w =
      VectorX::Ones(stress.num_dofs()) - stress_negative_fractions(stress, lattice, solid_phi);
  // boundary DOFs: beyond a wall is solid (keep the inside half), an open side has no shear DOF
  for (int i = 0; i < stress.num_dofs(); ++i) {
    const auto [k, c] = stress.coord(i);
    if (!stress.is_boundary(k, c)) continue;
    const auto [a, b] = StressGrid<Dim>::component_axes(k);
    for (int axis : {a, b}) {
      if (grid.periodic(axis)) continue;
      int side = -1;
      if (c[axis] == 0) side = 0;
      if (c[axis] == grid.cells()[axis]) side = 1;
      if (side < 0) continue;
      if (boundary[2 * axis + side] == BoundaryType::wall)
        w[i] *= 0.5;
      else
        w[i] = 0.0;
    }
  }
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
                                            const VectorX&);
MONOLITH_INSTANTIATE(2)
MONOLITH_INSTANTIATE(3)
#undef MONOLITH_INSTANTIATE

}  // namespace monolith
