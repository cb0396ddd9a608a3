#pragma once
/// \file coupled_validation.hpp
/// Scenes and closed-form answers shared by test_coupled_validation.cpp and
/// slow_coupled_validation.cpp: floating bodies (Archimedes), a body of the liquid's density,
/// the square log's energy-minimising tilt, Stokes settling with wall corrections, and the
/// spin-down of a body in a concentric container (a 1D radial reference solve).

#include <Eigen/SparseLU>
#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/sim/simulation.hpp"

namespace monolith::validation {

constexpr double kG = 9.81;
constexpr double kRho = 1000.0;
constexpr double kPi = 3.14159265358979323846;

/// A point of the scene: (x, y) in 2D, (x, y, z) in 3D.
inline nlohmann::json point(int dim, double x, double y, double z = 0.5) {
  return dim == 2 ? nlohmann::json{x, y} : nlohmann::json{x, y, z};
}

/// A scene of `dim` dimensions on [0, upper] with n cells per metre, walls all round except
/// an open top, gravity -g e_y (or none), explicit back end, tight solver tolerance.
inline nlohmann::json base_scene(int dim, const std::vector<double>& upper, int n,
                                 const std::string& scheme, double fps, bool gravity = true,
                                 bool open_top = true) {
  nlohmann::json j = {{"format", "monolith-scene/1"}, {"name", "coupled-validation"}, {"dim", dim}};
  std::vector<int> cells;
  for (double u : upper) cells.push_back(static_cast<int>(std::lround(u * n)));
  j["domain"] = {{"lower", std::vector<double>(dim, 0.0)}, {"upper", upper}, {"cells", cells}};
  j["domain"]["boundary"] = {{"x-", "wall"}, {"x+", "wall"}, {"y-", "wall"},
                             {"y+", open_top ? "open" : "wall"}};
  if (dim == 3) {
    j["domain"]["boundary"]["z-"] = "wall";
    j["domain"]["boundary"]["z+"] = "wall";
  }
  std::vector<double> g(dim, 0.0);
  if (gravity) g[1] = -kG;
  j["gravity"] = g;
  j["time"] = {{"fps", fps}, {"frames", 1}, {"cfl", 2.0}, {"max_dt", 0.02}};
  j["solver"] = {{"scheme", scheme}, {"tolerance", 1e-8}, {"max_iterations", 20000},
                 {"backend", "explicit"}};
  j["render"] = {{"enabled", false}};
  j["probes"] = nlohmann::json::array();
  j["bodies"] = nlohmann::json::array();
  j["liquids"] = nlohmann::json::array();
  return j;
}

/// A liquid of density kRho filling the box [0, width]^(dim-1) x [0, depth] (width 1).
inline nlohmann::json pool(int dim, double depth, double eta = 0.0) {
  std::vector<double> c(dim, 0.5), h(dim, 0.5);
  c[1] = h[1] = depth / 2;
  return {{"name", "water"},
          {"shape", {{"type", "box"}, {"center", c}, {"half_size", h}}},
          {"density", kRho},
          {"viscosity", {{"eta", eta}}}};
}

/// Runs a scene for `frames` frames; returns frame 0 and every frame after it.
inline std::vector<FrameStats> run_frames(const nlohmann::json& j, int frames) {
  const auto sim = make_simulation(parse_scene(j, "coupled-validation.json", "."));
  std::vector<FrameStats> out{sim->current_stats()};
  for (int f = 0; f < frames; ++f) out.push_back(sim->advance_frame());
  return out;
}

/// A floating box (half sizes a along x and z, b along y) or ball (radius a) of density s rho.
struct FloatBody {
  int dim = 2;
  bool is_box = true;
  double a = 0.1, b = 0.1, s = 0.5;

  static FloatBody box(int dim, double half_width, double half_height, double s) {
    return {dim, true, half_width, half_height, s};
  }
  static FloatBody ball(int dim, double radius, double s) { return {dim, false, radius, radius, s}; }

