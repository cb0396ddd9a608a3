// Notebook 10: Herschel-Bulkley viscosity (section 5). The flow curves of eq. (27) for the four
// models of section 6.4, why the norm is sqrt(2) ||D u||_F (simple shear on the grid), and
// Algorithm 2 on one step of a channel: the residual per round (Fig. 9's convergence plot) for
// the printed update and, for shear thickening, the relaxed one.
//
// Run: build/notebooks/notebook_10_herschel_bulkley --out DIR
#include <cmath>
#include <iomanip>
#include <sstream>

#include "notebooks_cpp/notebook.hpp"
#include "reference/fluid/deformation_rate.hpp"
#include "reference/fluid/herschel_bulkley.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/viz/plot.hpp"

using namespace monolith;

namespace {

struct Model {
  const char* name;
  HerschelBulkley hb;
};

/// The section 6.4 sets (r, gamma0, tau0, k) of Fig. 10 as (k, n, tau0, gamma0).
const Model kModels[] = {
    {"Newtonian", {11.0, 1.0, 0.0, 1.0}},
    {"shear thinning", {10.0, 0.5, 1.0, 1.0}},
    {"shear thickening", {10.0, 2.0, 1.0, 1.0}},
    {"Bingham", {10.0, 1.0, 1000.0, 1.0}},
};

/// One backward-Euler step of a 2D periodic channel (walls at y = 0, 1; 4 x 32 cells, water
/// density) from rest under a body force along x, with `rounds` rounds of Algorithm 2 from u*.
std::vector<double> channel_residuals(const HerschelBulkley& m, int rounds) {
  const int n = 32;
  std::array<BoundaryType, 4> boundary{BoundaryType::periodic, BoundaryType::periodic,
                                       BoundaryType::wall, BoundaryType::wall};
  const MacGrid<2> grid(Vec<2>::Zero(), 1.0 / n, VecI<2>(4, n), {true, false});
  const SampleLattice<2> lattice = half_lattice(grid);
  const VectorX solid_phi = solid_phi_on_lattice<2>(grid, lattice, {}, 0.0);
  const VectorX liquid_phi = VectorX::Constant(lattice.size(), -1.0);
  StokesWeights w = uniform_stokes_weights(grid, solid_phi, liquid_phi, boundary, 1000.0, 1.0);
  const StressGrid<2> stress(grid);
  ViscosityMixture mixture;
  mixture.models = {m};
  mixture.fractions = {VectorX::Ones(stress.num_dofs())};
  NonNewtonianViscosity<2> nn(stress, w.fluid_stress, w.liquid_stress, mixture);
  // u* = dt g on the x faces: 0.01 s of 981 m/s^2
  VectorX u_star = VectorX::Zero(grid.num_faces());
  for (int i = 0; i < grid.num_faces(0); ++i) u_star[i] = 0.01 * 981.0;
  PcgSettings settings;
  settings.tolerance = 1e-12;
  settings.max_iterations = 50000;
  run_algorithm2<2>(nn, w.pressure.fluid_face, u_star, rounds, [&](const VectorX& eta) {
    w.viscosity = eta;
    VectorX u = u_star;
    return solve_stokes(grid, w, 0.01, StokesUnknowns::pressure_and_stress, StressForm::reduced,
                        Backend::matrix_free, settings, u)
        .stress;
  });
  return nn.residuals();
}

}  // namespace

