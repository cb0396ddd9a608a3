#pragma once
/// \file preconditioner.hpp
/// The preconditioner interface of the Krylov solvers (pcg_solve, mprgp_solve): a fixed linear
/// operator z = M^-1 r, symmetric positive definite for CG. The paper's SSOR (section 4.3) is
/// one implementation; reference/fluid/stokes_preconditioner.hpp is the project's block
/// preconditioner of eq. (8) (docs/preconditioners.md).

#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/core/enum_names.hpp"
#include "reference/solvers/linear_operator.hpp"

namespace monolith {

/// `solver.preconditioner` of a scene: the PCG preconditioner of the liquid's unified solves.
/// "multigrid" (the default, SceneDesc's SolverSpec): the block preconditioner of eq. (8) built
/// on the Woodbury identity and multigrid V-cycles (reference/fluid/stokes_preconditioner.hpp);
/// "ssor": the paper's SSOR of section 4.3, which reproduces the paper's iteration counts.
enum class PreconditionerKind { multigrid, ssor };

template <>
struct EnumNames<PreconditionerKind> {
  static constexpr std::array<std::pair<PreconditionerKind, const char*>, 2> values{
      {{PreconditionerKind::multigrid, "multigrid"}, {PreconditionerKind::ssor, "ssor"}}};
};

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