  double volume() const {
    if (is_box) return (dim == 2 ? 2 * a : 4 * a * a) * 2 * b;
    return dim == 2 ? kPi * a * a : 4.0 / 3.0 * kPi * a * a * a;
  }
  /// Volume below the plane at depth d above the lowest point.
  double submerged(double d) const {
    if (is_box) return (dim == 2 ? 2 * a : 4 * a * a) * d;
    const double r = a;
    if (dim == 2) return r * r * std::acos((r - d) / r) - (r - d) * std::sqrt(2 * r * d - d * d);
    return kPi * d * d * (3 * r - d) / 3.0;
  }
  /// Archimedes: the draft d with submerged(d) = s volume (bisection).
  double draft() const {
    double lo = 0.0, hi = 2 * b;
    for (int k = 0; k < 100; ++k) {
      const double m = 0.5 * (lo + hi);
      (submerged(m) < s * volume() ? lo : hi) = m;
    }
    return 0.5 * (lo + hi);
  }
  /// Centre height at equilibrium when the free surface is at h.
  double centre_at(double h) const { return h - draft() + b; }
  nlohmann::json shape(double y) const {
    const int d = dim;
    if (is_box)
      return {{"type", "box"},
              {"center", point(d, 0.5, y)},
              {"half_size", d == 2 ? nlohmann::json{a, b} : nlohmann::json{a, b, a}}};
    return {{"type", "sphere"}, {"center", point(d, 0.5, y)}, {"radius", a}};
  }
};

struct BuoyancyResult {
  double error = 0.0;  ///< mean centre height - Archimedes' prediction (m)
  double range = 0.0;  ///< max - min of the centre height over the window (m)
  bool converged = true;
};

/// The first body's height in a run of a unit-width tank against Archimedes: the prediction
/// uses the surface height (V_L + s V) / 1 with the liquid volume V_L measured per frame; means
/// are over the second third of the run to its end; converged over every frame after frame 0.
inline BuoyancyResult floating_result(const FloatBody& body, const std::vector<FrameStats>& s) {
  BuoyancyResult r;
  double sum_y = 0.0, sum_pred = 0.0, lo = 1e9, hi = -1e9;
  int count = 0;
  for (std::size_t f = 1; f < s.size(); ++f) {
    r.converged = r.converged && s[f].solver.converged;
    if (3 * f < s.size()) continue;
    const double y = s[f].bodies[0].position[1];
    sum_y += y;
    sum_pred += body.centre_at(s[f].liquid_volume + body.s * body.volume());
    lo = std::min(lo, y);
    hi = std::max(hi, y);
    ++count;
  }
  r.error = (sum_y - sum_pred) / count;
  r.range = hi - lo;
  return r;
}

/// Tank of unit width (unit cross-section in 3D) filled to 0.5 m; the body is released at rest
/// `lift` above its equilibrium. The prediction uses the surface height (V_L + s V) / 1 with the
/// liquid volume V_L measured per frame; means are over the second third of the run to its end.
template <int Dim>
BuoyancyResult run_floating(const FloatBody& body, int n, double lift, int frames, double fps,
                            const std::string& scheme, double eta = 0.0) {
  nlohmann::json j = base_scene(Dim, std::vector<double>(Dim, 1.0), n, scheme, fps);
  j["liquids"].push_back(pool(Dim, 0.5, eta));
  j["bodies"].push_back({{"name", "floater"},
                         {"density", body.s * kRho},
                         {"shape", body.shape(body.centre_at(0.5) + lift)}});
  return floating_result(body, run_frames(j, frames));
}

struct NeutralResult {
  double deficit = 0.0;   ///< (V - V_h) / V of the initial pose
  double drift = 0.0;     ///< vertical displacement after the run (m)
  double sideways = 0.0;  ///< horizontal displacement (m)
};

/// A disk / ball of the liquid's density at mid depth of a 0.5 m pool (n cells per metre),
/// PC-unified, 20 fps.
template <int Dim>
NeutralResult run_neutral(int n, double r, double shrink, double seconds) {
  const double fps = 20;
  nlohmann::json j = base_scene(Dim, std::vector<double>(Dim, 1.0), n, "PC-unified", fps);
  j["solver"]["shrink"] = shrink;
  j["liquids"].push_back(pool(Dim, 0.5));
  j["bodies"].push_back({{"name", "neutral"},
                         {"density", kRho},
                         {"shape", {{"type", "sphere"}, {"center", point(Dim, 0.5, 0.25)}, {"radius", r}}}});
  NeutralResult out;
  // V_h: dx^Dim times the sum of the body's weights on the y-faces (the buoyancy of a
  // hydrostatic pressure, docs/coupling.md)
  const SceneDesc scene = parse_scene(j, "neutral.json", ".");
  std::array<bool, Dim> periodic{};
  const MacGrid<Dim> grid(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), periodic);
  CouplingBody<Dim> cb;
  cb.shape = make_shape<Dim>(scene.bodies[0].shape, "neutral");
  cb.center = Vec<Dim>::Constant(0.5);
  cb.center[1] = 0.25;
  std::array<BoundaryType, 2 * Dim> walls;
  walls.fill(BoundaryType::wall);
  walls[3] = BoundaryType::open;
  const SolidWeights<Dim> w = solid_weights<Dim>(grid, {cb}, {}, walls, shrink / n);
  double vh = 0.0;
  for (int f = 0; f < grid.num_faces(); ++f)
    if (grid.face_coord(f).first == 1) vh += w.body_face[0][f];
  vh *= grid.cell_volume();
  out.deficit = 1.0 - vh / (Dim == 2 ? kPi * r * r : 4.0 / 3.0 * kPi * r * r * r);
  const std::vector<FrameStats> s = run_frames(j, static_cast<int>(std::lround(seconds * fps)));
  out.drift = s.back().bodies[0].position[1] - 0.25;
  out.sideways = 0.0;
  for (int a = 0; a < Dim; ++a)
    if (a != 1) out.sideways = std::max(out.sideways, std::abs(s.back().bodies[0].position[a] - 0.5));
  return out;
}

}  // namespace monolith::validation

