#include "reference/particles/particles.hpp"

#include "reference/core/parallel.hpp"
#include "reference/grid/face_neighbour.hpp"

#include <omp.h>

#include <Eigen/IterativeLinearSolvers>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <iterator>
#include <limits>
#include <memory>
#include <random>
#include <tuple>
#include <type_traits>

#include "reference/grid/tiled_lattice.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/particles/slab_bounds.hpp"

namespace monolith {

namespace {

/// An allocator whose construction without arguments leaves a value unset (default-
/// initialisation) instead of zeroing it, for per-particle buffers that a parallel loop writes
/// whole before anything reads them: std::vector<T>(n) zero-fills its n values on the calling
/// thread first (the position correction's nine per-particle buffers were 0.8 ms of serial
/// memset per call on the 64^3 bunny at two threads; docs/benchmarks.md, two23).
template <class T>
struct UnsetAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = UnsetAllocator<U>;
  };
  UnsetAllocator() = default;
  template <class U>
  UnsetAllocator(const UnsetAllocator<U>&) noexcept {}
  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};
/// A vector whose sized constructor and resize leave the values unset (see UnsetAllocator):
/// every value must be written before it is read.
template <class T>
using UnsetVector = std::vector<T, UnsetAllocator<T>>;

/// Particles never rest closer than this to a solid surface (in units of dx).
constexpr double kSolidMargin = 0.05;
/// Particles stay at least this far inside a wall (in units of dx).
constexpr double kWallMargin = 0.01;
/// Largest distance, in cells, a particle moves in one advection substep (advect_particles): the
/// solid distance is checked after every substep, so solids thicker than this are not crossed.
constexpr double kAdvectionSubstep = 0.5;
/// Upper bound on the advection substeps of one particle in one step (a guard against a
/// pathological velocity; at CFL 3 the bound from kAdvectionSubstep is about 6-12).
constexpr int kMaxAdvectionSubsteps = 64;
/// Seeding jitter: width of the jitter window as a fraction of the sub-cell width, so the
/// stratified sub-lattice keeps a minimum spacing of half a sub-cell.
constexpr double kSeedJitter = 0.5;
/// Position correction (docs/particles.md): kernel support in rest spacings, relaxation time (s),
/// under-relaxation of the Jacobi step, tolerated compression before a particle is corrected,
/// and the largest step per call in rest spacings.
constexpr double kCorrectionSupport = 2.0;
constexpr double kCorrectionTime = 0.02;
constexpr double kCorrectionRelaxation = 0.5;
constexpr double kCorrectionSlack = 0.05;
constexpr double kCorrectionMaxStep = 0.25;
/// Pairs closer than this many rest spacings are pushed apart regardless of density.
constexpr double kCorrectionMinDistance = 0.5;
/// Density projection (docs/particles.md): fraction of the Poisson solution's gradient applied per
/// call, largest move per call in cells, relative tolerance of the conjugate gradient solve.
constexpr double kProjectionRelaxation = 1.0;
constexpr double kProjectionMaxStep = 0.25;
constexpr double kProjectionTolerance = 1e-4;
/// Cells whose hat-weighted liquid fraction T_c is below this lie on the air side of the particle
/// level set; there the density projection corrects an excess of particle volume only
/// (project_particle_density, docs/particles.md "Still water").
constexpr double kProjectionAirSide = 0.5;
/// Cells with T_c at or above this are full (not of the surface band) for the rule of the surface
/// band's deficits (SurfaceDeficits of project_particle_density).
constexpr double kProjectionFullCell = 0.999;
/// SurfaceDeficits::beyond_dead_band: the deficits of the surface band's liquid side are left alone
/// while the level set encloses at most kDeficitDeadBand more than the particle volume (relative),
/// corrected in full from kDeficitFullShare on, in proportion between (docs/particles.md,
/// "Sloshing"). In a sloshing tank the level set of the disordered surface settles at +0.2 % over
/// the particles when these deficits are not corrected; a splash's thin sheets take it past 1 %.
constexpr double kDeficitDeadBand = 0.003;
constexpr double kDeficitFullShare = 0.006;
/// Zhu & Bridson surface: kernel support in units of the particle spacing.
constexpr double kSurfaceSupport = 2.0;
/// Lattice points per axis of one particle's splat box held in a stack table (liquid_phi_on_lattice;
/// wider boxes, from particles far larger than a cell, compute their offsets point by point).
constexpr int kMaxSplatPoints = 16;

/// What differs between 2D and 3D for the particles: the rigid rotation of a seeded liquid, and
/// the calibrated particle radius of the surface reconstruction.
template <int Dim>
struct ParticleTraits;

template <>
struct ParticleTraits<2> {
  /// omega x r in the plane: omega (-r_y, r_x).
  static Vec<2> rotation_velocity(const std::vector<double>& w, const Vec<2>& r) {
    const double om = w.empty() ? 0.0 : w[0];
    return Vec<2>(-om * r[1], om * r[0]);
  }
  /// Gradient of that velocity: row a is grad v_a.
  static Mat<2> rotation_gradient(const std::vector<double>& w) {
    const double om = w.empty() ? 0.0 : w[0];
    Mat<2> c;
    c << 0.0, -om, om, 0.0;
    return c;
  }
  /// Particle radius / particle spacing, calibrated so a uniformly seeded block's zero level set
  /// lies on the block boundary and its enclosed area matches (docs/particles.md).
  static constexpr double surface_radius = 0.59;
};

template <>
struct ParticleTraits<3> {
  static Vec<3> rotation_velocity(const std::vector<double>& w, const Vec<3>& r) {
    const Vec<3> om = w.size() == 3 ? Vec<3>(w[0], w[1], w[2]) : Vec<3>::Zero();
    return om.cross(r);
  }
  /// The cross-product matrix [omega]_x: row a is grad (omega x r)_a.
  static Mat<3> rotation_gradient(const std::vector<double>& w) {
    const Vec<3> om = w.size() == 3 ? Vec<3>(w[0], w[1], w[2]) : Vec<3>::Zero();
    Mat<3> c;
    c << 0.0, -om[2], om[1], om[2], 0.0, -om[0], -om[1], om[0], 0.0;
    return c;
  }
  /// Particle radius / particle spacing (3D calibration, docs/particles.md).
  static constexpr double surface_radius = 0.58;
};

/// Uniform double in (0, 1) from a 32-bit Mersenne twister draw (portable across standard
/// libraries, unlike std::uniform_real_distribution).
double unit_draw(std::mt19937& rng) {
  return (static_cast<double>(rng()) + 0.5) / 4294967296.0;
}

int int_pow(int base, int exponent) {
  int r = 1;
  for (int i = 0; i < exponent; ++i) r *= base;
  return r;
}

/// Rest spacing of a particle: the side of the cube (square) holding its volume m / rho.
template <int Dim>
double particle_spacing(const Particles<Dim>& particles, std::size_t p, double dx) {
  const double rho = particles.density[p];
  if (!(rho > 0.0) || !(particles.mass[p] > 0.0)) return 0.5 * dx;
  return std::pow(particles.mass[p] / rho, 1.0 / Dim);
}

/// particle_spacing through the last particle's inputs: the power is taken again only when the
/// mass or the density differs from the last call's (the particles of one liquid mostly share
/// both, and equal inputs give the same bits), one per thread (pow was ~3 ms per frame of the
/// 64^3 viscous bunny's step on one thread)
template <int Dim>
class SpacingOf {
 public:
  SpacingOf(const Particles<Dim>& particles, double dx) : particles_(particles), dx_(dx) {}
  double operator()(std::size_t p) {
    const double m = particles_.mass[p], rho = particles_.density[p];
    if (!(m == mass_ && rho == density_)) {
      mass_ = m;
      density_ = rho;
      spacing_ = particle_spacing(particles_, p, dx_);
    }
    return spacing_;
  }

 private:
  const Particles<Dim>& particles_;
  double dx_;
  double mass_ = std::numeric_limits<double>::quiet_NaN();
  double density_ = std::numeric_limits<double>::quiet_NaN();
  double spacing_ = 0.0;
};

/// Moves a point inside a solid out along the solid's gradient to distance kSolidMargin dx.
template <int Dim>
void push_out_of_solids(const SolidField<Dim>& solids, double dx, Vec<Dim>& x) {
  if (solids.empty()) return;
  double d = solids.distance(x);
  if (d >= 0.0) return;
  const double target = kSolidMargin * dx;
  // a couple of projection steps (the gradient of a min/max SDF is only piecewise exact)
  for (int it = 0; it < 3 && d < 0.5 * target; ++it) {
    Vec<Dim> n = solids.gradient(x);
    const double len = n.norm();
    if (!(len > 0.0)) break;
    x += (target - d) * (n / len);
    d = solids.distance(x);
  }
}

/// Wraps periodic axes, pushes out of solids and keeps the point inside walls. Returns false
/// when the point left through an open face and removal is allowed.
template <int Dim>
bool settle_position(const MacGrid<Dim>& grid, const SolidField<Dim>& solids,
                     const std::array<BoundaryType, 2 * Dim>& boundary, bool allow_removal,
                     Vec<Dim>& x) {
  const double dx = grid.dx();
  x = grid.wrap_position(x);
  push_out_of_solids(solids, dx, x);
  const Box<Dim> box = grid.domain_box();
  const double m = kWallMargin * dx;
  for (int a = 0; a < Dim; ++a) {
    if (grid.periodic(a)) continue;
    const double lo = box.min()[a], hi = box.max()[a];
    // lower face
    if (boundary[2 * a] == BoundaryType::open) {
      if (x[a] < lo) {
        if (allow_removal) return false;
        x[a] = lo + m;
      }
    } else if (x[a] < lo + m) {
      x[a] = lo + m;
    }
    // upper face
    if (boundary[2 * a + 1] == BoundaryType::open) {
      if (x[a] > hi) {
        if (allow_removal) return false;
        x[a] = hi - m;
      }
    } else if (x[a] > hi - m) {
      x[a] = hi - m;
    }
  }
  x = grid.wrap_position(x);
  return true;
}

/// Minimum-image difference on periodic axes of the grid.
template <int Dim>
Vec<Dim> periodic_difference(const MacGrid<Dim>& grid, Vec<Dim> d) {
  for (int a = 0; a < Dim; ++a) {
    if (!grid.periodic(a)) continue;
    const double length = grid.cells()[a] * grid.dx();
    d[a] -= length * std::round(d[a] / length);
  }
  return d;
}

/// The per-axis stencils (MacGrid::axis_stencil) of the face lattice normal to `axis` at the
/// wrapped position xp: grid.stencil()'s set-up, axis by axis, for particles_to_grid and
/// pic_velocity_on_faces (which must sum the same weights bit for bit).
template <int Dim>
std::array<typename MacGrid<Dim>::AxisStencil, Dim> face_axis_stencils(const MacGrid<Dim>& grid,
                                                                       int axis,
                                                                       const Vec<Dim>& xp) {
  const Vec<Dim> shift = MacGrid<Dim>::face_shift(axis);
  const VecI<Dim> dims = grid.face_dims(axis);
  std::array<typename MacGrid<Dim>::AxisStencil, Dim> st;
  for (int b = 0; b < Dim; ++b)
    st[b] = grid.axis_stencil(b, (xp[b] - grid.origin()[b]) / grid.dx() - shift[b], dims[b]);
  return st;
}

/// Corner k of a stencil (bit b of k picks its sample on axis b): its weight, the product of the
/// axes' weights in axis order (grid.stencil()'s).
template <int Dim>
double corner_weight(const std::array<typename MacGrid<Dim>::AxisStencil, Dim>& st, int k) {
  double weight = 1.0;
  for (int b = 0; b < Dim; ++b) weight *= st[b].weight[(k >> b) & 1];
  return weight;
}

/// Corner k's index on the lattice of size dims (grid.stencil()'s).
template <int Dim>
int corner_index(const std::array<typename MacGrid<Dim>::AxisStencil, Dim>& st,
                 const VecI<Dim>& dims, int k) {
  int index = 0;
  for (int b = Dim - 1; b >= 0; --b) index = index * dims[b] + st[b].index[(k >> b) & 1];
  return index;
}

}  // namespace

// --- particles container -------------------------------------------------------------------------

template <int Dim>
void Particles<Dim>::remove_flagged(const std::vector<char>& flag) {
  std::size_t out = 0;
  for (std::size_t p = 0; p < x.size(); ++p) {
    if (p < flag.size() && flag[p]) continue;
    if (out != p) {
      x[out] = x[p];
      v[out] = v[p];
      c[out] = c[p];
      mass[out] = mass[p];
      density[out] = density[p];
      liquid[out] = liquid[p];
    }
    ++out;
  }
  x.resize(out);
  v.resize(out);
  c.resize(out);
  mass.resize(out);
  density.resize(out);
  liquid.resize(out);
}

// --- seeding -------------------------------------------------------------------------------------

/// Stratified seeding: each cell covered by the liquid's bounds is split into n^Dim sub-cells
/// (n = ceil(per_cell^(1/Dim)); per_cell of them drawn at random when per_cell is not a perfect
/// power), one particle per sub-cell jittered by +-kSeedJitter/2 of the sub-cell width. Kept:
/// inside the shape, not inside an earlier liquid, more than kSolidMargin dx from solids, inside
/// the domain. One std::mt19937(seed) drawn in a fixed order, so the result depends only on the
/// inputs.
template <int Dim>
Particles<Dim> seed_particles(const MacGrid<Dim>& grid, const std::vector<LiquidSpec>& liquids,
                              const std::vector<ShapePtr<Dim>>& liquid_shapes,
                              const SolidField<Dim>& solids, int per_cell, unsigned seed) {
  Particles<Dim> particles;
  if (per_cell <= 0) return particles;
  const double dx = grid.dx();
  const Box<Dim> domain = grid.domain_box();

  // stratified sub-lattice: n^Dim sub-cells per cell, per_cell of them used
  int n = 1;
  while (int_pow(n, Dim) < per_cell) ++n;
  const int sub_count = int_pow(n, Dim);
  std::vector<int> sub_order(sub_count);

  std::mt19937 rng(seed);
  const std::size_t count = std::min(liquids.size(), liquid_shapes.size());
  for (std::size_t l = 0; l < count; ++l) {
    const LiquidSpec& spec = liquids[l];
    const Shape<Dim>& shape = *liquid_shapes[l];
    const double mass = spec.density * grid.cell_volume() / per_cell;

    // cells covered by the shape's bounds clipped to the domain
    Box<Dim> bounds = shape.bounds().intersection(domain);
    if (bounds.isEmpty()) continue;
    VecI<Dim> c0, c1;
    for (int a = 0; a < Dim; ++a) {
      c0[a] = std::max(0, static_cast<int>(std::floor((bounds.min()[a] - domain.min()[a]) / dx)));
      c1[a] = std::min(grid.cells()[a] - 1,
                       static_cast<int>(std::ceil((bounds.max()[a] - domain.min()[a]) / dx)));
    }

    // rotation centre: the shape's centre, else the centre of its clipped bounds
    Vec<Dim> centre = bounds.center();
    if (static_cast<int>(spec.shape.center.size()) == Dim)
      for (int a = 0; a < Dim; ++a) centre[a] = spec.shape.center[a];
    Vec<Dim> v0 = Vec<Dim>::Zero();
    if (static_cast<int>(spec.velocity.size()) == Dim)
      for (int a = 0; a < Dim; ++a) v0[a] = spec.velocity[a];
    const Mat<Dim> grad_v = ParticleTraits<Dim>::rotation_gradient(spec.angular_velocity);

    // keep: inside this liquid, not claimed by an earlier liquid, clear of solids
    const auto keeps = [&](const Vec<Dim>& x) {
      if (!(shape.distance(x) < 0.0)) return false;
      for (std::size_t e = 0; e < l; ++e)
        if (liquid_shapes[e]->distance(x) < 0.0) return false;
      if (!solids.empty() && !(solids.distance(x) > kSolidMargin * dx)) return false;
      return domain.contains(x);
    };
    // (issue 20, setup19) The candidates are drawn serially in the order of the serial loop (the
    // draws do not depend on the tests: a candidate's sub-cell and jitter are drawn before it is
    // tested), tested on several threads in chunks (the distances, MeshSdf::exact for a mesh
    // liquid, were 37.5 % of Fig. 2's set-up at the paper's grid, on one thread), and the kept
    // ones appended in candidate order: the same particles in the same order for any team.
    std::vector<Vec<Dim>> candidates;
    std::vector<char> kept;
    const auto flush = [&] {
      const int m = static_cast<int>(candidates.size());
      kept.assign(m, 0);
#pragma omp parallel for schedule(dynamic, 64) num_threads(m >= 1024 ? process_threads() : 1)
      for (int i = 0; i < m; ++i) kept[i] = keeps(candidates[i]);
      for (int i = 0; i < m; ++i) {
        if (!kept[i]) continue;
        const Vec<Dim>& x = candidates[i];
        particles.x.push_back(x);
        particles.v.push_back(
            v0 + ParticleTraits<Dim>::rotation_velocity(spec.angular_velocity, x - centre));
        particles.c.push_back(grad_v);
        particles.mass.push_back(mass);
        particles.density.push_back(spec.density);
        particles.liquid.push_back(static_cast<int>(l));
      }
      candidates.clear();
    };
    constexpr std::size_t kChunk = std::size_t(1) << 16;

    // visit the cells (x fastest), one jittered particle per chosen sub-cell
    VecI<Dim> cell = c0;
    bool done = false;
    while (!done) {
      // choose per_cell of the sub-cells (all of them when per_cell is a perfect power)
      for (int s = 0; s < sub_count; ++s) sub_order[s] = s;
      if (per_cell < sub_count)
        for (int s = 0; s < per_cell; ++s) {
          const int pick = s + static_cast<int>(rng() % static_cast<unsigned>(sub_count - s));
          std::swap(sub_order[s], sub_order[pick]);
        }
      for (int k = 0; k < per_cell; ++k) {
        const VecI<Dim> sub = lattice_coord<Dim>(sub_order[k], VecI<Dim>::Constant(n));
        Vec<Dim> x;
        for (int a = 0; a < Dim; ++a) {
          const double jitter = kSeedJitter * (unit_draw(rng) - 0.5);
          x[a] = domain.min()[a] + (cell[a] + (sub[a] + 0.5 + jitter) / n) * dx;
        }
        candidates.push_back(x);
      }
      if (candidates.size() >= kChunk) flush();
      // next cell
      int a = 0;
      for (; a < Dim; ++a) {
        if (++cell[a] <= c1[a]) break;
        cell[a] = c0[a];
      }
      done = a == Dim;
    }
    flush();
  }
  return particles;
}

// --- APIC transfers ------------------------------------------------------------------------------

