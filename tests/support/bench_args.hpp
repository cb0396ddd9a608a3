#pragma once
/// \file bench_args.hpp
/// Command-line walking for the benchmark programs (tests/bench), so that each one lists only its
/// own flags:
///
///     BenchArgs args(argc, argv);
///     while (args.next()) {
///       if (args.flag() == "--cells") cells = std::atoi(args.value().c_str());
///       else if (args.flag() == "--only") only = args.list();
///       else return usage();
///     }
///
/// A flag whose value is missing stops the program with exit code 2 and "<flag> needs a value".

#include <cstdlib>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

namespace monolith::bench {

class BenchArgs {
 public:
  BenchArgs(int argc, char** argv) : argc_(argc), argv_(argv) {}

  /// Moves to the next argument; false after the last one.
  bool next() {
    if (++i_ >= argc_) return false;
    flag_ = argv_[i_];
    return true;
  }
  /// The current argument.
  const std::string& flag() const { return flag_; }
  /// The argument after the current flag (consumed).
  std::string value() {
    if (i_ + 1 >= argc_) {
      std::cerr << flag_ << " needs a value\n";
      std::exit(2);
    }
    return argv_[++i_];
  }
  /// The value split at commas ("a,b,c").
  std::vector<std::string> list() {
    std::vector<std::string> items;
    std::stringstream text(value());
    for (std::string item; std::getline(text, item, ',');) items.push_back(item);
    return items;
  }

 private:
  int argc_;
  char** argv_;
  int i_ = 0;
  std::string flag_;
};

}  // namespace monolith::bench
