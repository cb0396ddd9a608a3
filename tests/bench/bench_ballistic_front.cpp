// The surge front of dam-break-2d (as test_validation_dam_break runs it: 64 x 32 cells, 100 frames
// per second, 34 frames) with the PIC value on the ballistic faces beside walls and solids
// (StageSwitches::ballistic_faces_pic, the default; column "pic") and with their APIC value
// (before issue 16's fix; column "apic"), side by side: the front
// Z = z/a (the largest particle x over a) at Martin & Moyce's (1952) times T = t sqrt(2 g / a),
// the front speed over T in [1.6, 2.95] and the liquid volume's worst drift. The surge front is
// a sheet along the floor whose faces are ballistic (docs/particles.md, "Energy regains over long
// runs"). A measurement program: it asserts nothing (test_validation_dam_break does).
//
//   bench_ballistic_front [--cells NX,NY]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/sim/simulation.hpp"
#include "tests/support/bench_args.hpp"

using namespace monolith;

namespace {

struct Front {
  std::vector<double> T, Z;
  double worst_drift = 0.0;
  double at(double t) const {
    for (std::size_t i = 0; i + 1 < T.size(); ++i)
      if (T[i] <= t && t <= T[i + 1]) {
        const double f = (t - T[i]) / (T[i + 1] - T[i]);
        return (1 - f) * Z[i] + f * Z[i + 1];
      }
    return NAN;
  }
};

Front run(const std::string& cells, const StageSwitches& switches) {
  const double a = 0.2, g = 9.81, T_of_t = std::sqrt(2.0 * g / a);
  SceneDesc scene = load_scene("dam-break-2d", {"time.fps=100", "time.frames=34",
                                                "domain.cells=[" + cells + "]",
                                                "render.enabled=false"});
  Simulation<2> sim(scene, switches);
  Front h;
  FrameStats s = sim.current_stats();
  const double v0 = s.liquid_volume;
  h.T.push_back(0.0);
  h.Z.push_back(s.liquid_bounds_upper.at(0) / a);
  for (int f = 0; f < scene.time.frames; ++f) {
    s = sim.advance_frame();
    h.T.push_back(s.time * T_of_t);
    h.Z.push_back(s.liquid_bounds_upper.at(0) / a);
    h.worst_drift = std::max(h.worst_drift, std::abs(s.liquid_volume - v0) / v0);
  }
  return h;
}

}  // namespace

int main(int argc, char** argv) {
  std::string cells = "64,32";
  bench::BenchArgs args(argc, argv);
  while (args.next()) {
    if (args.flag() == "--cells") {
      cells = args.value();
    } else {
      std::fprintf(stderr, "usage: bench_ballistic_front [--cells NX,NY]\n");
      return 2;
    }
  }
  StageSwitches apic;
  apic.ballistic_faces_pic = false;
  const Front pic_front = run(cells, StageSwitches{}), apic_front = run(cells, apic);
  const std::vector<std::pair<double, double>> data = {
      {0.832, 1.217}, {0.849, 1.245}, {1.212, 1.443}, {1.219, 1.474}, {1.602, 1.884},
      {1.997, 2.292}, {2.283, 2.689}, {2.547, 2.995}, {2.950, 3.728}};
  std::printf("%6s %8s | %8s %8s | %8s %8s\n", "T", "Z exp", "Z pic", "error", "Z apic", "error");
  for (const auto& [T, Z] : data) {
    const double zp = pic_front.at(T), za = apic_front.at(T);
    std::printf("%6.3f %8.3f | %8.3f %+7.1f%% | %8.3f %+7.1f%%\n", T, Z, zp, 100 * (zp - Z) / Z, za,
                100 * (za - Z) / Z);
  }
  auto speed = [](const Front& h) { return (h.at(2.950) - h.at(1.602)) / (2.950 - 1.602); };
  std::printf("front speed dZ/dT over [1.602, 2.950]: experiment %.3f, pic %.3f, apic %.3f\n",
              (3.728 - 1.884) / (2.950 - 1.602), speed(pic_front), speed(apic_front));
  auto best_shift = [&](const Front& h, double& error) {
    double best = 0.0;
    error = 1e300;
    for (double dT = 0.0; dT <= 0.5 + 1e-12; dT += 0.01) {
      double worst = 0.0;
      for (const auto& [T, Z] : data) worst = std::max(worst, std::abs(h.at(T - dT) - Z) / Z);
      if (worst < error) error = worst, best = dT;
    }
    return best;
  };
  double ep = 0.0, ea = 0.0;
  const double sp = best_shift(pic_front, ep), sa = best_shift(apic_front, ea);
  std::printf("best time shift: pic dT %.2f (largest error %.1f%%), apic dT %.2f (%.1f%%)\n", sp,
              100 * ep, sa, 100 * ea);
  std::printf("worst volume drift: pic %.3f%%, apic %.3f%%\n", 100 * pic_front.worst_drift,
              100 * apic_front.worst_drift);
  return 0;
}
