// Where a long run regains energy (issue 16, tests/slow/slow_long_runs.cpp): a built-in scene run
// frame by frame with the energy ledger on (StageSwitches::energy_ledger), printing per frame the
// mechanical energy E = kinetic + potential of liquid and bodies + the credit line 15's account
// holds (FrameStats::line15_banked_energy when positive, as the slow test counts it; printed as
// "credit"), its regain over the running minimum (the slow test's quantity) against the test's
// bound, and the ledger's stages of that frame, so that the stage which injects the energy in the frames where E rises can be read off.
// Variants switch one stage off at a time (as bench_still_water does); a variant changes the run
// from its first frame, so compare the regains, not single frames.
//
//   bench_energy_regain SCENE [--frames N] [--from F] [--only NAME[,NAME...]] [--affine]
//                       [--near] [--columns] [--set KEY=VALUE]...
//
// --affine adds a line per frame on the particles' APIC matrices c (print_affine). --near adds
// one on where the liquid beside the moving bodies is carried (print_near: the liquid's mean
// vertical velocity, the bodies' heights and vertical velocities, and the particles' mean face
// v_y by side of and distance to the nearest body, split by the class of face it is read from);
// --columns (2D) also the top of every grid column and the profiles of four columns.
// --frames defaults to three times the scene's length (the slow test's run); frames before --from
// are run but not printed; "volume" is the liquid volume's drift from frame 0. Each variant ends with a summary line: the largest regain, its frame,
// the bound there, and the ledger summed over the run. A measurement program: it asserts nothing.
// Run it with OMP_NUM_THREADS=1. docs/particles.md ("Energy regains over long runs").
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/core/errors.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/rigid/rigid_world.hpp"
#include "reference/sim/simulation.hpp"
#include "tests/support/bench_args.hpp"
#include "tests/support/stage_variants.hpp"

using namespace monolith;

