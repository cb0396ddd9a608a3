#pragma once
/// \file cli.hpp
/// The command line of docs/cli.md: `monolith run | check | list | --help | --version`.

#include <ostream>
#include <string>
#include <vector>

namespace monolith {

/// Runs the CLI with args (without the program name); writes normal output to out and errors
/// and progress to err. Returns the exit code: 0 success, 2 invalid input, 3 simulation failure.
int run_cli(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

}  // namespace monolith
