// The density projection alone on water at rest: a tank (unit box, walls, open top, 0.5 m deep)
// is seeded as the simulator seeds it and then only project_particle_density (optionally with
// correct_positions before it) is applied, call after call, with no flow at all. An exact
// projection leaves such water where it is; this prints how far the particles' mean height (the
// potential energy), the level set's volume, the projection's error and the roughness of the
// reconstructed surface (spread of the column heights) go instead.
//
//   bench_projection_rest [--dim 2|3] [--cells N] [--calls K] [--correct] [--box] [--dump]
//
// --dump (with --box) prints the liquid fractions W_L^p of the cells beside and under the box
// before the first call (of the particles' level set and of it extended into the box) and the
// particles the last call moved by more than 0.03 dx.
// --box puts the floating box of slow_still_water.cpp (half size 0.1 x 0.05 (x 0.1), centre
// (0.5, 0.5), half in the water) into the tank as a solid: the water is seeded around it, and
// the projection sees it in its face weights and its solid field. Printed then as well: the
// mean height of the particles under the box and beside it (within 2 dx), in dx.
//
// A measurement program, not a test: it asserts nothing. docs/particles.md ("Still water").
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

#include "reference/grid/volume_fractions.hpp"
#include "reference/particles/particles.hpp"
#include "reference/geometry/shape.hpp"

using namespace monolith;

