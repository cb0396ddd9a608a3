// Benchmark (not a test) of the two back ends of the Stokes system of eq. (8) / eq. (24) without
// bodies: the explicit back end (ExplicitStokesSystem's A through SparseMatrixOperator,
// serial row-order SSOR sweeps) against the matrix-free one (MatrixFreeStokesOperator, red-black
// SSOR sweeps in parallel), on a viscous scene in 2D and 3D at several resolutions. In one run it
// prints, and writes as CSV and as a log-log PPM plot of time per iteration against DOFs:
//   - set-up time (assembly of the named matrices and A / the stencils of B), time per operator
//     apply, time per SSOR-PCG iteration, iterations to relative tolerance 1e-6, whole-solve
//     time (set-up + PCG), each with 2 threads, and the whole solve with 1 thread and the ratio;
//   - peak memory of building and solving once, measured in a child process per configuration
//     (this binary re-executed with the hidden flag --child), per DOF, explicit / matrix-free;
//   - the bandwidth the apply achieves (the bytes one apply must move / its time) next to a
//     STREAM-style triad a[i] = b[i] + s c[i] measured in the same run, 1 and 2 threads;
//   - the goal lines of the back ends with the measured ratios, met or not met.
// Results go to docs/benchmarks.md, section "Back ends: matrix-free versus explicit".
//
//   build-X/bench/bench_backends [--quick] [--csv PATH] [--plot PATH] [--eta ETA] [--dims 2|3|all]
//
// (--dims 3 re-measures the 3D rows, which the goals are about, alone.)
//
// Scene: liquid below y = 0.6 in a unit box with walls and an open top, a fixed solid ball of
// radius 0.15 under the surface, density 1000, viscosity eta (default 1 Pa s), dt = 0.01 s, u* a
// smooth swirl plus one step of gravity; the reduced stress form (the solver default).
#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/contact/collision.hpp"
#include "reference/contact/contact_system.hpp"
#include "reference/coupling/coupled_schemes.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/coupling/monolithic_system.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/solvers/pcg.hpp"
#include "reference/viz/plot.hpp"
#include "tests/support/body_helpers.hpp"

using namespace monolith;

