#pragma once
/// \file matrix_market.hpp
/// Matrix Market files (the NIST format that scipy.io.mmread, MATLAB, Julia's MatrixMarket.jl,
/// PETSc and Eigen read) for the oracle's export and verify (docs/oracle.md):
///   matrices: "%%MatrixMarket matrix coordinate real general", 1-based (row, column, value)
///             triplets in column-major order;
///   vectors:  "%%MatrixMarket matrix array real general", size n x 1, one value a line;
/// values with 17 significant digits (%.16e), so reading a file back gives every double bit for
/// bit. Written here rather than with Eigen's unsupported SparseExtra (saveMarket /
/// loadMarket): Eigen 3.4's writer puts two spaces after "coordinate" in the header and 18
/// significant digits, does not report a failed write, and its reader reports bad input on
/// stderr / by assertion instead of naming the line that is wrong.

#include <string>
#include <vector>

#include "reference/core/common.hpp"

namespace monolith {

/// Writes `m`; `comments` become "% ..." lines after the header. Throws std::runtime_error
/// naming the path when the file cannot be written.
void write_market_matrix(const std::string& path, const SparseMatrix& m,
                         const std::vector<std::string>& comments = {});
void write_market_vector(const std::string& path, const VectorX& v,
                         const std::vector<std::string>& comments = {});

/// Reads a coordinate real general matrix (also "symmetric", mirrored). Throws
/// std::runtime_error "PATH:LINE: what is wrong (what is allowed)" on a missing file, a wrong
/// header, a bad size line, a garbled or out-of-range entry, a missing or extra entry.
SparseMatrix read_market_matrix(const std::string& path);
/// Reads an array real general n x 1 vector (also a coordinate n x 1 matrix, as some writers
/// store vectors); errors as read_market_matrix.
VectorX read_market_vector(const std::string& path);

}  // namespace monolith