namespace {

using Variant = bench::StageVariant;

std::vector<Variant> variants() {
  return {
      {"simulator", [](StageSwitches&) {}},
      {"no-correction", [](StageSwitches& s) { s.position_correction = false; }},
      {"no-projection", [](StageSwitches& s) { s.density_projection = false; }},
      {"no-step-projection", [](StageSwitches& s) { s.density_projection_in_steps = false; }},
      {"no-line-15", [](StageSwitches& s) { s.position_correction = s.density_projection = false; }},
      {"pic", [](StageSwitches& s) { s.apic = false; }},
      {"no-surface-deficits",
       [](StageSwitches& s) { s.density_projection_surface_deficits = SurfaceDeficits::none; }},
      {"no-extrapolation", [](StageSwitches& s) { s.extrapolate_after_solve = false; }},
      {"all-trusted", [](StageSwitches& s) { s.trusted_faces = false; }},
      // faces that carry particle mass outside the level set (W_L^u = 0) are extrapolated over
      // instead of keeping u* (their ballistic velocity)
      {"no-ballistic-faces", [](StageSwitches& s) { s.unreached_faces_keep_u_star = false; }},
      // those faces keep P2G's APIC value plus g dt (before issue 16's fix: the PIC value)
      {"ballistic-apic", [](StageSwitches& s) { s.ballistic_faces_pic = false; }},
      // every ballistic face takes the PIC value, not only those beside a wall or solid
      {"ballistic-pic-everywhere",
       [](StageSwitches& s) { s.ballistic_faces_pic_everywhere = true; }},
      {"split", [](StageSwitches& s) { s.split_advection = true; }},
      {"whole-drift", [](StageSwitches& s) { s.split_advection = false; }},
      // line 15's potential energy not paid by the kinetic energy (the default before slosh11)
      {"line15-free", [](StageSwitches& s) { s.line15_energy = Line15Energy::free; }},
      {"line15-no-debt", [](StageSwitches& s) { s.line15_carry_debt = false; }},
      // every wall face zero after the solve, also beside air (the rule before pour18; liquid in
      // flight is slowed a cell before it reaches a wall)
      {"walls-zero-in-air", [](StageSwitches& s) { s.air_walls_extrapolated = false; }},
      // departures items 16 and 18 (the default): a wall face beside air within two layers of a
      // trusted face keeps the extrapolated velocity
      {"air-walls", [](StageSwitches& s) { s.air_walls_extrapolated = true; }},
      // item 18's reach: the wall faces within 1, 3 or 8 layers of a trusted face (default 2)
      {"air-walls-1", [](StageSwitches& s) { s.air_walls_extrapolated = true; s.air_wall_layers = 1; }},
      {"air-walls-3", [](StageSwitches& s) { s.air_walls_extrapolated = true; s.air_wall_layers = 3; }},
      {"air-walls-8", [](StageSwitches& s) { s.air_walls_extrapolated = true; s.air_wall_layers = 8; }},
  };
}

/// The particles' affine part (APIC) and where it sits: the largest Frobenius norm of c (1/s), the
/// sum of 1/2 m |c|_F^2 dx^2 / 4 (an indicator of the energy the affine matrices hold, in J, not
/// counted in the particles' kinetic energy), and how many particles lie inside a moving body or
/// within 1.5 dx of one, with their share of that sum.
template <int Dim>
void print_affine(const AnySimulation& any, int frame) {
  const auto* sim = dynamic_cast<const Simulation<Dim>*>(&any);
  if (!sim) return;
  const auto& p = sim->particles();
  const double dx = sim->grid().dx();
  std::vector<ShapePtr<Dim>> bodies;
  if (const auto* world = sim->rigid_world())
    for (const auto& b : world->bodies())
      if (b.moves()) bodies.push_back(b.posed_shape());
  double largest = 0.0, sum = 0.0, near_sum = 0.0, large_sum = 0.0;
  long inside = 0, near = 0, large = 0, large_at_wall = 0;
  Vec<Dim> at = Vec<Dim>::Zero();
  Mat<Dim> c_at = Mat<Dim>::Zero();
  Vec<Dim> v_at = Vec<Dim>::Zero();
  const SceneDesc& scene = sim->scene();
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double c2 = p.c[i].squaredNorm();
    const double e = 0.5 * p.mass[i] * c2 * dx * dx / 4.0;
    if (std::sqrt(c2) > largest) {
      largest = std::sqrt(c2);
      at = p.x[i];
      c_at = p.c[i];
      v_at = p.v[i];
    }
    sum += e;
    if (std::sqrt(c2) * dx > 0.5) {  // a velocity difference of 0.5 m/s across a cell
      ++large;
      large_sum += e;
      double wall = 1e300;
      for (int a = 0; a < Dim; ++a) {
        if (scene.domain.boundary[2 * a] == BoundaryType::wall)
          wall = std::min(wall, p.x[i][a] - scene.domain.lower[a]);
        if (scene.domain.boundary[2 * a + 1] == BoundaryType::wall)
          wall = std::min(wall, scene.domain.upper[a] - p.x[i][a]);
      }
      if (wall < 1.5 * dx) ++large_at_wall;
    }
    double d = 1e300;
    for (const auto& b : bodies) d = std::min(d, b->distance(p.x[i]));
    if (d < 0.0) ++inside;
    if (d < 1.5 * dx) {
      ++near;
      near_sum += e;
    }
  }
  std::printf("affine frame %5d particles %ld |c| max %.3e 1/s, sum 1/2 m |c|^2 dx^2/4 %.4e J "
              "(within 1.5 dx of a moving body: %ld particles, %.4e J; inside one: %ld); |c| dx > "
              "0.5 m/s: %ld particles (%ld within 1.5 dx of a wall), %.4e J; largest at",
              frame, static_cast<long>(p.size()), largest, sum, near, near_sum, inside, large,
              large_at_wall, large_sum);
  for (int a = 0; a < Dim; ++a) std::printf(" %.4f", at[a]);
  std::printf(", v");
  for (int a = 0; a < Dim; ++a) std::printf(" %+.3e", v_at[a]);
  std::printf(", c (rows)");
  for (int a = 0; a < Dim; ++a)
    for (int b = 0; b < Dim; ++b) std::printf(" %+.3e", c_at(a, b));
  std::printf("\n");
}


