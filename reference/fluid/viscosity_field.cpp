/// \file viscosity_field.cpp
/// eta per stress DOF and per cell from the particles (viscosity_field.hpp).

#include "reference/fluid/viscosity_field.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "reference/core/parallel.hpp"
#include "reference/grid/box_rows.hpp"

namespace monolith {

std::vector<double> liquid_viscosities(const std::vector<LiquidSpec>& liquids) {
  std::vector<double> eta;
  eta.reserve(liquids.size());
  for (const auto& l : liquids)
    eta.push_back(l.viscosity.model == ViscosityModel::newtonian ? l.viscosity.eta : 0.0);
  return eta;
}

namespace {

/// sample_viscosity written into out[0, dims.prod()) (a component's segment of stress_viscosity's
/// vector, or a vector of its own).
///
/// Every pass but the last visits the box of samples a particle's stencil reaches, grown by
/// kViscosityFillLayers on every side (the whole axis when it is periodic): a sample outside it
/// is not reached (no particle's stencil lies there) and no ring of the fill reaches it (ring r
/// visits samples at most r axis steps from a reached one), so it takes the liquid's mean, which
/// the last pass writes. Inside, the box's own lattice in the same index order (the last axis
/// slowest) holds the same sums in the same particle order, the same rings in the same order:
/// the same bits as the splat over the whole lattice (docs/derivations.md, "Passes restricted to
/// boxes").
/// The reached box comes from the particles' bounding box: the lattice coordinate
/// (x - origin) / dx - shift, floor, clamp and min of axis_stencil are monotone, so the stencil
/// of the smallest and of the largest coordinate bound every particle's stencil on that axis.
template <int Dim>
void sample_viscosity_into(const MacGrid<Dim>& grid, const Vec<Dim>& shift, const VecI<Dim>& dims,
                           const Particles<Dim>& particles, const std::vector<double>& liquid_eta,
                           double* out) {
  constexpr int kCorners = 1 << Dim;
  constexpr int kLast = Dim - 1;
  const int n = dims.prod();
  const long np = static_cast<long>(particles.size());
  // the particles' bounding box (non-periodic axes; a non-finite coordinate: the whole lattice)
  Vec<Dim> xmin = Vec<Dim>::Constant(std::numeric_limits<double>::infinity());
  Vec<Dim> xmax = Vec<Dim>::Constant(-std::numeric_limits<double>::infinity());
  bool finite = true;
  for (long p = 0; p < np; ++p) {
    const Vec<Dim>& x = particles.x[p];
    for (int a = 0; a < Dim; ++a) {
      finite = finite && std::isfinite(x[a]);
      xmin[a] = std::min(xmin[a], x[a]);
      xmax[a] = std::max(xmax[a], x[a]);
    }
  }
  VecI<Dim> lo = VecI<Dim>::Zero(), hi = dims - VecI<Dim>::Ones();
  if (finite && np > 0)
    for (int a = 0; a < Dim; ++a) {
      if (grid.periodic(a)) continue;
      const auto coordinate = [&](double x) { return (x - grid.origin()[a]) / grid.dx() - shift[a]; };
      lo[a] = std::max(grid.axis_stencil(a, coordinate(xmin[a]), dims[a]).index[0] -
                           kViscosityFillLayers, 0);
      hi[a] = std::min(grid.axis_stencil(a, coordinate(xmax[a]), dims[a]).index[1] +
                           kViscosityFillLayers, dims[a] - 1);
    }
  const VecI<Dim> bdims = hi - lo + VecI<Dim>::Ones();
  const int bn = np > 0 ? bdims.prod() : 0;
  // mass-weighted sums over the particles. On several threads (one called from the outside,
  // not from stress_viscosity's components, which run side by side on one thread each): the
  // box's samples are split into slabs of layers of the last axis (contiguous index ranges, the
  // last axis being the slowest), one per thread; each thread walks all particles in order, skips
  // those whose stencil misses its slab and adds only into its own samples, so every sample sums
  // its particles in the order of the serial loop (the same bits for any team). The slabs cut
  // the particles' layers into equal counts (any bounds give the same bits). The totals are
  // summed in particle order by the first slab's thread.
  const int layers = bn > 0 ? bdims[kLast] : 0;
  const long plane = bn / std::max(1, layers);
  using AxisStencil = typename MacGrid<Dim>::AxisStencil;
  const auto axis_stencil = [&](const Vec<Dim>& xw, int a) {
    return grid.axis_stencil(a, (xw[a] - grid.origin()[a]) / grid.dx() - shift[a], dims[a]);
  };
  const auto last_layer = [&](long p) {
    return axis_stencil(grid.wrap_position(particles.x[p]), kLast).index[0] - lo[kLast];
  };
  const int slabs = static_cast<int>(std::max(1L, std::min<long>(team_threads(np), layers)));
  std::vector<int> slab_first(slabs + 1, 0);
  slab_first[slabs] = layers;
  if (slabs > 1) {
    std::vector<int> layer_of(np);
#pragma omp parallel for schedule(static) num_threads(slabs)
    for (long p = 0; p < np; ++p) layer_of[p] = last_layer(p);
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
  std::vector<double> mass(bn), mass_eta(bn);
  double total_mass = 0.0, total_mass_eta = 0.0;
#pragma omp parallel for schedule(static, 1) num_threads(slabs)
  for (int slab = 0; slab < slabs; ++slab) {
    const int first = slab_first[slab], end = slab_first[slab + 1];
    std::fill(mass.data() + first * plane, mass.data() + end * plane, 0.0);
    std::fill(mass_eta.data() + first * plane, mass_eta.data() + end * plane, 0.0);
    const auto owned = [&](int layer) { return layer >= first && layer < end; };
    std::array<AxisStencil, Dim> st;
    for (long p = 0; p < np; ++p) {
      const int liquid = particles.liquid[p];
      const double eta =
          liquid >= 0 && liquid < static_cast<int>(liquid_eta.size()) ? liquid_eta[liquid] : 0.0;
      const double mp = particles.mass[p];
      if (slab == 0) {
        total_mass += mp;
        total_mass_eta += mp * eta;
      }
      const Vec<Dim> xw = grid.wrap_position(particles.x[p]);
      st[kLast] = axis_stencil(xw, kLast);
      if (slabs > 1 && !owned(st[kLast].index[0] - lo[kLast]) &&
          !owned(st[kLast].index[1] - lo[kLast]))
        continue;
      for (int a = 0; a < kLast; ++a) st[a] = axis_stencil(xw, a);
      // MacGrid::stencil's corners and weights, the index in the box's lattice (its layer, the
      // index over a plane, is the corner's index along the last axis: no division)
      for (int corner = 0; corner < kCorners; ++corner) {
        int index = 0;
        double w = 1.0;
        for (int a = Dim - 1; a >= 0; --a)
          index = index * bdims[a] + (st[a].index[(corner >> a) & 1] - lo[a]);
        for (int a = 0; a < Dim; ++a) w *= st[a].weight[(corner >> a) & 1];
        if (w == 0.0) continue;
        if (slabs > 1 && !owned(st[kLast].index[(corner >> kLast) & 1] - lo[kLast])) continue;
        mass[index] += w * mp;
        mass_eta[index] += w * mp * eta;
      }
    }
  }
  std::vector<double> eta(bn);
  std::vector<char> known(bn);  // (each entry written below)
  // the samples a particle reached, in index order (fixed blocks joined in order)
  std::vector<int> frontier = gather_in_order<int>(bn, [&](int i, std::vector<int>& list) {
    if (mass[i] > 0.0) {
      eta[i] = mass_eta[i] / mass[i];
      known[i] = 1;
      list.push_back(i);
    } else {
      eta[i] = 0.0;
      known[i] = 0;
    }
  });
  // the axis neighbour of c in direction s along a within the box, -1 outside a non-periodic
  // lattice (a periodic axis is whole in the box; beyond the box on another axis no sample is
  // known or a candidate: see above)
  auto neighbour = [&](const VecI<Dim>& c, int a, int s) {
    VecI<Dim> d = c;
    d[a] += s;
    if (grid.periodic(a))
      d[a] = (d[a] % bdims[a] + bdims[a]) % bdims[a];
    else if (d[a] < 0 || d[a] >= bdims[a])
      return -1;
    return lattice_index<Dim>(d, bdims);
  };
  // fill: unreached samples take the mean of their reached axis neighbours, ring by ring. Only
  // the unreached neighbours of the last ring are visited (the lattice is mostly far from the
  // liquid); each takes the same sum in the same neighbour order as a sweep over the whole
  // lattice would, and reads only samples known before the ring.
  std::vector<char> queued(bn, 0);
  std::vector<int> candidates, filled;
  for (int layer = 0; layer < kViscosityFillLayers && !frontier.empty(); ++layer) {
    candidates.clear();
    for (int i : frontier) {
      const VecI<Dim> c = lattice_coord<Dim>(i, bdims);
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
      const VecI<Dim> c = lattice_coord<Dim>(i, bdims);
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
  // the rest: the mean viscosity of the whole liquid; the box's rows (along axis 0) copied in
  const double mean = total_mass > 0.0 ? total_mass_eta / total_mass : 0.0;
  const BoxRows<Dim> box = bn > 0 ? BoxRows<Dim>(dims, lo, hi) : BoxRows<Dim>();
  const int rows = box.rows();
#pragma omp parallel num_threads(team_threads(n))
  {
#pragma omp for schedule(static)
    for (int i = 0; i < n; ++i) out[i] = mean;
#pragma omp for schedule(static)
    for (int r = 0; r < rows; ++r) {
      const int first = box.box_first(r);
      const int to = box.first(r);
      for (int i = 0; i < box.nx; ++i)
        out[to + i] = known[first + i] ? eta[first + i] : mean;
    }
  }
}

}  // namespace

template <int Dim>
VectorX sample_viscosity(const MacGrid<Dim>& grid, const Vec<Dim>& shift, const VecI<Dim>& dims,
                         const Particles<Dim>& particles, const std::vector<double>& liquid_eta) {
  VectorX eta(dims.prod());
  sample_viscosity_into(grid, shift, dims, particles, liquid_eta, eta.data());
  return eta;
}

template <int Dim>
VectorX stress_viscosity(const StressGrid<Dim>& stress, const Particles<Dim>& particles,
                         const std::vector<double>& liquid_eta) {
  VectorX eta;
  stress_viscosity_into(stress, particles, liquid_eta, eta);
  return eta;
}

template <int Dim>
void stress_viscosity_into(const StressGrid<Dim>& stress, const Particles<Dim>& particles,
                           const std::vector<double>& liquid_eta, VectorX& eta) {
  // every entry is written below (each component's segment whole by sample_viscosity_into or
  // the copies), so a kept vector of the right size is reused as it is
  if (eta.size() != stress.num_dofs()) eta.resize(stress.num_dofs());
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
    sample_viscosity_into(stress.grid(), StressGrid<Dim>::shift(k), stress.dims(k), particles,
                          liquid_eta, eta.data() + stress.offset(k));
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
  template void stress_viscosity_into(const StressGrid<D>&, const Particles<D>&,                 \
                                     const std::vector<double>&, VectorX&);                       \
  template VectorX cell_viscosity(const MacGrid<D>&, const Particles<D>&,                         \
                                  const std::vector<double>&);                                    \
  template std::vector<VectorX> liquid_stress_fractions(const StressGrid<D>&, const Particles<D>&, \
                                                        int);

MONOLITH_INSTANTIATE_VISCOSITY_FIELD(2)
MONOLITH_INSTANTIATE_VISCOSITY_FIELD(3)

#undef MONOLITH_INSTANTIATE_VISCOSITY_FIELD

}  // namespace monolith
