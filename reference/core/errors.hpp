#pragma once
/// \file errors.hpp
/// The two kinds of failure the CLI distinguishes (docs/cli.md): invalid input (exit 2) and a
/// simulation that breaks down (exit 3). Anything else escaping to main() is a bug.

#include <stdexcept>
#include <string>
#include <vector>

namespace monolith {

/// Invalid input: a bad scene, a bad flag, an unreadable or malformed file, or a scene that asks
/// for physics this build does not support yet. Each entry of `problems` is one line of the form
/// `FILE: KEY.PATH: what is wrong (what is allowed)`. The CLI exits with code 2.
class InputError : public std::runtime_error {
 public:
  explicit InputError(const std::string& problem)
      : std::runtime_error(problem), problems_{problem} {}
  explicit InputError(std::vector<std::string> problems)
      : std::runtime_error(problems.empty() ? std::string("invalid input") : problems.front()),
        problems_(std::move(problems)) {}
  const std::vector<std::string>& problems() const { return problems_; }

 private:
  std::vector<std::string> problems_;
};

/// The simulation produced a non-finite state or a solver broke down. The CLI writes everything
/// produced so far and exits with code 3.
class SimulationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace monolith