namespace {

using Clock = std::chrono::steady_clock;
using Record = std::map<std::string, double>;

constexpr double kRho = 1000.0, kDt = 0.01, kTolerance = 1e-6;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// --- memory: /proc/self/status ---------------------------------------------------------------

/// The value of a line of /proc/self/status such as "VmHWM:", in bytes (0 when absent).
double status_bytes(const char* key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  const std::size_t len = std::strlen(key);
  while (std::getline(in, line))
    if (line.compare(0, len, key) == 0) return 1024.0 * std::atof(line.c_str() + len);
  return 0.0;
}

/// Resets VmHWM to the current resident set ("5" to /proc/self/clear_refs, Linux >= 4.0).
/// Returns whether the reset took (the peak then equals VmRSS).
bool reset_peak_rss() {
  {
    std::ofstream out("/proc/self/clear_refs");
    if (!out) return false;
    out << "5";
  }
  return status_bytes("VmHWM:") <= status_bytes("VmRSS:") + 64.0 * 1024.0;
}

// --- bytes one apply moves ----------------------------------------------------------------------

template <class T, class = void>
struct HasBytesPerApply : std::false_type {};
template <class T>
struct HasBytesPerApply<T, std::void_t<decltype(std::declval<const T&>().bytes_per_apply())>>
    : std::true_type {};
template <class T, class = void>
struct HasMemoryBytes : std::false_type {};
template <class T>
struct HasMemoryBytes<T, std::void_t<decltype(std::declval<const T&>().memory_bytes())>>
    : std::true_type {};

/// The compulsory memory traffic of one y = A x with A in compressed rows (n rows, nnz entries):
/// values and column indices once, row starts, x read once and y written once (8-byte values,
/// 4-byte indices; the STREAM convention, no write-allocate traffic). The operator's own
/// bytes_per_apply() when it has one.
template <class Op>
double explicit_apply_bytes(const Op& op, const SparseMatrix& a) {
  if constexpr (HasBytesPerApply<Op>::value) {
    if (op.bytes_per_apply() > 0.0) return op.bytes_per_apply();
  }
  const double n = static_cast<double>(a.rows()), nnz = static_cast<double>(a.nonZeros());
  return nnz * (8.0 + 4.0) + (n + 1.0) * 4.0 + 2.0 * n * 8.0;
}

/// The same for the matrix-free apply (its own bytes_per_apply() when it reports one; otherwise
/// from what the face/unknown-stencil operator of stokes_system.cpp stores): B by face and by
/// unknown (nnz_B coefficients and indices each), the face coefficients C_f, the face values v
/// written then read, the N^-1 W^s diagonal with the 3D partner coupling (value, index), x read by
/// both loops, y written.
template <class Op>
double matrix_free_apply_bytes(const Op& op, double num_faces, double nnz_b) {
  if constexpr (HasBytesPerApply<Op>::value) {
    if (op.bytes_per_apply() > 0.0) return op.bytes_per_apply();
  }
  const double n = op.size();
  const double stencils = 2.0 * nnz_b * (8.0 + 4.0) + (num_faces + 1.0) * 4.0 + (n + 1.0) * 4.0;
  const double faces = num_faces * 8.0 /* C_f */ + 2.0 * num_faces * 8.0 /* v out, in */;
  const double unknowns = n * (8.0 + 8.0 + 4.0) /* self, partner coef, index */ +
                          2.0 * n * 8.0 /* x twice */ + n * 8.0 /* y */;
  return stencils + faces + unknowns;
}

template <class Op>
double operator_bytes(const Op& op) {
  if constexpr (HasMemoryBytes<Op>::value) {
    if (op.memory_bytes() > 0) return static_cast<double>(op.memory_bytes());
  }
  return -1.0;
}

// --- the scene --------------------------------------------------------------------------------

template <int Dim>
struct ViscousScene {
  MacGrid<Dim> grid;
  StokesWeights weights;
  VectorX u_star;
};

/// u*: a smooth swirl plus one step of gravity, on every face.
template <int Dim>
VectorX viscous_scene_velocity(const MacGrid<Dim>& grid) {
  VectorX u(grid.num_faces());
  for (int f = 0; f < grid.num_faces(); ++f) {
    const auto [axis, c] = grid.face_coord(f);
    const Vec<Dim> x = grid.face_center(axis, c);
    u[f] = std::sin(3 * x[(axis + 1) % Dim] + axis) * std::cos(2 * x[axis]) -
           (axis == 1 ? 9.81 * kDt : 0.0);
  }
  return u;
}

template <int Dim>
ViscousScene<Dim> viscous_scene(int n, double eta) {
  ViscousScene<Dim> s{MacGrid<Dim>(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), {}), {}, {}};
  const MacGrid<Dim>& grid = s.grid;
  const SampleLattice<Dim> lattice = half_lattice(grid);
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  boundary[3] = BoundaryType::open;  // the top
  // a fixed ball under the surface
  ShapeSpec ball;
  ball.type = ShapeType::sphere;
  ball.center = std::vector<double>(Dim, 0.5);
  ball.center[1] = 0.3;
  ball.radius = 0.15;
  const VectorX solid_phi =
      solid_phi_on_lattice<Dim>(grid, lattice, {make_shape<Dim>(ball, "bench.ball")}, 0.0);
  VectorX phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) phi[k] = lattice.position(lattice.coord(k))[1] - 0.6;
  s.weights = uniform_stokes_weights<Dim>(grid, solid_phi, phi, boundary, kRho, eta);
  s.u_star = viscous_scene_velocity(grid);
  return s;
}

// --- the child: build and solve one (back end, dimension, size) -------------------------------

/// Best time of one call of f over at least `min_runs` runs and about `budget` seconds.
template <class F>
double best_time(F&& f, int min_runs, double budget) {
  double best = 1e300, total = 0.0;
  for (int r = 0; r < min_runs || (total < budget && r < 200); ++r) {
    const auto t0 = Clock::now();
    f();
    const double t = seconds_since(t0);
    best = std::min(best, t);
    total += t;
  }
  return best;
}

/// One back end, built and solved: the operator, its right-hand side, what it costs to move.
struct Built {
  std::optional<ExplicitStokesSystem> system;  ///< explicit: kept alive as solve_stokes does
  std::unique_ptr<LinearOperator> op;
  VectorX b;
  double apply_bytes = 0.0, op_bytes = -1.0, nnz = 0.0;
};

