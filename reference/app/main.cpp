// The `monolith` command: see docs/cli.md.
#include <iostream>

#include "reference/app/cli.hpp"
#include "reference/core/memory_policy.hpp"
#include "reference/core/parallel.hpp"

int main(int argc, char** argv) {
  // GNU OpenMP reads its wait policy when it loads: set a short spin and re-execute once
  // (reference/core/parallel.hpp, docs/cli.md "Threads")
  monolith::apply_default_wait_policy(argv);
  // freed grid-sized blocks stay in the heap for the next step (reference/core/memory_policy.hpp)
  monolith::keep_freed_memory_for_reuse();
  std::vector<std::string> args(argv + 1, argv + argc);
  return monolith::run_cli(args, std::cout, std::cerr);
}
