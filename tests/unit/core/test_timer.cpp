// The timing facility (reference/core/timer.hpp): a ScopedTimer adds the wall time of its scope
// to its accumulator (at least the time slept inside it: the steady clock never runs slow), two
// scopes on one phase add up, and the phases of a TimingTable are independent and start at zero.
#include <catch2/catch.hpp>

#include <chrono>
#include <thread>

#include "reference/core/timer.hpp"
#include "reference/sim/frame_stats.hpp"

using namespace monolith;

TEST_CASE("ScopedTimer fills one phase of a TimingTable and adds up", "[unit]") {
  using namespace std::chrono_literals;
  TimingTable<FramePhase> table;
  CHECK(table[FramePhase::total] == 0.0);
  CHECK(table[FramePhase::solve] == 0.0);
  {
    ScopedTimer timer(table[FramePhase::solve]);
    std::this_thread::sleep_for(20ms);
    CHECK(timer.seconds() >= 0.02);
    CHECK(table[FramePhase::solve] == 0.0);  // added when the scope ends
  }
  const double first = table[FramePhase::solve];
  CHECK(first >= 0.02);
  {
    ScopedTimer timer(table[FramePhase::solve]);
    std::this_thread::sleep_for(10ms);
  }
  CHECK(table[FramePhase::solve] >= first + 0.01);
  CHECK(table[FramePhase::total] == 0.0);  // the other phase is untouched
  // a copy is a snapshot (FrameStats is returned by value)
  const TimingTable<FramePhase> copy = table;
  table[FramePhase::total] = 1.5;
  CHECK(copy[FramePhase::total] == 0.0);
}

TEST_CASE("Stopwatch measures from construction or restart", "[unit]") {
  using namespace std::chrono_literals;
  Stopwatch watch;
  std::this_thread::sleep_for(10ms);
  const double before = watch.seconds();
  CHECK(before >= 0.01);
  watch.restart();
  const double after = watch.seconds();  // counting again from zero
  CHECK(after >= 0.0);
  CHECK(after < before);
}