/// APIC particle-to-grid (Algorithm 1 line 1; Jiang et al. 2015, per velocity component a on
/// its face lattice):
///   m_f = sum_p w_fp m_p,  (m u)_f = sum_p w_fp m_p (v_pa + c_pa . (x_f - x_p)),
///   rho_f = sum_p w_fp m_p rho_p / m_f,
/// with w_fp the multilinear weights of face lattice a. Parallel as a scatter over fixed spatial
/// partitions: the faces are split into slabs of the last axis (one per thread, balanced by the
/// particles' cell layers), each thread visits the particles that reach its slab in particle
/// order and writes only its own faces. Every face therefore sums its contributions in particle
/// order, as the serial loop does: the same bits for any thread count, and no per-thread copies
/// of the grid.
/// The block of faces of particles_to_grid's zero and division passes (one parallel region
/// each, static blocks: a few blocks per thread on a 64^3 grid's 800k faces)
constexpr long kFaceBlock = 1L << 14;

template <int Dim>
void particles_to_grid(const Particles<Dim>& particles, const MacGrid<Dim>& grid, VectorX& u,
                       VectorX& face_mass, VectorX& face_density, DensitySpans* density_spans) {
  constexpr int kCorners = 1 << Dim;
  constexpr int kLast = Dim - 1;
  const int nf = grid.num_faces();
  const long np = static_cast<long>(particles.size());
  const int layers = grid.cells()[kLast];
  const bool wrap_last = grid.periodic(kLast);
  // each particle's cell layer along the last axis (clamped): its stencils reach face layers
  // layer - 1 .. layer + 1 of every component's lattice (wrapped on a periodic axis)
  // (counted per thread in the same loop and the counts added: integer sums, any split)
  std::vector<int> layer_of(np);
  std::vector<long> per_layer(layers + 1, 0);
  bool finite = true;
  {
    const int team = team_threads(np);
    std::vector<std::vector<long>> counts(team, std::vector<long>(layers + 1, 0));
#pragma omp parallel num_threads(team) reduction(&& : finite)
    {
      std::vector<long>& count = counts[omp_get_thread_num()];
#pragma omp for schedule(static)
      for (long p = 0; p < np; ++p) {
        const double s =
            (grid.wrap_position(particles.x[p])[kLast] - grid.origin()[kLast]) / grid.dx();
        finite = finite && std::isfinite(s);
        layer_of[p] = std::clamp(static_cast<int>(std::floor(s)), 0, layers - 1);
        ++count[layer_of[p] + 1];
      }
    }
    for (const auto& count : counts)
      for (int c = 0; c <= layers; ++c) per_layer[c] += count[c];
  }
  for (int c = 0; c < layers; ++c) per_layer[c + 1] += per_layer[c];
  // The accumulators live in the outputs. Only the face layers the particles reach are zeroed
  // before the sums (issue 20: at Fig. 2's paper grid the liquid spans a part of the box's
  // layers): the particles' cell layers [first, last] grown by particles_to_grid_zero_margin()
  // (1: the stencils' reach, as for the slabs below), every layer on a periodic last axis or
  // when a position is not finite. Each component lattice's layers along the last axis are a
  // contiguous index range [zero_begin[a], zero_end[a]); the faces outside it get their zeros
  // after the sums (u, the mass and the density are all 0 there, as the fill and the division
  // of a face without mass gave), so every face ends with the bits of the whole-grid fill.
  int first_layer = layers, last_layer = -1;
  for (int c = 0; c < layers; ++c)
    if (per_layer[c + 1] > per_layer[c]) {
      first_layer = std::min(first_layer, c);
      last_layer = c;
    }
  // (a component lattice's face layers within `margin` of the particles' cell layers, as an
  // index range [begin, end); every layer on a periodic last axis or for a non-finite position)
  const auto layer_range = [&](int a, int margin) {
    const VecI<Dim> dims = grid.face_dims(a);
    const long per = dims.prod() / dims[kLast];  // faces per layer
    int lo = 0, hi = dims[kLast] - 1;
    if (!wrap_last && finite) {
      lo = std::max(first_layer - margin, 0);
      hi = std::min(last_layer + margin, dims[kLast] - 1);
    }
    const long offset = grid.face_offset(a);
    return lo <= hi ? std::pair<long, long>{offset + lo * per, offset + (hi + 1) * per}
                    : std::pair<long, long>{offset, offset};
  };
  std::array<long, Dim> zero_begin{}, zero_end{};
  for (int a = 0; a < Dim; ++a)
    std::tie(zero_begin[a], zero_end[a]) = layer_range(a, particles_to_grid_zero_margin());
  // (kern22) the faces' densities are written on `written` only: the layers the diagonal of P
  // reads (kDensityReadLayers around the particles' layers, which hold the zeroed ranges above)
  // and the faces the last call wrote; the rest holds the caller's value already
  if (density_spans) {
    density_spans->layers.clear();
    for (int a = 0; a < Dim; ++a) {
      const int margin = std::max(kDensityReadLayers, particles_to_grid_zero_margin());
      const auto range = layer_range(a, margin);
      if (range.first < range.second) density_spans->layers.push_back(range);
    }
    density_spans->written = density_spans->known
                                 ? union_of_ranges(density_spans->layers, density_spans->kept)
                                 : FaceIndexRanges{{0L, static_cast<long>(nf)}};
  }
  const FaceIndexRanges* density_written = density_spans ? &density_spans->written : nullptr;
  // (the ranges of all components zeroed in one parallel region: fixed blocks of the ranges
  // laid end to end; a region per range and vector cost more than the zeros on two threads)
  for (VectorX* v : {&u, &face_mass, &face_density}) v->resize(nf);
  long zero_total = 0;
  for (int a = 0; a < Dim; ++a) zero_total += zero_end[a] - zero_begin[a];
  {
    const long blocks = (zero_total + kFaceBlock - 1) / kFaceBlock;
#pragma omp parallel for schedule(static) num_threads(team_threads(zero_total))
    for (long b = 0; b < blocks; ++b) {
      // block b covers [b, b + 1) kFaceBlock of the ranges laid end to end
      long skip = b * kFaceBlock, left = std::min(kFaceBlock, zero_total - skip);
      for (int a = 0; a < Dim && left > 0; ++a) {
        const long length = zero_end[a] - zero_begin[a];
        if (skip >= length) {
          skip -= length;
          continue;
        }
        const long begin = zero_begin[a] + skip, count = std::min(left, length - skip);
        for (VectorX* v : {&u, &face_mass, &face_density})
          std::fill(v->data() + begin, v->data() + begin + count, 0.0);
        left -= count;
        skip = 0;
      }
    }
  }
  const int threads = std::max(1, std::min(process_threads(), layers));
  // slab t owns the face layers [first[t], first[t + 1]); the face lattices along the last axis
  // have at most layers + 1 samples. A particle of cell layer c writes face layers c - 1 .. c + 1
  // (as `reaches` below has it): the bounds balance the particles each slab visits, the layers
  // beside a bound counted on both sides (slab_bounds.hpp)
  std::vector<int> first;
  {
    std::vector<long> count(layers);
    for (int c = 0; c < layers; ++c) count[c] = per_layer[c + 1] - per_layer[c];
    first = balanced_slab_bounds(count, layers + 1, threads, -1, 1);
  }

#pragma omp parallel num_threads(threads)
  {
    const int t = omp_get_thread_num();
    const int nt = omp_get_num_threads();
    // a team smaller than asked for: thread t covers the slabs t, t + nt, ...
    for (int slab = t; slab < threads; slab += nt) {
      const int lo = first[slab], hi = first[slab + 1];
      if (lo >= hi) continue;
      auto owned = [&](int k) { return k >= lo && k < hi; };
      auto reaches = [&](int c) {
        for (int d = -1; d <= 1; ++d) {
          int k = c + d;
          if (wrap_last) k = (k + layers) % layers;  // the periodic face lattice has `layers`
          if (owned(k)) return true;
        }
        return false;
      };
      const Vec<Dim>& origin = grid.origin();
      const double dx = grid.dx();
      for (long p = 0; p < np; ++p) {
        if (!reaches(layer_of[p])) continue;
        const Vec<Dim> xp = grid.wrap_position(particles.x[p]);
        const double mp = particles.mass[p];
        for (int a = 0; a < Dim; ++a) {
          const Vec<Dim> shift = MacGrid<Dim>::face_shift(a);
          const VecI<Dim> dims = grid.face_dims(a);
          const int offset = grid.face_offset(a);
          // grid.stencil() per axis: the corners' indices, weights and, per axis, the face
          // sample's coordinate minus the particle's (face_center's arithmetic per component)
          const auto st = face_axis_stencils(grid, a, xp);
          std::array<std::array<double, 2>, Dim> rel;
          for (int b = 0; b < Dim; ++b)
            for (int bit = 0; bit < 2; ++bit)
              rel[b][bit] =
                  (origin[b] + (static_cast<double>(st[b].index[bit]) + shift[b]) * dx) - xp[b];
          for (int k = 0; k < kCorners; ++k) {
            const double weight = corner_weight<Dim>(st, k);
            if (weight == 0.0 || !owned(st[kLast].index[(k >> kLast) & 1])) continue;
            const int index = corner_index<Dim>(st, dims, k);
            // affine velocity at the face sample (minimum image on periodic axes)
            Vec<Dim> rel_k;
            for (int b = 0; b < Dim; ++b) rel_k[b] = rel[b][(k >> b) & 1];
            const Vec<Dim> d = periodic_difference(grid, rel_k);
            const double vel = particles.v[p][a] + particles.c[p].row(a).dot(d);
            const int f = offset + index;
            face_mass[f] += weight * mp;
            u[f] += weight * mp * vel;
            face_density[f] += weight * mp * particles.density[p];
          }
        }
      }
    }
  }

  // velocities and densities from the sums (in the zeroed ranges: no face outside them has
  // mass), zeros elsewhere. One parallel region over all faces in fixed blocks (the ranges are
  // ascending and disjoint, each within its component's lattice): a block divides where it
  // overlaps a range and writes zeros to all three vectors between them; every face gets what
  // the division or the fill of its own component gave, whatever the split
  {
    const long blocks = (nf + kFaceBlock - 1) / kFaceBlock;
    const auto divide = [&](long begin, long end) {
      for (long f = begin; f < end; ++f) {
        const double m = face_mass[f];
        if (m > 0.0) {
          u[f] = (0.0 + u[f]) / m;
          face_density[f] = (0.0 + face_density[f]) / m;
        } else {
          u[f] = 0.0;
          face_density[f] = 0.0;
        }
      }
    };
    const auto zeros = [&](long begin, long end) {
      if (begin >= end) return;
      for (VectorX* v : {&u, &face_mass})
        std::fill(v->data() + begin, v->data() + end, 0.0);
      if (!density_written) {
        std::fill(face_density.data() + begin, face_density.data() + end, 0.0);
        return;
      }
      // (the densities' zeros on the written faces only)
      for (const auto& [b, e] : *density_written) {
        const long z0 = std::max(begin, b), z1 = std::min(end, e);
        if (z0 < z1) std::fill(face_density.data() + z0, face_density.data() + z1, 0.0);
      }
    };
#pragma omp parallel for schedule(static) num_threads(team_threads(nf))
    for (long b = 0; b < blocks; ++b) {
      const long b0 = b * kFaceBlock, b1 = std::min<long>(nf, b0 + kFaceBlock);
      long cursor = b0;
      for (int a = 0; a < Dim; ++a) {
        const long r0 = std::max<long>(b0, zero_begin[a]), r1 = std::min<long>(b1, zero_end[a]);
        if (r0 >= r1) continue;
        zeros(cursor, r0);
        divide(r0, r1);
        cursor = r1;
      }
      zeros(cursor, b1);
    }
  }
}

FaceIndexRanges union_of_ranges(const FaceIndexRanges& a, const FaceIndexRanges& b) {
  FaceIndexRanges all;
  all.reserve(a.size() + b.size());
  std::merge(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(all));
  FaceIndexRanges joined;
  for (const auto& r : all) {
    if (r.first >= r.second) continue;
    if (!joined.empty() && r.first <= joined.back().second)
      joined.back().second = std::max(joined.back().second, r.second);
    else
      joined.push_back(r);
  }
  return joined;
}

int& particles_to_grid_zero_margin() {
  static int margin = 1;
  return margin;
}

/// The PIC sums of particles_to_grid on the listed faces only. A particle in cell c (its wrapped
/// position's cell, clamped to the grid or wrapped on a periodic axis) reaches, on every face
/// lattice, samples whose coordinate lies within c - 1 .. c + 1 along every axis (axis_stencil:
/// i0 = floor(q - shift) with shift 0 or 1/2, clamped), so the particles that reach a listed
/// face sit in the 3^Dim cells around the face's coordinate (wrapped on periodic axes). Those
/// particles are found in parallel, then summed serially in particle order with the stencils,
/// weights and products of particles_to_grid: each listed face gets P2G's sums, bit for bit.
template <int Dim>
void pic_velocity_on_faces(const Particles<Dim>& particles, const MacGrid<Dim>& grid,
                           const std::vector<int>& faces, std::vector<double>& pic) {
  constexpr int kCorners = 1 << Dim;
  constexpr int kAround = Dim == 2 ? 9 : 27;
  const std::size_t nl = faces.size();
  pic.assign(nl, 0.0);
  if (nl == 0) return;
  const VecI<Dim>& cells = grid.cells();
  // the cells around the listed faces, sorted
  std::vector<int> near_cells;
  near_cells.reserve(nl * kAround);
  for (const int f : faces) {
    const VecI<Dim> coord = grid.face_coord(f).second;
    for (int k = 0; k < kAround; ++k) {
      VecI<Dim> c;
      bool inside = true;
      int rest = k;
      for (int b = 0; b < Dim; ++b, rest /= 3) {
        c[b] = coord[b] + rest % 3 - 1;
        if (grid.periodic(b))
          c[b] = ((c[b] % cells[b]) + cells[b]) % cells[b];
        else if (c[b] < 0 || c[b] >= cells[b])
          inside = false;
      }
      if (inside) near_cells.push_back(grid.cell_index(c));
    }
  }
  std::sort(near_cells.begin(), near_cells.end());
  near_cells.erase(std::unique(near_cells.begin(), near_cells.end()), near_cells.end());

  // the particles in those cells (flags in parallel, the list in particle order)
  const long np = static_cast<long>(particles.size());
  const Vec<Dim>& origin = grid.origin();
  const double dx = grid.dx();
  std::vector<char> near(np, 0);
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (long p = 0; p < np; ++p) {
    const Vec<Dim> xp = grid.wrap_position(particles.x[p]);
    VecI<Dim> c;
    for (int b = 0; b < Dim; ++b) {
      // (on a periodic axis the quotient of a wrapped position can round up to cells[b])
      const int q = static_cast<int>(std::floor((xp[b] - origin[b]) / dx));
      c[b] = grid.periodic(b) ? ((q % cells[b]) + cells[b]) % cells[b]
                              : std::clamp(q, 0, cells[b] - 1);
    }
    near[p] = std::binary_search(near_cells.begin(), near_cells.end(), grid.cell_index(c));
  }

  // the sums, in particle order (particles_to_grid's loop body for the listed faces)
  std::vector<double> mass(nl, 0.0);
  for (long p = 0; p < np; ++p) {
    if (!near[p]) continue;
    const Vec<Dim> xp = grid.wrap_position(particles.x[p]);
    const double mp = particles.mass[p];
    for (int a = 0; a < Dim; ++a) {
      const VecI<Dim> dims = grid.face_dims(a);
      const int offset = grid.face_offset(a);
      const auto st = face_axis_stencils(grid, a, xp);
      for (int k = 0; k < kCorners; ++k) {
        const double weight = corner_weight<Dim>(st, k);
        if (weight == 0.0) continue;
        const int f = offset + corner_index<Dim>(st, dims, k);
        const auto it = std::lower_bound(faces.begin(), faces.end(), f);
        if (it == faces.end() || *it != f) continue;
        const std::size_t i = static_cast<std::size_t>(it - faces.begin());
        mass[i] += weight * mp;
        pic[i] += weight * mp * particles.v[p][a];
      }
    }
  }
  for (std::size_t i = 0; i < nl; ++i)
    pic[i] = mass[i] > 0.0 ? (0.0 + pic[i]) / mass[i] : 0.0;
}

/// APIC grid-to-particle (first half of Algorithm 1 line 14; Jiang et al. 2015): v_pa = sum_f w_fp
/// u_f, c_pa = sum_f grad w_fp u_f (row a of c is the gradient of component a; exact for affine
/// fields away from walls).
template <int Dim>
long grid_to_particles(Particles<Dim>& particles, const MacGrid<Dim>& grid, const VectorX& u,
                       std::vector<char>* unread) {
  constexpr int kCorners = 1 << Dim;
  const long np = static_cast<long>(particles.size());
  // with `unread`: a second pass (flags given) redoes the flagged particles only
  const bool again = unread != nullptr && static_cast<long>(unread->size()) == np;
  if (unread != nullptr && !again) unread->assign(np, 0);
  long flagged = 0;
#pragma omp parallel for schedule(static) reduction(+ : flagged) num_threads(process_threads())
  for (long p = 0; p < np; ++p) {
    if (again && !(*unread)[p]) continue;
    std::array<int, kCorners> idx;
    std::array<double, kCorners> w;
    std::array<Vec<Dim>, kCorners> g;
    const Vec<Dim> xp = grid.wrap_position(particles.x[p]);
    Vec<Dim> v = Vec<Dim>::Zero();
    Mat<Dim> c = Mat<Dim>::Zero();
    for (int a = 0; a < Dim; ++a) {
      const int offset = grid.face_offset(a);
      grid.stencil(xp, MacGrid<Dim>::face_shift(a), grid.face_dims(a), idx, w, &g);
      for (int k = 0; k < kCorners; ++k) {
        const double uf = u[offset + idx[k]];
        v[a] += w[k] * uf;
        c.row(a) += uf * g[k].transpose();
      }
    }
    particles.v[p] = v;
    particles.c[p] = c;
    if (unread != nullptr) {
      // a NaN face (one the caller marked unreadable) makes v or c NaN
      const bool bad = !(v.allFinite() && c.allFinite());
      (*unread)[p] = bad;
      flagged += bad;
    }
  }
  return flagged;
}

// --- extrapolation -------------------------------------------------------------------------------

/// extrapolate_velocity with optional boxes (both null: every face) outside which valid is 0.
template <int Dim>
void extrapolate_velocity_in(const MacGrid<Dim>& grid, VectorX& u, std::vector<char>& valid,
                             int layers, const std::array<VecI<Dim>, Dim>* box_lo,
                             const std::array<VecI<Dim>, Dim>* box_hi);

