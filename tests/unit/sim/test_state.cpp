// Tests of the simulation state as plain bytes (reference/core/state_io.hpp,
// Simulation::save_state / load_state, docs/checkpoints.md): fields round-trip exactly, bytes
// that do not fit are refused with InputError, and a restored simulation continues bit for bit
// (also when it was stopped between two steps of a frame).
#include <catch2/catch.hpp>

#include <csignal>
#include <cstring>

#include <omp.h>

#include "reference/app/scene_file.hpp"
#include "reference/core/errors.hpp"
#include "reference/core/parallel.hpp"
#include "reference/core/state_io.hpp"
#include "reference/sim/simulation.hpp"

using namespace monolith;

namespace {

struct Sample {
  int i = 0;
  double d = 0.0;
  bool b = false;
  std::string s;
  std::vector<Vec<3>> points;
  std::vector<int> ints;
  VectorX v;
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();

  template <class Archive>
  void state_fields(Archive& a) {
    a(i);
    a(d);
    a(b);
    a(s);
    a(points);
    a(ints);
    a(v);
    a(q);
  }
};

SceneFile small_scene(const std::string& name, const std::string& cells) {
  return load_scene(name, {"domain.cells=" + cells, "render.enabled=false"});
}

/// Every state field that stats show, compared exactly.
void check_same_stats(const FrameStats& a, const FrameStats& b) {
  CHECK(a.frame == b.frame);
  CHECK(a.time == b.time);
  CHECK(a.steps == b.steps);
  CHECK(a.dt_min == b.dt_min);
  CHECK(a.dt_max == b.dt_max);
  CHECK(a.liquid_volume == b.liquid_volume);
  CHECK(a.particles == b.particles);
  CHECK(a.kinetic_energy_liquid == b.kinetic_energy_liquid);
  CHECK(a.kinetic_energy_bodies == b.kinetic_energy_bodies);
  CHECK(a.solver.iterations == b.solver.iterations);
  CHECK(a.solver.max_relative_residual == b.solver.max_relative_residual);
  CHECK(a.solver.stokes_solves_multigrid == b.solver.stokes_solves_multigrid);
  CHECK(a.solver.stokes_solves_ssor == b.solver.stokes_solves_ssor);
  CHECK(a.solver.preconditioner_fallbacks == b.solver.preconditioner_fallbacks);
  CHECK(a.solver.unsettled_steps == b.solver.unsettled_steps);
  REQUIRE(a.bodies.size() == b.bodies.size());
  for (std::size_t i = 0; i < a.bodies.size(); ++i) {
    CHECK(a.bodies[i].position == b.bodies[i].position);
    CHECK(a.bodies[i].orientation == b.bodies[i].orientation);
    CHECK(a.bodies[i].velocity == b.bodies[i].velocity);
  }
}

}  // namespace

TEST_CASE("StateWriter and StateReader round-trip every kind of field exactly", "[unit]") {
  Sample a;
  a.i = -7;
  a.d = 0.1 + 0.2;
  a.b = true;
  a.s = std::string("with\0nul", 8);
  a.points = {Vec<3>(1, 2, 3), Vec<3>(-0.0, 1e-300, 4)};
  a.ints = {1, -2, 3};
  a.v = VectorX::LinSpaced(5, 0.0, 1.0);
  a.q = Eigen::Quaterniond(0.5, 0.5, -0.5, 0.5);
  StateWriter w;
  w(a);
  const std::vector<char> bytes = w.take();
  Sample b;
  StateReader r(bytes, "test");
  r(b);
  r.finish();
  CHECK(b.i == a.i);
  CHECK(b.d == a.d);
  CHECK(b.b);
  CHECK(b.s == a.s);
  CHECK(b.points == a.points);
  CHECK(b.ints == a.ints);
  CHECK(b.v == a.v);
  CHECK(b.q.coeffs() == a.q.coeffs());
  // every shorter prefix is refused, never read past its end
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    Sample c;
    const std::vector<char> prefix(bytes.begin(), bytes.begin() + static_cast<long>(n));
    StateReader cut(prefix, "test");
    CHECK_THROWS_AS(cut(c), InputError);
  }
  // left-over bytes are refused
  std::vector<char> longer = bytes;
  longer.push_back(0);
  Sample c;
  StateReader extra(longer, "test");
  extra(c);
  CHECK_THROWS_AS(extra.finish(), InputError);
  // a length field beyond the data is refused without allocating it
  std::vector<char> huge = bytes;
  const std::size_t string_length_at = sizeof(int) + sizeof(double) + 1;
  for (int k = 0; k < 8; ++k) huge[string_length_at + k] = static_cast<char>(0x7f);
  StateReader big(huge, "test");
  CHECK_THROWS_AS(big(c), InputError);
}

