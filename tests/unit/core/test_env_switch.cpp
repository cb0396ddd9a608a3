// env_switch (core/env_switch.hpp) and the three process-wide switches that use it: each reads
// its own variable once, and only the one value that flips its default flips it.
#include <catch2/catch.hpp>

#include <atomic>
#include <cstdlib>
#include <string>

#include "reference/core/env_switch.hpp"
#include "reference/core/first_touch.hpp"
#include "reference/core/huge_pages.hpp"
#include "reference/core/parallel.hpp"

using namespace monolith;

namespace {

/// The switch `query` decides with `name` set to `value` (unset when null), read afresh (flag
/// -1); the variable and the flag's decision are put back after.
template <class Query>
bool decided_by(std::atomic<int>& flag, const char* name, const char* value, Query query) {
  const char* env = std::getenv(name);
  const std::string saved = env ? env : "";
  const int was = flag.load();
  if (value)
    setenv(name, value, 1);
  else
    unsetenv(name);
  flag.store(-1);  // undecided: read the environment again
  const bool on = query();
  if (env)
    setenv(name, saved.c_str(), 1);
  else
    unsetenv(name);
  flag.store(was);
  return on;
}

}  // namespace

TEST_CASE("env_switch: a default-on switch is turned off by exactly \"0\", a default-off one on "
          "by exactly \"1\"; the first answer stays", "[unit]") {
  std::atomic<int> flag{-1};
  const char* name = "MONOLITH_TEST_ENV_SWITCH";
  const auto on_by_default = [&] { return env_switch(flag, name, true); };
  const auto off_by_default = [&] { return env_switch(flag, name, false); };
  CHECK(decided_by(flag, name, nullptr, on_by_default));
  CHECK_FALSE(decided_by(flag, name, "0", on_by_default));
  CHECK(decided_by(flag, name, "1", on_by_default));
  CHECK(decided_by(flag, name, "no", on_by_default));
  CHECK_FALSE(decided_by(flag, name, nullptr, off_by_default));
  CHECK(decided_by(flag, name, "1", off_by_default));
  CHECK_FALSE(decided_by(flag, name, "0", off_by_default));
  CHECK_FALSE(decided_by(flag, name, "yes", off_by_default));
  // decided once: a later change of the variable does not change the answer
  flag.store(-1);
  setenv(name, "0", 1);
  CHECK_FALSE(env_switch(flag, name, true));
  unsetenv(name);
  CHECK_FALSE(env_switch(flag, name, true));
  // a set_... decision before the first question wins over the environment
  flag.store(1);
  setenv(name, "0", 1);
  CHECK(env_switch(flag, name, true));
  unsetenv(name);
}

TEST_CASE("the process switches read their own variables: MONOLITH_POPULATE=0 (kern25), "
          "MONOLITH_HUGE_PAGES=1 (opt-in), MONOLITH_ADAPTIVE_THREADS=0", "[unit]") {
  CHECK(decided_by(populate_flag(), "MONOLITH_POPULATE", nullptr, populate_enabled));
  CHECK_FALSE(decided_by(populate_flag(), "MONOLITH_POPULATE", "0", populate_enabled));
  CHECK_FALSE(decided_by(huge_pages_flag(), "MONOLITH_HUGE_PAGES", nullptr, huge_pages_enabled));
  CHECK(decided_by(huge_pages_flag(), "MONOLITH_HUGE_PAGES", "1", huge_pages_enabled));
  CHECK(decided_by(adaptive_teams_flag(), "MONOLITH_ADAPTIVE_THREADS", nullptr, adaptive_teams));
  CHECK_FALSE(decided_by(adaptive_teams_flag(), "MONOLITH_ADAPTIVE_THREADS", "0", adaptive_teams));
  CHECK_FALSE(decided_by(core_monitor_flag(), "MONOLITH_ADAPTIVE_THREADS", "0", core_monitor));
}
