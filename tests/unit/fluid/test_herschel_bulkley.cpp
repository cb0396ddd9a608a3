// Herschel-Bulkley liquids (section 5): eq. (27) and its shear-rate norm, Algorithm 2 on the grid
// solve of eq. (29) (channel, Couette and film flows with known steady answers, the residual of
// the outer iteration), and the simulator's non-Newtonian path (a herschel-bulkley liquid with
// n = 1, tau0 = 0 runs bit for bit as its newtonian twin). 2D and 3D.
#include <catch2/catch.hpp>
#include <algorithm>
#include <cmath>
#include <functional>

#include "reference/app/scene_file.hpp"
#include "reference/app/stats_json.hpp"
#include "reference/fluid/deformation_rate.hpp"
#include "reference/fluid/herschel_bulkley.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/particles/particles.hpp"
#include "reference/sim/simulation.hpp"
#include "reference/viz/render.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using namespace monolith::testing;

namespace {

/// A periodic channel (every axis but y periodic, `across` cells along them) between no-slip
/// walls at y = 0 and y = H = 1, n cells across, density rho; liquid below y = h (h >= 1: full).
template <int Dim>
struct HbChannel {
  MacGrid<Dim> grid;
  StokesWeights w;
  StressGrid<Dim> stress;

  HbChannel(int n, double rho, double h = 2.0, int across = 4) {
    std::array<BoundaryType, 2 * Dim> boundary;
    boundary.fill(BoundaryType::periodic);
    boundary[2] = boundary[3] = BoundaryType::wall;
    VecI<Dim> cells = VecI<Dim>::Constant(across);
    cells[1] = n;
    std::array<bool, Dim> periodic{};
    for (int a = 0; a < Dim; ++a) periodic[a] = a != 1;
    grid = MacGrid<Dim>(Vec<Dim>::Zero(), 1.0 / n, cells, periodic);
    const SampleLattice<Dim> lattice = half_lattice(grid);
    const VectorX solid_phi = solid_phi_on_lattice<Dim>(grid, lattice, {}, 0.0);
    VectorX phi(lattice.size());
    for (int k = 0; k < lattice.size(); ++k) phi[k] = lattice.position(lattice.coord(k))[1] - h;
    w = stokes_weights(grid, solid_phi, phi, boundary, rho, 1.0);
    stress = StressGrid<Dim>(grid);
  }

  /// g along x on the x faces that carry liquid.
  VectorX force_along_x(double g) const {
    VectorX f = VectorX::Zero(grid.num_faces());
    for (int i = 0; i < grid.num_faces(0); ++i)
      if (w.pressure.fluid_face[i] > 0.0 && w.pressure.liquid_face[i] > 0.0) f[i] = g;
    return f;
  }

  /// One backward-Euler step with Algorithm 2: u* = u + dt f, then `rounds` rounds of eq. (29)
  /// in (tau, p), reduced, SSOR-PCG to 1e-12, each with the viscosity of the previous round's
  /// stress. Faces without liquid then take the velocity of the liquid below them (what the
  /// simulator's extrapolation does before a viscous solve). Returns tau (all components).
  /// With `warm`, line 1 starts from *warm (the previous step's shear rate, empty at first) and
  /// *warm is left at this step's final rate.
  VectorX step(VectorX& u, double dt, const VectorX& force, const HerschelBulkley& model,
               int rounds, std::vector<double>* residuals = nullptr,
               VectorX* warm = nullptr) const {
    ViscosityMixture mixture;
    mixture.models = {model};
    mixture.fractions = {VectorX::Ones(stress.num_dofs())};
    NonNewtonianViscosity<Dim> nn(stress, w.fluid_stress, w.liquid_stress, mixture);
    const VectorX u_star = force.size() ? VectorX(u + dt * force) : u;
    StokesWeights ws = w;
    PcgSettings settings;
    settings.tolerance = 1e-12;
    settings.max_iterations = 50000;
    VectorX tau;
    run_algorithm2<Dim>(nn, w.pressure.fluid_face, u_star, rounds, [&](const VectorX& eta) {
      ws.viscosity = eta;
      u = u_star;
      const StokesSolveResult r = solve_stokes(grid, ws, dt, StokesUnknowns::pressure_and_stress,
                                               StressForm::reduced, Backend::matrix_free, settings, u);
      REQUIRE(r.pcg.converged);
      tau = r.stress;
      return r.stress;
    }, warm ? *warm : VectorX());
    if (residuals) *residuals = nn.residuals();
    if (warm) *warm = nn.shear_rate();
    std::vector<char> valid(grid.num_faces(), 0);
    for (int f = 0; f < grid.num_faces(); ++f) valid[f] = w.pressure.liquid_face[f] > 0.0;
    extrapolate_velocity(grid, u, valid, grid.cells()[1]);
    return tau;
  }

  /// Largest |u_f - exact(y_f)| over the x faces below y = top, relative to the largest |exact|.
  double profile_error(const VectorX& u, const std::function<double(double)>& exact,
                       double top = 2.0) const {
    double err = 0.0, scale = 0.0;
    for (int i = 0; i < grid.num_faces(0); ++i) {
      const double y = grid.face_center(0, grid.face_coord(i).second)[1];
      if (y > top) continue;
      err = std::max(err, std::abs(u[i] - exact(y)));
      scale = std::max(scale, std::abs(exact(y)));
    }
    return err / scale;
  }