namespace monolith::validation {

/// Faxen's drag on a circular cylinder (radius a) moving parallel to and midway between two
/// plane walls 2 h apart, at low Reynolds number, per unit length: F = 4 pi mu U / K(k), k = a / h,
/// K = ln(1/k) - 0.9157 + 1.7244 k^2 - 1.7302 k^4 + 2.4056 k^6 - 4.5913 k^8 (Faxen 1946, as
/// quoted by Happel & Brenner, Low Reynolds Number Hydrodynamics, 1965). Returns the terminal velocity
/// of a cylinder of density excess drho under gravity g: (drho g pi a^2) K / (4 pi mu).
inline double faxen_terminal_velocity(double a, double h, double mu, double drho, double g) {
  const double k = a / h, k2 = k * k;
  const double K = std::log(1.0 / k) - 0.9157 + 1.7244 * k2 - 1.7302 * k2 * k2 +
                   2.4056 * k2 * k2 * k2 - 4.5913 * k2 * k2 * k2 * k2;
  return drho * g * kPi * a * a * K / (4.0 * kPi * mu);
}

/// Spin-down of a body (radius R1, moment of inertia I per unit length in 2D) spinning inside a
/// fixed concentric container (inner radius R2) filled with liquid (rho, mu) initially at rest,
/// gravity off: the exact axisymmetric reduction of the Navier-Stokes equations. The azimuthal
/// velocity is f(r, t) (2D) or f(r, t) sin(theta) (3D), with
///   2D: rho f_t = mu (f_rr + f_r / r - f / r^2),          torque 2 pi R1^2 mu (f_r - f / r)
///   3D: rho f_t = mu (f_rr + 2 f_r / r - 2 f / r^2),      torque 8 pi / 3 R1^3 mu (f_r - f / r)
/// at r = R1 (Landau & Lifshitz, Fluid Mechanics, Couette flow and its problems; the steady states
/// are the Couette torques 4 pi mu omega R1^2 R2^2 / (R2^2 - R1^2) and
/// 8 pi mu omega R1^3 R2^3 / (R2^3 - R1^3)), f(R1) = omega R1, f(R2) = 0, I omega' = torque.
/// Solved by backward Euler on `cells` radial cells; returns omega at the times asked (sorted).
inline std::vector<double> radial_spin_down(int dim, double r1, double r2, double rho, double mu,
                                            double inertia, double omega0,
                                            const std::vector<double>& times, int cells = 400,
                                            double dt = 2e-5) {
  const int n = cells;
  const double h = (r2 - r1) / n;
  const double c = dim == 2 ? 1.0 : 2.0;  // the 1 / r terms: f_r c / r - c f / r^2
  const double torque_coeff = dim == 2 ? 2 * kPi * r1 * r1 : 8.0 * kPi / 3.0 * r1 * r1 * r1;
  // unknowns: x[0] = omega, x[i] = f(r1 + i h) for i = 1 .. n-1
  Eigen::SparseMatrix<double> A(n, n);
  std::vector<Eigen::Triplet<double>> t;
  for (int i = 1; i < n; ++i) {
    const double r = r1 + i * h;
    const double lo = mu * (1.0 / (h * h) - c / (2 * h * r)), hi = mu * (1.0 / (h * h) + c / (2 * h * r));
    const double mid = -mu * (2.0 / (h * h) + c / (r * r));
    t.emplace_back(i, i, rho / dt - mid);
    if (i > 1) t.emplace_back(i, i - 1, -lo);
    else t.emplace_back(i, 0, -lo * r1);  // f(r1) = omega r1
    if (i < n - 1) t.emplace_back(i, i + 1, -hi);
  }
  // I (omega - omega_old) / dt = coeff mu ((-3 omega r1 + 4 f1 - f2) / (2 h) - omega)
  const double k = torque_coeff * mu;
  t.emplace_back(0, 0, inertia / dt - k * (-3.0 * r1 / (2 * h) - 1.0));
  t.emplace_back(0, 1, -k * 4.0 / (2 * h));
  t.emplace_back(0, 2, -k * -1.0 / (2 * h));
  A.setFromTriplets(t.begin(), t.end());
  Eigen::SparseLU<Eigen::SparseMatrix<double>> lu(A);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(n);
  x[0] = omega0;
  std::vector<double> out;
  double time = 0.0;
  for (double target : times) {
    while (time < target - 0.5 * dt) {
      Eigen::VectorXd b(n);
      b[0] = inertia / dt * x[0];
      for (int i = 1; i < n; ++i) b[i] = rho / dt * x[i];
      x = lu.solve(b);
      time += dt;
    }
    out.push_back(x[0]);
  }
  return out;
}

}  // namespace monolith::validation

