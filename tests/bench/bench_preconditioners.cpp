// Benchmark (not a test): PCG iterations and time to a relative residual of 1e-6 on the unified
// pressure-viscosity system of eq. (8) (reduced stress form, the (tau, p) blocks of eq. (24)),
// the paper's SSOR against the block preconditioner of reference/fluid/stokes_preconditioner.hpp,
// in the same run, over viscosities and grid sizes. Results go to docs/preconditioners.md and
// docs/benchmarks.md.
//
//   build/bench/bench_preconditioners [--dim 2|3] [--n 16,32] [--eta 0.1,1,10,100,1000,5000]
//       [--scene tank|blob|pool] [--backend matrixfree|explicit] [--ssor-max N (SSOR stopped there
//        unconverged: its ratios printed as ">=", lower bounds)] [--no-ssor]
//       [--gamma G] [--cycles K] [--smoothing S] [--sweeps W] [--no-schur] [--no-elements]
//       [--clamp T] [--repeats R] [--cut-threshold T (0: no cut block)] [--cut-layers L]
//       [--cut-layer-limit N (layers after the first only while the block has at most N unknowns; 0: none)]
//       [--no-renumber (Multigrid keeps the caller's numbering: same results, for timing)]
//       [--double-velocity | --single-velocity (the velocity hierarchy's smoothed levels in
//        double, or in single precision as by default: docs/preconditioners.md section 31)]
//       [--two-term | --additive] [--schur cc|mobility|scaled (Sigma^-1 of the two-term form)]
//       [--cycle-ratio R (0: --cycles always)]
//       [--lean-share S (3D: one V-cycle fewer below this free-surface share; 0: off)]
//       [--setup-only (the block preconditioner is built, not used: its set-up timed alone)]
//       [--cut-simplicial (the cut block factored by Eigen's simplicial LDL^T, not by supernodes)]
//       [--system-malloc (glibc's default allocator settings; by default the bench sets those of
//        the `monolith` application, keep_freed_memory_for_reuse: docs/preconditioners.md section 41)]
//
// Scenes (unit box, walls, open top, rho = 1000, dt = 0.01, a smooth swirl plus one step of
// gravity as u*):
//   tank: liquid below a wavy surface y = 0.62 + 0.08 sin(2 pi x) around a solid ball (centre
//         0.37, radius 0.16): walls, free surface and a cut-cell solid;
//   blob: a liquid ball (centre 0.5, radius 0.3) in the air, touching nothing;
//   pool: liquid below y = 0.6, no solid.
#include <chrono>
#include <ctime>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <cstring>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <sys/resource.h>

#include "reference/core/memory_policy.hpp"
#include "reference/fluid/stokes_preconditioner.hpp"
#include "reference/fluid/velocity_operator.hpp"
#include "reference/solvers/pcg.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/grid/stress_weights.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}
/// CPU seconds of the process (all threads): on a shared machine less inflated by the load than
/// the wall clock; with one thread the CPU time of the work itself.
double cpu_seconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

std::vector<double> parse_list(const char* s) {
  std::vector<double> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) out.push_back(std::atof(item.c_str()));
  return out;
}

struct Config {
  int dim = 3;
  std::vector<double> n{16};
  std::vector<double> eta{0.1, 1, 10, 100, 1000, 5000};
  std::string scene = "tank";
  std::string backend = "matrixfree";
  int ssor_max = 20000;
  bool ssor = true;
  int repeats = 1;
  bool setup_only = false;  ///< --setup-only: build the block preconditioner, no solve with it
  bool app_memory_policy = true;  ///< false (--system-malloc): glibc's default allocator settings
  double noise = 0.0;
  StokesPreconditionerOptions options;
};

template <int Dim>
struct Case {
  MacGrid<Dim> grid;
  StokesWeights w;
  VectorX u_star;
  double dt = 0.01;
};

template <int Dim>
Case<Dim> make_case(const std::string& scene, int n, double eta, double noise) {
  Case<Dim> sc;
  sc.grid = MacGrid<Dim>(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), {});
  const MacGrid<Dim>& grid = sc.grid;
  const SampleLattice<Dim> lattice = half_lattice(grid);
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  boundary[3] = BoundaryType::open;
  std::vector<ShapePtr<Dim>> solids;
  if (scene == "tank")
    solids.push_back(std::make_shared<monolith::testing::TestBall<Dim>>(Vec<Dim>::Constant(0.37), 0.16));
  const VectorX solid_phi = solid_phi_on_lattice<Dim>(grid, lattice, solids, 0.0);
  VectorX liquid_phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) {
    const Vec<Dim> x = lattice.position(lattice.coord(k));
    if (scene == "blob")
      liquid_phi[k] = (x - Vec<Dim>::Constant(0.5)).norm() - 0.3;
    else if (scene == "pool")
      liquid_phi[k] = x[1] - 0.6;
    else
      liquid_phi[k] = x[1] - 0.62 - 0.08 * std::sin(2.0 * M_PI * x[0]);
  }
  sc.w = uniform_stokes_weights(grid, solid_phi, liquid_phi, boundary, 1000.0, eta);
  sc.u_star.resize(grid.num_faces());
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, c] = grid.face_coord(f);
    const Vec<Dim> x = grid.face_center(axis, c);
    sc.u_star[f] = std::sin(3 * x[(axis + 1) % Dim] + axis) * std::cos(2 * x[axis]) -
                   (axis == 1 ? 9.81 * sc.dt : 0.0);
  }
  if (noise > 0.0) sc.u_star += noise * monolith::testing::random_vector(grid.num_faces(), 11);
  return sc;
}