TEST_CASE("a restored simulation continues bit for bit, also from inside a frame", "[unit]") {
  for (const auto& [name, cells] : std::vector<std::pair<std::string, std::string>>{
           {"bunnies-onto-pool-2d", "[32,32]"}, {"liquid-drop-bingham-3d", "[10,10,10]"}}) {
    INFO(name);
    const SceneFile scene = small_scene(name, cells);
    // straight: three frames
    auto straight = make_simulation(scene);
    std::vector<FrameStats> expected;
    for (int k = 0; k < 3; ++k) expected.push_back(straight->advance_frame());
    // stopped inside frame 2 (the flag is raised before it starts: it stops after one step)
    auto first = make_simulation(scene);
    first->advance_frame();
    volatile std::sig_atomic_t stop = 1;
    first->set_stop_flag(&stop);
    first->advance_frame();
    REQUIRE(first->mid_frame());
    const std::vector<char> bytes = first->save_state();
    REQUIRE_FALSE(bytes.empty());
    // a fresh simulation of the same scene takes the state and finishes the run
    auto second = make_simulation(scene);
    second->load_state(bytes);
    CHECK(second->mid_frame());
    check_same_stats(second->advance_frame(), expected[1]);
    CHECK_FALSE(second->mid_frame());
    check_same_stats(second->advance_frame(), expected[2]);
    // the saved state is the same bytes again after a round trip
    auto third = make_simulation(scene);
    third->load_state(bytes);
    CHECK(third->save_state() == bytes);
  }
}

TEST_CASE("with the surface deficits handed to the solve, a restored simulation continues bit for bit", "[unit]") {
  // SurfaceDeficits::to_solve: the deficits the last density projection listed are the next
  // step's divergence source (Simulation::volume_source), so they are part of the state; a
  // simulation restored after a frame or inside one must read them as the straight run does
  StageSwitches switches;
  switches.density_projection_surface_deficits = SurfaceDeficits::to_solve;
  const SceneFile scene = small_scene("bunnies-onto-pool-2d", "[32,32]");
  auto straight = make_simulation(scene, switches);
  std::vector<FrameStats> expected;
  for (int k = 0; k < 3; ++k) expected.push_back(straight->advance_frame());
  // after frame 1
  auto first = make_simulation(scene, switches);
  first->advance_frame();
  const std::vector<char> after_frame = first->save_state();
  // stopped inside frame 2 (after its first step)
  volatile std::sig_atomic_t stop = 1;
  first->set_stop_flag(&stop);
  first->advance_frame();
  REQUIRE(first->mid_frame());
  const std::vector<char> inside_frame = first->save_state();
  auto from_frame = make_simulation(scene, switches);
  from_frame->load_state(after_frame);
  check_same_stats(from_frame->advance_frame(), expected[1]);
  check_same_stats(from_frame->advance_frame(), expected[2]);
  auto from_inside = make_simulation(scene, switches);
  from_inside->load_state(inside_frame);
  check_same_stats(from_inside->advance_frame(), expected[1]);
  check_same_stats(from_inside->advance_frame(), expected[2]);
  // a state restored and saved again is the same bytes
  auto again = make_simulation(scene, switches);
  again->load_state(inside_frame);
  CHECK(again->save_state() == inside_frame);
}

TEST_CASE("the preconditioner's fallbacks booked before a stop inside a frame survive the state", "[unit]") {
  // A viscous liquid under "auto" with max_iterations and tolerance such that each block-preconditioned
  // solve misses its attempt budget and is redone with SSOR (docs/preconditioners.md section 20):
  // each step books fallbacks, so a frame stopped after its first step has some to carry over.
  // Frame 4: the sphere falls freely through frames 1-2 and the first step of frame 3, whose
  // right-hand sides are round-off and solved by no iteration (docs/preconditioners.md section 33).
  const SceneFile scene = load_scene("viscous-sphere-wall-2d",
                                     {"domain.cells=[24,24]", "render.enabled=false", "solver.preconditioner=auto",
                                      "solver.max_iterations=2", "solver.tolerance=1e-13"});
  auto straight = make_simulation(scene);
  for (int k = 0; k < 3; ++k) straight->advance_frame();
  const FrameStats expected = straight->advance_frame();
  REQUIRE(expected.steps >= 2);
  REQUIRE(expected.solver.preconditioner_fallbacks >= 2);
  auto first = make_simulation(scene);
  for (int k = 0; k < 3; ++k) first->advance_frame();
  volatile std::sig_atomic_t stop = 1;
  first->set_stop_flag(&stop);
  first->advance_frame();
  REQUIRE(first->mid_frame());
  auto second = make_simulation(scene);
  second->load_state(first->save_state());
  check_same_stats(second->advance_frame(), expected);
}