/// Where the liquid beside the moving bodies is carried (--near; axis 1 is vertical): the
/// particles outside the bodies by the side of the nearest body (top: its outward normal n_y >
/// 1/2, bottom: n_y < -1/2, side) and distance to it (0-0.5, 0.5-1, 1-1.5, 1.5-3, 3-6, > 6 dx),
/// with their mass-weighted mean vertical velocity read
/// from the frame's last face velocities, split by the class of the faces it is read from
/// (interpolation is linear in u): faces the solids cover (W_F^u = 0, the bodies' velocities),
/// faces with fluid and no liquid weight (W_F^u > 0, W_L^u = 0), partly solid faces with liquid
/// (0 < W_F^u < 1) and open faces with liquid (W_F^u = 1).
template <int Dim>
void print_near(const AnySimulation& any, int frame, bool columns) {
  const auto* sim = dynamic_cast<const Simulation<Dim>*>(&any);
  if (!sim) return;
  const auto& p = sim->particles();
  const auto& grid = sim->grid();
  const double dx = grid.dx();
  std::vector<ShapePtr<Dim>> bodies;
  if (const auto* world = sim->rigid_world())
    for (const auto& b : world->bodies())
      if (b.moves()) bodies.push_back(b.posed_shape());
  if (bodies.empty()) return;
  const VectorX& u = sim->velocity();
  const PressureWeights& w = sim->weights();
  std::array<VectorX, 4> part;
  for (auto& v : part) v = VectorX::Zero(u.size());
  for (int f = 0; f < u.size(); ++f) {
    const double wf = w.fluid_face[f];
    const int k = wf == 0.0 ? 0 : w.liquid_face[f] == 0.0 ? 1 : wf < 1.0 ? 2 : 3;
    part[k][f] = u[f];
  }
  double mass[3][6] = {}, vy[3][6][4] = {};
  for (std::size_t i = 0; i < p.size(); ++i) {
    double d = 1e300;
    int nearest = -1;
    for (std::size_t b = 0; b < bodies.size(); ++b) {
      const double db = bodies[b]->distance(p.x[i]);
      if (db < d) {
        d = db;
        nearest = static_cast<int>(b);
      }
    }
    if (nearest < 0 || !(d >= 0.0)) continue;
    Vec<Dim> n = bodies[nearest]->gradient(p.x[i]);
    if (n.norm() > 0.0) n /= n.norm();
    const int side = n[1] > 0.5 ? 0 : n[1] < -0.5 ? 1 : 2;
    const int bin = d < 0.5 * dx   ? 0
                    : d < dx       ? 1
                    : d < 1.5 * dx ? 2
                    : d < 3 * dx   ? 3
                    : d < 6 * dx   ? 4
                                   : 5;
    mass[side][bin] += p.mass[i];
    for (int k = 0; k < 4; ++k)
      vy[side][bin][k] += p.mass[i] * grid.interpolate_velocity(part[k], p.x[i])[1];
  }
  // the whole liquid: mass-weighted mean of the particles' v_y and of the face velocity read
  double all_mass = 0.0, all_v = 0.0, all_u = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    all_mass += p.mass[i];
    all_v += p.mass[i] * p.v[i][1];
    all_u += p.mass[i] * grid.interpolate_velocity(u, p.x[i])[1];
  }
  if (columns && Dim == 2) {
    // per grid column c: the highest particle's height (in dx), the mean face v_y of the
    // particles within 2 dx of it (mm/s) and that point's distance to the nearest moving body
    // (in dx), printed as c:height:v_y:distance
    const int nx = grid.cells()[0];
    std::vector<double> top(nx, -1e300), m(nx, 0.0), mu(nx, 0.0);
    for (std::size_t i = 0; i < p.size(); ++i) {
      const int c = std::clamp(static_cast<int>((p.x[i][0] - grid.origin()[0]) / dx), 0, nx - 1);
      top[c] = std::max(top[c], p.x[i][1]);
    }
    for (std::size_t i = 0; i < p.size(); ++i) {
      const int c = std::clamp(static_cast<int>((p.x[i][0] - grid.origin()[0]) / dx), 0, nx - 1);
      if (p.x[i][1] > top[c] - 2.0 * dx) {
        m[c] += p.mass[i];
        mu[c] += p.mass[i] * grid.interpolate_velocity(u, p.x[i])[1];
      }
    }
    std::printf("columns frame %d:", frame);
    for (int c = 0; c < nx; ++c) {
      Vec<Dim> at = Vec<Dim>::Zero();
      at[0] = grid.origin()[0] + (c + 0.5) * dx;
      at[1] = top[c];
      double d = 1e300;
      for (const auto& b : bodies) d = std::min(d, b->distance(at));
      std::printf(" %d:%.1f:%+.1f:%.1f", c, top[c] / dx, m[c] > 0 ? 1e3 * mu[c] / m[c] : 0.0, d / dx);
    }
    std::printf("\n");
    // profiles of four columns, per cell from the cell of the column's highest particle down
    // 14 cells: [row, particles, W_L^p, the cell centre's distance to the nearest body (dx), the
    // mean face v_y of its particles (mm/s)]
    for (int c : {nx / 4, 2 * nx / 5, 3 * nx / 5, 24 * nx / 25}) {
      std::printf("profile column %d:", c);
      const int first = top[c] > -1e300
                            ? std::min(grid.cells()[1] - 1,
                                       static_cast<int>((top[c] - grid.origin()[1]) / dx))
                            : -1;
      for (int j = first; j >= 0 && j > first - 14; --j) {
        VecI<Dim> ci = VecI<Dim>::Zero();
        ci[0] = c;
        ci[1] = j;
        const int cell = grid.cell_index(ci);
        double mm = 0.0, uu = 0.0;
        long count = 0;
        for (std::size_t i = 0; i < p.size(); ++i) {
          if (grid.cell_containing(p.x[i]) != ci) continue;
          mm += p.mass[i];
          uu += p.mass[i] * grid.interpolate_velocity(u, p.x[i])[1];
          ++count;
        }
        Vec<Dim> at = grid.cell_center(ci);
        double d = 1e300;
        for (const auto& b : bodies) d = std::min(d, b->distance(at));
        std::printf(" [j%d n%ld WL%.2f d%.1f u%+.0f]", j, count, w.liquid_cell[cell], d / dx,
                    mm > 0 ? 1e3 * uu / mm : 0.0);
      }
      std::printf("\n");
    }
  }
  static const char* sides[3] = {"top", "bottom", "side"};
  std::printf("near frame %5d liquid %.2f kg mean v_y %+.3f mm/s (particles), %+.3f mm/s (faces)",
              frame, all_mass, 1e3 * all_v / all_mass, 1e3 * all_u / all_mass);
  std::printf(" | bodies y (m), v_y (mm/s):");
  for (const auto& b : sim->rigid_world()->bodies())
    if (b.moves()) std::printf(" %.4f %+.2f", b.position[1], 1e3 * b.velocity[1]);
  std::printf(" | mean v_y (mm/s) = solid + unwet + partial + open:");
  static const char* bins[6] = {"0-0.5", "0.5-1", "1-1.5", "1.5-3", "3-6", ">6"};
  for (int s = 0; s < 3; ++s)
    for (int b = 0; b < 6; ++b) {
      const double m = mass[s][b] > 0.0 ? mass[s][b] : 1.0;
      double total = 0.0;
      for (int k = 0; k < 4; ++k) total += vy[s][b][k];
      std::printf(" | %s %s dx %.3f kg: %+.2f = %+.2f %+.2f %+.2f %+.2f (momentum %+.4f)", sides[s],
                  bins[b], mass[s][b], 1e3 * total / m, 1e3 * vy[s][b][0] / m,
                  1e3 * vy[s][b][1] / m, 1e3 * vy[s][b][2] / m, 1e3 * vy[s][b][3] / m, total);
    }
  std::printf("\n");
}

