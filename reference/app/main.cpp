// The `monolith` command: see docs/cli.md.
#include <iostream>

#include "reference/app/cli.hpp"
#include "reference/core/parallel.hpp"

int main(int argc, char** argv) {
  // GNU OpenMP reads its wait policy when it loads: set a short spin and re-execute once
  // (reference/core/parallel.hpp, docs/cli.md "Threads")
  monolith::apply_default_wait_policy(argv);
  std::vector<std::string> args(argv + 1, argv + argc);
  return monolith::run_cli(args, std::cout, std::cerr);
}
