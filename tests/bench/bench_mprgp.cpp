// Benchmark: MPRGP on contact-like box QPs of growing size (lambda >= 0 on a grid of 2D bodies
// touching their neighbours and the ground): iterations and time without and with the SSOR
// preconditioner (1 thread), and the coloured operator on 1 and 2 threads (times are the best of
// three runs). Numbers in docs/mprgp.md.
//
// Run: build/bench/bench_mprgp [max_bodies]
#include <omp.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <random>

#include "reference/solvers/colouring.hpp"
#include "reference/solvers/mprgp.hpp"

using namespace monolith;

namespace {

struct Problem {
  SparseMatrix a;
  VectorX b;
  std::vector<std::pair<int, int>> bodies;  ///< per contact
  int num_bodies = 0;
};

/// side x side bodies (3 DOFs each: vx, vy, omega; unit mass, inertia 1/6), a contact between
/// each body and its right and upper neighbour, and one with the ground for the bottom row.
/// Rows of J: (n, r x n) on the first body, -(n, r' x n) on the second; random velocities.
Problem make_problem(int side, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const int nb = side * side;
  std::vector<Triplet> jt;
  Problem p;
  p.num_bodies = nb;
  auto add_contact = [&](int b0, int b1, double nx, double ny) {
    const int row = static_cast<int>(p.bodies.size());
    const double r0x = 0.5 * nx + 0.2 * u(rng), r0y = 0.5 * ny + 0.2 * u(rng);
    jt.emplace_back(row, 3 * b0, nx);
    jt.emplace_back(row, 3 * b0 + 1, ny);
    jt.emplace_back(row, 3 * b0 + 2, r0x * ny - r0y * nx);
    if (b1 >= 0) {
      const double r1x = -0.5 * nx + 0.2 * u(rng), r1y = -0.5 * ny + 0.2 * u(rng);
      jt.emplace_back(row, 3 * b1, -nx);
      jt.emplace_back(row, 3 * b1 + 1, -ny);
      jt.emplace_back(row, 3 * b1 + 2, -(r1x * ny - r1y * nx));
    }
    p.bodies.emplace_back(b0, b1);
  };
  for (int j = 0; j < side; ++j)
    for (int i = 0; i < side; ++i) {
      const int b = i + side * j;
      if (j == 0) add_contact(b, -1, 0.0, 1.0);
      if (i + 1 < side) add_contact(b, b + 1, -1.0, 0.1 * u(rng));
      if (j + 1 < side) add_contact(b, b + side, 0.1 * u(rng), -1.0);
    }
  const int m = static_cast<int>(p.bodies.size());
  SparseMatrix jm(m, 3 * nb);
  jm.setFromTriplets(jt.begin(), jt.end());
  VectorX m_inv(3 * nb);
  for (int k = 0; k < nb; ++k) m_inv.segment<3>(3 * k) << 1.0, 1.0, 6.0;
  p.a = (jm * m_inv.asDiagonal() * SparseMatrix(jm.transpose())).pruned();
  VectorX v(3 * nb);
  for (int k = 0; k < 3 * nb; ++k) v[k] = u(rng) - (k % 3 == 1 ? 0.5 : 0.0);  // falling on average
  p.b = -(jm * v);
  return p;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

struct Run {
  MprgpResult r;
  double seconds = 0;
};
Run run(const LinearOperator& op, const Problem& p, bool precondition, bool adaptive = false) {
  MprgpSettings s;
  s.adaptive_expansion = adaptive;
  s.tolerance = 1e-6;
  s.max_iterations = 20000;
  s.precondition = precondition;
  const int n = static_cast<int>(p.b.size());
  const VectorX l = VectorX::Zero(n), u = VectorX::Constant(n, std::numeric_limits<double>::infinity());
  // best of three (the machine is shared: the minimum is the least disturbed run)
  Run out;
  out.seconds = std::numeric_limits<double>::infinity();
  for (int repeat = 0; repeat < 3; ++repeat) {
    VectorX x = VectorX::Zero(n);
    const auto t0 = std::chrono::steady_clock::now();
    out.r = mprgp_solve(op, p.b, l, u, x, s);
    out.seconds = std::min(out.seconds, seconds_since(t0));
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  const int max_bodies = argc > 1 ? std::atoi(argv[1]) : 40000;
  std::printf("| bodies | contacts | colours | plain: it (cg/exp/prop) | time | SSOR: it (cg/exp/prop) | time "
              "| SSOR + adaptive expansion | time | coloured SSOR: it | 1 thread | 2 threads | sweep speed-up |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (int side = 4; side * side <= max_bodies; side *= 2) {
    const Problem p = make_problem(side, 1234u + side);
    SparseMatrixOperator plain_op(p.a);
    const Colouring colours = welsh_powell(contact_adjacency(p.bodies, p.num_bodies));
    ColouredSparseOperator coloured(p.a, colours);
    omp_set_num_threads(1);
    const Run plain = run(plain_op, p, false);
    const Run ssor = run(plain_op, p, true);
    const Run adaptive = run(plain_op, p, true, true);
    const Run c1 = run(coloured, p, true);
    omp_set_num_threads(2);
    const Run c2 = run(coloured, p, true);
    // the sweeps alone: 20 SSOR applications, best of three
    VectorX z = VectorX::Zero(p.b.size());
    double sweep[2] = {std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity()};
    for (int repeat = 0; repeat < 3; ++repeat)
      for (int t = 1; t <= 2; ++t) {
        omp_set_num_threads(t);
        const auto t0 = std::chrono::steady_clock::now();
        for (int k = 0; k < 20; ++k) {
          coloured.forward_sweep(p.b, z, 1.0);
          coloured.backward_sweep(p.b, z, 1.0);
        }
        sweep[t - 1] = std::min(sweep[t - 1], seconds_since(t0));
      }
    auto cell = [](const Run& r) {
      static char buf[5][96];
      static int k = 0;
      char* s = buf[k++ % 5];
      std::snprintf(s, 96, "%d (%d/%d/%d)%s", r.r.iterations, r.r.cg_steps, r.r.expansion_steps,
                    r.r.proportioning_steps, r.r.converged ? "" : " NOT CONVERGED");
      return s;
    };
    std::printf("| %d | %d | %d | %s | %.4f s | %s | %.4f s | %s | %.4f s | %s | %.4f s | %.4f s | %.2f |\n",
                p.num_bodies, static_cast<int>(p.b.size()), colours.num_colours(), cell(plain), plain.seconds,
                cell(ssor), ssor.seconds, cell(adaptive), adaptive.seconds, cell(c1), c1.seconds, c2.seconds, sweep[0] / sweep[1]);
    std::fflush(stdout);
  }
  return 0;
}
