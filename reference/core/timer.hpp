#pragma once
/// \file timer.hpp
/// Wall-clock timing as a facility rather than inline clock arithmetic: a Stopwatch, a
/// ScopedTimer that adds the wall time of its scope to an accumulator, and TimingTable, the
/// seconds per named phase (an enum with EnumNames) that a frame fills (FrameStats::timing, the
/// `timing` object of stats.jsonl). Timings are measurements, never inputs to the numerics.

#include <array>
#include <chrono>

#include "reference/core/enum_names.hpp"

namespace monolith {

/// Seconds of wall time since construction or the last restart (steady clock).
class Stopwatch {
 public:
  Stopwatch() : start_(Clock::now()) {}
  double seconds() const { return std::chrono::duration<double>(Clock::now() - start_).count(); }
  void restart() { start_ = Clock::now(); }

 private:
  using Clock = std::chrono::steady_clock;
  Clock::time_point start_;
};

/// Adds the wall time from its construction to its destruction to `accumulator`, e.g.
///   { ScopedTimer timer(stats.timing[FramePhase::solve]); ... the solve ... }
/// seconds() reads the time so far (for a second accumulator of the same span).
class ScopedTimer {
 public:
  explicit ScopedTimer(double& accumulator) : accumulator_(accumulator) {}
  ~ScopedTimer() { accumulator_ += watch_.seconds(); }
  ScopedTimer(const ScopedTimer&) = delete;
  ScopedTimer& operator=(const ScopedTimer&) = delete;
  double seconds() const { return watch_.seconds(); }

 private:
  double& accumulator_;
  Stopwatch watch_;
};

/// Seconds per phase of the enum Phase (which specialises EnumNames: the phases and their output
/// names). A new phase is one enumerator and its name; writers loop over enum_values<Phase>().
template <class Phase>
class TimingTable {
 public:
  double& operator[](Phase phase) { return seconds_[enum_index(phase)]; }
  double operator[](Phase phase) const { return seconds_[enum_index(phase)]; }

 private:
  std::array<double, enum_count<Phase>()> seconds_{};
};

}  // namespace monolith
