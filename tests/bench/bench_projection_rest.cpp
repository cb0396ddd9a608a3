// The density projection alone on water at rest: a tank (unit box, walls, open top, 0.5 m deep)
// is seeded as the simulator seeds it and then only project_particle_density (optionally with
// correct_positions before it) is applied, call after call, with no flow at all. An exact
// projection leaves such water where it is; this prints how far the particles' mean height (the
// potential energy), the level set's volume, the projection's error and the roughness of the
// reconstructed surface (spread of the column heights) go instead.
//
//   bench_projection_rest [--dim 2|3] [--cells N] [--calls K] [--correct]
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

template <int Dim>
int run(int cells, int calls, bool correct) {
  std::array<bool, Dim> periodic{};
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / cells, VecI<Dim>::Constant(cells), periodic);
  const double dx = grid.dx();
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  boundary[3] = BoundaryType::open;  // y+
  const SampleLattice<Dim> lattice = half_lattice(grid);
  const VectorX solid_phi = VectorX::Constant(lattice.size(), 1.0);
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
  Particles<Dim> p = seed_particles<Dim>(grid, {water}, {shape}, SolidField<Dim>{},
                                         Dim == 2 ? 4 : 8, 1u);
  double vp = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) vp += p.mass[i] / p.density[i];
  std::printf("%dD %d cells, %zu particles, particle volume %.6f, %s\n", Dim, cells, p.size(), vp,
              correct ? "correct_positions + projection" : "projection only");
  std::printf("%6s %12s %12s %12s %12s %10s %10s %10s\n", "call", "mean y - y0", "top y - y0",
              "V_ls/V_p-1", "error", "max move", "cg iters", "roughness");
  const double y0 = mean_height(p), t0 = surface_layer_height(p, dx);
  for (int k = 0; k <= calls; ++k) {
    DensityProjectionStats st;
    if (k > 0) {
      if (correct) correct_positions(p, grid, 0.02, SolidField<Dim>{}, boundary);
      st = project_particle_density(p, grid, lattice, fluid, SolidField<Dim>{}, boundary);
    }
    if (k <= 4 || k % (calls / 10 > 0 ? calls / 10 : 1) == 0)
      std::printf("%6d %12.3e %12.3e %12.3e %12.3e %10.3e %10d %10.3e\n", k,
                  (mean_height(p) - y0) / dx, (surface_layer_height(p, dx) - t0) / dx,
                  level_set_volume(p, grid, boundary) / vp - 1.0, st.error_before / vp,
                  st.max_move / dx, st.iterations, surface_roughness(p, grid, boundary));
  }
  std::printf("heights, moves and roughness in dx; error = sum |e| dx^Dim / particle volume\n");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  int dim = 3, cells = 0, calls = 200;
  bool correct = false;
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
    else {
      std::fprintf(stderr, "usage: bench_projection_rest [--dim 2|3] [--cells N] [--calls K] "
                           "[--correct]\n");
      return 2;
    }
  }
  if (cells <= 0) cells = dim == 2 ? 64 : 32;
  if (dim == 2) return run<2>(cells, calls, correct);
  if (dim == 3) return run<3>(cells, calls, correct);
  std::fprintf(stderr, "--dim must be 2 or 3\n");
  return 2;
}