namespace monolith::validation {

struct SettlingResult {
  double velocity = 0.0;  ///< mean downward speed over the last 40 % of the run (m/s)
  double sideways = 0.0;  ///< largest horizontal speed (m/s)
  bool converged = true;
};

/// The SettlingResult of body `body` over frames 1..frames of `s` (frame 0 the initial state):
/// all solves converged, the largest horizontal speed (every component but y), the mean
/// downward speed over the last 40 % of the frames.
inline SettlingResult settling_result(const std::vector<FrameStats>& s, int frames, int body) {
  SettlingResult r;
  int count = 0;
  for (int f = 1; f <= frames; ++f) {
    const std::vector<double>& v = s[f].bodies[body].velocity;
    r.converged = r.converged && s[f].solver.converged;
    for (std::size_t a = 0; a < v.size(); ++a)
      if (a != 1) r.sideways = std::max(r.sideways, std::abs(v[a]));
    if (f > frames - (2 * frames) / 5) {
      r.velocity -= v[1];
      ++count;
    }
  }
  r.velocity /= count;
  return r;
}

/// A disk (a = 0.125, density 2000) settling in eta = 1000 Pa s between walls 1 m apart
/// (domain 1 x 2 m, liquid 1.8 m deep, centre at 1 m), PVC-unified, frames at 100 fps.
inline SettlingResult run_settling_disk(int n, double seconds) {
  const double fps = 100;
  nlohmann::json j = base_scene(2, {1.0, 2.0}, n, "PVC-unified", fps);
  nlohmann::json liquid = pool(2, 1.8, 1000.0);
  j["liquids"].push_back(liquid);
  j["bodies"].push_back({{"name", "disk"},
                         {"density", 2000.0},
                         {"shape", {{"type", "sphere"}, {"center", {0.5, 1.0}}, {"radius", 0.125}}}});
  const int frames = static_cast<int>(std::lround(seconds * fps));
  return settling_result(run_frames(j, frames), frames, 0);
}

struct SpinResult {
  double time = 0.0, omega = 0.0, reference = 0.0;  ///< omega / omega0 at the end, both
  double offset = 0.0;                               ///< largest distance of the centre from its start
  bool converged = true;
};

/// A disk / ball R1 = 0.15 (density 1e5) spinning at 1 rad/s (about z) at the centre of a fixed
/// shell of inner radius R2 = 0.35 (outer 0.45) full of liquid eta = 500, gravity off,
/// PVC-unified, 50 fps; compared with radial_spin_down.
inline SpinResult run_spin_down(int dim, int n, double seconds) {
  const double fps = 50, r1 = 0.15, r2 = 0.35, eta = 500.0, rho_b = 1e5;
  nlohmann::json j = base_scene(dim, std::vector<double>(dim, 1.0), n, "PVC-unified", fps, false, false);
  j["liquids"].push_back({{"name", "gap"},
                          {"shape", {{"type", "sphere"}, {"center", point(dim, 0.5, 0.5)}, {"radius", r2}}},
                          {"density", kRho},
                          {"viscosity", {{"eta", eta}}}});
  j["bodies"].push_back({{"name", "ring"},
                         {"motion", "static"},
                         {"shape", {{"type", "shell"}, {"center", point(dim, 0.5, 0.5)}, {"radius", 0.45},
                                    {"thickness", 0.45 - r2}}}});
  j["bodies"].push_back({{"name", "rotor"},
                         {"density", rho_b},
                         {"angular_velocity", dim == 2 ? nlohmann::json(1.0) : nlohmann::json{0.0, 0.0, 1.0}},
                         {"shape", {{"type", "sphere"}, {"center", point(dim, 0.5, 0.5)}, {"radius", r1}}}});
  const int frames = static_cast<int>(std::lround(seconds * fps));
  const std::vector<FrameStats> s = run_frames(j, frames);
  SpinResult r;
  for (int f = 1; f <= frames; ++f) {
    r.converged = r.converged && s[f].solver.converged;
    double d2 = 0.0;
    for (int a = 0; a < dim; ++a) d2 += std::pow(s[f].bodies[1].position[a] - 0.5, 2);
    r.offset = std::max(r.offset, std::sqrt(d2));
  }
  r.time = s.back().time;
  r.omega = s.back().bodies[1].angular_velocity.back();
  const double inertia = dim == 2 ? rho_b * kPi * std::pow(r1, 4) / 2
                                  : rho_b * 8.0 / 15.0 * kPi * std::pow(r1, 5);
  r.reference = radial_spin_down(dim, r1, r2, kRho, eta, inertia, 1.0, {r.time}).back();
  return r;
}

}  // namespace monolith::validation

