#pragma once
/// \file render.hpp
/// Frame pictures. A RenderView holds read-only references to the state to draw; render_view
/// reads it from a Simulation<Dim> (its const accessors, reference/sim/simulation.hpp), so the
/// solver core never depends on the pictures. The 2D renderer lives in dim2/render_2d.cpp and
/// the 3D ray marcher in dim3/render_3d.cpp.

#include <array>
#include <memory>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/grid/boundary.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/sim/simulation.hpp"
#include "reference/viz/image.hpp"
#include "reference/viz/render_spec.hpp"

namespace monolith {

/// A solid to draw: a static solid, or a moving body at its current pose.
template <int Dim>
struct RenderSolid {
  ShapePtr<Dim> shape;
  Rgb color{170, 140, 110};
};

template <int Dim>
struct RenderView {
  const MacGrid<Dim>* grid = nullptr;
  /// Liquid signed distance (negative inside) on half_lattice(*grid).
  const VectorX* liquid_phi = nullptr;
  /// render_view's whole-lattice copy of the simulation's level set, which is stored over its
  /// band (Simulation::liquid_phi(): made on demand); liquid_phi points into it (shared: the
  /// view stays valid when copied or moved)
  std::shared_ptr<const VectorX> liquid_phi_store;
  const std::vector<Vec<Dim>>* particles = nullptr;
  const VectorX* velocity = nullptr;  ///< face field
  const VectorX* pressure = nullptr;  ///< cell field (zero in air)
  /// Effective viscosity per cell (for color_by viscosity); may be null (treated as zero).
  const VectorX* viscosity = nullptr;
  std::vector<RenderSolid<Dim>> solids;
  std::array<BoundaryType, 2 * Dim> boundary{};
  double time = 0.0;
};

/// The view of a simulation's current state: its grid, liquid level set, particles, velocity,
/// pressure and cell viscosity; its static solids (brown), dynamic bodies (blue) and kinematic
/// bodies (green) at their current pose. Holds references into `sim` (and its own copy of the
/// liquid level set).
template <int Dim>
RenderView<Dim> render_view(const Simulation<Dim>& sim);

/// Renders the current state of `sim` (a Simulation<2> or Simulation<3>; std::invalid_argument
/// for any other AnySimulation) at spec.size with colouring spec.color_by.
Image render_simulation(const AnySimulation& sim, const RenderSpec& spec);

/// Values of the colour field `color_by` (speed, pressure, viscosity) at the centres of the cells
/// whose centre lies inside the liquid: the sample set both renderers take their robust colour
/// range from. `lattice` is half_lattice(*view.grid).
template <int Dim>
std::vector<double> liquid_field_values(const RenderView<Dim>& view, const SampleLattice<Dim>& lattice,
                                        ColorBy color_by);

/// Renders one frame at spec.size with colouring spec.color_by.
template <int Dim>
Image render_frame(const RenderView<Dim>& view, const RenderSpec& spec);
/// The two renderers are explicit specialisations (dim2/render_2d.cpp, dim3/render_3d.cpp).
template <>
Image render_frame<2>(const RenderView<2>& view, const RenderSpec& spec);
template <>
Image render_frame<3>(const RenderView<3>& view, const RenderSpec& spec);

}  // namespace monolith
