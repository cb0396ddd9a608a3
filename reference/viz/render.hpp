#pragma once
/// \file render.hpp
/// Frame pictures. The simulation exposes a RenderView (read-only references to its state); the
/// 2D renderer lives in dim2/render_2d.cpp and the 3D ray marcher in dim3/render_3d.cpp.

#include <array>
#include <string>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/viz/image.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/app/scene.hpp"
#include "reference/geometry/shape.hpp"

namespace monolith {

/// A solid to draw (a wall-less static body now; posed dynamic bodies arrive with issue 4).
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
  const std::vector<Vec<Dim>>* particles = nullptr;
  const VectorX* velocity = nullptr;  ///< face field
  const VectorX* pressure = nullptr;  ///< cell field (zero in air)
  /// Effective viscosity per cell (for color_by viscosity); may be null (treated as zero).
  const VectorX* viscosity = nullptr;
  std::vector<RenderSolid<Dim>> solids;
  std::array<BoundaryType, 2 * Dim> boundary{};
  double time = 0.0;
};

/// Values of the colour field `color_by` (speed, pressure, viscosity) at the centres of the cells
/// whose centre lies inside the liquid: the sample set both renderers take their robust colour
/// range from. `lattice` is half_lattice(*view.grid).
template <int Dim>
std::vector<double> liquid_field_values(const RenderView<Dim>& view, const SampleLattice<Dim>& lattice,
                                        const std::string& color_by);

/// Renders one frame at spec.size with colouring spec.color_by.
template <int Dim>
Image render_frame(const RenderView<Dim>& view, const RenderSpec& spec);
/// The two renderers are explicit specialisations (dim2/render_2d.cpp, dim3/render_3d.cpp).
template <>
Image render_frame<2>(const RenderView<2>& view, const RenderSpec& spec);
template <>
Image render_frame<3>(const RenderView<3>& view, const RenderSpec& spec);

}  // namespace monolith
