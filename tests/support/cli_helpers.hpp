#pragma once
/// \file cli_helpers.hpp
/// The command line run in-process with its exit code and both output streams captured, for the
/// tests of reference/app (tests/unit/app).
#include <sstream>
#include <string>
#include <vector>

#include "reference/app/cli.hpp"

namespace monolith::test {

struct CliResult {
  int code;
  std::string out, err;
};

/// run_cli(args) with stdout and stderr captured.
inline CliResult cli(const std::vector<std::string>& args) {
  std::ostringstream out, err;
  const int code = run_cli(args, out, err);
  return {code, out.str(), err.str()};
}

}  // namespace monolith::test
