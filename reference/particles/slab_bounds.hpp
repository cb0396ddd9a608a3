/// \file slab_bounds.hpp
/// Where the particle scatters split their output layers among threads (particles_to_grid, the
/// density projection's volume splat).
#pragma once

#include <algorithm>
#include <vector>

namespace monolith {

/// The first output layer of each of `slabs` slabs (slabs + 1 entries: 0, ..., output_layers)
/// for a scatter in which every thread walks all particles, takes those that reach its slab and
/// writes only its own output layers. A particle counted in layer l of `count` (count[l], l in
/// [0, count.size())) writes output layers l + reach_lo .. l + reach_hi (reach_lo <= 0 <=
/// reach_hi), so a slab owning output layers [a, b) visits the particles of layers
/// [a - reach_hi, b - 1 - reach_lo]: the layers beside a bound are visited by both slabs. The
/// bounds minimise the largest number of particles a slab visits (a search over that number,
/// each slab extended while it stays within it), where cutting the particles' layers into equal
/// counts left the lower slab a whole boundary layer more (the 64^3 viscous bunny's P2G: 24.9k
/// against 20.2k of 38.1k particles per call). Only the time depends on the bounds: each output
/// sums its particles in particle order whatever the slab that owns it.
inline std::vector<int> balanced_slab_bounds(const std::vector<long>& count, int output_layers,
                                             int slabs, int reach_lo, int reach_hi) {
  const int layers = static_cast<int>(count.size());
  std::vector<int> first(slabs + 1, output_layers);
  first[0] = 0;
  if (slabs <= 1 || output_layers <= 0) return first;
  // below[l] = particles in layers < l (l clamped to [0, layers])
  std::vector<long> below(layers + 1, 0);
  for (int l = 0; l < layers; ++l) below[l + 1] = below[l] + count[l];
  const auto below_clamped = [&](long l) {
    return below[static_cast<std::size_t>(std::clamp<long>(l, 0, layers))];
  };
  // the particles a slab owning output layers [a, b) visits (a < b)
  const auto visited = [&](int a, int b) {
    return below_clamped(static_cast<long>(b) - reach_lo) -
           below_clamped(static_cast<long>(a) - reach_hi);
  };
  // the bounds when no slab may visit more than `bound`, or empty when the slabs cannot cover
  // the output layers within it
  std::vector<int> bounds(slabs + 1);
  const auto fits = [&](long bound) {
    bounds[0] = 0;
    int a = 0;
    for (int s = 0; s < slabs; ++s) {
      int b = a;
      while (b < output_layers && visited(a, b + 1) <= bound) ++b;
      if (s == slabs - 1) b = output_layers;
      if (b < output_layers && b == a && visited(a, a + 1) > bound) return false;
      bounds[s + 1] = b;
      a = b;
    }
    return visited(bounds[slabs - 1], output_layers) <= bound || bounds[slabs - 1] == output_layers;
  };
  long lo = 0, hi = below[layers];  // fits(hi): one slab takes everything
  while (lo < hi) {
    const long mid = lo + (hi - lo) / 2;
    if (fits(mid))
      hi = mid;
    else
      lo = mid + 1;
  }
  fits(hi);
  return bounds;
}

}  // namespace monolith