namespace monolith::validation {

struct DropResult {
  double volume_drift = 0.0;   ///< largest |V_L / V_L(0) - 1| over the run
  double penetration = 0.0;    ///< largest contacts.max_penetration (m)
  double final_height = 0.0;   ///< centre height at the end (m)
  bool landed = false, converged = true;
};

/// A stone (disk / ball r = 0.08, density 3000) released at rest with its centre at 0.65 m above
/// the floor of a pool 0.4 m deep, PC-unified, 20 fps.
inline DropResult run_drop(int dim, int n, int frames) {
  nlohmann::json j = base_scene(dim, std::vector<double>(dim, 1.0), n, "PC-unified", 20);
  j["liquids"].push_back(pool(dim, 0.4));
  j["bodies"].push_back({{"name", "stone"},
                         {"density", 3000.0},
                         {"shape", {{"type", "sphere"}, {"center", point(dim, 0.5, 0.65)}, {"radius", 0.08}}}});
  const std::vector<FrameStats> s = run_frames(j, frames);
  DropResult r;
  for (std::size_t f = 1; f < s.size(); ++f) {
    r.converged = r.converged && s[f].solver.converged;
    r.volume_drift = std::max(r.volume_drift, std::abs(s[f].liquid_volume / s[0].liquid_volume - 1.0));
    r.penetration = std::max(r.penetration, s[f].max_penetration);
    r.landed = r.landed || s[f].contact_count > 0;
  }
  r.final_height = s.back().bodies[0].position[1];
  return r;
}

}  // namespace monolith::validation

namespace monolith::validation {

/// The absolute tilt (degrees) of a square, folded into [-45, 45): the square looks the same
/// every 90 degrees.
inline double folded_tilt(double radians) {
  double deg = std::fmod(radians * 180.0 / kPi + 45.0, 90.0);
  if (deg < 0) deg += 90.0;
  return deg - 45.0;
}

/// A square log (side L = 0.25; in 3D a prism 0.9 m long along z, 0.05 m from the end walls)
/// of density s rho released at tilt `start` (degrees, about z) in a pool 0.5 m deep with
/// viscosity eta, PVC-unified, 20 fps. Returns the final absolute tilt (degrees; the mean over
/// the last 0.5 s) and whether every solve converged.
inline std::pair<double, bool> square_log(int dim, int n, double s, double start, double eta,
                                          double seconds) {
  const double fps = 20, L = 0.25;
  nlohmann::json j = base_scene(dim, std::vector<double>(dim, 1.0), n, "PVC-unified", fps);
  j["liquids"].push_back(pool(dim, 0.5, eta));
  const double angle = start * kPi / 180.0;
  j["bodies"].push_back(
      {{"name", "log"},
       {"density", s * kRho},
       {"shape", {{"type", "box"},
                  {"center", point(dim, 0.5, 0.5 - s * L + L / 2)},
                  {"half_size", dim == 2 ? nlohmann::json{L / 2, L / 2} : nlohmann::json{L / 2, L / 2, 0.45}},
                  {"rotation", dim == 2 ? nlohmann::json(angle) : nlohmann::json{0.0, 0.0, angle}}}}});
  const int frames = static_cast<int>(std::lround(seconds * fps));
  const std::vector<FrameStats> st = run_frames(j, frames);
  bool converged = true;
  double sum = 0.0;
  int count = 0;
  for (int f = 1; f <= frames; ++f) {
    converged = converged && st[f].solver.converged;
    if (f <= frames - 10) continue;
    // the reported orientation is relative to the scene's pose (2D: angle; 3D: quaternion
    // [w, x, y, z], a rotation about z by 2 atan2(z, w))
    const auto& o = st[f].bodies[0].orientation;
    const double turned = dim == 2 ? o[0] : 2.0 * std::atan2(o[3], o[0]);
    // averaged before folding: a tilt that rocks across +-45 deg folds to both ends
    sum += angle + turned;
    ++count;
  }
  return {folded_tilt(sum / count), converged};
}

}  // namespace monolith::validation