/// Breadth-first extrapolation: per layer, every invalid face with valid same-axis neighbours
/// (+-1 along each axis, wrapped on periodic axes) of the previous layer takes their average.
/// The first layer visits the invalid neighbours of the given valid faces; a later layer can fill only faces next to those the
/// layer before it filled (any other invalid face has no valid neighbour, or would have been
/// filled earlier), so it visits just those: work in proportion to the band, not the box.
template <int Dim>
void extrapolate_velocity(const MacGrid<Dim>& grid, VectorX& u, std::vector<char>& valid,
                          int layers) {
  extrapolate_velocity_in<Dim>(grid, u, valid, layers, nullptr, nullptr);
}

template <int Dim>
void extrapolate_velocity(const MacGrid<Dim>& grid, VectorX& u, std::vector<char>& valid,
                          int layers, const std::array<VecI<Dim>, Dim>& box_lo,
                          const std::array<VecI<Dim>, Dim>& box_hi) {
  extrapolate_velocity_in<Dim>(grid, u, valid, layers, &box_lo, &box_hi);
}

template <int Dim>
void extrapolate_velocity_in(const MacGrid<Dim>& grid, VectorX& u, std::vector<char>& valid,
                             int layers, const std::array<VecI<Dim>, Dim>* box_lo,
                             const std::array<VecI<Dim>, Dim>* box_hi) {
  const int nf = grid.num_faces();
  valid.resize(nf, 0);
  // the same-axis neighbours of face f (each once, in a fixed order), -1 where there is none
  auto neighbours = [&](int f, std::array<int, 2 * Dim>& nb) {
    const auto [axis, coord] = grid.face_coord(f);
    const VecI<Dim> dims = grid.face_dims(axis);
    for (int b = 0; b < Dim; ++b)
      for (int s = 0; s < 2; ++s)
        nb[2 * b + s] = face_along(grid, axis, dims, coord, f, b, s == 0 ? -1 : 1);
  };
  // The flags during the layers: 0 (not filled), 1 (valid before the layer before last), or the
  // stamp of the layer that filled the face, stamp(L) = 2 + L % 3: the faces the current layer
  // fills, those of the layer before (its sources) and those of the one before that (made 1 by
  // their filler during the current layer) are told apart. Within a layer a face's flag changes
  // only between values that mean the same to every reader of that layer (0 -> stamp(L): not
  // valid at the layer's start, not a source; stamp(L - 2) -> 1: valid, not a source), so the
  // flags are read and written with relaxed atomic byte accesses and need no barrier.
  const auto flag = [&](int g) { return __atomic_load_n(&valid[g], __ATOMIC_RELAXED); };
  const auto set_flag = [&](int g, char v) { __atomic_store_n(&valid[g], v, __ATOMIC_RELAXED); };
  const auto stamp = [](int layer) { return static_cast<char>(2 + layer % 3); };
  // the average of the neighbours valid at the start of the layer whose stamp is `current` (flag
  // neither 0 nor `current`) of an invalid face
  auto average = [&](int f, char current, double& value) {
    std::array<int, 2 * Dim> nb;
    neighbours(f, nb);
    double sum = 0.0;
    int count = 0;
    for (int g : nb) {
      if (g < 0) continue;
      const char v = flag(g);
      if (v == 0 || v == current) continue;
      sum += u[g];
      ++count;
    }
    if (count == 0) return false;
    value = sum / count;
    return true;
  };
  // The candidates of a layer: the invalid neighbours of its sources (the given valid faces for
  // the first layer, the faces the layer before filled for the others), each once. A candidate g
  // is listed by the first of its neighbours (in g's neighbour order) that is a source, at that
  // neighbour's first mention of g, so the sources can be visited on several threads without
  // sorting or a shared mark: the union of the threads' lists is the same set of faces for any
  // split of the sources, and only g's lister fills g. The order of the lists changes no value
  // (every average of a layer reads the validity at the layer's start, and each candidate is
  // written once).
  // the candidates that source f lists, appended to out
  const auto list_candidates = [&](int f, auto&& is_source, std::vector<int>& out) {
    std::array<int, 2 * Dim> nb, nb_of_g;
    neighbours(f, nb);
    for (int k = 0; k < 2 * Dim; ++k) {
      const int g = nb[k];
      // (a face another thread fills in the next layer meanwhile is not f's: it has another
      // lister, so skipping it lists the same faces)
      if (g < 0 || flag(g) != 0) continue;
      bool first_mention = true;
      for (int l = 0; l < k && first_mention; ++l) first_mention = nb[l] != g;
      if (!first_mention) continue;
      neighbours(g, nb_of_g);
      int first_source = -1;
      for (int l = 0; l < 2 * Dim && first_source < 0; ++l)
        if (nb_of_g[l] >= 0 && is_source(nb_of_g[l])) first_source = nb_of_g[l];
      if (first_source == f) out.push_back(g);
    }
  };
  // The sources of the first layer: beside any valid face; with boxes (issue 20, band17) the
  // boxes' faces only (every flag outside them is 0: no source there, nothing to make 0 / 1),
  // row by row.
  std::vector<std::pair<int, int>> rows;  // (first face, faces in the row)
  long work = nf;
  if (box_lo != nullptr) {
    work = 0;
    for (int axis = 0; axis < Dim; ++axis) {
      const VecI<Dim> lo = (*box_lo)[axis], hi = (*box_hi)[axis];
      if ((lo.array() > hi.array()).any()) continue;
      VecI<Dim> row_dims = hi - lo + VecI<Dim>::Ones();
      const int nx = row_dims[0];
      row_dims[0] = 1;
      for (int r = 0; r < row_dims.prod(); ++r)
        rows.push_back({grid.face_index(axis, lo + lattice_coord<Dim>(r, row_dims)), nx});
      work += static_cast<long>(row_dims.prod()) * nx;
    }
  } else {
    rows.push_back({0, nf});  // every face as one row
  }
  const int count = static_cast<int>(rows.size());
  // Every layer in one parallel region with one barrier per layer (issue 16, two22: a region per
  // pass made three regions per layer, 35-50 layers per landed step of the 64^3 viscous bunny,
  // each region waking the sleeping thread). Each thread holds its own part of a layer: its
  // candidates and the faces it filled. Per layer L: (a) each thread averages its candidates
  // (the validity and u at the layer's start), writes each filled one's u and stamp(L), and
  // makes its faces of layer L - 2 valid (1); barrier; (c) the faces layer L filled, all
  // threads' taken as one list in part order and split evenly, list the next layer's candidates
  // into the lister's part. A candidate's u is read by no average of its own layer (it is not
  // valid at the layer's start), and (c) reads flags only, each test meaning the same under the
  // changes (a) of the next layer makes meanwhile: no second barrier. The stop (nothing filled)
  // reads every part's count after the barrier: the same decision on every thread. Each face is
  // written by one thread, so the values are those of the serial pass for any team.
  const int team = team_threads(work);
  struct Part {
    std::vector<int> candidates;
    std::array<std::vector<int>, 3> fills;  // the faces filled in layer L, at L % 3
  };
  std::vector<Part> part(team);
#pragma omp parallel num_threads(team)
  {
    const int threads = omp_get_num_threads();
    const int me = omp_get_thread_num();
    Part& mine = part[me];
    // the first layer's sources: the given flags made 0 / 1 first, then (after the barrier) the
    // candidates listed over static blocks of rows (the sources are the faces flagged 1: a
    // stamp is a face another thread filled meanwhile)
    const auto given_valid = [&](int g) { return flag(g) == 1; };
    if (box_lo != nullptr) {
#pragma omp for schedule(static)
      for (int r = 0; r < count; ++r)
        for (int f = rows[r].first; f < rows[r].first + rows[r].second; ++f)
          if (valid[f] != 0 && valid[f] != 1) valid[f] = 1;
#pragma omp for schedule(static) nowait
      for (int r = 0; r < count; ++r)
        for (int f = rows[r].first; f < rows[r].first + rows[r].second; ++f)
          if (flag(f) == 1) list_candidates(f, given_valid, mine.candidates);
    } else {
#pragma omp for schedule(static)
      for (int f = 0; f < nf; ++f)
        if (valid[f] != 0 && valid[f] != 1) valid[f] = 1;
#pragma omp for schedule(static) nowait
      for (int f = 0; f < nf; ++f)
        if (flag(f) == 1) list_candidates(f, given_valid, mine.candidates);
    }
    for (int layer = 0; layer < layers; ++layer) {
      // (a) this thread's candidates: averages and writes; its faces of layer - 2 made valid
      const char current = stamp(layer);
      std::vector<int>& filled = mine.fills[layer % 3];
      std::vector<int>& older = mine.fills[(layer + 1) % 3];  // those of layer - 2
      for (const int f : older) set_flag(f, 1);
      older.clear();
      filled.clear();
      for (const int c : mine.candidates) {
        double value;
        if (!average(c, current, value)) continue;
        u[c] = value;
        set_flag(c, current);
        filled.push_back(c);
      }
#pragma omp barrier
      long filled_total = 0;
      for (const Part& other : part) filled_total += static_cast<long>(other.fills[layer % 3].size());
      if (filled_total == 0 || layer + 1 == layers) break;
      // (c) the next layer's candidates, from this thread's even share of the faces just filled
      mine.candidates.clear();
      const long lo = filled_total * me / threads, hi = filled_total * (me + 1) / threads;
      long at = 0;  // the index of part q's first face in the joined list
      for (const Part& q : part) {
        const std::vector<int>& list = q.fills[layer % 3];
        const long size = static_cast<long>(list.size());
        const long from = std::max(lo, at), to = std::min(hi, at + size);
        for (long k = from; k < to; ++k)
          list_candidates(list[k - at], [&](int g) { return flag(g) == current; },
                          mine.candidates);
        at += size;
      }
    }
    // (after the last layer's barrier nothing reads the flags: every stamp made 1)
    for (const auto& list : mine.fills)
      for (const int f : list) set_flag(f, 1);
  }
}

template <int Dim>
void divergence_free_air_velocity(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                  const VectorX& phi, const VectorX& fluid_face,
                                  const std::vector<char>& trusted,
                                  const std::vector<char>& valid, int layers,
                                  double liquid_reach, VectorX& u) {
  const int nc = grid.num_cells();
  const double dx = grid.dx();
  const double reach = layers * dx;
  // the air cells of the band (and the liquid's surface cells within liquid_reach), nearest the
  // liquid first (ties in cell order)
  const double lowest = liquid_reach > 0.0 ? -liquid_reach * dx : 0.0;
  std::vector<std::pair<double, int>> band = gather_in_order<std::pair<double, int>>(
      nc, [&](int c, std::vector<std::pair<double, int>>& out) {
        const VecI<Dim> ci = grid.cell_coord(c);
        const double p = phi[lattice.index(2 * ci + VecI<Dim>::Ones())];
        if (p > lowest && p < reach) out.emplace_back(p, c);
      });
  std::sort(band.begin(), band.end());
  for (const auto& [p, c] : band) {
    (void)p;
    const VecI<Dim> ci = grid.cell_coord(c);
    const VecI<Dim> li = 2 * ci + VecI<Dim>::Ones();
    // the level set's gradient at the centre (central differences on the half lattice)
    int axis = 0;
    double largest = -1.0, sign = 1.0;
    for (int a = 0; a < Dim; ++a) {
      VecI<Dim> lo = li, hi = li;
      lo[a] -= 1;
      hi[a] += 1;
      const double g = phi[lattice.index(hi)] - phi[lattice.index(lo)];
      if (std::abs(g) > largest) {
        largest = std::abs(g);
        axis = a;
        sign = g >= 0.0 ? 1.0 : -1.0;
      }
    }
    // the cell's faces: minus and plus side per axis
    std::array<std::array<int, 2>, Dim> face;
    bool cut = false;
    for (int a = 0; a < Dim; ++a)
      for (int s = 0; s < 2; ++s) {
        VecI<Dim> fc = ci;
        fc[a] += s;
        if (grid.periodic(a) && fc[a] == grid.cells()[a]) fc[a] = 0;
        face[a][s] = grid.face_index(a, fc);
        const double w = fluid_face[face[a][s]];
        // a face cut by a solid, or one the extrapolation did not reach (stale), leaves the
        // cell as it is
        if ((w > 0.0 && w < 1.0) || (w > 0.0 && !valid[face[a][s]])) cut = true;
      }
    if (cut) continue;
    const int outer = face[axis][sign > 0.0 ? 1 : 0];
    if (trusted[outer] || !(fluid_face[outer] > 0.0)) continue;
    // sum over the other faces of the outward flux; the outer face closes it
    double flux = 0.0;
    for (int a = 0; a < Dim; ++a)
      for (int s = 0; s < 2; ++s) {
        const int f = face[a][s];
        if (f == outer) continue;
        flux += (s == 1 ? 1.0 : -1.0) * u[f];
      }
    u[outer] = (sign > 0.0 ? -1.0 : 1.0) * flux;
  }
}

// --- advection -----------------------------------------------------------------------------------

/// Midpoint rule (RK2), Algorithm 1 line 14, in substeps with continuous collision against the
/// solids: the step dt is split into n equal substeps so that no substep moves a particle more
/// than kAdvectionSubstep dx (n from the larger of the speeds at the start and at the midpoint of
/// the full step), and after every substep the particle is settled (periodic wrap, projection out
/// of solids to kSolidMargin dx, clamping to kWallMargin dx inside walls, removal beyond open
/// faces). A solid of thickness above about kAdvectionSubstep dx can therefore not be crossed in
/// one step, whatever the CFL number (a single RK2 step at CFL 3 jumps up to 3 dx and more where
/// the pressure has just accelerated the liquid, which carried particles through the bowl wall).
template <int Dim>
long advect_particles(Particles<Dim>& particles, const MacGrid<Dim>& grid, const VectorX& u,
                      double dt, const SolidField<Dim>& solids,
                      const std::array<BoundaryType, 2 * Dim>& boundary,
                      std::vector<char>* unread) {
  const long np = static_cast<long>(particles.size());
  const double max_move = kAdvectionSubstep * grid.dx();
  // with `unread`: a second pass (flags given) moves the flagged particles only
  const bool again = unread != nullptr && static_cast<long>(unread->size()) == np;
  if (unread != nullptr && !again) unread->assign(np, 0);
  std::vector<char> remove(np, 0);
  long removed = 0;
  // chunks handed out as threads come free: the substeps per particle follow its speed, which
  // varies across the liquid (each particle is independent, so the result does not change)
#pragma omp parallel for schedule(dynamic, 512) reduction(+ : removed) num_threads(process_threads())
  for (long p = 0; p < np; ++p) {
    if (again && !(*unread)[p]) continue;
    Vec<Dim> x = particles.x[p];
    // a NaN read (a face the caller marked unreadable, or the particle's own v and c from
    // grid_to_particles): the particle stays where it is, flagged (checked before the value
    // places a point: a NaN point has no stencil)
    const auto unreadable = [&](const Vec<Dim>& value) {
      return unread != nullptr && !value.allFinite();
    };
    bool read = !unreadable(particles.v[p]) &&
                !(unread != nullptr && !particles.c[p].allFinite());
    // number of substeps from the speeds along the full-step midpoint path
    const Vec<Dim> v1 = read ? grid.interpolate_velocity(u, x) : Vec<Dim>::Zero();
    read = read && !unreadable(v1);
    const Vec<Dim> v2 =
        read ? grid.interpolate_velocity(u, Vec<Dim>(x + 0.5 * dt * v1)) : Vec<Dim>::Zero();
    read = read && !unreadable(v2);
    if (!read) {
      (*unread)[p] = 1;
      continue;
    }
    const double path = dt * std::max(v1.norm(), v2.norm());
    const int n = std::clamp(static_cast<int>(std::ceil(path / max_move)), 1, kMaxAdvectionSubsteps);
    const double h = dt / n;
    bool inside = true;
    for (int s = 0; s < n && inside; ++s) {
      // midpoint rule (RK2) over the substep, then solids, walls, periodic wrap, open faces
      const Vec<Dim> a = s == 0 ? v1 : grid.interpolate_velocity(u, x);
      if (unreadable(a)) {
        read = false;
        break;
      }
      // (one substep: h is dt and a is v1, so the midpoint is the one v2 was read at, the same
      // bits, and v2 is its velocity: not interpolated again)
      const Vec<Dim> xm = x + 0.5 * h * a;
      const Vec<Dim> b = n == 1 ? v2 : grid.interpolate_velocity(u, xm);
      if (unreadable(b)) {
        read = false;
        break;
      }
      x += h * b;
      inside = settle_position(grid, solids, boundary, true, x);
    }
    if (unread != nullptr) (*unread)[p] = !read;
    if (!read) continue;
    if (!inside) {
      remove[p] = 1;
      ++removed;
    }
    particles.x[p] = x;
  }
  if (removed > 0) {
    particles.remove_flagged(remove);
    // the flags follow their particles
    if (unread != nullptr) {
      std::size_t out = 0;
      for (long p = 0; p < np; ++p)
        if (!remove[p]) (*unread)[out++] = (*unread)[p];
      unread->resize(out);
    }
  }
  return removed;
}

template <int Dim>
long drift_particles_own_velocity(Particles<Dim>& particles, const MacGrid<Dim>& grid, double dt,
                                  const SolidField<Dim>& solids,
                                  const std::array<BoundaryType, 2 * Dim>& boundary) {
  const long np = static_cast<long>(particles.size());
  const double max_move = kAdvectionSubstep * grid.dx();
  std::vector<char> remove(np, 0);
  long removed = 0;
#pragma omp parallel for schedule(static) reduction(+ : removed) num_threads(process_threads())
  for (long p = 0; p < np; ++p) {
    const Vec<Dim> v = particles.v[p];
    const double path = dt * v.norm();
    if (!(path > 0.0)) continue;  // at rest (or no finite velocity): stays as seeded
    const int n = std::clamp(static_cast<int>(std::ceil(path / max_move)), 1, kMaxAdvectionSubsteps);
    const double h = dt / n;
    Vec<Dim> x = particles.x[p];
    bool inside = true;
    for (int s = 0; s < n && inside; ++s) {
      x += h * v;
      inside = settle_position(grid, solids, boundary, true, x);
    }
    if (!inside) {
      remove[p] = 1;
      ++removed;
    }
    particles.x[p] = x;
  }
  if (removed > 0) particles.remove_flagged(remove);
  return removed;
}

// --- position correction -------------------------------------------------------------------------

