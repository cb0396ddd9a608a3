#pragma once
/// \file env_switch.hpp
/// A process-wide on/off switch that the environment decides the first time it is asked, unless
/// the program decided it before (the set_... functions of parallel.hpp, huge_pages.hpp and
/// first_touch.hpp store 0 or 1 into the flag first).

#include <atomic>
#include <cstdlib>
#include <cstring>

namespace monolith {

/// The switch held in `flag` (-1: not decided yet, then 0 off or 1 on). Undecided, it reads the
/// environment variable `name`: a switch on by default is turned off by exactly "0", one off by
/// default is turned on by exactly "1"; any other value, or none, leaves the default.
inline bool env_switch(std::atomic<int>& flag, const char* name, bool default_on) {
  int f = flag.load(std::memory_order_relaxed);
  if (f < 0) {
    const char* value = std::getenv(name);
    const bool flipped = value && std::strcmp(value, default_on ? "0" : "1") == 0;
    f = (default_on != flipped) ? 1 : 0;
    flag.store(f, std::memory_order_relaxed);
  }
  return f == 1;
}

}  // namespace monolith