TEST_CASE("load_state refuses bytes of another scene or dimension, or damaged bytes", "[unit]") {
  const SceneFile pool = small_scene("bunnies-onto-pool-2d", "[32,32]");
  const SceneFile dam = small_scene("dam-break-2d", "[32,16]");
  const SceneFile drop3 = small_scene("liquid-drop-bingham-3d", "[10,10,10]");
  const std::vector<char> pool_state = make_simulation(pool)->save_state();
  CHECK_THROWS_AS(make_simulation(dam)->load_state(pool_state), InputError);    // bodies, grid
  CHECK_THROWS_AS(make_simulation(drop3)->load_state(pool_state), InputError);  // dimension
  CHECK_THROWS_AS(make_simulation(pool)->load_state({}), InputError);
  std::vector<char> cut(pool_state.begin(), pool_state.end() - 3);
  CHECK_THROWS_AS(make_simulation(pool)->load_state(cut), InputError);
}

namespace {

/// Entries of two vectors that differ in their bits (sizes must match).
long bits_differ(const VectorX& a, const VectorX& b) {
  REQUIRE(a.size() == b.size());
  long n = 0;
  for (Eigen::Index i = 0; i < a.size(); ++i)
    n += std::memcmp(&a[i], &b[i], sizeof(double)) != 0;
  return n;
}

template <int Dim>
FrameStats check_frame_end_left_pending(const SceneDesc& scene, bool expect_pending) {
  // A: two frames; its frame's end leaves W_L^p, W_L^u and eta per cell until they are read
  Simulation<Dim> a(scene);
  a.advance_frame();
  a.advance_frame();
  CHECK(a.frame_end_weights_pending() == expect_pending);
  const FrameStats stats_a = a.current_stats();
  // B: the same state restored, whose load_state makes the whole weights of the frame's end
  Simulation<Dim> b(scene);
  b.load_state(a.save_state());
  CHECK_FALSE(b.frame_end_weights_pending());
  CHECK(stats_a.liquid_volume == b.current_stats().liquid_volume);
  CHECK(bits_differ(a.liquid_phi(), b.liquid_phi()) == 0);
  CHECK(bits_differ(a.cell_eta(), b.cell_eta()) == 0);
  // (read here: made now, from the same particles)
  CHECK(bits_differ(a.weights().liquid_cell, b.weights().liquid_cell) == 0);
  CHECK(bits_differ(a.weights().liquid_face, b.weights().liquid_face) == 0);
  CHECK_FALSE(a.frame_end_weights_pending());
  // C: the same run never read: after one more frame A, B and C agree bit for bit
  Simulation<Dim> c(scene);
  for (int k = 0; k < 3; ++k) c.advance_frame();
  const FrameStats third_a = a.advance_frame(), third_b = b.advance_frame();
  check_same_stats(third_a, c.current_stats());
  check_same_stats(third_b, c.current_stats());
  long moved = 0;
  for (std::size_t p = 0; p < c.particles().x.size(); ++p)
    moved += a.particles().x[p] != c.particles().x[p] || b.particles().x[p] != c.particles().x[p];
  CHECK(moved == 0);
  return c.current_stats();
}

}  // namespace

TEST_CASE("a frame's end that leaves the liquid weights and eta per cell until read gives the "
          "whole weights' values and the same run",
          "[unit]") {
  // (the viscous bunny's container at 12^3, cfl 100: the next step's dt is max_dt whatever
  // W_L^u is; the 2D bowl at cfl 100 likewise, and at cfl 0.2, where the limit may bind, the
  // frame's end makes every weight)
  SECTION("3d, static container, viscous; 1, 2, 3 and 5 threads") {
    // (at 32^3 the bound's face rows are above the serial fall-back: 101376 faces, the band's
    // box about half of them)
    const SceneFile scene = small_scene("viscous-bunny-into-sphere-3d", "[32,32,32]");
    const bool monitor = core_monitor();
    set_core_monitor(false);
    const int threads = omp_get_max_threads();
    std::vector<FrameStats> third;
    for (int t : {1, 2, 3, 5}) {
      INFO(t << " threads");
      omp_set_num_threads(t);
      third.push_back(check_frame_end_left_pending<3>(scene, true));
      check_same_stats(third.back(), third.front());
    }
    omp_set_num_threads(threads);
    set_core_monitor(monitor);
  }
  SECTION("2d, static bowl, inviscid") {
    const SceneFile scene =
        load_scene("pour-into-bowl-2d", {"domain.cells=[32,32]", "render.enabled=false",
                                         "time.cfl=100", "time.max_dt=0.005"});
    check_frame_end_left_pending<2>(scene, true);
    const SceneFile tight =
        load_scene("pour-into-bowl-2d", {"domain.cells=[32,32]", "render.enabled=false",
                                         "time.cfl=0.2"});
    check_frame_end_left_pending<2>(tight, false);
  }
}
