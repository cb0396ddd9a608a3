#pragma once
/// \file notebook.hpp
/// The tiny harness every notebook uses: Markdown transcript to stdout and DIR/transcript.md,
/// checks that are printed with their numbers and counted, PPM figures into DIR, and an exit code
/// that is non-zero if any check failed. Usage: notebook_NN [--out DIR].

#include <Eigen/Core>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>

#include "reference/viz/image.hpp"

namespace notebook {

class Notebook {
 public:
  Notebook(int argc, char** argv, const std::string& title) {
    dir_ = "notebook_out";
    for (int i = 1; i + 1 < argc; ++i)
      if (std::string(argv[i]) == "--out") dir_ = argv[i + 1];
    std::filesystem::create_directories(dir_);
    file_.open(dir_ / "transcript.md");
    md("# " + title + "\n");
  }
  /// Appends Markdown text (a paragraph).
  void md(const std::string& text) { emit(text + "\n"); }
  /// A matrix as a Markdown table with the given number of decimals.
  void matrix(const std::string& caption, const Eigen::MatrixXd& m, int decimals = 3) {
    std::ostringstream s;
    s << "*" << caption << "* (" << m.rows() << " x " << m.cols() << ")\n\n|";
    for (int j = 0; j < m.cols(); ++j) s << " " << j << " |";
    s << "\n|";
    for (int j = 0; j < m.cols(); ++j) s << "---|";
    s << "\n";
    for (int i = 0; i < m.rows(); ++i) {
      s << "|";
      for (int j = 0; j < m.cols(); ++j) s << " " << std::fixed << std::setprecision(decimals) << m(i, j) << " |";
      s << "\n";
    }
    emit(s.str());
  }
  /// A checked identity: prints the measured value against its bound and counts failures.
  void check(const std::string& what, double value, double bound) {
    const bool ok = std::isfinite(value) && value <= bound;
    std::ostringstream s;
    s << "- check: " << what << ": " << std::scientific << std::setprecision(3) << value
      << " <= " << bound << " ... " << (ok ? "ok" : "FAILED") << "\n";
    emit(s.str());
    failures_ += ok ? 0 : 1;
    ++checks_;
  }
  void check_true(const std::string& what, bool ok) {
    emit("- check: " + what + " ... " + (ok ? "ok" : "FAILED") + "\n");
    failures_ += ok ? 0 : 1;
    ++checks_;
  }
  /// Writes a figure into the output folder and links it from the transcript.
  void figure(const std::string& name, const monolith::Image& image, const std::string& caption) {
    image.write_ppm((dir_ / name).string());
    emit("![" + caption + "](" + name + ")\n");
  }
  /// Closing line and exit code.
  int finish() {
    std::ostringstream s;
    s << "\n" << (checks_ - failures_) << " passed, " << failures_ << " failed\n";
    emit(s.str());
    return failures_ == 0 ? 0 : 1;
  }

 private:
  void emit(const std::string& text) {
    std::cout << text << "\n";
    file_ << text << "\n";
  }
  std::filesystem::path dir_;
  std::ofstream file_;
  int checks_ = 0, failures_ = 0;
};

}  // namespace notebook
