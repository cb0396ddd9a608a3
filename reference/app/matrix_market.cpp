/// \file matrix_market.cpp
/// The Matrix Market writer and reader of matrix_market.hpp.

#include "reference/app/matrix_market.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace monolith {

namespace {

/// One value with 17 significant digits.
void put(std::string& out, double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.16e", v);
  out += buf;
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  if (!f) throw std::runtime_error(path + ": cannot open for writing");
  f.write(text.data(), static_cast<std::streamsize>(text.size()));
  f.close();
  if (!f) throw std::runtime_error(path + ": write failed (disk full or not writable?)");
}

std::string header(const char* layout, const std::vector<std::string>& comments) {
  std::string out = std::string("%%MatrixMarket matrix ") + layout + " real general\n";
  for (const auto& c : comments) out += "% " + c + "\n";
  return out;
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

/// The lines of a Matrix Market file after its header and comments.
struct MarketFile {
  std::string path, layout, symmetry;
  std::vector<std::string> lines;  ///< data lines (blank ones dropped)
  std::vector<int> numbers;        ///< their line numbers in the file
  [[noreturn]] void fail(int line, const std::string& what) const {
    throw std::runtime_error(path + ":" + std::to_string(line) + ": " + what);
  }
};

MarketFile read_file(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error(path + ": cannot open (a Matrix Market file)");
  MarketFile m;
  m.path = path;
  std::string line;
  if (!std::getline(f, line)) m.fail(1, "empty file (a Matrix Market file starts with %%MatrixMarket)");
  std::istringstream h(line);
  std::string banner, object, layout, field, symmetry;
  h >> banner >> object >> layout >> field >> symmetry;
  if (banner != "%%MatrixMarket" || lower(object) != "matrix")
    m.fail(1, "not a Matrix Market header (expected \"%%MatrixMarket matrix coordinate|array real general\")");
  m.layout = lower(layout);
  m.symmetry = lower(symmetry);
  if (m.layout != "coordinate" && m.layout != "array")
    m.fail(1, "layout \"" + layout + "\" (coordinate or array allowed)");
  if (lower(field) != "real" && lower(field) != "double" && lower(field) != "integer")
    m.fail(1, "field \"" + field + "\" (real allowed)");
  if (m.symmetry != "general" && !(m.layout == "coordinate" && m.symmetry == "symmetric"))
    m.fail(1, "symmetry \"" + symmetry + "\" (general allowed; symmetric for coordinate)");
  int number = 1;
  while (std::getline(f, line)) {
    ++number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '%') continue;
    if (line.find_first_not_of(" \t") == std::string::npos) continue;
    m.lines.push_back(line);
    m.numbers.push_back(number);
  }
  if (m.lines.empty()) m.fail(number, "no size line");
  return m;
}

/// Parses `count` integers then `reals` doubles from a line; false if the line holds anything
/// else.
bool parse_line(const std::string& line, int count, long long* ints, int reals, double* values) {
  const char* p = line.c_str();
  char* end = nullptr;
  for (int i = 0; i < count; ++i) {
    errno = 0;
    ints[i] = std::strtoll(p, &end, 10);
    if (end == p || errno) return false;
    p = end;
  }
  for (int i = 0; i < reals; ++i) {
    errno = 0;
    values[i] = std::strtod(p, &end);
    if (end == p || errno == ERANGE || !std::isfinite(values[i])) return false;
    p = end;
  }
  while (*p == ' ' || *p == '\t') ++p;
  return *p == '\0';
}

}  // namespace

void write_market_matrix(const std::string& path, const SparseMatrix& m,
                         const std::vector<std::string>& comments) {
  std::string out = header("coordinate", comments);
  out += std::to_string(m.rows()) + " " + std::to_string(m.cols()) + " " + std::to_string(m.nonZeros()) + "\n";
  for (int k = 0; k < m.outerSize(); ++k)
    for (SparseMatrix::InnerIterator it(m, k); it; ++it) {
      out += std::to_string(it.row() + 1) + " " + std::to_string(it.col() + 1) + " ";
      put(out, it.value());
      out += "\n";
    }
  write_text(path, out);
}

