#pragma once
/// \file stage_variants.hpp
/// What the measurement programs that run a scene once per variant of the step share
/// (bench_still_water, bench_floating_rest, bench_energy_regain): a variant switches stages of the
/// step off or replaces them (StageSwitches), `--only` picks variants by name, every run keeps the
/// energy ledger (Simulation::energy_ledger), and the mechanical energy and the ledger's sums are
/// read the same way (tests/support/still_water.hpp's tests read them so too).

#include <algorithm>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "reference/sim/simulation.hpp"

namespace monolith::bench {

/// One run of a measurement program: a name for `--only` and the output, what it changes (for
/// the reader of the list; may be empty), and the switches it sets.
struct StageVariant {
  std::string name;
  std::string what;
  std::function<void(StageSwitches&)> apply;

  StageVariant(std::string n, std::function<void(StageSwitches&)> f)
      : name(std::move(n)), apply(std::move(f)) {}
  StageVariant(std::string n, std::string w, std::function<void(StageSwitches&)> f)
      : name(std::move(n)), what(std::move(w)), apply(std::move(f)) {}

  /// Whether `--only` picks this variant (an empty list picks every one).
  bool selected(const std::vector<std::string>& only) const {
    return only.empty() || std::find(only.begin(), only.end(), name) != only.end();
  }
  /// The variant's switches, with the energy ledger on.
  StageSwitches switches() const {
    StageSwitches s;
    s.energy_ledger = true;
    apply(s);
    return s;
  }
};

/// Kinetic + potential energy of the liquid and the bodies in one frame's statistics (J; 2D: J
/// per metre of depth).
inline double mechanical_energy(const FrameStats& s) {
  return s.kinetic_energy_liquid + s.kinetic_energy_bodies + s.potential_energy_liquid +
         s.potential_energy_bodies;
}

/// Adds one frame's energy ledger (Simulation::energy_ledger) to a running sum, stage by stage.
inline void accumulate(EnergyLedger& sum, const EnergyLedger& l) {
  sum.to_grid += l.to_grid;
  sum.forces_and_solve += l.forces_and_solve;
  sum.velocity_extension += l.velocity_extension;
  sum.to_particles += l.to_particles;
  sum.advection += l.advection;
  sum.position_correction += l.position_correction;
  sum.density_projection += l.density_projection;
}

/// The value of a `--pay-line15` flag: free, balance, local (Line15Energy::balance_local) or
/// per-step (anything else), read once.
inline Line15Energy line15_energy(const std::string& value) {
  if (value == "free") return Line15Energy::free;
  if (value == "balance") return Line15Energy::balance;
  if (value == "local") return Line15Energy::balance_local;
  return Line15Energy::per_step;
}

}  // namespace monolith::bench