namespace {

/// Density kernel of the position correction, (1 - q^2)^3 for q = r / h < 1 (poly6 shape).
double correction_kernel(double q2) {
  if (q2 >= 1.0) return 0.0;
  const double t = 1.0 - q2;
  return t * t * t;
}

/// Kernel sum of a particle inside an infinite uniform lattice of spacing s (the rest number
/// density n0; h / s = kCorrectionSupport). Scale invariant, so a constant per dimension.
template <int Dim>
double lattice_number_density() {
  const int reach = static_cast<int>(std::ceil(kCorrectionSupport));
  const int side = 2 * reach + 1;
  double sum = 0.0;
  for (int k = 0; k < int_pow(side, Dim); ++k) {
    const VecI<Dim> off =
        lattice_coord<Dim>(k, VecI<Dim>::Constant(side)) - VecI<Dim>::Constant(reach);
    const double r2 = off.template cast<double>().squaredNorm();
    sum += correction_kernel(r2 / (kCorrectionSupport * kCorrectionSupport));
  }
  return sum;
}

}  // namespace

/// Unilateral position-based density constraint (Macklin & Mueller 2013, applied as a position
/// correction as in Takahashi & Lin 2019): with number density n_i = sum_j W(|x_i - x_j| / h),
/// h = kCorrectionSupport s (s = (m / rho)^(1/Dim), the rest spacing), and the constraint
/// C_i = n_i / n0 - 1 (n0 the number density of a uniform lattice of spacing s), only particles
/// with C_i > kCorrectionSlack are corrected:
///   lambda_i = -(C_i - slack) / (sum_k |grad_k C_i|^2 + eps),
///   dx_i = alpha / n0 sum_j (lambda_i + lambda_j) grad W_spiky(x_i - x_j),
/// one Jacobi iteration per call, alpha = kCorrectionRelaxation min(1, dt / kCorrectionTime).
/// Compressed clusters spread towards emptier neighbours; a uniform lattice (C = 0) and free
/// surfaces (C < 0) do not move, so apart from a one-off settling of the seeding noise the
/// correction does not inflate the liquid. Pairs closer than kCorrectionMinDistance spacings are
/// also pushed apart (half the overlap each). Algorithm 1, line 15.
template <int Dim>
void correct_positions(Particles<Dim>& particles, const MacGrid<Dim>& grid, double dt,
                       const SolidField<Dim>& solids,
                       const std::array<BoundaryType, 2 * Dim>& boundary,
                       PositionCorrectionBuffers* buffers) {
  const long np = static_cast<long>(particles.size());
  if (np < 2 || !(dt > 0.0)) return;
  const double dx = grid.dx();
  const double alpha = kCorrectionRelaxation * std::min(1.0, dt / kCorrectionTime);
  const double n0 = lattice_number_density<Dim>();

  // kernel supports h_i from the rest spacings, wrapped positions and cells (in parallel; the
  // largest support does not depend on the order)
  const int nc = grid.num_cells();
  // (unset: the first parallel loop writes every particle's, the sort every slot's)
  UnsetVector<double> support(np);
  UnsetVector<int> bucket(np), order(np);
  UnsetVector<Vec<Dim>> xw(np), xs(np);
  double max_support = 0.0;
  // spatial hash by occupied cells only (no table the size of the grid): the particles sorted by
  // cell (a stable radix sort, so in particle order within a cell), each occupied cell a run of
  // slots, the wrapped positions stored in slot order for locality; runs found through tiles of
  // 8^Dim cells made only where particles are.
  // Each pass of the sort on several threads: fixed blocks of slots count their digits, every
  // block's share of a digit starts after the earlier digits and the earlier blocks' share of
  // it, and each block scatters its slots in order (a stable sort, whose result is unique: the
  // same order for any team). The supports, the sort and the runs' starts share one parallel
  // region (they were seven regions, each a fork-join around a fraction of a millisecond)
  constexpr int kDigitBits = 11, kDigits = 1 << kDigitBits;
  int bits = 0;
  while ((1L << bits) < nc) ++bits;
  const int blocks = static_cast<int>(std::clamp(np / 8192, 1L, 16L));
  UnsetVector<int> sorted(np);
  std::vector<std::vector<long>> count(blocks, std::vector<long>(kDigits));
  const auto block_begin = [&](int b) { return np * b / blocks; };
  const int sort_team = process_threads();
  // run k's first slot: listed per thread over static (contiguous, ascending) blocks of slots
  // and joined in thread order, the list of the serial loop
  std::vector<std::vector<int>> run_part(sort_team);
#pragma omp parallel reduction(max : max_support) num_threads(sort_team)
  {
    SpacingOf<Dim> spacing_of(particles, dx);
#pragma omp for schedule(static)
    for (long p = 0; p < np; ++p) {
      support[p] = kCorrectionSupport * spacing_of(p);
      max_support = std::max(max_support, support[p]);
      xw[p] = grid.wrap_position(particles.x[p]);
      bucket[p] = grid.cell_index(grid.cell_containing(xw[p]));
      order[p] = static_cast<int>(p);
    }
    for (int shift = 0; shift < bits; shift += kDigitBits) {
      const auto digit = [&](long s) { return (bucket[order[s]] >> shift) & (kDigits - 1); };
#pragma omp for schedule(static, 1)
      for (int b = 0; b < blocks; ++b) {
        std::fill(count[b].begin(), count[b].end(), 0L);
        for (long s = block_begin(b); s < block_begin(b + 1); ++s) ++count[b][digit(s)];
      }
#pragma omp single
      {
        long start = 0;
        for (int d = 0; d < kDigits; ++d)
          for (int b = 0; b < blocks; ++b) {
            const long c = count[b][d];
            count[b][d] = start;
            start += c;
          }
      }
#pragma omp for schedule(static, 1)
      for (int b = 0; b < blocks; ++b)
        for (long s = block_begin(b); s < block_begin(b + 1); ++s)
          sorted[count[b][digit(s)]++] = order[s];
#pragma omp single
      order.swap(sorted);
    }
    std::vector<int>& part = run_part[omp_get_thread_num()];
#pragma omp for schedule(static) nowait
    for (long s = 0; s < np; ++s) {
      xs[s] = xw[order[s]];
      if (s == 0 || bucket[order[s]] != bucket[order[s - 1]]) part.push_back(static_cast<int>(s));
    }
  }
  // runs: occupied cell k holds the slots [run_start[k], run_start[k + 1]) (gathered in order)
  std::vector<int> run_start;
  {
    std::size_t total = 0;
    for (const auto& part : run_part) total += part.size();
    run_start.reserve(total + 1);
    for (const auto& part : run_part) run_start.insert(run_start.end(), part.begin(), part.end());
  }
  std::vector<int> run_cell(run_start.size());
  for (std::size_t k = 0; k < run_start.size(); ++k) run_cell[k] = bucket[order[run_start[k]]];
  run_start.push_back(static_cast<int>(np));
  const int runs = static_cast<int>(run_cell.size());
  TiledLattice<Dim, int> run_of(grid.cells(), -1);
  for (int k = 0; k < runs; ++k) *run_of.at(grid.cell_coord(run_cell[k])) = k;

  // cells to search around a particle's own: the support is one cell at the default 8 (4) particles
  // per cell, but (m / rho)^(1/Dim) rounds to a hair above dx / 2, and a plain ceil then searched
  // two rings (125 cells instead of 27 in 3D) for neighbours that cannot lie there: a pair in
  // cells two apart is farther than dx, and the excess of the support over dx is a rounding error
  const int ring = std::max(1, static_cast<int>(std::ceil(max_support / dx * (1.0 - 1e-12))));
  const int side = 2 * ring + 1;
  const int neighbour_cells = int_pow(side, Dim);
  // a periodic axis shorter than the stencil maps two offsets to one cell: deduplicate then
  bool dedup = false;
  bool any_periodic = false;
  for (int a = 0; a < Dim; ++a) {
    dedup = dedup || (grid.periodic(a) && grid.cells()[a] < side);
    any_periodic = any_periodic || grid.periodic(a);
  }

  // the occupied cells around run k's cell (each once, in stencil order)
  auto neighbour_runs = [&](int k, std::vector<int>& out, std::vector<int>& cells) {
    out.clear();
    cells.clear();
    const VecI<Dim> ci = grid.cell_coord(run_cell[k]);
    for (int o = 0; o < neighbour_cells; ++o) {
      const VecI<Dim> cj = grid.wrap_cell(
          ci + lattice_coord<Dim>(o, VecI<Dim>::Constant(side)) - VecI<Dim>::Constant(ring));
      if (!grid.cell_in_range(cj)) continue;
      if (dedup) {
        const int c = grid.cell_index(cj);
        if (std::find(cells.begin(), cells.end(), c) != cells.end()) continue;
        cells.push_back(c);
      }
      const int r = run_of.value(cj);
      if (r >= 0) out.push_back(r);
    }
  };

  // spiky gradient grad_{x_i} W(x_i - x_j) = -3 (1 - r/h)^2 / h * (x_i - x_j) / r
  auto spiky_gradient = [](long p, long j, const Vec<Dim>& d, double r, double h) {
    Vec<Dim> dir;
    if (r > 1e-9 * h) {
      dir = d / r;
    } else {
      // coincident pair: a fixed direction, opposite for the two particles
      dir = Vec<Dim>::Zero();
      dir[0] = p < j ? 1.0 : -1.0;
    }
    const double t = 1.0 - r / h;
    return Vec<Dim>(-3.0 * t * t / h * dir);
  };

  // pass 1: constraint values and multipliers (zero unless the particle is compressed). Each
  // particle keeps the slots of its neighbours within the support, in candidate order (per
  // thread buffer, found through neighbours_of): the gradients and pass 2 visit only those, in
  // the order the full scan visits them
  // (unset: pass 1 writes every particle's lambda and close flag and every run's active flag;
  // their zero fills ran on the calling thread, two24)
  UnsetVector<double> lambda(np);
  UnsetVector<char> close_pair(np);
  // occupied cells holding a compressed particle or a close pair: only their neighbourhoods move
  UnsetVector<char> active_run(runs);
  const int team = process_threads();
  // (the caller's buffers when given: cleared, their capacity kept from the last call)
  PositionCorrectionBuffers local;
  std::vector<std::vector<int>>& neighbour_slots = (buffers ? *buffers : local).neighbour_slots;
  if (static_cast<int>(neighbour_slots.size()) < team) neighbour_slots.resize(team);
  for (auto& slots : neighbour_slots) slots.clear();
  // (buffer, first, count): written for every particle by its run in pass 1
  UnsetVector<std::array<int, 3>> neighbours_of(np);
  long compressed = 0, closes = 0;
#pragma omp parallel reduction(+ : compressed, closes) num_threads(team)
  {
    std::vector<int> near, cells, cand;
    // the candidates' positions by axis (contiguous, for the distances of a whole run at once)
    // and a particle's squared distances to them
    std::array<std::vector<double>, Dim> cand_x;
    std::vector<double> cand_r2;
    std::vector<int>& buffer = neighbour_slots[omp_get_thread_num()];
    const int thread = omp_get_thread_num();
#pragma omp for schedule(dynamic, 16)
    for (int k = 0; k < runs; ++k) {
      neighbour_runs(k, near, cells);
      cand.clear();
      for (int r : near)
        for (int q = run_start[r]; q < run_start[r + 1]; ++q) cand.push_back(q);
      const int m = static_cast<int>(cand.size());
      for (int a = 0; a < Dim; ++a) {
        cand_x[a].resize(m);
        for (int i = 0; i < m; ++i) cand_x[a][i] = xs[cand[i]][a];
      }
      cand_r2.resize(m);
      bool active = false;
      for (int slot = run_start[k]; slot < run_start[k + 1]; ++slot) {
        const int p = order[slot];
        const double h = support[p];
        const double inv_h2 = 1.0 / (h * h);
        const double min_distance = kCorrectionMinDistance * h / kCorrectionSupport;
        const double min_distance2 = min_distance * min_distance;
        const Vec<Dim> xp = xw[p];
        // number density from squared distances only (no square roots): a candidate outside
        // the support (or p itself) adds nothing, and skipping it leaves the sum (at least 1)
        // bit for bit as adding +0.0 would
        double n = 1.0;  // the particle itself
        const double h2 = h * h;
        bool close = false;
        const int first = static_cast<int>(buffer.size());
        // squared distances as squaredNorm() sums them (axis order), axis by axis over the
        // contiguous candidates; on a periodic axis through the minimum image
        if (any_periodic) {
          for (int i = 0; i < m; ++i)
            cand_r2[i] = periodic_difference(grid, Vec<Dim>(xp - xs[cand[i]])).squaredNorm();
        } else {
          const double* x0 = cand_x[0].data();
          for (int i = 0; i < m; ++i) {
            const double d = xp[0] - x0[i];
            cand_r2[i] = d * d;
          }
          for (int a = 1; a < Dim; ++a) {
            const double* xa = cand_x[a].data();
            for (int i = 0; i < m; ++i) {
              const double d = xp[a] - xa[i];
              cand_r2[i] += d * d;
            }
          }
        }
        for (int i = 0; i < m; ++i) {
          const int q = cand[i];
          const double r2 = cand_r2[i];
          if (!(r2 < h2) || q == slot) continue;
          buffer.push_back(q);
          close = close || r2 < min_distance2;
          const double t = 1.0 - r2 * inv_h2;
          if (t > 0.0) n += t * t * t;
        }
        neighbours_of[p] = {thread, first, static_cast<int>(buffer.size()) - first};
        close_pair[p] = close ? 1 : 0;
        lambda[p] = 0.0;
        if (close) {
          active = true;
          ++closes;
        }
        const double c = n / n0 - 1.0 - kCorrectionSlack;
        if (c <= 0.0) continue;
        // constraint gradients, only for the compressed particles
        Vec<Dim> grad_self = Vec<Dim>::Zero();
        double grad_others = 0.0;
        for (int i = first; i < static_cast<int>(buffer.size()); ++i) {
          const int q = buffer[i];
          Vec<Dim> d = xp - xs[q];
          if (any_periodic) d = periodic_difference(grid, d);
          const Vec<Dim> g = spiky_gradient(p, order[q], d, std::sqrt(d.squaredNorm()), h) / n0;
          grad_self += g;
          grad_others += g.squaredNorm();
        }
        // eps regularises the denominator (units 1/length^2, scaled by h)
        const double eps = 1e-6 / (h * h);
        lambda[p] = -c / (grad_self.squaredNorm() + grad_others + eps);
        active = active || lambda[p] != 0.0;
        ++compressed;
      }
      active_run[k] = active ? 1 : 0;
    }
  }

  if (compressed == 0 && closes == 0) return;

  // pass 2: displacements from the multipliers (Jacobi, so the result is order independent)
  // (unset: written for every particle below, zero in the runs with no active run near)
  UnsetVector<Vec<Dim>> delta(np);
#pragma omp parallel num_threads(team)
  {
    std::vector<int> near, cells;
#pragma omp for schedule(dynamic, 16)
    for (int k = 0; k < runs; ++k) {
      neighbour_runs(k, near, cells);
      bool near_active = false;
      for (int r : near) near_active = near_active || active_run[r];
      if (!near_active) {
        for (int slot = run_start[k]; slot < run_start[k + 1]; ++slot)
          delta[order[slot]] = Vec<Dim>::Zero();
        continue;
      }
      for (int slot = run_start[k]; slot < run_start[k + 1]; ++slot) {
        const int p = order[slot];
        Vec<Dim> push = Vec<Dim>::Zero();
        const double min_distance = kCorrectionMinDistance * support[p] / kCorrectionSupport;
        // a neighbour with l = 0 whose squared distance is clearly beyond the minimum distance
        // contributes nothing: skip its square root (the margin keeps the skip conservative)
        const double skip_r2 = min_distance * min_distance * (1.0 + 1e-9);
        const double h = support[p];
        const Vec<Dim> xp = xw[p];
        const auto [buffer, first, count] = neighbours_of[p];
        const int* slots = neighbour_slots[buffer].data() + first;
        for (int i = 0; i < count; ++i) {
          const int q = slots[i];
          Vec<Dim> d = xp - xs[q];
          if (any_periodic) d = periodic_difference(grid, d);
          const double r2 = d.squaredNorm();
          const int j = order[q];
          // density constraints
          const double l = lambda[p] + lambda[j];
          if (l == 0.0 && r2 > skip_r2) continue;
          const double r = std::sqrt(r2);
          if (l != 0.0) push += l * spiky_gradient(p, j, d, r, h) / n0;
          // minimum distance: each particle of a close pair takes half of the overlap
          if (r < min_distance) {
            Vec<Dim> dir = Vec<Dim>::Zero();
            if (r > 1e-9 * h)
              dir = d / r;
            else
              dir[0] = p < j ? 1.0 : -1.0;  // as in spiky_gradient
            push += 0.5 * (min_distance - r) * dir;
          }
        }
        push *= alpha;
        // never more than kCorrectionMaxStep spacings per step
        const double cap = kCorrectionMaxStep * support[p] / kCorrectionSupport;
        const double len = push.norm();
        if (len > cap) push *= cap / len;
        delta[p] = push;
      }
    }
  }

  // apply, then keep clear of solids and walls
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (long p = 0; p < np; ++p) {
    if (delta[p].squaredNorm() == 0.0) continue;
    Vec<Dim> x = particles.x[p] + delta[p];
    settle_position(grid, solids, boundary, false, x);
    particles.x[p] = x;
  }
}

// --- density projection --------------------------------------------------------------------------