void write_market_vector(const std::string& path, const VectorX& v,
                         const std::vector<std::string>& comments) {
  std::string out = header("array", comments);
  out += std::to_string(v.size()) + " 1\n";
  for (int i = 0; i < v.size(); ++i) {
    put(out, v[i]);
    out += "\n";
  }
  write_text(path, out);
}

SparseMatrix read_market_matrix(const std::string& path) {
  const MarketFile f = read_file(path);
  if (f.layout != "coordinate") f.fail(1, "an array (dense) file where a coordinate (sparse) matrix is expected");
  long long size[3];
  if (!parse_line(f.lines[0], 3, size, 0, nullptr) || size[0] < 0 || size[1] < 0 || size[2] < 0 ||
      size[0] > 2000000000LL || size[1] > 2000000000LL)
    f.fail(f.numbers[0], "bad size line \"" + f.lines[0].substr(0, 60) + "\" (rows columns entries)");
  const long long entries = static_cast<long long>(f.lines.size()) - 1;
  if (entries != size[2])
    f.fail(f.numbers.back(), std::to_string(entries) + " entries, the size line says " + std::to_string(size[2]));
  std::vector<Triplet> t;
  t.reserve(static_cast<std::size_t>(entries) * (f.symmetry == "symmetric" ? 2 : 1));
  for (std::size_t k = 1; k < f.lines.size(); ++k) {
    long long ij[2];
    double v = 0.0;
    if (!parse_line(f.lines[k], 2, ij, 1, &v))
      f.fail(f.numbers[k], "garbled entry \"" + f.lines[k].substr(0, 60) + "\" (row column value, a finite real)");
    if (ij[0] < 1 || ij[0] > size[0] || ij[1] < 1 || ij[1] > size[1])
      f.fail(f.numbers[k], "entry (" + std::to_string(ij[0]) + ", " + std::to_string(ij[1]) + ") outside the " +
                               std::to_string(size[0]) + " x " + std::to_string(size[1]) + " matrix");
    t.emplace_back(static_cast<int>(ij[0] - 1), static_cast<int>(ij[1] - 1), v);
    if (f.symmetry == "symmetric" && ij[0] != ij[1])
      t.emplace_back(static_cast<int>(ij[1] - 1), static_cast<int>(ij[0] - 1), v);
  }
  SparseMatrix m(size[0], size[1]);
  m.setFromTriplets(t.begin(), t.end());
  return m;
}

VectorX read_market_vector(const std::string& path) {
  const MarketFile f = read_file(path);
  if (f.layout == "coordinate") {
    const SparseMatrix m = read_market_matrix(path);
    if (m.cols() != 1) f.fail(1, "a " + std::to_string(m.rows()) + " x " + std::to_string(m.cols()) + " matrix where a vector (n x 1) is expected");
    return VectorX(m.col(0));
  }
  long long size[2];
  if (!parse_line(f.lines[0], 2, size, 0, nullptr) || size[0] < 0 || size[0] > 2000000000LL)
    f.fail(f.numbers[0], "bad size line \"" + f.lines[0].substr(0, 60) + "\" (rows 1)");
  if (size[1] != 1)
    f.fail(f.numbers[0], "a " + std::to_string(size[0]) + " x " + std::to_string(size[1]) + " array where a vector (n x 1) is expected");
  const long long values = static_cast<long long>(f.lines.size()) - 1;
  if (values != size[0])
    f.fail(f.numbers.back(), std::to_string(values) + " values, the size line says " + std::to_string(size[0]));
  VectorX v(size[0]);
  for (long long k = 0; k < size[0]; ++k)
    if (!parse_line(f.lines[k + 1], 0, nullptr, 1, &v[k]))
      f.fail(f.numbers[k + 1], "garbled value \"" + f.lines[k + 1].substr(0, 60) + "\" (one finite real a line)");
  return v;
}

}  // namespace monolith
