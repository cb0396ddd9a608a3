// The `monolith` command: see docs/cli.md.
#include <iostream>

#include "reference/app/cli.hpp"

int main(int argc, char** argv) {
  std::vector<std::string> args(argv + 1, argv + argc);
  return monolith::run_cli(args, std::cout, std::cerr);
}