/// The slow test's E (tests/slow/slow_long_runs.cpp, mechanical_energy): kinetic + potential
/// energy of liquid and bodies + line 15's credit when positive (a debt is not forgiven).
double test_energy(const FrameStats& s) {
  return bench::mechanical_energy(s) + std::max(0.0, s.line15_banked_energy);
}

}  // namespace

int main(int argc, char** argv) {
  int frames = 0, from = 1;
  bool affine = false, near = false, columns = false;
  std::string name;
  std::vector<std::string> only, overrides{"render.enabled=false"};
  bench::BenchArgs args(argc, argv);
  while (args.next()) {
    const std::string& a = args.flag();
    if (a == "--frames") {
      frames = std::atoi(args.value().c_str());
    } else if (a == "--from") {
      from = std::atoi(args.value().c_str());
    } else if (a == "--only") {
      for (const std::string& item : args.list()) only.push_back(item);
    } else if (a == "--affine") {
      affine = true;
    } else if (a == "--near") {
      near = true;
    } else if (a == "--columns") {
      near = columns = true;
    } else if (a == "--set") {
      overrides.push_back(args.value());
    } else if (!a.empty() && a[0] != '-' && name.empty()) {
      name = a;
    } else {
      std::cerr << "usage: bench_energy_regain SCENE [--frames N] [--from F] [--only NAME,...] "
                   "[--affine] [--near] [--columns] [--set KEY=VALUE]...\n";
      return 2;
    }
  }
  if (name.empty()) {
    std::cerr << "bench_energy_regain: give a built-in scene's name\n";
    return 2;
  }
  SceneFile scene;
  try {
    scene = load_scene(name, overrides);
  } catch (const InputError& e) {
    std::cerr << e.what() << "\n";
    return 2;
  }
  if (frames <= 0) frames = 3 * scene.time.frames;
  for (const Variant& v : variants()) {
    if (!v.selected(only)) continue;
    auto sim = make_simulation(scene, v.switches());
    const FrameStats s0 = sim->current_stats();
    const double e0 = test_energy(s0);
    double lowest = e0, worst = -1e300, worst_regain = 0.0, worst_bound = 0.0;
    int worst_frame = 0;
    EnergyLedger total;
    std::printf("%-12s %5s %7s %11s %10s %9s %8s | %9s %9s %9s %9s %9s %9s %9s | %9s %9s %10s\n",
                v.name.c_str(), "frame", "t", "E - E0", "regain", "bound", "volume", "to_grid", "solve",
                "extend", "to_part", "advect", "correct", "project", "KE liq", "KE body", "credit");
    try {
      for (int f = 1; f <= frames; ++f) {
        const FrameStats s = sim->advance_frame();
        const EnergyLedger l = sim->energy_ledger();
        bench::accumulate(total, l);
        const double e = test_energy(s);
        const double regain = e - lowest;
        // the slow test's bound without its floor of 1e-5 M g H
        const double bound = 0.02 * (e0 - lowest);
        if (regain - bound > worst) {
          worst = regain - bound;
          worst_regain = regain;
          worst_bound = bound;
          worst_frame = f;
        }
        lowest = std::min(lowest, e);
        if (f >= from)
          std::printf("%-12s %5d %7.3f %11.4e %10.3e %9.3e %+7.3f%% | %+9.2e %+9.2e %+9.2e %+9.2e %+9.2e "
                      "%+9.2e %+9.2e | %9.3e %9.3e %+10.3e\n",
                      v.name.c_str(), f, s.time, e - e0, regain, bound,
                      100.0 * (s.liquid_volume / s0.liquid_volume - 1.0), l.to_grid,
                      l.forces_and_solve, l.velocity_extension, l.to_particles, l.advection,
                      l.position_correction, l.density_projection, s.kinetic_energy_liquid,
                      s.kinetic_energy_bodies, s.line15_banked_energy);
        if (affine && f >= from) {
          if (scene.dim == 2) print_affine<2>(*sim, f);
          else print_affine<3>(*sim, f);
        }
        if (near && f >= from) {
          if (scene.dim == 2) print_near<2>(*sim, f, columns);
          else print_near<3>(*sim, f, columns);
        }
        std::fflush(stdout);
      }
    } catch (const std::exception& e) {
      std::printf("%-12s failed: %s\n", v.name.c_str(), e.what());
    }
    std::printf("summary %-12s worst regain %.4e at frame %d (bound %.4e, excess %+.4e) | ledger "
                "to_grid %+.4f solve %+.4f extend %+.4f to_part %+.4f advect %+.4f correct %+.4f "
                "project %+.4f total %+.4f\n",
                v.name.c_str(), worst_regain, worst_frame, worst_bound, worst, total.to_grid,
                total.forces_and_solve, total.velocity_extension, total.to_particles,
                total.advection, total.position_correction, total.density_projection,
                total.total());
    std::fflush(stdout);
  }
  return 0;
}
