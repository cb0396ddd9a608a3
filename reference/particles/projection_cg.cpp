/// \file projection_cg.cpp
/// The density projection's conjugate gradient on a team (projection_cg.hpp).

#include "reference/particles/projection_cg.hpp"

#include <omp.h>

#include <Eigen/IterativeLinearSolvers>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "reference/core/parallel.hpp"

namespace monolith {

namespace {

/// Eigen's solver itself, on one thread (its product would open a region per iteration above
/// 20000 non-zeros: docs/benchmarks.md, threads14).
EigenOrderCgResult eigen_cg(const SparseMatrix& a, const VectorX& b, double tolerance,
                            long max_iterations, VectorX& x) {
  Eigen::ConjugateGradient<SparseMatrix, Eigen::Lower | Eigen::Upper,
                           Eigen::DiagonalPreconditioner<double>>
      cg;
  cg.setTolerance(tolerance);
  cg.setMaxIterations(max_iterations);
  cg.compute(a);
  const int eigen_threads = Eigen::nbThreads();
  Eigen::setNbThreads(1);
  x = cg.solve(b);
  Eigen::setNbThreads(eigen_threads);
  EigenOrderCgResult result;
  result.iterations = static_cast<int>(cg.iterations());
  result.error = cg.error();
  return result;
}

}  // namespace

EigenOrderCgResult cg_in_eigen_order(const SparseMatrix& a, const VectorX& b, double tolerance,
                                     long max_iterations, VectorX& x) {
  const int n = static_cast<int>(a.rows());
  const long nonzeros = a.nonZeros();
  static AdaptiveTeam site;
  const int team = a.isCompressed() && n > 1 ? site.choose(nonzeros) : 0;
  if (team <= 1) return eigen_cg(a, b, tolerance, max_iterations, x);
  const auto start = std::chrono::steady_clock::now();

  const int* outer = a.outerIndexPtr();
  const int* inner = a.innerIndexPtr();
  const double* value = a.valuePtr();
  // Eigen's row-major sparse times dense: the destination zeroed, then per row
  // res(i) += alpha * (sum in column order of value * v(column)), alpha = 1
  const double one = 1.0;
  const auto row_product = [&](int i, const double* v) {
    double sum = 0.0;
    for (int k = outer[i]; k < outer[i + 1]; ++k) sum += value[k] * v[inner[k]];
    double res = 0.0;
    res += one * sum;
    return res;
  };
  // DiagonalPreconditioner::factorize: 1 / a_jj, 1 where the diagonal is missing or zero
  VectorX invdiag(n);
  x.setZero(n);
  VectorX residual(n), p(n), z(n), tmp(n);
  EigenOrderCgResult result;
  result.team = team;
  // shared between the team's threads: written by one thread between barriers
  double rhs_norm2 = 0.0, residual_norm2 = 0.0, p_dot_tmp = 0.0, residual_dot_z = 0.0;
  double abs_new = 0.0;
  bool stop = false;
  long iterations = 0;
  double threshold = 0.0;
#pragma omp parallel num_threads(team)
  {
    const int t = omp_get_thread_num(), nt = omp_get_num_threads();
    // fixed row ranges (each entry written by one thread; any split gives the same entries)
    const int lo = static_cast<int>(static_cast<long>(n) * t / nt);
    const int hi = static_cast<int>(static_cast<long>(n) * (t + 1) / nt);
    for (int j = lo; j < hi; ++j) {
      int k = outer[j];
      while (k < outer[j + 1] && inner[k] != j) ++k;
      invdiag[j] = k < outer[j + 1] && value[k] != 0.0 ? 1.0 / value[k] : 1.0;
    }
    // residual = rhs - mat * x (x = 0: the product is evaluated all the same, as Eigen does)
    for (int i = lo; i < hi; ++i) residual[i] = b[i] - row_product(i, x.data());
#pragma omp barrier
#pragma omp single
    {
      rhs_norm2 = b.squaredNorm();
      if (rhs_norm2 == 0.0) {
        stop = true;  // x stays 0, no iteration, error 0
      } else {
        threshold = std::max(tolerance * tolerance * rhs_norm2,
                             std::numeric_limits<double>::min());
        residual_norm2 = residual.squaredNorm();
        stop = residual_norm2 < threshold;
      }
    }
    if (!stop) {
      for (int i = lo; i < hi; ++i) p[i] = invdiag[i] * residual[i];
#pragma omp barrier
#pragma omp single
      abs_new = residual.dot(p);
      // every thread keeps the same abs_new and iteration count (the same operations on the
      // same shared inputs)
      double abs_local = abs_new;
      long i_local = 0;
      while (i_local < max_iterations) {
        for (int i = lo; i < hi; ++i) tmp[i] = row_product(i, p.data());
#pragma omp barrier
#pragma omp single
        p_dot_tmp = p.dot(tmp);
        const double alpha = abs_local / p_dot_tmp;
        for (int i = lo; i < hi; ++i) {
          x[i] += alpha * p[i];
          residual[i] -= alpha * tmp[i];
          z[i] = invdiag[i] * residual[i];  // (unread when this iteration ends the loop)
        }
#pragma omp barrier
#pragma omp sections
        {
#pragma omp section
          residual_norm2 = residual.squaredNorm();
#pragma omp section
          residual_dot_z = residual.dot(z);
        }
        if (residual_norm2 < threshold) break;
        const double abs_old = abs_local;
        abs_local = residual_dot_z;
        const double beta = abs_local / abs_old;
        for (int i = lo; i < hi; ++i) p[i] = z[i] + beta * p[i];
        ++i_local;
#pragma omp barrier
      }
#pragma omp single nowait
      iterations = i_local;
    }
  }
  if (rhs_norm2 == 0.0) {
    result.iterations = 0;
    result.error = 0.0;
  } else {
    result.iterations = static_cast<int>(iterations);
    result.error = std::sqrt(residual_norm2 / rhs_norm2);
  }
  site.record(team, nonzeros * (iterations + 1),
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  return result;
}

}  // namespace monolith