  double max_speed(const VectorX& u) const {
    return u.head(grid.num_faces(0)).template lpNorm<Eigen::Infinity>();
  }
};

/// Steady channel flow under body force g (rho = 1, so the pressure gradient is G = g) by
/// `steps` backward-Euler steps of length dt from rest, `rounds` Algorithm 2 rounds each,
/// warm-started from the previous step's rate when `warm`.
template <int Dim>
VectorX steady_channel(const HbChannel<Dim>& ch, const HerschelBulkley& model, double g,
                       double dt, int steps, int rounds, bool warm = true) {
  VectorX u = VectorX::Zero(ch.grid.num_faces());
  const VectorX f = ch.force_along_x(g);
  VectorX rate;
  for (int s = 0; s < steps; ++s) ch.step(u, dt, f, model, rounds, nullptr, warm ? &rate : nullptr);
  return u;
}

/// Herschel-Bulkley flow between plates at y = 0, H under the pressure gradient G (exact,
/// e.g. Chhabra & Richardson 2008, section 3.3 for slits): the shear stress is
/// tau(y) = G (H/2 - y); the liquid yields where |tau| > tau0, i.e. outside the plug
/// |y - H/2| < y0 = tau0 / G, and there k |du/dy|^n = |tau| - tau0, so with h = H/2, d = |y - h|
///   u(y) = n/(n+1) (G/k)^(1/n) [ (h - y0)^((n+1)/n) - (d - y0)^((n+1)/n) ]   (d >= y0),
/// the plug moving at the value for d = y0.
[[maybe_unused]] double channel_profile(const HerschelBulkley& m, double G, double H, double y) {
  const double h = 0.5 * H, y0 = m.tau0 / G, d = std::max(std::abs(y - h), y0);
  const double e = (m.n + 1.0) / m.n;
  if (y0 >= h) return 0.0;
  return m.n / (m.n + 1.0) * std::pow(G / m.k, 1.0 / m.n) *
         (std::pow(h - y0, e) - std::pow(d - y0, e));
}

/// The velocity field sampled from a function of position on every face (component `axis` of
/// f on the faces normal to axis).
template <int Dim>
VectorX face_field(const MacGrid<Dim>& grid, const std::function<Vec<Dim>(const Vec<Dim>&)>& f) {
  VectorX u(grid.num_faces());
  for (int i = 0; i < grid.num_faces(); ++i) {
    const auto [axis, c] = grid.face_coord(i);
    u[i] = f(grid.face_center(axis, c))[axis];
  }
  return u;
}

}  // namespace

TEST_CASE("eq. (27): limiting viscosity below gamma0, tau0 + k s^n in simple shear above",
          "[unit]") {
  // power law, Bingham and their mix; the shear stress of simple shear is eta(s) s
  for (const HerschelBulkley m : {HerschelBulkley{2.0, 0.5, 0.0, 1e-3}, HerschelBulkley{0.5, 2.0, 0.0, 1e-2},
                                  HerschelBulkley{1.0, 1.0, 3.0, 1e-3}, HerschelBulkley{10.0, 0.5, 1.0, 1.0}}) {
    const double eta0 = m.k * std::pow(m.gamma0, m.n - 1.0) + m.tau0 / m.gamma0;
    CHECK(m.limiting_viscosity() == Approx(eta0).epsilon(1e-14));
    CHECK(m.viscosity(0.5 * m.gamma0) == Approx(eta0).epsilon(1e-14));
    for (double s : {2.0 * m.gamma0, 0.37, 1.0, 12.5}) {
      if (s <= m.gamma0) continue;
      CHECK(m.shear_stress(s) == Approx(m.tau0 + m.k * std::pow(s, m.n)).epsilon(1e-13));
    }
  }
  // the presets and the scene's newtonian viscosity: k exactly, whatever the rate
  const HerschelBulkley water = HerschelBulkley::from_spec(ViscositySpec{ViscosityModel::newtonian, 0.1});
  for (double s : {0.0, 1e-5, 3.0, 1e4}) CHECK(water.viscosity(s) == 0.1);
  CHECK(newtonian_model(0.3).viscosity(7.0) == 0.3);
  CHECK(power_law_model(2.0, 0.5).viscosity(4.0) == Approx(1.0));
  CHECK(bingham_model(1.0, 5.0, 1e-3).viscosity(5.0) == Approx(2.0));
  ViscositySpec hb;
  hb.model = ViscosityModel::herschel_bulkley;
  hb.k = 10;
  hb.n = 2;
  hb.tau0 = 1;
  hb.gamma0 = 1;
  const HerschelBulkley thick = HerschelBulkley::from_spec(hb);
  CHECK(thick.k == 10);
  CHECK(thick.n == 2);
  CHECK(thick.tau0 == 1);
  CHECK(thick.gamma0 == 1);
}

TEMPLATE_TEST_CASE_SIG("the shear-rate norm is the simple-shear rate s for every placement of D u",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  // linear velocity fields: D u is exact on interior DOFs, and s = sqrt(2) ||D u||_F is the same
  // at every DOF although the components live at cell centres, nodes and edges
  const MacGrid<Dim> grid = unit_grid<Dim>(8);
  const StressGrid<Dim> stress(grid);
  const SparseMatrix D = deformation_rate_matrix(stress);
  const std::vector<char> active(stress.num_dofs(), 1);
  struct Case {
    std::function<Vec<Dim>(const Vec<Dim>&)> u;
    double s;
  };
  std::vector<Case> cases;
  // simple shear u = (s y, 0): D_xy = s/2, ||D u||_F = s / sqrt(2)
  cases.push_back({[](const Vec<Dim>& x) { Vec<Dim> v = Vec<Dim>::Zero(); v[0] = 1.7 * x[1]; return v; }, 1.7});
  // planar extension u = (e x, -e y): D_xx = e, D_yy = -e, s = 2 e
  cases.push_back({[](const Vec<Dim>& x) { Vec<Dim> v = Vec<Dim>::Zero(); v[0] = 0.6 * x[0]; v[1] = -0.6 * x[1]; return v; }, 1.2});
  // in 3D also the other shear planes: u_z = s y (D_yz), and u_x = s z (D_xz)
  if (Dim == 3) {
    cases.push_back({[](const Vec<Dim>& x) { Vec<Dim> v = Vec<Dim>::Zero(); v[Dim - 1] = 0.9 * x[1]; return v; }, 0.9});
    cases.push_back({[](const Vec<Dim>& x) { Vec<Dim> v = Vec<Dim>::Zero(); v[0] = 2.5 * x[Dim - 1]; return v; }, 2.5});
  }
  for (const Case& c : cases) {
    const VectorX rate = D * face_field<Dim>(grid, c.u);
    const VectorX s = shear_rate_norm(stress, rate, active);
    double worst = 0.0;
    int checked = 0;
    for (int i = 0; i < stress.num_dofs(); ++i) {
      const auto [k, coord] = stress.coord(i);
      // DOFs at least one cell from the walls (the boundary rows of D are one-sided)
      bool interior = true;
      for (int a = 0; a < Dim; ++a) interior = interior && coord[a] >= 1 && coord[a] <= grid.cells()[a] - 2;
      if (!interior) continue;
      worst = std::max(worst, std::abs(s[i] - c.s));
      ++checked;
    }
    CHECK(checked > 0);
    CHECK(worst < 1e-12 * c.s);
  }
}