namespace {

/// The particle level set of liquid_phi_on_lattice (particles > 0) in tiles of the lattice: the
/// same values where a particle or image reaches, the kernel support (its background)
/// elsewhere; no lattice-sized vector (defined with liquid_phi_on_lattice below).
template <int Dim>
void liquid_phi_tiles(const Particles<Dim>& particles, const MacGrid<Dim>& grid,
                      const SampleLattice<Dim>& lattice,
                      const std::array<BoundaryType, 2 * Dim>& boundary,
                      const SolidField<Dim>& solids, TiledLattice<Dim, double>& phi);

/// Antiderivative of the hat max(0, 1 - |u|).
double hat_integral(double u) {
  if (u <= -1.0) return 0.0;
  if (u <= 0.0) return 0.5 * (1.0 + u) * (1.0 + u);
  if (u < 1.0) return 1.0 - 0.5 * (1.0 - u) * (1.0 - u);
  return 1.0;
}

/// One axis of the splat kernel of the density projection: the hat of a cell centre averaged
/// over a box of `width` (a particle's rest spacing, in cells) centred at offset t (in cells):
/// (H(t + width/2) - H(t - width/2)) / width, H the hat's antiderivative. A regular lattice of
/// particles of that spacing then splats exactly the hat-weighted volume of the region it fills.
double box_hat_weight(double t, double width) {
  return (hat_integral(t + 0.5 * width) - hat_integral(t - 0.5 * width)) / width;
}

/// The runs of consecutive indices that [lo, hi] covers on an axis of n entries, wrapped on a
/// periodic axis and clamped to [0, n) otherwise: at most two (a periodic range across the seam).
int axis_runs(int lo, int hi, int n, bool periodic, std::array<std::array<int, 2>, 2>& runs) {
  if (!periodic) {
    lo = std::max(lo, 0);
    hi = std::min(hi, n - 1);
    if (lo > hi) return 0;
    runs[0] = {lo, hi};
    return 1;
  }
  if (hi - lo + 1 >= n) {
    runs[0] = {0, n - 1};
    return 1;
  }
  const int wl = ((lo % n) + n) % n, wh = ((hi % n) + n) % n;
  if (wl <= wh) {
    runs[0] = {wl, wh};
    return 1;
  }
  runs[0] = {wl, n - 1};
  runs[1] = {0, wh};
  return 2;
}

/// box(lo, hi) for every box of runs `runs[a][0 .. count[a])` per axis (every combination of
/// one run per axis).
template <int Dim, class Box>
void for_each_run_box(const std::array<std::array<std::array<int, 2>, 2>, Dim>& runs,
                      const std::array<int, Dim>& count, Box&& box) {
  for (int a = 0; a < Dim; ++a)
    if (count[a] == 0) return;
  std::array<int, Dim> k{};
  while (true) {
    VecI<Dim> lo, hi;
    for (int a = 0; a < Dim; ++a) {
      lo[a] = runs[a][k[a]][0];
      hi[a] = runs[a][k[a]][1];
    }
    box(lo, hi);
    int a = 0;
    for (; a < Dim; ++a) {
      if (++k[a] < count[a]) break;
      k[a] = 0;
    }
    if (a == Dim) return;
  }
}

/// The density projection's per-cell values, in tiles of cells (TiledLattice over the grid's
/// cells) made only in the band around the particles: target T, the air-side test's T on the
/// level set extended into the solids, and the row of the cell in the Poisson problem (-1: not
/// an unknown); the particle volume fraction rho~ has tiles of its own (the splat's 5^Dim cells
/// per particle then touch as many cache lines as in a dense array). Every cell outside the
/// tiles has rho~ = T = 0.
enum ProjectionValue { kTarget = 0, kWet = 1, kRow = 2, kProjectionValues = 3 };

/// The liquid indicator of the level set convolved with the multilinear hat of each cell centre,
///   T_c = dx^-Dim int hat_c(x) H(-phi(x)) dx,
/// i.e. what a perfectly even distribution of liquid particles filling {phi < 0} would splat
/// onto cell c. Evaluated on the half cells of the lattice (2^Dim per cell; their liquid
/// fractions from lattice_cell_negative_fraction): per axis, the half cells 2c-1 .. 2c+2 carry the
/// hat integrals 1/8, 3/8, 3/8, 1/8. A half cell outside a non-periodic domain passes its weight
/// to the adjacent inside one, as the clamped particle stencil does.
///
/// Written for the cells of one tile of `values`, for each of `Slots` components: component
/// slot[s] from the lattice values corner_values(point, out)'s out[s] (one call per point
/// gives every component's value, so lookups they share are made once): the half cells under
/// the tile's hats (2 x 8 + 2 per axis) and their fractions, then the three (two) passes of the
/// taps along the axes, each output the same sum in the same order as a pass over the whole grid
/// would form it (so the same bits). A component whose gathered values equal an earlier one's
/// bit for bit takes that one's cells (the same function of the same values); one whose values
/// are all of one sign takes 0 or 1 (below).
template <int Dim, int Slots, class Values, class CornerValues>
void hat_liquid_fractions_in_tile(const MacGrid<Dim>& grid, Values& values, int tile,
                                  const std::array<int, Slots>& slot,
                                  CornerValues&& corner_values) {
  constexpr int kTile = Values::kTile;
  constexpr int kHalf = 2 * kTile + 2;  // half cells under the hats of one tile's cells, per axis
  constexpr int kCorners = 1 << Dim;
  const VecI<Dim> t0 = values.tile_origin(tile);
  // per axis: the half cell of each local one (wrapped or clamped as the taps read them) and the
  // distinct lattice points their corners take, gathered once
  std::array<std::array<int, kHalf>, Dim> lo_point, hi_point;  // local corner indices
  std::array<std::array<int, 2 * kHalf>, Dim> point;          // lattice point coordinates
  std::array<int, Dim> points{};
  for (int a = 0; a < Dim; ++a) {
    const int n2 = 2 * grid.cells()[a];
    for (int l = 0; l < kHalf; ++l) {
      int j = 2 * t0[a] - 1 + l;
      if (grid.periodic(a))
        j = ((j % n2) + n2) % n2;
      else
        j = std::clamp(j, 0, n2 - 1);
      for (int o = 0; o < 2; ++o) {
        int k = 0;
        while (k < points[a] && point[a][k] != j + o) ++k;
        if (k == points[a]) point[a][points[a]++] = j + o;
        (o == 0 ? lo_point : hi_point)[a][l] = k;
      }
    }
  }
  // the lattice values at the gathered points (axis 0 fastest), per component
  int gathered = 1;
  for (int a = 0; a < Dim; ++a) gathered *= points[a];
  std::array<std::vector<double>, Slots> value;
  for (auto& v : value) v.resize(gathered);
  {
    std::array<int, Dim> k{};
    std::array<double, Slots> out;
    for (int g = 0; g < gathered; ++g) {
      VecI<Dim> c;
      for (int a = 0; a < Dim; ++a) c[a] = point[a][k[a]];
      corner_values(c, out.data());
      for (int s = 0; s < Slots; ++s) value[s][g] = out[s];
      for (int a = 0; a < Dim; ++a) {
        if (++k[a] < points[a]) break;
        k[a] = 0;
      }
    }
  }
  int count = 1;
  for (int a = 0; a < Dim; ++a) count *= kHalf;
  std::vector<double> cur, next;
  for (int s = 0; s < Slots; ++s) {
    // the same values as an earlier component (bit for bit: memcmp, so -0 and NaN patterns
    // count as they are): its cells
    int same = -1;
    for (int e = 0; e < s && same < 0; ++e)
      if (std::memcmp(value[e].data(), value[s].data(), sizeof(double) * gathered) == 0) same = e;
    if (same >= 0) {
      const int from = slot[same], to = slot[s];
      values.for_each_point_in_tile(tile, [&](const VecI<Dim>&, double* v) { v[to] = v[from]; });
      continue;
    }
    // values all of one sign need no half cell: every half cell's fraction is 0 (no value
    // below 0) or 1 (every value below 0), as lattice_cell_negative_fraction returns them, and
    // the taps (1/8, 3/8, 3/8, 1/8) sum zeros to +0 and ones to exactly 1 (every partial sum is
    // a multiple of 1/8), so every cell of the tile takes 0 or 1, bit for bit as the passes
    // below would give it (the band's tiles in the air or deep in the liquid)
    {
      int negatives = 0;
      for (int g = 0; g < gathered; ++g) negatives += value[s][g] < 0.0;
      if (negatives == 0 || negatives == gathered) {
        const double uniform = negatives == 0 ? 0.0 : 1.0;
        const int to = slot[s];
        values.for_each_point_in_tile(tile, [&](const VecI<Dim>&, double* v) { v[to] = uniform; });
        continue;
      }
    }
    // liquid fractions of the half cells (axis 0 fastest)
    cur.resize(count);
    {
      std::array<int, Dim> l{};
      for (int h = 0; h < count; ++h) {
        std::array<double, kCorners> corner;
        for (int b = 0; b < kCorners; ++b) {
          int g = 0;
          for (int a = Dim - 1; a >= 0; --a)
            g = g * points[a] + (((b >> a) & 1) ? hi_point[a][l[a]] : lo_point[a][l[a]]);
          corner[b] = value[s][g];
        }
        cur[h] = lattice_cell_negative_fraction<Dim>(corner);
        for (int a = 0; a < Dim; ++a) {
          if (++l[a] < kHalf) break;
          l[a] = 0;
        }
      }
    }
    // per axis, the 4-tap hat integrals from half cells to cells: local cell o reads the local
    // half cells 2 o .. 2 o + 3
    static constexpr double kTaps[4] = {0.125, 0.375, 0.375, 0.125};
    VecI<Dim> dims = VecI<Dim>::Constant(kHalf);
    for (int a = 0; a < Dim; ++a) {
      VecI<Dim> out_dims = dims;
      out_dims[a] = kTile;
      const int out_count = out_dims.prod();
      next.assign(out_count, 0.0);
      int stride = 1;
      for (int b = 0; b < a; ++b) stride *= dims[b];
      // (the output's coordinates o counted along, axis 0 fastest, as lattice_coord gives them)
      VecI<Dim> o = VecI<Dim>::Zero();
      for (int k = 0; k < out_count; ++k) {
        VecI<Dim> i = o;
        i[a] = 2 * o[a];
        const int base = lattice_index<Dim>(i, dims);
        double sum = 0.0;
        for (int t = 0; t < 4; ++t) sum += kTaps[t] * cur[base + t * stride];
        next[k] = sum;
        for (int b = 0; b < Dim; ++b) {
          if (++o[b] < out_dims[b]) break;
          o[b] = 0;
        }
      }
      cur.swap(next);
      dims = out_dims;
    }
    const int to = slot[s];
    values.for_each_point_in_tile(tile, [&](const VecI<Dim>& c, double* v) {
      v[to] = cur[lattice_index<Dim>(VecI<Dim>(c - t0), dims)];
    });
  }
}

/// The share of a deficit on the liquid side of the surface band that the density projection
/// corrects, given how much more the level set encloses than the particles (`mismatch`, relative):
/// SurfaceDeficits::beyond_dead_band ramps from 0 at kDeficitDeadBand to 1 at kDeficitFullShare,
/// a volume feedback with a dead band (in the spirit of Losasso et al. 2008's volume control).
double surface_deficit_share(SurfaceDeficits rule, double mismatch) {
  switch (rule) {
    case SurfaceDeficits::all:
      return 1.0;
    case SurfaceDeficits::none:
    case SurfaceDeficits::to_solve:
      return 0.0;
    case SurfaceDeficits::beyond_dead_band:
      break;
  }
  return std::clamp((mismatch - kDeficitDeadBand) / (kDeficitFullShare - kDeficitDeadBand), 0.0,
                    1.0);
}

/// sum_c T_c / sum_c rho~_c - 1 over the projection's unknowns (cells in order): how much more
/// the level set encloses than the particles' splat (0 without particle volume).
template <int Dim, class Values, class Rho>
double level_set_volume_mismatch(const MacGrid<Dim>& grid, const std::vector<int>& cells,
                                 const Rho& rho, const Values& values) {
  double particle = 0.0, level_set = 0.0;
  for (int c : cells) {
    const VecI<Dim> ci = grid.cell_coord(c);
    particle += *rho.find(ci);
    level_set += values.find(ci)[kTarget];
  }
  return particle > 0.0 ? level_set / particle - 1.0 : 0.0;
}

/// One (reconstruction, solve, move) of project_particle_density. Its grid work visits only the
/// band of cells within reach of a particle (tiles of 8^Dim cells): outside it no particle
/// splats volume and the level set has no liquid, so rho~ = T = 0 there and no cell is an
/// unknown; the values in the band, the rows (in cell order) and the moves are those of a pass
/// over the whole grid, bit for bit.
template <int Dim>
DensityProjectionStats project_density_once(Particles<Dim>& particles, const MacGrid<Dim>& grid,
                                            const SampleLattice<Dim>& lattice,
                                            const VectorX& fluid_face,
                                            const SolidField<Dim>& solids,
                                            const std::array<BoundaryType, 2 * Dim>& boundary,
                                            SurfaceDeficits surface_deficits,
                                            KeptZeros& move_scratch,
                                            const SolidField<Dim>* held_near, double held_reach) {
  DensityProjectionStats stats;
  const long np = static_cast<long>(particles.size());
  if (np == 0) return stats;
  const int nf = grid.num_faces();
  const double dx = grid.dx();
  const double cell_volume = grid.cell_volume();
  std::array<bool, Dim> periodic{};
  for (int a = 0; a < Dim; ++a) periodic[a] = grid.periodic(a);

  // the band: the cells within `ring` of a particle's cell (in tiles of 8^Dim cells, so a few
  // cells more). The splat reaches two cells from a particle's cell; the level set is negative
  // only at lattice points within the support R of a particle (2 R with solids: a particle's
  // image across a solid reaches points inside it), and T_c reads the lattice points of
  // [c - 1/2, c + 3/2] dx per axis, so T_c > 0 needs a particle with |c - c_p| < 3/2 + R / dx
  // (in one pass with the particles' cells (wrapped, clamped): max gives the same result for
  // any split)
  constexpr int kLast = Dim - 1;
  double max_support = 0.0;
  std::vector<VecI<Dim>> particle_cell(np);
  // the first of the five cell layers of the last axis each particle's volume splat reaches
  // (before wrapping or clamping), for the slabs' skip below
  // (unset: written for every particle by the loop below)
  UnsetVector<int> splat_base(np);
#pragma omp parallel reduction(max : max_support) num_threads(process_threads())
  {
    SpacingOf<Dim> spacing_of(particles, dx);
#pragma omp for schedule(static)
    for (long p = 0; p < np; ++p) {
      max_support = std::max(max_support, kSurfaceSupport * spacing_of(p));
      const Vec<Dim> xw = grid.wrap_position(particles.x[p]);
      const VecI<Dim> c = grid.cell_containing(xw);
      particle_cell[p] = c;
      splat_base[p] = static_cast<int>(std::floor((xw[kLast] - grid.origin()[kLast]) / dx)) - 2;
    }
  }
  const double reach = (solids.empty() ? 1.0 : 2.0) * max_support;
  const int ring = std::max(2, static_cast<int>(std::floor(1.5 + reach / dx + 1e-6)));
  // the tiles under the ring around every particle's cell, flagged on several threads (a particle
  // in the cell of the one before it flags nothing new) and made in parallel: the same tiles for
  // any team; `rho` has the same tiles (the same lattice and tile size)
  TiledLattice<Dim, double, kProjectionValues> values(grid.cells(), 0.0);
  TiledLattice<Dim, double> rho(grid.cells(), 0.0);
  std::vector<unsigned char> band_flags = values.tile_flags();
#pragma omp parallel for schedule(static) num_threads(team_threads(np))
  for (long p = 0; p < np; ++p) {
    const VecI<Dim>& c = particle_cell[p];
    if (p > 0 && particle_cell[p - 1] == c) continue;
    std::array<std::array<std::array<int, 2>, 2>, Dim> runs;
    std::array<int, Dim> count;
    for (int a = 0; a < Dim; ++a)
      count[a] = axis_runs(c[a] - ring, c[a] + ring, grid.cells()[a], periodic[a], runs[a]);
    for_each_run_box<Dim>(runs, count, [&](const VecI<Dim>& lo, const VecI<Dim>& hi) {
      values.mark_box(lo, hi, band_flags);
    });
  }
  // (the tiles' memory claimed here, filled with the background in the region of the layer
  // histogram below)
  const std::vector<double*> fresh_values = values.claim_tiles(band_flags);
  const std::vector<double*> fresh_rho = rho.claim_tiles(band_flags);
  std::vector<int> band;  // the made tiles of `values` (and of `rho`)
  for (int t = 0; t < values.num_tile_slots(); ++t)
    if (values.has_tile(t)) band.push_back(t);
  const int band_tiles = static_cast<int>(band.size());

  // particle volume fractions: each particle's volume spread as a box of its rest spacing and
  // then by the hat of the cell centres. In parallel without races: the cells are split into
  // slabs of layers of the last axis, one per thread; each thread walks all particles in index
  // order, skips those whose five layers miss its slab and adds only into its own cells, so every
  // cell sums its contributions in the order of the serial loop (the same bits for any number of
  // threads, and as before)
  // The slabs' bounds balance the particles each slab visits (equal widths left one thread most
  // of a blob's particles; any bounds give the same bits).
  const int layers = grid.cells()[kLast];
  const int slabs = std::max(1, std::min(process_threads(), layers));
  std::vector<int> slab_first(slabs + 1, 0);
  slab_first[slabs] = layers;
  // (counted per thread and the counts added: integer sums, any split; in one parallel region
  // with the filling of the band's new tiles)
  const int team = team_threads(np);
  std::vector<std::vector<long>> counts(slabs > 1 ? team : 0, std::vector<long>(layers + 1, 0));
  {
    const int nv = static_cast<int>(fresh_values.size()), nr = static_cast<int>(fresh_rho.size());
#pragma omp parallel num_threads(team)
    {
#pragma omp for schedule(static) nowait
      for (int i = 0; i < nv; ++i) values.fill_tile(fresh_values[i]);
#pragma omp for schedule(static) nowait
      for (int i = 0; i < nr; ++i) rho.fill_tile(fresh_rho[i]);
      if (slabs > 1) {
        std::vector<long>& count = counts[omp_get_thread_num()];
#pragma omp for schedule(static) nowait
        for (long p = 0; p < np; ++p) ++count[particle_cell[p][kLast] + 1];
      }
    }
  }
  if (slabs > 1) {
    // a particle of cell layer l writes cell layers l - 2 .. l + 2 (clamped or wrapped): the
    // bounds balance the particles each slab visits, those beside a bound counted on both sides
    // (slab_bounds.hpp; the first layer where the running count reached k / slabs of np left one
    // slab the bound's layers more)
    std::vector<long> per_layer(layers, 0);
    for (const auto& count : counts)
      for (int l = 0; l < layers; ++l) per_layer[l] += count[l + 1];
    slab_first = balanced_slab_bounds(per_layer, layers, slabs, -2, 2);
  }
  const bool last_periodic = grid.periodic(kLast);
#pragma omp parallel for schedule(static, 1) num_threads(process_threads())
  for (int slab = 0; slab < slabs; ++slab) {
    const int first = slab_first[slab];
    const int end = slab_first[slab + 1];
    const auto slab_holds = [&](int layer) { return layer >= first && layer < end; };
    SpacingOf<Dim> spacing_of(particles, dx);
    for (long p = 0; p < np; ++p) {
      // the five layers of the last axis this particle reaches: skip it if none is in the slab
      // (the first layer found once per particle above: every slab's thread walks all the
      // particles, and wrapping and flooring each position again per slab made the splat's
      // region 35 % dearer on two threads than on one; docs/benchmarks.md, two23)
      {
        const int base = splat_base[p];
        bool reaches = false;
        if (!last_periodic) {
          // (clamped, the five layers are the run [clamp(base), clamp(base + 4)])
          reaches = first < end && std::clamp(base + 4, 0, layers - 1) >= first &&
                    std::clamp(base, 0, layers - 1) < end;
        } else {
          for (int k = 0; k < 5 && !reaches; ++k)
            reaches = slab_holds(((base + k) % layers + layers) % layers);
        }
        if (!reaches) continue;
      }
      const double volume =
          particles.density[p] > 0.0 ? particles.mass[p] / particles.density[p] : 0.0;
      const double width = spacing_of(p) / dx;
      const Vec<Dim> xr = (grid.wrap_position(particles.x[p]) - grid.origin()) / dx;
      // per axis: five candidate cells around the particle and their weights
      std::array<std::array<int, 5>, Dim> cell;
      std::array<std::array<double, 5>, Dim> weight;
      for (int a = 0; a < Dim; ++a) {
        const int base = static_cast<int>(std::floor(xr[a])) - 2;
        for (int k = 0; k < 5; ++k) {
          int c = base + k;
          weight[a][k] = box_hat_weight(c + 0.5 - xr[a], width);
          if (grid.periodic(a))
            c = ((c % grid.cells()[a]) + grid.cells()[a]) % grid.cells()[a];
          else
            c = std::clamp(c, 0, grid.cells()[a] - 1);
          cell[a][k] = c;
        }
      }
      // only the candidates of nonzero weight per axis (a zero weight makes the product 0, which
      // is never added): the same additions in the same order
      std::array<int, Dim> k_lo, k_hi;
      bool none = false;
      for (int a = 0; a < Dim; ++a) {
        k_lo[a] = 0;
        k_hi[a] = 4;
        while (k_lo[a] <= 4 && weight[a][k_lo[a]] == 0.0) ++k_lo[a];
        while (k_hi[a] >= k_lo[a] && weight[a][k_hi[a]] == 0.0) --k_hi[a];
        none = none || k_lo[a] > k_hi[a];
      }
      if (none) continue;
      // the last axis (the odometer's slowest) only at the candidates in the slab: a particle
      // beside a bound visits only its own slab's corners there (each slab used to walk all of
      // them and drop the others' at the addition); the corners kept are added in the same order
      for (int kl = k_lo[kLast]; kl <= k_hi[kLast]; ++kl) {
        if (!slab_holds(cell[kLast][kl])) continue;
        std::array<int, Dim> k = k_lo;
        k[kLast] = kl;
        while (true) {
          double w = volume / cell_volume;
          VecI<Dim> ci;
          for (int a = 0; a < Dim; ++a) {
            w *= weight[a][k[a]];
            ci[a] = cell[a][k[a]];
          }
          if (w != 0.0) *rho.find(ci) += w;
          int a = 0;
          for (; a < kLast; ++a) {
            if (++k[a] <= k_hi[a]) break;
            k[a] = k_lo[a];
          }
          if (a == kLast) break;
        }
      }
    }
  }
  // liquid fractions of the particle level set, smoothed by the same hat. With solids, the level
  // set (mirrored across them) reads liquid into a solid next to liquid: the target counts the
  // liquid in the fluid only ({phi < 0} minus the solids: max(phi, -d_S) < 0, d_S the solid
  // distance), as the particles' splat does, while the air side is decided on the level set
  // extended into the solids (as the weights of eq. (8) see it, extend_liquid_into_solids), so a
  // submerged cell cut by a solid is not taken for a free surface.
  // (in tiles: no lattice-sized vector; 541 MB at Fig. 2's 256x128x256 grid)
  TiledLattice<Dim, double> phi;
  liquid_phi_tiles(particles, grid, lattice, boundary, solids, phi);
  if (solids.empty()) {
#pragma omp parallel for schedule(dynamic, 1) num_threads(process_threads())
    for (int b = 0; b < band_tiles; ++b)
      hat_liquid_fractions_in_tile<Dim, 1>(
          grid, values, band[b], {kTarget},
          [&](const VecI<Dim>& c, double* out) { out[0] = phi.value(c); });
  } else {
    // the solid distances of the lattice points under the band's hats where the level set is
    // within 2 dx of liquid (elsewhere phi >= 2 dx stays positive), each computed once: tiles of
    // the half lattice made under every band tile, filled in parallel tile by tile (NaN: not
    // needed)
    TiledLattice<Dim, double> solid_distance(lattice.dims,
                                             std::numeric_limits<double>::quiet_NaN());
    // (the tiles flagged serially, a few boxes per band tile, and made in parallel)
    std::vector<unsigned char> distance_flags = solid_distance.tile_flags();
    for (int b = 0; b < band_tiles; ++b) {
      const VecI<Dim> t0 = values.tile_origin(band[b]);
      std::array<std::array<std::array<int, 2>, 2>, Dim> runs;
      std::array<int, Dim> count;
      for (int a = 0; a < Dim; ++a) {
        // half cells 2 t0 - 1 .. 2 t0 + 2 kTile, their corner points one further
        count[a] = axis_runs(2 * t0[a] - 1, 2 * t0[a] + 2 * TiledLattice<Dim, char>::kTile,
                             2 * grid.cells()[a], periodic[a], runs[a]);
        for (int r = 0; r < count[a]; ++r) ++runs[a][r][1];
      }
      for_each_run_box<Dim>(runs, count, [&](const VecI<Dim>& lo, const VecI<Dim>& hi) {
        solid_distance.mark_box(lo, hi, distance_flags);
      });
    }
    solid_distance.make_tiles(distance_flags, process_threads());
    const int slots = solid_distance.num_tile_slots();
#pragma omp parallel for schedule(dynamic, 1) num_threads(process_threads())
    for (int t = 0; t < slots; ++t)
      solid_distance.for_each_point_in_tile(t, [&](const VecI<Dim>& c, double* ds) {
        if (phi.value(c) < 2.0 * dx) *ds = solids.distance(lattice.position(c));
      });
    const double solid_reach = kLiquidSolidReach * dx;
#pragma omp parallel for schedule(dynamic, 1) num_threads(process_threads())
    for (int b = 0; b < band_tiles; ++b) {
      // the fluid's liquid max(phi, -d_S) for the target, the level set extended into the
      // solids for the air side (only near liquid and solids: elsewhere both are phi)
      // (both from one gather: a tile away from the solids reads the same values for both and
      // makes its fractions once)
      hat_liquid_fractions_in_tile<Dim, 2>(
          grid, values, band[b], {kTarget, kWet}, [&](const VecI<Dim>& c, double* out) {
            const double v = phi.value(c);
            out[0] = out[1] = v;
            if (!(v < 2.0 * dx)) return;
            const double ds = *solid_distance.find(c);
            if (!(ds < 2.0 * dx)) return;
            out[0] = std::max(v, -ds);
            out[1] = liquid_extended_into_solid(v, ds, solid_reach, dx);
          });
    }
  }

  // unknowns: cells holding particle volume or smoothed liquid, rows in cell order
  // (tile by tile on several threads, each part's list sorted by its thread, the sorted lists
  // merged in part order: every cell is listed once, so the order is the one sorted list of them
  // all, as the serial sort of the joined lists gave it (two24); each cell's row written by one
  // thread)
  std::vector<int> cells;
  {
    const int parts = team_threads(static_cast<long>(band_tiles) * decltype(values)::kTilePoints);
    std::vector<std::vector<int>> part(parts);
#pragma omp parallel for schedule(static, 1) num_threads(parts)
    for (int t = 0; t < parts; ++t) {
      for (int b = band_tiles * t / parts; b < band_tiles * (t + 1) / parts; ++b)
        values.for_each_point_in_tile(band[b], [&](const VecI<Dim>& c, double* v) {
          v[kRow] = -1.0;
          if (*rho.find(c) > 0.0 || v[kTarget] > 0.0) part[t].push_back(grid.cell_index(c));
        });
      std::sort(part[t].begin(), part[t].end());
    }
    cells.swap(part[0]);
    std::vector<int> merged;
    for (int t = 1; t < parts; ++t) {
      merged.resize(cells.size() + part[t].size());
      std::merge(cells.begin(), cells.end(), part[t].begin(), part[t].end(), merged.begin());
      cells.swap(merged);
    }
  }
  const int n = static_cast<int>(cells.size());
#pragma omp parallel for schedule(static) num_threads(team_threads(n))
  for (int r = 0; r < n; ++r) values.find(grid.cell_coord(cells[r]))[kRow] = r;
  // the row of cell c (coordinates, wrapped on periodic axes; -1 outside the domain, outside the
  // band or not an unknown)
  auto row_of = [&](VecI<Dim> c) {
    c = grid.wrap_cell(c);
    if (!grid.cell_in_range(c)) return -1;
    const double* v = values.find(c);
    return v ? static_cast<int>(v[kRow]) : -1;
  };
  stats.cells = n;
  if (n == 0) return stats;

  // with the dead band: how much more the level set encloses than the particles, over the band
  // (both sums see the walls and solids alike), and the share of the surface band's deficits
  // corrected at that (the other rules need no sums)
  const double mismatch = surface_deficits == SurfaceDeficits::beyond_dead_band
                              ? level_set_volume_mismatch(grid, cells, rho, values)
                              : 0.0;
  const double deficit_share = surface_deficit_share(surface_deficits, mismatch);
  stats.volume_mismatch = mismatch;
  stats.deficit_share = deficit_share;

  // with q = -psi dx^2: (-L dx^2) psi = e (rows in cell order), and the move is grad q.
  // The rows are made on several threads, each row by one: its entries (at most 2 Dim + 1) in
  // the order of the loops below, sorted by column with the entries of one column summed in
  // that order (a column twice only across a periodic axis of two cells), which is what
  // setFromTriplets made of the same entries, bit for bit; then laid out row after row
  constexpr int kRowEntries = 2 * Dim + 1;
  // (unset: each row writes its count and its first `count` entries, the only ones read)
  UnsetVector<int> entry_column(static_cast<std::size_t>(n) * kRowEntries);
  UnsetVector<double> entry_value(entry_column.size());
  UnsetVector<int> row_entries(n);
  // (the surface band's deficits listed by to_solve: flagged per row, e before the share)
  const bool listing = surface_deficits == SurfaceDeficits::to_solve;
  const bool holding = held_near != nullptr && !held_near->empty() && held_reach > 0.0;
  const double held_distance = held_reach * dx;
  std::vector<unsigned char> listed_deficit(listing ? n : 0, 0);
  std::vector<double> deficit_before_share(listing ? n : 0, 0.0);
  VectorX rhs(n);
#pragma omp parallel for schedule(static) num_threads(team_threads(static_cast<long>(n) * kRowEntries))
  for (int r = 0; r < n; ++r) {
    const int c = cells[r];
    const VecI<Dim> ci = grid.cell_coord(c);
    const double* v = values.find(ci);
    int* column = entry_column.data() + static_cast<std::size_t>(r) * kRowEntries;
    double* value = entry_value.data() + static_cast<std::size_t>(r) * kRowEntries;
    int count = 0;
    const auto add = [&](int col, double val) {
      // insertion by column: a column already listed sums (in the order of the loops)
      int k = 0;
      while (k < count && column[k] < col) ++k;
      if (k < count && column[k] == col) {
        value[k] += val;
        return;
      }
      for (int m = count; m > k; --m) {
        column[m] = column[m - 1];
        value[m] = value[m - 1];
      }
      column[k] = col;
      value[k] = val;
      ++count;
    };
    double diag = 0.0;
    for (int a = 0; a < Dim; ++a)
      for (int s = 0; s < 2; ++s) {
        // the face between c and its neighbour along a (s = 0: minus side, 1: plus side)
        VecI<Dim> fc = ci;
        fc[a] += s;
        if (grid.periodic(a) && fc[a] == grid.cells()[a]) fc[a] = 0;  // the stored seam face
        const int fi = grid.face_index(a, fc);
        const double wf = fluid_face[fi];
        if (!(wf > 0.0)) continue;
        diag += wf;
        VecI<Dim> cj = ci;
        cj[a] += s == 0 ? -1 : 1;
        const int j = grid.cell_index_or_outside(cj);
        const int rj = j >= 0 ? row_of(cj) : -1;
        if (rj >= 0 && j != c) add(rj, -wf);
      }
    // a tiny shift keeps fully enclosed liquid (no air neighbour) non-singular
    add(r, diag * (1.0 + 1e-6) + 1e-12);
    row_entries[r] = count;
    // On the air side of the surface (T_c < 1/2) a deficit (e < 0) is not corrected: there T
    // measures where the reconstructed surface lies, and the surface follows the particles, so
    // moving particles cannot remove it. Chasing it pulls particles into every bump of the level
    // set (a bump reads more liquid than the particles under it splat), which raises the bump
    // further: on water at rest, projection after projection roughened the surface (column
    // heights 0.034 -> 0.11 dx in 2D, 0.028 -> 0.059 dx in 3D over 100-200 calls) and fed waves.
    // An excess there (particles outside the level set: drops, thin sheets) is still spread.
    // Next to a solid a low T_c can come from the solid filling part of the cell, not from a
    // free surface, so with solids the air side is read from the level set extended into them.
    // On the liquid side of the surface band (1/2 <= T_c < kProjectionFullCell) a deficit is
    // corrected by deficit_share (1 by default; the measurement switches: 0, or the dead band's
    // share, docs/particles.md "Sloshing").
    double e = *rho.find(ci) - v[kTarget];
    if (holding && held_near->distance(grid.cell_center(ci)) < held_distance)
      // (the cells beside a moving body: not corrected, see project_particle_density)
      e = 0.0;
    else if ((solids.empty() ? v[kTarget] : v[kWet]) < kProjectionAirSide)
      e = std::max(e, 0.0);
    else if (v[kTarget] < kProjectionFullCell && e < 0.0) {
      if (surface_deficits == SurfaceDeficits::to_solve) {
        listed_deficit[r] = 1;
        deficit_before_share[r] = e;
      }
      e *= deficit_share;
    }
    rhs[r] = e;
  }
  // the sums and the list in row order, as the serial loop made them
  for (int r = 0; r < n; ++r) {
    if (!listed_deficit.empty() && listed_deficit[r])
      stats.surface_deficits.emplace_back(cells[r], deficit_before_share[r]);
    stats.error_before += std::abs(rhs[r]) * cell_volume;
  }
  SparseMatrix A(n, n);
  {
    std::vector<int> row_start(static_cast<std::size_t>(n) + 1, 0);
    for (int r = 0; r < n; ++r) row_start[r + 1] = row_start[r] + row_entries[r];
    A.resizeNonZeros(row_start[n]);
    std::copy(row_start.begin(), row_start.end(), A.outerIndexPtr());
    int* inner = A.innerIndexPtr();
    double* nonzero = A.valuePtr();
#pragma omp parallel for schedule(static) num_threads(team_threads(static_cast<long>(row_start[n])))
    for (int r = 0; r < n; ++r) {
      const std::size_t from = static_cast<std::size_t>(r) * kRowEntries;
      std::copy(entry_column.begin() + from, entry_column.begin() + from + row_entries[r],
                inner + row_start[r]);
      std::copy(entry_value.begin() + from, entry_value.begin() + from + row_entries[r],
                nonzero + row_start[r]);
    }
  }
  Eigen::ConjugateGradient<SparseMatrix, Eigen::Lower | Eigen::Upper,
                           Eigen::DiagonalPreconditioner<double>>
      cg;
  cg.setTolerance(kProjectionTolerance);
  cg.setMaxIterations(4 * n + 100);
  cg.compute(A);
  // On one thread: Eigen would split each product of the CG (a row-major view above 20000
  // non-zeros) over the process team, a parallel region per iteration around a few tens of
  // microseconds of work (the 64^3 viscous bunny: 8k rows, 54k non-zeros, ~45 iterations), and
  // the vector operations between them are serial anyway; the regions cost more than they saved
  // on two threads (the CG's CPU time rose from 2.6 to 14 ms per frame, measured at load 8;
  // docs/benchmarks.md, threads14). Each row's product is
  // summed by one thread either way: the same bits.
  // (threads15 ran the whole CG in one parallel region, Eigen's steps and bits with five
  // barriers per iteration: at load 7-8 its two threads took 16 ms each per frame against
  // 2.7 ms on one, for at most ~1 ms to gain on an idle machine; docs/benchmarks.md, threads15)
  const int eigen_threads = Eigen::nbThreads();
  Eigen::setNbThreads(1);
  const VectorX psi = cg.solve(rhs);  // in units of dx^2
  Eigen::setNbThreads(eigen_threads);
  stats.iterations = static_cast<int>(cg.iterations());

  // displacement on the faces: -omega grad psi (psi = 0 in air), zero through walls and solids;
  // nonzero only on the faces of the unknowns. Each face is written by one cell: its minus cell
  // if that is an unknown, else its plus cell.
  // (issue 20, p2g21) The storage is the caller's, kept across calls: zero on every face at the
  // lend (the faces the last call wrote zeroed, the rest zero since; a fresh one's zeros from
  // the kernel, KeptZeros::lend), so every face the particles' stencils read holds what the
  // whole-grid fill gave, and no face outside the rows' is written. The faces each component's
  // rows write lie in [written_lo[a], written_hi[a]] (min and max: the same for any split),
  // handed back as the dirty spans the next lend zeroes. Before, a fresh 202 MB vector per call
  // at Fig. 2's paper grid had the liquid's layers zeroed: first touches at every call.
  // (two24) The kept storage's dirty spans are zeroed here in the region that writes the rows,
  // in blocks on the team, not by KeptZeros::lend on the calling thread (the spans cover the
  // liquid's layers of every component: about 2 MB per call on the 64^3 viscous bunny)
  VectorX move;
  std::vector<std::pair<long, long>> stale;  // blocks of the kept storage to zero first
  long stale_entries = 0;
  if (move_scratch.values.size() == nf) {
    constexpr long kZeroBlock = 1L << 14;
    for (const auto& [b, e] : move_scratch.dirty) {
      stale_entries += e - b;
      for (long from = b; from < e; from += kZeroBlock)
        stale.emplace_back(from, std::min(e, from + kZeroBlock));
    }
    move.swap(move_scratch.values);
    move_scratch.values = VectorX();
    move_scratch.dirty.clear();
  } else {
    move_scratch.lend(nf, move);
  }
  long written_lo[Dim], written_hi[Dim];
  for (int a = 0; a < Dim; ++a) {
    written_lo[a] = nf;
    written_hi[a] = -1;
  }
  {
    const int blocks = static_cast<int>(stale.size());
#pragma omp parallel num_threads(team_threads(std::max<long>(n, stale_entries)))
    {
      // (a barrier after it: a row may write a face of another thread's block)
#pragma omp for schedule(static)
      for (int b = 0; b < blocks; ++b)
        std::fill(move.data() + stale[b].first, move.data() + stale[b].second, 0.0);
#pragma omp for schedule(static) reduction(min : written_lo[:Dim]) reduction(max : written_hi[:Dim])
      for (int r = 0; r < n; ++r) {
        const VecI<Dim> ci = grid.cell_coord(cells[r]);
        for (int a = 0; a < Dim; ++a) {
          VecI<Dim> lower = ci, upper = ci;
          lower[a] -= 1;
          upper[a] += 1;
          const int r_minus = row_of(lower);
          const int r_plus = row_of(upper);
          // the face on the minus side (unless the minus cell writes it) and on the plus side
          for (int s = 0; s < 2; ++s) {
            if (s == 0 && r_minus >= 0) continue;
            VecI<Dim> fc = ci;
            fc[a] += s;
            if (grid.periodic(a) && fc[a] == grid.cells()[a]) fc[a] = 0;  // the stored seam face
            const int f = grid.face_index(a, fc);
            if (!(fluid_face[f] > 0.0)) continue;
            const double pm = s == 0 ? 0.0 : psi[r];
            const double pp = s == 0 ? psi[r] : (r_plus >= 0 ? psi[r_plus] : 0.0);
            move[f] = -kProjectionRelaxation * (pp - pm) * dx;  // psi dx^2 / dx
            written_lo[a] = std::min<long>(written_lo[a], f);
            written_hi[a] = std::max<long>(written_hi[a], f);
          }
        }
      }
    }
  }

  // move the particles (at most kProjectionMaxStep dx), then keep clear of solids and walls
  const double cap = kProjectionMaxStep * dx;
  double max_move = 0.0;
#pragma omp parallel for schedule(static) reduction(max : max_move) num_threads(process_threads())
  for (long p = 0; p < np; ++p) {
    Vec<Dim> d = grid.interpolate_velocity(move, particles.x[p]);
    const double len = d.norm();
    if (len > cap) d *= cap / len;
    max_move = std::max(max_move, std::min(len, cap));
    Vec<Dim> x = particles.x[p] + d;
    settle_position(grid, solids, boundary, false, x);
    particles.x[p] = x;
  }
  stats.max_move = max_move;
  // the storage back to the caller, with the spans its rows wrote
  move_scratch.values.swap(move);
  for (int a = 0; a < Dim; ++a)
    if (written_lo[a] <= written_hi[a])
      move_scratch.dirty.emplace_back(written_lo[a], written_hi[a] + 1);
  return stats;
}

}  // namespace

