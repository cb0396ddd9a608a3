/// \file scene_desc.cpp
/// The dimension-dependent defaults of SceneDesc (scene_desc.hpp).

#include "reference/sim/scene_desc.hpp"

namespace monolith {

std::vector<double> default_gravity(int dim) {
  std::vector<double> g(static_cast<std::size_t>(dim), 0.0);
  g[1] = -9.81;
  return g;
}

}  // namespace monolith