template <int Dim>
Built build_backend(Backend backend, const ViscousScene<Dim>& s,
                    const StressLayout<Dim>& layout, const StokesDofs& dofs) {
  Built built;
  if (backend == Backend::explicit_matrices) {
    built.system = assemble_explicit_stokes(s.grid, layout, s.weights, dofs, kDt, s.u_star);
    auto op = std::make_unique<SparseMatrixOperator>(built.system->A, dofs.null_space);
    built.b = built.system->b;
    built.nnz = static_cast<double>(op->matrix().nonZeros());
    built.apply_bytes = explicit_apply_bytes(*op, op->matrix());
    built.op_bytes = operator_bytes(*op);
    built.op = std::move(op);
  } else {
    auto op = std::make_unique<MatrixFreeStokesOperator<Dim>>(s.grid, layout, s.weights, dofs, kDt);
    built.b = op->rhs(s.u_star);
    built.op_bytes = operator_bytes(*op);
    built.op = std::move(op);
  }
  return built;
}

/// nnz of B (the matrix-free stencils) and the apply bytes: counted once, outside the timings.
template <int Dim>
void count_matrix_free(Built& built, const ViscousScene<Dim>& s) {
  const auto& op = static_cast<const MatrixFreeStokesOperator<Dim>&>(*built.op);
  double nnz_b = 0.0;
  for (int i = 0; i < op.size(); ++i) nnz_b += static_cast<double>(op.stencil(i).size());
  built.nnz = nnz_b;
  built.apply_bytes = matrix_free_apply_bytes(op, s.grid.num_faces(), nnz_b);
}

template <int Dim>
Record run_child(Backend backend, int n, double eta) {
  Record r;
  omp_set_num_threads(2);
  const ViscousScene<Dim> s = viscous_scene<Dim>(n, eta);
  const StressLayout<Dim> layout(StressGrid<Dim>(s.grid), StressForm::reduced);
  const StokesDofs dofs =
      select_stokes_dofs(s.grid, layout, s.weights, kDt, StokesUnknowns::pressure_and_stress);
  r["pressure_dofs"] = dofs.num_pressure();
  r["stress_dofs"] = dofs.num_stress();
  r["dofs"] = dofs.size();
  PcgSettings settings;
  settings.tolerance = kTolerance;
  settings.max_iterations = 100000;

  // peak memory of building and solving once, above what the scene itself holds
  const bool reset = reset_peak_rss();
  const double base = reset ? status_bytes("VmRSS:") : status_bytes("VmHWM:");
  r["peak_reset"] = reset ? 1 : 0;

  // set-up and solve with 2 threads
  auto t0 = Clock::now();
  Built built = build_backend<Dim>(backend, s, layout, dofs);
  r["setup_s"] = seconds_since(t0);
  VectorX x = VectorX::Zero(dofs.size());
  t0 = Clock::now();
  const PcgResult pcg = pcg_solve(*built.op, built.b, x, settings);
  r["pcg_s"] = seconds_since(t0);
  r["peak_bytes"] = status_bytes("VmHWM:") - base;
  r["iterations"] = pcg.iterations;
  r["converged"] = pcg.converged ? 1 : 0;
  r["residual"] = pcg.relative_residual;
  r["solve_s"] = r["setup_s"] + r["pcg_s"];
  r["iteration_s"] = r["pcg_s"] / std::max(1, pcg.iterations);

  // the apply alone, 2 then 1 thread (best of several)
  if (backend == Backend::matrix_free) count_matrix_free<Dim>(built, s);
  r["nnz"] = built.nnz;
  r["apply_bytes"] = built.apply_bytes;
  r["operator_bytes"] = built.op_bytes;
  VectorX y(dofs.size());
  const double budget = 0.4;
  r["apply_s"] = best_time([&] { built.op->apply(x, y); }, 5, budget);
  omp_set_num_threads(1);
  r["apply_s_1t"] = best_time([&] { built.op->apply(x, y); }, 3, budget);

  // the whole solve again with 1 thread
  built = Built{};
  t0 = Clock::now();
  built = build_backend<Dim>(backend, s, layout, dofs);
  r["setup_s_1t"] = seconds_since(t0);
  VectorX x1 = VectorX::Zero(dofs.size());
  t0 = Clock::now();
  const PcgResult pcg1 = pcg_solve(*built.op, built.b, x1, settings);
  r["pcg_s_1t"] = seconds_since(t0);
  r["iterations_1t"] = pcg1.iterations;
  r["solve_s_1t"] = r["setup_s_1t"] + r["pcg_s_1t"];
  return r;
}