/// Grid density projection (after Kugelstadt et al. 2019), with e the volume-fraction error:
///   rho~_c = dx^-Dim sum_p V_p w_cp     (V_p = m_p / rho_p, w_cp the hat of cell c averaged over
///                                        the box of side s_p = V_p^(1/Dim) around x_p)
///   T_c    = dx^-Dim int hat_c(x) H(-phi(x)) dx           (the same kernel on the level set)
///   e_c    = rho~_c - T_c, or max(0, rho~_c - T_c) where T_c < 1/2 (the air side of the surface),
///            a deficit times s(M) where 1/2 <= T_c < 0.999 (the surface band's liquid side), with
///            M = sum T / sum rho~ - 1 and s the dead-band share of surface_deficit_share
///   L q = e on S = {c : rho~_c > 0 or T_c > 0},  (L q)_c = sum_f W_F^u_f (q_nb - q_c) / dx^2,
///         q = 0 outside S (air), no flux through faces with W_F^u = 0 (walls, solids);
///   x_p <- x_p + omega grad q (x_p),  grad q on the faces, interpolated like a velocity.
/// L is num_S x num_S, negative semi-definite; the solve uses -L dx^2 (symmetric positive
/// definite) with a diagonally preconditioned conjugate gradient. Since div(grad q) = e, the move
/// empties over-full cells (e > 0) into under-full ones to first order.
template <int Dim>
DensityProjectionStats project_particle_density(Particles<Dim>& particles, const MacGrid<Dim>& grid,
                                                const SampleLattice<Dim>& lattice,
                                                const VectorX& fluid_face,
                                                const SolidField<Dim>& solids,
                                                const std::array<BoundaryType, 2 * Dim>& boundary,
                                                int iterations,
                                                SurfaceDeficits surface_deficits,
                                                KeptZeros* move_scratch,
                                                const SolidField<Dim>* held_near,
                                                double held_reach) {
  DensityProjectionStats total;
  KeptZeros own;  // the displacement's storage when the caller keeps none (over the iterations)
  KeptZeros& scratch = move_scratch ? *move_scratch : own;
  for (int it = 0; it < iterations; ++it) {
    const DensityProjectionStats one = project_density_once(
        particles, grid, lattice, fluid_face, solids, boundary, surface_deficits, scratch,
        held_near, held_reach);
    if (it == 0)
      total = one;
    else {
      total.iterations += one.iterations;
      total.max_move = std::max(total.max_move, one.max_move);
      total.surface_deficits = one.surface_deficits;
    }
  }
  return total;
}

