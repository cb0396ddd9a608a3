/// \file render.cpp
/// The view of a simulation's state and the colour samples both renderers share (render.hpp).

#include "reference/viz/render.hpp"

#include <stdexcept>

namespace monolith {

template <int Dim>
RenderView<Dim> render_view(const Simulation<Dim>& sim) {
  RenderView<Dim> view;
  view.grid = &sim.grid();
  view.liquid_phi_store = std::make_shared<const VectorX>(sim.liquid_phi());
  view.liquid_phi = view.liquid_phi_store.get();
  view.particles = &sim.particles().x;
  view.velocity = &sim.velocity();
  view.pressure = &sim.pressure();
  view.viscosity = &sim.cell_eta();
  for (const auto& shape : sim.static_shapes()) {
    RenderSolid<Dim> solid;
    solid.shape = shape;
    view.solids.push_back(solid);
  }
  // moving bodies at their current pose: dynamic in blue, kinematic in green
  if (const RigidWorld<Dim>* world = sim.rigid_world())
    for (const auto& b : world->bodies()) {
      if (!b.moves()) continue;
      RenderSolid<Dim> solid;
      solid.shape = b.posed_shape();
      solid.color = b.is_dynamic() ? Rgb{70, 110, 180} : Rgb{110, 160, 90};
      view.solids.push_back(solid);
    }
  view.boundary = sim.boundary();
  view.time = sim.time();
  return view;
}

Image render_simulation(const AnySimulation& sim, const RenderSpec& spec) {
  if (const auto* s2 = dynamic_cast<const Simulation<2>*>(&sim))
    return render_frame<2>(render_view(*s2), spec);
  if (const auto* s3 = dynamic_cast<const Simulation<3>*>(&sim))
    return render_frame<3>(render_view(*s3), spec);
  throw std::invalid_argument("render_simulation: not a Simulation<2> or Simulation<3>");
}

template <int Dim>
std::vector<double> liquid_field_values(const RenderView<Dim>& view, const SampleLattice<Dim>& lattice,
                                        ColorBy color_by) {
  std::vector<double> values;
  const MacGrid<Dim>& grid = *view.grid;
  for (int c = 0; c < grid.num_cells(); ++c) {
    const VecI<Dim> cc = grid.cell_coord(c);
    // the cell centre is half-lattice point 2c + 1
    const VecI<Dim> li = (2 * cc.array() + 1).matrix();
    if ((*view.liquid_phi)[lattice.index(li)] >= 0.0) continue;
    if (color_by == ColorBy::speed && view.velocity)
      values.push_back(grid.interpolate_velocity(*view.velocity, grid.cell_center(cc)).norm());
    else if (color_by == ColorBy::pressure && view.pressure)
      values.push_back((*view.pressure)[c]);
    else if (color_by == ColorBy::viscosity)
      values.push_back(view.viscosity ? (*view.viscosity)[c] : 0.0);
  }
  return values;
}

template RenderView<2> render_view<2>(const Simulation<2>&);
template RenderView<3> render_view<3>(const Simulation<3>&);
template std::vector<double> liquid_field_values<2>(const RenderView<2>&, const SampleLattice<2>&,
                                                    ColorBy);
template std::vector<double> liquid_field_values<3>(const RenderView<3>&, const SampleLattice<3>&,
                                                    ColorBy);

}  // namespace monolith