TEMPLATE_TEST_CASE_SIG("Couette flow: the solved shear stress is tau0 + k s^n (the parameters' "
                       "rheological meaning)", "[validation]", ((int Dim), Dim), 2, 3) {
  // source: plane Couette flow of a generalised Newtonian liquid has a uniform shear stress and,
  // yielded everywhere, a uniform rate s = U / y_lid, so the stress is tau0 + k s^n (the
  // definition of the parameters, interface.md). Lid as in test_viscous_flow: the top rows
  // filled with a 1e12 times denser liquid moving at U = 1.
  const int n = Dim == 2 ? 16 : 8, lid = 2;
  HbChannel<Dim> ch(n, 1.0);
  for (int f = 0; f < ch.grid.num_faces(); ++f)
    if (ch.grid.face_coord(f).second[1] >= n - lid) ch.w.pressure.face_density[f] = 1e12;
  const double y_lid = ch.grid.face_center(0, VecI<Dim>::Unit(1) * (n - lid))[1];
  const double s = 1.0 / y_lid;
  const int off = ch.stress.offset(Dim);  // tau_xy, the first off-diagonal component
  for (const HerschelBulkley m : {power_law_model(1.0, 0.5), power_law_model(0.5, 2.0),
                                  bingham_model(1.0, 0.5, 1e-3), HerschelBulkley{2.0, 0.7, 0.3, 1e-3}}) {
    VectorX u = VectorX::Zero(ch.grid.num_faces());
    for (int f = 0; f < ch.grid.num_faces(0); ++f)
      if (ch.grid.face_coord(f).second[1] >= n - lid) u[f] = 1.0;
    VectorX tau;
    for (int step = 0; step < 12; ++step) tau = ch.step(u, 10.0, VectorX(), m, 2);
    // tau_xy on the nodes/edges strictly between the wall and the lid
    const double expected = m.tau0 + m.k * std::pow(s, m.n);
    double worst = 0.0;
    for (int i = 0; i < ch.stress.num_dofs(Dim); ++i) {
      const int y = ch.stress.coord(off + i).second[1];
      if (y < 1 || y > n - lid - 1) continue;
      worst = std::max(worst, std::abs(tau[off + i] - expected) / expected);
    }
    const double profile = ch.profile_error(u, [&](double y) { return s * y; }, y_lid - 0.5 / n);
    WARN("Couette " << Dim << "D k " << m.k << " n " << m.n << " tau0 " << m.tau0 << ": tau_xy "
                    << expected << ", relative error " << worst << ", profile error " << profile);
    CHECK(worst < 1e-6);
    CHECK(profile < 1e-6);
  }
}

