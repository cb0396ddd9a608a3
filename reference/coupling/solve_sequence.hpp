#pragma once
/// \file solve_sequence.hpp
/// Lines 7-11 of Algorithm 1 as the list of solves a coupling scheme runs (section 6), written
/// once for liquids with and without moving bodies: the pressure solve alone, the unified
/// pressure-viscosity solve, or the PC-VC-PC sequence of section 6.2 (pressure, viscosity with
/// stress unknowns only, pressure again), with Algorithm 2 (section 5) around the viscous solve
/// for non-Newtonian liquids. What one solve is differs by caller (Simulation's liquid-only
/// solves of eq. (8) by PCG, solve_coupled_step's MonolithicSystem solves of eq. (24)), so the
/// dispatcher takes the stages as callables.

#include <algorithm>
#include <cstring>
#include <functional>

#include "reference/core/common.hpp"
#include "reference/coupling/coupling_scheme.hpp"

namespace monolith {

/// The solves of lines 7-11 of Algorithm 1.
enum class SolveSequence {
  pressure,   ///< the pressure (or pressure-contact) solve alone, no stress unknowns
  unified,    ///< eq. (8) / (24) in (tau, p) together, reduced stress
  decoupled,  ///< section 6.2: pressure, then stress only (p = 0), then pressure again
};

/// The sequence of `scheme`: P-C, C-P, PC-iterative, PC-unified -> pressure (viscosity ignored);
/// PV-C, C-PV, PVC-iterative, PVC-unified -> unified; PC-VC-PC-unified -> decoupled. Without
/// viscous liquid (`viscous` false) always pressure.
inline SolveSequence solve_sequence(CouplingScheme scheme, bool viscous) {
  // without viscous liquid (or under a scheme that leaves viscosity out) there are no stress
  // unknowns: every scheme is the pressure solve
  if (!viscous || !scheme_uses_viscosity(scheme)) return SolveSequence::pressure;
  if (scheme == CouplingScheme::pc_vc_pc_unified) return SolveSequence::decoupled;
  return SolveSequence::unified;
}

/// Which solve of a sequence a stage callable is asked for (names the solve in messages and
/// tells the caller where to book its statistics).
enum class SolveStage { pressure, unified, first_pressure, viscosity, second_pressure };

inline const char* solve_stage_name(SolveStage s) {
  switch (s) {
    case SolveStage::pressure: return "pressure";
    case SolveStage::unified: return "Stokes";
    case SolveStage::first_pressure: return "first pressure";
    case SolveStage::viscosity: return "viscosity";
    case SolveStage::second_pressure: return "second pressure";
  }
  return "?";
}

/// The viscosity of the viscous solve (the unified solve, or the VC solve of PC-VC-PC).
/// Newtonian (no callables): one solve with the liquids' own eta. Algorithm 2 (section 5, lines
/// 1-6): eta^1 = initial(u) of the velocities the solve starts from, then `rounds` times (solve
/// with eta^k from the same start, eta^(k+1) = update(tau, eta^k)), so the step ends with tau,
/// p optimal for the last viscosity.
struct ViscosityRounds {
  std::function<VectorX(const VectorX& u_start)> initial;
  std::function<VectorX(const VectorX& stress, const VectorX& viscosity)> update;
  int rounds = 1;
  /// (P13) A round whose viscosity has the previous round's bits is not solved again: it would
  /// build the same system from the same state, and a solve that is deterministic and starts
  /// from that state alone (not from the previous round's result) returns the same result. Such
  /// are a herschel-bulkley liquid with n = 1 and tau0 = 0 (eta does not depend on the rate) and
  /// a round that met the fixed point exactly. The update still runs after it (its residual is
  /// recorded as before). solve_coupled_step sets it (docs/preconditioners.md section 32).
  bool skip_repeated = false;
  bool non_newtonian() const { return initial && update; }
};

/// The viscous solve of a sequence under `viscosity`: solve(from, eta) with eta null for the
/// liquids' own viscosity. Returns the state of the last solve.
template <class State, class Solve>
State viscous_rounds(const ViscosityRounds& viscosity, const State& from, Solve solve) {
  if (!viscosity.non_newtonian()) return solve(from, static_cast<const VectorX*>(nullptr));
  VectorX eta = viscosity.initial(from.u);
  VectorX solved;  // (skip_repeated) the viscosity of the last solve
  State out;
  for (int k = 0; k < std::max(1, viscosity.rounds); ++k) {
    const bool repeated = k > 0 && viscosity.skip_repeated && solved.size() == eta.size() &&
                          std::memcmp(solved.data(), eta.data(), sizeof(double) * static_cast<std::size_t>(eta.size())) == 0;
    if (!repeated) out = solve(from, &eta);
    VectorX next = viscosity.update(out.stress, eta);
    if (viscosity.skip_repeated) solved.swap(eta);
    eta.swap(next);
  }
  return out;
}

/// Runs `sequence` from `start`. State holds at least u (face velocities), pressure (cell
/// pressures) and stress (all stress components). pressure(from, stage) is the inviscid solve
/// (stage pressure, first_pressure or second_pressure), unified(from, eta) the solve in (tau, p),
/// viscous(from, eta) the stress-only solve with p fixed at zero (eta null: the liquids' own
/// viscosity). The decoupled sequence of section 6.2 returns the last pressure solve's state with
/// pressure = p1 + p3 and stress = tau2.
template <class State, class Pressure, class Unified, class Viscous>
State run_solve_sequence(SolveSequence sequence, const State& start,
                         const ViscosityRounds& viscosity, Pressure pressure, Unified unified,
                         Viscous viscous) {
  switch (sequence) {
    case SolveSequence::pressure:
      return pressure(start, SolveStage::pressure);
    case SolveSequence::unified:
      return viscous_rounds(viscosity, start, unified);
    case SolveSequence::decoupled:
      break;
  }
  const State first = pressure(start, SolveStage::first_pressure);
  const State second = viscous_rounds(viscosity, first, viscous);
  State third = pressure(second, SolveStage::second_pressure);
  third.pressure = first.pressure + third.pressure;
  third.stress = second.stress;
  return third;
}

}  // namespace monolith
