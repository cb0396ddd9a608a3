// Volume steadiness over the built-in dam breaks: stats.jsonl's liquid_volume, sum(W_L^p) dx^Dim
// of the particle level set, must stay within 1% of its frame-0 value at every frame (the issue's
// requirement). The liquid is carried by particles of fixed volume; what keeps the level set's
// volume on theirs is the position correction of Algorithm 1 line 15 (the density constraint and
// the grid density projection of reference/particles/particles.cpp, docs/particles.md).
#include <algorithm>
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <iostream>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/sim/frame_stats.hpp"
#include "reference/sim/simulation.hpp"

using namespace monolith;

namespace {

struct DriftHistory {
  std::vector<double> drift;  ///< liquid_volume / frame-0 liquid_volume - 1, frames 1..N
  long particles_first = 0, particles_last = 0;
  double seconds = 0.0;
  double worst() const {
    double w = 0.0;
    for (double d : drift) w = std::max(w, std::abs(d));
    return w;
  }
  int worst_frame() const {
    int f = 0;
    for (std::size_t i = 0; i < drift.size(); ++i)
      if (std::abs(drift[i]) > std::abs(drift[f])) f = static_cast<int>(i);
    return f + 1;
  }
};

/// Runs a built-in scene with overrides for `frames` frames and records the volume drift.
DriftHistory run_scene(const std::string& name, const std::vector<std::string>& overrides,
                       int frames) {
  const auto t0 = std::chrono::steady_clock::now();
  SceneDesc scene = load_scene(name, overrides);
  auto sim = make_simulation(scene);
  const FrameStats first = sim->current_stats();
  DriftHistory h;
  h.particles_first = first.particles;
  for (int f = 0; f < frames; ++f) {
    const FrameStats s = sim->advance_frame();
    h.drift.push_back(s.liquid_volume / first.liquid_volume - 1.0);
    h.particles_last = s.particles;
  }
  h.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return h;
}

void report(const std::string& label, const DriftHistory& h) {
  double lo = 0.0, hi = 0.0;
  for (double d : h.drift) {
    lo = std::min(lo, d);
    hi = std::max(hi, d);
  }
  std::cout << label << ": worst |drift| " << 100.0 * h.worst() << " % at frame " << h.worst_frame()
            << " (min " << 100.0 * lo << " %, max " << 100.0 * hi << " %), " << h.drift.size()
            << " frames in " << h.seconds << " s\n";
}

}  // namespace

TEST_CASE("dam-break-2d at 64x32: liquid volume within 1% at every frame", "[validation]") {
  const DriftHistory h = run_scene("dam-break-2d", {"domain.cells=[64,32]"}, 60);
  report("dam-break-2d 64x32", h);
  REQUIRE(h.drift.size() == 60);
  // no particle leaves the closed tank, so the particle volume is exactly conserved
  CHECK(h.particles_last == h.particles_first);
  for (std::size_t f = 0; f < h.drift.size(); ++f) {
    INFO("frame " << f + 1 << ": drift " << 100.0 * h.drift[f] << " %");
    CHECK(std::abs(h.drift[f]) < 0.01);
  }
}

TEST_CASE("dam-break-3d at 32x16x16: liquid volume within 1% at every frame", "[validation]") {
  const DriftHistory h = run_scene("dam-break-3d", {"domain.cells=[32,16,16]"}, 30);
  report("dam-break-3d 32x16x16", h);
  REQUIRE(h.drift.size() == 30);
  CHECK(h.particles_last == h.particles_first);
  for (std::size_t f = 0; f < h.drift.size(); ++f) {
    INFO("frame " << f + 1 << ": drift " << 100.0 * h.drift[f] << " %");
    CHECK(std::abs(h.drift[f]) < 0.01);
  }
}