namespace {

/// Shear rate |du/dy| at the interior node rows of a channel (the x faces of one column):
/// (y of the node, rate) pairs, bottom to top.
template <int Dim>
std::vector<std::pair<double, double>> node_rates(const HbChannel<Dim>& ch, const VectorX& u) {
  const int n = ch.grid.cells()[1];
  std::vector<double> column(n);
  for (int i = 0; i < ch.grid.num_faces(0); ++i) {
    const VecI<Dim> c = ch.grid.face_coord(i).second;
    bool first_column = true;
    for (int a = 0; a < Dim; ++a) first_column = first_column && (a == 1 || c[a] == 0);
    if (first_column) column[c[1]] = u[i];
  }
  std::vector<std::pair<double, double>> rates;
  for (int j = 1; j < n; ++j)
    rates.emplace_back(j * ch.grid.dx(), std::abs(column[j] - column[j - 1]) / ch.grid.dx());
  return rates;
}

/// Half the height of the band of nodes whose rate is below 1e-2 of the largest: the plug
/// half-width of a channel (0 without a plug).
template <int Dim>
double plug_half_width(const HbChannel<Dim>& ch, const VectorX& u) {
  const auto rates = node_rates(ch, u);
  double top = 0.0;
  for (const auto& r : rates) top = std::max(top, r.second);
  int plug = 0;
  for (const auto& r : rates) plug += r.second < 1e-2 * top;
  // the band spans `plug` nodes, i.e. (plug + 1) node spacings between the yielded nodes
  // either side: its edge lies within half a spacing of that midpoint
  return plug == 0 ? 0.0 : 0.5 * (plug + 1) * ch.grid.dx();
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("Bingham channel flow: plug half-width tau0 / G and the analytic profile",
                       "[validation]", ((int Dim), Dim), 2, 3) {
  // source: pressure-driven Bingham flow in a slit (channel_profile; e.g. Chhabra & Richardson
  // 2008, section 3.3), driven here by the body force G = rho g along x (the same thing in a
  // periodic channel). The steady state is reached by 16 backward-Euler steps (dt = 10 H^2 rho
  // / k) from rest with Algorithm 2 (2 rounds per step, as the paper), each warm-started from
  // the previous step's rate. Regularisation gamma0 = 1e-3 (eq. (27)). The plug converges
  // slowly (in the plug eta ~ tau0 / s, so one round shrinks s there only by the factor
  // tau0 / (tau0 + k s)): 8 steps leave 5 % at tau0 = 0.2, 16 steps 0.5 %.
  // Measured relative max profile errors: 2D (n = 32) tau0 = 0.1: 1.5e-3, tau0 = 0.2: 5.3e-3;
  // 3D (n = 16) 6.1e-3 and 1.1e-2 (see the WARN lines); plug half-width within one dx
  // (0.125 for 0.1, 0.21875 / 0.25 for 0.2). Asserted: error < 0.03, |width - tau0/G| <= dx.
  const int n = Dim == 2 ? 32 : 16;
  const HbChannel<Dim> ch(n, 1.0, 2.0, 2);
  const double G = 1.0;
  for (double tau0 : {0.1, 0.2}) {
    const HerschelBulkley m = bingham_model(1.0, tau0, 1e-3);
    const VectorX u = steady_channel(ch, m, G, 10.0, 16, 2);
    const double err = ch.profile_error(u, [&](double y) { return channel_profile(m, G, 1.0, y); });
    const double half = plug_half_width(ch, u);
    WARN("Bingham " << Dim << "D n = " << n << ", tau0 " << tau0 << ": plug half-width " << half
                    << " (tau0 / G = " << tau0 / G << ", dx = " << ch.grid.dx()
                    << "), relative profile error " << err);
    CHECK(std::abs(half - tau0 / G) <= ch.grid.dx());
    CHECK(err < 0.03);
  }
}

TEMPLATE_TEST_CASE_SIG("power-law channel flow follows the analytic profile for n < 1 and n > 1",
                       "[validation]", ((int Dim), Dim), 2, 3) {
  // source: channel_profile with tau0 = 0 (Bird, Armstrong & Hassager 1987, power-law slit
  // flow). Shear thinning n = 0.5 (blunted profile) and thickening n = 2 (pointed); 8
  // backward-Euler steps of dt = 10 from rest, 2 warm-started rounds each. Measured relative
  // max errors: 2D (n = 32) 2.9e-3 (n = 0.5), 9.0e-4 (n = 2); 3D (n = 16) 1.1e-2, 2.9e-3.
  // Asserted: < 0.03.
  const int n = Dim == 2 ? 32 : 16;
  const HbChannel<Dim> ch(n, 1.0, 2.0, 2);
  for (const HerschelBulkley m : {power_law_model(1.0, 0.5), power_law_model(1.0, 2.0)}) {
    const VectorX u = steady_channel(ch, m, 1.0, 10.0, 8, 2);
    const double err = ch.profile_error(u, [&](double y) { return channel_profile(m, 1.0, 1.0, y); });
    WARN("power law " << Dim << "D n_cells = " << n << ", n = " << m.n
                      << ": relative profile error " << err);
    CHECK(err < 0.03);
  }
}

TEMPLATE_TEST_CASE_SIG("no flow when the yield stress exceeds the wall stress", "[validation]",
                       ((int Dim), Dim), 2, 3) {
  // source: the wall shear stress of channel flow is G H / 2; with tau0 above it the material
  // nowhere yields. Regularised by eq. (27), |tau| < tau0 forces s < gamma0 everywhere, so the
  // speed is at most gamma0 H / 2: that bound is asserted, against the flowing case just below
  // the threshold, whose plug speed is asserted within 10 % (measured 2D 0.0193, 3D 0.0196,
  // exact 0.02). Measured still speed 2.1e-4 (2D and 3D).
  const int n = Dim == 2 ? 32 : 16;
  const HbChannel<Dim> ch(n, 1.0, 2.0, 2);
  const double G = 1.0, gamma0 = 1e-3;
  const VectorX still = steady_channel(ch, bingham_model(1.0, 0.6, gamma0), G, 10.0, 16, 2);
  const HerschelBulkley yielding = bingham_model(1.0, 0.3, gamma0);
  const VectorX flowing = steady_channel(ch, yielding, G, 10.0, 16, 2);
  // Algorithm 2 as printed (line 1 from u* every step, 2 rounds): the wall rate of u* is
  // dt G / dx, and 2 rounds do not bring the wall viscosity back up to eta0, so the layer creeps
  const VectorX paper = steady_channel(ch, bingham_model(1.0, 0.6, gamma0), G, 10.0, 16, 2, false);
  WARN("tau0 = 0.6 > G H/2: max speed " << ch.max_speed(still) << " (bound gamma0 H/2 = "
                                        << 0.5 * gamma0 << "); tau0 = 0.3: " << ch.max_speed(flowing)
                                        << "; tau0 = 0.6 started from u* every step: " << ch.max_speed(paper));
  CHECK(ch.max_speed(still) <= 0.5 * gamma0);
  const double plug = channel_profile(yielding, G, 1.0, 0.5);
  CHECK(std::abs(ch.max_speed(flowing) - plug) < 0.1 * plug);
}


TEMPLATE_TEST_CASE_SIG("a yield-stress layer on an incline rests below its critical thickness and "
                       "flows above", "[validation]", ((int Dim), Dim), 2, 3) {
  // source: a Bingham film of thickness h on a plane inclined at theta carries the wall shear
  // stress rho g sin(theta) h, so it rests for h < h_c = tau0 / (rho g sin(theta)) (e.g. Coussot
  // 2005, Rheometry of pastes, section 1.3) and above it flows with a plug of thickness h_c over a
  // sheared layer: surface speed G (h - h_c)^2 / (2 k), G = rho g sin(theta). The slope is the
  // body force G along x on a flat layer (the normal component only adds hydrostatic pressure),
  // free surface at y = h. 16 backward-Euler steps of dt = 10 from rest, 2 warm-started rounds.
  // Below h_c the regularised law bounds the speed by gamma0 h (as in the channel).
  // 16 cells across the box (h = 2 h_c is 6.4 cells). Measured: h = 0.7 h_c: 5.2e-5 in 2D and 3D
  // (bound 1.4e-4); h = 2 h_c: surface speed 0.01989 in 2D and 3D, 0.5 % below
  // G (h - h_c)^2 / (2 k) = 0.02. Asserted: the bound, and 10 %. At 32 cells and exactly
  // h = 0.4 (12.8 cells) 2D is still at 0.0115 after 64 steps (h = 0.39, 0.41 agree to 1 %):
  // its plug is too thick and yields only slowly, since where |tau| > tau0 but s is small one
  // round multiplies s by about |tau| / tau0, which is close to 1 near the yield surface
  // (docs/non-newtonian.md).
  const int n = 16;
  const double G = 1.0, k = 1.0, tau0 = 0.2, gamma0 = 1e-3, h_c = tau0 / G;
  const HerschelBulkley m = bingham_model(k, tau0, gamma0);
  for (double h : {0.7 * h_c, 2.0 * h_c}) {
    const HbChannel<Dim> layer(n, 1.0, h, 2);
    const VectorX u = steady_channel(layer, m, G, 10.0, 16, 2);
    // the speed on the liquid faces (the air faces hold extrapolated copies)
    double top = 0.0;
    for (int i = 0; i < layer.grid.num_faces(0); ++i)
      if (layer.w.pressure.liquid_face[i] > 0.0) top = std::max(top, std::abs(u[i]));
    const double expected = h > h_c ? G * (h - h_c) * (h - h_c) / (2.0 * k) : 0.0;
    WARN("incline " << Dim << "D h / h_c = " << h / h_c << ": surface speed " << top
                    << " (expected " << expected << ", rest bound " << gamma0 * h << ")");
    if (h < h_c)
      CHECK(top <= gamma0 * h);
    else
      CHECK(std::abs(top - expected) < 0.1 * expected);
  }
}

TEMPLATE_TEST_CASE_SIG("the residual of Algorithm 2 falls with the iterations (Fig. 9's plot)",
                       "[property]", ((int Dim), Dim), 2, 3) {
  // one step from rest of a channel driven by a body force, 8 rounds from u* (line 1 as
  // printed): the residual ||tau - 2 N(gamma_dot) gamma_dot|| / ||tau|| (NonNewtonianViscosity::
  // residuals) of the section 6.4 shear-thinning model (r, gamma0, tau0, k) = (0.5, 1, 1, 10),
  // a thickening one (2, 1, 1, 10) and a Bingham one (1, 1, 100, 10). Measured in the WARN lines.
  // Asserted: every round lowers it, and 8 rounds by at least a factor 10.
  const int n = Dim == 2 ? 32 : 16;
  const HbChannel<Dim> ch(n, 1000.0, 2.0, 2);
  for (const HerschelBulkley m : {HerschelBulkley{10.0, 0.5, 1.0, 1.0}, HerschelBulkley{10.0, 2.0, 1.0, 1.0},
                                  HerschelBulkley{10.0, 1.0, 100.0, 1.0}}) {
    VectorX u = VectorX::Zero(ch.grid.num_faces());
    std::vector<double> res;
    ch.step(u, 0.01, ch.force_along_x(9.81 * 1000.0 / 1000.0 * 100.0), m, 8, &res);
    std::ostringstream line;
    for (double r : res) line << " " << r;
    WARN("residuals " << Dim << "D n = " << m.n << " tau0 = " << m.tau0 << ":" << line.str());
    REQUIRE(res.size() == 8);
    // (until it reaches round-off: the 3D thinning case hits exactly 0 after 6 rounds)
    for (std::size_t i = 1; i < res.size(); ++i) CHECK((res[i] < res[i - 1] || res[i] < 1e-14));
    CHECK(res.back() < 0.1 * res.front());
  }
}

namespace {

/// A 2D / 3D dam break (a liquid block in the left half of a closed box with an open top) with
/// the given viscosity object, `cells` per axis, rendering coloured by viscosity.
nlohmann::json dam_scene(int dim, int cells, const nlohmann::json& viscosity,
                         const std::string& scheme) {
  nlohmann::json j;
  j["format"] = "monolith-scene/1";
  j["dim"] = dim;
  j["domain"]["lower"] = std::vector<double>(dim, 0.0);
  j["domain"]["upper"] = std::vector<double>(dim, 1.0);
  j["domain"]["cells"] = std::vector<int>(dim, cells);
  j["domain"]["boundary"] = {{"y+", "open"}};
  j["time"] = {{"fps", 30}, {"frames", 2}, {"cfl", 2.0}, {"max_dt", 0.02}};
  j["solver"] = {{"tolerance", 1e-8}, {"scheme", scheme}};
  std::vector<double> centre(dim, 0.5), half(dim, 0.45);
  centre[0] = 0.25;
  half[0] = 0.2;
  centre[1] = 0.3;
  half[1] = 0.25;
  j["liquids"] = {{{"shape", {{"type", "box"}, {"center", centre}, {"half_size", half}}},
                   {"density", 1000.0},
                   {"viscosity", viscosity}}};
  j["render"] = {{"enabled", true}, {"size", {48, 48}}, {"color_by", "viscosity"}};
  return j;
}

}  // namespace

TEST_CASE("n = 1, tau0 = 0 runs bit for bit as the newtonian liquid of viscosity k", "[unit]") {
  // the non-Newtonian path (Algorithm 2, 2 rounds) with a rate-independent viscosity: each
  // round solves the same system as the Newtonian path's one solve, so the states agree exactly
  struct Case {
    int dim, cells;
    const char* scheme;
  };
  for (const Case c : {Case{2, 16, "PVC-unified"}, Case{2, 16, "PC-VC-PC-unified"}, Case{3, 8, "PVC-unified"}}) {
    const nlohmann::json newtonian = {{"model", "newtonian"}, {"eta", 20.0}};
    const nlohmann::json hb = {{"model", "herschel-bulkley"}, {"k", 20.0}, {"n", 1.0}, {"tau0", 0.0}};
    auto a = make_simulation(parse_scene(dam_scene(c.dim, c.cells, newtonian, c.scheme), "newtonian", "."));
    auto b = make_simulation(parse_scene(dam_scene(c.dim, c.cells, hb, c.scheme), "hb", "."));
    for (int frame = 0; frame < 2; ++frame) {
      const FrameStats sa = a->advance_frame(), sb = b->advance_frame();
      INFO(c.dim << "D " << c.scheme << " frame " << frame + 1);
      CHECK(sa.steps == sb.steps);
      CHECK(sa.kinetic_energy_liquid == sb.kinetic_energy_liquid);
      CHECK(sa.liquid_volume == sb.liquid_volume);
      CHECK(sa.liquid_bounds_upper == sb.liquid_bounds_upper);
      CHECK(a->liquid_potential_energy() == b->liquid_potential_energy());
      // Algorithm 2 ran its 2 rounds: twice the viscous solves
      CHECK(sb.solver.iterations > sa.solver.iterations);
      CHECK(sa.kinetic_energy_liquid > 0.0);
    }
    RenderSpec spec;
    spec.size = {48, 48};
    spec.color_by = ColorBy::viscosity;
    CHECK(render_simulation(*a, spec).rgb == render_simulation(*b, spec).rgb);
  }
}

TEST_CASE("a Bingham block holds its shape where a Newtonian one of the same k slumps", "[validation]") {
  // section 6.4 (Fig. 10): a yield stress keeps the dropped shape. A 2D block at rest under
  // gravity: the Newtonian liquid (eta = 10) spreads, the Bingham one (k = 10, tau0 = 5e3 Pa,
  // about rho g H = 4.9e3 Pa of the 0.5 m block) much less. Compared: the advance of the right
  // edge of the particle bounds and the kinetic energy after 2 frames. Measured: 0.0342 m and
  // 29.0 J/m (Newtonian) against 0.0048 m and 0.93 J/m (Bingham). Asserted: half or less.
  const nlohmann::json newtonian = {{"model", "newtonian"}, {"eta", 10.0}};
  const nlohmann::json bingham = {{"model", "herschel-bulkley"}, {"k", 10.0}, {"n", 1.0}, {"tau0", 5e3}, {"gamma0", 1.0}};
  auto a = make_simulation(parse_scene(dam_scene(2, 16, newtonian, "PVC-unified"), "newtonian", "."));
  auto b = make_simulation(parse_scene(dam_scene(2, 16, bingham, "PVC-unified"), "bingham", "."));
  const double right0 = a->current_stats().liquid_bounds_upper[0];
  FrameStats sa, sb;
  for (int frame = 0; frame < 2; ++frame) {
    sa = a->advance_frame();
    sb = b->advance_frame();
  }
  const double spread_a = sa.liquid_bounds_upper[0] - right0, spread_b = sb.liquid_bounds_upper[0] - right0;
  WARN("right edge moved: Newtonian " << spread_a << " m, Bingham " << spread_b << " m; kinetic energy "
                                      << sa.kinetic_energy_liquid << " vs " << sb.kinetic_energy_liquid);
  CHECK(spread_b < 0.5 * spread_a);
  CHECK(sb.kinetic_energy_liquid < 0.5 * sa.kinetic_energy_liquid);
  // stats.jsonl: the residual of each viscosity round (default staggered_iterations = 2) for
  // the non-Newtonian liquid only
  CHECK(sb.solver.viscosity_residuals.size() == 2);
  CHECK(sb.solver.max_viscosity_residual > 0.0);
  CHECK(frame_stats_json(sb)["solver"]["viscosity"]["residuals"].size() == 2);
  CHECK_FALSE(frame_stats_json(sa)["solver"].contains("viscosity"));
}

namespace {

/// A 2D box (density 500, friction 0.3) dropped into a pool of the given liquid: 16^2 cells,
/// 2 frames at 30 fps, explicit back end (the coupled step's).
nlohmann::json drop_scene(const nlohmann::json& viscosity, const std::string& scheme) {
  nlohmann::json j = nlohmann::json::parse(R"({
    "format": "monolith-scene/1", "name": "hb-drop", "dim": 2,
    "domain": {"lower": [0, 0], "upper": [1, 1], "cells": [16, 16], "boundary": {"y+": "open"}},
    "time": {"fps": 30, "frames": 2, "cfl": 2.0, "max_dt": 0.01},
    "solver": {"backend": "explicit", "staggered_iterations": 2, "tolerance": 1e-8},
    "liquids": [{"name": "pool", "density": 1000,
                 "shape": {"type": "box", "center": [0.5, 0.2], "half_size": [0.5, 0.2]}}],
    "bodies": [{"name": "box", "motion": "dynamic", "density": 500, "friction": 0.3,
                "shape": {"type": "box", "center": [0.5, 0.45], "half_size": [0.1, 0.06]},
                "velocity": [0, -1.5]}],
    "render": {"enabled": false}
  })");
  j["solver"]["scheme"] = scheme;
  j["liquids"][0]["viscosity"] = viscosity;
  return j;
}

}  // namespace

TEST_CASE("coupled step: n = 1, tau0 = 0 equals newtonian, a Bingham pool stops the body sooner",
          "[unit]") {
  // the viscosity rounds of solve_coupled_step (unified, iterative and PC-VC-PC schemes) with a
  // rate-independent viscosity repeat the Newtonian solve exactly; a yield stress slows the box
  const nlohmann::json newtonian = {{"model", "newtonian"}, {"eta", 10.0}};
  const nlohmann::json linear = {{"model", "herschel-bulkley"}, {"k", 10.0}, {"n", 1.0}, {"tau0", 0.0}};
  const nlohmann::json bingham = {{"model", "herschel-bulkley"}, {"k", 10.0}, {"n", 1.0}, {"tau0", 1e3}, {"gamma0", 1.0}};
  for (const char* scheme : {"PVC-unified", "PVC-iterative", "PC-VC-PC-unified"}) {
    auto a = make_simulation(parse_scene(drop_scene(newtonian, scheme), "newtonian", "."));
    auto b = make_simulation(parse_scene(drop_scene(linear, scheme), "linear", "."));
    auto c = make_simulation(parse_scene(drop_scene(bingham, scheme), "bingham", "."));
    FrameStats sa, sb, sc;
    for (int frame = 0; frame < 2; ++frame) {
      sa = a->advance_frame();
      sb = b->advance_frame();
      sc = c->advance_frame();
      INFO(scheme << " frame " << frame + 1);
      REQUIRE(sa.bodies.size() == 1);
      CHECK(sa.bodies[0].position == sb.bodies[0].position);
      CHECK(sa.bodies[0].velocity == sb.bodies[0].velocity);
      CHECK(sa.kinetic_energy_liquid == sb.kinetic_energy_liquid);
    }
    WARN(scheme << ": body velocity after 2 frames, Newtonian " << sa.bodies[0].velocity[1]
                << ", Bingham " << sc.bodies[0].velocity[1] << " m/s; liquid kinetic energy "
                << sa.kinetic_energy_liquid << " vs " << sc.kinetic_energy_liquid);
    CHECK(std::isfinite(sc.kinetic_energy_liquid));
    CHECK(std::abs(sc.bodies[0].velocity[1]) < std::abs(sa.bodies[0].velocity[1]));
  }
}

TEST_CASE("3D drop: shear thinning spreads, shear thickening damps (section 6.4.1)", "[validation]") {
  // Fig. 10 in small: a 0.3 x 0.4 x 0.3 m block thrown down at 2 m/s onto the floor of a 1 m box,
  // 16^3, the paper's (r, gamma0, tau0, k) sets (0.5, 1, 1, 10) and (2, 1, 1, 10), 6 frames at
  // 30 fps (impact at about 0.15 s). Measured after 0.2 s: x extent 0.955 m (thinning) vs 0.505 m
  // (thickening), liquid kinetic energy 192.8 vs 25.2 J (Newtonian eta = 11: 0.873 m, 142.3 J).
  // Asserted: thinning spreads wider and keeps more energy, and each step's 2 rounds are recorded.
  auto scene = [](const nlohmann::json& viscosity) {
    nlohmann::json j = dam_scene(3, 16, viscosity, "PVC-unified");
    j["time"] = {{"fps", 30}, {"frames", 6}, {"cfl", 2.0}, {"max_dt", 0.01}};
    j["liquids"][0]["shape"] = {{"type", "box"}, {"center", {0.5, 0.55, 0.5}}, {"half_size", {0.15, 0.2, 0.15}}};
    j["liquids"][0]["velocity"] = {0.0, -2.0, 0.0};
    j["render"] = {{"enabled", false}};
    return parse_scene(j, "drop-3d", ".");
  };
  auto thin = make_simulation(scene({{"model", "herschel-bulkley"}, {"k", 10.0}, {"n", 0.5}, {"tau0", 1.0}, {"gamma0", 1.0}}));
  auto thick = make_simulation(scene({{"model", "herschel-bulkley"}, {"k", 10.0}, {"n", 2.0}, {"tau0", 1.0}, {"gamma0", 1.0}}));
  FrameStats a, b;
  for (int frame = 0; frame < 6; ++frame) {
    a = thin->advance_frame();
    b = thick->advance_frame();
  }
  const double extent_a = a.liquid_bounds_upper[0] - a.liquid_bounds_lower[0];
  const double extent_b = b.liquid_bounds_upper[0] - b.liquid_bounds_lower[0];
  WARN("3D drop after 0.2 s: x extent thinning " << extent_a << " m, thickening " << extent_b
                                                 << " m; kinetic energy " << a.kinetic_energy_liquid
                                                 << " vs " << b.kinetic_energy_liquid << " J");
  CHECK(extent_a > 1.5 * extent_b);
  CHECK(a.kinetic_energy_liquid > 3.0 * b.kinetic_energy_liquid);
  CHECK(a.solver.viscosity_residuals.size() == 2);
  CHECK(b.solver.viscosity_residuals.size() == 2);
}

namespace {

/// A Bingham film (density 1000, k = 1, tau0, gamma0 = 1e-2) of height 0.5 m on the floor of a
/// periodic 2D / 3D box (0.5 m long, 0.125 m deep in 3D, 1 m high, 16 cells high), gravity
/// (1, -9.81): the wall stress is rho g_x h = 500 Pa. `frames` at 10 fps, steps up to 0.02 s;
/// warm start as given.
SceneDesc film_scene(int dim, double tau0, bool warm, int frames) {
  nlohmann::json j;
  j["format"] = "monolith-scene/1";
  j["dim"] = dim;
  std::vector<double> upper(dim, 0.125);
  upper[0] = 0.5;
  upper[1] = 1.0;
  std::vector<int> cells(dim, 2);
  cells[0] = 8;
  cells[1] = 16;
  j["domain"]["lower"] = std::vector<double>(dim, 0.0);
  j["domain"]["upper"] = upper;
  j["domain"]["cells"] = cells;
  j["domain"]["boundary"] = {{"x-", "periodic"}, {"x+", "periodic"}, {"y+", "open"}};
  if (dim == 3) {
    j["domain"]["boundary"]["z-"] = "periodic";
    j["domain"]["boundary"]["z+"] = "periodic";
  }
  std::vector<double> g(dim, 0.0);
  g[0] = 1.0;
  g[1] = -9.81;
  j["gravity"] = g;
  j["time"] = {{"fps", 10}, {"frames", frames}, {"cfl", 2.0}, {"max_dt", 0.02}};
  j["solver"] = {{"tolerance", 1e-8}, {"scheme", "PVC-unified"}, {"staggered_iterations", 2}};
  std::vector<double> centre(dim, 0.0625), half(dim, 0.0625);
  centre[0] = 0.25;
  centre[1] = 0.25;
  half[0] = 0.25;
  half[1] = 0.25;
  j["liquids"] = {{{"shape", {{"type", "box"}, {"center", centre}, {"half_size", half}}},
                   {"density", 1000.0},
                   {"viscosity",
                    {{"model", "herschel-bulkley"}, {"k", 1.0}, {"n", 1.0}, {"tau0", tau0}, {"gamma0", 1e-2}}}}};
  std::vector<double> probe(dim, 0.0625);
  probe[0] = 0.25;
  probe[1] = 0.46;
  j["probes"] = {{{"name", "surface"}, {"position", probe}}};
  j["render"] = {{"enabled", false}};
  SceneDesc scene = parse_scene(j, "bingham-film", ".");
  scene.solver.viscosity_warm_start = warm;
  return scene;
}

/// The film's speed: the larger of the probe's speed near the surface (where a film flows
/// fastest) and the root-mean-square speed sqrt(2 KE / (rho V)) of the liquid.
double film_speed(const FrameStats& s) {
  double probe = 0.0;
  for (double v : s.probes.at(0).velocity) probe += v * v;
  const double rms = std::sqrt(2.0 * s.kinetic_energy_liquid / (1000.0 * s.liquid_volume));
  return std::max(std::sqrt(probe), rms);
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("simulator: a Bingham film below yield stays at rest (Algorithm 2 warm start)",
                       "[validation]", ((int Dim), Dim), 2, 3) {
  // source: a film of height h on a floor under the along-floor load rho g_x has wall stress
  // rho g_x h = 500 Pa; with tau0 = 600 Pa it nowhere yields. Regularised by eq. (27), |tau| <
  // tau0 keeps s < gamma0, so the speed is at most gamma0 h = 5e-3 m/s: asserted for the
  // simulator's start (the previous step's rate). Started from u* every step (line 1 as printed)
  // the wall rate of u* is about dt g_x / dx = 0.32 1/s >> gamma0, 2 rounds do not bring the
  // wall viscosity back to eta0, and the film creeps: asserted faster than the bound (the reason
  // for the departure). Above yield (tau0 = 300 Pa) the film flows with either start.
  // Measured (2D / 3D, speeds in m/s): warm start 2.3e-3 / 2.1e-3 after 0.5 s (bound 5e-3),
  // from u* 0.045 after 0.2 s (0.066 / 0.053 after 0.5 s), above yield 0.23 / 0.20 after 0.5 s.
  const int frames = 3;
  auto run = [&](double tau0, bool warm, int n) {
    auto sim = make_simulation(film_scene(Dim, tau0, warm, n));
    FrameStats s;
    long iterations = 0;
    for (int f = 0; f < n; ++f) {
      s = sim->advance_frame();
      iterations += s.solver.iterations;
    }
    WARN(Dim << "D tau0 = " << tau0 << (warm ? " warm" : " from u*") << ": " << iterations
             << " solver iterations in " << n << " frames");
    return s;
  };
  const FrameStats still = run(600.0, true, frames), flowing = run(300.0, true, 2);
  const FrameStats paper = run(600.0, false, 2);
  WARN(Dim << "D Bingham film: tau0 = 600 Pa, warm start (0.3 s): " << film_speed(still)
           << " m/s (bound 5e-3); line 1 from u* (0.2 s): " << film_speed(paper)
           << " m/s; tau0 = 300 Pa (0.2 s): " << film_speed(flowing) << " m/s; last residuals "
           << still.solver.max_viscosity_residual << " vs " << paper.solver.max_viscosity_residual);
  CHECK(film_speed(still) <= 5e-3);
  CHECK(film_speed(paper) > 5e-3);
  CHECK(film_speed(flowing) > 10.0 * film_speed(still));
}

TEMPLATE_TEST_CASE_SIG("simulator: the viscosity residual of a frame falls with the rounds (Fig. 9)",
                       "[property]", ((int Dim), Dim), 2, 3) {
  // Fig. 9's quantity through the simulator: the shear-thinning set (r, gamma0, tau0, k) =
  // (0.5, 1, 1, 10) dropped at 2 m/s, one frame of 1/15 s
  // (the block lands on the floor within it), staggered_iterations 1, 2, 3. Asserted: within the last step every
  // round lowers the residual, and the frame's largest last-round residual falls with the rounds.
  // Measured, largest last-round residual for 1 / 2 / 3 rounds: 2D 0.90 / 0.076 / 2.1e-3,
  // 3D 0.84 / 0.11 / 7.7e-3.
  std::vector<double> last;
  for (int rounds = 1; rounds <= 3; ++rounds) {
    nlohmann::json j = dam_scene(Dim, Dim == 2 ? 24 : 12,
                                 {{"model", "herschel-bulkley"}, {"k", 10.0}, {"n", 0.5}, {"tau0", 1.0}, {"gamma0", 1.0}},
                                 "PVC-unified");
    std::vector<double> centre(Dim, 0.5), half(Dim, 0.15);
    centre[1] = 0.35;
    half[1] = 0.2;
    // Replaced values are assigned from a typed temporary, not a bare braced list: inside a
    // template, Clang up to 16 (llvm-project issue 51037) omits the destructor of the by-value
    // parameter of json's operator= when it is initialised from a braced list, which leaks the
    // replaced value (LeakSanitizer found it; GCC is not affected).
    j["liquids"][0]["shape"] = nlohmann::json{{"type", "box"}, {"center", centre}, {"half_size", half}};
    std::vector<double> v(Dim, 0.0);
    v[1] = -2.0;
    j["liquids"][0]["velocity"] = v;
    j["time"] = nlohmann::json{{"fps", 15}, {"frames", 1}, {"cfl", 2.0}, {"max_dt", 0.01}};
    j["solver"]["staggered_iterations"] = rounds;
    j["render"] = nlohmann::json{{"enabled", false}};
    auto sim = make_simulation(parse_scene(j, "fig9-rounds", "."));
    const FrameStats s = sim->advance_frame();
    const std::vector<double>& res = s.solver.viscosity_residuals;
    std::ostringstream line;
    for (double r : res) line << " " << r;
    WARN(Dim << "D, " << rounds << " rounds: last step's residuals" << line.str()
             << "; largest last-round residual of the frame " << s.solver.max_viscosity_residual);
    REQUIRE(res.size() == static_cast<std::size_t>(rounds));
    for (std::size_t i = 1; i < res.size(); ++i) CHECK(res[i] < res[i - 1]);
    last.push_back(s.solver.max_viscosity_residual);
  }
  CHECK(last[1] < last[0]);
  CHECK(last[2] < last[1]);
}