template <int Dim>
void run_case(const Config& cfg, int n, double eta) {
  const Case<Dim> sc = make_case<Dim>(cfg.scene, n, eta, cfg.noise);
  const StressLayout<Dim> layout(StressGrid<Dim>(sc.grid), StressForm::reduced);
  const StokesDofs dofs = select_stokes_dofs(sc.grid, layout, sc.w, sc.dt, StokesUnknowns::pressure_and_stress);
  std::unique_ptr<LinearOperator> op;
  std::unique_ptr<ExplicitStokesSystem> sys;
  VectorX b;
  if (cfg.backend == "explicit") {
    sys = std::make_unique<ExplicitStokesSystem>(
        assemble_explicit_stokes(sc.grid, layout, sc.w, dofs, sc.dt, sc.u_star));
    op = std::make_unique<SparseMatrixOperator>(sys->A, dofs.null_space);
    b = sys->b;
  } else {
    auto mf = std::make_unique<MatrixFreeStokesOperator<Dim>>(sc.grid, layout, sc.w, dofs, sc.dt);
    b = mf->rhs(sc.u_star);
    op = std::move(mf);
  }
  PcgSettings settings;
  settings.tolerance = 1e-6;
  settings.max_iterations = cfg.ssor_max;
  // SSOR
  int it_ssor = -1;
  double t_ssor = 0.0, c_ssor = 0.0;
  bool conv_ssor = false;
  if (cfg.ssor) {
    for (int r = 0; r < cfg.repeats; ++r) {
      VectorX x;
      const auto t0 = Clock::now();
      const double c0 = cpu_seconds();
      const PcgResult res = pcg_solve(*op, b, x, settings);
      t_ssor += seconds_since(t0) / cfg.repeats;
      c_ssor += (cpu_seconds() - c0) / cfg.repeats;
      it_ssor = res.iterations;
      conv_ssor = res.converged;
    }
  }
  // block preconditioner
  double t_setup = 0.0, t_solve = 0.0, c_setup = 0.0, c_solve = 0.0;
  int cut_size = 0, cycles = 0;
  double share = 0.0;
  long cut_entries = 0;
  int it_block = -1;
  std::uint64_t digest = 0;
  bool conv_block = false;
  std::size_t bytes = 0;
  int levels = 0;
  for (int r = 0; r < cfg.repeats; ++r) {
    const auto t0 = Clock::now();
    const double c0 = cpu_seconds();
    StokesFactors f =
        cfg.backend == "explicit"
            ? stokes_factors(sc.grid, layout, sc.w, dofs, sc.dt, *sys, cfg.options.min_fluid_fraction)
            : stokes_factors(sc.grid, layout, sc.w, dofs, sc.dt,
                             static_cast<const MatrixFreeStokesOperator<Dim>&>(*op),
                             cfg.options.min_fluid_fraction);
    const StokesPreconditioner<Dim> m(sc.grid, *op, std::move(f), cfg.options);
    t_setup += seconds_since(t0) / cfg.repeats;
    c_setup += (cpu_seconds() - c0) / cfg.repeats;
    VectorX x;
    const auto t1 = Clock::now();
    const double c1 = cpu_seconds();
    settings.max_iterations = 2000;
    PcgResult res;
    if (cfg.options.inner_cg > 0) {
      // flexible CG (Polak-Ribiere beta): the preconditioner is not linear
      const int nn = op->size();
      x.setZero(nn);
      VectorX r = b, z(nn), p(nn), ap(nn), r_old;
      const double bn = b.lpNorm<Eigen::Infinity>();
      m.apply(r, z);
      p = z;
      double rz = r.dot(z);
      res.iterations = 0;
      for (int k = 0; k < 2000; ++k) {
        op->apply(p, ap);
        const double alpha = rz / p.dot(ap);
        x += alpha * p;
        r_old = r;
        r -= alpha * ap;
        res.iterations = k + 1;
        res.relative_residual = r.lpNorm<Eigen::Infinity>() / bn;
        if (res.relative_residual <= 1e-6) { res.converged = true; break; }
        m.apply(r, z);
        const double beta = z.dot(r - r_old) / rz;
        rz = r.dot(z);
        p = z + beta * p;
      }
    } else if (!cfg.setup_only) {
      res = pcg_solve(*op, b, x, settings, m);
    }
    t_solve += seconds_since(t1) / cfg.repeats;
    c_solve += (cpu_seconds() - c1) / cfg.repeats;
    cut_size = static_cast<int>(m.cut_unknowns().size());
    cycles = m.velocity_cycles();
    share = m.free_surface_share();
    cut_entries = m.cut_factor_entries();
    it_block = res.iterations;
    {
      // a digest of the solution's bits (same preconditioner, same bits: compare across builds)
      std::uint64_t h = 1469598103934665603ull;
      for (int i = 0; i < x.size(); ++i) {
        std::uint64_t bits;
        std::memcpy(&bits, &x[i], sizeof bits);
        h = (h ^ bits) * 1099511628211ull;
      }
      digest = h;
    }
    conv_block = res.converged;
    bytes = m.memory_bytes();
    levels = m.velocity_multigrid().num_levels();
    if (std::getenv("MG_INFO")) {
      for (const Multigrid* mg : {&m.velocity_multigrid(), &m.pressure_multigrid()}) {
        for (int l = 0; l < mg->num_levels(); ++l) {
          const MultigridLevel& lv = mg->level(l);
          const PatchSet& ps = lv.patches;
          long gathered = 0, dense = 0;  // row entries read and patch-inverse entries per sweep
          for (int k = 0; k < ps.size(); ++k) {
            const long pm = ps.start[k + 1] - ps.start[k];
            dense += pm * pm;
            for (int q = ps.start[k]; q < ps.start[k + 1]; ++q)
              gathered += lv.a.outerIndexPtr()[ps.index[q] + 1] - lv.a.outerIndexPtr()[ps.index[q]];
          }
          std::printf("   level %d: %ld unknowns, %ld nnz, %d patches, %zu colours, %ld row entries and %ld inverse entries per sweep",
                      l, (long)lv.a.rows(), (long)lv.a.nonZeros(), ps.size(), ps.colours.size(), gathered, dense);
          if (l + 1 < mg->num_levels()) {
            VectorX bl = VectorX::Ones(lv.a.rows()), xl = VectorX::Zero(lv.a.rows());
            double best = 1e9;
            for (int rep = 0; rep < 5; ++rep) {
              const double c0 = cpu_seconds();
              for (int k = 0; k < 4; ++k) mg->sweep(l, bl, xl, k % 2 == 1);
              best = std::min(best, (cpu_seconds() - c0) / 4 * 1e3);
            }
            std::printf(", %.2f", best);
            std::printf(" ms CPU per sweep (min of 5)");
          }
          std::printf("\n");
        }
        VectorX bb = VectorX::Ones(mg->size()), xx;
        auto t0 = Clock::now();
        for (int k = 0; k < 5; ++k) mg->apply(bb, xx, 1);
        std::printf("   -- V-cycle %.2f ms", seconds_since(t0) / 5 * 1e3);
        t0 = Clock::now();
        for (int k = 0; k < 5; ++k) mg->sweep(0, bb, xx, false);
        std::printf("  fine sweep %.2f ms\n", seconds_since(t0) / 5 * 1e3);
      }
      VectorX rr = VectorX::Ones(m.size()), zz;
      auto t0 = Clock::now();
      for (int k = 0; k < 40; ++k) m.apply(rr, zz);
      std::printf("   preconditioner apply %.2f ms\n", seconds_since(t0) / 40 * 1e3);
      t0 = Clock::now();
      for (int k = 0; k < 5; ++k) op->apply(rr, zz);
      std::printf("   A apply %.2f ms\n", seconds_since(t0) / 5 * 1e3);
    }
  }
  std::printf("%dD %4d %-6s eta %7g | n_tau %7d n_p %6d | SSOR %5d%s %8.3f s | block %3d%s setup %7.3f solve %7.3f s"
              " (%d lv, %.1f MB) | speed-up %s%.1f\n",
              Dim, n, cfg.scene.c_str(), eta, dofs.num_stress(), dofs.num_pressure(), it_ssor,
              conv_ssor ? " " : "!", t_ssor, it_block, conv_block ? " " : "!", t_setup, t_solve, levels,
              bytes / 1e6, cfg.ssor && !conv_ssor ? ">=" : "", cfg.ssor ? t_ssor / (t_setup + t_solve) : 0.0);
  // a capped SSOR that stopped unconverged spent at least this much: its ratio is a lower bound
  const char* bound = cfg.ssor && !conv_ssor ? ">=" : "";
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);  // ru_maxrss: the process's peak resident set so far, in KiB
  std::printf("     cpu s: SSOR %.3f | block setup %.3f solve %.3f | speed-up %s%.1f | %d V-cycles (share %.3f) | cut block %d unknowns, "
              "%ld factor entries | digest %016llx | peak resident so far %.2f GB\n",
              c_ssor, c_setup, c_solve, bound, cfg.ssor ? c_ssor / (c_setup + c_solve) : 0.0, cycles, share, cut_size,
              cut_entries, static_cast<unsigned long long>(digest), static_cast<double>(usage.ru_maxrss) * 1024.0 / 1e9);
  if (cfg.ssor && !conv_ssor)
    std::printf("     (SSOR stopped unconverged at --ssor-max %d: its times and both speed-ups are lower bounds)\n",
                cfg.ssor_max);
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  Config cfg;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "missing value after %s\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--dim") cfg.dim = std::atoi(next());
    else if (a == "--n") cfg.n = parse_list(next());
    else if (a == "--eta") cfg.eta = parse_list(next());
    else if (a == "--scene") cfg.scene = next();
    else if (a == "--backend") cfg.backend = next();
    else if (a == "--ssor-max") cfg.ssor_max = std::atoi(next());
    else if (a == "--no-ssor") cfg.ssor = false;
    else if (a == "--repeats") cfg.repeats = std::atoi(next());
    else if (a == "--setup-only") cfg.setup_only = true;
    else if (a == "--cut-simplicial") cfg.options.cut_supernodal = false;
    else if (a == "--noise") cfg.noise = std::atof(next());
    else if (a == "--gamma") cfg.options.penalty_factor = std::atof(next());
    else if (a == "--cycles") cfg.options.velocity_cycles = std::atoi(next());
    else if (a == "--smoothing") cfg.options.smoothing = std::atoi(next());
    else if (a == "--sweeps") cfg.options.outer_sweeps = std::atoi(next());
    else if (a == "--no-schur") { cfg.options.schur_correction = false; cfg.options.additive_pressure = false; }
    else if (a == "--two-term") { cfg.options.schur_correction = true; cfg.options.additive_pressure = false; }
    else if (a == "--no-elements") cfg.options.element_patches = false;
    else if (a == "--clamp") cfg.options.min_fluid_fraction = std::atof(next());
    else if (a == "--transverse-constant") cfg.options.transverse_linear = false;
    else if (a == "--no-fine-cells") cfg.options.fine_cell_patches = false;
    else if (a == "--additive") cfg.options.additive_pressure = true;
    else if (a == "--inner-cg") cfg.options.inner_cg = std::atoi(next());
    else if (a == "--schur") {
      const std::string v = next();
      if (v == "cc") cfg.options.schur = SchurApproximation::cahouet_chabard;
      else if (v == "mobility") cfg.options.schur = SchurApproximation::commutator_mobility;
      else if (v == "scaled") cfg.options.schur = SchurApproximation::commutator_scaled;
      else {
        std::fprintf(stderr, "--schur: cc, mobility or scaled, not %s\n", v.c_str());
        return 2;
      }
    }
    else if (a == "--cycle-ratio") cfg.options.cycle_ratio = std::atof(next());
    else if (a == "--lean-share") cfg.options.lean_share = std::atof(next());
    else if (a == "--max-coarse") cfg.options.max_coarse = std::atoi(next());
    else if (a == "--cut-threshold") cfg.options.cut_threshold = std::atof(next());
    else if (a == "--cut-layers") cfg.options.cut_layers = std::atoi(next());
    else if (a == "--cut-layer-limit") cfg.options.cut_layer_limit = std::atoi(next());
    else if (a == "--no-renumber") cfg.options.renumber = false;
    else if (a == "--double-velocity") cfg.options.single_precision_velocity = false;
    else if (a == "--single-velocity") cfg.options.single_precision_velocity = true;
    else if (a == "--system-malloc") cfg.app_memory_policy = false;
    else {
      std::fprintf(stderr, "unknown option %s\n", a.c_str());
      return 2;
    }
  }
  // the allocator setting of the `monolith` application (reference/app/main.cpp): freed blocks
  // stay in the heap for reuse, as the solves of a simulation run under it
  if (cfg.app_memory_policy) keep_freed_memory_for_reuse();
  for (double n : cfg.n)
    for (double eta : cfg.eta) {
      if (cfg.dim == 2)
        run_case<2>(cfg, static_cast<int>(n), eta);
      else
        run_case<3>(cfg, static_cast<int>(n), eta);
    }
  return 0;
}
