#include "reference/viz/render.hpp"

namespace monolith {

template <int Dim>
std::vector<double> liquid_field_values(const RenderView<Dim>& view, const SampleLattice<Dim>& lattice,
                                        const std::string& color_by) {
  std::vector<double> values;
  const MacGrid<Dim>& grid = *view.grid;
  for (int c = 0; c < grid.num_cells(); ++c) {
    const VecI<Dim> cc = grid.cell_coord(c);
    // the cell centre is half-lattice point 2c + 1
    const VecI<Dim> li = (2 * cc.array() + 1).matrix();
    if ((*view.liquid_phi)[lattice.index(li)] >= 0.0) continue;
    if (color_by == "speed" && view.velocity)
      values.push_back(grid.interpolate_velocity(*view.velocity, grid.cell_center(cc)).norm());
    else if (color_by == "pressure" && view.pressure)
      values.push_back((*view.pressure)[c]);
    else if (color_by == "viscosity")
      values.push_back(view.viscosity ? (*view.viscosity)[c] : 0.0);
  }
  return values;
}

template std::vector<double> liquid_field_values<2>(const RenderView<2>&, const SampleLattice<2>&,
                                                    const std::string&);
template std::vector<double> liquid_field_values<3>(const RenderView<3>&, const SampleLattice<3>&,
                                                    const std::string&);

}  // namespace monolith
