#pragma once
/// \file row_sums.hpp
/// Row sums of a compressed row-major sparse matrix, several rows side by side. A row's sum
/// s = s0 -/+ sum_q a_q x_{j_q} is a chain of dependent additions: its latency (not the loads)
/// bounds a loop that finishes one row before it starts the next, and on the finest velocity
/// level of the block preconditioner (about 15 terms per row) the loop exit of every row stands
/// between two chains. Advancing four rows together over their common length gives the processor
/// four independent chains in one loop; each row still adds its terms one after the other in
/// its stored order, starting from the same s0: the operations of the plain row loop, hence the
/// same bits (no reassociation; docs/preconditioners.md section 28).

#include <algorithm>
#include <array>

#include "reference/core/parallel.hpp"

namespace monolith {

/// One term of a row sum: s - a x (a residual's) or s + a x (a product's).
template <bool Subtract, typename V>
inline double row_sum_term(double s, V a, double x) {
  return Subtract ? s - static_cast<double>(a) * x : s + static_cast<double>(a) * x;
}

/// The sums of `count` rows of a CSR matrix: out[t] = out[t] -/+ sum_q a_{row_t q} x_q over
/// row `rows[t]`'s entries in their stored order, each row its own chain of dependent
/// additions (the same operations per row as a plain row loop, hence the same bits). A row's
/// sum is a chain whose latency, not the loads, bounds a row-by-row loop (about 15 terms per row
/// on the finest velocity level, the next row's chain started only after the previous row's
/// loop exit); four rows advanced together over their common length give the processor four
/// independent chains and one loop instead of four, then pairs, then single rows.
template <bool Subtract, typename V = double>
inline void row_sums(const int* outer, const int* inner, const V* value, const double* x,
                     const int* rows, int count, double* out) {
  int t = 0;
  for (; t + 4 <= count; t += 4) {
    int q0 = outer[rows[t]], q1 = outer[rows[t + 1]], q2 = outer[rows[t + 2]], q3 = outer[rows[t + 3]];
    const int e0 = outer[rows[t] + 1], e1 = outer[rows[t + 1] + 1], e2 = outer[rows[t + 2] + 1],
              e3 = outer[rows[t + 3] + 1];
    double s0 = out[t], s1 = out[t + 1], s2 = out[t + 2], s3 = out[t + 3];
    const int common = std::min(std::min(e0 - q0, e1 - q1), std::min(e2 - q2, e3 - q3));
    for (int c = 0; c < common; ++c) {
      s0 = row_sum_term<Subtract>(s0, value[q0 + c], x[inner[q0 + c]]);
      s1 = row_sum_term<Subtract>(s1, value[q1 + c], x[inner[q1 + c]]);
      s2 = row_sum_term<Subtract>(s2, value[q2 + c], x[inner[q2 + c]]);
      s3 = row_sum_term<Subtract>(s3, value[q3 + c], x[inner[q3 + c]]);
    }
    for (q0 += common; q0 < e0; ++q0) s0 = row_sum_term<Subtract>(s0, value[q0], x[inner[q0]]);
    for (q1 += common; q1 < e1; ++q1) s1 = row_sum_term<Subtract>(s1, value[q1], x[inner[q1]]);
    for (q2 += common; q2 < e2; ++q2) s2 = row_sum_term<Subtract>(s2, value[q2], x[inner[q2]]);
    for (q3 += common; q3 < e3; ++q3) s3 = row_sum_term<Subtract>(s3, value[q3], x[inner[q3]]);
    out[t] = s0;
    out[t + 1] = s1;
    out[t + 2] = s2;
    out[t + 3] = s3;
  }
  for (; t + 2 <= count; t += 2) {
    int q0 = outer[rows[t]], q1 = outer[rows[t + 1]];
    const int e0 = outer[rows[t] + 1], e1 = outer[rows[t + 1] + 1];
    double s0 = out[t], s1 = out[t + 1];
    const int common = std::min(e0 - q0, e1 - q1);
    for (int c = 0; c < common; ++c) {
      s0 = row_sum_term<Subtract>(s0, value[q0 + c], x[inner[q0 + c]]);
      s1 = row_sum_term<Subtract>(s1, value[q1 + c], x[inner[q1 + c]]);
    }
    for (q0 += common; q0 < e0; ++q0) s0 = row_sum_term<Subtract>(s0, value[q0], x[inner[q0]]);
    for (q1 += common; q1 < e1; ++q1) s1 = row_sum_term<Subtract>(s1, value[q1], x[inner[q1]]);
    out[t] = s0;
    out[t + 1] = s1;
  }
  for (; t < count; ++t) {
    double s = out[t];
    for (int q = outer[rows[t]]; q < outer[rows[t] + 1]; ++q) s = row_sum_term<Subtract>(s, value[q], x[inner[q]]);
    out[t] = s;
  }
}

/// y[i - begin] = b_i - (A x)_i (Subtract, b given) or (A x)_i (b null, not Subtract) for the
/// rows begin..end-1 of a CSR matrix, in blocks of eight consecutive rows handed to row_sums
/// (row-parallel when `parallel`: one writer per entry, so any thread count gives the same bits).
template <bool Subtract, typename V = double>
inline void csr_row_sums(const int* outer, const int* inner, const V* value, int begin, int end,
                         const double* b, const double* x, double* y, bool parallel) {
  constexpr int kBlock = 8;
  const int blocks = (end - begin + kBlock - 1) / kBlock;
#pragma omp parallel for schedule(static) if (parallel) num_threads(process_threads())
  for (int blk = 0; blk < blocks; ++blk) {
    const int first = begin + blk * kBlock;
    const int count = std::min(kBlock, end - first);
    std::array<int, kBlock> rows;
    std::array<double, kBlock> out;
    for (int t = 0; t < count; ++t) {
      rows[t] = first + t;
      out[t] = b ? b[first + t] : 0.0;
    }
    row_sums<Subtract, V>(outer, inner, value, x, rows.data(), count, out.data());
    for (int t = 0; t < count; ++t) y[first + t - begin] = out[t];
  }
}

}  // namespace monolith