// --- the coupled scene: eq. (24) with bodies and contacts -------------------------------------

/// The viscous scene with three dynamic bodies: a heavy box resting on the floor (0.1 dx into
/// it), a lighter box stacked on it and a ball floating at the surface; contacts as the rigid
/// world finds them (no friction), every body with one step of gravity in v*.
template <int Dim>
CoupledStepInput<Dim> coupled_scene(int n, double eta) {
  CoupledStepInput<Dim> in{MacGrid<Dim>(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), {}),
                           {},
                           kDt,
                           {},
                           {},
                           {},
                           {},
                           {}};
  const double dx = in.grid.dx();
  Vec<Dim> c0 = Vec<Dim>::Constant(0.5), h0 = Vec<Dim>::Constant(0.08);
  c0[0] = 0.3;
  c0[1] = h0[1] - 0.1 * dx;
  Vec<Dim> c1 = c0, h1 = Vec<Dim>::Constant(0.06);
  c1[1] = c0[1] + h0[1] + h1[1] - 0.05 * dx;
  Vec<Dim> c2 = Vec<Dim>::Constant(0.5);
  c2[0] = 0.7;
  c2[1] = 0.6;
  in.bodies = {monolith::testing::make_box<Dim>(c0, h0, 2000.0),
               monolith::testing::make_box<Dim>(c1, h1, 1500.0),
               monolith::testing::make_body<Dim>(
                   monolith::testing::round_spec<Dim>(ShapeType::sphere, c2, 0.1), 500.0)};
  BodyVec<Dim> gv = BodyVec<Dim>::Zero();
  gv[1] = -9.81 * kDt;
  for (RigidBody<Dim>& b : in.bodies) b.set_generalized_velocity(gv);
  std::array<BoundaryType, 2 * Dim> boundary;
  boundary.fill(BoundaryType::wall);
  boundary[3] = BoundaryType::open;
  in.solids = solid_weights<Dim>(in.grid, coupling_bodies(in.bodies), {}, boundary, 0.01 * dx);
  const SampleLattice<Dim> lattice = half_lattice(in.grid);
  VectorX phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) phi[k] = lattice.position(lattice.coord(k))[1] - 0.6;
  in.weights = coupled_stokes_weights<Dim>(in.grid, in.solids, phi, kRho, eta);
  in.u_star = viscous_scene_velocity(in.grid);
  Walls<Dim> walls = testing::unit_box_walls<Dim>();
  walls.is_wall[3] = false;  // open top
  in.contacts = detect_contacts<Dim>(in.bodies, walls, 0.2 * dx + 2.0 * kDt * 0.4);
  for (Contact<Dim>& c : in.contacts) c.friction = c.restitution = 0.0;
  in.contact_params.dt = kDt;
  in.contact_params.dx = dx;
  in.contact_params.restitution_threshold = 2.0 * 9.81 * kDt;
  return in;
}

/// One coupled step per back end: building eq. (24) (ContactSystem and MonolithicSystem), the
/// MLCP (26) operator's apply (MonolithicOperator), and a PVC-unified solve (MPRGP on the
/// Jacobi-scaled MLCP, as solve_coupled_step runs it), 2 threads; and how far the two back ends'
/// applies are apart on one vector.
template <int Dim>
void bench_coupled(int n, double eta) {
  omp_set_num_threads(2);
  const CoupledStepInput<Dim> in = coupled_scene<Dim>(n, eta);
  StaggeredSettings settings;
  settings.max_iterations = 1;
  settings.mprgp.tolerance = kTolerance;
  settings.mprgp.max_iterations = 20000;
  PvcUnifiedOptions options;
  options.jacobi_scaling = true;
  options.compute_updates = false;
  VectorX reference, probe;
  for (const Backend backend : {Backend::explicit_matrices, Backend::matrix_free}) {
    auto t0 = Clock::now();
    const ContactSystem<Dim> contacts(in.bodies, in.contacts, in.contact_params);
    const MonolithicSystem<Dim> system(in.grid, StressForm::reduced, in.weights, in.dt, in.u_star,
                                       in.bodies, in.solids, contacts, backend,
                                       StokesUnknowns::pressure_and_stress);
    const MonolithicOperator<Dim> op(system, settings.diagonal_boost);
    const double setup = seconds_since(t0);
    if (probe.size() == 0) probe = VectorX::LinSpaced(op.size(), -1.0, 1.0).array().sin();
    VectorX y(op.size());
    const double apply = best_time([&] { op.apply(probe, y); }, 5, 0.3);
    double difference = 0.0;
    if (reference.size() == 0)
      reference = y;
    else
      difference =
          (y - reference).lpNorm<Eigen::Infinity>() / reference.lpNorm<Eigen::Infinity>();
    t0 = Clock::now();
    const PvcUnifiedResult r = solve_pvc_unified(system, settings, options);
    const double solve = seconds_since(t0);
    std::printf("| %dD | %d^%d | %s | %d + %d + %d | %.3f | %.3f | %.3f | %ld%s | %.3f | %s |\n",
                Dim, n, Dim, enum_name(backend).c_str(), system.num_stress(), system.num_pressure(),
                system.num_contacts(), setup, 1e3 * apply,
                1e3 * solve / std::max(1L, r.mprgp_iterations), r.mprgp_iterations,
                r.converged ? "" : " (not converged)", solve,
                backend == Backend::explicit_matrices ? "" : format_number(difference, 2).c_str());
    std::fflush(stdout);
  }
}

