/// \file viscosity_field.cpp
/// eta per stress DOF and per cell from the particles (viscosity_field.hpp).

#include "reference/fluid/viscosity_field.hpp"

#include <algorithm>
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
  constexpr int kLast = Dim - 1;
  const int n = dims.prod();
  const long np = static_cast<long>(particles.size());
  // mass-weighted sums over the particles. On several threads (one called from the outside,
  // not from stress_viscosity's components, which run side by side on one thread each): the
  // samples are split into slabs of layers of the last axis (contiguous index ranges, the last
  // axis being the slowest), one per thread; each thread walks all particles in order, skips
  // those whose stencil misses its slab and adds only into its own samples, so every sample sums
  // its particles in the order of the serial loop (the same bits for any team). The slabs cut
  // the particles' layers into equal counts (any bounds give the same bits). The totals are
  // summed in particle order by the first slab's thread.
  const int layers = dims[kLast];
  const long plane = n / std::max(1, layers);
  const double shift_last = shift[kLast];
  const auto last_stencil = [&](long p) {
    const double xl = grid.wrap_position(particles.x[p])[kLast];
    return grid.axis_stencil(kLast, (xl - grid.origin()[kLast]) / grid.dx() - shift_last, layers);
  };
  const int slabs = static_cast<int>(std::max(1L, std::min<long>(team_threads(np), layers)));
  std::vector<int> slab_first(slabs + 1, 0);
  slab_first[slabs] = layers;
  if (slabs > 1) {
    std::vector<int> layer_of(np);
#pragma omp parallel for schedule(static) num_threads(slabs)
    for (long p = 0; p < np; ++p) layer_of[p] = last_stencil(p).index[0];
    std::vector<long> histogram(layers + 1, 0);
    for (long p = 0; p < np; ++p) ++histogram[layer_of[p] + 1];
    for (int l = 0; l < layers; ++l) histogram[l + 1] += histogram[l];
    int l = 0;
    for (int k = 1; k < slabs; ++k) {
      // slab k starts at the first layer whose running count reaches k / slabs of np
      while (l < layers && histogram[l + 1] * slabs < np * k) ++l;
      slab_first[k] = std::max(l, slab_first[k - 1]);
    }
  }
  VectorX mass(n), mass_eta(n);
  double total_mass = 0.0, total_mass_eta = 0.0;
#pragma omp parallel for schedule(static, 1) num_threads(slabs)
  for (int slab = 0; slab < slabs; ++slab) {
    const int first = slab_first[slab], end = slab_first[slab + 1];
    std::fill(mass.data() + first * plane, mass.data() + end * plane, 0.0);
    std::fill(mass_eta.data() + first * plane, mass_eta.data() + end * plane, 0.0);
    const auto owned = [&](int layer) { return layer >= first && layer < end; };
    std::array<int, kCorners> idx;
    std::array<double, kCorners> w;
    for (long p = 0; p < np; ++p) {
      const int liquid = particles.liquid[p];
      const double eta =
          liquid >= 0 && liquid < static_cast<int>(liquid_eta.size()) ? liquid_eta[liquid] : 0.0;
      const double mp = particles.mass[p];
      if (slab == 0) {
        total_mass += mp;
        total_mass_eta += mp * eta;
      }
      if (slabs > 1) {
        const auto st = last_stencil(p);
        if (!owned(st.index[0]) && !owned(st.index[1])) continue;
      }
      grid.stencil(grid.wrap_position(particles.x[p]), shift, dims, idx, w);
      for (int k = 0; k < kCorners; ++k) {
        if (w[k] == 0.0 || !owned(static_cast<int>(idx[k] / plane))) continue;
        mass[idx[k]] += w[k] * mp;
        mass_eta[idx[k]] += w[k] * mp * eta;
      }
    }
  }
  VectorX eta(n);
  std::vector<char> known(n);  // (each entry written below)
  // the samples a particle reached, in index order (fixed blocks joined in order)
  std::vector<int> frontier = gather_in_order<int>(n, [&](int i, std::vector<int>& out) {
    if (mass[i] > 0.0) {
      eta[i] = mass_eta[i] / mass[i];
      known[i] = 1;
      out.push_back(i);
    } else {
      eta[i] = 0.0;
      known[i] = 0;
    }
  });
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
#pragma omp parallel for schedule(static) num_threads(team_threads(n))
  for (int i = 0; i < n; ++i)
    if (!known[i]) eta[i] = mean;
  return eta;
}

template <int Dim>
VectorX stress_viscosity(const StressGrid<Dim>& stress, const Particles<Dim>& particles,
                         const std::vector<double>& liquid_eta) {
  VectorX eta(stress.num_dofs());
  // The diagonal components all sit at the cell centres (shift 1/2 on every axis, dims = the
  // cells: StressGrid), so their samples are one splat, made once (component 0) and copied to the
  // other Dim - 1 (the same bits: the same call). The distinct components (0, then the
  // off-diagonal ones) on several threads, each made whole by one thread (serially, as above),
  // into its own segment: the same bits for any team size. (In 3D, 4 splats instead of 6: two
  // per thread on two threads.)
  constexpr int components = StressGrid<Dim>::num_components();
  constexpr int distinct = components - (Dim - 1);
#pragma omp parallel for schedule(dynamic, 1) num_threads(team_threads(static_cast<long>(particles.size()) * distinct))
  for (int i = 0; i < distinct; ++i) {
    const int k = i == 0 ? 0 : Dim - 1 + i;
    eta.segment(stress.offset(k), stress.num_dofs(k)) =
        sample_viscosity(stress.grid(), StressGrid<Dim>::shift(k), stress.dims(k), particles,
                         liquid_eta);
  }
  // the copies in fixed blocks on several threads
  const long n0 = stress.num_dofs(0);
  constexpr long kBlock = 1L << 15;
  const long blocks = (n0 + kBlock - 1) / kBlock;
#pragma omp parallel for collapse(2) schedule(static) num_threads(team_threads(n0 * (Dim - 1)))
  for (int k = 1; k < Dim; ++k)
    for (long b = 0; b < blocks; ++b) {
      const double* from = eta.data() + stress.offset(0);
      std::copy(from + b * kBlock, from + std::min(n0, (b + 1) * kBlock),
                eta.data() + stress.offset(k) + b * kBlock);
    }
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
