// Every face a particle reads after the solve holds the extrapolated velocity (issue 16; the
// guard of Simulation::advect, docs/particles.md "Velocity extrapolation"). Splash particles of
// dam-break-2d (from frame 17; from frame 15 before the ballistic faces beside walls took the
// particles' PIC velocity, energy8b) and of pour-into-bowl-3d at 24^3 (from frame 17) read faces that
// no layer of the extrapolation reached (their path runs ahead of the trusted liquid); they used
// to read whatever the solve had left there.
#include <catch2/catch.hpp>
#include <memory>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/sim/simulation.hpp"

using namespace monolith;

namespace {

template <int Dim>
std::unique_ptr<Simulation<Dim>> scene_run(const std::string& name,
                                           const std::vector<std::string>& sets,
                                           const StageSwitches& switches) {
  std::vector<std::string> overrides = sets;
  overrides.push_back("render.enabled=false");
  return std::make_unique<Simulation<Dim>>(load_scene(name, overrides), switches);
}

/// The same particles bit for bit: count, positions, velocities and affine matrices.
template <int Dim>
void require_same_particles(const Particles<Dim>& p, const Particles<Dim>& q) {
  REQUIRE(p.size() == q.size());
  long differing = 0;
  for (std::size_t i = 0; i < p.size(); ++i)
    differing += !(p.x[i] == q.x[i] && p.v[i] == q.v[i] && p.c[i] == q.c[i]);
  REQUIRE(differing == 0);
}

/// The scene for `frames` frames three ways: (1) the faces not reached poisoned (NaN, no fallback
/// to the solve's value): no particle may read one, and the deeper extrapolations must have been
/// needed (or the scene tests nothing); (2) the extrapolation over every face it can reach: the
/// same particles bit for bit every frame (only a probe in the far air may differ); (3) without
/// the deeper extrapolations, poisoned: some particle reads a face not reached by frame
/// `frames` (the hole the guard closes).
template <int Dim>
void check_every_read_reached(const std::string& name, const std::vector<std::string>& sets,
                              int frames) {
  INFO(name);
  // (the scenes' frames were chosen with the whole drift and line 15's energy free, the
  // defaults before slosh11; with drift-kick-drift no particle of these frames reads beyond the
  // ordinary extrapolation, and the guard would test nothing)
  StageSwitches before;
  before.split_advection = false;
  before.line15_energy = Line15Energy::free;
  StageSwitches poisoned = before, everywhere = before, unguarded = before;
  poisoned.poison_unreached_faces = true;
  everywhere.extrapolate_everywhere = true;
  unguarded.poison_unreached_faces = true;
  unguarded.extend_to_every_read = false;
  auto guarded = scene_run<Dim>(name, sets, poisoned);
  auto reference = scene_run<Dim>(name, sets, everywhere);
  for (int frame = 1; frame <= frames; ++frame) {
    INFO("frame " << frame);
    const FrameStats a = guarded->advance_frame();
    const FrameStats b = reference->advance_frame();
    REQUIRE(a.steps == b.steps);
    REQUIRE(a.dt_min == b.dt_min);
    require_same_particles(guarded->particles(), reference->particles());
    CHECK(a.kinetic_energy_liquid == b.kinetic_energy_liquid);
  }
  CHECK(guarded->reread_particles() > 0);
  auto hole = scene_run<Dim>(name, sets, unguarded);
  CHECK_THROWS_WITH(
      [&] {
        for (int frame = 1; frame <= frames; ++frame) hole->advance_frame();
      }(),
      Catch::Contains("read a face the extrapolation did not reach"));
}

}  // namespace

TEST_CASE("every face a particle reads after the solve is reached by the extrapolation (2D)",
          "[validation][regression]") {
  check_every_read_reached<2>("dam-break-2d", {}, 17);
}

TEST_CASE("every face a particle reads after the solve is reached by the extrapolation (3D)",
          "[validation][regression]") {
  // the bowl at a third of its cells: from frame 17 on, splashes read faces not reached
  check_every_read_reached<3>("pour-into-bowl-3d", {"domain.cells=[24,24,24]"}, 17);
}


namespace {

/// The largest Frobenius norm of the particles' affine matrices c over `frames` frames of a film
/// on the floor of dam-break-2d (0.6 m long, 4 mm = 0.64 dx thick: the level set does not resolve
/// it, so the faces above its particles carry mass with W_L^u = 0, the ballistic faces).
double film_largest_affine(const StageSwitches& switches, int frames, double& g_dt_over_dx) {
  auto sim = scene_run<2>("dam-break-2d",
                          {"liquids[0].shape.center=[0.4,0.002]",
                           "liquids[0].shape.half_size=[0.3,0.002]"},
                          switches);
  g_dt_over_dx = 9.81 * sim->scene().time.max_dt / sim->grid().dx();
  double largest = 0.0;
  for (int frame = 1; frame <= frames; ++frame) {
    sim->advance_frame();
    for (const auto& c : sim->particles().c) largest = std::max(largest, c.norm());
  }
  return largest;
}

}  // namespace