// --- STREAM-style triad -----------------------------------------------------------------------

/// Best bandwidth (bytes/s) of a[i] = b[i] + s c[i] over `runs` runs with `threads` threads,
/// 24 bytes per element (STREAM's count: two reads, one write).
double triad_bandwidth(std::vector<double>& a, const std::vector<double>& b,
                       const std::vector<double>& c, int threads, int runs) {
  omp_set_num_threads(threads);
  const long n = static_cast<long>(a.size());
  const double scalar = 3.0;
  double best = 1e300;
  for (int r = 0; r < runs; ++r) {
    const auto t0 = Clock::now();
#pragma omp parallel for schedule(static)
    for (long i = 0; i < n; ++i) a[i] = b[i] + scalar * c[i];
    best = std::min(best, seconds_since(t0));
  }
  // keep the result observable
  if (a[n / 2] != b[n / 2] + scalar * c[n / 2]) std::printf("triad check failed\n");
  return 24.0 * static_cast<double>(n) / best;
}

// --- the parent -------------------------------------------------------------------------------

/// The 1-minute load average (/proc/loadavg): other processes on the same cores distort every
/// timing, the 2-thread ones most (each colour group is a parallel region that waits for both).
double load_average() {
  std::ifstream in("/proc/loadavg");
  double load = -1.0;
  in >> load;
  return load;
}

std::string self_path() {
  char buf[4096];
  const ssize_t len = readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  if (len <= 0) return "";
  buf[len] = '\0';
  return buf;
}

std::string format_record(const Record& r) {
  std::ostringstream out;
  out.precision(10);
  out << "RESULT";
  for (const auto& [k, v] : r) out << ' ' << k << '=' << v;
  return out.str();
}

/// Runs the child for one configuration and parses its RESULT line (empty on failure).
Record run_configuration(const std::string& exe, Backend backend, int dim, int n,
                         double eta) {
  const std::string cmd = "'" + exe + "' --child " + enum_name(backend) + " " + std::to_string(dim) + " " +
                          std::to_string(n) + " --eta " + std::to_string(eta);
  Record r;
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return r;
  char line[8192];
  while (std::fgets(line, sizeof(line), pipe)) {
    if (std::strncmp(line, "RESULT", 6) != 0) continue;
    std::istringstream in(line + 6);
    std::string item;
    while (in >> item) {
      const std::size_t eq = item.find('=');
      if (eq != std::string::npos) r[item.substr(0, eq)] = std::atof(item.c_str() + eq + 1);
    }
  }
  if (pclose(pipe) != 0) r.clear();
  return r;
}

struct Row {
  int dim = 0, n = 0;
  Backend backend = Backend::matrix_free;
  Record r;
};

const Row* find_row(const std::vector<Row>& rows, int dim, int n, Backend backend) {
  for (const Row& row : rows)
    if (row.dim == dim && row.n == n && row.backend == backend && !row.r.empty()) return &row;
  return nullptr;
}

}  // namespace