int main(int argc, char** argv) {
  notebook::Notebook nb(argc, argv, "Notebook 10: Herschel-Bulkley viscosity (section 5)");

  // --- eq. (27) ----------------------------------------------------------------------------------
  nb.md("## Eq. (27) for the four models of section 6.4\n\n"
        "eta(s) = k max(s, gamma0)^(n-1) + tau0 / max(s, gamma0), s the equivalent simple-shear "
        "rate. The paper lists (r, gamma0, tau0, k); the scene keys are n = r, gamma0, tau0, k. "
        "Effective viscosity (Pa s) and shear stress eta(s) s (Pa):");
  const double rates[] = {0.1, 1.0, 10.0, 100.0};
  {
    std::ostringstream t;
    t << "| model | (k, n, tau0, gamma0) |";
    for (double s : rates) t << " eta(" << s << ") | tau(" << s << ") |";
    t << "\n|---|---|";
    for (std::size_t i = 0; i < 2 * std::size(rates); ++i) t << "---|";
    t << "\n";
    for (const Model& m : kModels) {
      t << "| " << m.name << " | (" << m.hb.k << ", " << m.hb.n << ", " << m.hb.tau0 << ", "
        << m.hb.gamma0 << ") |";
      for (double s : rates)
        t << " " << format_number(m.hb.viscosity(s), 4) << " | " << format_number(m.hb.shear_stress(s), 4) << " |";
      t << "\n";
    }
    nb.md(t.str());
  }
  PlotSpec curves;
  curves.title = "eq. (27): effective viscosity of the section 6.4 models";
  curves.x_label = "shear rate s (1/s)";
  curves.y_label = "eta (Pa s)";
  curves.log_x = curves.log_y = true;
  for (const Model& m : kModels) {
    PlotSeries series;
    series.label = m.name;
    for (double e = -2.0; e <= 3.0; e += 0.05) {
      series.x.push_back(std::pow(10.0, e));
      series.y.push_back(m.hb.viscosity(std::pow(10.0, e)));
    }
    curves.series.push_back(series);
  }
  nb.figure("hb_flow_curves.ppm", plot_lines(curves),
            "eta(s) of the four models: flat below gamma0 = 1, then power law / Bingham 1/s");
  for (const Model& m : kModels)
    for (double s : rates)
      if (s > m.hb.gamma0)
        nb.check(std::string(m.name) + ": |eta(s) s - (tau0 + k s^n)| / tau at s = " + format_number(s),
                 std::abs(m.hb.shear_stress(s) - (m.hb.tau0 + m.hb.k * std::pow(s, m.hb.n))) /
                     m.hb.shear_stress(s),
                 1e-14);

  // --- the norm ------------------------------------------------------------------------------------
  nb.md("## Why s = sqrt(2) ||D u||_F\n\n"
        "Simple shear u = (s y, 0) on a 2D grid: D u has D_xy = s/2 on the nodes, zero diagonal. "
        "||D u||_F = s / sqrt(2) (D_xy and D_yx). shear_rate_norm interpolates the components to "
        "every DOF and returns sqrt(2 sum_ab D_ab^2):");
  {
    const MacGrid<2> grid(Vec<2>::Zero(), 1.0 / 8, VecI<2>(8, 8), {false, false});
    const StressGrid<2> stress(grid);
    const double s = 1.7;
    VectorX u = VectorX::Zero(grid.num_faces());
    for (int i = 0; i < grid.num_faces(0); ++i)
      u[i] = s * grid.face_center(0, grid.face_coord(i).second)[1];
    const VectorX rate = deformation_rate_matrix(stress) * u;
    const VectorX norm = shear_rate_norm(stress, rate, std::vector<char>(stress.num_dofs(), 1));
    // an interior node and an interior cell centre
    const int node = stress.index(2, VecI<2>(4, 4)), cell = stress.index(0, VecI<2>(3, 3));
    std::ostringstream t;
    t << "D_xy at node (4,4) = " << rate[node] << " (s/2 = " << s / 2 << "); s at that node = "
      << norm[node] << ", at cell (3,3) = " << norm[cell] << " (s = " << s << ").";
    nb.md(t.str());
    nb.check("D_xy at an interior node equals s / 2", std::abs(rate[node] - s / 2.0), 1e-12);
    nb.check("s at an interior node equals the simple-shear rate", std::abs(norm[node] - s), 1e-12);
    nb.check("s at an interior cell centre (xy interpolated from 4 nodes)", std::abs(norm[cell] - s), 1e-12);
    const HerschelBulkley m{2.0, 0.5, 3.0, 1e-3};
    const double literal = m.viscosity(s / std::sqrt(2.0)) * s;
    std::ostringstream u2;
    u2 << "With (k, n, tau0) = (2, 0.5, 3): eq. (27) at sqrt(2)||D||_F gives tau_xy = eta s = "
       << m.shear_stress(s) << " = tau0 + k s^n = " << 3.0 + 2.0 * std::sqrt(s)
       << "; taken literally at ||D||_F it would give " << literal
       << " = sqrt(2) tau0 + k s^n 2^((1-n)/2) (tau = 2 eta D, D_xy = s/2).";
    nb.md(u2.str());
    nb.check("eta(s) s = tau0 + k s^n", std::abs(m.shear_stress(s) - (3.0 + 2.0 * std::sqrt(s))), 1e-12);
    nb.check("the literal reading equals sqrt(2) tau0 + k s^n 2^((1-n)/2)",
             std::abs(literal - (std::sqrt(2.0) * 3.0 + 2.0 * std::sqrt(s) * std::pow(2.0, 0.25))), 1e-12);
    nb.check("literal reading differs from tau0 + k s^n (by more than 10 %)",
             -std::abs(literal / m.shear_stress(s) - 1.0), -0.1);
  }

  // --- Algorithm 2 -------------------------------------------------------------------------------
  nb.md("## Algorithm 2: the residual per round (Fig. 9's convergence plot)\n\n"
        "Eq. (28), the minimisation over p and the shear rate with N(rate) inside the energy, is "
        "not quadratic and is never assembled. Algorithm 2 solves (29) instead: the quadratic "
        "problem (8) with the viscosity N^k fixed (the Newtonian solvers, unchanged), then the "
        "viscosity from the solved stress, round after round.\n\n"
        "One step (dt = 0.01 s) of a water-density channel between no-slip walls, from rest with "
        "u* = dt g along the channel (32 cells across), 10 rounds from u*. Residual of round k: "
        "||tau^(k+1) - 2 N(gamma_dot^(k+1)) gamma_dot^(k+1)||_F / ||tau^(k+1)||_F with "
        "gamma_dot^(k+1) = tau^(k+1) / (2 eta^k), i.e. how far the solved stress is from the "
        "constitutive law. Shear thickening uses the relaxed rate update (theta = 1/n); the "
        "printed one oscillates for n = 2 (docs/non-newtonian.md).");
  PlotSpec conv;
  conv.title = "Algorithm 2: residual per round, one channel step";
  conv.x_label = "round k";
  conv.y_label = "relative residual";
  conv.log_y = true;
  for (std::size_t i = 1; i < std::size(kModels); ++i) {
    const std::vector<double> res = channel_residuals(kModels[i].hb, 10);
    PlotSeries series;
    series.label = kModels[i].name;
    series.marker = Marker::circle;
    std::ostringstream line;
    line << kModels[i].name << ":";
    for (std::size_t k = 0; k < res.size(); ++k) {
      series.x.push_back(static_cast<double>(k + 1));
      series.y.push_back(std::max(res[k], 1e-16));
      line << " " << format_number(res[k], 3);
    }
    conv.series.push_back(series);
    nb.md(line.str());
    nb.check(std::string(kModels[i].name) + ": residual after 10 rounds / after 1",
             res.back() / res.front(), 0.1);
  }
  nb.figure("hb_residuals.ppm", plot_lines(conv), "residual of Algorithm 2 per round");
  // Newtonian: no residual at all
  const std::vector<double> newtonian = channel_residuals(kModels[0].hb, 3);
  nb.check("Newtonian (n = 1, tau0 = 0): residual of every round", newtonian.back(), 0.0);
  return nb.finish();
}