TEST_CASE("a film on the floor does not store free fall in its affine matrices",
          "[validation][regression]") {
  // Issue 16 (docs/particles.md, "Energy regains over long runs"): a ballistic face above a
  // particle the floor supports kept P2G's APIC value plus g dt, so G2P lowered the particle's
  // c_yy by g dt / dx every step, a sum the transfers later released as energy (the spilled film
  // of liquid-bunny-into-bowl-3d). With the PIC value on those faces c holds about one step's
  // free fall; with the APIC value it grows to several (170 /s against g dt / dx = 31 /s).
  double g_dt_over_dx = 0.0;
  // (the whole drift and line 15's energy free, the defaults before slosh11: with `balance`
  // and its debt the film's line 15 lifts, which its small kinetic energy cannot pay, take v and
  // c to zero, and both rules read 0)
  StageSwitches pic_switches;
  pic_switches.split_advection = false;
  pic_switches.line15_energy = Line15Energy::free;
  const double pic = film_largest_affine(pic_switches, 30, g_dt_over_dx);
  StageSwitches apic_switches = pic_switches;
  apic_switches.ballistic_faces_pic = false;
  const double apic = film_largest_affine(apic_switches, 30, g_dt_over_dx);
  INFO("largest |c|: PIC on the ballistic faces " << pic << " /s, APIC " << apic
                                                   << " /s, g dt_max / dx " << g_dt_over_dx);
  CHECK(pic < 3.0 * g_dt_over_dx);
  CHECK(apic > 3.0 * g_dt_over_dx);  // the test would see the old rule
}

namespace {

/// The defaults (drift-kick-drift): the extrapolation after the solve reaches only the step's
/// reach, and the next step's first half drift reads through the guard (drift_guarded). With the
/// extrapolation cut to `layers` (so that the guards must extend it: at the step's reach no
/// particle of these frames reads beyond it) and the faces not reached poisoned (a read left
/// unreached throws), the particles are bit for bit those of the extrapolation to the cfl bound
/// (the layers the drift was given before particles12), every frame, and the drift's deeper
/// extrapolations must have been needed. Line 15's payments scale u_ between the two drifts of
/// these scenes, so the deeper values' scaling is checked too.
template <int Dim>
void check_drift_reads_reached(const std::string& name, const std::vector<std::string>& sets,
                               int frames, int layers) {
  INFO(name);
  StageSwitches poisoned, bound;
  poisoned.poison_unreached_faces = true;
  poisoned.extrapolation_layers = layers;
  bound.extrapolate_cfl_layers = true;
  auto guarded = scene_run<Dim>(name, sets, poisoned);
  auto reference = scene_run<Dim>(name, sets, bound);
  // restored half way (the checkpoint's drift velocity resolved to the deepest pass): it goes on
  // as the guarded run
  std::unique_ptr<Simulation<Dim>> restored;
  for (int frame = 1; frame <= frames; ++frame) {
    INFO("frame " << frame);
    const FrameStats a = guarded->advance_frame();
    const FrameStats b = reference->advance_frame();
    if (restored) {
      restored->advance_frame();
      const Particles<Dim>& r = restored->particles();
      const Particles<Dim>& g = guarded->particles();
      CHECK((r.x == g.x && r.v == g.v && r.c == g.c));
    }
    if (frame == frames / 2) {
      restored = scene_run<Dim>(name, sets, poisoned);
      restored->load_state(guarded->save_state());
    }
    REQUIRE(a.steps == b.steps);
    REQUIRE(a.dt_min == b.dt_min);
    require_same_particles(guarded->particles(), reference->particles());
    CHECK(a.kinetic_energy_liquid == b.kinetic_energy_liquid);
    CHECK(a.liquid_volume == b.liquid_volume);
  }
  CHECK(guarded->drift_reread_particles() > 0);
}

}  // namespace

TEST_CASE("the first half drift reads only faces an extrapolation reached (2D)",
          "[validation][regression]") {
  check_drift_reads_reached<2>("dam-break-2d", {}, 17, 1);
}

TEST_CASE("the first half drift reads only faces an extrapolation reached (2D, a static disk; 3D)",
          "[validation][regression]") {
  // the disk's faces in the solid are constrained in the deeper extrapolations as in the step's
  check_drift_reads_reached<2>("default", {}, 20, 1);
  check_drift_reads_reached<3>("dam-break-3d", {"domain.cells=[32,16,16]"}, 12, 1);
}