// --- liquid surface ------------------------------------------------------------------------------

/// The liquid/air domain of Algorithm 1 line 4, after Zhu & Bridson (2005):
/// phi(x) = |x - x_bar(x)| - r_bar(x), with x_bar and r_bar the kernel-
/// weighted averages of the particle positions and radii, k(s) = max(0, 1 - s^2)^3, s = |x - x_p|
/// / R. Particles splat onto the lattice points within R, with their images: shifted by the
/// period on periodic axes, reflected across wall faces within R (x' = 2 x_wall - x per
/// reflected axis, which puts the points on the wall at the centre of a symmetric cloud). A
/// reflected image reaches only lattice points its particle reaches. Slabs of the last axis wider
/// than 2 R are processed even/odd in parallel, so no two threads touch the same point and every
/// point sums its contributions in particle order (deterministic for any thread count).
template <int Dim>
VectorX liquid_phi_on_lattice(const Particles<Dim>& particles, const MacGrid<Dim>& grid,
                              const SampleLattice<Dim>& lattice,
                              const std::array<BoundaryType, 2 * Dim>& boundary,
                              const SolidField<Dim>& solids) {
  VectorX phi;
  liquid_phi_on_lattice(particles, grid, lattice, boundary, solids, phi);
  return phi;
}

namespace {

/// The splat of liquid_phi_on_lattice (particles > 0): per lattice point the sums of k, k r_p and
/// k x_p over the particles and images that reach it, in tiles made where they reach (`acc`,
/// reset here). Returns the largest kernel support, the level set's value where nothing reaches.
template <int Dim>
double surface_sums(const Particles<Dim>& particles, const MacGrid<Dim>& grid,
                    const SampleLattice<Dim>& lattice,
                    const std::array<BoundaryType, 2 * Dim>& boundary,
                    const SolidField<Dim>& solids, TiledLattice<Dim, double, Dim + 2>& acc) {
  const long np = static_cast<long>(particles.size());
  const double h = lattice.spacing;
  const double dx = grid.dx();

  // per-particle support and radius (the spacing's pow once per run of equal mass and density;
  // unset until the loop below writes every particle's)
  UnsetVector<double> support(np), radius(np);
  double max_support = 0.0;
#pragma omp parallel reduction(max : max_support) num_threads(process_threads())
  {
    SpacingOf<Dim> spacing_of(particles, dx);
#pragma omp for schedule(static)
    for (long p = 0; p < np; ++p) {
      const double s = spacing_of(p);
      support[p] = kSurfaceSupport * s;
      radius[p] = ParticleTraits<Dim>::surface_radius * s;
      max_support = std::max(max_support, support[p]);
    }
  }

  // slabs along the last axis, width > 2 R in lattice points
  constexpr int kLast = Dim - 1;
  // (a particle next to a solid reaches up to 2 R through its image, see below: slabs > 4 R)
  const double reach_factor = solids.empty() ? 1.0 : 2.0;
  const int width = static_cast<int>(std::ceil(2.0 * reach_factor * max_support / h)) + 2;
  const int slabs = std::max(1, (lattice.dims[kLast] + width - 1) / width);
  // The particles by slab, in particle order within a slab (a stable counting sort, whose result
  // is unique: the same for any team), on several threads: fixed blocks of particles count their
  // slabs, every block's share of a slab starts after the earlier slabs and the earlier blocks'
  // share of it, and each block places its particles in order. The same pass counts the
  // particles' lattice indices along axis 0 for the parts of the splat below (integer counts:
  // any split gives them).
  const int parts = std::max(1, std::min(process_threads(), lattice.dims[0]));
  const int blocks = std::max(1, team_threads(np));
  // (slab_of and order unset: the sort writes every particle's and every slot's)
  UnsetVector<int> slab_of(np), order(np);
  std::vector<int> slab_start(slabs + 1, 0);
  std::vector<std::vector<int>> slab_count(blocks, std::vector<int>(slabs, 0));
  std::vector<std::vector<long>> index_count(parts > 1 ? blocks : 0,
                                             std::vector<long>(lattice.dims[0], 0));
  const auto block_begin = [&](int b) { return np * b / blocks; };
  // A part of the splat below (a clip along axis 0, with several parts) skips the particles that
  // add to none of its points. Every point a particle adds to lies within 3 R of it along axis 0:
  // within R of the particle, of a wall mirror image (made only within R of the wall, so within
  // 2 R of the particle) or of the solid image (2 d < 2 R away; its points also within 2 R of the
  // particle). Per slot of `order` (written with it, so the parts read it in their order): the
  // lattice indices along axis 0 of [x - 3 R_max - h, x + 3 R_max + h] rounded inwards (the
  // extra spacing covers the roundings); the whole axis on a periodic axis 0 (images a period
  // away) and for a non-finite position. Each part used to find every particle's image segments
  // and offsets only to clip them away (docs/benchmarks.md, two23).
  const bool clip_skips = parts > 1 && !grid.periodic(0);
  UnsetVector<std::array<int, 2>> slot_reach(clip_skips ? np : 0);
  const double clip_reach = 3.0 * max_support / h + 1.0;
  const auto reach_of = [&](long p) -> std::array<int, 2> {
    const double s = (particles.x[p][0] - lattice.origin[0]) / h;
    if (!std::isfinite(s)) return {0, lattice.dims[0] - 1};
    const double lo = std::clamp(s - clip_reach, -1.0, static_cast<double>(lattice.dims[0]));
    const double hi = std::clamp(s + clip_reach, -1.0, static_cast<double>(lattice.dims[0]));
    return {static_cast<int>(std::ceil(lo)), static_cast<int>(std::floor(hi))};
  };
  // (the sort's two passes share one parallel region with the solid images and the flagging of
  // the tiles below; they were four regions)
  const auto count_blocks = [&] {
#pragma omp for schedule(static, 1)
    for (int b = 0; b < blocks; ++b)
      for (long p = block_begin(b); p < block_begin(b + 1); ++p) {
        const double s = (particles.x[p][kLast] - lattice.origin[kLast]) / h;
        const int k = static_cast<int>(std::floor(s / width));
        slab_of[p] = std::clamp(k, 0, slabs - 1);
        ++slab_count[b][slab_of[p]];
        if (parts > 1) {
          const double s0 = (particles.x[p][0] - lattice.origin[0]) / h;
          ++index_count[b][std::clamp(static_cast<int>(std::floor(s0)), 0, lattice.dims[0] - 1)];
        }
      }
#pragma omp single
    {
      int start = 0;
      for (int k = 0; k < slabs; ++k) {
        slab_start[k] = start;
        for (int b = 0; b < blocks; ++b) {
          const int c = slab_count[b][k];
          slab_count[b][k] = start;
          start += c;
        }
      }
      slab_start[slabs] = start;
    }
#pragma omp for schedule(static, 1) nowait
    for (int b = 0; b < blocks; ++b)
      for (long p = block_begin(b); p < block_begin(b + 1); ++p) {
        const int slot = slab_count[b][slab_of[p]]++;
        order[slot] = static_cast<int>(p);
        if (clip_skips) slot_reach[slot] = reach_of(p);
      }
  };

  // periodic images: shift by +-L on periodic axes; mirror images across wall faces
  std::array<double, Dim> period{};
  for (int a = 0; a < Dim; ++a) period[a] = grid.periodic(a) ? grid.cells()[a] * dx : 0.0;
  const Box<Dim> box = grid.domain_box();
  std::array<bool, 2 * Dim> mirror{};
  for (int a = 0; a < Dim; ++a)
    for (int side = 0; side < 2; ++side)
      mirror[2 * a + side] = !grid.periodic(a) && boundary[2 * a + side] == BoundaryType::wall;

  // the solid distance of the lattice points an image reaches, computed once per point when
  // first needed (NaN: not yet); within a phase only one thread touches a point. Tiles only
  // where a solid image reaches (issue 20: a half-lattice vector is 541 MB at 256x128x256).
  TiledLattice<Dim, double> solid_distance(lattice.dims, std::numeric_limits<double>::quiet_NaN());

  // the sums of each lattice point side by side (weight, radius, position): one cache line per
  // point touched instead of three arrays' worth, in tiles of 8^Dim points made only where a
  // particle or one of its images reaches (0 elsewhere: no particle)
  constexpr int kStride = Dim + 2;
  acc.reset(lattice.dims, 0.0);
  constexpr int kSplatTile = TiledLattice<Dim, double, kStride>::kTile;
  // each particle's image across the nearest solid surface (NaN where it has none), found before
  // the tiles are made and read by the splat (unset: the images' loop writes every particle's;
  // its NaN fill ran on the calling thread, two24)
  UnsetVector<Vec<Dim>> solid_image;
  if (!solids.empty()) solid_image.resize(np);

  // splat one particle (with its periodic and wall images) onto the lattice points whose index
  // along axis 0 lies in [clip_lo, clip_hi]; with `make_tiles` it only flags the tiles under
  // every box the splat visits (before the splat, which then makes no tile)
  std::vector<unsigned char> acc_flags = acc.tile_flags(), solid_flags = solid_distance.tile_flags();
  const int all_lo = 0, all_hi = lattice.dims[0] - 1;
  auto splat = [&](int p, bool make_tiles, int clip_lo, int clip_hi) {
    const Vec<Dim> xp = particles.x[p];
    const double R = support[p];
    const double inv_r2 = 1.0 / (R * R);
    // per axis up to three image segments: (image coordinate, first index, last index)
    std::array<std::array<double, 3>, Dim> img;
    std::array<std::array<int, 3>, Dim> lo, hi;
    std::array<int, Dim> nseg;
    for (int a = 0; a < Dim; ++a) {
      nseg[a] = 0;
      for (int k = -1; k <= 1; ++k) {
        double xa = xp[a];
        if (period[a] != 0.0) {
          xa += k * period[a];
        } else if (k != 0) {
          // the mirror image across a wall within the support
          const int side = k < 0 ? 0 : 1;
          const double wall = k < 0 ? box.min()[a] : box.max()[a];
          if (!mirror[2 * a + side] || std::abs(xp[a] - wall) >= R) continue;
          xa = 2.0 * wall - xp[a];
        }
        const int i0 = std::max(0, static_cast<int>(std::ceil((xa - R - lattice.origin[a]) / h)));
        const int i1 = std::min(lattice.dims[a] - 1,
                                static_cast<int>(std::floor((xa + R - lattice.origin[a]) / h)));
        if (i0 > i1) continue;
        img[a][nseg[a]] = xa;
        lo[a][nseg[a]] = i0;
        hi[a][nseg[a]] = i1;
        ++nseg[a];
      }
      if (nseg[a] == 0) return;
    }
    // every combination of image segments
    std::array<int, Dim> seg{};
    while (true) {
      Vec<Dim> xi;
      VecI<Dim> i0, i1;
      for (int a = 0; a < Dim; ++a) {
        xi[a] = img[a][seg[a]];
        i0[a] = lo[a][seg[a]];
        i1[a] = hi[a][seg[a]];
      }
      // the whole box decides the offsets (as without a clip); the clip narrows the points
      // visited along axis 0 only
      const VecI<Dim> base = i0;
      const int first0 = std::max(i0[0], clip_lo), last0 = std::min(i1[0], clip_hi);
      // the offsets lattice.position(i) - xi per axis (a lattice position's component depends
      // on its own index only), computed once per segment with the same arithmetic
      std::array<std::array<double, kMaxSplatPoints>, Dim> offset;
      bool fits = true;
      for (int a = 0; a < Dim; ++a) fits = fits && i1[a] - i0[a] < kMaxSplatPoints;
      if (fits) {
        for (int a = 0; a < Dim; ++a)
          for (int j = i0[a]; j <= i1[a]; ++j)
            offset[a][j - i0[a]] = (lattice.origin[a] + static_cast<double>(j) * h) - xi[a];
      }
      const double rp = radius[p];
      i0[0] = first0;
      i1[0] = last0;
      if (make_tiles && first0 <= last0) acc.mark_box(i0, i1, acc_flags);
      // The points within R of the image (q2 < 1) of each row along axis 0 are a run around
      // the row's point nearest the image on that axis, j* (its squared offset the smallest):
      // q2 is the same squaredNorm of the same offsets as point by point, and it does not
      // decrease with any one squared offset (every rounding is monotone), which along the row
      // falls to j* and rises after it. So a row whose j* is not within R has no such point,
      // and a row's run is found from j* outwards: the same points take the same k, each point
      // once (rows of a segment's box are mostly outside its ball: about 70 of the 125 points of
      // a 5^3 box were tested for nothing; docs/benchmarks.md, particles18)
      if (!make_tiles && fits && first0 <= last0) {
        int jstar = first0;
        double smallest = std::numeric_limits<double>::infinity();
        for (int j = first0; j <= last0; ++j) {
          const double o = offset[0][j - base[0]];
          if (o * o < smallest) {
            smallest = o * o;
            jstar = j;
          }
        }
        const auto q2_at = [&](const VecI<Dim>& c) {
          Vec<Dim> d;
          for (int b = 0; b < Dim; ++b) d[b] = offset[b][c[b] - base[b]];
          return d.squaredNorm() * inv_r2;
        };
        const auto add = [&](const VecI<Dim>& c, double q2) {
          const double t = 1.0 - q2;
          const double k = t * t * t;
          double* sum = acc.find(c);
          sum[0] += k;
          sum[1] += k * rp;
          for (int b = 0; b < Dim; ++b) sum[2 + b] += k * xi[b];
        };
        VecI<Dim> i = i0;
        i[0] = jstar;
        while (true) {
          const double q2 = q2_at(i);
          if (q2 < 1.0) {
            add(i, q2);
            VecI<Dim> c = i;
            for (c[0] = jstar - 1; c[0] >= first0; --c[0]) {
              const double q = q2_at(c);
              if (!(q < 1.0)) break;
              add(c, q);
            }
            for (c[0] = jstar + 1; c[0] <= last0; ++c[0]) {
              const double q = q2_at(c);
              if (!(q < 1.0)) break;
              add(c, q);
            }
          }
          int a = 1;
          for (; a < Dim; ++a) {
            if (++i[a] <= i1[a]) break;
            i[a] = i0[a];
          }
          if (a == Dim) break;
        }
      }
      VecI<Dim> i = i0;
      // the sums of point i, found once per run of points along axis 0 within one tile (the
      // points of a tile row are consecutive in it), null until needed
      double* row = nullptr;
      while (!make_tiles && !fits && first0 <= last0) {
        Vec<Dim> d;
        if (fits) {
          for (int a = 0; a < Dim; ++a) d[a] = offset[a][i[a] - base[a]];
        } else {
          d = lattice.position(i) - xi;
        }
        const double q2 = d.squaredNorm() * inv_r2;
        if (q2 < 1.0) {
          const double t = 1.0 - q2;
          const double k = t * t * t;
          if (!row) row = acc.find(i);
          double* sum = row;
          sum[0] += k;
          sum[1] += k * rp;
          for (int a = 0; a < Dim; ++a) sum[2 + a] += k * xi[a];
        }
        int a = 0;
        for (; a < Dim; ++a) {
          if (++i[a] <= i1[a]) break;
          i[a] = i0[a];
        }
        if (a == Dim) break;
        if (a == 0 && row && i[0] % kSplatTile != 0)
          row += kStride;
        else
          row = nullptr;
      }
      int a = 0;
      for (; a < Dim; ++a) {
        if (++seg[a] < nseg[a]) break;
        seg[a] = 0;
      }
      if (a == Dim) break;
    }
    // the mirror image across the nearest solid surface within the support (x' = x - 2 d n),
    // added at the lattice points the particle itself reaches and at those inside the solids
    // (within 2 R of the particle): the points near the solid then see a symmetric cloud, the
    // level set inside the solid next to liquid reads liquid (about as far in as the liquid
    // reaches out), and no image reaches through a thin solid to its dry side. Without the
    // points inside, a point about 1 dx deep got a contribution or not depending on where the
    // jittered particles sat, and the weights of the cells cut by the solid (read on the level
    // set extended into it, extend_liquid_into_solids) followed: left and right of a settling
    // disk they differed by up to 0.2 and pushed it sideways (docs/particles.md)
    if (solids.empty()) return;
    const Vec<Dim> xm = solid_image[p];
    if (std::isnan(xm[0])) return;
    VecI<Dim> j0, j1;
    for (int a = 0; a < Dim; ++a) {
      j0[a] = std::max(0, static_cast<int>(std::ceil((xm[a] - R - lattice.origin[a]) / h)));
      j1[a] = std::min(lattice.dims[a] - 1,
                       static_cast<int>(std::floor((xm[a] + R - lattice.origin[a]) / h)));
      if (a == 0) {
        j0[a] = std::max(j0[a], clip_lo);
        j1[a] = std::min(j1[a], clip_hi);
      }
      if (j0[a] > j1[a]) return;
    }
    if (make_tiles) {
      acc.mark_box(j0, j1, acc_flags);
      solid_distance.mark_box(j0, j1, solid_flags);
      return;
    }
    const double inv_reach2 = 0.25 * inv_r2;
    VecI<Dim> i = j0;
    while (true) {
      const Vec<Dim> y = lattice.position(i);
      const double q2 = (y - xm).squaredNorm() * inv_r2;
      const double p2 = (y - xp).squaredNorm();
      bool reached = q2 < 1.0 && p2 * inv_reach2 < 1.0;
      if (reached && !(p2 * inv_r2 < 1.0)) {
        double& ds = *solid_distance.find(i);
        if (std::isnan(ds)) ds = solids.distance(y);
        reached = ds < 0.0;
      }
      if (reached) {
        const double t = 1.0 - q2;
        const double k = t * t * t;
        double* sum = acc.find(i);
        sum[0] += k;
        sum[1] += k * radius[p];
        for (int a = 0; a < Dim; ++a) sum[2 + a] += k * xm[a];
      }
      int a = 0;
      for (; a < Dim; ++a) {
        if (++i[a] <= j1[a]) break;
        i[a] = j0[a];
      }
      if (a == Dim) break;
    }
  };

  // each particle's image across the nearest solid surface within its support (independent per
  // particle, in parallel), then the tiles under every box a particle or an image reaches,
  // flagged in parallel and made before the splat
  // (in the region of the sort above; the images are complete before any splat reads them)
#pragma omp parallel num_threads(process_threads())
  {
    count_blocks();
    if (!solids.empty()) {
#pragma omp for schedule(static)
      for (long p = 0; p < np; ++p) {
        solid_image[p] = Vec<Dim>::Constant(std::numeric_limits<double>::quiet_NaN());
        const Vec<Dim> xp = particles.x[p];
        const double d = solids.distance(xp);
        if (!(d > 0.0) || d >= support[p]) continue;
        const Vec<Dim> n = solids.gradient(xp);
        const double len = n.norm();
        if (!(len > 0.0)) continue;
        solid_image[p] = xp - (2.0 * d / len) * n;
      }
    }
#pragma omp for schedule(static)
    for (long p = 0; p < np; ++p) splat(static_cast<int>(p), true, all_lo, all_hi);
  }
  // (the tiles' memory claimed here, filled in the splat's region below before its phases)
  const std::vector<double*> fresh_acc = acc.claim_tiles(acc_flags);
  const std::vector<double*> fresh_distance = solid_distance.claim_tiles(solid_flags);

  // phases: even slabs, odd slabs, then (periodic last axis) the two end slabs serially
  const bool wrap_last = grid.periodic(kLast);
  const bool serial = wrap_last && slabs < 5;
  std::vector<int> phase_slabs[3];
  for (int k = 0; k < slabs; ++k) {
    if (serial || (wrap_last && (k == 0 || k == slabs - 1)))
      phase_slabs[2].push_back(k);
    else
      phase_slabs[k % 2].push_back(k);
  }
  // Within a phase the threads split the lattice along axis 0, not the slabs: one slab often
  // holds most of the particles (the 64^3 viscous bunny: 18236 of 19504 in phase 0), so a slab
  // per thread left the splat nearly serial. Each part walks the phase's slabs and particles in
  // the serial order and adds only into its own points, so every point sums its contributions
  // in the same order as one thread does (the same bits for any team). The parts' bounds cut
  // the particles' axis-0 lattice indices into equal counts (any bounds give the same bits).
  // (parts and the particles' axis-0 index counts: with the slabs above)
  std::vector<int> part_lo(parts, all_lo), part_hi(parts, all_hi);
  if (parts > 1) {
    std::vector<long> histogram(lattice.dims[0] + 1, 0);
    for (int b = 0; b < blocks; ++b)
      for (int i = 0; i < lattice.dims[0]; ++i) histogram[i + 1] += index_count[b][i];
    for (int i = 0; i < lattice.dims[0]; ++i) histogram[i + 1] += histogram[i];
    int i = 0;
    for (int k = 1; k < parts; ++k) {
      // part k - 1 ends at the last index whose running count stays below k / parts of np
      while (i < lattice.dims[0] && histogram[i + 1] * parts < np * k) ++i;
      part_hi[k - 1] = std::max(i, part_lo[k - 1]) - 1;
      part_lo[k] = part_hi[k - 1] + 1;
    }
  }
  // (the new tiles' filling and phases 0 and 1 in one parallel region, a barrier after each;
  // phase 2 after it on one thread)
  {
    const int na = static_cast<int>(fresh_acc.size()), nd = static_cast<int>(fresh_distance.size());
#pragma omp parallel num_threads(std::max(parts, team_threads(static_cast<long>(na + nd) * TiledLattice<Dim, double>::kTilePoints)))
    {
#pragma omp for schedule(static) nowait
      for (int t = 0; t < na; ++t) acc.fill_tile(fresh_acc[t]);
#pragma omp for schedule(static)
      for (int t = 0; t < nd; ++t) solid_distance.fill_tile(fresh_distance[t]);
      for (int phase = 0; phase < 2; ++phase) {
        const std::vector<int>& list = phase_slabs[phase];
        const int count = static_cast<int>(list.size());
#pragma omp for schedule(static, 1)
        for (int part = 0; part < parts; ++part)
          for (int s = 0; s < count; ++s)
            for (int q = slab_start[list[s]]; q < slab_start[list[s] + 1]; ++q) {
              if (clip_skips &&
                  (slot_reach[q][1] < part_lo[part] || slot_reach[q][0] > part_hi[part]))
                continue;
              splat(order[q], false, part_lo[part], part_hi[part]);
            }
      }
    }
  }
  {
    const std::vector<int>& list = phase_slabs[2];
    for (int s = 0; s < static_cast<int>(list.size()); ++s)
      for (int q = slab_start[list[s]]; q < slab_start[list[s] + 1]; ++q)
        splat(order[q], false, all_lo, all_hi);
  }

  return max_support;
}

/// The slots of the made tiles of `acc`, in slot order.
template <int Dim, int Stride>
std::vector<int> made_tile_slots(const TiledLattice<Dim, double, Stride>& acc) {
  std::vector<int> tiles;
  for (int t = 0; t < acc.num_tile_slots(); ++t)
    if (acc.has_tile(t)) tiles.push_back(t);
  return tiles;
}

/// phi = |x - x_bar| - r_bar at a lattice point from its sums (weight > 0).
template <int Dim>
double surface_phi(const SampleLattice<Dim>& lattice, const VecI<Dim>& c, const double* sum) {
  Vec<Dim> xbar;
  for (int a = 0; a < Dim; ++a) xbar[a] = sum[2 + a] / sum[0];
  return (lattice.position(c) - xbar).norm() - sum[1] / sum[0];
}

template <int Dim>
void liquid_phi_tiles(const Particles<Dim>& particles, const MacGrid<Dim>& grid,
                      const SampleLattice<Dim>& lattice,
                      const std::array<BoundaryType, 2 * Dim>& boundary,
                      const SolidField<Dim>& solids, TiledLattice<Dim, double>& phi) {
  TiledLattice<Dim, double, Dim + 2> acc;
  const double max_support = surface_sums(particles, grid, lattice, boundary, solids, acc);
  // the level set in the splat's tiles, the kernel support everywhere else
  phi.reset(lattice.dims, max_support);
  const int slots = acc.num_tile_slots();
  std::vector<unsigned char> made = phi.tile_flags();
  for (int tile = 0; tile < slots; ++tile) made[tile] = acc.has_tile(tile);
  phi.make_tiles(made, process_threads());
  const std::vector<int> tiles = made_tile_slots(acc);
  const int count = static_cast<int>(tiles.size());
#pragma omp parallel for schedule(dynamic, 1) num_threads(process_threads())
  for (int t = 0; t < count; ++t) {
    acc.for_each_point_in_tile(tiles[t], [&](const VecI<Dim>& c, const double* sum) {
      if (sum[0] > 0.0) *phi.find(c) = surface_phi(lattice, c, sum);
    });
  }
}

}  // namespace