namespace {

template <int Dim>
double mean_height(const Particles<Dim>& p) {
  double s = 0.0;
  for (const auto& x : p.x) s += x[1];
  return s / static_cast<double>(p.size());
}

/// Mean height of the particles above 0.5 - 2 dx (the surface layers).
template <int Dim>
double surface_layer_height(const Particles<Dim>& p, double dx) {
  double s = 0.0;
  long n = 0;
  for (const auto& x : p.x)
    if (x[1] > 0.5 - 2.0 * dx) {
      s += x[1];
      ++n;
    }
  return n ? s / n : 0.0;
}

template <int Dim>
double level_set_volume(const Particles<Dim>& p, const MacGrid<Dim>& grid,
                        const std::array<BoundaryType, 2 * Dim>& boundary) {
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const VectorX phi = liquid_phi_on_lattice(p, grid, lattice, boundary);
  return liquid_cell_weights(grid, lattice, phi).sum() * grid.cell_volume();
}

/// Standard deviation over the columns (cells along y) of the liquid height sum_y W_L^p dx, in
/// dx: how rough the reconstructed surface is.
template <int Dim>
double surface_roughness(const Particles<Dim>& p, const MacGrid<Dim>& grid,
                         const std::array<BoundaryType, 2 * Dim>& boundary) {
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const VectorX w = liquid_cell_weights(grid, lattice, liquid_phi_on_lattice(p, grid, lattice, boundary));
  const int ny = grid.cells()[1];
  const int columns = grid.num_cells() / ny;
  std::vector<double> h(columns, 0.0);
  for (int c = 0; c < grid.num_cells(); ++c) {
    VecI<Dim> ci = grid.cell_coord(c);
    int col = 0;
    for (int a = Dim - 1; a >= 0; --a)
      if (a != 1) col = col * grid.cells()[a] + ci[a];
    h[col] += w[c];
  }
  double m = 0.0, m2 = 0.0;
  for (double v : h) {
    m += v;
    m2 += v * v;
  }
  m /= columns;
  return std::sqrt(std::max(0.0, m2 / columns - m * m));
}

/// Mean height (in dx, relative to y0) of the particles within `reach` of the box's bottom face
/// (under it) and of its sides (beside it, below the surface).
template <int Dim>
std::pair<double, double> near_box_heights(const Particles<Dim>& p, const Shape<Dim>& box,
                                           double reach) {
  double under = 0.0, beside = 0.0;
  long nu = 0, nb = 0;
  for (const auto& x : p.x) {
    if (box.distance(x) > reach) continue;
    bool inside_x = true;
    for (int a = 0; a < Dim; ++a)
      if (a != 1 && std::abs(x[a] - 0.5) > 0.1) inside_x = false;
    if (inside_x && x[1] < 0.45) {
      under += x[1];
      ++nu;
    } else if (!inside_x) {
      beside += x[1];
      ++nb;
    }
  }
  return {nu ? under / nu : 0.0, nb ? beside / nb : 0.0};
}

template <int Dim>
int run(int cells, int calls, bool correct, bool with_box, bool dump) {
  std::array<bool, Dim> periodic{};
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / cells, VecI<Dim>::Constant(cells), periodic);
  const double dx = grid.dx();
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  boundary[3] = BoundaryType::open;  // y+
  const SampleLattice<Dim> lattice = half_lattice(grid);
  // the floating box of slow_still_water.cpp, as a static solid (--box)
  ShapeSpec body;
  body.type = ShapeType::box;
  body.center.assign(Dim, 0.5);
  body.half_size.assign(Dim, 0.1);
  body.half_size[1] = 0.05;
  std::vector<ShapePtr<Dim>> solid_shapes;
  SolidField<Dim> solids;
  if (with_box) {
    solid_shapes.push_back(make_shape<Dim>(body, "box"));
    const ShapePtr<Dim> shape = solid_shapes.front();
    solids.distance = [shape](const Vec<Dim>& x) { return shape->distance(x); };
    solids.gradient = [shape](const Vec<Dim>& x) { return shape->gradient(x); };
  }
  const VectorX solid_phi = with_box ? solid_phi_on_lattice(grid, lattice, solid_shapes, 0.0)
                                     : VectorX::Constant(lattice.size(), 1.0);
  const VectorX fluid = fluid_face_weights(grid, lattice, solid_phi, boundary);
  ShapeSpec box;
  box.type = ShapeType::box;
  box.center.assign(Dim, 0.5);
  box.center[1] = 0.25;
  box.half_size.assign(Dim, 0.5);
  box.half_size[1] = 0.25;
  LiquidSpec water;
  water.name = "water";
  water.density = 1000.0;
  water.shape = box;
  const auto shape = make_shape<Dim>(box, "water");
  Particles<Dim> p = seed_particles<Dim>(grid, {water}, {shape}, solids,
                                         Dim == 2 ? 4 : 8, 1u);
  double vp = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) vp += p.mass[i] / p.density[i];
  std::printf("%dD %d cells, %zu particles, particle volume %.6f, %s\n", Dim, cells, p.size(), vp,
              correct ? "correct_positions + projection" : "projection only");
  std::printf("%6s %12s %12s %12s %12s %10s %10s %10s %10s %10s\n", "call", "mean y - y0",
              "top y - y0", "V_ls/V_p-1", "error", "max move", "cg iters", "roughness",
              "under box", "beside box");
  const double y0 = mean_height(p), t0 = surface_layer_height(p, dx);
  std::pair<double, double> near0{0.0, 0.0};
  if (with_box) near0 = near_box_heights(p, *solid_shapes.front(), 2.0 * dx);
  if (with_box && dump) {
    const VectorX phi = liquid_phi_on_lattice(p, grid, lattice, boundary);
    const VectorX w = liquid_cell_weights(grid, lattice, phi);
    const VectorX we = liquid_cell_weights(grid, lattice, extend_liquid_into_solids(grid, phi, solid_phi, dx));
    for (int c = 0; c < grid.num_cells(); ++c) {
      const Vec<Dim> xc = grid.cell_center(grid.cell_coord(c));
      const double d = solid_shapes.front()->distance(xc) / dx;
      if (d > 0.0 && d < 1.6 && xc[1] < 0.47 && xc[1] > 0.4 && (Dim == 2 || std::abs(xc[2] - 0.5) < dx))
        std::printf("  cell (%.1f, %.1f) distance %.2f dx: W_L^p %.3f extended %.3f\n", xc[0] / dx, xc[1] / dx, d, w[c], we[c]);
    }
  }
  for (int k = 0; k <= calls; ++k) {
    DensityProjectionStats st;
    if (k > 0) {
      if (correct) correct_positions(p, grid, 0.02, solids, boundary);
      const std::vector<Vec<Dim>> before = p.x;
      st = project_particle_density(p, grid, lattice, fluid, solids, boundary);
      if (dump && k == calls)
        for (std::size_t i = 0; i < p.size(); ++i)
          if ((p.x[i] - before[i]).norm() > 0.03 * dx)
            std::printf("  moved %zu from (%.4f, %.4f) dx by (%.4f, %.4f) dx\n", i,
                        before[i][0] / dx, before[i][1] / dx, (p.x[i][0] - before[i][0]) / dx,
                        (p.x[i][1] - before[i][1]) / dx);
    }
    std::pair<double, double> near{0.0, 0.0};
    if (with_box) near = near_box_heights(p, *solid_shapes.front(), 2.0 * dx);
    if (k <= 4 || k % (calls / 10 > 0 ? calls / 10 : 1) == 0)
      std::printf("%6d %12.3e %12.3e %12.3e %12.3e %10.3e %10d %10.3e %10.3e %10.3e\n", k,
                  (mean_height(p) - y0) / dx, (surface_layer_height(p, dx) - t0) / dx,
                  level_set_volume(p, grid, boundary) / vp - 1.0, st.error_before / vp,
                  st.max_move / dx, st.iterations, surface_roughness(p, grid, boundary),
                  (near.first - near0.first) / dx, (near.second - near0.second) / dx);
  }
  std::printf("heights, moves and roughness in dx; error = sum |e| dx^Dim / particle volume\n");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  int dim = 3, cells = 0, calls = 200;
  bool correct = false, with_box = false, dump = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--dim" && i + 1 < argc)
      dim = std::atoi(argv[++i]);
    else if (a == "--cells" && i + 1 < argc)
      cells = std::atoi(argv[++i]);
    else if (a == "--calls" && i + 1 < argc)
      calls = std::atoi(argv[++i]);
    else if (a == "--correct")
      correct = true;
    else if (a == "--box")
      with_box = true;
    else if (a == "--dump")
      dump = true;
    else {
      std::fprintf(stderr, "usage: bench_projection_rest [--dim 2|3] [--cells N] [--calls K] "
                           "[--correct] [--box] [--dump]\n");
      return 2;
    }
  }
  if (cells <= 0) cells = dim == 2 ? 64 : 32;
  if (dim == 2) return run<2>(cells, calls, correct, with_box, dump);
  if (dim == 3) return run<3>(cells, calls, correct, with_box, dump);
  std::fprintf(stderr, "--dim must be 2 or 3\n");
  return 2;
}
