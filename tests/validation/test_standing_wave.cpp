// A small-amplitude standing gravity wave released from rest in a tank periodic along x (check24,
// docs/validation.md "A second independent check"): its period against the dispersion relation
// omega0^2 = g k tanh(k h) (Lamb 1932, art. 228) and, with viscosity, its decay against
// Prosperetti's initial-value solution (A. Prosperetti 1981, "Motion of two superposed viscous
// fluids", Phys. Fluids 24, 1217; one liquid below a void). The wave is read from the liquid's
// energies only: the potential energy is lowest when the surface passes flat (a = 0) twice a
// period, and the kinetic energy peaks in between at a value proportional to the square of the
// wave's amplitude.
#include <catch2/catch.hpp>

#include <cmath>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/sim/simulation.hpp"

using namespace monolith;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kG = 9.81, kDepth = 0.5, kAmplitude = 0.03, kLength = 1.0;

/// [0, 1] x [0, 1], `cells` per axis, periodic in x, a wall below and open above; the liquid is a
/// polygon whose top is kDepth + kAmplitude cos(2 pi x) (one wavelength across the domain,
/// k h = pi, a k = 0.19), frames of 0.01 s for 2 s.
nlohmann::json wave_scene(int cells, double eta) {
  using nlohmann::json;
  json points = json::array();
  const int segments = 200;
  for (int i = 0; i <= segments; ++i) {
    const double x = -0.05 + (kLength + 0.1) * i / segments;
    points.push_back({x, kDepth + kAmplitude * std::cos(2 * kPi * x / kLength)});
  }
  points.push_back({kLength + 0.05, -0.05});
  points.push_back({-0.05, -0.05});
  json j;
  j["format"] = "monolith-scene/1";
  j["name"] = "standing-wave";
  j["dim"] = 2;
  j["domain"] = {{"lower", {0.0, 0.0}},
                 {"upper", {kLength, 2 * kDepth}},
                 {"cells", {cells, cells}},
                 {"boundary", {{"x-", "periodic"}, {"x+", "periodic"}, {"y-", "wall"}, {"y+", "open"}}}};
  j["gravity"] = {0.0, -kG};
  j["time"] = {{"fps", 100}, {"frames", 200}};
  j["liquids"] = {{{"name", "water"},
                   {"density", 1000.0},
                   {"shape", {{"type", "polygon"}, {"points", points}}},
                   {"viscosity", {{"model", "newtonian"}, {"eta", eta}}}}};
  j["render"] = {{"enabled", false}};
  return j;
}

struct Extremum {
  double t, value;
};

/// Interior extrema of a sampled signal (maxima for sign = +1, minima for -1), each refined by the
/// parabola through the sample and its two neighbours.
std::vector<Extremum> extrema(const std::vector<double>& t, const std::vector<double>& y, double sign) {
  std::vector<Extremum> out;
  for (std::size_t i = 1; i + 1 < y.size(); ++i) {
    if (!(sign * y[i] > sign * y[i - 1] && sign * y[i] >= sign * y[i + 1])) continue;
    const double curvature = y[i - 1] - 2 * y[i] + y[i + 1];
    const double offset = curvature != 0 ? 0.5 * (y[i - 1] - y[i + 1]) / curvature : 0.0;
    out.push_back({t[i] + offset * (t[i + 1] - t[i]), y[i] - 0.25 * (y[i - 1] - y[i + 1]) * offset});
  }
  return out;
}

struct WaveRun {
  double period = 0.0;      ///< twice the mean spacing of the potential energy's minima (s)
  double decay_rate = 0.0;  ///< amplitude decay rate from the first and last kinetic peaks (1/s)
  int minima = 0, peaks = 0;
  bool converged = true;
};

WaveRun run_wave(int cells, double eta) {
  const auto sim = make_simulation(parse_scene(wave_scene(cells, eta), "standing-wave.json", "."));
  std::vector<double> t, kinetic, potential;
  WaveRun r;
  FrameStats s = sim->current_stats();
  for (int f = 0; f <= 200; ++f) {
    if (f > 0) s = sim->advance_frame();
    r.converged = r.converged && s.solver.converged;
    t.push_back(s.time);
    kinetic.push_back(s.kinetic_energy_liquid);
    potential.push_back(s.potential_energy_liquid);
  }
  const auto flat = extrema(t, potential, -1.0);
  const auto peaks = extrema(t, kinetic, +1.0);
  r.minima = static_cast<int>(flat.size());
  r.peaks = static_cast<int>(peaks.size());
  if (flat.size() >= 2) r.period = 2 * (flat.back().t - flat.front().t) / (flat.size() - 1);
  if (peaks.size() >= 2)
    r.decay_rate = std::log(peaks.front().value / peaks.back().value) / (2 * (peaks.back().t - peaks.front().t));
  return r;
}

}  // namespace

TEST_CASE("an inviscid standing wave keeps the period of omega^2 = g k tanh(k h) (2D)", "[validation]") {
  // 32 cells per wavelength. Measured (a10d2ef): period 0.8231 s against 0.8018 s (+2.65 %;
  // +1.11 % at 64^2, +0.76 % at 128^2; +0.64 % at 128^2 with half the amplitude, so about
  // 0.16 % is the wave's steepness), the wave's energy decaying at 0.055 1/s (numerical; 0.013 at 64^2).
  const double k = 2 * kPi / kLength;
  const double period = 2 * kPi / std::sqrt(kG * k * std::tanh(k * kDepth));
  const WaveRun r = run_wave(32, 0.0);
  INFO("period " << r.period << " s against " << period << " s; amplitude decay " << r.decay_rate
                 << " 1/s; " << r.minima << " flat passes, " << r.peaks << " kinetic peaks");
  CHECK(r.converged);
  CHECK(r.minima == 5);
  CHECK(r.peaks == 5);
  CHECK(std::abs(r.period / period - 1) < 0.04);
  CHECK(r.decay_rate < 0.1);
}

TEST_CASE("a viscous standing wave decays as Prosperetti's initial-value solution (2D)", "[validation]") {
  // eta = 10 Pa s (nu k^2 / omega0 = 0.05). Prosperetti's closed form (the roots of
  // z^4 + 2 nu k^2 z^2 + 4 (nu k^2)^(3/2) z + nu^2 k^4 + omega0^2 = 0 and a complex erfc),
  // evaluated with mpmath: over the kinetic peaks' times 0.19-1.82 s the amplitude's peaks decay
  // at 0.6695 1/s and |da/dt|'s at 0.6597 1/s; its late-time mode decays at 0.661 1/s. Lamb's
  // 2 nu k^2 = 0.790 is the limit nu -> 0 and is not the answer here: the vorticity layer at the
  // surface forms from rest, so the early decay is slower. Measured (a10d2ef): 0.6395 1/s at
  // 32^2 (-3.8 % against 0.665), 0.637 at 64^2 and 128^2; with the lead's probe of the surface
  // clamp (check24) 0.659, 0.652, 0.657. With surf24's clamp merged the bound is 2 %, which
  // main's surface lid (-3.8 %) fails.
  const double expected = 0.665;
  const WaveRun r = run_wave(32, 10.0);
  INFO("amplitude decay " << r.decay_rate << " 1/s against " << expected << "; period " << r.period
                          << " s; " << r.peaks << " kinetic peaks");
  CHECK(r.converged);
  CHECK(r.peaks == 5);
  CHECK(std::abs(r.decay_rate / expected - 1) < 0.02);
}
