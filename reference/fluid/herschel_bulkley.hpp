#pragma once
/// \file herschel_bulkley.hpp
/// Non-Newtonian viscosity of section 5: the Herschel-Bulkley effective viscosity of eq. (27)
/// per stress DOF, and Algorithm 2 (the staggered viscosity update around the solves of eq. (29)).
/// docs/non-newtonian.md explains the choices; the short version:
///
/// Shear-rate norm. The scene's parameters (k, n, tau0, gamma0) have their rheological meaning:
/// in steady simple shear u = (s y, 0) at rate s beyond yield the shear stress is tau0 + k s^n.
/// The deformation rate there is D u with D_xy = D_yx = s/2, so ||D u||_F = s / sqrt(2): eq. (27)
/// read with ||gamma_dot||_F would give tau_xy = sqrt(2) tau0 + k s^n 2^((1-n)/2). We evaluate
/// (27) at the equivalent simple-shear rate
///     s = sqrt(2) ||D u||_F = sqrt(2 sum_ab (D u)_ab^2),
/// and tau = 2 eta D u gives tau_xy = eta(s) s = tau0 + k s^n exactly (tests/test_herschel_bulkley).
///
/// Staggering. The components of D u live at different places (stress_grid.hpp): s at a DOF of
/// component k sums the squares of every component m interpolated there, each the mean of the
/// nearest DOFs of m (1, 2, 4 or 8 of them: those within half a cell along every axis where the
/// two lattices differ), over the active DOFs only (W_F^s W_L^s > 0).

#include <functional>
#include <memory>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/fluid/liquid_spec.hpp"
#include "reference/grid/stress_grid.hpp"

namespace monolith {

/// One liquid's rheology in the parameters of eq. (27): consistency k (Pa s^n), flow index n
/// (the paper's r), yield stress tau0 (Pa), yielding threshold gamma0 (1/s). A Newtonian
/// liquid of viscosity eta is k = eta, n = 1, tau0 = 0.
struct HerschelBulkley {
  double k = 0.0;
  double n = 1.0;
  double tau0 = 0.0;
  double gamma0 = 1e-3;