namespace monolith::validation {

/// Stokes drag on a sphere (radius a) moving at the centre of a fixed spherical container
/// (radius b), lambda = a / b, as a multiple of 6 pi mu a U (Cunningham 1910, Williams 1915;
/// Happel & Brenner 1965, chapter 4):
///   K = (1 - l^5) / (1 - 9/4 l + 5/2 l^3 - 9/4 l^5 + l^6).
/// It is the Stokeslet coefficient C of the stream function sin^2(theta) (A r^4 + B r^2 + C r +
/// D / r) with f(a) = U a^2 / 2, f'(a) = U a, f(b) = f'(b) = 0, over its unbounded value 3 a U / 4
/// (drag 8 pi mu C); the test checks the two agree.
inline double concentric_sphere_factor(double lambda) {
  const double l = lambda, l3 = l * l * l, l5 = l3 * l * l, l6 = l5 * l;
  return (1.0 - l5) / (1.0 - 2.25 * l + 2.5 * l3 - 2.25 * l5 + l6);
}

/// The same factor from the 4 x 4 boundary-value problem of the stream function (a = 1).
inline double concentric_sphere_factor_from_stream_function(double lambda) {
  const double a = 1.0, b = 1.0 / lambda, U = 1.0;
  Eigen::Matrix4d M;
  M << std::pow(a, 4), a * a, a, 1.0 / a,  //
      4 * a * a * a, 2 * a, 1.0, -1.0 / (a * a),  //
      std::pow(b, 4), b * b, b, 1.0 / b,  //
      4 * b * b * b, 2 * b, 1.0, -1.0 / (b * b);
  const Eigen::Vector4d rhs(U * a * a / 2, U * a, 0.0, 0.0);
  const Eigen::Vector4d c = M.fullPivLu().solve(rhs);
  return std::abs(c[2]) / (0.75 * a * U);
}

/// A ball a = 0.15 of density 2000 settling from the centre of a fixed spherical shell of inner
/// radius 0.36 (outer 0.49: walls of 3 dx at 24^3; static walls under 2 dx let a liquid at rest
/// under gravity leak, docs/validation.md) filled with liquid of viscosity eta = 1000 Pa s (3D,
/// n cells per metre, 100 fps, PVC-unified); returns the mean downward speed over the last 40 %
/// of the frames.
inline SettlingResult run_settling_ball(int n, double seconds) {
  const double fps = 100;
  nlohmann::json j = base_scene(3, {1.0, 1.0, 1.0}, n, "PVC-unified", fps, true, false);
  j["liquids"].push_back({{"name", "inside"},
                          {"shape", {{"type", "sphere"}, {"center", point(3, 0.5, 0.5)}, {"radius", 0.36}}},
                          {"density", kRho},
                          {"viscosity", {{"eta", 1000.0}}}});
  j["bodies"].push_back({{"name", "container"},
                         {"motion", "static"},
                         {"shape", {{"type", "shell"}, {"center", point(3, 0.5, 0.5)}, {"radius", 0.49},
                                    {"thickness", 0.13}}}});
  j["bodies"].push_back({{"name", "ball"},
                         {"density", 2000.0},
                         {"shape", {{"type", "sphere"}, {"center", point(3, 0.5, 0.5)}, {"radius", 0.15}}}});
  const int frames = static_cast<int>(std::lround(seconds * fps));
  return settling_result(run_frames(j, frames), frames, 1);
}

}  // namespace monolith::validation
