/// \file herschel_bulkley.cpp
/// Eq. (27) per stress DOF and Algorithm 2 (herschel_bulkley.hpp).

#include "reference/fluid/herschel_bulkley.hpp"
#include "reference/core/parallel.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "reference/fluid/deformation_rate.hpp"

namespace monolith {

HerschelBulkley HerschelBulkley::from_spec(const ViscositySpec& spec) {
  if (spec.model == ViscosityModel::herschel_bulkley) return {spec.k, spec.n, spec.tau0, spec.gamma0};
  HerschelBulkley m;
  m.k = spec.eta;
  m.gamma0 = spec.gamma0;
  return m;
}

double HerschelBulkley::viscosity(double s) const {
  // eq. (27): below the threshold the limiting viscosity eta0, the value at s = gamma0
  const double rate = std::max(s, gamma0);
  // n = 1 without the pow, so a Newtonian model gives k exactly
  const double power = n == 1.0 ? k : k * std::pow(rate, n - 1.0);
  return tau0 == 0.0 ? power : power + tau0 / rate;
}

HerschelBulkley newtonian_model(double eta) { return {eta, 1.0, 0.0, 1e-3}; }
HerschelBulkley power_law_model(double k, double n) { return {k, n, 0.0, 1e-3}; }
HerschelBulkley bingham_model(double k, double tau0, double gamma0) {
  return {k, 1.0, tau0, gamma0};
}

bool has_non_newtonian(const std::vector<LiquidSpec>& liquids) {
  return std::any_of(liquids.begin(), liquids.end(), [](const LiquidSpec& l) {
    return l.viscosity.model == ViscosityModel::herschel_bulkley;
  });
}

namespace {

/// Calls visit(m, index) for every DOF of component m within half a cell of DOF i that exists:
/// along an axis where the two lattices agree the same coordinate, where they differ the two
/// neighbours (in component order, corners in bit order). The relation is symmetric: j is
/// visited from i exactly when i is visited from j.
template <int Dim, typename Visit>
void for_stress_stencil(const StressGrid<Dim>& stress, int i, Visit&& visit) {
  constexpr int kComponents = StressGrid<Dim>::kComponents;
  const auto [k, c] = stress.coord(i);
  const Vec<Dim> shift_k = StressGrid<Dim>::shift(k);
  for (int m = 0; m < kComponents; ++m) {
    const Vec<Dim> shift_m = StressGrid<Dim>::shift(m);
    int differ[Dim];
    int num_differ = 0;
    for (int a = 0; a < Dim; ++a)
      if (shift_k[a] != shift_m[a]) differ[num_differ++] = a;
    for (int corner = 0; corner < (1 << num_differ); ++corner) {
      VecI<Dim> cm = c;
      for (int j = 0; j < num_differ; ++j) {
        const int a = differ[j];
        const int bit = (corner >> j) & 1;
        // node-aligned target (shift 0) reads cell-centred c - 1, c; cell-centred target
        // (shift 1/2) reads node-aligned c, c + 1
        cm[a] += shift_k[a] == 0.0 ? bit - 1 : bit;
      }
      visit(m, stress.index_or_outside(m, cm));
    }
    visit(m, -2);  // end of component m
  }
}

}  // namespace

template <int Dim>
VectorX shear_rate_norm(const StressGrid<Dim>& stress, const VectorX& rate,
                        const std::vector<char>& active) {
  const int n = stress.num_dofs();
  VectorX s = VectorX::Zero(n);
  // only DOFs with an active DOF in their stencil can be nonzero (elsewhere every mean is empty
  // and s = sqrt(0) = 0, the zero already stored): mark them from the active DOFs, which the
  // liquid confines to a band, instead of visiting every stencil of the grid
  std::vector<char> reach(n, 0);
  for (int j = 0; j < n; ++j) {
    if (!active[j]) continue;
    for_stress_stencil(stress, j, [&](int, int index) {
      if (index >= 0) reach[index] = 1;
    });
  }
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (int i = 0; i < n; ++i) {
    if (!reach[i]) continue;
    double sum = 0.0, value = 0.0;
    int count = 0;
    for_stress_stencil(stress, i, [&](int m, int index) {
      if (index == -2) {
        if (count > 0) {
          const double mean = value / count;
          sum += StressGrid<Dim>::multiplicity(m) * mean * mean;
        }
        value = 0.0;
        count = 0;
        return;
      }
      if (index < 0 || !active[index]) return;
      value += rate[index];
      ++count;
    });
    s[i] = std::sqrt(2.0 * sum);
  }
  return s;
}

bool ViscosityMixture::is_newtonian() const {
  return std::all_of(models.begin(), models.end(), [](const HerschelBulkley& m) {
    return m.n == 1.0 && m.tau0 == 0.0;
  });
}

double ViscosityMixture::relaxation(int j) const {
  double n = 1.0;
  for (std::size_t l = 0; l < models.size(); ++l)
    if (fractions[l][j] != 0.0) n = std::max(n, models[l].n);
  return 1.0 / n;
}

VectorX ViscosityMixture::viscosity(const VectorX& s) const {
  if (constant.size() == s.size()) return constant;
  VectorX eta = VectorX::Zero(s.size());
  for (std::size_t l = 0; l < models.size(); ++l) {
    const VectorX& f = fractions[l];
    const HerschelBulkley& model = models[l];
    for (int j = 0; j < s.size(); ++j)
      if (f[j] != 0.0) eta[j] += f[j] * model.viscosity(s[j]);
  }
  return eta;
}

template <int Dim>
NonNewtonianViscosity<Dim>::NonNewtonianViscosity(const StressGrid<Dim>& stress,
                                                  const VectorX& fluid_stress,
                                                  const VectorX& liquid_stress,
                                                  ViscosityMixture mixture)
    : NonNewtonianViscosity(stress,
                            std::make_shared<const SparseMatrix>(deformation_rate_matrix(stress)),
                            fluid_stress, liquid_stress, std::move(mixture)) {}

template <int Dim>
NonNewtonianViscosity<Dim>::NonNewtonianViscosity(const StressGrid<Dim>& stress,
                                                  std::shared_ptr<const SparseMatrix> d,
                                                  const VectorX& fluid_stress,
                                                  const VectorX& liquid_stress,
                                                  ViscosityMixture mixture)
    : stress_(stress),
      d_(std::move(d)),
      fluid_stress_(fluid_stress),
      active_(stress.num_dofs(), 0),
      mixture_(std::move(mixture)) {
  for (int i = 0; i < stress.num_dofs(); ++i)
    active_[i] = fluid_stress[i] * liquid_stress[i] > 0.0;
}

template <int Dim>
VectorX NonNewtonianViscosity<Dim>::initial_viscosity(const VectorX& fluid_face,
                                                      const VectorX& u_star, const VectorX& warm) {
  residuals_.clear();
  const bool has_warm = warm.size() == stress_.num_dofs();
  const bool complete = has_warm && warm.allFinite();
  if (complete) {
    s_ = warm;
    return mixture_.viscosity(s_);
  }
  // line 1: gamma_dot^1 = (W_F^s)^-1 D W_F^u u* on the active DOFs
  VectorX rate = *d_ * fluid_face.cwiseProduct(u_star);
  for (int i = 0; i < rate.size(); ++i) rate[i] = active_[i] ? rate[i] / fluid_stress_[i] : 0.0;
  // line 3: eq. (27) at the interpolated norm
  s_ = shear_rate_norm(stress_, rate, active_);
  // a partial warm start: the previous rate where it has one (finite), line 1 elsewhere
  if (has_warm)
    for (int i = 0; i < s_.size(); ++i)
      if (std::isfinite(warm[i])) s_[i] = warm[i];
  return mixture_.viscosity(s_);
}

template <int Dim>
VectorX NonNewtonianViscosity<Dim>::previous_shear_rate() const {
  VectorX warm = s_;
  for (int i = 0; i < warm.size(); ++i)
    if (!active_[i]) warm[i] = std::numeric_limits<double>::quiet_NaN();
  return warm;
}

template <int Dim>
VectorX NonNewtonianViscosity<Dim>::update(const VectorX& tau, const VectorX& eta) {
  // line 6: gamma_dot^(k+1) = 1/2 N^-1 tau = tau / (2 eta) where the DOF was an unknown
  VectorX rate = VectorX::Zero(tau.size());
  for (int i = 0; i < tau.size(); ++i)
    if (active_[i] && eta[i] > 0.0) rate[i] = tau[i] / (2.0 * eta[i]);
  const VectorX s_new = shear_rate_norm(stress_, rate, active_);
  const VectorX law = mixture_.viscosity(s_new);
  // residual of the constitutive law: tau - 2 N(gamma_dot) gamma_dot = (1 - eta' / eta) tau
  double num = 0.0, den = 0.0;
  for (int i = 0; i < tau.size(); ++i) {
    if (!active_[i] || eta[i] <= 0.0) continue;
    const int k = stress_.coord(i).first;
    const double m = StressGrid<Dim>::multiplicity(k);
    const double r = (1.0 - law[i] / eta[i]) * tau[i];
    num += m * r * r;
    den += m * tau[i] * tau[i];
  }
  residuals_.push_back(den > 0.0 ? std::sqrt(num / den) : 0.0);
  // shear thickening: the rate relaxed geometrically, s <- s_old^(1 - theta) s_new^theta with
  // theta = 1 / n (departure, docs/non-newtonian.md); theta = 1 (line 6 as printed) for n <= 1
  bool relax = false;
  VectorX next_s = s_new;
  for (int i = 0; i < tau.size(); ++i) {
    const double theta = mixture_.relaxation(i);
    if (theta >= 1.0 || !(s_[i] > 0.0) || !(s_new[i] > 0.0)) continue;
    next_s[i] = std::exp((1.0 - theta) * std::log(s_[i]) + theta * std::log(s_new[i]));
    relax = true;
  }
  s_ = next_s;
  return relax ? mixture_.viscosity(s_) : law;
}

template <int Dim>
VectorX run_algorithm2(NonNewtonianViscosity<Dim>& model, const VectorX& fluid_face,
                       const VectorX& u_star, int iterations,
                       const std::function<VectorX(const VectorX& eta)>& solve,
                       const VectorX& warm) {
  VectorX eta = model.initial_viscosity(fluid_face, u_star, warm);
  for (int k = 0; k < std::max(1, iterations); ++k) {
    // lines 4-5 with N^k, then line 6 and the next eta
    const VectorX tau = solve(eta);
    eta = model.update(tau, eta);
  }
  return eta;
}

#define MONOLITH_INSTANTIATE_HERSCHEL_BULKLEY(D)                                                  \
  template VectorX shear_rate_norm(const StressGrid<D>&, const VectorX&,                         \
                                   const std::vector<char>&);                                     \
  template class NonNewtonianViscosity<D>;                                                        \
  template VectorX run_algorithm2(NonNewtonianViscosity<D>&, const VectorX&, const VectorX&, int, \
                                  const std::function<VectorX(const VectorX&)>&, const VectorX&);

MONOLITH_INSTANTIATE_HERSCHEL_BULKLEY(2)
MONOLITH_INSTANTIATE_HERSCHEL_BULKLEY(3)

#undef MONOLITH_INSTANTIATE_HERSCHEL_BULKLEY

}  // namespace monolith
