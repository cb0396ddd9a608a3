#pragma once
/// \file preconditioner.hpp
/// The preconditioner interface of the Krylov solvers (pcg_solve, mprgp_solve): a fixed linear
/// operator z = M^-1 r, symmetric positive definite for CG. The paper's SSOR (section 4.3) is
/// one implementation; reference/fluid/stokes_preconditioner.hpp is the project's block
/// preconditioner of eq. (8) (docs/preconditioners.md).

#include <algorithm>
#include <cmath>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/core/enum_names.hpp"
#include "reference/solvers/linear_operator.hpp"

namespace monolith {

/// The PCG preconditioner of one of the liquid's unified solves, as the solve takes it:
/// "multigrid": the block preconditioner of eq. (8) built on the Woodbury identity and multigrid
/// V-cycles (reference/fluid/stokes_preconditioner.hpp); "ssor": the paper's SSOR of section 4.3,
/// which reproduces the paper's iteration counts. Also `solver.pressure_preconditioner`.
enum class PreconditionerKind { multigrid, ssor };

template <>
struct EnumNames<PreconditionerKind> {
  static constexpr std::array<std::pair<PreconditionerKind, const char*>, 2> values{
      {{PreconditionerKind::multigrid, "multigrid"}, {PreconditionerKind::ssor, "ssor"}}};
};

/// `solver.preconditioner` of a scene: "auto" (the default, SceneDesc's SolverSpec) picks one
/// PreconditionerKind per solve by the solve's stiffness (choose_preconditioner); "multigrid" and
/// "ssor" fix it (docs/preconditioners.md section 7).
enum class PreconditionerChoice { automatic, multigrid, ssor };

template <>
struct EnumNames<PreconditionerChoice> {
  static constexpr std::array<std::pair<PreconditionerChoice, const char*>, 3> values{
      {{PreconditionerChoice::automatic, "auto"},
       {PreconditionerChoice::multigrid, "multigrid"},
       {PreconditionerChoice::ssor, "ssor"}}};
};

/// The iteration count per solve that "auto" holds the paper's SSOR to: the goal of at
/// most 60 iterations per solve at any viscosity and grid (issue 15). The block preconditioner
/// meets it on every measured system (at most 6 per solve on the tank, 16^3-96^3 and 16^2-128^2,
/// eta 0.1-5000); SSOR only on small grids at low stiffness, where it is also the faster one
/// (its set-up is nothing; docs/preconditioners.md section 29).
constexpr int kAutoSsorIterationLimit = 60;

/// (P10) The estimated number of SSOR-PCG iterations of a unified / viscosity solve to 1e-6, from
/// the dimension, the stiffness s = eta_max dt / (rho dx^2) and the grid's largest cell count n
/// along an axis: c_d n (1 + k_d sqrt(s)), c_2 = 1.75, k_2 = 5, c_3 = 3, k_3 = 10. SSOR on the
/// pressure (Poisson) part takes about c_d n iterations (SSOR-PCG's condition number grows like
/// n^2); the stress block adds a factor that grows with the stiffness (section 2 of
/// docs/preconditioners.md). Fitted to the tank of bench_preconditioners (2D n = 16-64,
/// 3D n = 8-16, eta 0.1-1000, dt 0.01: c_d is the count at eta 0.1 divided by n, k_d bounds the
/// growth with sqrt(s) from above on the small grids where the estimate meets the limit) and
/// above the measured counts of the 3D built-in scenes at 24^3 and 64^3 (section 29), so that
/// a wrong estimate errs towards the block preconditioner.
inline double estimated_ssor_iterations(int dim, double stiffness, int cells) {
  const double c = dim == 2 ? 1.75 : 3.0, k = dim == 2 ? 5.0 : 10.0;
  return c * cells * (1.0 + k * std::sqrt(std::max(0.0, stiffness)));
}

/// The stiffness eta_max dt / (rho dx^2) of a solve: the ratio of the viscous to the inertial
/// term of the velocity operator M + dt D^T eta D at the grid scale (section 2 of
/// docs/preconditioners.md: SSOR's iteration count grows with it). eta_max the largest viscosity
/// of the solve, rho the liquid's density (the smallest one with several liquids).
inline double solve_stiffness(double eta_max, double dt, double rho, double dx) {
  return eta_max * dt / (rho * dx * dx);
}

/// The preconditioner a solve uses under `solver.preconditioner` = choice: fixed for "multigrid"
/// and "ssor"; for "auto" the paper's SSOR iff its estimated iteration count
/// (estimated_ssor_iterations; `cells` the grid's largest cell count along an axis) is within
/// kAutoSsorIterationLimit, else multigrid (the block preconditioner). The same rule in 2D and
/// 3D (docs/preconditioners.md section 29).
inline PreconditionerKind choose_preconditioner(PreconditionerChoice choice, int dim, double stiffness,
                                                int cells) {
  switch (choice) {
    case PreconditionerChoice::multigrid: return PreconditionerKind::multigrid;
    case PreconditionerChoice::ssor: return PreconditionerKind::ssor;
    case PreconditionerChoice::automatic: break;
  }
  if (estimated_ssor_iterations(dim, stiffness, cells) <= kAutoSsorIterationLimit)
    return PreconditionerKind::ssor;
  return PreconditionerKind::multigrid;
}

/// The iterations a solve preconditioned by the project's multigrid/block preconditioner may
/// take under "auto" before it is given up and solved again with the paper's SSOR, which then
/// has the full solver.max_iterations (the fallback, docs/preconditioners.md section 20): 500
/// (or max_iterations if that is smaller). The block preconditioner converges in at most 11
/// iterations on the tank sweep (16^3-96^3, eta 0.1-5000) and in about 92 per system on the
/// hardest scene measured (hollow-spheres-viscous-3d at 64^3); in the 2D contact scenes where it
/// stalls (section 20) it sits at a residual of 1e-2..1e-5 for thousands of iterations, where
/// SSOR converges in 190-380.
inline int multigrid_attempt_budget(int max_iterations) {
  return std::min(max_iterations, 500);
}

class Preconditioner {
 public:
  virtual ~Preconditioner() = default;
  /// n (the size of r and z).
  virtual int size() const = 0;
  /// z = M^-1 r (z resized to n). Must be a fixed linear map: the same r gives the same z.
  virtual void apply(const VectorX& r, VectorX& z) const = 0;
  /// A short name for reports ("ssor", "block", ...).
  virtual std::string name() const = 0;
};

/// SSOR of section 4.3: one forward then one backward SOR sweep of the operator from z = 0
/// (ssor_precondition in pcg.hpp). Holds a reference to the operator.
class SsorPreconditioner : public Preconditioner {
 public:
  SsorPreconditioner(const LinearOperator& a, double omega) : a_(a), omega_(omega) {}
  int size() const override { return a_.size(); }
  void apply(const VectorX& r, VectorX& z) const override {
    z.setZero(r.size());
    a_.forward_sweep(r, z, omega_);
    a_.backward_sweep(r, z, omega_);
  }
  std::string name() const override { return "ssor"; }

