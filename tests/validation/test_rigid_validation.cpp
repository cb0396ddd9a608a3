// Validation of the rigid-body contact model (reference/rigid/rigid_world.hpp) against closed-form
// mechanics, 2D and 3D. Every case states its source, the measured error and the tolerance.
#include <catch2/catch.hpp>

#include <cmath>

#include "reference/app/scene_file.hpp"
#include "reference/app/stats_json.hpp"
#include "reference/rigid/rigid_world.hpp"
#include "reference/sim/simulation.hpp"

using namespace monolith;
using nlohmann::json;

namespace {

constexpr double kG = 9.81;

/// A vector of `dim` numbers: x, y, then z = 0.5 (the middle of a unit-deep 3D domain).
json p(int dim, double x, double y) {
  return dim == 2 ? json{x, y} : json{x, y, 0.5};
}

/// A scene with walls all round [lo, hi]^Dim, cubic cells dx, and the given bodies.
SceneDesc scene_with(int dim, const json& bodies, double lo, double hi, int cells,
                     double wall_friction, int staggered = 2) {
  json j = {{"format", "monolith-scene/1"}, {"name", "validation"}, {"dim", dim}};
  j["domain"] = {{"lower", dim == 2 ? json{lo, lo} : json{lo, lo, lo}},
                 {"upper", dim == 2 ? json{hi, hi} : json{hi, hi, hi}},
                 {"cells", dim == 2 ? json{cells, cells} : json{cells, cells, cells}},
                 {"wall_friction", wall_friction},
                 {"wall_restitution", 0.0}};
  j["solver"] = {{"staggered_iterations", staggered}};
  j["bodies"] = bodies;
  return parse_scene(j, "validation", ".");
}

json rotation(int dim, double angle) {
  return dim == 2 ? json(angle) : json{0.0, 0.0, angle};
}

/// A block of half size (0.06, 0.04[, 0.06]) resting on a ramp (a static box rotated by theta),
/// both with friction mu. Returns the world; the block is body 1.
template <int Dim>
RigidWorld<Dim> incline_world(double theta, double mu) {
  const double c[2] = {0.5, 0.25};
  const double half_thick = 0.05, block_half = 0.04;
  const double n[2] = {-std::sin(theta), std::cos(theta)};
  const double t[2] = {std::cos(theta), std::sin(theta)};
  const double s0 = 0.3, lift = half_thick + block_half;
  json ramp_half = Dim == 2 ? json{0.6, half_thick} : json{0.6, half_thick, 0.3};
  json block_half_size = Dim == 2 ? json{0.06, block_half} : json{0.06, block_half, 0.06};
  json bodies = json::array();
  bodies.push_back({{"name", "ramp"}, {"motion", "static"}, {"friction", mu},
                    {"shape", {{"type", "box"}, {"center", p(Dim, c[0], c[1])}, {"half_size", ramp_half},
                               {"rotation", rotation(Dim, theta)}}}});
  bodies.push_back({{"name", "block"}, {"density", 500}, {"friction", mu},
                    {"shape", {{"type", "box"},
                               {"center", p(Dim, c[0] + s0 * t[0] + lift * n[0], c[1] + s0 * t[1] + lift * n[1])},
                               {"half_size", block_half_size}, {"rotation", rotation(Dim, theta)}}}});
  return RigidWorld<Dim>(scene_with(Dim, bodies, -0.5, 1.5, Dim == 2 ? 128 : 64, 0.0));
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("incline: slides with a = g (sin theta - mu cos theta) when tan theta > mu",
                       "[validation]", ((int Dim), Dim), 2, 3) {
  // source: Coulomb friction on an inclined plane (any mechanics text), a = g (sin - mu cos).
  // theta = 0.5, mu = 0.3: a = 2.1197 m/s^2. Measured from the block's velocity along the slope
  // between t = 0.1 s and 0.5 s: 2D 2.12044, 3D 2.12044 (error < 1e-5); tolerance 2 %. Max
  // penetration: the margin, 0.1 dx, in both.
  const double theta = 0.5, mu = 0.3, dt = 0.005;
  RigidWorld<Dim> world = incline_world<Dim>(theta, mu);
  Vec<Dim> slope = Vec<Dim>::Zero(), g = Vec<Dim>::Zero();
  slope[0] = std::cos(theta);
  slope[1] = std::sin(theta);
  g[1] = -kG;
  double v1 = 0.0, v2 = 0.0, max_pen = 0.0;
  for (int k = 1; k <= 100; ++k) {
    const RigidStepStats s = world.step(dt, (k - 1) * dt, g);
    max_pen = std::max(max_pen, s.max_penetration);
    if (k == 20) v1 = world.bodies()[1].velocity.dot(slope);
    if (k == 100) v2 = world.bodies()[1].velocity.dot(slope);
  }
  const double a = -(v2 - v1) / (80 * dt);
  const double expected = kG * (std::sin(theta) - mu * std::cos(theta));
  INFO("measured a = " << a << " expected " << expected << " max penetration " << max_pen);
  CHECK(a == Approx(expected).epsilon(0.02));
  // the block neither sinks into nor leaves the ramp: within the margin (dx/10) plus 10 %
  CHECK(max_pen <= 1.1 * 0.1 * world.settings().dx);
}

TEMPLATE_TEST_CASE_SIG("incline: sticks when tan theta <= mu", "[validation]", ((int Dim), Dim), 2, 3) {
  // source: static friction holds when tan theta <= mu. theta = 0.5 (tan 0.546), mu = 0.6.
  // Measured displacement over 0.9 s: 2D 1.6e-4 dx, 3D 9e-3 dx; tolerance 0.05 dx.
  const double theta = 0.5, mu = 0.6, dt = 0.005;
  RigidWorld<Dim> world = incline_world<Dim>(theta, mu);
  Vec<Dim> g = Vec<Dim>::Zero();
  g[1] = -kG;
  // settle the margin for a few steps, then measure
  for (int k = 0; k < 20; ++k) world.step(dt, k * dt, g);
  const Vec<Dim> x0 = world.bodies()[1].position;
  for (int k = 20; k < 200; ++k) world.step(dt, k * dt, g);
  const double drift = (world.bodies()[1].position - x0).norm();
  INFO("drift " << drift / world.settings().dx << " dx");
  CHECK(drift <= 0.05 * world.settings().dx);
}

TEMPLATE_TEST_CASE_SIG("a block sliding on the floor stops after v0^2 / (2 mu g)", "[validation]",
                       ((int Dim), Dim), 2, 3) {
  // source: uniform Coulomb deceleration mu g. v0 = 2 m/s, mu = 0.5: distance 0.4077 m, time
  // 0.408 s. Measured: 2D 0.4037 m (-1.0 %), 3D 0.4037 m (-1.0 %), stop at 0.408 s in both; the
  // deficit is that of symplectic Euler, x += dt v_new, which loses v0 dt / 2 = 4 mm; tolerance
  // 3 % on the distance, 3 steps on the time.
  const double v0 = 2.0, mu = 0.5, dt = 0.004;
  json half = Dim == 2 ? json{0.05, 0.05} : json{0.05, 0.05, 0.05};
  json bodies = json::array();
  // resting in the margin (phi = -epsilon): a block placed at phi = 0 would first sink through
  // epsilon and land with a small vertical speed, whose impact takes mu times its impulse
  const double dx = Dim == 2 ? 1.0 / 64 : 1.0 / 32, y0 = 0.05 - 0.1 * dx;
  bodies.push_back({{"name", "block"}, {"density", 500}, {"friction", mu},
                    {"shape", {{"type", "box"}, {"center", p(Dim, 0.2, y0)}, {"half_size", half}}}});
  bodies[0]["velocity"] = Dim == 2 ? json{v0, 0.0} : json{v0, 0.0, 0.0};
  RigidWorld<Dim> world(scene_with(Dim, bodies, 0.0, 1.0, Dim == 2 ? 64 : 32, mu));
  Vec<Dim> g = Vec<Dim>::Zero();
  g[1] = -kG;
  const double x0 = world.bodies()[0].position[0];
  double stop_time = -1.0;
  for (int k = 0; k < 200; ++k) {
    world.step(dt, k * dt, g);
    // stopped: below 1 mm/s (5e-4 v0)
    if (stop_time < 0 && std::abs(world.bodies()[0].velocity[0]) < 1e-3) stop_time = (k + 1) * dt;
  }
  const double distance = world.bodies()[0].position[0] - x0;
  const double expected = v0 * v0 / (2.0 * mu * kG);
  INFO("distance " << distance << " expected " << expected << " stop time " << stop_time);
  CHECK(distance == Approx(expected).epsilon(0.03));
  CHECK(stop_time == Approx(v0 / (mu * kG)).margin(3 * dt));
  // it does not tip or hop: the height stays within the margin
  CHECK(std::abs(world.bodies()[0].position[1] - y0) <= 0.05 * dx);
}

TEMPLATE_TEST_CASE_SIG("a ball dropped from h with restitution e bounces to about e^2 h", "[validation]",
                       ((int Dim), Dim), 2, 3) {
  // source: Newton's restitution law, rebound speed e v, so the apex is e^2 h. h = 0.4 m (the
  // ball's bottom above the floor), e = 0.5: 0.1 m. The speculative contact bounces the ball in
  // the step in which its gap would close, up to one step's travel v dt before touching (2.8 m/s
  // x 2 ms = 5.6 mm), and the margin shifts the rest height by epsilon: the bound asserted is
  // v dt + epsilon. Measured 2D 0.1032 m (+3.2 %), 3D 0.1032 m (+3.2 %).
  const double h = 0.4, r = 0.05, e = 0.5, dt = 0.002;
  json bodies = json::array();
  bodies.push_back({{"name", "ball"}, {"density", 500}, {"restitution", e},
                    {"shape", {{"type", "sphere"}, {"center", p(Dim, 0.5, h + r)}, {"radius", r}}}});
  RigidWorld<Dim> world(scene_with(Dim, bodies, 0.0, 1.0, Dim == 2 ? 64 : 32, 0.0));
  Vec<Dim> g = Vec<Dim>::Zero();
  g[1] = -kG;
  bool bounced = false;
  double apex = 0.0;
  for (int k = 0; k < 500; ++k) {
    world.step(dt, k * dt, g);
    const double vy = world.bodies()[0].velocity[1];
    const double y = world.bodies()[0].position[1] - r;
    if (vy > 0.0) bounced = true;
    if (bounced) apex = std::max(apex, y);
    if (bounced && vy < 0.0 && y < 0.5 * apex) break;
  }
  INFO("apex " << apex << " expected " << e * e * h);
  REQUIRE(bounced);
  const double impact_speed = std::sqrt(2.0 * kG * h);
  CHECK(std::abs(apex - e * e * h) <= impact_speed * dt + 0.1 * world.settings().dx);
}

TEMPLATE_TEST_CASE_SIG("a stack of four boxes stays at rest for three seconds", "[validation]",
                       ((int Dim), Dim), 2, 3) {
  // source: static equilibrium. Boxes 0.16 x 0.1 (x 0.16) stacked touching; after 0.2 s of
  // settling into the margin, every box's drift over the next 2.8 s: measured 2D 4.8e-7 dx,
  // 3D 5.3e-6 dx; tolerance 0.05 dx. Max penetration: measured 0.1001 dx (2D), 0.1003 dx (3D),
  // the margin epsilon = 0.1 dx; bound 0.11 dx.
  const double dt = 0.01, h = 0.05;
  json half = Dim == 2 ? json{0.08, h} : json{0.08, h, 0.08};
  json bodies = json::array();
  for (int i = 0; i < 4; ++i)
    bodies.push_back({{"name", "box" + std::to_string(i)}, {"density", 500}, {"friction", 0.5},
                      {"shape", {{"type", "box"}, {"center", p(Dim, 0.5, h + 2 * h * i)}, {"half_size", half}}}});
  RigidWorld<Dim> world(scene_with(Dim, bodies, 0.0, 1.0, Dim == 2 ? 64 : 32, 0.5));
  Vec<Dim> g = Vec<Dim>::Zero();
  g[1] = -kG;
  std::vector<Vec<Dim>> settled;
  double max_pen = 0.0;
  for (int k = 0; k < 300; ++k) {
    const RigidStepStats s = world.step(dt, k * dt, g);
    max_pen = std::max(max_pen, s.max_penetration);
    if (k == 19)
      for (const auto& b : world.bodies()) settled.push_back(b.position);
  }
  const double dx = world.settings().dx;
  double drift = 0.0;
  for (std::size_t i = 0; i < settled.size(); ++i)
    drift = std::max(drift, (world.bodies()[i].position - settled[i]).norm());
  INFO("drift " << drift / dx << " dx, max penetration " << max_pen / dx << " dx");
  CHECK(drift <= 0.05 * dx);
  CHECK(max_pen <= 0.11 * dx);
  CHECK(world.kinetic_energy() < 1e-8);
}

TEST_CASE("the simulation runs the rigid world for a built-in scene and reports it in the stats",
          "[validation]") {
  // the hook of Algorithm 1's body lines into Simulation<Dim> (reference/sim/simulation.cpp):
  // box-stack-2d/3d for 0.5 s, stats of every frame carry the bodies, the contacts, the body
  // kinetic energy and the contact DOFs; the stack (placed with 1-2 mm gaps) comes to rest with
  // every contact epsilon = 0.1 dx deep: box i (half height h) at h (2 i + 1) - (i + 1) epsilon.
  // Measured deviation from that: at most 2.3e-4 dx (2D), 6.4e-4 dx (3D); bound 0.05 dx.
  for (const char* name : {"box-stack-2d", "box-stack-3d"}) {
    CAPTURE(name);
    SceneDesc scene = load_scene(name, {"time.frames=25"});
    const auto sim = make_simulation(scene);
    FrameStats s;
    for (int f = 0; f < 25; ++f) s = sim->advance_frame();
    REQUIRE(s.bodies.size() == scene.bodies.size());
    CHECK(s.contact_count > 0);
    CHECK(s.max_penetration > 0.0);
    CHECK(s.max_penetration <= 0.11 * scene.dx());
    CHECK(s.solver.dofs_contact == s.contact_count);
    CHECK(s.solver.converged);
    CHECK(s.kinetic_energy_bodies < 1e-8);
    const double eps = 0.1 * scene.dx();
    for (std::size_t i = 0; i < scene.bodies.size(); ++i) {
      const double h = scene.bodies[i].shape.half_size[1];
      const double rest = h * (2.0 * i + 1.0) - (i + 1.0) * eps;
      INFO("box " << i << " off its rest height by " << (s.bodies[i].position[1] - rest) / scene.dx() << " dx");
      CHECK(std::abs(s.bodies[i].position[1] - rest) <= 0.05 * scene.dx());
      CHECK(std::abs(s.bodies[i].position[0] - scene.bodies[i].shape.center[0]) < 1e-4);
    }
    // the stats line carries the contract's keys
    const nlohmann::json j = frame_stats_json(s);
    CHECK(j["contacts"]["count"] == s.contact_count);
    CHECK(j["kinetic_energy"]["bodies"].get<double>() == s.kinetic_energy_bodies);
    CHECK(j["bodies"].size() == scene.bodies.size());
  }
}