int main(int argc, char** argv) {
  bool quick = false;
  std::string csv_path = "bench_backends.csv", plot_path = "bench_backends.ppm";
  double eta = 1.0;
  std::string dims = "all";
  std::vector<std::string> child;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--quick") {
      quick = true;
    } else if (a == "--csv" && i + 1 < argc) {
      csv_path = argv[++i];
    } else if (a == "--plot" && i + 1 < argc) {
      plot_path = argv[++i];
    } else if (a == "--eta" && i + 1 < argc) {
      eta = std::atof(argv[++i]);
    } else if (a == "--dims" && i + 1 < argc) {
      dims = argv[++i];
    } else if (a == "--child" && i + 3 < argc) {
      child = {argv[i + 1], argv[i + 2], argv[i + 3]};
      i += 3;
    } else {
      std::fprintf(stderr,
                   "usage: bench_backends [--quick] [--csv PATH] [--plot PATH] [--eta ETA] "
                   "[--dims 2|3|all]\n");
      return 2;
    }
  }

  if (dims != "2" && dims != "3" && dims != "all") {
    std::fprintf(stderr, "bench_backends: --dims takes 2, 3 or all\n");
    return 2;
  }

  // hidden: one configuration in this process, printed as a RESULT line for the parent
  if (!child.empty()) {
    const int dim = std::atoi(child[1].c_str()), n = std::atoi(child[2].c_str());
    const std::optional<Backend> backend = parse_enum<Backend>(child[0]);
    if (!backend) {
      std::fprintf(stderr, "bench_backends: --child: unknown back end %s\n", child[0].c_str());
      return 2;
    }
    const Record r = dim == 2 ? run_child<2>(*backend, n, eta) : run_child<3>(*backend, n, eta);
    std::printf("%s\n", format_record(r).c_str());
    return 0;
  }

  const std::string exe = self_path();
  const auto t_start = Clock::now();
  std::printf(
      "bench_backends: eta = %g Pa s, dt = %g s, tolerance %g, threads 2 and 1%s; load "
      "average at start %.2f\n\n",
      eta, kDt, kTolerance, quick ? " (quick set)" : "", load_average());

  // the triad first, on arrays far larger than the last-level cache (3 x 128 MiB)
  double triad[3] = {0, 0, 0};
  {
    const std::size_t count = quick ? (std::size_t{1} << 23) : (std::size_t{1} << 24);
    std::vector<double> a(count), b(count), c(count);
    omp_set_num_threads(2);
#pragma omp parallel for schedule(static)
    for (long i = 0; i < static_cast<long>(count); ++i) {
      a[i] = 0.0;
      b[i] = 1.0 + 1e-9 * i;
      c[i] = 2.0 - 1e-9 * i;
    }
    triad[1] = triad_bandwidth(a, b, c, 1, 8);
    triad[2] = triad_bandwidth(a, b, c, 2, 8);
    std::printf(
        "STREAM-style triad on 3 x %zu doubles (%.0f MiB), best of 8: 1 thread %.2f GB/s, "
        "2 threads %.2f GB/s\n\n",
        count, 3.0 * 8.0 * count / (1 << 20), 1e-9 * triad[1], 1e-9 * triad[2]);
    std::fflush(stdout);
  }

  std::vector<int> sizes2 = quick ? std::vector<int>{64, 128} : std::vector<int>{128, 256, 512};
  std::vector<int> sizes3 = quick ? std::vector<int>{16, 24} : std::vector<int>{32, 48, 64};
  if (dims == "2") sizes3.clear();
  if (dims == "3") sizes2.clear();
  const std::vector<Backend> backends = {Backend::explicit_matrices, Backend::matrix_free};
  std::vector<Row> rows;

  std::printf(
      "Per configuration; \"a / b\" = 2 threads / 1 thread:\n\n"
      "| dim | grid | back end | DOFs (p + tau) | set-up s | apply ms | iteration ms | "
      "iterations | solve s (2 thr) | solve s (1 thr) | 1 thr / 2 thr | peak MiB | bytes/DOF | "
      "apply GB/s | apply / triad "
      "|\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  std::fflush(stdout);
  for (int dim : {2, 3}) {
    for (int n : dim == 2 ? sizes2 : sizes3) {
      for (const Backend backend : backends) {
        Row row{dim, n, backend, run_configuration(exe, backend, dim, n, eta)};
        if (row.r.empty()) {
          std::printf("| %dD | %d^%d | %s | child failed | | | | | | | | | | |\n", dim, n, dim,
                      enum_name(backend).c_str());
          continue;
        }
        Record& r = row.r;
        r["thread_ratio"] = r["solve_s_1t"] / r["solve_s"];
        r["iteration_s_1t"] = r["pcg_s_1t"] / std::max(1.0, r["iterations_1t"]);
        r["bytes_per_dof"] = r["peak_bytes"] / r["dofs"];
        r["apply_gbs"] = 1e-9 * r["apply_bytes"] / r["apply_s"];
        r["apply_gbs_1t"] = 1e-9 * r["apply_bytes"] / r["apply_s_1t"];
        r["triad_fraction"] = 1e9 * r["apply_gbs"] / triad[2];
        r["triad_fraction_1t"] = 1e9 * r["apply_gbs_1t"] / triad[1];
        std::printf(
            "| %dD | %d^%d | %s | %.0f (%.0f + %.0f) | %.3f | %.3f / %.3f | %.2f / %.2f | "
            "%.0f%s | %.3f | %.3f | %.2f | %.1f | %.0f | %.2f / %.2f | %.2f / %.2f |\n",
            dim, n, dim, enum_name(backend).c_str(), r["dofs"], r["pressure_dofs"], r["stress_dofs"],
            r["setup_s"], 1e3 * r["apply_s"], 1e3 * r["apply_s_1t"], 1e3 * r["iteration_s"],
            1e3 * r["iteration_s_1t"], r["iterations"],
            r["converged"] > 0 ? "" : " (not converged)", r["solve_s"], r["solve_s_1t"],
            r["thread_ratio"], r["peak_bytes"] / (1 << 20), r["bytes_per_dof"], r["apply_gbs"],
            r["apply_gbs_1t"], r["triad_fraction"], r["triad_fraction_1t"]);
        std::fflush(stdout);
        rows.push_back(row);
      }
    }
  }

  // explicit / matrix-free ratios per size
  std::printf(
      "\nExplicit / matrix-free (\"a / b\" = 2 threads / 1 thread):\n\n| dim | grid | per apply | "
      "per iteration | iterations | whole solve | set-up | peak memory |\n"
      "|---|---|---|---|---|---|---|---|\n");
  for (int dim : {2, 3}) {
    for (int n : dim == 2 ? sizes2 : sizes3) {
      const Row* e = find_row(rows, dim, n, Backend::explicit_matrices);
      const Row* m = find_row(rows, dim, n, Backend::matrix_free);
      if (!e || !m) continue;
      auto ratio = [&](const char* key) { return e->r.at(key) / m->r.at(key); };
      std::printf(
          "| %dD | %d^%d | %.2f / %.2f | %.2f / %.2f | %.2f | %.2f / %.2f | %.2f | %.2f |\n", dim,
          n, dim, ratio("apply_s"), ratio("apply_s_1t"), ratio("iteration_s"),
          ratio("iteration_s_1t"), ratio("iterations"), ratio("solve_s"), ratio("solve_s_1t"),
          ratio("setup_s"), ratio("peak_bytes"));
    }
  }

  // the goals of the back ends, on the 3D scene at 48^3 and above (the largest 3D grids of --quick)
  std::printf("\nGoals of the back ends, 3D at %s:\n\n",
              quick ? "the quick sizes (not the goal's 48^3)" : ">= 48^3");
  // value: explicit[key] / matrix-free[key], or matrix-free[key] alone when `ratio` is false
  auto goal = [&](const std::string& what, double target, const char* key, bool ratio) {
    for (int n : sizes3) {
      if (!quick && n < 48) continue;
      const Row* e = find_row(rows, 3, n, Backend::explicit_matrices);
      const Row* m = find_row(rows, 3, n, Backend::matrix_free);
      if (!m || (ratio && !e)) continue;
      const double value = ratio ? e->r.at(key) / m->r.at(key) : m->r.at(key);
      std::printf("- %s at %d^3: %.2f (goal >= %.2f): %s\n", what.c_str(), n, value, target,
                  value >= target ? "met" : "not met");
    }
  };
  goal("matrix-free faster per iteration than explicit (2 threads each), x", 2.0, "iteration_s",
       true);
  goal("matrix-free faster per whole solve than explicit (2 threads each), x", 1.5, "solve_s",
       true);
  goal("matrix-free 2 threads faster than 1 thread on the whole solve, x", 1.6, "thread_ratio",
       false);
  goal("matrix-free apply bandwidth / triad bandwidth (2 threads each)", 0.5, "triad_fraction",
       false);
  goal("explicit / matrix-free peak memory per DOF (goal: matrix-free at most a third)", 3.0,
       "bytes_per_dof", true);
  std::printf(
      "\nThe same with 1 thread each (less sensitive to other processes on the cores):\n\n");
  goal("matrix-free faster per iteration than explicit (1 thread each), x", 2.0, "iteration_s_1t",
       true);
  goal("matrix-free faster per whole solve than explicit (1 thread each), x", 1.5, "solve_s_1t",
       true);
  goal("matrix-free apply bandwidth / triad bandwidth (1 thread each)", 0.5, "triad_fraction_1t",
       false);

  // the coupled scene (bodies and contacts), both back ends
  std::printf(
      "\nCoupled step, eq. (24) with three dynamic bodies and their contacts (2 threads; "
      "MLCP apply and PVC-unified solve; difference = max |y_mf - y_ex| / max |y_ex| of one "
      "apply):\n\n| dim | grid | back end | tau + p + lambda | set-up s | apply ms | "
      "ms per MPRGP iteration | MPRGP iterations | solve s | difference |\n"
      "|---|---|---|---|---|---|---|---|---|---|\n");
  if (dims != "3") bench_coupled<2>(quick ? 64 : 128, eta);
  if (dims != "2") bench_coupled<3>(quick ? 16 : 24, eta);

  // CSV
  {
    std::ofstream csv(csv_path);
    const std::vector<std::string> keys = {
        "dofs",           "pressure_dofs", "stress_dofs",    "nnz",
        "setup_s",        "apply_s",       "apply_s_1t",     "iteration_s",
        "iteration_s_1t", "iterations",    "iterations_1t",  "converged",
        "residual",       "pcg_s",         "solve_s",        "setup_s_1t",
        "pcg_s_1t",       "solve_s_1t",    "thread_ratio",   "peak_bytes",
        "peak_reset",     "bytes_per_dof", "operator_bytes", "apply_bytes",
        "apply_gbs",      "apply_gbs_1t",  "triad_fraction", "triad_fraction_1t"};
    csv << "dim,n,backend";
    for (const std::string& k : keys) csv << ',' << k;
    csv << ",triad_gbs_1t,triad_gbs_2t\n";
    csv.precision(8);
    for (const Row& row : rows) {
      csv << row.dim << ',' << row.n << ',' << enum_name(row.backend);
      for (const std::string& k : keys) csv << ',' << row.r.at(k);
      csv << ',' << 1e-9 * triad[1] << ',' << 1e-9 * triad[2] << '\n';
    }
  }

  // plot: time per SSOR-PCG iteration against DOFs, one curve per back end and dimension with
  // 2 threads (thick) and the same with 1 thread (thin, crosses: the timings least disturbed by
  // other processes)
  {
    PlotSpec spec;
    spec.title = "time per SSOR-PCG iteration";
    spec.x_label = "unknowns (tau + p)";
    spec.y_label = "seconds per iteration";
    spec.log_x = spec.log_y = true;
    spec.width = 900;
    spec.height = 600;
    int index = 0;
    for (int dim : {2, 3}) {
      for (const Backend backend : backends) {
        const Rgb color = plot_palette(index++);
        for (const char* key : {"iteration_s", "iteration_s_1t"}) {
          const bool one = std::strcmp(key, "iteration_s_1t") == 0;
          PlotSeries series;
          series.label =
              std::to_string(dim) + "D " + enum_name(backend) + (one ? ", 1 thread" : ", 2 threads");
          for (const Row& row : rows) {
            if (row.dim != dim || row.backend != backend) continue;
            series.x.push_back(row.r.at("dofs"));
            series.y.push_back(row.r.at(key));
          }
          series.color = color;
          series.marker = one ? Marker::cross : dim == 2 ? Marker::circle : Marker::square;
          series.line_width = one ? 1.0 : 2.0;
          series.dash = backend == Backend::explicit_matrices ? 8.0 : 0.0;
          spec.series.push_back(series);
        }
      }
    }
    write_plot(spec, plot_path);
  }
  const double load = load_average();
  if (load > 1.5)
    std::printf(
        "\nload average %.2f on this machine: other processes share the cores, and the "
        "timings (the 2-thread ones most) are not the back ends' own\n",
        load);
  std::printf("\nwrote %s and %s; total %.0f s, load average at the end %.2f\n", csv_path.c_str(),
              plot_path.c_str(), seconds_since(t_start), load_average());
  return 0;
}