  /// From a scene's viscosity: herschel-bulkley as given, newtonian as (eta, 1, 0, gamma0).
  static HerschelBulkley from_spec(const ViscositySpec& spec);
  /// eq. (27): eta0 = k gamma0^(n-1) + tau0 / gamma0 for s <= gamma0, else k s^(n-1) + tau0 / s;
  /// s the equivalent simple-shear rate (file comment). Pa s.
  double viscosity(double s) const;
  /// The limiting viscosity eta0 of eq. (27) (the viscosity of a liquid at rest).
  double limiting_viscosity() const { return viscosity(0.0); }
  /// The shear stress of steady simple shear at rate s: eta(s) s (= tau0 + k s^n beyond gamma0).
  double shear_stress(double s) const { return viscosity(s) * s; }
};

/// The section 6.4 models in the standard sense (docs/non-newtonian.md gives the scene
/// parameters). k in Pa s^n, tau0 in Pa.
HerschelBulkley newtonian_model(double eta);
HerschelBulkley power_law_model(double k, double n);  ///< n < 1 thinning, n > 1 thickening
HerschelBulkley bingham_model(double k, double tau0, double gamma0);

/// True when some liquid of the scene is herschel-bulkley (the simulator then runs Algorithm 2).
bool has_non_newtonian(const std::vector<LiquidSpec>& liquids);

/// The equivalent simple-shear rate s = sqrt(2 sum_ab R_ab^2) at every DOF of `stress`, R a
/// deformation-rate field (StressGrid numbering, all components; off-diagonal entries count
/// twice, as R_ab and R_ba) interpolated as the file comment says. Only DOFs with active[i] != 0
/// enter the interpolation; an inactive DOF gets the value interpolated from its active
/// neighbours (0 if it has none).
template <int Dim>
VectorX shear_rate_norm(const StressGrid<Dim>& stress, const VectorX& rate,
                        const std::vector<char>& active);

/// Section 5 per stress DOF: the effective viscosity of a mixture of liquids,
///   eta_j = sum_i f_ij eta_i(s_j),
/// f_ij the mass fraction of liquid i at DOF j (liquid_stress_fractions, viscosity_field.hpp)
/// and eta_i the model of liquid i (eq. (27)).
struct ViscosityMixture {
  std::vector<HerschelBulkley> models;
  std::vector<VectorX> fractions;  ///< per liquid, one entry per stress DOF
  /// When set (one entry per stress DOF), the viscosity regardless of s: the simulator sets it
  /// when every model is Newtonian (n = 1, tau0 = 0) to the eta per DOF of its Newtonian path
  /// (stress_viscosity), so such a scene runs bit for bit as its newtonian twin.
  VectorX constant;
  /// True when no model depends on the shear rate (n = 1 and tau0 = 0 for all).
  bool is_newtonian() const;
  /// eta_j for the shear rates s (one per stress DOF).
  VectorX viscosity(const VectorX& s) const;
  /// The relaxation theta of Algorithm 2's rate update at DOF j: 1 / max(1, n) over the liquids
  /// present there (NonNewtonianViscosity::update).
  double relaxation(int j) const;
};

/// Algorithm 2 (section 5) for one step on a fixed stress layout: holds the shear rate
/// gamma_dot between the solves and turns it into the effective viscosity N(gamma_dot).
///   line 1: gamma_dot^1 = (W_F^s)^-1 D W_F^u u*   (initial_viscosity)
///   line 3: eta^k = eq. (27) at s(gamma_dot^k)
///   line 6: gamma_dot^(k+1) = 1/2 N^-1 tau^(k+1) (update)
/// Departure 1 (shear thickening): line 6 as printed converges only for n < 2. Where the stress
/// is set by the load (a body force, a weight), s^(k+1) = tau / (2 eta(s^k)) with eta ~ s^(n-1)
/// maps log s by a factor -(n - 1): n = 2 oscillates forever (measured: the residual stays at
/// 0.08-0.16 over 8 rounds of a Couette start), n > 2 diverges. The update therefore relaxes the
/// rate geometrically, s^(k+1) = (s^k)^(1 - theta) (s_new)^theta with theta = 1 / n for n > 1
/// (factor 0 under a load, 1 - 1/n where the rate is set by the walls), and keeps theta = 1, the
/// paper's update, for n <= 1.
/// Departure 2: the paper weights the rate by the liquid fraction (gamma_dot = W_L^s D W_F^u u,
/// line 6 with W_F^s W_L^s); we use the rate itself (the optimum of eq. (29) is
/// tau = 2 eta (W_F^s)^-1 D W_F^u u, so tau / (2 eta) is that rate), so a partly filled DOF at
/// the surface does not look less sheared than the flow around it: with the weight a Bingham
/// liquid would stiffen in a layer of a cell at every free surface.
template <int Dim>
class NonNewtonianViscosity {
 public:
  /// `stress` the layout, `fluid_stress` and `liquid_stress` W_F^s and W_L^s (active DOFs:
  /// product > 0), `mixture` the liquids.
  NonNewtonianViscosity(const StressGrid<Dim>& stress, const VectorX& fluid_stress,
                        const VectorX& liquid_stress, ViscosityMixture mixture);
  /// The same with D (deformation_rate_matrix(stress)) given, so a caller that keeps it (the
  /// simulator, every step on one grid) does not rebuild it.
  NonNewtonianViscosity(const StressGrid<Dim>& stress, std::shared_ptr<const SparseMatrix> d,
                        const VectorX& fluid_stress, const VectorX& liquid_stress,
                        ViscosityMixture mixture);
  /// Line 1 and line 3 for k = 1: gamma_dot^1 = (W_F^s)^-1 D W_F^u u* on the active DOFs,
  /// eta^1. With `warm` (one shear rate s per stress DOF, e.g. the previous step's
  /// shear_rate()) line 1 is replaced by s^1 = warm: the iteration's fixed point is the same,
  /// only its start differs (docs/non-newtonian.md: with 2 rounds from u* a steady flow is not
  /// a fixed point of the time stepping, the wall rate of u* carries dt g / dx). A non-finite
  /// entry of `warm` (NaN: no previous rate there, e.g. a DOF that just became active) takes
  /// line 1's value at that DOF (the simulator's start, previous_shear_rate()).
  VectorX initial_viscosity(const VectorX& fluid_face, const VectorX& u_star,
                            const VectorX& warm = VectorX());
  /// Line 6 and line 3 for k + 1: gamma_dot^(k+1) = tau / (2 eta) on the active DOFs with
  /// eta > 0 (tau all StressGrid components, eta the viscosity it was solved with), and the
  /// next viscosity. Records the residual of the pair (tau, eta) (residuals()).
  VectorX update(const VectorX& tau, const VectorX& eta);
  /// Per update: how far the solved stress is from the constitutive law of eq. (27),
  ///   ||tau - 2 N(gamma_dot) gamma_dot||_M / ||tau||_M,  gamma_dot = tau / (2 eta^k),
  /// i.e. ||(1 - eta^(k+1) / eta^k) tau||_M / ||tau||_M (M the multiplicity: ||tau||_F); 0 at
  /// the fixed point of Algorithm 2, and 0 for Newtonian liquids.
  const std::vector<double>& residuals() const { return residuals_; }
  /// The last shear rate s per stress DOF (equivalent simple-shear rate).
  const VectorX& shear_rate() const { return s_; }
  const std::vector<char>& active() const { return active_; }
  /// The warm start for the next step on the same layout: shear_rate() on the DOFs that were
  /// active, NaN elsewhere (initial_viscosity then falls back to line 1 there).
  VectorX previous_shear_rate() const;

 private:
  StressGrid<Dim> stress_;
  std::shared_ptr<const SparseMatrix> d_;
  VectorX fluid_stress_;
  std::vector<char> active_;
  ViscosityMixture mixture_;
  VectorX s_;
  std::vector<double> residuals_;
};

/// Algorithm 2 around a solve: eta^1 from u* (or `warm`, initial_viscosity), then `iterations` times (at least 1)
/// tau = solve(eta^k) and eta^(k+1) = update(tau, eta^k). `solve` returns tau (all StressGrid
/// components) optimal for the viscosity it is given (eq. (29) with N fixed). Returns the
/// viscosity of the final flow, eta^(iterations + 1) (the colour of `color_by: viscosity`).
template <int Dim>
VectorX run_algorithm2(NonNewtonianViscosity<Dim>& model, const VectorX& fluid_face,
                       const VectorX& u_star, int iterations,
                       const std::function<VectorX(const VectorX& eta)>& solve,
                       const VectorX& warm = VectorX());

}  // namespace monolith
