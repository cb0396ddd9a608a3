/// \file projection_cg.hpp
/// The density projection's conjugate gradient (project_particle_density, docs/particles.md
/// "Density projection") with its products and vector updates on a team and Eigen's bits.
#pragma once

#include "reference/core/common.hpp"

namespace monolith {

/// What cg_in_eigen_order did.
struct EigenOrderCgResult {
  int iterations = 0;  ///< Eigen's iterations(): completed updates of the search direction
  double error = 0.0;  ///< Eigen's error(): sqrt(|r|^2 / |b|^2) at the end
  int team = 1;        ///< the threads that ran it
};

/// x = the solution of a x = b (a symmetric positive definite, compressed, row-major: the
/// projection's -L dx^2) by
///   Eigen::ConjugateGradient<SparseMatrix, Eigen::Lower | Eigen::Upper,
///                            Eigen::DiagonalPreconditioner<double>>
/// with setTolerance(tolerance), setMaxIterations(max_iterations) and solve(b) from x = 0, bit for
/// bit for any team size: the same steps as Eigen's conjugate_gradient (Eigen 3.4,
/// ConjugateGradient.h), each row's product summed in column order by one thread (Eigen's
/// row-major product), the entrywise updates with the same operations, and the three dot products
/// per iteration made by Eigen's own dot() / squaredNorm() on the whole vectors by one thread
/// (their sums keep Eigen's order; the two after the update run side by side). The team comes from
/// an AdaptiveTeam site measured per unit of work (non-zeros times iterations), one thread below
/// kParallelMinWork non-zeros: the regions' five barriers per iteration lose to one thread when
/// another process takes a core (docs/benchmarks.md, threads15 and outside21).
EigenOrderCgResult cg_in_eigen_order(const SparseMatrix& a, const VectorX& b, double tolerance,
                                     long max_iterations, VectorX& x);

}  // namespace monolith
