// The settling disk of test_coupled_validation (2D, a = 4 dx): how the particles and their level
// set sit left and right of the disk before the first step, and the disk's sideways velocity
// after each of the first frames, per particle seed. A measurement program, not a test.
//
//   bench_disk_symmetry [--frames N] [--seeds S1,S2,...] [--dump 1]
//
// Per seed: the particles within 1.5 dx of the disk left / right, the largest |phi - mirror| of
// the level set near the disk and away from it, the faces near the disk no particle reaches, the
// summed mirror differences of W_F^u, of W_L^u (times W_F^u) near the disk, far and at the
// surface, and of W_L^p near the disk; --dump 1 lists the asymmetric faces and cells. Run it with
// OMP_NUM_THREADS=1 (docs/particles.md, "The settling disk's sideways drift").
#include <cmath>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/particles/particles.hpp"
#include "reference/sim/simulation.hpp"
#include "tests/support/coupled_validation.hpp"

using namespace monolith;
using namespace monolith::validation;

int main(int argc, char** argv) {
  int frames = 3;
  bool dump = false;
  std::vector<int> seeds = {1, 2, 3, 4, 5};
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--frames") frames = std::stoi(argv[i + 1]);
    if (a == "--dump") dump = std::stoi(argv[i + 1]) != 0;
    if (a == "--seeds") {
      seeds.clear();
      std::stringstream ss(argv[i + 1]);
      std::string t;
      while (std::getline(ss, t, ',')) seeds.push_back(std::stoi(t));
    }
  }
  for (int seed : seeds) {
    nlohmann::json j = base_scene(2, {1.0, 2.0}, 32, "PVC-unified", 100);
    j["liquids"].push_back(pool(2, 1.8, 1000.0));
    j["bodies"].push_back({{"name", "disk"},
                           {"density", 2000.0},
                           {"shape", {{"type", "sphere"}, {"center", {0.5, 1.0}}, {"radius", 0.125}}}});
    j["particles"] = {{"seed", seed}};
    const SceneFile scene = parse_scene(j, "disk.json", ".");
    Simulation<2> sim(scene);
    const MacGrid<2>& grid = sim.grid();
    const double dx = grid.dx();
    const Vec<2> centre(0.5, 1.0);
    const double r = 0.125;
    // particles in the ring within 1.5 dx of the disk: count and volume-weighted mean x offset
    const Particles<2>& P = sim.particles();
    double left = 0, right = 0, moment = 0, gapl = 1e9, gapr = 1e9;
    for (std::size_t p = 0; p < P.size(); ++p) {
      const Vec<2> d = P.x[p] - centre;
      const double s = d.norm() - r;
      if (s > 1.5 * dx) continue;
      (d[0] < 0 ? left : right) += 1;
      moment += d[0] / d.norm();
      if (d[0] < 0) gapl = std::min(gapl, s); else gapr = std::min(gapr, s);
    }
    // level set near the disk: largest |phi(x) - phi(mirror x)| and the largest phi in the ring
    const SampleLattice<2> lat = half_lattice(grid);
    const VectorX& phi = sim.liquid_phi();
    double asym = 0, asym_far = 0, maxphi = -1e9;
    for (int k = 0; k < lat.size(); ++k) {
      const VecI<2> i = lat.coord(k);
      VecI<2> m = i;
      m[0] = lat.dims[0] - 1 - i[0];
      const Vec<2> y = lat.position(i);
      const double s = (y - centre).norm() - r;
      const double a = std::abs(phi[k] - phi[lat.index(m)]);
      if (y[1] > 1.6) continue;
      if (s > -0.5 * dx && s < 2 * dx) {
        asym = std::max(asym, a);
        if (s > 0) maxphi = std::max(maxphi, phi[k]);
      } else if (s > 0) {
        asym_far = std::max(asym_far, a);
      }
    }
    VectorX u, fm, fd;
    particles_to_grid(P, grid, u, fm, fd);
    int emptyl = 0, emptyr = 0;
    for (int f = 0; f < grid.num_faces(); ++f) {
      const auto [axis, fc] = grid.face_coord(f);
      const Vec<2> y = grid.face_center(axis, fc);
      const double s = (y - centre).norm() - r;
      if (s < -0.75 * dx || s > 2 * dx || fm[f] > 0.0) continue;
      (y[0] < 0.5 ? emptyl : emptyr) += 1;
      if (dump) std::printf("  empty face axis %d at (%.3f, %.3f) s %.2f dx\n", axis, (y[0] - 0.5) / dx, (y[1] - 1.0) / dx, s / dx);
    }
    // faces partly in the fluid near the disk that no particle reaches (no mass, so no gravity
    // in u*): count left / right
    {
      const PressureWeights& W = sim.weights();
      // mirror of a face: axis 0 faces i -> nx - i; axis 1 faces i -> nx - 1 - i
      const int nx = grid.cells()[0];
      double near = 0, far = 0, surf = 0, nearc = 0, wf = 0;
      for (int f = 0; f < grid.num_faces(); ++f) {
        const auto [axis, fc] = grid.face_coord(f);
        VecI<2> m = fc;
        m[0] = axis == 0 ? nx - fc[0] : nx - 1 - fc[0];
        const int g = grid.face_index(axis, m);
        const double dw = std::abs(W.liquid_face[f] - W.liquid_face[g]) * W.fluid_face[f];
        const Vec<2> y = grid.face_center(axis, fc);
        const double s = (y - centre).norm() - r;
        wf += std::abs(W.fluid_face[f] - W.fluid_face[g]);
        if (dump && std::abs(W.fluid_face[f] - W.fluid_face[g]) > 1e-6 && y[0] <= 0.5)
          std::printf("  W_F ax %d (%.1f, %.1f): %.4f mirror %.4f\n", axis, (y[0] - 0.5) / dx, (y[1] - 1.0) / dx, W.fluid_face[f], W.fluid_face[g]);
        if (y[1] > 1.6) surf += dw; else if (s < 2 * dx) near += dw; else far += dw;
        if (dump && y[1] <= 1.6 && dw > 1e-3 && y[0] < 0.5)
          std::printf("  face ax %d (%.1f, %.1f) s %.2f dx W_F %.3f W_L %.3f mirror %.3f mass %g %g\n", axis,
                      (y[0] - 0.5) / dx, (y[1] - 1.0) / dx, s / dx, W.fluid_face[f], W.liquid_face[f],
                      W.liquid_face[g], fm[f], fm[g]);
      }
      for (int c = 0; c < grid.num_cells(); ++c) {
        VecI<2> ci = grid.cell_coord(c), m = ci;
        m[0] = nx - 1 - ci[0];
        const double s = (grid.cell_center(ci) - centre).norm() - r;
        const double dc = std::abs(W.liquid_cell[c] - W.liquid_cell[grid.cell_index(m)]);
        if (s < 2 * dx) nearc += dc;
        if (dump && s < 2 * dx && dc > 1e-3 && ci[0] < nx / 2)
          std::printf("  cell (%d, %d) s %.2f dx W_L^p %.3f mirror %.3f\n", ci[0] - nx / 2, ci[1] - 32, s / dx, W.liquid_cell[c], W.liquid_cell[grid.cell_index(m)]);
      }
      std::printf("|dW_F| %.2e sum |dW_L^u| near %.4f far %.4f surface %.4f, |dW_L^p| near %.4f; ", wf, near, far, surf, nearc);
    }
    std::printf("seed %d: empty faces L %d R %d; ", seed, emptyl, emptyr);
    std::printf("seed %d: ring particles L %g R %g, sum cos %+.3f, nearest L %.3f R %.3f dx; phi asym near %.4f far %.4f dx, max phi in ring %+.3f dx; vx e-5:",
                seed, left, right, moment, gapl / dx, gapr / dx, asym / dx, asym_far / dx, maxphi / dx);
    for (int f = 0; f < frames; ++f) {
      const FrameStats s = sim.advance_frame();
      std::printf(" %+.2f", s.bodies[0].velocity[0] * 1e5);
    }
    std::printf("\n");
  }
}
