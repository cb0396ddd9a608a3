/// \file viscosity_field.cpp
/// eta per stress DOF and per cell from the particles (viscosity_field.hpp).

#include "reference/fluid/viscosity_field.hpp"

#include <array>

#include "reference/core/parallel.hpp"

namespace monolith {

std::vector<double> liquid_viscosities(const std::vector<LiquidSpec>& liquids) {
  std::vector<double> eta;
  eta.reserve(liquids.size());
  for (const auto& l : liquids)
    eta.push_back(l.viscosity.model == ViscosityModel::newtonian ? l.viscosity.eta : 0.0);
  return eta;
}

template <int Dim>
VectorX sample_viscosity(const MacGrid<Dim>& grid, const Vec<Dim>& shift, const VecI<Dim>& dims,
                         const Particles<Dim>& particles, const std::vector<double>& liquid_eta) {
  constexpr int kCorners = 1 << Dim;
  const int n = dims.prod();
  // mass-weighted sums over the particles (serial: the cost is small beside the solve and the
  // order of the sums stays fixed for any thread count)
  VectorX mass = VectorX::Zero(n), mass_eta = VectorX::Zero(n);
  double total_mass = 0.0, total_mass_eta = 0.0;
  std::array<int, kCorners> idx;
  std::array<double, kCorners> w;
  for (std::size_t p = 0; p < particles.size(); ++p) {
    const int liquid = particles.liquid[p];
    const double eta =
        liquid >= 0 && liquid < static_cast<int>(liquid_eta.size()) ? liquid_eta[liquid] : 0.0;
    const double mp = particles.mass[p];
    total_mass += mp;
    total_mass_eta += mp * eta;
    grid.stencil(grid.wrap_position(particles.x[p]), shift, dims, idx, w);
    for (int k = 0; k < kCorners; ++k) {
      if (w[k] == 0.0) continue;
      mass[idx[k]] += w[k] * mp;
      mass_eta[idx[k]] += w[k] * mp * eta;
    }
  }
  VectorX eta = VectorX::Zero(n);
  std::vector<char> known(n, 0);
  std::vector<int> frontier;  // the samples made known in the last round
  for (int i = 0; i < n; ++i)
    if (mass[i] > 0.0) {
      eta[i] = mass_eta[i] / mass[i];
      known[i] = 1;
      frontier.push_back(i);
    }
  // the axis neighbour of c in direction s along a, -1 outside a non-periodic lattice
  auto neighbour = [&](const VecI<Dim>& c, int a, int s) {
    VecI<Dim> d = c;
    d[a] += s;
    if (grid.periodic(a))
      d[a] = (d[a] % dims[a] + dims[a]) % dims[a];
    else if (d[a] < 0 || d[a] >= dims[a])
      return -1;
    return lattice_index<Dim>(d, dims);
  };
  // fill: unreached samples take the mean of their reached axis neighbours, ring by ring. Only
  // the unreached neighbours of the last ring are visited (the lattice is mostly far from the
  // liquid); each takes the same sum in the same neighbour order as a sweep over the whole
  // lattice would, and reads only samples known before the ring.
  std::vector<char> queued(n, 0);
  std::vector<int> candidates, filled;
  for (int layer = 0; layer < kViscosityFillLayers && !frontier.empty(); ++layer) {
    candidates.clear();
    for (int i : frontier) {
      const VecI<Dim> c = lattice_coord<Dim>(i, dims);
      for (int a = 0; a < Dim; ++a)
        for (int s : {-1, 1}) {
          const int j = neighbour(c, a, s);
          if (j >= 0 && !known[j] && !queued[j]) {
            queued[j] = 1;
            candidates.push_back(j);
          }
        }
    }
    filled.clear();
    for (int i : candidates) {
      queued[i] = 0;
      const VecI<Dim> c = lattice_coord<Dim>(i, dims);
      double sum = 0.0;
      int count = 0;
      for (int a = 0; a < Dim; ++a)
        for (int s : {-1, 1}) {
          const int j = neighbour(c, a, s);
          if (j < 0 || !known[j]) continue;
          sum += eta[j];
          ++count;
        }
      if (count > 0) {
        eta[i] = sum / count;
        filled.push_back(i);
      }
    }
    for (int i : filled) known[i] = 1;
    frontier.swap(filled);
  }
  // the rest: the mean viscosity of the whole liquid
  const double mean = total_mass > 0.0 ? total_mass_eta / total_mass : 0.0;
  for (int i = 0; i < n; ++i)
    if (!known[i]) eta[i] = mean;
  return eta;
}

template <int Dim>
VectorX stress_viscosity(const StressGrid<Dim>& stress, const Particles<Dim>& particles,
                         const std::vector<double>& liquid_eta) {
  VectorX eta(stress.num_dofs());
  // the components on several threads, each made whole by one thread (serially, as above), into
  // its own segment: the same bits for any team size
  constexpr int components = StressGrid<Dim>::num_components();
#pragma omp parallel for schedule(dynamic, 1) num_threads(team_threads(static_cast<long>(particles.size()) * components))
  for (int k = 0; k < components; ++k)
    eta.segment(stress.offset(k), stress.num_dofs(k)) =
        sample_viscosity(stress.grid(), StressGrid<Dim>::shift(k), stress.dims(k), particles,
                         liquid_eta);
  return eta;
}

template <int Dim>
VectorX cell_viscosity(const MacGrid<Dim>& grid, const Particles<Dim>& particles,
                       const std::vector<double>& liquid_eta) {
  return sample_viscosity<Dim>(grid, Vec<Dim>::Constant(0.5), grid.cells(), particles, liquid_eta);
}

template <int Dim>
std::vector<VectorX> liquid_stress_fractions(const StressGrid<Dim>& stress,
                                             const Particles<Dim>& particles, int num_liquids) {
  std::vector<VectorX> fractions;
  for (int i = 0; i < num_liquids; ++i) {
    // an indicator "viscosity": 1 for liquid i
    std::vector<double> indicator(num_liquids, 0.0);
    indicator[i] = 1.0;
    fractions.push_back(stress_viscosity(stress, particles, indicator));
  }
  return fractions;
}

#define MONOLITH_INSTANTIATE_VISCOSITY_FIELD(D)                                                   \
  template VectorX sample_viscosity(const MacGrid<D>&, const Vec<D>&, const VecI<D>&,           \
                                    const Particles<D>&, const std::vector<double>&);             \
  template VectorX stress_viscosity(const StressGrid<D>&, const Particles<D>&,                    \
                                    const std::vector<double>&);                                  \
  template VectorX cell_viscosity(const MacGrid<D>&, const Particles<D>&,                         \
                                  const std::vector<double>&);                                    \
  template std::vector<VectorX> liquid_stress_fractions(const StressGrid<D>&, const Particles<D>&, \
                                                        int);

MONOLITH_INSTANTIATE_VISCOSITY_FIELD(2)
MONOLITH_INSTANTIATE_VISCOSITY_FIELD(3)

#undef MONOLITH_INSTANTIATE_VISCOSITY_FIELD

}  // namespace monolith