template <int Dim>
void liquid_phi_on_lattice(const Particles<Dim>& particles, const MacGrid<Dim>& grid,
                           const SampleLattice<Dim>& lattice,
                           const std::array<BoundaryType, 2 * Dim>& boundary,
                           const SolidField<Dim>& solids, VectorX& phi) {
  LiquidPhiBand<Dim> band;
  liquid_phi_on_lattice(particles, grid, lattice, boundary, solids, phi, band);
}

template <int Dim>
void liquid_phi_on_lattice(const Particles<Dim>& particles, const MacGrid<Dim>& grid,
                           const SampleLattice<Dim>& lattice,
                           const std::array<BoundaryType, 2 * Dim>& boundary,
                           const SolidField<Dim>& solids, VectorX& phi,
                           LiquidPhiBand<Dim>& band) {
  // the boxed form over the whole lattice, in phi's own buffer
  BoxedLattice<Dim> whole;
  whole.values.swap(phi);
  liquid_phi_on_lattice(particles, grid, lattice, boundary, solids, whole, band, 0,
                        std::numeric_limits<double>::infinity());
  phi.swap(whole.values);
}

template <int Dim>
void liquid_phi_on_lattice(const Particles<Dim>& particles, const MacGrid<Dim>& grid,
                           const SampleLattice<Dim>& lattice,
                           const std::array<BoundaryType, 2 * Dim>& boundary,
                           const SolidField<Dim>& solids, BoxedLattice<Dim>& phi,
                           LiquidPhiBand<Dim>& band, int margin, double boxed_from) {
  band = LiquidPhiBand<Dim>();
  const VecI<Dim> last = lattice.dims - VecI<Dim>::Ones();
  // the stored box: the band grown by `margin` points, or the whole lattice
  const auto store = [&](double background) {
    if (background >= boxed_from && band.empty())
      phi.set_box(lattice.dims, VecI<Dim>::Zero(), -VecI<Dim>::Ones(), background);
    else if (background >= boxed_from)
      phi.set_box(lattice.dims, band.lo - VecI<Dim>::Constant(margin),
                  band.hi + VecI<Dim>::Constant(margin), background);
    else
      phi.set_box(lattice.dims, VecI<Dim>::Zero(), last, background);
    fill_in_parallel(phi.values.data(), static_cast<long>(phi.values.size()), background);
  };
  if (particles.size() == 0) {
    band.background = 3.0 * grid.dx();
    store(band.background);
    return;
  }
  TiledLattice<Dim, double, Dim + 2> acc;
  const double max_support = surface_sums(particles, grid, lattice, boundary, solids, acc);
  // phi = |x - x_bar| - r_bar, a positive constant (the kernel support) away from particles
  // (every point outside the tiles)
  band.background = max_support;
  // (the made tiles shared out one by one: they lie together in the slots, and static blocks
  // of slots left one thread most of them; two24)
  const std::vector<int> tiles = made_tile_slots(acc);
  const int count = static_cast<int>(tiles.size());
  // the box of the points with a value of their own, per thread then merged (a min and max: any
  // split gives it), before the store is sized to it
  const int threads = process_threads();
  std::vector<VecI<Dim>> lo(threads, lattice.dims), hi(threads, -VecI<Dim>::Ones());
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (int t = 0; t < count; ++t) {
    VecI<Dim>& tlo = lo[omp_get_thread_num()];
    VecI<Dim>& thi = hi[omp_get_thread_num()];
    acc.for_each_point_in_tile(tiles[t], [&](const VecI<Dim>& c, const double* sum) {
      if (sum[0] > 0.0) {
        tlo = tlo.cwiseMin(c);
        thi = thi.cwiseMax(c);
      }
    });
  }
  band.lo = lattice.dims;
  for (int t = 0; t < threads; ++t) {
    band.lo = band.lo.cwiseMin(lo[t]);
    band.hi = band.hi.cwiseMax(hi[t]);
  }
  store(max_support);
  double* values = phi.values.data();
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (int t = 0; t < count; ++t) {
    acc.for_each_point_in_tile(tiles[t], [&](const VecI<Dim>& c, const double* sum) {
      if (sum[0] > 0.0) values[phi.entry(c)] = surface_phi(lattice, c, sum);
    });
  }
}

template <int Dim>
double max_particle_speed(const Particles<Dim>& particles) {
  const long np = static_cast<long>(particles.size());
  double vmax = 0.0;
#pragma omp parallel for schedule(static) reduction(max : vmax) num_threads(process_threads())
  for (long p = 0; p < np; ++p) vmax = std::max(vmax, particles.v[p].norm());
  return vmax;
}

// --- explicit instantiations ---------------------------------------------------------------------

#define MONOLITH_INSTANTIATE_PARTICLES(D)                                                          \
  template struct Particles<D>;                                                                    \
  template Particles<D> seed_particles(const MacGrid<D>&, const std::vector<LiquidSpec>&,          \
                                       const std::vector<ShapePtr<D>>&, const SolidField<D>&, int, \
                                       unsigned);                                                  \
  template void particles_to_grid(const Particles<D>&, const MacGrid<D>&, VectorX&, VectorX&,      \
                                  VectorX&, DensitySpans*);                                        \
  template void pic_velocity_on_faces(const Particles<D>&, const MacGrid<D>&,                      \
                                      const std::vector<int>&, std::vector<double>&);              \
  template long grid_to_particles(Particles<D>&, const MacGrid<D>&, const VectorX&,                \
                                  std::vector<char>*);                                             \
  template void extrapolate_velocity(const MacGrid<D>&, VectorX&, std::vector<char>&, int);        \
  template void extrapolate_velocity<D>(const MacGrid<D>&, VectorX&, std::vector<char>&, int,      \
                                        const std::array<VecI<D>, D>&,                             \
                                        const std::array<VecI<D>, D>&);                            \
  template void divergence_free_air_velocity(const MacGrid<D>&, const SampleLattice<D>&,          \
                                            const VectorX&, const VectorX&,                       \
                                            const std::vector<char>&,                             \
                                            const std::vector<char>&, int, double, VectorX&);     \
  template long advect_particles(Particles<D>&, const MacGrid<D>&, const VectorX&, double,         \
                                 const SolidField<D>&, const std::array<BoundaryType, 2 * D>&,     \
                                 std::vector<char>*);                                              \
  template long drift_particles_own_velocity(Particles<D>&, const MacGrid<D>&, double,            \
                                             const SolidField<D>&,                                 \
                                             const std::array<BoundaryType, 2 * D>&);              \
  template void correct_positions(Particles<D>&, const MacGrid<D>&, double, const SolidField<D>&,  \
                                  const std::array<BoundaryType, 2 * D>&,                          \
                                  PositionCorrectionBuffers*);                                     \
  template DensityProjectionStats project_particle_density(                                        \
      Particles<D>&, const MacGrid<D>&, const SampleLattice<D>&, const VectorX&,                   \
      const SolidField<D>&, const std::array<BoundaryType, 2 * D>&, int, SurfaceDeficits,          \
      KeptZeros*, const SolidField<D>*, double);                                                   \
  template void liquid_phi_on_lattice(const Particles<D>&, const MacGrid<D>&,                     \
                                       const SampleLattice<D>&,                                    \
                                       const std::array<BoundaryType, 2 * D>&,                     \
                                       const SolidField<D>&, VectorX&);                            \
  template void liquid_phi_on_lattice(const Particles<D>&, const MacGrid<D>&,                     \
                                       const SampleLattice<D>&,                                    \
                                       const std::array<BoundaryType, 2 * D>&,                     \
                                       const SolidField<D>&, VectorX&, LiquidPhiBand<D>&);         \
  template void liquid_phi_on_lattice(const Particles<D>&, const MacGrid<D>&,                     \
                                       const SampleLattice<D>&,                                    \
                                       const std::array<BoundaryType, 2 * D>&,                     \
                                       const SolidField<D>&, BoxedLattice<D>&, LiquidPhiBand<D>&,  \
                                       int, double);                                               \
  template VectorX liquid_phi_on_lattice(const Particles<D>&, const MacGrid<D>&,                   \
                                         const SampleLattice<D>&,                                  \
                                         const std::array<BoundaryType, 2 * D>&,                   \
                                         const SolidField<D>&);                                    \
  template double max_particle_speed(const Particles<D>&);

MONOLITH_INSTANTIATE_PARTICLES(2)
MONOLITH_INSTANTIATE_PARTICLES(3)

#undef MONOLITH_INSTANTIATE_PARTICLES

}  // namespace monolith