 private:
  const LinearOperator& a_;
  double omega_;
};

/// A preconditioner built on its first application: `make` runs (once) only when a solver
/// actually needs M^-1, so a solve that stops before its first iteration (zero right-hand side,
/// or a warm start that already meets the tolerance) pays nothing for an expensive set-up
/// (the multigrid hierarchy of reference/fluid/stokes_preconditioner.hpp costs seconds at 64^3).
/// Not thread-safe on the first call (the solvers apply it from one thread).
class LazyPreconditioner : public Preconditioner {
 public:
  using Factory = std::function<std::unique_ptr<Preconditioner>()>;
  LazyPreconditioner(int n, std::string name, Factory make)
      : n_(n), name_(std::move(name)), make_(std::move(make)) {}
  int size() const override { return n_; }
  void apply(const VectorX& r, VectorX& z) const override {
    if (!built_) built_ = make_();
    built_->apply(r, z);
  }
  std::string name() const override { return name_; }
  /// The preconditioner once built (nullptr before the first apply).
  const Preconditioner* built() const { return built_.get(); }

 private:
  int n_;
  std::string name_;
  Factory make_;
  mutable std::unique_ptr<Preconditioner> built_;
};

/// No preconditioning: z = r.
class IdentityPreconditioner : public Preconditioner {
 public:
  explicit IdentityPreconditioner(int n) : n_(n) {}
  int size() const override { return n_; }
  void apply(const VectorX& r, VectorX& z) const override { z = r; }
  std::string name() const override { return "none"; }

 private:
  int n_;
};

}  // namespace monolith
