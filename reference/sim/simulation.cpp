/// \file simulation.cpp
/// Simulation<Dim>: the time loop of Algorithm 1 (simulation.hpp). step() lists the algorithm's
/// stages, one member function each. Lines 7-11 run the solves of the scene's scheme through
/// run_solve_sequence (solve_sequence.hpp): for a liquid beside static solids by PCG on eq. (8)
/// (solve_liquid), with moving bodies by solve_coupled_step on eq. (24) (solve_coupled); bodies
/// without liquid step through RigidWorld.

#include "reference/sim/simulation.hpp"
#include "reference/sim/air_velocity.hpp"
#include "reference/core/parallel.hpp"
#include "reference/core/periodic_image.hpp"

#include <omp.h>

#include <algorithm>
#include <tuple>
#include <cstdint>
#include <cstring>
#include <cmath>
#include <limits>
#include <sstream>
#include <optional>
#include <utility>

#include "reference/core/errors.hpp"
#include "reference/core/first_touch.hpp"
#include "reference/core/huge_pages.hpp"
#include "reference/core/state_io.hpp"
#include "reference/core/timer.hpp"
#include "reference/coupling/coupled_schemes.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/coupling/solve_sequence.hpp"
#include "reference/fluid/deformation_rate.hpp"
#include "reference/fluid/herschel_bulkley.hpp"
#include "reference/fluid/pressure_projection.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/fluid/viscosity.hpp"
#include "reference/fluid/viscosity_field.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/grid/stress_weights.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/particles/particles.hpp"
#include "reference/rigid/rigid_world.hpp"

namespace monolith {

namespace {

/// A particle left flagged in `unread` after the guarded reads (only when the unreached faces are
/// poisoned, StageSwitches::poison_unreached_faces): the extrapolation did not reach a face it
/// read. Stops the step with the particle, the time and the read (`where`) named.
void throw_if_unread(const std::vector<char>& unread, double time, int next_frame,
                     const char* where) {
  const auto left = std::find(unread.begin(), unread.end(), 1);
  if (left == unread.end()) return;
  std::ostringstream msg;
  msg << "t = " << time << " s (frame " << next_frame << "): particle " << (left - unread.begin())
      << " read a face the extrapolation did not reach" << where;
  throw SimulationError(msg.str());
}

/// W_F^s given to the stress DOFs that tie the liquid part of a solid-cut face to the solid
/// (departures item 24): small, so that the DOF's strain is held near zero (its compliance in eq.
/// (8) scales with 1 / W_F^s); 0.001 gives the same settling and Couette answers to 0.4 %, 0.5 ties
/// too weakly (check25, docs/validation.md).
constexpr double kCutFaceStressFraction = 0.01;

/// The stress DOFs raised by raise_cut_face_stress for one solve, put back to W_F^s = 0 when the
/// solve is done (also when it throws): the stored W_F^s stays the weights' own (the incremental
/// update of the next pose, the checkpoint and the frame-end clamp read the unraised values).
struct RaisedStressWeights {
  VectorX* fluid_stress = nullptr;
  std::vector<int> dofs;
  RaisedStressWeights() = default;
  RaisedStressWeights(const RaisedStressWeights&) = delete;
  RaisedStressWeights& operator=(const RaisedStressWeights&) = delete;
  ~RaisedStressWeights() {
    if (fluid_stress)
      for (const int d : dofs) (*fluid_stress)[d] = 0.0;
  }
};

/// Departures item 24 (docs/derivations.md; eq. (8) with the J_s mixing of section 4.4.1): a face
/// that a solid cuts (0 < W_F^u < 1) is read by D from the stress DOFs on both sides of it. When
/// the solid side's DOF has its whole control volume in the solid (W_F^s = 0, inactive), only the
/// liquid side's DOF reads the face, and the minimisation of eq. (8) / (24) gives the face's liquid
/// part the velocity that cancels that DOF's strain: the liquid slips freely along the body
/// (check25: a Couette plate whose surface cuts its faces less than half way drags nothing; a
/// settling square shifted by half a cell falls 47 % faster). Such a DOF gets W_F^s =
/// kCutFaceStressFraction for the solve, so that its strain, which reads the face's liquid part
/// and the solid's velocity on the faces inside it, holds the liquid to the solid. Raised: DOFs
/// with W_F^s = 0 and W_L^s > 0 whose D stencil has a cut face and no fluid face without liquid
/// (W_F^u > 0, W_L^u = 0: eq. (8) would read such a face as a prescribed velocity, the surface's
/// lid of departures item 23). A raised DOF where eta = 0 stays inactive (StokesDofs), so the
/// viscosity need not be known here (a Herschel-Bulkley liquid's is made per round). Each DOF is
/// decided from its own stencil and written by itself: the same raised set for any thread count.
template <int Dim>
void raise_cut_face_stress(const StressGrid<Dim>& stress, const VectorX& fluid_face,
                           const VectorX& liquid_face, const VectorX& liquid_stress,
                           VectorX& fluid_stress, RaisedStressWeights& raised) {
  const long n = stress.num_dofs();
  if (fluid_stress.size() != n || liquid_stress.size() != n ||
      fluid_face.size() != stress.grid().num_faces() ||
      liquid_face.size() != stress.grid().num_faces())
    return;
  raised.dofs = gather_in_order<int>(static_cast<int>(n), [&](int d, std::vector<int>& out) {
    if (fluid_stress[d] != 0.0 || !(liquid_stress[d] > 0.0)) return;
    bool cut = false, dry = false;
    for_each_deformation_rate_entry(stress, d, [&](int f, double) {
      const double wf = fluid_face[f];
      if (wf > 0.0 && wf < 1.0) cut = true;
      if (wf > 0.0 && !(liquid_face[f] > 0.0)) dry = true;
    });
    if (cut && !dry) out.push_back(d);
  });
  raised.fluid_stress = &fluid_stress;
  for (const int d : raised.dofs) fluid_stress[d] = kCutFaceStressFraction;
}

template <int Dim>
Vec<Dim> to_vec(const std::vector<double>& v, const Vec<Dim>& fallback) {
  if (static_cast<int>(v.size()) != Dim) return fallback;
  Vec<Dim> x;
  for (int a = 0; a < Dim; ++a) x[a] = v[a];
  return x;
}

template <int Dim>
std::vector<double> to_std(const Vec<Dim>& x) {
  return std::vector<double>(x.data(), x.data() + Dim);
}

/// phi(k) = value(k, phi(k)) for every point k of the lattice box [lo, hi] (inclusive, clamped to
/// the lattice) of a level set stored over a box (BoxedLattice), on several threads (rows along
/// x shared statically); every point whose bits change is listed with its entry and old value in
/// `undo` (one list per thread, cleared first), so that restore_points gives phi back exactly.
/// The lists hold the changed points only: the level sets are changed in a band (issue 20: no
/// second lattice-sized vector for a modified copy). [lo, hi] must lie in phi's stored box
/// (checked: std::logic_error).
template <int Dim, class Value>
void overwrite_in_box(const SampleLattice<Dim>& lattice, VecI<Dim> lo, VecI<Dim> hi,
                      BoxedLattice<Dim>& phi, Value&& value,
                      std::vector<std::vector<std::pair<int, double>>>& undo) {
  const int threads = process_threads();
  if (static_cast<int>(undo.size()) < threads) undo.resize(threads);
  for (auto& list : undo) list.clear();
  for (int a = 0; a < Dim; ++a) {
    lo[a] = std::max(lo[a], 0);
    hi[a] = std::min(hi[a], lattice.dims[a] - 1);
    if (lo[a] > hi[a]) return;
  }
  if (!phi.holds_box(lo, hi))
    throw std::logic_error("overwrite_in_box: the box is not in the level set's stored box");
  const BoxRows<Dim> box(lattice.dims, lo, hi);
  const int rows = box.rows(), nx = box.nx;
  double* values = phi.values.data();
  // (rows on several threads, each thread listing the points it changed)
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int q = 0; q < rows; ++q) {
    const VecI<Dim> c = box.start(q);
    const int k0 = lattice.index(c), e0 = phi.entry(c);
    for (int x = 0; x < nx; ++x) {
      const double old = values[e0 + x], v = value(k0 + x, old);
      if (std::memcmp(&old, &v, sizeof(double)) == 0) continue;
      undo[omp_get_thread_num()].emplace_back(e0 + x, old);
      values[e0 + x] = v;
    }
  }
}

/// Undoes overwrite_in_box (each point is listed once, so the order does not matter).
template <int Dim>
void restore_points(BoxedLattice<Dim>& phi,
                    const std::vector<std::vector<std::pair<int, double>>>& undo) {
  for (const auto& list : undo)
    for (const auto& [e, old] : list) phi.values[e] = old;
}

/// Lattice points the liquid level set is stored beyond its band on every side (band19): the
/// weights read the band and two points around it (liquid_weights_from_phi: the non-positive
/// lattice cells of the extended level set start at most one point before the band, and the
/// fluid level set is written and classified one point around their box and its far corners;
/// docs/derivations.md, "The liquid level set stored over its band").
inline constexpr int kLiquidPhiMargin = 2;

/// Throws std::logic_error unless the lattice points [lo, hi] grown by `grow` points (clamped to
/// the lattice; nothing when [lo, hi] is empty), which a reader of the level set reads, lie in
/// its stored box (the readers of LatticeValues read through the box's strides: a point outside
/// it would be another point's entry).
template <int Dim>
void require_stored(const BoxedLattice<Dim>& phi, VecI<Dim> lo, VecI<Dim> hi, int grow,
                    const char* what) {
  if ((lo.array() > hi.array()).any()) return;  // no point
  lo = (lo - VecI<Dim>::Constant(grow)).cwiseMax(VecI<Dim>::Zero());
  hi = (hi + VecI<Dim>::Constant(grow)).cwiseMin(phi.dims - VecI<Dim>::Ones());
  if (!phi.holds_box(lo, hi))
    throw std::logic_error(std::string(what) + ": reads the liquid level set outside its box");
}

/// A shape's signed distance where it matters: farther than `far` from its bounds box, the
/// distance to that box (a positive lower bound of the true distance) stands in for it. The
/// particle pipeline reads the solid distance only for its sign and near the surface (push-out,
/// position correction), while an exact query of a mesh body far from it walks the triangle
/// hierarchy: every particle in every substep would pay for it.
template <int Dim>
double bounded_distance(const Shape<Dim>& shape, const Box<Dim>& box, double far,
                        const Vec<Dim>& x) {
  if (!box.isEmpty() && box.min().allFinite() && box.max().allFinite()) {
    const double outside = (x - x.cwiseMax(box.min()).cwiseMin(box.max())).norm();
    if (outside > far) return outside;
  }
  return shape.distance(x);
}

/// The nearest of shapes [from, to) to x by bounded_distance (far), continuing a search whose
/// nearest so far is `best` at distance d: the loop of make_solid_field's gradient, which a
/// caller can split (the fixed solids' part kept, the moving ones' evaluated again).
template <int Dim>
void nearest_solid(const std::vector<ShapePtr<Dim>>& shapes, const std::vector<Box<Dim>>& boxes,
                   double far, const Vec<Dim>& x, std::size_t from, std::size_t to, double& d,
                   std::size_t& best) {
  for (std::size_t k = from; k < to; ++k) {
    const double dk = bounded_distance<Dim>(*shapes[k], boxes[k], far, x);
    if (dk < d) {
      d = dk;
      best = k;
    }
  }
}

/// The SolidField of a set of solids: the union's distance (min over the shapes, each through
/// bounded_distance with far = 2 dx) and the gradient of the nearest one. Empty for no shapes.
template <int Dim>
SolidField<Dim> make_solid_field(const std::vector<ShapePtr<Dim>>& shapes, double dx) {
  SolidField<Dim> field;
  if (shapes.empty()) return field;
  std::vector<Box<Dim>> boxes;
  for (const auto& s : shapes) boxes.push_back(s->bounds());
  const double far = 2.0 * dx;
  field.distance = [shapes, boxes, far](const Vec<Dim>& x) {
    double d = std::numeric_limits<double>::infinity();
    for (std::size_t k = 0; k < shapes.size(); ++k)
      d = std::min(d, bounded_distance<Dim>(*shapes[k], boxes[k], far, x));
    return d;
  };
  field.gradient = [shapes, boxes, far](const Vec<Dim>& x) {
    std::size_t best = 0;
    double d = std::numeric_limits<double>::infinity();
    nearest_solid<Dim>(shapes, boxes, far, x, 0, shapes.size(), d, best);
    return shapes[best]->gradient(x);
  };
  return field;
}

/// Faces whose weight W_F^u W_L^u in the energy of eq. (8) (W_L^u the geometric liquid fraction,
/// before the clamp; the clamped value selects the same faces, see trusted_face) is below this
/// keep their solved velocity out of the particles: it is
/// replaced by extrapolation from the faces above it (a departure from the paper). The
/// projection bounds the weighted energy, sum_f rho W_F^u_f W_L^u_f u_f^2 dx^Dim / 2 <= that of
/// u*, so a face's speed is bounded only in proportion to 1 / sqrt(W_F^u W_L^u): the minimisation
/// routes flux through low-weight faces almost for free and their velocity can be many times the
/// flow speed (the clamped faces of kMinLiquidFaceFraction, and faces that are mostly solid, small
/// W_F^u); fed back to the particles it injects energy at splashes and impacts. The product, not
/// W_L^u alone, is the weight: with W_L^u alone, faces with W_F^u = 0.02-0.07 beside the bowl
/// carried 10-23 m/s into the particles of pour-into-bowl-3d (impact speed 3-4 m/s).
constexpr double kTrustedLiquidFaceFraction = 0.1;

/// With moving bodies a step moves no body point by more than this fraction of a cell: the
/// contact constraints are linear in the velocities at the step's start positions (section
/// 3.2), so their error grows with the rotation and travel within a step.
constexpr double kBodyCellFraction = 0.5;

/// Layers of faces beyond the particles' reach that get u* by extrapolation before the solve: a
/// stress control volume with W_L^s > 0 reaches at most one cell into the air, a surface cell's
/// divergence one face.
constexpr int kAirVelocityLayers = 2;

/// stress_viscosity(stress, particles, values) without the particle splat when the values make
/// it a constant, else `fallback()`. Every value 0: each reached DOF divides a sum of zeros by
/// its mass, every fill averages zeros and the liquid's mean is zero, so the field is +0
/// everywhere. Every value 1 (the indicator of the only liquid, liquid_stress_fractions): each
/// product w m 1 is w m, so a reached DOF divides its mass by itself, every fill averages ones
/// and the liquid's mean is its mass over itself, so the field is 1 everywhere (0 without
/// particle mass). The same bits as the splat, for a fraction of a step's weights
/// (docs/particles.md, "Speed").
/// (The same holds for the cells' samples of cell_viscosity, also a sample_viscosity splat:
/// constant_viscosity gives that constant, or nothing when the splat is needed.)
template <int Dim>
std::optional<double> constant_viscosity(const Particles<Dim>& particles,
                                         const std::vector<double>& values) {
  const auto all = [&](double v) {
    return !values.empty() &&
           std::all_of(values.begin(), values.end(), [v](double e) { return e == v; });
  };
  const int nv = static_cast<int>(values.size());
  const bool indices_in_range = std::all_of(particles.liquid.begin(), particles.liquid.end(),
                                            [nv](int l) { return l >= 0 && l < nv; });
  const bool masses = std::all_of(particles.mass.begin(), particles.mass.end(),
                                  [](double m) { return std::isfinite(m) && m >= 0.0; });
  if (!indices_in_range || !masses) return std::nullopt;
  if (all(0.0)) return 0.0;
  if (all(1.0)) {
    const bool mass = std::any_of(particles.mass.begin(), particles.mass.end(),
                                  [](double m) { return m > 0.0; });
    return mass ? 1.0 : 0.0;
  }
  return std::nullopt;
}

template <int Dim, class Fallback>
VectorX stress_viscosity_constant_or(const StressGrid<Dim>& stress, const Particles<Dim>& particles,
                                     const std::vector<double>& values, Fallback&& fallback) {
  if (const auto c = constant_viscosity(particles, values))
    return VectorX::Constant(stress.num_dofs(), *c);
  return fallback();
}

}  // namespace

template <int Dim>
Simulation<Dim>::Simulation(const SceneDesc& scene, const StageSwitches& switches)
    : scene_(scene), switches_(switches) {
  const Stopwatch setup_watch;  // frame 0's timing: the set-up (solids, seeding, first weights)
  // grid and boundary
  Vec<Dim> lower, upper;
  VecI<Dim> cells;
  std::array<bool, Dim> periodic{};
  for (int a = 0; a < Dim; ++a) {
    lower[a] = scene.domain.lower[a];
    upper[a] = scene.domain.upper[a];
    cells[a] = scene.domain.cells[a];
    boundary_[2 * a] = scene.domain.boundary[2 * a];
    boundary_[2 * a + 1] = scene.domain.boundary[2 * a + 1];
    periodic[a] = boundary_[2 * a] == BoundaryType::periodic;
  }
  grid_ = MacGrid<Dim>(lower, scene.dx(), cells, periodic);
  lattice_ = half_lattice(grid_);
  gravity_ = to_vec<Dim>(scene.gravity.empty() ? default_gravity(Dim) : scene.gravity,
                        Vec<Dim>::Zero());

  // static bodies form the solid field (walls are the boundary faces)
  for (std::size_t i = 0; i < scene.bodies.size(); ++i)
    if (scene.bodies[i].motion == BodyMotion::fixed)
      solid_shapes_.push_back(
          make_shape<Dim>(scene.bodies[i].shape, "bodies[" + std::to_string(i) + "].shape"));
  solids_ = make_solid_field<Dim>(solid_shapes_, grid_.dx());
  solid_field_shapes_ = solid_shapes_;
  for (const auto& sh : solid_shapes_) solid_field_boxes_.push_back(sh->bounds());
  // viscosity: which solves the scheme runs (the stress DOFs with W_F^s below)
  liquid_eta_ = liquid_viscosities(scene.liquids);
  non_newtonian_ = has_non_newtonian(scene.liquids);
  const bool viscous = non_newtonian_ || std::any_of(liquid_eta_.begin(), liquid_eta_.end(),
                                                     [](double eta) { return eta > 0.0; });
  if (non_newtonian_)
    for (const auto& l : scene.liquids)
      mixture_.models.push_back(HerschelBulkley::from_spec(l.viscosity));
  sequence_ = solve_sequence(scene.solver.scheme, viscous);
  // W_F^u from the solid level set shrunk by zeta (section 4.4.6). Without a static solid that
  // level set is +infinity everywhere (no fraction anywhere), and unless W_F^s is made from it
  // below it is not made: W_F^u is 1 but on the walls (fluid_face_weights_without_solids, the
  // same bits), and no point or face is in a solid. Its 541 MB at the paper's 256x128x256 grid
  // were the set-up's first block: released in step 1 (it was lent to the liquid level set),
  // they left a hole at the bottom of the heap that the steps' kept buffers split, so the next
  // liquid level set went above every other block (a peak one lattice-sized vector higher)
  if (!solid_shapes_.empty() || sequence_ != SolveSequence::pressure) {
    solid_phi_ =
        solid_phi_on_lattice(grid_, lattice_, solid_shapes_, scene.solver.shrink * grid_.dx());
    std::tie(solid_lo_, solid_hi_) = negative_point_box(lattice_, solid_phi_);
    find_faces_in_solids();
    weights_.fluid_face = fluid_face_weights(grid_, lattice_, solid_phi_, boundary_);
  } else {
    // (the box negative_point_box finds in a level set without a negative point)
    solid_lo_ = lattice_.dims;
    solid_hi_ = -VecI<Dim>::Ones();
    find_faces_in_solids();
    weights_.fluid_face = fluid_face_weights_without_solids(grid_, boundary_);
  }
  // moving bodies: the rigid world; next to a liquid they enter the weights of every step
  // (W_F^u, W_F^s from their pose) and the particles never start inside them
  for (const auto& b : scene.bodies)
    if (b.motion != BodyMotion::fixed) {
      rigid_ = std::make_unique<RigidWorld<Dim>>(scene);
      break;
    }
  coupled_ = rigid_ && !scene.liquids.empty();

  stress_grid_ = StressGrid<Dim>(grid_);
  if (non_newtonian_ && sequence_ != SolveSequence::pressure)
    deformation_rate_ = std::make_shared<const SparseMatrix>(deformation_rate_matrix(stress_grid_));
  if (sequence_ != SolveSequence::pressure)
    stress_fluid_ = stress_fluid_weights(stress_grid_, lattice_, solid_phi_, boundary_);
  // the last solve's stress (warm-start data): none without stress solves (an inviscid liquid
  // or a P.. scheme has no stress field; it was a zero vector of 400 MB at 256x128x256)
  if (sequence_ != SolveSequence::pressure) stress_ = VectorX::Zero(stress_grid_.num_dofs());
  if (coupled_) update_moving_solids();

  // liquids: particles seeded in each liquid's shape
  std::vector<ShapePtr<Dim>> liquid_shapes;
  for (std::size_t i = 0; i < scene.liquids.size(); ++i)
    liquid_shapes.push_back(
        make_shape<Dim>(scene.liquids[i].shape, "liquids[" + std::to_string(i) + "].shape"));
  if (!scene.liquids.empty()) reference_density_ = scene.liquids.front().density;
  particles_ = seed_particles(grid_, scene.liquids, liquid_shapes, solids_,
                              scene.particles.count_per_cell(Dim), scene.particles.seed);

  // solver settings
  pcg_settings_.tolerance = scene.solver.tolerance;
  pcg_settings_.max_iterations = scene.solver.max_iterations;

  // the seeded particles spread so that their volume and the level set's agree from frame 0
  if (scene.particles.position_correction && switches_.density_projection)
    volume_errors_ =
        project_particle_density(particles_, grid_, lattice_, weights_.fluid_face, solids_,
                                 boundary_, kSeedProjectionIterations,
                                 switches_.density_projection_surface_deficits, &density_move_)
            .surface_deficits;
  reserve_step_buffers();
  frame_zero();
  if (scene.particles.settle_steps > 0 && !particles_.x.empty()) {
    settle(scene.particles.settle_steps);
    stats_ = FrameStats{};  // the settling steps' solver statistics are not frame 0's
    frame_zero();
  }
  stats_.timing[FramePhase::total] = setup_watch.seconds();
}

template <int Dim>
void Simulation<Dim>::reserve_step_buffers() {
  // Heap placement (issue 20, branch paper16). The lattice-sized liquid level set is released
  // before every solve (release_liquid_phi) so that the solve's grid-sized vectors reuse its
  // memory, and made again by the next step's weights. That sharing holds only while no kept
  // buffer is placed in the released block: made first in step 1 (a face-sized flag array, the
  // faces in the solids' frames) or after the level set in frame_zero (W_L^p, W_L^u, eta per
  // cell, the pressure), such buffers split it or lay above it, the next level set no longer
  // fit and went above every other block: a peak one lattice-sized vector higher (541 MB,
  // 135k first-touch page faults at the paper's 256x128x256 grid). Sized here, before
  // frame_zero, the kept buffers lie below the level set's block, which is the heap's last one
  // and goes back to its top when released. A reserve or resize does not touch the pages, and
  // every buffer below is overwritten before it is read: the results do not change.
  const auto faces = static_cast<std::size_t>(grid_.num_faces());
  // (kern25) buffers written whole at their first use are made resident here in one call
  // (core/first_touch.hpp): the flags are copied whole from the faces with mass
  if (switches_.air_velocity || switches_.extrapolate_after_solve)
    reserve_resident(face_flags_, faces);
  // the faces in the solids with their frame (constrain_velocity_in_solids): twice the
  // set-up's count, room for the bodies to move into more faces before a reallocation (the
  // set-up's count made resident: the first step writes about that many)
  if (guards_reads()) {
    solid_frame_.reserve(2 * solid_faces_.size());
    populate_for_writing(solid_frame_.data(), sizeof(SolidFaceFrame) * solid_faces_.size());
  }
  // W_L^p and W_L^u (their first fill zeroes them whole: no valid WrittenBox yet) and the
  // pressure (frame_zero zeroes it)
  // (huge21) W_L^p and W_L^u are written in the liquid's band only when their WrittenBox is
  // valid: made here, they are zeroed without writing their pages (zero_by_release: fresh
  // storage, given back whole) and their boxes set to "nothing written", so the first fill
  // writes its band only, like every later one (the same zeros elsewhere; the pages outside
  // the band are never provided). Without restricted passes every fill zeroes them whole.
  // (fresh storage of n zeros from the kernel, and the box that says nothing is written in it)
  const auto fresh_zeros = [](VectorX& v, long n) {
    resize_to_released_zeros(v, n);
    return WrittenBox<Dim>::nothing_written(v.data(), n);
  };
  if (weights_.liquid_cell.size() == 0) {
    if (switches_.restricted_passes)
      liquid_cell_box_ = fresh_zeros(weights_.liquid_cell, grid_.num_cells());
    else
      weights_.liquid_cell.resize(grid_.num_cells());
  }
  // the reported volume's cell fractions likewise (fluid_volume_in_box)
  if (switches_.restricted_passes && volume_cells_.size() == 0) {
    volume_cells_box_ = fresh_zeros(volume_cells_, grid_.num_cells());
    // (kern25) its sum reads it whole at every call: its pages mapped for reading in one call,
    // as that first read would map them (core/first_touch.hpp)
    populate_for_reading(volume_cells_.data(), sizeof(double) * volume_cells_.size());
  }
  if (weights_.liquid_face.size() == 0) {
    if (switches_.restricted_passes) {
      fresh_zeros(weights_.liquid_face, grid_.num_faces());
      for (int a = 0; a < Dim; ++a)
        liquid_face_boxes_[a] = WrittenBox<Dim>::nothing_written(
            weights_.liquid_face.data() + grid_.face_offset(a), grid_.face_dims(a).prod());
    } else {
      weights_.liquid_face.resize(grid_.num_faces());
    }
  }
  // the pressure (written whole by every solve) on huge pages (core/huge_pages.hpp); (band23)
  // with restricted passes the coupled solves write it in their DOFs' cells only
  // (pressure_cells_), so its pages stay small: a huge page is provided whole
  if (pressure_.size() == 0) {
    if (switches_.restricted_passes)
      pressure_.resize(grid_.num_cells());
    else
      resize_resident(pressure_, grid_.num_cells());
  }
  // eta per cell likewise (a non-Newtonian liquid's is made before the first solve when its
  // size is not the grid's: left to update_liquid_weights)
  if (!non_newtonian_ && cell_eta_.size() == 0) cell_eta_.resize(grid_.num_cells());
  // (huge21) u, the face masses and the faces' densities: kept across steps and written whole
  // by every particles_to_grid (its resize to the same size keeps this storage): sized here,
  // after the blocks above as before (frame_zero's transfer made them next), on huge pages;
  // (kern25) made resident in one call (core/first_touch.hpp), not one fault per page
  resize_resident(u_, faces);
  resize_resident(face_mass_, faces);
  // (band24) the densities' storage from the kernel's zeros (not on huge pages: a huge page is
  // provided whole), recorded as +0 outside no faces: the first transfer then writes the
  // particles' layers only, and the pages beyond them are never provided
  if (densities_zero_mode() && weights_.face_density.size() == 0) {
    resize_to_released_zeros(weights_.face_density, grid_.num_faces());
    density_spans_.kept.clear();
    density_spans_data_ = weights_.face_density.data();
    density_spans_value_ = reference_density_;
    density_spans_zero_ = true;
  } else {
    resize_resident(weights_.face_density, faces);
  }
}

template <int Dim>
bool Simulation<Dim>::densities_zero_mode() const {
  return switches_.restricted_passes && switches_.densities_zero_outside &&
         !density_zero_dropped_ && scene_.solver.backend == Backend::matrix_free;
}

template <int Dim>
void Simulation<Dim>::densities_before_solve() {
  // (band24) docs/derivations.md, "Passes restricted to boxes", "The faces' densities +0 beyond
  // their layers": every reader of P outside the kept layers gives the bits of rho_0 there
  // while W_L^u is +0 on those faces
  VectorX& rho = weights_.face_density;
  const long nf = grid_.num_faces();
  if (!density_spans_zero_ || density_spans_data_ != rho.data() || rho.size() != nf) return;
  // (the oracle's export reads P on every face)
  bool inside = !export_sink_;
  for (int a = 0; a < Dim && inside; ++a) {
    const WrittenBox<Dim>& lb = liquid_face_boxes_[a];
    if (!lb.valid_for(weights_.liquid_face.data() + grid_.face_offset(a),
                      grid_.face_dims(a).prod())) {
      inside = false;
      break;
    }
    if ((lb.lo.array() > lb.hi.array()).any()) continue;  // W_L^u = +0 on every face of a
    // axis a's kept faces: whole layers [klo, khi] of its lattice along the last axis (one
    // range of `kept` within the component, or none)
    const VecI<Dim> dims = grid_.face_dims(a);
    const long offset = grid_.face_offset(a), per = dims.prod() / dims[Dim - 1];
    int klo = 0, khi = -1;
    for (const auto& [b, e] : density_spans_.kept)
      if (b >= offset && e <= offset + dims.prod() && b < e) {
        klo = static_cast<int>((b - offset) / per);
        khi = static_cast<int>((e - offset) / per) - 1;
      }
    // the box's layers outside them (a few: the written box reaches a little beyond the
    // particles' layers) must hold W_L^u = +-0
    const auto zero_in = [&](int l0, int l1) {
      if (l0 > l1) return true;
      VecI<Dim> lo = lb.lo, extent = lb.hi - lb.lo + VecI<Dim>::Ones();
      lo[Dim - 1] = l0;
      extent[Dim - 1] = l1 - l0 + 1;
      const int count = extent.prod();
      bool zero = true;
      for (int k = 0; k < count && zero; ++k) {
        const int f = grid_.face_index(a, lo + lattice_coord<Dim>(k, extent));
        zero = weights_.liquid_face[f] == 0.0;
      }
      return zero;
    };
    if (khi < klo) {
      inside = zero_in(lb.lo[Dim - 1], lb.hi[Dim - 1]);
    } else {
      inside = zero_in(lb.lo[Dim - 1], std::min(lb.hi[Dim - 1], klo - 1)) &&
               zero_in(std::max(lb.lo[Dim - 1], khi + 1), lb.hi[Dim - 1]);
    }
  }
  if (inside) return;
  // rho_0 on every face outside the kept layers (all +0 there): the storage the dense diagonal
  // leaves, and the record of kern22 (rho_0 outside `kept`); the zeros are not used again
  long begin = 0;
  const auto fill = [&](long end) {
    if (end <= begin) return;
#pragma omp parallel for schedule(static) num_threads(team_threads(end - begin))
    for (long f = begin; f < end; ++f) rho[f] = reference_density_;
  };
  for (const auto& [b, e] : density_spans_.kept) {
    fill(b);
    begin = std::max(begin, e);
  }
  fill(nf);
  density_spans_value_ = reference_density_;
  density_spans_zero_ = false;
  density_zero_dropped_ = true;
  ++density_zero_fallbacks_;
}

template <int Dim>
void Simulation<Dim>::frame_zero() {
  // frame 0: the seeded state on the grid (no pressure yet); the faces' densities become the
  // diagonal of P in place (as in every step, update_step_weights)
  transfer_to_grid();
  mark_faces_with_mass();
  density_diagonal_in_place_after_transfer();
  update_liquid_weights();
  liquid_weights_current_ = true;
  // (band23) the pressure's zeros from the kernel (pressure_cells_: nothing written in it), so
  // that the coupled solves write their DOFs' cells only; the same +0 everywhere
  if (switches_.restricted_passes) {
    resize_to_released_zeros(pressure_, grid_.num_cells());
    pressure_cells_.nothing_written(pressure_);
  } else {
    pressure_ = VectorX::Zero(grid_.num_cells());
    pressure_cells_.forget();
  }
  stats_.frame = 0;
  stats_.time = 0.0;
  stats_.solver.scheme = scene_.solver.scheme;
  fill_state_stats(stats_);
}

template <int Dim>
void Simulation<Dim>::settle(int steps) {
  // A settled start (particles.settle_steps; docs/particles.md, "A settled start"). The seeded
  // particles are jittered, so the level set they reconstruct is rough and its weights are not
  // the discrete hydrostatic equilibrium: liquid seeded at rest starts to move in its first
  // steps, and an inviscid APIC liquid keeps that motion (a floating body then sways with it).
  // Here whole steps run before t = 0 (gravity, the solve, the advection, line 15), each
  // followed by zeroing the liquid's velocities (v, c and the grid's u_) and the dynamic bodies'
  // ones: a pseudo-time relaxation in which everything moves only by what the imbalance drives
  // within one step from rest (g dt^2 at most), so the rough surface flattens and the particles
  // and the floating bodies reach the discrete equilibrium. Static and kinematic bodies keep the
  // scene's pose; at the end every seeded particle velocity and body velocity is given back.
  // Meant for scenes that start at rest: liquid or a body out of equilibrium (a dam break's
  // column, a body dropped from above) would start to fall during it.
  const std::vector<Vec<Dim>> v0 = particles_.v;
  const auto c0 = particles_.c;
  std::vector<char> bodies;
  if (rigid_) {
    StateWriter w;
    rigid_->state_fields(w);
    bodies = w.take();
  }
  // the scene's body state back, the dynamic bodies at the pose the settling gave them
  const auto restore_bodies = [&](bool at_rest) {
    if (!rigid_) return;
    std::vector<Vec<Dim>> position;
    std::vector<decltype(RigidBody<Dim>::orientation)> orientation;
    for (const auto& b : rigid_->bodies()) {
      position.push_back(b.position);
      orientation.push_back(b.orientation);
    }
    StateReader r(bodies, "settle");
    rigid_->state_fields(r);
    r.finish();
    auto& b = rigid_->bodies();
    for (std::size_t i = 0; i < b.size(); ++i) {
      if (b[i].motion != BodyMotion::dynamic) continue;
      b[i].position = position[i];
      b[i].orientation = orientation[i];
      if (at_rest) {
        b[i].velocity.setZero();
        b[i].angular_velocity.setZero();
      }
    }
    if (coupled_) {
      rebuild_solid_field();
      update_moving_solids();
    }
  };
  const double dt = std::min(scene_.time.max_dt, 1.0 / scene_.time.fps);
  for (int k = 0; k < steps; ++k) {
    for (auto& v : particles_.v) v.setZero();
    for (auto& c : particles_.c) c.setZero();
    u_.setZero();
    restore_bodies(true);
    step(dt);
  }
  if (particles_.v.size() != v0.size())
    throw SimulationError("particles.settle_steps: particles left the domain while the liquid "
                          "settled; settle only scenes whose liquid starts at rest");
  particles_.v = v0;
  particles_.c = c0;
  u_.setZero();
  drop_drift_guard();
  reached_u_ = VectorX();
  restore_bodies(false);
  line15_credit_ = 0.0;
  frame_ledger_ = EnergyLedger{};
}

template <int Dim>
void Simulation<Dim>::update_liquid_weights(bool stress, bool volume) {
  make_liquid_phi();
  liquid_weights_from_phi(stress, volume);
}

template <int Dim>
void Simulation<Dim>::make_liquid_phi() {
  ScopedTimer timer(stats_.timing[FramePhase::particles]);
  // mirrored across the walls and the solids, so liquid against either reads as liquid up to
  // it (docs/particles.md, "Still water")
  // (written into liquid_phi_'s own buffer: no second lattice-sized vector during the call)
  // Stored over its band (issue 20, band19): the band's box and kLiquidPhiMargin points around
  // it, which hold every point the weights read (liquid_weights_from_phi); the whole lattice when
  // those passes are not restricted to the band (`banded` there) or divergence_free_air reads it
  const bool boxed = switches_.restricted_passes && !switches_.divergence_free_air;
  liquid_phi_on_lattice(particles_, grid_, lattice_, boundary_, solids_, liquid_phi_,
                        liquid_band_, kLiquidPhiMargin,
                        boxed ? kLiquidSolidReach * grid_.dx()
                              : std::numeric_limits<double>::infinity());
}

template <int Dim>
void Simulation<Dim>::liquid_weights_from_phi(bool stress, bool volume) {
  liquid_weights_pending_ = false;
  ScopedTimer timer(stats_.timing[FramePhase::weights]);
  // the weights of eq. (8) see the liquid level set extended into the static solids, so that a
  // wall's fluid sliver next to the liquid is not a free surface (extend_liquid_into_solids)
  // (buffers kept across steps; the fractions visit only the band where phi changes sign)
  // The extension is written into liquid_phi_ itself, in the solids' box, and undone after the
  // weights (the points it changes are listed: the solids' part of the liquid's band), so no
  // lattice-sized copy is made (541 MB at the paper's 256x128x256 grid); the values the weights
  // read are those of extend_liquid_into_solids_in_box
  const bool solids = !solid_shapes_.empty() || coupled_;
  const bool extend = solids && (solid_phi_.size() == lattice_.size() ||
                                  solid_box_phi_.valid() || solid_scratch_.union_parts.valid());
  // The liquid's band (issue 20): outside the box of the points liquid_phi_on_lattice wrote,
  // the level set is its background value; when that is at least the extension's reach, the
  // extension changes no point there (it changes points with phi < reach only) and the extended
  // level set is not negative there (>= reach > 0): the extension and the search for negative
  // points visit that box only (the same points changed, the same box found)
  const double reach = kLiquidSolidReach * grid_.dx();
  const bool banded = switches_.restricted_passes && liquid_band_.background >= reach;
  VecI<Dim> band_lo = VecI<Dim>::Zero(), band_hi = lattice_.dims - VecI<Dim>::Ones();
  if (banded) {
    band_lo = liquid_band_.lo;
    band_hi = liquid_band_.hi;
  }
  if (extend) {
    const double dx = grid_.dx();
    // liquid_extended_into_solid, which reads only the solids' sign (solid_negative_at)
    overwrite_in_box<Dim>(lattice_, solid_lo_.cwiseMax(band_lo), solid_hi_.cwiseMin(band_hi),
                          liquid_phi_, [&](int k, double l) {
      return l < reach && solid_negative_at(k) ? std::min(l, -0.5 * dx) : l;
    }, phi_undo_);
  }
  // (the level set through its box's view; the classes read the band and one point around it,
  // the fractions the corners of the mixed lattice cells among those)
  require_stored(liquid_phi_, band_lo, band_hi, 1, "liquid_weights_from_phi");
  const LatticeValues<Dim> phi = liquid_phi_.view();
  classify_lattice_cells_searching(grid_, lattice_, phi, band_lo, band_hi, liquid_signs_);
  // the points where the extended level set is negative (the box of its non-positive cells)
  const VecI<Dim> liquid_lo = liquid_signs_.lo, liquid_hi = liquid_signs_.hi + VecI<Dim>::Ones();
  // W_L^p and W_L^u are reset where the last step wrote them, not over the grid (issue 20:
  // WrittenBox; nothing else writes these vectors, which the solve borrows and gives back)
  const bool sparse = switches_.restricted_passes;
  cell_negative_fractions(grid_, lattice_, phi, liquid_signs_, weights_.liquid_cell,
                          sparse ? &liquid_cell_box_ : nullptr);
  // W_L^u clamped in place: the trust test of trusted_face reads it instead of the unclamped
  // fractions (the same faces, kept no longer in a face-sized vector of their own)
  face_negative_fractions<Dim>(grid_, lattice_, phi, liquid_signs_, weights_.liquid_face,
                               sparse ? &liquid_face_boxes_ : nullptr);
  if (sparse)
    clamp_liquid_face_weights_in_place<Dim>(grid_, weights_.liquid_face, weights_.liquid_cell,
                                            liquid_cell_box_, liquid_face_boxes_);
  else
    clamp_liquid_face_weights_in_place(grid_, weights_.liquid_face, weights_.liquid_cell);
  if (!sparse) {
    liquid_cell_box_.valid = false;
    for (auto& box : liquid_face_boxes_) box.valid = false;
  }
  // W_L^s from the same extended level set, eta per stress DOF and per cell from the particles
  const bool stress_eta_made = sequence_ != SolveSequence::pressure && stress;
  if (stress_eta_made) {
    stress_negative_fractions(stress_grid_, lattice_, phi, liquid_signs_, stress_liquid_);
    // (a non-Newtonian liquid's eta here is 0, and the only liquid's fractions are 1: constants
    // without the splat, the same bits). Written into stress_eta_'s kept storage (the solve
    // lends it and gives it back): no fresh grid-sized vector per step, whose first touch was
    // 16 % of the splat's time on the 64^3 bunny (docs/benchmarks.md, "Kept buffers and one
    // more pass on the team")
    if (const auto c = constant_viscosity(particles_, liquid_eta_))
      stress_eta_.setConstant(stress_grid_.num_dofs(), *c);
    else
      stress_viscosity_into(stress_grid_, particles_, liquid_eta_, stress_eta_);
    if (non_newtonian_) {
      const int liquids = static_cast<int>(mixture_.models.size());
      if (liquids == 1)
        mixture_.fractions = {stress_viscosity_constant_or(
            stress_grid_, particles_, std::vector<double>{1.0},
            [&] { return liquid_stress_fractions(stress_grid_, particles_, 1).front(); })};
      else
        mixture_.fractions = liquid_stress_fractions(stress_grid_, particles_, liquids);
      // n = 1, tau0 = 0 for all: the Newtonian path's eta per DOF (bit for bit the same run)
      if (mixture_.is_newtonian()) {
        std::vector<double> k;
        for (const auto& m : mixture_.models) k.push_back(m.k);
        mixture_.constant = stress_viscosity(stress_grid_, particles_, k);
      }
    }
    // eq. (8)'s zero traction at the free surface (docs/derivations.md, departures item 23): W_L^u
    // raised on the dry faces that the stress DOFs which can be active read. W_F^s is the static
    // solids' (stress_fluid_) or, coupled, the bodies' of this pose (update_moving_solids ran
    // before; empty without stress solves: nothing raised). The test's eta is the one the solve
    // reads; a Herschel-Bulkley liquid's is made per round, but it is positive exactly where its
    // value at rest is (eq. (27): k > 0 or tau0 > 0 of a liquid with a fraction there)
    const VectorX& fluid_stress = coupled_ ? coupled_in_.solids.fluid_stress : stress_fluid_;
    VectorX at_rest;
    if (non_newtonian_) at_rest = mixture_.viscosity(VectorX::Zero(stress_grid_.num_dofs()));
    clamp_stressed_face_weights<Dim>(stress_grid_, fluid_stress, stress_liquid_,
                                     non_newtonian_ ? at_rest : stress_eta_, weights_.liquid_face,
                                     sparse ? &liquid_signs_ : nullptr,
                                     sparse ? &liquid_face_boxes_ : nullptr);
  }
  // eta per cell is read only at a frame's end (the render, save_state, cell_eta()): with every
  // liquid inviscid it is +0 at every cell whatever the particles (constant_viscosity, or the
  // splat of zeros), so it is left pending until read instead of written whole here (band20: a
  // cell-sized fill first touched in the set-up, 67 MB at the paper's 256x128x256 grid, read
  // by nothing in a run without pictures or checkpoints)
  if (!non_newtonian_ && !liquid_eta_.empty() &&
      std::all_of(liquid_eta_.begin(), liquid_eta_.end(), [](double e) { return e == 0.0; }))
    cell_eta_pending_ = true;
  else
    update_cell_eta(stress_eta_made);
  // the reported volume is that of the particles' own level set outside the solids (its mirror
  // images and the extension reach into them)
  // (in the extended level set's buffer, which the weights no longer read: no new lattice-sized
  // vector)
  // max(phi_L, -phi_S) <= 0 only where phi_L < 0, where the extended level set (<= phi_L) is
  // negative too: it is written in that box and one point around it (the corners of every
  // lattice cell the classes and fractions read; the rest of the buffer keeps the extended level
  // set's values, >= 0 there), and classified in the box
  // (in liquid_phi_ again, the extension undone first: the fluid level set is written in that
  // box and one point around it and undone after its fractions. Outside, liquid_phi_ has the
  // signs the extended level set had there, >= 0, and no value of it is read)
  if (extend) restore_points(liquid_phi_, phi_undo_);
  if (volume && solids)
    liquid_volume_ =
        fluid_volume_in_box(liquid_lo, liquid_hi, liquid_signs_.any_negative(), extend);
  else if (volume)
    liquid_volume_ = weights_.liquid_cell.sum() * grid_.cell_volume();
  // with moving bodies the solids' level set is made again with the next weights
  // (update_moving_solids always runs before this) and read by nothing else (the velocity
  // constraints use the faces in solids found with it): its buffer goes back to the heap too
  // (541 MB at the paper's 256x128x256 grid)
  if (coupled_) {
    solid_phi_ = VectorX();
    solid_box_phi_.clear();
    solid_scratch_.union_parts.clear();
  }
}

template <int Dim>
void Simulation<Dim>::update_cell_eta(bool stress_eta_made) const {
  cell_eta_pending_ = false;
  if (!non_newtonian_) {
    // eta per cell (the render's colour and the checkpoint). A constant field (every liquid
    // inviscid: +0) is written into the kept vector: the splat made three cell-sized vectors and
    // two cell-sized byte arrays per step (256 MiB at the paper's 256x128x256 grid, alive at the
    // step's memory peak, so first touched by the kernel)
    if (const auto c = constant_viscosity(particles_, liquid_eta_)) {
      if (cell_eta_.size() == grid_.num_cells())
        cell_eta_.setConstant(*c);
      else
        cell_eta_ = VectorX::Constant(grid_.num_cells(), *c);
    } else if (stress_eta_made) {
      // the cell centres are the diagonal stress DOFs' samples (stress_viscosity's component 0,
      // the same sample_viscosity call as cell_viscosity): a copy instead of a second splat
      const int nc = grid_.num_cells();
      cell_eta_.resize(nc);
      const double* from = stress_eta_.data() + stress_grid_.offset(0);
#pragma omp parallel for schedule(static) num_threads(team_threads(nc))
      for (int c = 0; c < nc; ++c) cell_eta_[c] = from[c];
    } else {
      cell_eta_ = cell_viscosity(grid_, particles_, liquid_eta_);
    }
  } else if (cell_eta_.size() != grid_.num_cells()) {
    // before the first solve: each liquid at rest, the limiting viscosity eta0 of eq. (27)
    std::vector<double> eta0;
    for (const auto& m : mixture_.models) eta0.push_back(m.limiting_viscosity());
    cell_eta_ = cell_viscosity(grid_, particles_, eta0);
  }
}

template <int Dim>
double Simulation<Dim>::cfl_dt() const {
  // the liquid's speed: its particles' and the grid velocity on the faces they take it from.
  // Faces below kTrustedLiquidFaceFraction are left out: their solved velocity is not physical
  // (it scales like 1 / sqrt(W_F^u W_L^u)) and never reaches a particle, and where extrapolation
  // does not reach them it stays in u_. Read in the CFL limit, a few hundred km/s on one such
  // face cut dt to 1e-7 s, the contacts' penetration recovery (-beta phi / dt, eq. (16))
  // then threw the bodies at km/s, which cut dt further (hollow-spheres-inviscid-3d stalled in
  // frame 9 at dt = 6e-28 s).
  // (after liquid_volume_from_phi W_L^u is the last step's: frame_end_dt_is_max showed at
  // the frame's end that no grid speed below its bound, hence none of the trusted faces',
  // changes the result, max_dt; the state has not changed since)
  double grid_speed = 0.0;
  const auto faces = static_cast<Eigen::Index>(grid_.num_faces());
  if (!liquid_weights_pending_ && u_.size() == faces && weights_.fluid_face.size() == faces &&
      weights_.liquid_face.size() == faces &&
      mass_faces_.size() == static_cast<std::size_t>(grid_.num_faces())) {
    // (a maximum: the same for any split of the faces, and over any set that holds the
    // trusted faces: the boxes outside which none is, trusted_boxes)
    FaceBoxes boxes;
    if (trusted_boxes(boxes)) {
      grid_speed = std::max(grid_speed, max_abs_in_boxes(boxes, u_.data(), [&](int f) { return trusted_face(f); }));
    } else {
      const int nf = grid_.num_faces();
#pragma omp parallel for schedule(static) reduction(max : grid_speed) num_threads(process_threads())
      for (int f = 0; f < nf; ++f)
        if (trusted_face(f)) grid_speed = std::max(grid_speed, std::abs(u_[f]));
    }
  }
  const double speed = std::max(max_particle_speed(particles_), grid_speed);
  const double max_dt = scene_.time.max_dt;
  double dt = speed > 0.0 ? std::min(max_dt, scene_.time.cfl * grid_.dx() / speed) : max_dt;
  // a body point moves at most a fraction of a cell per step (contacts are linearised in time)
  const double body_speed = rigid_ ? rigid_->max_point_speed() : 0.0;
  if (body_speed > 0.0) dt = std::min(dt, kBodyCellFraction * grid_.dx() / body_speed);
  return dt;
}

template <int Dim>
bool Simulation<Dim>::frame_end_dt_is_max() const {
  // cfl_dt's speed is max(particles, grid) with the grid's maximum over the trusted faces, each
  // with W_F^u > 0: B = the largest |u| over every face with W_F^u > 0 bounds it (std::max drops
  // a NaN in both). With S = max(particles, B), cfl dx / S >= max_dt (or S = 0) gives
  // min(max_dt, cfl dx / s) = max_dt for every s in [0, S] (the division is monotone), whatever
  // the trusted faces; the bodies' limit is applied after it alike.
  // A trusted face has mass (0 outside mass_boxes_) or W_L^u > 0 of the frame's end, whose
  // extended level set is negative only in the band of the level set just made (outside it
  // phi_L is its background, at least the extension's reach: update_liquid_weights' `banded`);
  // a face's fraction reads the lattice points of its control volume (2 c - 1 .. 2 c + 2 per
  // axis) and their mirrors at the walls within a point: two faces more on each side bound the
  // faces of the band. Without the boxes, every face.
  const auto faces = static_cast<Eigen::Index>(grid_.num_faces());
  double bound = 0.0;
  if (u_.size() == faces && weights_.fluid_face.size() == faces) {
    const int nf = grid_.num_faces();
    const double* u = u_.data();
    const double* fluid = weights_.fluid_face.data();
    const bool boxed = switches_.restricted_passes && mass_boxes_valid_ &&
                       mass_faces_.data() == mass_boxes_data_ &&
                       mass_faces_.size() == static_cast<std::size_t>(nf) &&
                       liquid_band_.background >= kLiquidSolidReach * grid_.dx();
    if (boxed) {
      FaceBoxes boxes;
      for (int axis = 0; axis < Dim; ++axis) {
        const VecI<Dim> fdims = grid_.face_dims(axis);
        VecI<Dim> lo = VecI<Dim>::Zero(), hi = -VecI<Dim>::Ones();
        if (!liquid_band_.empty())
          for (int a = 0; a < Dim; ++a) {
            lo[a] = grid_.periodic(a) ? 0 : std::max(liquid_band_.lo[a] / 2 - 3, 0);
            hi[a] = grid_.periodic(a) ? fdims[a] - 1
                                      : std::min(liquid_band_.hi[a] / 2 + 3, fdims[a] - 1);
          }
        const VecI<Dim>& mlo = mass_boxes_.lo[axis];
        const VecI<Dim>& mhi = mass_boxes_.hi[axis];
        const bool band_empty = (lo.array() > hi.array()).any();
        const bool mass_empty = (mlo.array() > mhi.array()).any();
        if (band_empty) {
          lo = mlo;
          hi = mhi;
        } else if (!mass_empty) {
          lo = lo.cwiseMin(mlo);
          hi = hi.cwiseMax(mhi);
        }
        boxes.lo[axis] = lo;
        boxes.hi[axis] = hi;
      }
      bound = std::max(bound, max_abs_in_boxes(boxes, u, [&](int f) { return fluid[f] > 0.0; }));
    } else {
#pragma omp parallel for schedule(static) reduction(max : bound) num_threads(team_threads(nf))
      for (int f = 0; f < nf; ++f)
        if (fluid[f] > 0.0) bound = std::max(bound, std::abs(u[f]));
    }
  }
  const double speed = std::max(max_particle_speed(particles_), bound);
  const double max_dt = scene_.time.max_dt;
  if (!(speed > 0.0)) return speed == 0.0;
  return std::min(max_dt, scene_.time.cfl * grid_.dx() / speed) == max_dt;
}

template <int Dim>
void Simulation<Dim>::liquid_volume_from_phi() {
  ScopedTimer timer(stats_.timing[FramePhase::weights]);
  // update_liquid_weights' volume with solids: the cell fractions of the fluid level set
  // max(phi_L, -phi_S), negative only where phi_L is. There the box of the points to classify
  // was that of the extended level set's negative points (which hold phi_L's); here it is
  // phi_L's own (searched in the band, outside which phi_L is its positive background). Any
  // box outside which the level set is nowhere negative gives the same classes
  // (classify_lattice_cells_in_box), and the fluid values are written in it and one point
  // around it (every corner read) as before: the same fractions, the same volume.
  const bool extend = solid_phi_.size() == lattice_.size() || solid_box_phi_.valid() ||
                      solid_scratch_.union_parts.valid();
  VecI<Dim> band_lo = VecI<Dim>::Zero(), band_hi = lattice_.dims - VecI<Dim>::Ones();
  if (switches_.restricted_passes && liquid_band_.background > 0.0) {
    band_lo = liquid_band_.lo;
    band_hi = liquid_band_.hi;
  }
  require_stored(liquid_phi_, band_lo, band_hi, 0, "liquid_volume_from_phi");
  const auto [liquid_lo, liquid_hi] =
      negative_point_box_in<Dim>(lattice_, liquid_phi_.view(), band_lo, band_hi);
  liquid_volume_ = fluid_volume_in_box(liquid_lo, liquid_hi,
                                       (liquid_lo.array() <= liquid_hi.array()).all(), extend);
  liquid_weights_pending_ = true;
  cell_eta_pending_ = true;
}

template <int Dim>
double Simulation<Dim>::fluid_volume_in_box(const VecI<Dim>& liquid_lo, const VecI<Dim>& liquid_hi,
                                            bool grow, bool extend) {
  // The fluid level set max(phi_L, -phi_S) is negative only where phi_L is: its values are
  // written into liquid_phi_ (with `extend`; without, it is phi_L) in the box [liquid_lo,
  // liquid_hi] outside which phi_L is nowhere negative and, with `grow`, one point around it
  // (the corners of every lattice cell the classes and fractions read), classified in the box,
  // its cell fractions summed, and the writes undone. Outside the box liquid_phi_ keeps values
  // >= 0 and none of them is read.
  VecI<Dim> lo = liquid_lo, hi = liquid_hi;
  if (grow)
    for (int a = 0; a < Dim; ++a) {
      lo[a] = std::max(lo[a] - 1, 0);
      hi[a] = std::min(hi[a] + 1, lattice_.dims[a] - 1);
    }
  if (extend)
    overwrite_in_box<Dim>(lattice_, lo, hi, liquid_phi_, [&](int k, double l) {
      // where phi_L >= 0 and the solids' union is not negative, -phi_S <= 0 <= phi_L and the
      // maximum is phi_L itself (the union's value, closed forms per body, is not needed)
      if (l >= 0.0 && !solid_negative_at(k)) return l;
      return std::max(l, -solid_phi_at(k));
    }, phi_undo_);
  require_stored(liquid_phi_, liquid_lo, liquid_hi, 1, "fluid_volume_in_box");
  const LatticeValues<Dim> fluid_phi = liquid_phi_.view();
  classify_lattice_cells_in_box(grid_, lattice_, fluid_phi, liquid_lo, liquid_hi, liquid_signs_);
  // (a cell-sized vector read by nothing else, 64 MiB at the paper's 256x128x256 grid.) With
  // restricted passes it is kept (huge21): made in reserve_step_buffers with its zeros from the
  // kernel and reset where the last call wrote (its WrittenBox), so its pages outside the
  // liquid's band are never written (they read as the kernel's zero page) and it holds no more
  // memory than the band; the same values as a fresh vector, the same sum. Else made here and
  // given back at the return, so the solve's vectors reuse it instead of keeping it alive.
  if (switches_.restricted_passes && volume_cells_.size() == grid_.num_cells()) {
    cell_negative_fractions(grid_, lattice_, fluid_phi, liquid_signs_, volume_cells_,
                            &volume_cells_box_);
    if (extend) restore_points(liquid_phi_, phi_undo_);
    return volume_cells_.sum() * grid_.cell_volume();
  }
  VectorX cells;
  cell_negative_fractions(grid_, lattice_, fluid_phi, liquid_signs_, cells);
  if (extend) restore_points(liquid_phi_, phi_undo_);
  return cells.sum() * grid_.cell_volume();
}

template <int Dim>
void Simulation<Dim>::complete_frame_end_weights() {
  const auto timing = stats_.timing;
  // (with stress solves the stress weights too: W_L^u carries the stress's clamp, departures
  // item 23, as it does when load_state or a step makes the weights)
  update_liquid_weights(/*stress=*/sequence_ != SolveSequence::pressure, /*volume=*/true);
  stats_.timing = timing;
}

template <int Dim>
void Simulation<Dim>::step_bodies(double dt) {
  const RigidStepStats s = rigid_->step(dt, time_, gravity_);
  stats_.contact_count = std::max(stats_.contact_count, s.contacts);
  stats_.max_penetration = std::max(stats_.max_penetration, s.max_penetration);
  SolverStats& st = stats_.solver;
  st.add_solve(s.iterations, s.staggered_iterations, s.max_relative_residual, s.converged);
  st.add_dofs(0, 0, s.dofs_contact, s.dofs_friction);
  st.contact_iterations += s.iterations;
  st.contact_seconds += s.solve_seconds;
  if (!s.converged)
    note_unconverged("contact (staggered projections)", s.iterations, s.max_relative_residual);
  stats_.timing[FramePhase::solve] += s.solve_seconds;
}

template <int Dim>
void Simulation<Dim>::step(double dt) {
  // a scene of bodies without liquid: (3), (6), (8), (10), (12), (13) through RigidWorld
  if (rigid_ && scene_.liquids.empty()) {
    if (!switches_.energy_ledger) {
      step_bodies(dt);
      return;
    }
    const double kinetic = rigid_->kinetic_energy(), potential = body_potential_energy();
    step_bodies(dt);
    frame_ledger_.forces_and_solve += rigid_->kinetic_energy() - kinetic;
    frame_ledger_.advection += body_potential_energy() - potential;
    return;
  }
  first_half_drift(dt);
  restart_ledger([&] { return particle_kinetic_energy(); });  // the energy ledger (diagnosis)
  particles_to_grid_with_forces(dt);  // (1)-(3)
  update_step_weights();              // (4)-(5)
  release_liquid_phi();
  ballistic_faces_take_pic(dt);       // u* of the faces with mass outside the level set
  extrapolate_into_air();             // u* on the faces the particles did not reach
  solve_step(dt);                     // (6)-(12)
  check_finite("the pressure/viscosity/contact solve");
  account(frame_ledger_.forces_and_solve, [&] { return grid_and_body_kinetic_energy(); });
  extrapolate_from_trusted_faces(dt); // the solved velocity into air and solid
  apply_wall_and_solid_velocities();
  divergence_free_air();
  account(frame_ledger_.velocity_extension, [&] { return grid_and_body_kinetic_energy(); });
  move_bodies(dt);                    // (13)
  advect(dt);                         // (14)
  correct_volume(dt);                 // (15)
  // (the pressure and the stress are written by the solve only: checked after it)
  check_finite("advection", false);
}

template <int Dim>
double Simulation<Dim>::grid_and_body_kinetic_energy() const {
  return face_kinetic_energy() + (coupled_ ? rigid_->kinetic_energy() : 0.0);
}

template <int Dim>
typename Simulation<Dim>::FaceBoxes Simulation<Dim>::particle_face_boxes() const {
  // the particles' bounds (a minimum and maximum per axis: the same for any split), every axis
  // in one pass and one parallel region (a region per axis was three fork-joins per call, each
  // around ~0.1 ms of work; the per-thread results are combined by min and max, exact in any order)
  Vec<Dim> lo = Vec<Dim>::Constant(std::numeric_limits<double>::infinity());
  Vec<Dim> hi = -lo;
  const long np = static_cast<long>(particles_.size());
  std::array<double, Dim> mn, mx;
  for (int a = 0; a < Dim; ++a) {
    mn[a] = lo[a];
    mx[a] = hi[a];
  }
  std::array<bool, Dim> finite;
  finite.fill(true);
  {
    const int team = team_threads(np);
    std::vector<std::array<double, 2 * Dim>> part(team);
    std::vector<std::array<bool, Dim>> part_finite(team);
#pragma omp parallel num_threads(team)
    {
      std::array<double, 2 * Dim> m;
      std::array<bool, Dim> fin;
      for (int a = 0; a < Dim; ++a) {
        m[a] = mn[a];
        m[Dim + a] = mx[a];
        fin[a] = true;
      }
#pragma omp for schedule(static)
      for (long p = 0; p < np; ++p) {
        const Vec<Dim> x = grid_.wrap_position(particles_.x[p]);
        for (int a = 0; a < Dim; ++a) {
          fin[a] = fin[a] && std::isfinite(x[a]);
          m[a] = std::min(m[a], x[a]);
          m[Dim + a] = std::max(m[Dim + a], x[a]);
        }
      }
      part[omp_get_thread_num()] = m;
      part_finite[omp_get_thread_num()] = fin;
    }
    for (int t = 0; t < team; ++t)
      for (int a = 0; a < Dim; ++a) {
        mn[a] = std::min(mn[a], part[t][a]);
        mx[a] = std::max(mx[a], part[t][Dim + a]);
        finite[a] = finite[a] && part_finite[t][a];
      }
  }
  for (int a = 0; a < Dim; ++a) {
    lo[a] = finite[a] ? mn[a] : -std::numeric_limits<double>::infinity();
    hi[a] = finite[a] ? mx[a] : std::numeric_limits<double>::infinity();
  }
  // a particle in cell c (clamped) reaches the samples c - 1 .. c + 1 of every face lattice
  // (pic_velocity_on_faces's note on axis_stencil); two more cells either side
  FaceBoxes boxes;
  for (int c = 0; c < Dim; ++c) {
    const VecI<Dim> fdims = grid_.face_dims(c);
    for (int a = 0; a < Dim; ++a) {
      const int cells = grid_.cells()[a];
      int clo = 0, chi = fdims[a] - 1;
      if (np > 0 && !grid_.periodic(a) && std::isfinite(lo[a]) && std::isfinite(hi[a])) {
        const double slo = std::floor((lo[a] - grid_.origin()[a]) / grid_.dx());
        const double shi = std::floor((hi[a] - grid_.origin()[a]) / grid_.dx());
        const int cl = static_cast<int>(std::clamp(slo, 0.0, cells - 1.0));
        const int ch = static_cast<int>(std::clamp(shi, 0.0, cells - 1.0));
        clo = std::max(cl - 3, 0);
        chi = std::min(ch + 3, fdims[a] - 1);
      } else if (np == 0) {
        clo = 0;
        chi = -1;
      }
      boxes.lo[c][a] = clo;
      boxes.hi[c][a] = chi;
    }
  }
  return boxes;
}

template <int Dim>
typename Simulation<Dim>::FaceRows Simulation<Dim>::face_rows(const FaceBoxes& boxes,
                                                               int axis) const {
  FaceRows rows;
  rows.box = BoxRows<Dim>(grid_.face_dims(axis), boxes.lo[axis], boxes.hi[axis]);
  rows.nx = rows.box.nx;
  rows.offset = grid_.face_offset(axis);
  return rows;
}

template <int Dim>
template <class Keep>
double Simulation<Dim>::max_abs_in_boxes(const FaceBoxes& boxes, const double* v, Keep&& keep) const {
  // a maximum: the same for any split of each box's rows over the threads
  double largest = 0.0;
  for (int axis = 0; axis < Dim; ++axis) {
    const FaceRows rows_of_box = face_rows(boxes, axis);
    const int rows = rows_of_box.rows(), nx = rows_of_box.nx;
    if (rows == 0) continue;
    double speed = 0.0;
#pragma omp parallel for schedule(static) reduction(max : speed) \
    num_threads(team_threads(static_cast<long>(rows) * nx))
    for (int r = 0; r < rows; ++r) {
      const int first = rows_of_box.first(r);
      for (int f = first; f < first + nx; ++f)
        if (keep(f)) speed = std::max(speed, std::abs(v[f]));
    }
    largest = std::max(largest, speed);
  }
  return largest;
}

template <int Dim>
template <class Fn>
void Simulation<Dim>::for_faces_in_boxes(const FaceBoxes& boxes, Fn&& fn) const {
  // every axis's box in one parallel region (a region per axis cost three fork-joins per call),
  // each axis's rows split statically; the axes' faces are distinct, so no barrier between them
  std::array<FaceRows, Dim> rows_of;
  long total = 0;
  for (int axis = 0; axis < Dim; ++axis) {
    rows_of[axis] = face_rows(boxes, axis);
    total += static_cast<long>(rows_of[axis].rows()) * rows_of[axis].nx;
  }
  if (total == 0) return;
#pragma omp parallel num_threads(team_threads(total))
  for (int axis = 0; axis < Dim; ++axis) {
    const FaceRows& face_rows_of_box = rows_of[axis];
    const int rows = face_rows_of_box.rows(), nx = face_rows_of_box.nx;
#pragma omp for schedule(static) nowait
    for (int r = 0; r < rows; ++r) {
      const int first = face_rows_of_box.first(r);
      for (int x = 0; x < nx; ++x) fn(first + x);
    }
  }
}

template <int Dim>
bool Simulation<Dim>::trusted_boxes(FaceBoxes& boxes) const {
  // a trusted face has W_L^u > 0 (0 outside liquid_face_boxes_) or mass (0 outside mass_boxes_)
  const int nf = grid_.num_faces();
  if (!switches_.restricted_passes || !mass_boxes_valid_ || mass_faces_.data() != mass_boxes_data_ ||
      mass_faces_.size() != static_cast<std::size_t>(nf) || weights_.liquid_face.size() != nf)
    return false;
  for (int a = 0; a < Dim; ++a) {
    const WrittenBox<Dim>& lb = liquid_face_boxes_[a];
    if (!lb.valid_for(weights_.liquid_face.data() + grid_.face_offset(a),
                      grid_.face_dims(a).prod()))
      return false;
    const bool mass_empty = (mass_boxes_.lo[a].array() > mass_boxes_.hi[a].array()).any();
    const bool liquid_empty = (lb.lo.array() > lb.hi.array()).any();
    if (mass_empty) {
      boxes.lo[a] = lb.lo;
      boxes.hi[a] = lb.hi;
    } else if (liquid_empty) {
      boxes.lo[a] = mass_boxes_.lo[a];
      boxes.hi[a] = mass_boxes_.hi[a];
    } else {
      boxes.lo[a] = mass_boxes_.lo[a].cwiseMin(lb.lo);
      boxes.hi[a] = mass_boxes_.hi[a].cwiseMax(lb.hi);
    }
  }
  return true;
}

template <int Dim>
void Simulation<Dim>::transfer_to_grid() {
  // (kern22) the densities' storage holds P's fallback outside the layers the last transfer
  // wrote when it is the storage the last diagonal was written into, with the same fallback
  // (docs/derivations.md, "Passes restricted to boxes", "The faces' densities written where
  // they change"); then only those layers and this transfer's are written
  VectorX& rho = weights_.face_density;
  DensitySpans* spans = nullptr;
  // (band24) in the zeros' mode the storage holds +0 outside `kept` instead (the record says
  // which): a record of the other mode makes this transfer write every face
  density_transfer_zero_ = densities_zero_mode();
  if (switches_.restricted_passes) {
    spans = &density_spans_;
    spans->known = density_spans_data_ != nullptr && rho.data() == density_spans_data_ &&
                   rho.size() == grid_.num_faces() &&
                   std::memcmp(&density_spans_value_, &reference_density_, sizeof(double)) == 0 &&
                   density_spans_zero_ == density_transfer_zero_;
  }
  density_spans_data_ = nullptr;  // (known again once this transfer's diagonal is written)
  particles_to_grid(particles_, grid_, u_, face_mass_, rho, spans);
  density_transfer_pending_ = spans != nullptr;
}

template <int Dim>
void Simulation<Dim>::density_diagonal_in_place_after_transfer() {
  VectorX& rho = weights_.face_density;
  const bool pending = density_transfer_pending_;
  density_transfer_pending_ = false;
  // particles_to_grid's densities are positive only on faces with mass, which lie in
  // mass_boxes_ (kept by mark_faces_with_mass right after it)
  if (switches_.restricted_passes && mass_boxes_valid_ && mass_faces_.data() == mass_boxes_data_) {
    // (kern22) after a transfer with density_spans_ the fallback is written on the faces that
    // transfer wrote (the others hold it); the boxes' last-axis range is the particles' cell
    // layers grown by 3, kDensityReadLayers (particle_face_boxes), so every face read lies in them
    // (band24) in the zeros' mode on the transfer's layers only: the faces it wrote beyond
    // them hold its +0 (no density there, none near), the faces it did not write +0 already
    const bool zero = pending && density_transfer_zero_;
    density_diagonal_in_place<Dim>(
        grid_, rho, reference_density_, mass_boxes_.lo, mass_boxes_.hi,
        pending ? (zero ? &density_spans_.layers : &density_spans_.written) : nullptr);
    if (pending) {
      density_spans_.kept = density_spans_.layers;
      density_spans_data_ = rho.data();
      density_spans_value_ = reference_density_;
      density_spans_zero_ = zero;
    }
    return;
  }
  density_spans_zero_ = false;  // (the whole diagonal below: rho_0 on every face without one)
  if (pending && density_spans_.known) {
    // (not reached: restricted passes always keep the boxes) the faces the transfer left hold
    // the last fallback, not its zeros: the zeros first, then the whole diagonal
    long begin = 0;
    const auto zero = [&](long end) {
      if (end > begin) std::fill(rho.data() + begin, rho.data() + end, 0.0);
    };
    for (const auto& [b, e] : density_spans_.written) {
      zero(b);
      begin = e;
    }
    zero(rho.size());
  }
  density_diagonal_in_place(grid_, rho, reference_density_);
}

template <int Dim>
void Simulation<Dim>::mark_faces_with_mass() {
  const int nf = grid_.num_faces();
  if (switches_.restricted_passes) {
    // face_mass_ > 0 only where a particle's stencil reaches: the flags of the last step's
    // boxes are cleared and the new boxes marked (every other flag is 0 already)
    const bool kept = mass_boxes_valid_ && mass_faces_.data() == mass_boxes_data_ &&
                      mass_faces_.size() == static_cast<std::size_t>(nf);
    // (the new boxes first; then the old boxes cleared and the new ones marked in one parallel
    // region, a barrier between: a face of both is cleared before it is marked)
    const FaceBoxes boxes = particle_face_boxes();
    // (fresh storage made resident in one call: kern25, core/first_touch.hpp)
    if (!kept) assign_resident(mass_faces_, static_cast<std::size_t>(nf), char{0});
    std::array<FaceRows, Dim> clear_rows, mark_rows;
    long total = 0;
    for (int axis = 0; axis < Dim; ++axis) {
      if (kept) clear_rows[axis] = face_rows(mass_boxes_, axis);
      mark_rows[axis] = face_rows(boxes, axis);
      total += static_cast<long>(clear_rows[axis].rows()) * clear_rows[axis].nx +
               static_cast<long>(mark_rows[axis].rows()) * mark_rows[axis].nx;
    }
#pragma omp parallel num_threads(team_threads(total))
    {
      for (int axis = 0; axis < Dim; ++axis) {
        const FaceRows& fr = clear_rows[axis];
        const int rows = fr.rows(), nx = fr.nx;
#pragma omp for schedule(static) nowait
        for (int r = 0; r < rows; ++r) {
          const int first = fr.first(r);
          std::fill(mass_faces_.begin() + first, mass_faces_.begin() + first + nx, 0);
        }
      }
#pragma omp barrier
      for (int axis = 0; axis < Dim; ++axis) {
        const FaceRows& fr = mark_rows[axis];
        const int rows = fr.rows(), nx = fr.nx;
#pragma omp for schedule(static) nowait
        for (int r = 0; r < rows; ++r) {
          const int first = fr.first(r);
          for (int x = 0; x < nx; ++x) mass_faces_[first + x] = face_mass_[first + x] > 0.0;
        }
      }
    }
    mass_boxes_ = boxes;
    mass_boxes_data_ = mass_faces_.data();
    mass_boxes_valid_ = true;
    return;
  }
  mass_boxes_valid_ = false;
  mass_faces_.resize(grid_.num_faces());
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (int f = 0; f < nf; ++f) mass_faces_[f] = face_mass_[f] > 0.0;
}

template <int Dim>
bool Simulation<Dim>::masses_read_after_solve() const {
  return switches_.energy_ledger;
}

template <int Dim>
void Simulation<Dim>::particles_to_grid_with_forces(double dt) {
  // (1) map velocity from particles to grid (APIC)
  {
    ScopedTimer timer(stats_.timing[FramePhase::particles]);
    // the faces' densities into P's own storage (P of the last step is read by nothing from
    // here on; update_step_weights turns them into this step's P in place)
    transfer_to_grid();
    mark_faces_with_mass();
  }
  account(frame_ledger_.to_grid, [&] { return face_kinetic_energy(); });
  restart_ledger([&] { return grid_and_body_kinetic_energy(); });
  // (2) add external force (gravity) on the faces that carry mass; (3) on the dynamic bodies
  // (per face, on several threads: each face written once)
  // (the faces with mass lie in mass_boxes_ when those are kept)
  const int nf = grid_.num_faces();
  if (switches_.restricted_passes && mass_boxes_valid_ && mass_faces_.data() == mass_boxes_data_) {
    for (int axis = 0; axis < Dim; ++axis) {
      FaceBoxes one = mass_boxes_;
      for (int a = 0; a < Dim; ++a)
        if (a != axis) one.hi[a] = one.lo[a] - VecI<Dim>::Ones();
      const double g = dt * gravity_[axis];
      for_faces_in_boxes(one, [&](int f) {
        if (mass_faces_[f]) u_[f] += g;
      });
    }
  } else {
#pragma omp parallel for schedule(static) num_threads(process_threads())
    for (int f = 0; f < nf; ++f)
      if (mass_faces_[f]) u_[f] += dt * gravity_[grid_.face_coord(f).first];
  }
  if (coupled_) rigid_->apply_gravity(dt, gravity_);
}

template <int Dim>
bool Simulation<Dim>::ballistic_faces_pic() const {
  // without APIC (c = 0) the PIC value is P2G's own
  return switches_.unreached_faces_keep_u_star && switches_.ballistic_faces_pic && switches_.apic;
}

template <int Dim>
bool Simulation<Dim>::ballistic_face(int f) const {
  if (!(switches_.unreached_faces_keep_u_star && weights_.fluid_face[f] > 0.0 && mass_faces_[f]))
    return false;
  const double w = weights_.liquid_face[f];
  if (w == 0.0) return true;
  // A face with no liquid in its control volume is ballistic also when clamp_stressed_face_weights
  // raised its W_L^u for the stress (departures item 23): the clamp gives the solve zero traction
  // there, and the face still carries only the particles' free flight. Such a face has no liquid
  // cell beside it (the clamp of kMinLiquidFaceFraction for the pressure raises only faces beside
  // a liquid cell, which stay as they were). Without this, particles resting on a floor under a
  // thin viscous sheet lost their PIC value there (ballistic_faces_take_pic) and a thin
  // shear-thinning sheet regained 14 J in one frame (thinning-bunny-drop-3d, slow_long_runs).
  if (w != kMinLiquidFaceFraction) return false;
  const auto [axis, c] = grid_.face_coord(f);
  const int minus = grid_.face_cell_minus(axis, c), plus = grid_.face_cell_plus(axis, c);
  return !(minus >= 0 && weights_.liquid_cell[minus] > 0.0) &&
         !(plus >= 0 && weights_.liquid_cell[plus] > 0.0);
}

template <int Dim>
void Simulation<Dim>::ballistic_faces_take_pic(double dt) {
  // A ballistic face's u* is P2G's value plus g dt, and nothing in the solve changes it. For a
  // particle lying on the floor the face below it is the wall's (0) and the one above it is
  // ballistic: with APIC's value, v_y + c_yy dx - g dt there, G2P returns c_yy lower by g dt / dx
  // than before, so the particle's affine matrix sums the free fall the floor does not let it
  // take, step after step, and the transfers release it (liquid-bunny-into-bowl-3d regained
  // 3.6 J; docs/particles.md, "Energy regains over long runs"). The PIC value (the particles'
  // velocities without their affine part) keeps c_yy at one step's -g dt / dx; a drop in flight
  // loses APIC's rotation on these faces only. Only the faces beside a wall or solid along
  // their axis take it (the sum needs a neighbour that does not fall; elsewhere the PIC value
  // took the rotation of a free spinning blob's surface, test_viscous_simulation), unless
  // ballistic_faces_pic_everywhere. The PIC value is summed for the listed faces only
  // (pic_velocity_on_faces, from the particles in the cells around them, which have not moved
  // since particles_to_grid): a few thousand faces at Fig. 2's paper grid, where a face-sized
  // PIC sum in P2G kept 200 MB alive and first-touched.
  if (!ballistic_faces_pic()) return;
  ScopedTimer timer(stats_.timing[FramePhase::particles]);
  const bool everywhere = switches_.ballistic_faces_pic_everywhere;
  const int nf = grid_.num_faces();
  const auto keep = [&](int f) {
    return mass_faces_[f] && ballistic_face(f) && (everywhere || face_beside_support(f));
  };
  // the faces, per thread over fixed ranges, joined in range order: ascending. With the mass
  // boxes (mass_faces_ is 0 outside them, and a face without mass is never listed) the ranges
  // are of the boxes' rows, axis after axis: a row's faces are consecutive and ascending, the
  // rows of an axis ascending and the axes' faces in axis order, so the joined list is that of
  // the pass over every face (800k faces on the 64^3 bunny, its boxes ~50k)
  const bool boxed = switches_.restricted_passes && mass_boxes_valid_ &&
                     mass_faces_.data() == mass_boxes_data_ &&
                     mass_faces_.size() == static_cast<std::size_t>(nf);
  std::array<FaceRows, Dim> rows_of;
  std::array<long, Dim + 1> row_start{};
  long work = nf;
  if (boxed) {
    work = 0;
    for (int axis = 0; axis < Dim; ++axis) {
      rows_of[axis] = face_rows(mass_boxes_, axis);
      row_start[axis + 1] = row_start[axis] + rows_of[axis].rows();
      work += static_cast<long>(rows_of[axis].rows()) * rows_of[axis].nx;
    }
  }
  const int threads = team_threads(work);
  std::vector<std::vector<int>> found(threads);
#pragma omp parallel num_threads(threads)
  {
    const int t = omp_get_thread_num(), nt = omp_get_num_threads();
    for (int r = t; r < threads; r += nt) {
      if (boxed) {
        const long lo = row_start[Dim] * r / threads, hi = row_start[Dim] * (r + 1) / threads;
        int axis = 0;
        for (long k = lo; k < hi; ++k) {
          while (k >= row_start[axis + 1]) ++axis;
          const int first = rows_of[axis].first(static_cast<int>(k - row_start[axis]));
          for (int f = first; f < first + rows_of[axis].nx; ++f)
            if (keep(f)) found[r].push_back(f);
        }
        continue;
      }
      const int lo = static_cast<int>(static_cast<long>(nf) * r / threads);
      const int hi = static_cast<int>(static_cast<long>(nf) * (r + 1) / threads);
      for (int f = lo; f < hi; ++f)
        if (keep(f)) found[r].push_back(f);
    }
  }
  pic_faces_.clear();
  for (const auto& list : found) pic_faces_.insert(pic_faces_.end(), list.begin(), list.end());
  pic_velocity_on_faces(particles_, grid_, pic_faces_, pic_values_);
  const long nl = static_cast<long>(pic_faces_.size());
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (long i = 0; i < nl; ++i) {
    const int f = pic_faces_[i];
    u_[f] = pic_values_[i] + dt * gravity_[grid_.face_coord(f).first];
  }
}

template <int Dim>
bool Simulation<Dim>::face_beside_support(int f) const {
  if (weights_.fluid_face[f] < 1.0 || wall_face(f)) return true;
  const auto [axis, coord] = grid_.face_coord(f);
  for (int side : {-1, 1}) {
    VecI<Dim> n = coord;
    n[axis] += side;
    const int g = grid_.face_index_or_outside(axis, n);
    if (g >= 0 && (wall_face(g) || weights_.fluid_face[g] < 1.0)) return true;
  }
  return false;
}

template <int Dim>
void Simulation<Dim>::update_step_weights() {
  // (4) liquid/air domain: level set from the particles on the half lattice
  // (5) volume fractions: W_F^u, W_F^s from the solids at the bodies' pose (section 4.4.6),
  // W_L^p, W_L^u, W_L^s from the liquid; the particles and bodies have not moved since the end
  // of the last frame if that is where we are
  // (the volume is read at a frame's end only, where advance_frame makes the weights again)
  if (!liquid_weights_current_) {
    if (coupled_) update_moving_solids();
    update_liquid_weights(/*stress=*/true, /*volume=*/false);
  }
  liquid_weights_current_ = false;
  {
    ScopedTimer timer(stats_.timing[FramePhase::weights]);
    density_diagonal_in_place_after_transfer();
  }
}

template <int Dim>
void Simulation<Dim>::release_liquid_phi() {
  // The liquid level set is read after the weights only by divergence_free_air (a diagnosis
  // switch) and, outside the steps, at a frame's end (render, liquid_phi()), where
  // advance_frame makes it again; the next step's weights make it anew too (into a lent buffer,
  // update_moving_solids, or a fresh one). Its memory goes back to the heap before the solve,
  // whose grid-sized vectors then reuse it: at a coupled step's memory peak (the solve) it was
  // a lattice-sized vector alive and unread (541 MB at the paper's 256x128x256 grid).
  // (The guard's velocity copy, reached_u_, is dead here too, but releasing it left the paper
  // grid's peak as it was: not done)
  if (!switches_.divergence_free_air) liquid_phi_.release();
}

template <int Dim>
void Simulation<Dim>::extrapolate_into_air() {
  // the solve reads u* on faces the particles did not reach: with stress unknowns D reads the
  // air faces next to the surface (b1 of eq. (24)), and the weighted divergence of a surface
  // cell (b2) reads its faces towards the air, whose W_L^u is small but not zero. Extend u*
  // there from the faces that carry mass, so the surface sees the liquid's own velocity (close
  // to traction-free) rather than air at rest (a no-slip lid, and a spurious divergence: a
  // liquid ball in free fall felt a pressure of 1e-4 rho g dx), as Batty & Bridson (2008)
  // extrapolate before their viscosity solve
  if (!switches_.air_velocity) return;
  ScopedTimer timer(stats_.timing[FramePhase::extrapolation]);
  std::vector<char>& carried = face_flags_;
  carried = mass_faces_;
  // (the faces with mass lie in mass_boxes_: the first layer searches those boxes grown by a face,
  // band17). The first layer is exact for a linear field (a rigid rotation): neighbour averaging
  // there made a free viscous blob's surface feel a shear it does not have (departures item 22)
  if (switches_.restricted_passes && mass_boxes_valid_ && mass_faces_.data() == mass_boxes_data_)
    extrapolate_air_velocity<Dim>(grid_, u_, carried, kAirVelocityLayers, &mass_boxes_.lo,
                                  &mass_boxes_.hi);
  else
    extrapolate_air_velocity<Dim>(grid_, u_, carried, kAirVelocityLayers);
}

template <int Dim>
void Simulation<Dim>::solve_step(double dt) {
  // (6) contacts, (7)-(10) active DOFs, assembly (or stencil set-up) and the solves of the
  // scheme; (11) velocity update u = u* - dt P^-1 (W_L^u)^-1 (G W_L^p p + D^T M W_L^s tau) and
  // (12) the bodies' velocities (eq. (21))
  ScopedTimer timer(stats_.timing[FramePhase::solve]);
  densities_before_solve();  // (band24) P +0 beyond its layers only where W_L^u is +0
  if (coupled_) {
    solve_coupled(dt);
  } else {
    solve_liquid(dt);
    stats_.solver.fluid_seconds += timer.seconds();
  }
}

template <int Dim>
void Simulation<Dim>::trusted_faces(std::vector<char>& trusted) const {
  // faces with fluid whose weight W_F^u W_L^u (W_L^u before the clamp) reaches
  // kTrustedLiquidFaceFraction, and faces that carry mass outside the liquid's weights (the
  // stage switches, for diagnosis only, can drop the second kind or trust every liquid face)
  const int nf = grid_.num_faces();
  FaceBoxes boxes;
  if (trusted_boxes(boxes)) {
    // no face outside the boxes is trusted: a zero fill of the flags and the test in the boxes
    assign_resident(trusted, static_cast<std::size_t>(nf), char{0});  // (kern25)
    for_faces_in_boxes(boxes, [&](int f) { trusted[f] = trusted_face(f); });
    return;
  }
  reserve_resident(trusted, static_cast<std::size_t>(nf));
  trusted.resize(nf);
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (int f = 0; f < nf; ++f) trusted[f] = trusted_face(f);
}

template <int Dim>
bool Simulation<Dim>::trusted_face(int f) const {
  // W_F^u W_L^u with the clamped W_L^u: the clamp raises a fraction below
  // kMinLiquidFaceFraction to it, and W_F^u <= 1, so such a face stays below
  // kTrustedLiquidFaceFraction (1e-4 < 0.1) as it was before the clamp: the same faces
  static_assert(kMinLiquidFaceFraction < kTrustedLiquidFaceFraction,
                "the trust test reads the clamped W_L^u");
  return weights_.fluid_face[f] > 0.0 &&
         (weights_.fluid_face[f] * weights_.liquid_face[f] >= kTrustedLiquidFaceFraction ||
          ballistic_face(f) ||
          (!switches_.trusted_faces && weights_.liquid_face[f] > 0.0));
}

template <int Dim>
int Simulation<Dim>::extrapolation_layers(double dt) const {
  // ceil(cfl) + 2: as far as the particles may travel in a step (cfl cells) and two more for the
  // stencils. The step's own velocity usually carries them much less far (a scene with cfl 100
  // extrapolated 102 layers, the whole container, every step), so the layers are cut to its
  // reach (docs/particles.md, "Velocity extrapolation"). Every face a particle reads after the
  // solve holds a trusted value, an extrapolated average of trusted values, zero (walls, static
  // solids) or, in a solid, a velocity interpolated there with its inflow removed
  // (constrain_velocity_in_solids), so |u_f| <= c = sqrt(Dim + 1) S with S the largest |u_f| of
  // a trusted face; interpolation is a convex combination, so an RK2 substep of
  // advect_particles moves a particle by at most c h per axis, Dim c h in faces of the
  // extrapolation (a layer steps one face along one axis). Pushed out of a static solid it
  // moves at most as far again (its depth, the solid's distance being 1-Lipschitz) plus 0.05 dx
  // per substep (substeps of at most half a cell). Hence (2 Dim + 1) c dt / dx layers, one more
  // for the 0.05 dx, and two for the interpolation stencils around the particles' starting
  // cells, as before; never more than the cfl bound. Scenes with moving bodies (whose motion
  // and push-out the bound does not cover: measured, bunnies-onto-pool-2d differed at frame 10),
  // the drift of the next step (split_advection) unless its reads are guarded as advect's are
  // (drift_guarded: then a particle of that drift that reads a face beyond the reach is moved
  // again after a deeper extrapolation) and divergence_free_air (whose band is these layers)
  // keep the cfl bound
  const int cfl_layers = static_cast<int>(std::ceil(scene_.time.cfl)) + 2;
  if (switches_.extrapolate_everywhere) {
    int diameter = 0;  // in layers: steps of one face along one axis
    for (int a = 0; a < Dim; ++a) diameter += grid_.cells()[a] + 1;
    return diameter;
  }
  if (switches_.extrapolation_layers > 0 && !coupled_ && !rigid_)
    return switches_.extrapolation_layers;
  if (switches_.extrapolate_cfl_layers || coupled_ || rigid_ ||
      (split_drift() && !drift_guarded()) || switches_.divergence_free_air)
    return cfl_layers;
  // the largest trusted speed (a maximum: the same for any split of the faces)
  double speed = 0.0;
  const int nf = grid_.num_faces();
#pragma omp parallel for schedule(static) reduction(max : speed) num_threads(process_threads())
  for (int f = 0; f < nf; ++f)
    if (face_flags_[f]) speed = std::max(speed, std::abs(u_[f]));
  const double reach = (2 * Dim + 1) * std::sqrt(Dim + 1.0) * speed * dt / grid_.dx();
  if (!(reach < cfl_layers)) return cfl_layers;  // also a non-finite speed
  return std::min(cfl_layers, static_cast<int>(std::ceil(reach)) + 3);
}

template <int Dim>
void Simulation<Dim>::extrapolate_from_trusted_faces(double dt) {
  if (!switches_.extrapolate_after_solve) return;
  ScopedTimer timer(stats_.timing[FramePhase::extrapolation]);
  trusted_faces(face_flags_);
  reached_layers_ = extrapolation_layers(dt);
  // (the next step's first half drift extends from the same trusted faces; the weights they
  // come from are made again before it, at the frame's end)
  drop_drift_guard();
  if (drift_guarded()) drift_trusted_ = face_flags_;
  // (trusted_faces found them in trusted_boxes when it can: the first layer searches those boxes,
  // band17; the same state, so the same boxes)
  FaceBoxes boxes;
  if (trusted_boxes(boxes))
    extrapolate_velocity<Dim>(grid_, u_, face_flags_, reached_layers_, boxes.lo, boxes.hi);
  else
    extrapolate_velocity(grid_, u_, face_flags_, reached_layers_);
  if (!guards_reads()) return;
  // a copy for a deeper extrapolation (which reads only the trusted faces and the layers it fills
  // itself, so the shallower layers here change nothing) and for the faces no particle read (the
  // extrapolation did not write them: the solve's values); then the faces not reached are NaN
  // while the particles read the velocity (advect), so that a read shows in the particle's values
  // The copy is u_'s own buffer (a swap: the same values, no pass), and u_ is written anew in
  // one stream: the reached faces' values, NaN elsewhere (issue 20, band17: the copy read u_ and
  // wrote both vectors, three face-sized streams per step, 202 MB each at the paper's
  // 256x128x256 grid)
  const int nf = grid_.num_faces();
  reached_u_.swap(u_);
  // The stream goes into the face masses' storage when nothing reads them before the next
  // particles_to_grid, which writes every face of it (band20: a fresh face-sized block per step,
  // 202 MB at the paper's 256x128x256 grid, first touched whole by this stream above the solve's
  // transient blocks); advect gives the copy's storage back to the masses
  if (!masses_read_after_solve() && face_mass_.size() == nf && u_.size() == 0)
    u_.swap(face_mass_);
  else
    u_.resize(nf);
  const double nan = std::numeric_limits<double>::quiet_NaN();
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (int f = 0; f < nf; ++f) u_[f] = face_flags_[f] ? reached_u_[f] : nan;
}

template <int Dim>
bool Simulation<Dim>::guards_reads() const {
  return switches_.extrapolate_after_solve &&
         (switches_.extend_to_every_read || switches_.poison_unreached_faces);
}

template <int Dim>
bool Simulation<Dim>::extend_extrapolation(bool drift) {
  if (!switches_.extend_to_every_read) return false;
  // a face lattice's diameter in extrapolation layers (steps of one face along one axis)
  int diameter = 0;
  for (int a = 0; a < Dim; ++a) diameter += grid_.cells()[a] + 1;
  if (reached_layers_ >= diameter) return false;
  reached_layers_ = std::min(diameter, 2 * reached_layers_ + 1);
  const bool deepest = reached_layers_ >= diameter;
  Stopwatch watch;
  // the deeper extrapolation (from the copy made after the shallower one) in u_'s place while the
  // stages of the step after the extrapolation run on it: its first layers are those of the
  // shallower one (each layer reads only the trusted faces and the layers before it), so every
  // face reached already gets the same value again
  const int nf = grid_.num_faces();
  extended_u_.resize(nf);
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (int f = 0; f < nf; ++f) extended_u_[f] = reached_u_[f];
  u_.swap(extended_u_);
  face_flags_.swap(extended_flags_);
  if (drift)
    face_flags_ = drift_trusted_;
  else
    trusted_faces(face_flags_);
  extrapolate_velocity(grid_, u_, face_flags_, reached_layers_);
  // unreached even now (no trusted face of that component to reach them from): the solve's value
  // as before the guard, unless the test switch keeps them NaN
  if (!deepest || switches_.poison_unreached_faces) {
#pragma omp parallel for schedule(static) num_threads(process_threads())
    for (int f = 0; f < nf; ++f)
      if (!face_flags_[f]) u_[f] = std::numeric_limits<double>::quiet_NaN();
  }
  // the walls and the fully solid faces as the step set them before it constrained the faces
  // in solids (extended_u_ holds the step's velocity now; a face in a solid its value before),
  // then the faces in solids constrained at the pose of the step's solve (the bodies have moved
  // since: move_bodies). For the drift (no moving bodies) the step's velocity has been scaled by
  // line 15's payments since: the value apply_wall_and_solid_velocities set, zero, scaled below
  // with the rest
  {
    const VectorX& given = extended_u_;
    // (the walls beside air, departures item 16, are air faces: they keep the deeper values)
    std::vector<double> air_wall_values(air_walls_.size());
    for (std::size_t i = 0; i < air_walls_.size(); ++i) air_wall_values[i] = u_[air_walls_[i]];
#pragma omp parallel for schedule(static) num_threads(process_threads())
    for (int f = 0; f < nf; ++f)
      if (weights_.fluid_face[f] == 0.0 || wall_face(f)) u_[f] = drift ? 0.0 : given[f];
    for (std::size_t i = 0; i < air_walls_.size(); ++i) u_[air_walls_[i]] = air_wall_values[i];
    // (the rows the step's constrain evaluated: a row it left keeps +0 in u_ and in given)
    const int count = static_cast<int>(constrained_rows_.size());
    for (int r = 0; r < count && !solids_.empty(); ++r) {
      const int j = constrained_rows_[r];
      const int f = solid_faces_[j];
      if (weights_.fluid_face[f] == 0.0 || wall_face(f)) u_[f] = solid_frame_[j].before;
    }
  }
  constrain_velocity_in_solids(true);
  // line 15's payments as they scaled u_ after the step (pay_line15_energy), in their order:
  // the deeper values are those u_ would hold had the step's extrapolation reached this far
  if (drift)
    for (const auto& [mean, s] : drift_rescales_) rescale_face_velocity(mean, s);
  stats_.timing[FramePhase::extrapolation] += watch.seconds();
  divergence_free_air();  // (timed as extrapolation)
  const Stopwatch rest;
  face_flags_.swap(extended_flags_);
  u_.swap(extended_u_);
  // only the faces still unread take the deeper values
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (int f = 0; f < nf; ++f)
    if (std::isnan(u_[f])) u_[f] = extended_u_[f];
  stats_.timing[FramePhase::extrapolation] += rest.seconds();
  return true;
}

template <int Dim>
void Simulation<Dim>::divergence_free_air() {
  if (!switches_.divergence_free_air || !switches_.extrapolate_after_solve) return;
  ScopedTimer timer(stats_.timing[FramePhase::extrapolation]);
  const int layers = static_cast<int>(std::ceil(scene_.time.cfl)) + 2;
  // face_flags_ holds the faces the extrapolation reached (or trusted)
  std::vector<char> trusted;
  trusted_faces(trusted);
  // (with this switch the level set is stored over the whole lattice: make_liquid_phi)
  if (!liquid_phi_.whole())
    throw std::logic_error("divergence_free_air: the liquid level set is not whole");
  divergence_free_air_velocity(grid_, lattice_, liquid_phi_.values, weights_.fluid_face, trusted,
                               face_flags_, layers,
                               switches_.divergence_free_surface_cells ? 1.0 : 0.0, u_);
}

template <int Dim>
bool Simulation<Dim>::wall_face(int f) const {
  const auto [axis, coord] = grid_.face_coord(f);
  return grid_.is_boundary_face(axis, coord) &&
         boundary_[2 * axis + (coord[axis] == 0 ? 0 : 1)] == BoundaryType::wall;
}

template <int Dim>
std::pair<VecI<Dim>, VecI<Dim>> Simulation<Dim>::solid_face_box(int axis) const {
  // (docs/derivations.md, "Passes restricted to boxes") W_F^u = 1 - W_S^u is 0 off the walls only where the solids' fraction of the face's
  // control volume is 1 > 0. Every such fraction is 0 unless a lattice point of that control
  // volume has a solids' level set < 0: lattice_cube_negative_fraction (fluid_face_weights, the
  // static solids) and solid_weights' parts per body (each body's level set >= the union's, so
  // a negative point of a body's is one of the union's) count negative corners and return 0
  // without one. Those points lie in [solid_lo_, solid_hi_] (the box of the solids' negative
  // points, made with W_F^u). The control volume of face c of `axis` spans the lattice points
  // p - 1 .. p + 1 per axis b, p = 2 c_b (+ 1 off `axis`), mirrored into the lattice at a
  // domain side (staying within p - 1 .. p + 1) or wrapped on a periodic axis: a face whose
  // coordinate b has 2 c_b + 2 < lo_b or 2 c_b - 2 > hi_b (one point of margin each side) reads
  // no point of the box. Periodic axes: every coordinate (the reads wrap). lo > hi: no face.
  const VecI<Dim> fdims = grid_.face_dims(axis);
  VecI<Dim> lo = VecI<Dim>::Zero(), hi = fdims - VecI<Dim>::Ones();
  if ((solid_lo_.array() > solid_hi_.array()).any()) return {lo, -VecI<Dim>::Ones()};
  for (int b = 0; b < Dim; ++b) {
    if (grid_.periodic(b)) continue;
    // c >= (lo_b - 2) / 2 rounded down, c <= (hi_b + 2) / 2 rounded down (lo_b, hi_b >= 0)
    lo[b] = std::max(0, (solid_lo_[b] - 2) / 2 - 1);
    hi[b] = std::min(fdims[b] - 1, (solid_hi_[b] + 2) / 2);
  }
  return {lo, hi};
}

namespace {

/// The nonzero lattice offsets of L1 length at most `layers` (the faces the extrapolation's
/// first `layers` layers fill a face from), in lexicographic order.
template <int Dim>
std::vector<VecI<Dim>> l1_ball_offsets(int layers) {
  std::vector<VecI<Dim>> ball;
  if (layers <= 0) return ball;
  const VecI<Dim> box = VecI<Dim>::Constant(2 * layers + 1);
  for (int j = 0; j < box.prod(); ++j) {
    const VecI<Dim> offset = lattice_coord<Dim>(j, box) - VecI<Dim>::Constant(layers);
    if (offset.cwiseAbs().sum() <= layers && !offset.isZero()) ball.push_back(offset);
  }
  return ball;
}

}  // namespace

template <int Dim>
bool Simulation<Dim>::trusted_within(int axis, const VecI<Dim>& coord, int layers,
                                     const std::vector<VecI<Dim>>& ball, bool have_boxes,
                                     const FaceBoxes& boxes) const {
  // the faces of `axis` within `layers` steps of one face along one axis (wrapped on periodic
  // axes, cut at the lattice's ends): the faces the extrapolation's first `layers` layers fill
  // from, so a face with a trusted one among them is reached by every extrapolation at least
  // `layers` deep, with the same value (extrapolate_velocity: each layer reads only the trusted
  // faces and the layers before it)
  if (layers <= 0) return false;
  if (have_boxes)
    for (int b = 0; b < Dim; ++b) {
      // no trusted face outside the box: none within `layers` of a face farther from it
      if (boxes.lo[axis][b] > boxes.hi[axis][b]) return false;
      if (!grid_.periodic(b) &&
          (coord[b] < boxes.lo[axis][b] - layers || coord[b] > boxes.hi[axis][b] + layers))
        return false;
    }
  const VecI<Dim> dims = grid_.face_dims(axis);
  for (const VecI<Dim>& offset : ball) {
    VecI<Dim> g = coord + offset;
    bool inside = true;
    for (int b = 0; b < Dim && inside; ++b) {
      if (grid_.periodic(b))
        g[b] = ((g[b] % dims[b]) + dims[b]) % dims[b];
      else
        inside = g[b] >= 0 && g[b] < dims[b];
    }
    if (inside && trusted_face(grid_.face_index(axis, g))) return true;
  }
  return false;
}

template <int Dim>
void Simulation<Dim>::apply_wall_and_solid_velocities() {
  ScopedTimer timer(stats_.timing[FramePhase::extrapolation]);
  // zero the normal velocity on walls, give fully solid faces their solid's velocity (zero for
  // static solids), then remove the inflow into solids. The fully solid faces are found by
  // their weight alone (a compare per face, on several threads: each face written once), the
  // walls by their layers of faces.
  const std::vector<Box<Dim>> bounds = body_bounds();  // (posed once, not per face)
  // row by row of each axis's face lattice (x fastest), the coordinates counted along the row
  // instead of divided out of the index per face (wall_face, face_coord): the same faces written
  // with the same values
  // (every axis in one parallel region, the rows of each split statically: the axes' faces are
  // distinct, so no barrier between them)
  // Only the faces whose W_F^u can be 0 off the walls are visited (issue 20, band17: the pass
  // over every face was box-sized work per step): solid_face_box
  // (StageSwitches::restricted_passes off: every face, the dense pass the tests compare with)
  const bool restricted = switches_.restricted_passes;
  if (!restricted || !(solid_lo_.array() > solid_hi_.array()).any()) {
#pragma omp parallel num_threads(process_threads())
  for (int axis = 0; axis < Dim; ++axis) {
    const auto [flo, fhi] = restricted ? solid_face_box(axis)
                                       : std::pair<VecI<Dim>, VecI<Dim>>(
                                             VecI<Dim>::Zero(),
                                             grid_.face_dims(axis) - VecI<Dim>::Ones());
    const int nx = fhi[0] - flo[0] + 1;
    VecI<Dim> row_dims = fhi - flo + VecI<Dim>::Ones();
    row_dims[0] = 1;
    const int rows = (flo.array() > fhi.array()).any() ? 0 : row_dims.prod();
    const bool walls = !grid_.periodic(axis);
    const bool wall_lo = walls && boundary_[2 * axis] == BoundaryType::wall;
    const bool wall_hi = walls && boundary_[2 * axis + 1] == BoundaryType::wall;
    const int top = grid_.cells()[axis];
#pragma omp for schedule(static) nowait
    for (int r = 0; r < rows; ++r) {
      VecI<Dim> coord = flo + lattice_coord<Dim>(r, row_dims);
      const int first = grid_.face_index(axis, coord);
      for (int i = 0; i < nx; ++i) {
        const int f = first + i;
        const int x = flo[0] + i;
        if (weights_.fluid_face[f] != 0.0) continue;
        coord[0] = x;
        if ((wall_lo && coord[axis] == 0) || (wall_hi && coord[axis] == top)) continue;
        u_[f] = coupled_ ? solid_velocity(grid_.face_center(axis, coord), bounds)[axis] : 0.0;
      }
    }
  }
  }
  // (departures items 16 and 18) a wall face beside air keeps the extrapolated velocity: no
  // particle's stencil reached it at the transfer (mass_faces_), the cell beside it holds no
  // liquid (W_L^p = 0), so the solve did not see this wall, and a trusted face lies within
  // air_wall_layers layers of the extrapolation (trusted_within), so the extrapolation's first
  // layers give it the same value however deep it goes (extrapolation_layers,
  // extrapolate_everywhere, a deeper extrapolation of the guard: a test switch's single layer
  // leaves it NaN under the guard, and a particle that reads it is redone after a deeper
  // extrapolation, extend_extrapolation, as for any air face). Liquid in flight that the solve
  // saw a cell or two from the wall is then not slowed by the wall before it reaches it; the
  // particles that reach it in the advection are stopped by the wall clamp (settle_position). A
  // wall face farther from the trusted faces (a splash's path ahead of the liquid) keeps the
  // zero: the extrapolation's deeper layers would carry a splash into the far walls and pile it
  // at the clamp (item 16's final form: dam-break-2d at 64x32 lost 1.44 % of its volume).
  const int nf = grid_.num_faces();
  const bool air_walls = switches_.air_walls_extrapolated && switches_.extrapolate_after_solve &&
                         mass_faces_.size() == static_cast<std::size_t>(nf) &&
                         weights_.liquid_cell.size() == grid_.num_cells();
  air_walls_.clear();
  // the trusted faces' boxes and the ball of offsets, once: the wall loop asks about every wall
  // face beside air (at 256x128x256 most of some 260k wall faces, a ball of 24 faces each)
  const int air_wall_layers = switches_.air_wall_layers;
  const std::vector<VecI<Dim>> ball = air_walls ? l1_ball_offsets<Dim>(air_wall_layers) : std::vector<VecI<Dim>>();
  FaceBoxes trusted_box{};
  const bool have_boxes = air_walls && trusted_boxes(trusted_box);
  // (issue 20, setup19) The wall layers row by row (a row runs along the layer's first axis other
  // than `axis`), every layer in one parallel region, each layer's rows split statically. Only
  // the faces within reach of the trusted boxes are asked the air-wall question: a face farther
  // than air_wall_layers from its axis's box along a non-periodic axis, or any face when that
  // box is empty, has trusted_within false (its own first test), so it is zeroed without reading
  // its mass flag, the liquid cell beside it and its weights (four strided reads per face of the
  // x walls, serial, before). The same faces zeroed and the same air walls: each face is
  // written by one thread, and the air walls gathered per thread are sorted below, as before.
  struct WallLayer {
    int axis, side, run, rows, n_run, stride;
    VecI<Dim> row_dims, lo, hi;  // the rows' lattice; the reach box (lo > hi: none)
    bool any;                    // any face of the layer within reach
  };
  std::vector<WallLayer> layers;
  long total = 0;
  for (int axis = 0; axis < Dim; ++axis) {
    if (grid_.periodic(axis)) continue;
    for (int side = 0; side < 2; ++side) {
      if (boundary_[2 * axis + side] != BoundaryType::wall) continue;
      WallLayer w;
      w.axis = axis;
      w.side = side;
      w.run = axis == 0 ? 1 : 0;
      const VecI<Dim> fdims = grid_.face_dims(axis);
      VecI<Dim> layer = fdims;
      layer[axis] = 1;
      w.n_run = layer[w.run];
      w.row_dims = layer;
      w.row_dims[w.run] = 1;
      w.rows = w.row_dims.prod();
      VecI<Dim> step = VecI<Dim>::Zero();
      step[w.run] = 1;
      w.stride = grid_.face_index(axis, step) - grid_.face_index(axis, VecI<Dim>::Zero());
      // the reach box: every face without boxes, none when the axis's trusted box is empty
      w.lo = VecI<Dim>::Zero();
      w.hi = fdims - VecI<Dim>::Ones();
      if (!air_walls) {
        w.hi = -VecI<Dim>::Ones();
      } else if (have_boxes) {
        const bool empty = (trusted_box.lo[axis].array() > trusted_box.hi[axis].array()).any();
        for (int b = 0; b < Dim; ++b) {
          if (empty) {
            w.hi[b] = -1;
          } else if (!grid_.periodic(b)) {
            w.lo[b] = std::max(w.lo[b], trusted_box.lo[axis][b] - air_wall_layers);
            w.hi[b] = std::min(w.hi[b], trusted_box.hi[axis][b] + air_wall_layers);
          }
        }
      }
      const int pos = side == 0 ? 0 : grid_.cells()[axis];
      w.any = (w.lo.array() <= w.hi.array()).all() && pos >= w.lo[axis] && pos <= w.hi[axis];
      total += static_cast<long>(w.rows) * w.n_run;
      layers.push_back(w);
    }
  }
  const int team = team_threads(total);
  std::vector<std::vector<int>> found(team);
  long asked = 0;
#pragma omp parallel num_threads(team) reduction(+ : asked)
  {
    std::vector<int>& mine = found[omp_get_thread_num()];
    for (const WallLayer& w : layers) {
      const int axis = w.axis;
#pragma omp for schedule(static) nowait
      for (int r = 0; r < w.rows; ++r) {
        VecI<Dim> coord = lattice_coord<Dim>(r, w.row_dims);
        coord[axis] = w.side == 0 ? 0 : grid_.cells()[axis];
        const int first = grid_.face_index(axis, coord);
        // the row's faces within reach: [begin, end] along the run (none when the row's other
        // coordinates are out of the box)
        bool row_in = w.any;
        for (int b = 0; b < Dim && row_in; ++b)
          if (b != w.run) row_in = coord[b] >= w.lo[b] && coord[b] <= w.hi[b];
        const int begin = row_in ? w.lo[w.run] : w.n_run, end = row_in ? w.hi[w.run] : -1;
        for (int i = 0; i < w.n_run; ++i) {
          const int f = first + i * w.stride;
          if (i >= begin && i <= end && !mass_faces_[f]) {
            ++asked;
            coord[w.run] = i;
            VecI<Dim> cell = coord;
            if (w.side == 1) cell[axis] -= 1;
            if (weights_.liquid_cell[grid_.cell_index(cell)] == 0.0 && !trusted_face(f) &&
                trusted_within(axis, coord, air_wall_layers, ball, have_boxes, trusted_box)) {
              mine.push_back(f);
              continue;
            }
          }
          u_[f] = 0.0;
        }
      }
    }
  }
  for (const std::vector<int>& part : found) air_walls_.insert(air_walls_.end(), part.begin(), part.end());
  wall_faces_asked_ = asked;
  std::sort(air_walls_.begin(), air_walls_.end());
  constrain_velocity_in_solids();
}

template <int Dim>
void Simulation<Dim>::move_bodies(double dt) {
  // (13) body positions; the particles then see the solids at the new pose
  if (!coupled_) return;
  const double potential = switches_.energy_ledger ? body_potential_energy() : 0.0;
  rigid_->integrate(dt, time_, "the coupled solve");
  if (switches_.energy_ledger) {
    frame_ledger_.advection += body_potential_energy() - potential;
    ledger_energy_ -= rigid_->kinetic_energy();
  }
  rebuild_solid_field();
}

template <int Dim>
void Simulation<Dim>::rebuild_solid_field() {
  ScopedTimer timer(stats_.timing[FramePhase::weights]);
  std::vector<ShapePtr<Dim>> shapes = solid_shapes_;
  std::vector<ShapePtr<Dim>> moving;
  for (const auto& b : rigid_->bodies())
    if (b.moves()) moving.push_back(b.posed_shape());
  shapes.insert(shapes.end(), moving.begin(), moving.end());
  solids_ = make_solid_field<Dim>(shapes, grid_.dx());
  // (departures item 25, an opt-in: the cells beside these keep their density error through
  // line 15; without it no field is made)
  moving_solids_ = switches_.density_held_beside_moving_bodies > 0.0
                       ? make_solid_field<Dim>(moving, grid_.dx())
                       : SolidField<Dim>();
  solid_field_shapes_ = shapes;
  solid_field_boxes_.clear();
  for (const auto& sh : shapes) solid_field_boxes_.push_back(sh->bounds());
}

template <int Dim>
void Simulation<Dim>::advect(double dt) {
  // (14) grid to particles (APIC), then advect (RK2) through the extrapolated field; particles
  // leaving through open faces are removed, particles that end up inside a solid are pushed out.
  // With the guard (guards_reads), the faces the extrapolation did not reach are NaN here: a
  // particle that reads one (its stencil, its path, a solid face interpolated from one) is
  // flagged and redone after a deeper extrapolation, until none is left
  const bool guard = guards_reads();
  std::vector<char>* unread = guard ? &unread_ : nullptr;
  if (guard) unread_.clear();
  {
    ScopedTimer particle_timer(stats_.timing[FramePhase::particles]);
    grid_to_particles(particles_, grid_, u_, unread);
  }
  const auto flagged = [&] { return std::count(unread_.begin(), unread_.end(), 1); };
  for (long n = guard ? flagged() : 0; n > 0 && extend_extrapolation(); n = flagged()) {
    reread_particles_ += n;
    ScopedTimer particle_timer(stats_.timing[FramePhase::particles]);
    grid_to_particles(particles_, grid_, u_, unread);
  }
  if (!switches_.apic) {
    ScopedTimer particle_timer(stats_.timing[FramePhase::particles]);
    for (auto& c : particles_.c) c.setZero();
  }
  account(frame_ledger_.to_particles, [&] { return particle_kinetic_energy(); });
  restart_ledger([&] { return liquid_potential_energy(); });
  const double h = split_drift() ? 0.5 * dt : dt;
  if (guard) unread_.clear();
  {
    ScopedTimer particle_timer(stats_.timing[FramePhase::particles]);
    advect_particles(particles_, grid_, u_, h, solids_, boundary_, unread);
  }
  // (a particle's own v and c were read well: the deeper extrapolation leaves its stencil's
  // faces as they were, so grid_to_particles would give it the same again)
  for (long n = guard ? flagged() : 0; n > 0 && extend_extrapolation(); n = flagged()) {
    reread_particles_ += n;
    ScopedTimer particle_timer(stats_.timing[FramePhase::particles]);
    advect_particles(particles_, grid_, u_, h, solids_, boundary_, unread);
  }
  if (guard) {
    // the faces no particle read get the solve's value back (what a probe or checkpoint of the
    // grid velocity read before the guard)
    // (with drift_guarded, the faces reached are kept for the next step's first half drift)
    const int nf = grid_.num_faces();
    const bool keep = drift_guarded();
    if (keep) {
      drift_reached_.resize(nf);
#pragma omp parallel for schedule(static) num_threads(process_threads())
      for (int f = 0; f < nf; ++f) {
        const bool unreached = std::isnan(u_[f]);
        drift_reached_[f] = !unreached;
        if (unreached) u_[f] = reached_u_[f];
      }
    } else {
      // the same values the other way round: the faces written since the guard (not NaN: the
      // reached ones, the walls' and solids' set after it, a deeper extrapolation's) go into the
      // copy, which becomes u_ (one face-sized read and a write per such face instead of a
      // write of nearly every face from a second vector); the copy is released below
#pragma omp parallel for schedule(static) num_threads(process_threads())
      for (int f = 0; f < nf; ++f)
        if (!std::isnan(u_[f])) reached_u_[f] = u_[f];
      u_.swap(reached_u_);
    }
    throw_if_unread(unread_, time_, frame_ + 1, "");
    // the guard's copies are dead until the next step's extrapolation writes them again (u_ has
    // no NaN left, so face_kinetic_energy does not read reached_u_): their memory goes back to
    // the heap, where the next step's solids' weights take it (the union's lattice-sized level
    // set was the step's live peak at Fig. 2's paper grid, with this face-sized copy beside it);
    // with drift_guarded the next step's first half drift extends from reached_u_ (scenes
    // without moving bodies, whose weights take no union)
    if (keep) {
      drift_guard_ = true;
      drift_rescales_.clear();
    } else {
      // (to the face masses when the extrapolation took their storage: the next
      // particles_to_grid writes every face of it, band20)
      if (face_mass_.size() == 0) face_mass_.swap(reached_u_);
      reached_u_ = VectorX();
    }
    extended_u_ = VectorX();
  }
  account(frame_ledger_.advection, [&] { return liquid_potential_energy(); });
}

template <int Dim>
bool Simulation<Dim>::split_drift() const {
  return switches_.split_advection && !coupled_;
}

template <int Dim>
void Simulation<Dim>::first_half_drift(double dt) {
  // drift-kick-drift: the particles move half a step through the last step's extrapolated
  // velocity (u_, which grid_to_particles gave them) before they are splatted for the solve, and
  // the other half through the solved velocity after it (advect). The kick then acts at the
  // step's midpoint positions, and the state at the end of a step pairs positions and velocities
  // of the same time: the energy error of the splitting is second order in dt instead of first
  // (sloshing tank, docs/particles.md "Sloshing"). The very first step has no solved velocity
  // yet and starts with the kick.
  // With drift_guarded the last step extrapolated only as far as its own velocity reaches: the
  // faces it did not reach are NaN while the particles drift (as in advect), and a particle that
  // reads one is moved again after a deeper extrapolation from the last step's trusted faces
  // (extend_extrapolation(true)), whose values are scaled by line 15's payments as u_ was. A face
  // the particles read holds what u_ would hold had the step extrapolated to the cfl bound. A
  // restored checkpoint brings that velocity fully extended (drift_resolved_).
  // The very first step has no solved velocity: its first half drift is through the particles'
  // own (initial) velocities, so that positions and velocities pair the same time from the first
  // step on. Starting with the kick instead left every particle half a step behind for good: a
  // falling drop then carried M g |v| dt / 2 more potential energy than it had lost (liquid-drop-
  // newtonian-2d: +12.2 J of 886 J at frame 1, slow_long_runs).
  if (!split_drift()) {
    drop_drift_guard();
    return;
  }
  if (!(time_ > 0.0)) {
    drop_drift_guard();
    const bool moving = std::any_of(particles_.v.begin(), particles_.v.end(),
                                    [](const Vec<Dim>& v) { return !v.isZero(0.0); });
    if (!moving) return;  // at rest (and every settling step): nothing to drift
    restart_ledger([&] { return liquid_potential_energy(); });
    {
      ScopedTimer particle_timer(stats_.timing[FramePhase::particles]);
      drift_particles_own_velocity(particles_, grid_, 0.5 * dt, solids_, boundary_);
    }
    account(frame_ledger_.advection, [&] { return liquid_potential_energy(); });
    liquid_weights_current_ = false;
    return;
  }
  restart_ledger([&] { return liquid_potential_energy(); });
  const double h = 0.5 * dt;
  const auto flagged = [&] { return std::count(unread_.begin(), unread_.end(), 1); };
  const int nf = grid_.num_faces();
  if (drift_guard_ && drift_reached_.size() == static_cast<std::size_t>(nf)) {
    VectorX& kept = drift_kept_;
    {
      ScopedTimer particle_timer(stats_.timing[FramePhase::particles]);
      // (u_ as the step left it, back in place after the drift: copied in the same parallel
      // pass that marks the unreached faces; every face is written, so the storage kept from the
      // last step's swap is reused as it is)
      kept.resize(nf);
#pragma omp parallel for schedule(static) num_threads(process_threads())
      for (int f = 0; f < nf; ++f) {
        kept[f] = u_[f];
        if (!drift_reached_[f]) u_[f] = std::numeric_limits<double>::quiet_NaN();
      }
      unread_.clear();
      advect_particles(particles_, grid_, u_, h, solids_, boundary_, &unread_);
    }
    for (long n = flagged(); n > 0 && extend_extrapolation(true); n = flagged()) {
      reread_particles_ += n;
      drift_reread_particles_ += n;
      ScopedTimer particle_timer(stats_.timing[FramePhase::particles]);
      advect_particles(particles_, grid_, u_, h, solids_, boundary_, &unread_);
    }
    u_.swap(kept);
  } else if (drift_resolved_.size() == u_.size()) {
    ScopedTimer particle_timer(stats_.timing[FramePhase::particles]);
    unread_.clear();
    advect_particles(particles_, grid_, drift_resolved_, h, solids_, boundary_, &unread_);
  } else {
    ScopedTimer particle_timer(stats_.timing[FramePhase::particles]);
    unread_.clear();
    advect_particles(particles_, grid_, u_, h, solids_, boundary_);
  }
  throw_if_unread(unread_, time_, frame_ + 1, " (first half drift)");
  drop_drift_guard();
  // (advect's copy, kept for the drift, dead until the next step's; its storage to the face
  // masses when the extrapolation took theirs: particles_to_grid writes every face, band20)
  if (face_mass_.size() == 0) face_mass_.swap(reached_u_);
  reached_u_ = VectorX();
  account(frame_ledger_.advection, [&] { return liquid_potential_energy(); });
  liquid_weights_current_ = false;
}

template <int Dim>
bool Simulation<Dim>::drift_guarded() const {
  return split_drift() && !rigid_ && guards_reads() && switches_.extend_to_every_read &&
         !switches_.divergence_free_air && switches_.line15_energy != Line15Energy::balance_local;
}

template <int Dim>
void Simulation<Dim>::drop_drift_guard() {
  drift_guard_ = false;
  drift_trusted_.clear();
  drift_reached_.clear();
  drift_rescales_.clear();
  drift_resolved_ = VectorX();
  // (reached_u_ is the guard's too once advect is done; during a step, before advect ends, it is
  // advect's and is not released here)
}

template <int Dim>
void Simulation<Dim>::resolve_drift_velocity() {
  if (!drift_guard_ || drift_reached_.size() != static_cast<std::size_t>(grid_.num_faces()))
    return;
  // the drift's guarded read with every deeper extrapolation it may ask for done at once (the
  // values of each face as the guarded drift would find them); the step's state left as it was
  const int layers = reached_layers_;
  const auto timing = stats_.timing;
  const int nf = grid_.num_faces();
  VectorX kept = u_;
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (int f = 0; f < nf; ++f)
    if (!drift_reached_[f]) u_[f] = std::numeric_limits<double>::quiet_NaN();
  while (extend_extrapolation(true)) {
  }
  drift_resolved_.swap(u_);
  u_.swap(kept);
  reached_layers_ = layers;
  stats_.timing = timing;
}

namespace {

/// The particles' mass-weighted centre (nothing without mass), summed serially in particle order.
template <int Dim>
std::optional<Vec<Dim>> mass_centre(const Particles<Dim>& particles) {
  Vec<Dim> moment = Vec<Dim>::Zero();
  double mass = 0.0;
  for (std::size_t p = 0; p < particles.size(); ++p) {
    moment += particles.mass[p] * particles.x[p];
    mass += particles.mass[p];
  }
  if (!(mass > 0.0)) return std::nullopt;
  return Vec<Dim>(moment / mass);
}

/// The liquid's mass-weighted centre, or nothing when the liquid may touch something: a particle
/// within `margin` of a face of the domain (any kind: a wall, an open face, a periodic seam), or,
/// for a solid whose bounds the particles' bounds grown by `margin` meet, a particle whose signed
/// distance to that solid is at most `margin` (a liquid falling inside a container is free until
/// it comes near the container's wall). Serial sums in particle order; the distance test is an
/// "any" over the particles (the same answer and bits for any thread count).
template <int Dim>
std::optional<Vec<Dim>> free_liquid_centre(const Particles<Dim>& particles,
                                           const MacGrid<Dim>& grid,
                                           const std::vector<ShapePtr<Dim>>& shapes,
                                           const std::vector<Box<Dim>>& solids, double margin) {
  const std::size_t np = particles.size();
  if (np == 0) return std::nullopt;
  Box<Dim> bounds;
  for (std::size_t p = 0; p < np; ++p) bounds.extend(particles.x[p]);
  const Box<Dim> domain = grid.domain_box();
  for (int a = 0; a < Dim; ++a)
    if (!(bounds.min()[a] - margin > domain.min()[a] && bounds.max()[a] + margin < domain.max()[a]))
      return std::nullopt;
  Box<Dim> reach(bounds.min() - Vec<Dim>::Constant(margin), bounds.max() + Vec<Dim>::Constant(margin));
  for (std::size_t i = 0; i < solids.size(); ++i) {
    if (solids[i].isEmpty() || !reach.intersects(solids[i])) continue;
    if (i >= shapes.size() || !shapes[i]) return std::nullopt;
    const Shape<Dim>& shape = *shapes[i];
    // (a particle outside the solid's bounds grown by the margin is farther than the margin from
    // it: only the others need the signed distance)
    const Box<Dim> grown(solids[i].min() - Vec<Dim>::Constant(margin),
                         solids[i].max() + Vec<Dim>::Constant(margin));
    const long n = static_cast<long>(np);
    bool near = false;
#pragma omp parallel for schedule(static) reduction(|| : near) num_threads(team_threads(n))
    for (long p = 0; p < n; ++p)
      if (!near && grown.contains(particles.x[p]) && !(shape.distance(particles.x[p]) > margin))
        near = true;
    if (near) return std::nullopt;
  }
  return mass_centre(particles);
}

}  // namespace

template <int Dim>
void Simulation<Dim>::correct_volume(double dt) {
  // (15) position correction for volume preservation, and the grid density projection that
  // keeps the particle volume and the level set's volume equal (docs/particles.md)
  if (!scene_.particles.position_correction) return;
  ScopedTimer timer(stats_.timing[FramePhase::particles]);
  const bool pay = switches_.line15_energy != Line15Energy::free;
  const double potential_before = pay ? liquid_potential_energy() : 0.0;
  const bool local = switches_.line15_energy == Line15Energy::balance_local;
  const bool limit =
      switches_.line15_lift_within_energy && switches_.line15_energy == Line15Energy::balance;
  // (kept across steps: the copy reuses its storage)
  std::vector<Vec<Dim>>& before = line15_before_;
  before.clear();
  // (gravity along a periodic axis: a particle line 15 moved across that face wrapped, and the
  // difference of the potential energies read it as a rise or drop of m |g_a| L, which the
  // account paid with the liquid's kinetic energy; check23: a periodic channel lost 1-3.5 % of
  // its kinetic energy in single steps)
  const bool seam = pay && gravity_along_periodic_axis();
  if (local || limit || seam) {
    // (copied on the team: a serial copy of every position, ~1.8 MB on the 64^3 viscous bunny,
    // ran on the calling thread; two24)
    const long np = static_cast<long>(particles_.size());
    before.resize(np);
#pragma omp parallel for schedule(static) num_threads(team_threads(np))
    for (long p = 0; p < np; ++p) before[p] = particles_.x[p];
  }
  // (departures item 15) a liquid that touches nothing (a drop in flight, more than a cell from every face of
  // the domain and from every solid) has no wall or body to push against: line 15's moves
  // rearrange it and may not carry it, so its centre of mass is put back where it was after them
  // (the density projection's displacement over a falling drop is not zero-mean: it lifted the
  // 3D drops of Fig. 10 by 1e-3 dx per frame, energy no force paid for)
  const double free_margin = grid_.dx();
  const std::optional<Vec<Dim>> free_centre =
      switches_.line15_keeps_free_centre
          ? free_liquid_centre(particles_, grid_, solid_field_shapes_, solid_field_boxes_, free_margin)
          : std::nullopt;
  if (switches_.position_correction)
    correct_positions(particles_, grid_, dt, solids_, boundary_, &correction_buffers_);
  account(frame_ledger_.position_correction, [&] { return liquid_potential_energy(); });
  if (switches_.density_projection && switches_.density_projection_in_steps)
    volume_errors_ =
        project_particle_density(particles_, grid_, lattice_, weights_.fluid_face, solids_,
                                 boundary_, 1, switches_.density_projection_surface_deficits,
                                 &density_move_, coupled_ ? &moving_solids_ : nullptr,
                                 switches_.density_held_beside_moving_bodies)
            .surface_deficits;
  if (free_centre) {
    // (the moves are a small part of a cell, far below the margin: the shifted liquid still
    // touches nothing)
    if (const auto after = mass_centre(particles_)) {
      const Vec<Dim> shift = *free_centre - *after;
      for (auto& x : particles_.x) x += shift;
    }
  }
  account(frame_ledger_.density_projection, [&] { return liquid_potential_energy(); });
  const double potential_after =
      limit ? limit_line15_lift(before, potential_before) : pay ? liquid_potential_energy() : 0.0;
  if (pay) {
    double gain = seam && before.size() == particles_.size() ? line15_potential_change(before)
                                                              : potential_after - potential_before;
    if (switches_.line15_energy != Line15Energy::per_step) {
      // a drop is kept as credit against the next rises
      gain += line15_credit_;
      line15_credit_ = std::min(0.0, gain);
    }
    if (gain > 0.0) {
      // the ledger books the kinetic energy taken with the projection's column
      restart_ledger([&] { return particle_kinetic_energy(); });
      const double kinetic_before = switches_.line15_carry_debt ? particle_kinetic_energy() : 0.0;
      if (local && before.size() == particles_.size())
        pay_line15_energy_locally(gain, before);
      else
        pay_line15_energy(gain);
      // what the kinetic energy could not pay stays owed, against the next drops and motion
      if (switches_.line15_carry_debt && switches_.line15_energy != Line15Energy::per_step)
        line15_credit_ += std::max(0.0, gain - (kinetic_before - particle_kinetic_energy()));
      account(frame_ledger_.density_projection, [&] { return particle_kinetic_energy(); });
    }
  }
}

template <int Dim>
double Simulation<Dim>::limit_line15_lift(const std::vector<Vec<Dim>>& before,
                                          double potential_before) {
  // (departures item 17) line 15's rise dPE = PE(x) - PE(before) with the account's credit c
  // (<= 0 banked, > 0 owed) costs dPE + c; the kinetic energy can pay KE_rel of it. The
  // potential energy is linear in the positions, so the moves scaled by
  //   s = (KE_rel - c) / dPE   (clamped to [0, 1])
  // raise it by exactly what can be paid: x <- before + s (x - before).
  const double potential = liquid_potential_energy();
  if (before.size() != particles_.size()) return potential;
  const double rise = gravity_along_periodic_axis() ? line15_potential_change(before)
                                                    : potential - potential_before;
  if (!(rise > 0.0)) return potential;
  const double s = line15_lift_scale(rise, line15_credit_, relative_motion().kinetic);
  if (s == 1.0) return potential;
  const long np = static_cast<long>(particles_.size());
  // (a move across a periodic face is scaled as the short step it was and wrapped again; scaling
  // the difference of the wrapped positions put such a particle most of the domain away)
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (long p = 0; p < np; ++p) {
    const Vec<Dim> x = before[p] + s * line15_move(before[p], particles_.x[p]);
    bool outside = false;
    for (int a = 0; a < Dim; ++a)
      outside = outside || (grid_.periodic(a) &&
                            (x[a] < grid_.origin()[a] ||
                             x[a] >= grid_.origin()[a] + grid_.cells()[a] * grid_.dx()));
    particles_.x[p] = outside ? grid_.wrap_position(x) : x;
  }
  account(frame_ledger_.density_projection, [&] { return liquid_potential_energy(); });
  return liquid_potential_energy();
}

template <int Dim>
Vec<Dim> Simulation<Dim>::line15_move(const Vec<Dim>& from, const Vec<Dim>& to) const {
  Vec<Dim> period = Vec<Dim>::Zero();
  for (int a = 0; a < Dim; ++a)
    if (grid_.periodic(a)) period[a] = grid_.cells()[a] * grid_.dx();
  const Vec<Dim> d = to - from;
  return d - periodic_image_shift<Dim>(d, period);
}

template <int Dim>
bool Simulation<Dim>::gravity_along_periodic_axis() const {
  for (int a = 0; a < Dim; ++a)
    if (grid_.periodic(a) && gravity_[a] != 0.0) return true;
  return false;
}

template <int Dim>
double Simulation<Dim>::line15_potential_change(const std::vector<Vec<Dim>>& before) const {
  double change = 0.0;
  for (std::size_t p = 0; p < particles_.size(); ++p)
    change -= particles_.mass[p] * gravity_.dot(line15_move(before[p], particles_.x[p]));
  return change;
}

template <int Dim>
typename Simulation<Dim>::RelativeMotion Simulation<Dim>::relative_motion() const {
  const long np = static_cast<long>(particles_.size());
  double mass = 0.0;
  Vec<Dim> momentum = Vec<Dim>::Zero();
  for (long p = 0; p < np; ++p) {
    mass += particles_.mass[p];
    momentum += particles_.mass[p] * particles_.v[p];
  }
  RelativeMotion motion;
  if (!(mass > 0.0)) return motion;
  motion.has_mass = true;
  motion.mean = momentum / mass;
  for (long p = 0; p < np; ++p)
    motion.kinetic += 0.5 * particles_.mass[p] * (particles_.v[p] - motion.mean).squaredNorm();
  return motion;
}

template <int Dim>
void Simulation<Dim>::pay_line15_energy(double gain) {
  // The moves of line 15 are not the flow's: they correct the particles' spacing and volume, and
  // lifting particle volume into the surface (the density projection's corrections of a surface
  // band the flow disordered or spread) raises the potential energy by what no force paid for.
  // Here the kinetic energy pays it: the liquid's velocities relative to their mass-weighted mean
  // vbar are scaled (the affine parts with them, so the next transfer's face momenta scale alike)
  //   v_p <- vbar + s (v_p - vbar),   c_p <- s c_p,   s = sqrt(max(0, 1 - dPE / KE_rel)),
  //   KE_rel = sum_p 1/2 m_p |v_p - vbar|^2,
  // which lowers the kinetic energy by dPE (by all of KE_rel if it holds less) and keeps the
  // liquid's momentum: a liquid in uniform motion (free fall) has nothing to pay with and keeps
  // its motion exactly (scaling v itself slowed a falling blob against the body it carried,
  // test_coupled_validation's Fig. 8 free fall; slosh11). A drop of the potential energy is not
  // given back (line 15 may lose energy, never create it).
  if (!(gain > 0.0)) return;
  const RelativeMotion motion = relative_motion();
  if (!motion.has_mass) return;
  const Vec<Dim>& mean = motion.mean;
  const double relative = motion.kinetic;
  if (!(relative > 0.0)) return;
  const long np = static_cast<long>(particles_.size());
  const double s = std::sqrt(std::max(0.0, 1.0 - gain / relative));
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (long p = 0; p < np; ++p) {
    particles_.v[p] = mean + s * (particles_.v[p] - mean);
    particles_.c[p] *= s;
  }
  // the next step's first half drift reads u_ (the velocity the particles were given)
  if (split_drift()) {
    rescale_face_velocity(mean, s);
    // (a deeper extrapolation for that drift is scaled alike: extend_extrapolation(true))
    if (drift_guard_) drift_rescales_.emplace_back(mean, s);
  }
}

template <int Dim>
void Simulation<Dim>::rescale_face_velocity(const Vec<Dim>& mean, double s) {
  const int nf = grid_.num_faces();
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (int f = 0; f < nf; ++f) {
    const auto [axis, fc] = grid_.face_coord(f);
    // (the domain's walls keep their zero)
    if (!grid_.is_boundary_face(axis, fc)) u_[f] = mean[axis] + s * (u_[f] - mean[axis]);
  }
  // the walls beside air hold air velocities (apply_wall_and_solid_velocities): scaled alike
  for (const int f : air_walls_) {
    const int axis = grid_.face_coord(f).first;
    u_[f] = mean[axis] + s * (u_[f] - mean[axis]);
  }
}

namespace {

/// out_c = sum of in over the cells within `reach` cells of c along every axis (a box of
/// (2 reach + 1)^Dim cells, wrapped on periodic axes, cut at the walls): one pass per axis, each
/// output summed in a fixed order (the same bits for any thread count)
template <int Dim>
std::vector<double> box_sum(const MacGrid<Dim>& grid, std::vector<double> in, int reach) {
  const int nc = grid.num_cells();
  std::vector<double> out(nc);
  for (int a = 0; a < Dim; ++a) {
#pragma omp parallel for schedule(static) num_threads(process_threads())
    for (int c = 0; c < nc; ++c) {
      const VecI<Dim> cc = grid.cell_coord(c);
      double sum = 0.0;
      for (int k = -reach; k <= reach; ++k) {
        VecI<Dim> n = cc;
        n[a] += k;
        const int i = grid.cell_index_or_outside(n);
        if (i >= 0) sum += in[i];
      }
      out[c] = sum;
    }
    in.swap(out);
  }
  return in;
}

}  // namespace

template <int Dim>
void Simulation<Dim>::pay_line15_energy_locally(double gain, const std::vector<Vec<Dim>>& before) {
  // balance's amount, paid where line 15 lifted the liquid. Per cell (of a particle's position
  // after the moves): G_c = its particles' potential energy change -m g . (x' - x), K_c = their
  // kinetic energy. Over the neighbourhoods N(c) of (2 R + 1)^Dim cells (R = std::max(0, switches_.line15_pay_reach)):
  //   D_c = a max(0, sum_N(c) G),  a = gain / sum_c max(0, sum_N(c) G)     (a <= 1: gain is at
  //         most the net rise, which is at most the sum of the positive parts)
  //   f_p = min(1, sum_{c : p in N(c)} D_c / sum_N(c) K)
  // and particle p keeps sqrt(1 - f_p) of its v and c, so each cell's share D_c is taken from the
  // kinetic energy of the particles around it in proportion to theirs. A share whose
  // neighbourhood holds no kinetic energy (or more than it holds) is paid by the uniform scaling
  // (pay_line15_energy) from what is left.
  if (!(gain > 0.0)) return;
  const int nc = grid_.num_cells();
  const long np = static_cast<long>(particles_.size());
  std::vector<int> cell(np);
  std::vector<double> rise(nc, 0.0), kinetic(nc, 0.0);
  for (long p = 0; p < np; ++p) {
    cell[p] = grid_.cell_index(grid_.cell_containing(particles_.x[p]));
    rise[cell[p]] -= particles_.mass[p] * gravity_.dot(particles_.x[p] - before[p]);
    kinetic[cell[p]] += 0.5 * particles_.mass[p] * particles_.v[p].squaredNorm();
  }
  std::vector<double> near_rise = box_sum(grid_, std::move(rise), std::max(0, switches_.line15_pay_reach));
  const std::vector<double> near_kinetic = box_sum(grid_, std::move(kinetic), std::max(0, switches_.line15_pay_reach));
  double positive = 0.0;
  for (int c = 0; c < nc; ++c) positive += std::max(0.0, near_rise[c]);
  if (!(positive > 0.0)) {
    pay_line15_energy(gain);
    return;
  }
  const double share = std::min(1.0, gain / positive);
  // near_rise becomes each cell's demand per joule of its neighbourhood's kinetic energy
  for (int c = 0; c < nc; ++c) {
    const double demand = share * std::max(0.0, near_rise[c]);
    near_rise[c] = demand > 0.0 && near_kinetic[c] > 0.0 ? demand / near_kinetic[c] : 0.0;
  }
  const std::vector<double> fraction = box_sum(grid_, std::move(near_rise), std::max(0, switches_.line15_pay_reach));
  double paid = 0.0;
  for (long p = 0; p < np; ++p) {
    const double f = std::min(1.0, fraction[cell[p]]);
    if (!(f > 0.0)) continue;
    paid += f * 0.5 * particles_.mass[p] * particles_.v[p].squaredNorm();
    const double s = std::sqrt(1.0 - f);
    particles_.v[p] *= s;
    particles_.c[p] *= s;
  }
  // the next step's first half drift reads u_: each face scaled by the mean of its cells' factors
  if (split_drift()) {
    const int nf = grid_.num_faces();
#pragma omp parallel for schedule(static) num_threads(process_threads())
    for (int f = 0; f < nf; ++f) {
      const auto [axis, fc] = grid_.face_coord(f);
      double sum = 0.0;
      int count = 0;
      for (int i : {grid_.face_cell_minus(axis, fc), grid_.face_cell_plus(axis, fc)})
        if (i >= 0) {
          sum += std::sqrt(1.0 - std::min(1.0, fraction[i]));
          ++count;
        }
      if (count > 0) u_[f] *= sum / count;
    }
  }
  if (gain - paid > 0.0) pay_line15_energy(gain - paid);
}

template <int Dim>
VectorX Simulation<Dim>::volume_source(double dt) const {
  // d_c = gain e_c / dt: a cell short of particle volume by e_c (in cell volumes) converges by
  // that much in the step (the solve's constraint with a target divergence, add_divergence_source)
  if (volume_errors_.empty() || !(switches_.volume_source_gain > 0.0) || !(dt > 0.0))
    return VectorX();
  VectorX d = VectorX::Zero(grid_.num_cells());
  for (const auto& [c, e] : volume_errors_) d[c] = switches_.volume_source_gain * e / dt;
  return d;
}

template <int Dim>
void Simulation<Dim>::update_moving_solids() {
  ScopedTimer timer(stats_.timing[FramePhase::weights]);
  // every body is a coupling body (fixed ones one-way at zero velocity), so the weights are
  // indexed like the bodies of the contact system; the static shapes are those fixed bodies
  // into the coupled solve's input, whose buffers live across steps; fixed bodies (static
  // solids) are sampled once and kept
  SolidWeights<Dim>& solids = coupled_in_.solids;
  if (solid_scratch_.fixed.empty())
    for (const auto& b : rigid_->bodies()) solid_scratch_.fixed.push_back(!b.moves());
  solid_scratch_.parts = false;  // W_S^u and its static share: read by nothing here
  // W_F^s only where a solve reads it: without stress solves (and no export of this step's
  // system) solve_coupled passes inviscid weights (lean_coupled_weights), so it is not made
  solid_scratch_.stress = !lean_coupled_weights();
  // the union kept per body where solid_weights can (Fig. 17: the basin's kept phi, the shells'
  // values in their boxes), read below and by update_liquid_weights through solid_phi_at and
  // solid_negative_at; solids.lattice_phi's lent buffer is then left unwritten
  solid_scratch_.union_in_parts = true;
  // the union's level set is written into solid_phi_'s buffer (lent to solids for the call:
  // solid_weights overwrites every entry, and nothing reads solids.lattice_phi after it), so
  // one lattice-sized vector serves both
  // When the union's last buffer is gone (update_liquid_weights releases it), nothing is lent:
  // the liquid level set is stored over its band (band19), not in a lattice-sized buffer, and
  // solid_weights leaves the lent buffer unwritten when it keeps the union per body (it sizes
  // it itself otherwise)
  solids.lattice_phi.swap(solid_phi_);
  // W_F^u likewise: weights_.fluid_face's buffer is lent as the output (solid_weights overwrites
  // every entry) and comes back below, so one face-sized vector holds it (solids.fluid_face is
  // left empty: read by nothing after this)
  solids.fluid_face.swap(weights_.fluid_face);
  weights_.fluid_face = VectorX();
  const std::vector<CouplingBody<Dim>> bodies = coupling_bodies(rigid_->bodies());
  const double shrink = scene_.solver.shrink * grid_.dx();
  solid_weights<Dim>(grid_, bodies, {}, boundary_, shrink, solids, solid_scratch_);
  solid_phi_.swap(solids.lattice_phi);
  // its negative points lie in the box of its non-positive lattice cells (of the union's classes)
  if (solid_scratch_.signs.any_negative()) {
    solid_lo_ = solid_scratch_.signs.lo;
    solid_hi_ = solid_scratch_.signs.hi + VecI<Dim>::Ones();
  } else {
    solid_lo_ = VecI<Dim>::Zero();
    solid_hi_ = -VecI<Dim>::Ones();
  }
  // W_F^u goes back to weights_ (in the solve: in.weights.pressure.fluid_face);
  // coupled_in_.solids.fluid_face stays empty. W_F^s stays in solids, where solve_coupled reads it
  // (stress_fluid_ is the uncoupled solve's: freed here)
  weights_.fluid_face.swap(solids.fluid_face);
  solids.fluid_face = VectorX();
  solid_box_phi_.clear();
  find_faces_in_solids();
  // The union is read from here on only by update_liquid_weights, which follows: in the box of
  // the bodies (their bounds grown by 2 dx, where solid_weights evaluates them) it is kept, and
  // outside it is the closed form solid_weights wrote there (BoxedUnionPhi: the same bits). The
  // lattice-sized buffer goes back to the heap (it went to the liquid level set, which is now
  // stored over its band: band19)
  if (solid_scratch_.union_parts.valid()) {
    // the union is kept per body: the lent buffer (unwritten) is not needed
    solid_phi_ = VectorX();
  } else {
    std::vector<Box<Dim>> bounds;
    for (const CouplingBody<Dim>& b : bodies) bounds.push_back(b.shape->bounds());
    if (solid_box_phi_.assign(lattice_, bounds, 2.0 * grid_.dx(), shrink, solid_phi_))
      solid_phi_ = VectorX();
  }
  stress_fluid_ = VectorX();
  // (without stress solves W_F^s was not made: solids.fluid_stress is empty, see above)
  rebuild_solid_field();
}

template <int Dim>
std::vector<Box<Dim>> Simulation<Dim>::body_bounds() const {
  std::vector<Box<Dim>> bounds;
  if (!rigid_) return bounds;
  for (const auto& b : rigid_->bodies()) bounds.push_back(b.bounds());
  return bounds;
}

template <int Dim>
Vec<Dim> Simulation<Dim>::solid_velocity(const Vec<Dim>& x, const std::vector<Box<Dim>>& bounds) const {
  if (!rigid_) return Vec<Dim>::Zero();
  const auto& bodies = rigid_->bodies();
  // a point outside a body's bounds is not inside it (and only inside points matter here)
  const auto outside = [&](std::size_t i) {
    const Box<Dim>& box = bounds[i];
    return box.min().allFinite() && box.max().allFinite() &&
           ((x.array() < box.min().array()).any() || (x.array() > box.max().array()).any());
  };
  // outside every moving body's bounds the answer is zero whatever is nearest (a fixed body, a
  // static solid or none): no distance is evaluated (the faces in a large static solid, most of
  // the faces this is asked for in Fig. 17's basin, evaluated every shape at every face)
  bool near_moving = false;
  for (std::size_t i = 0; i < bodies.size() && !near_moving; ++i)
    near_moving = bodies[i].moves() && !outside(i);
  if (!near_moving) return Vec<Dim>::Zero();
  double best = std::numeric_limits<double>::infinity();
  int which = -1;
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    if (outside(i)) continue;
    const double d = bodies[i].distance(x);
    if (d < best) {
      best = d;
      which = static_cast<int>(i);
    }
  }
  for (const auto& s : solid_shapes_)
    if (s->distance(x) < best) return Vec<Dim>::Zero();
  if (which < 0 || !bodies[which].moves()) return Vec<Dim>::Zero();
  return bodies[which].point_velocity(x);
}

template <int Dim>
void Simulation<Dim>::solve_coupled(double dt) {
  // the input lives across steps (its vectors are overwritten, not allocated); in.solids is
  // the last update_moving_solids'
  CoupledStepInput<Dim>& in = coupled_in_;
  in.grid = grid_;
  in.dt = dt;
  in.bodies = rigid_->bodies();
  // (6) contacts at the step's start pose, with the pair's friction and restitution
  RigidStepStats contact_stats;
  in.contacts = rigid_->find_contacts(dt, contact_stats);
  in.contact_params = rigid_->contact_parameters(dt, gravity_);
  stats_.contact_count = std::max(stats_.contact_count, contact_stats.contacts);
  stats_.max_penetration = std::max(stats_.max_penetration, contact_stats.max_penetration);
  // the weights of eq. (24): W_F from the bodies' pose, W_L from the liquid; the P.. C schemes
  // and inviscid liquids have no stress unknowns (eta = 0 leaves every stress DOF inactive).
  // The grid-sized vectors are swapped into the input for the solve and back after it (copies
  // of them were 1.2 GB at the paper's 256x128x256 grid); the zero vectors of the P.. C
  // schemes are made once and stay zero (the solve reads its input only)
  //
  // Without stress solves the weights are inviscid ones without stress vectors
  // (StokesWeights::inviscid; lean_coupled_weights), except for a step whose system goes to the
  // oracle's export, which reads them all.
  //
  // u* is lent as well: u_'s storage becomes in.u_star for the solve, and the solve writes the
  // new u into the storage of the previous step's u* (coupled_out_.u, given the storage that
  // in.u_star held), so two face-sized velocity vectors live across steps instead of three.
  // Nothing reads u_ during the solve; if the solve throws, u* goes back into u_.
  const bool stress = sequence_ != SolveSequence::pressure;
  const bool lean = lean_coupled_weights();
  auto lend = [&] {
    std::swap(in.weights.pressure, weights_);
    if (!lean) in.weights.fluid_stress.swap(in.solids.fluid_stress);
    if (stress) {
      in.weights.liquid_stress.swap(stress_liquid_);
      in.weights.viscosity.swap(stress_eta_);
    }
  };
  if (lean) {
    in.weights.fluid_stress = VectorX();
    in.weights.liquid_stress = VectorX();
    in.weights.viscosity = VectorX();
  } else if (!stress && in.weights.viscosity.size() != stress_grid_.num_dofs()) {
    in.weights.liquid_stress.setZero(stress_grid_.num_dofs());
    in.weights.viscosity.setZero(stress_grid_.num_dofs());
  }
  // The face masses are read by nothing after the step's gravity and extrapolation (the faces
  // that carry mass are kept as flags, mass_faces_) unless the energy ledger measures the grid's
  // kinetic energy: then the new u goes into their storage, and they take the storage of u*
  // after the solve (their values stale until the next particles_to_grid): u_, face_mass_, u*
  // and the new u share two face-sized vectors. The pressure likewise: nothing reads pressure_
  // during the coupled solve, so the new pressure is written into its storage.
  in.u_star.swap(u_);
  const bool masses_free = !masses_read_after_solve();
  coupled_out_.u.swap(masses_free ? face_mass_ : u_);
  coupled_out_.pressure.swap(pressure_);
  struct GiveBackVelocity {
    VectorX& u;
    VectorX& u_star;
    ~GiveBackVelocity() {
      if (u.size() == 0) u.swap(u_star);
    }
  } give_back_velocity{u_, in.u_star};
  lend();
  struct GiveBack {
    std::function<void()> f;
    ~GiveBack() { f(); }
  } give_back{lend};
  // departures item 24: the liquid part of solid-cut faces tied to the solid (before the
  // Herschel-Bulkley model copies W_F^s; put back after the solve, before the weights are given
  // back)
  RaisedStressWeights raised;
  if (stress && !lean)
    raise_cut_face_stress<Dim>(stress_grid_, in.weights.pressure.fluid_face,
                               in.weights.pressure.liquid_face, in.weights.liquid_stress,
                               in.weights.fluid_stress, raised);
  // (7)-(11) the scheme's solves (section 6)
  StaggeredSettings ss;
  ss.max_iterations = std::max(1, scene_.solver.staggered_iterations);
  ss.tolerance = scene_.solver.tolerance;
  ss.diagonal_boost = scene_.solver.diagonal_boost;
  ss.mprgp.tolerance = scene_.solver.tolerance;
  ss.mprgp.max_iterations = scene_.solver.max_iterations;
  // non-Newtonian liquids: Algorithm 2 alongside the scheme's staggered rounds (section 5)
  CoupledSchemeOptions options;
  // the preconditioners: solver.preconditioner ("auto": by the system's stiffness, the rule of
  // the liquid-only solves, with the smallest liquid density) and pressure_preconditioner
  options.preconditioner = scene_.solver.preconditioner;
  options.pressure_preconditioner = scene_.solver.pressure_preconditioner;
  options.liquid_density = smallest_liquid_density();
  std::unique_ptr<NonNewtonianViscosity<Dim>> model;
  VectorX eta;
  if (non_newtonian_ && stress) {
    model = std::make_unique<NonNewtonianViscosity<Dim>>(
        stress_grid_, deformation_rate_, in.weights.fluid_stress, in.weights.liquid_stress,
        mixture_);
    options.initial_viscosity = [&](const VectorX& u_star) {
      eta = model->initial_viscosity(in.weights.pressure.fluid_face, u_star, previous_shear_rate_);
      return eta;
    };
    options.update_viscosity = [&](const VectorX& tau, const VectorX& used) {
      eta = model->update(tau, used);
      return eta;
    };
  }
  // the oracle: this step's system to the requested sink (request_system_export)
  if (export_sink_ && stats_.steps + 1 == export_step_) options.export_sink = export_sink_;
  CoupledSolveResult& r = coupled_out_;
  // the volume correction's divergence source (empty: none; StageSwitches::volume_source_gain)
  const VectorX source = volume_source(dt);
  in.divergence_source = source.size() > 0 ? &source : nullptr;
  in.workspace = stokes_workspace_for(in.weights.pressure, in.u_star);
  // (band23) the pressure's storage is written in its DOFs' cells only (pressure_cells_)
  if (!switches_.restricted_passes) pressure_cells_.forget();
  in.pressure_cells = switches_.restricted_passes ? &pressure_cells_ : nullptr;
  solve_coupled_step<Dim>(in, scene_.solver.scheme, scene_.solver.backend, ss, options, r);
  in.divergence_source = nullptr;
  in.workspace = nullptr;
  in.pressure_cells = nullptr;
  // (a non-Newtonian solve's eta per cell; otherwise eta per cell stays as the weights left it,
  // made or pending: band20)
  if (eta.size() == stress_grid_.num_dofs()) {
    cell_eta_ = eta.segment(stress_grid_.offset(0), grid_.num_cells());
    cell_eta_pending_ = false;
  }
  if (model) {
    record_viscosity_rounds(model->residuals());
    if (scene_.solver.viscosity_warm_start) previous_shear_rate_ = model->previous_shear_rate();
  }
  u_.swap(r.u);
  if (masses_free) face_mass_.swap(in.u_star);
  pressure_.swap(r.pressure);
  stress_.swap(r.stress);
  // (12) the bodies' velocities (eq. (21))
  rigid_->set_velocities(r.body_velocity, r.body_dof);
  StaggeredResult kept;
  kept.lambda = r.lambda;
  kept.z = r.z;
  rigid_->remember(std::move(in.contacts), kept);
  // statistics: the phases of the paper's Tables 1-3
  SolverStats& st = stats_.solver;
  st.add_solve(r.fluid_iterations + r.contact_iterations + r.coupled_iterations,
               r.staggered_iterations, r.max_relative_residual, r.converged);
  if (!r.rounds_settled) ++st.unsettled_steps;
  st.add_dofs(r.pressure_dofs, r.stress_dofs, r.contact_dofs, r.friction_dofs);
  st.fluid_iterations += r.fluid_iterations;
  st.contact_iterations += r.contact_iterations;
  st.coupled_iterations += r.coupled_iterations;
  st.fluid_seconds += r.fluid_seconds;
  st.contact_seconds += r.contact_seconds;
  st.coupled_seconds += r.coupled_seconds;
  // the coupled systems with stress unknowns that took the block preconditioner, booked as the
  // liquid-only unified solves are (those on SSOR are not booked: a coupled scene on SSOR keeps
  // the stats rows of the paper's baseline exactly)
  for (long k = 0; k < r.multigrid_systems; ++k)
    st.add_stokes_preconditioner(PreconditionerKind::multigrid, r.max_stiffness);
  st.preconditioner_fallbacks += r.fallbacks;
  if (!r.converged)
    note_unconverged("coupled " + enum_name(scene_.solver.scheme),
                     r.fluid_iterations + r.contact_iterations + r.coupled_iterations,
                     r.max_relative_residual);
}

template <int Dim>
StokesWorkspace* Simulation<Dim>::stokes_workspace_for(const PressureWeights& w,
                                                       const VectorX& u_start) {
  stokes_workspace_.keep = switches_.kept_solve_storage;
  if (!stokes_workspace_.keep) {
    // (the storage a kept run left goes back to the heap)
    const LiquidBand band = stokes_workspace_.band;
    stokes_workspace_ = StokesWorkspace();
    stokes_workspace_.band = band;
    stokes_workspace_.keep = false;
  }
  LiquidBand& band = stokes_workspace_.band;
  band.valid = liquid_cell_box_.valid_for(w.liquid_cell.data(), w.liquid_cell.size());
  for (int a = 0; a < Dim; ++a)
    band.valid = band.valid && liquid_face_boxes_[a].valid_for(w.liquid_face.data() + grid_.face_offset(a),
                                                               grid_.face_dims(a).prod());
  if (band.valid) {
    for (int d = 0; d < Dim; ++d) {
      band.cell_lo[d] = liquid_cell_box_.lo[d];
      band.cell_hi[d] = liquid_cell_box_.hi[d];
      for (int a = 0; a < Dim; ++a) {
        band.face_lo[a][d] = liquid_face_boxes_[a].lo[d];
        band.face_hi[a][d] = liquid_face_boxes_[a].hi[d];
      }
    }
  }
  // The speed boxes (band18): u* is +-0 outside the boxes of the faces with mass grown by the
  // air extrapolation's layers. particles_to_grid leaves +0 on every face without mass, which
  // lie outside mass_boxes_ or inside them; gravity and the ballistic faces' PIC values are
  // written on faces with mass only; extrapolate_into_air fills faces from same-axis
  // neighbours, one face per layer along an axis (the whole axis where it wraps). Nothing
  // else writes u between particles_to_grid and the solve. A later solve of the step's
  // sequence starts from an earlier one's velocity, which differs from u* only on faces with
  // W_L^u > 0 (the velocity updates): the band's face boxes, joined in. Not kept when the
  // weights' band is not valid or the faces with mass have no boxes (no promise then).
  band.speed_valid = band.valid && switches_.restricted_passes && mass_boxes_valid_ &&
                     mass_faces_.data() == mass_boxes_data_;
  if (band.speed_valid) {
    const int reach = switches_.air_velocity ? kAirVelocityLayers : 0;
    for (int a = 0; a < Dim; ++a) {
      const VecI<Dim> dims = grid_.face_dims(a);
      const VecI<Dim>& mlo = mass_boxes_.lo[a];
      const VecI<Dim>& mhi = mass_boxes_.hi[a];
      const bool mass_empty = (mlo.array() > mhi.array()).any();
      const WrittenBox<Dim>& lb = liquid_face_boxes_[a];
      const bool liquid_empty = (lb.lo.array() > lb.hi.array()).any();
      for (int d = 0; d < Dim; ++d) {
        int lo = dims[d], hi = -1;  // empty
        if (!mass_empty) {
          lo = grid_.periodic(d) ? 0 : std::max(mlo[d] - reach, 0);
          hi = grid_.periodic(d) ? dims[d] - 1 : std::min(mhi[d] + reach, dims[d] - 1);
        }
        if (!liquid_empty) {
          lo = std::min(lo, lb.lo[d]);
          hi = std::max(hi, lb.hi[d]);
        }
        band.speed_lo[a][d] = lo;
        band.speed_hi[a][d] = hi;
      }
      // (an empty box on one coordinate empties the box: kept as it is, lo > hi there)
    }
  }
  if (speed_box_check_.on) check_speed_boxes(band, u_start);
  return &stokes_workspace_;
}

template <int Dim>
void Simulation<Dim>::check_speed_boxes(const LiquidBand& band, const VectorX& u_start) {
  // (tests) the promise of the speed boxes on this solve's starting velocity, and the faces
  // the boxes leave out
  ++speed_box_check_.solves;
  if (!band.speed_valid || u_start.size() != grid_.num_faces()) return;
  ++speed_box_check_.promised;
  for (int a = 0; a < Dim; ++a) {
    const VecI<Dim> dims = grid_.face_dims(a);
    for (int k = 0; k < dims.prod(); ++k) {
      const VecI<Dim> c = lattice_coord<Dim>(k, dims);
      bool inside = true;
      for (int d = 0; d < Dim; ++d)
        inside = inside && c[d] >= band.speed_lo[a][d] && c[d] <= band.speed_hi[a][d];
      if (inside) continue;
      const int f = grid_.face_index(a, c);
      ++speed_box_check_.left_out;
      if (u_start[f] != 0.0) ++speed_box_check_.nonzero_outside;
    }
  }
}

template <int Dim>
double Simulation<Dim>::smallest_liquid_density() const {
  double rho = std::numeric_limits<double>::infinity();
  for (const LiquidSpec& l : scene_.liquids) rho = std::min(rho, l.density);
  return std::isfinite(rho) ? rho : 0.0;
}

template <int Dim>
StokesSolveOptions Simulation<Dim>::stokes_options(const VectorX& eta, double dt) {
  // the stiffness with the smallest liquid density (the largest stiffness of the scene's liquids)
  const double rho = smallest_liquid_density();
  const double eta_max = eta.size() > 0 ? std::max(0.0, eta.maxCoeff()) : 0.0;
  const double stiffness = rho > 0.0 ? solve_stiffness(eta_max, dt, rho, grid_.dx()) : 0.0;
  StokesSolveOptions o;
  o.preconditioner =
      choose_preconditioner(scene_.solver.preconditioner, Dim, stiffness, grid_.cells().maxCoeff());
  o.fallback_to_ssor = scene_.solver.preconditioner == PreconditionerChoice::automatic;
  stats_.solver.add_stokes_preconditioner(o.preconditioner, stiffness);
  if (o.preconditioner != PreconditionerKind::ssor && scene_.solver.stokes_warm_start) {
    o.initial_stress = &stress_;
    o.initial_pressure = &pressure_;
  }
  return o;
}

template <int Dim>
void Simulation<Dim>::solve_liquid(double dt) {
  // the state between the solves of the sequence (solve_stokes / solve_pressure update u)
  struct State {
    VectorX u, pressure, stress;
  };
  const Backend backend = scene_.solver.backend;
  // the volume correction's divergence source (empty: none; StageSwitches::volume_source_gain)
  const VectorX source = volume_source(dt);
  // eq. (8) without stress
  // the weights of the solves: the simulation's own vectors, lent to w for the sequence below
  // and given back after it (also when a solve throws), instead of copies of four face-, one
  // cell- and two stress-sized vectors per step (a viscous 128^3 scene: about 0.4 GB alive
  // during the solves). Every stage reads them from w.
  StokesWeights w;
  auto pressure = [&](const State& from, SolveStage stage) {
    State out = from;
    const PressureSolveResult solve =
        solve_pressure(grid_, w.pressure, dt, backend, pcg_settings_, out.u,
                       scene_.solver.pressure_preconditioner, &source);
    record_solve(solve.pcg, solve.dofs, 0, solve_stage_name(stage));
    out.pressure = solve.pressure;
    return out;
  };
  // PVC without bodies: eq. (8) in (tau, p) at once, reduced stress (section 4.4.2)
  auto unified = [&](const State& from, const VectorX* eta) {
    w.viscosity = eta ? *eta : stress_eta_;
    State out = from;
    StokesSolveOptions options = stokes_options(w.viscosity, dt);
    options.divergence_source = &source;
    options.workspace = stokes_workspace_for(w.pressure, out.u);
    const StokesSolveResult solve =
        solve_stokes(grid_, w, dt, StokesUnknowns::pressure_and_stress, StressForm::reduced,
                     backend, pcg_settings_, out.u, options);
    record_solve(solve.pcg, solve.pressure_dofs, solve.stress_dofs, "Stokes");
    if (solve.fell_back) ++stats_.solver.preconditioner_fallbacks;
    out.pressure = solve.pressure;
    out.stress = solve.stress;
    return out;
  };
  // the VC solve of PC-VC-PC: stress unknowns only (p = 0; the full form, since the trace
  // vanishes only together with the pressure)
  auto viscous = [&](const State& from, const VectorX* eta) {
    w.viscosity = eta ? *eta : stress_eta_;
    State out = from;
    StokesSolveOptions options = stokes_options(w.viscosity, dt);
    options.workspace = stokes_workspace_for(w.pressure, out.u);
    const StokesSolveResult solve = solve_stokes(grid_, w, dt, StokesUnknowns::stress_only,
                                                 StressForm::full, backend, pcg_settings_, out.u,
                                                 options);
    record_solve(solve.pcg, 0, solve.stress_dofs, "viscosity");
    if (solve.fell_back) ++stats_.solver.preconditioner_fallbacks;
    out.stress = solve.stress;
    return out;
  };
  // herschel-bulkley liquids: Algorithm 2 around the viscous solve (section 5), started from the
  // previous step's shear rate where there is one (departure from line 1, docs/non-newtonian.md)
  ViscosityRounds viscosity;
  // departures item 24: the liquid part of solid-cut faces tied to the solid, in W_F^s itself
  // (before the Herschel-Bulkley model copies it and the weights are lent below; put back when
  // this function returns, after they are given back)
  RaisedStressWeights raised;
  if (sequence_ != SolveSequence::pressure)
    raise_cut_face_stress<Dim>(stress_grid_, weights_.fluid_face, weights_.liquid_face,
                               stress_liquid_, stress_fluid_, raised);
  std::unique_ptr<NonNewtonianViscosity<Dim>> model;
  VectorX eta;
  if (non_newtonian_ && sequence_ != SolveSequence::pressure) {
    model = std::make_unique<NonNewtonianViscosity<Dim>>(non_newtonian_model());
    viscosity.rounds = std::max(1, scene_.solver.staggered_iterations);
    viscosity.initial = [&](const VectorX& u) {
      return model->initial_viscosity(w.pressure.fluid_face, u, previous_shear_rate_);
    };
    viscosity.update = [&](const VectorX& tau, const VectorX& used) {
      eta = model->update(tau, used);
      return eta;
    };
  }
  // (the model above copied W_F^s and W_L^s before they are lent)
  struct Lend {
    Simulation& sim;
    StokesWeights& w;
    bool lent = false;
    void swap() {
      std::swap(w.pressure, sim.weights_);
      w.fluid_stress.swap(sim.stress_fluid_);
      w.liquid_stress.swap(sim.stress_liquid_);
      lent = !lent;
    }
    ~Lend() {
      if (lent) swap();
    }
  } lend{*this, w};
  lend.swap();
  const State end = run_solve_sequence(sequence_, State{u_, pressure_, stress_}, viscosity,
                                       pressure, unified, viscous);
  lend.swap();
  u_ = end.u;
  pressure_ = end.pressure;
  pressure_cells_.forget();  // (written whole)
  stress_ = end.stress;
  if (!model) return;
  // the effective viscosity of the step's flow on its cell-centred DOFs (component 0)
  cell_eta_ = eta.segment(stress_grid_.offset(0), grid_.num_cells());
  cell_eta_pending_ = false;
  record_viscosity_rounds(model->residuals());
  if (scene_.solver.viscosity_warm_start) previous_shear_rate_ = model->previous_shear_rate();
}

template <int Dim>
NonNewtonianViscosity<Dim> Simulation<Dim>::non_newtonian_model() const {
  return NonNewtonianViscosity<Dim>(stress_grid_, deformation_rate_, stress_fluid_, stress_liquid_,
                                    mixture_);
}

template <int Dim>
void Simulation<Dim>::record_viscosity_rounds(const std::vector<double>& residuals) {
  if (residuals.empty()) return;
  stats_.solver.viscosity_residuals = residuals;
  stats_.solver.max_viscosity_residual =
      std::max(stats_.solver.max_viscosity_residual, residuals.back());
}

template <int Dim>
void Simulation<Dim>::record_solve(const PcgResult& pcg, long pressure_dofs, long stress_dofs,
                                   const char* what) {
  if (pcg.breakdown) {
    std::ostringstream msg;
    msg << "t = " << time_ << " s: " << what << " solver broke down: " << pcg.message;
    throw SimulationError(msg.str());
  }
  stats_.solver.add_solve(pcg.iterations, 1, pcg.relative_residual, pcg.converged);
  stats_.solver.add_dofs(pressure_dofs, stress_dofs, 0, 0);
  stats_.solver.fluid_iterations += pcg.iterations;
  if (!pcg.converged) note_unconverged(what, pcg.iterations, pcg.relative_residual);
}

template <int Dim>
void Simulation<Dim>::note_unconverged(const std::string& what, long iterations, double residual) {
  stats_.solver.converged = false;
  stats_.solver.unconverged.push_back({what, time_, iterations, residual});
}

template <int Dim>
template <class Test>
void Simulation<Dim>::faces_with_centre(int axis, const VecI<Dim>& point_lo,
                                        const VecI<Dim>& point_hi, const Test& test,
                                        std::vector<int>& faces) const {
  // the centre of face (axis, coord) is lattice point 2 coord + 1 - e_axis of the half lattice,
  // so only the faces of the box of the points [point_lo, point_hi] are tested (a loose range;
  // the test decides), in face order
  if ((point_lo.array() > point_hi.array()).any()) return;
  const VecI<Dim> fdims = grid_.face_dims(axis);
  VecI<Dim> lo, hi;
  for (int a = 0; a < Dim; ++a) {
    lo[a] = std::max(point_lo[a] / 2 - 1, 0);
    hi[a] = std::min(point_hi[a] / 2 + 1, fdims[a] - 1);
  }
  if ((lo.array() > hi.array()).any()) return;
  const VecI<Dim> box = hi - lo + VecI<Dim>::Ones();
  for (int j = 0; j < box.prod(); ++j) {
    const VecI<Dim> coord = lo + lattice_coord<Dim>(j, box);
    VecI<Dim> k = 2 * coord + VecI<Dim>::Ones();
    k[axis] -= 1;
    if (k[axis] >= lattice_.dims[axis]) k[axis] = 0;  // periodic seam
    if (test(k, lattice_.index(k))) faces.push_back(grid_.face_index(axis, coord));
  }
}

template <int Dim>
void Simulation<Dim>::find_faces_in_solids() {
  // the faces whose centre lies in a solid, axis by axis in face order
  std::vector<int>& faces = solid_faces_;
  faces.clear();
  solid_face_fixed_.clear();
  const PartsUnionPhi<Dim>& parts = solid_scratch_.union_parts;
  if (parts.valid() && switches_.restricted_passes) {
    // The union kept per body (Fig. 17): the faces in the fixed bodies (dense parts) are found
    // once and kept while those parts are the same; each step searches only the moving bodies'
    // boxes of negative points for faces in them and in no fixed body. A face is in the union
    // iff it is in a fixed body or (not, and) in a moving one: the same faces, merged per axis
    // into the same increasing order as one search of the union's box
    std::vector<std::pair<const VectorX*, std::pair<VecI<Dim>, VecI<Dim>>>> key;
    VecI<Dim> dense_lo = lattice_.dims, dense_hi = -VecI<Dim>::Ones();
    for (int i = 0; i < parts.num_parts(); ++i) {
      if (!parts.is_dense(i)) continue;
      VecI<Dim> lo, hi;
      parts.part_negative_box(i, lo, hi);
      key.push_back({parts.dense_phi(i), {lo, hi}});
      if ((lo.array() > hi.array()).any()) continue;
      dense_lo = dense_lo.cwiseMin(lo);
      dense_hi = dense_hi.cwiseMax(hi);
    }
    if (!fixed_faces_valid_ || key != fixed_faces_key_) {
      fixed_faces_key_ = key;
      fixed_faces_valid_ = true;
      fixed_face_frame_.clear();
      fixed_face_deep_.clear();
      for (int axis = 0; axis < Dim; ++axis) {
        fixed_faces_[axis].clear();
        faces_with_centre(axis, dense_lo, dense_hi,
                          [&](const VecI<Dim>&, int k) { return parts.dense_negative(k); },
                          fixed_faces_[axis]);
      }
    }
    int fixed_offset = 0;
    std::vector<int>& moving = moving_faces_scratch_;
    for (int axis = 0; axis < Dim; ++axis) {
      moving.clear();
      for (int i = 0; i < parts.num_parts(); ++i) {
        if (parts.is_dense(i)) continue;
        VecI<Dim> lo, hi;
        parts.part_negative_box(i, lo, hi);
        faces_with_centre(axis, lo, hi, [&](const VecI<Dim>& c, int k) {
          return !parts.dense_negative(k) && parts.boxed_negative(c);
        }, moving);
      }
      // (two moving bodies' boxes may share faces)
      std::sort(moving.begin(), moving.end());
      moving.erase(std::unique(moving.begin(), moving.end()), moving.end());
      const std::vector<int>& fixed = fixed_faces_[axis];
      std::size_t a = 0, b = 0;
      while (a < fixed.size() || b < moving.size()) {
        if (b == moving.size() || (a < fixed.size() && fixed[a] < moving[b])) {
          faces.push_back(fixed[a]);
          solid_face_fixed_.push_back(fixed_offset + static_cast<int>(a));
          ++a;
        } else {
          faces.push_back(moving[b++]);
          solid_face_fixed_.push_back(-1);
        }
      }
      fixed_offset += static_cast<int>(fixed.size());
    }
    return;
  }
  fixed_faces_valid_ = false;
  fixed_faces_key_.clear();
  fixed_face_frame_.clear();
  fixed_face_deep_.clear();
  for (auto& list : fixed_faces_) list.clear();
  if ((solid_lo_.array() > solid_hi_.array()).any()) return;  // no lattice point in a solid
  std::array<std::size_t, Dim + 1> axis_start{};
  for (int axis = 0; axis < Dim; ++axis) {
    axis_start[axis] = faces.size();
    faces_with_centre(axis, solid_lo_, solid_hi_,
                      [&](const VecI<Dim>& k, int index) { return solid_negative_at(k, index); },
                      faces);
  }
  axis_start[Dim] = faces.size();
  solid_face_fixed_.assign(faces.size(), -1);
  if (!rigid_ && switches_.restricted_passes) {
    // static solids only (this call is the constructor's, before any body exists): the faces
    // never change, so every one keeps its normal's static share (constrain_velocity_in_solids)
    for (int axis = 0; axis < Dim; ++axis)
      fixed_faces_[axis].assign(faces.begin() + static_cast<long>(axis_start[axis]),
                                faces.begin() + static_cast<long>(axis_start[axis + 1]));
    for (std::size_t j = 0; j < faces.size(); ++j) solid_face_fixed_[j] = static_cast<int>(j);
    fixed_faces_valid_ = true;
    // (a key no union of parts has: a later search of parts finds its own fixed faces)
    fixed_faces_key_.push_back({nullptr, {VecI<Dim>::Zero(), VecI<Dim>::Zero()}});
  }
}

template <int Dim>
void Simulation<Dim>::constrain_velocity_in_solids(bool same_pose) {
  if (solids_.empty()) return;
  // every new value from the velocity before this stage, then all written (instead of a copy
  // of the whole velocity to read from); the faces in solids are those of the last
  // find_faces_in_solids (the solids have not moved since). With the guard of advect the
  // normals and solid velocities are kept per face, so that a deeper extrapolation after the
  // bodies moved (extend_extrapolation, same_pose) constrains at the pose of the step's solve
  const std::vector<int>& faces = solid_faces_;
  std::vector<double>& values = solid_values_;
  values.resize(faces.size());
  const int count = static_cast<int>(faces.size());
  const bool keep = guards_reads() && !same_pose;
  if (keep) solid_frame_.resize(faces.size());
  const std::vector<Box<Dim>> bounds = coupled_ && !same_pose ? body_bounds() : std::vector<Box<Dim>>();
  // The faces in the fixed bodies (find_faces_in_solids keeps them across steps) keep the fixed
  // solids' share of the normal's search: solids_ lists the static shapes first, so its
  // gradient's loop over them ends at the same (distance, nearest) at a face every step; it is
  // kept per fixed face with that nearest shape's gradient, and only the moving shapes are
  // searched again (the same comparisons in the same order, the same normal)
  const std::size_t fixed_shapes = solid_shapes_.size();
  const bool split = !same_pose && switches_.restricted_passes && fixed_faces_valid_ &&
                     fixed_shapes > 0 &&
                     solid_field_shapes_.size() >= fixed_shapes &&
                     solid_face_fixed_.size() == faces.size();
  const double far = 2.0 * grid_.dx();
  if (split && fixed_face_frame_.empty()) {
    int total = 0;
    for (int a = 0; a < Dim; ++a) total += static_cast<int>(fixed_faces_[a].size());
    fixed_face_frame_.resize(total);
    std::vector<int> all;
    all.reserve(total);
    for (int a = 0; a < Dim; ++a) all.insert(all.end(), fixed_faces_[a].begin(), fixed_faces_[a].end());
#pragma omp parallel for schedule(static) num_threads(team_threads(total))
    for (int i = 0; i < total; ++i) {
      const auto [axis, coord] = grid_.face_coord(all[i]);
      const Vec<Dim> x = grid_.face_center(axis, coord);
      FixedFaceFrame& frame = fixed_face_frame_[i];
      frame.distance = std::numeric_limits<double>::infinity();
      std::size_t best = 0;
      nearest_solid<Dim>(solid_field_shapes_, solid_field_boxes_, far, x, 0, fixed_shapes,
                         frame.distance, best);
      frame.nearest = best;
      frame.normal = solid_field_shapes_[best]->gradient(x);
    }
  }
  // The rows evaluated (issue 20): a fixed face deep in a fixed solid, far from every moving
  // body, is left out. Every face g its interpolation reads has W_F^u = 0 or is a wall's, so
  // apply_wall_and_solid_velocities has just set u_[g] to the solid's velocity there, which is
  // +0 outside every moving body's bounds (solid_velocity), or to +0 (walls); extend_extrapolation
  // gives those faces the same values again before its call at the same pose. The interpolation
  // sums w * (+-0) from +0.0 with w >= 0: +0 in every component; v_s = 0, so v_n = +-0 is not
  // negative and the new value is +0, which u_[f] (one of the faces read) holds already. The
  // flags are made once per set of fixed faces, with W_F^u at a time when no moving body's
  // bounds came within kDeepMargin of the face's centre, and a face is left out only while none
  // does: the faces read lie within one dx of the centre per axis, and W_F^u there reads the
  // solids' union within one more dx, where a moving body (its level set no lower than the
  // distance to its bounds) does not change the fixed solids' value
  std::vector<int>& rows = constrained_rows_;
  if (!same_pose) {
    rows.clear();
    const int fixed_total = [&] {
      int total = 0;
      for (int a = 0; a < Dim; ++a) total += static_cast<int>(fixed_faces_[a].size());
      return total;
    }();
    bool periodic = false;
    for (int a = 0; a < Dim; ++a) periodic = periodic || grid_.periodic(a);
    const bool skip_deep = switches_.restricted_passes && fixed_faces_valid_ && !periodic &&
                           fixed_total > 0 && solid_face_fixed_.size() == faces.size() &&
                           weights_.fluid_face.size() == grid_.num_faces();
    // the moving bodies' bounds grown by the margin; a body without finite bounds: none skipped
    constexpr double kDeepMargin = 4.0;
    std::vector<Box<Dim>> near;
    bool unbounded = false;
    if (skip_deep && rigid_) {
      const auto& bodies = rigid_->bodies();
      for (const auto& b : bodies) {
        if (!b.moves()) continue;
        const Box<Dim> box = b.bounds();
        if (!box.min().allFinite() || !box.max().allFinite()) {
          unbounded = true;
          continue;
        }
        const Vec<Dim> grow = Vec<Dim>::Constant(kDeepMargin * grid_.dx());
        near.emplace_back(box.min() - grow, box.max() + grow);
      }
    }
    const auto far_from_bodies = [&](const Vec<Dim>& x) {
      if (unbounded) return false;
      for (const Box<Dim>& box : near)
        if (!((x.array() < box.min().array()).any() || (x.array() > box.max().array()).any()))
          return false;
      return true;
    };
    if (skip_deep && !unbounded && static_cast<int>(fixed_face_deep_.size()) != fixed_total) {
      std::vector<int> all;
      all.reserve(fixed_total);
      for (int a = 0; a < Dim; ++a)
        all.insert(all.end(), fixed_faces_[a].begin(), fixed_faces_[a].end());
      fixed_face_deep_.assign(fixed_total, 0);
#pragma omp parallel for schedule(static) num_threads(team_threads(fixed_total))
      for (int i = 0; i < fixed_total; ++i) {
        const auto [axis, coord] = grid_.face_coord(all[i]);
        if (!far_from_bodies(grid_.face_center(axis, coord))) continue;
        bool deep = true;
        for (int c = 0; c < Dim && deep; ++c) {
          // MacGrid::axis_stencil at the centre on component c's lattice (non-periodic): along
          // axis a the samples i0, i0 + 1 with i0 = min(floor(clamp(s, 0, n - 1)), n - 2),
          // s = coord[a] + (a == c) / 2 - (a == axis) / 2 (in halves: s2 = 2 s)
          const VecI<Dim> fdims = grid_.face_dims(c);
          VecI<Dim> lo, hi;
          for (int a = 0; a < Dim; ++a) {
            const int n = fdims[a];
            if (n == 1) {
              lo[a] = hi[a] = 0;
              continue;
            }
            const int s2 = 2 * coord[a] + (a == c ? 1 : 0) - (a == axis ? 1 : 0);
            const int i0 = std::min(std::clamp(s2, 0, 2 * (n - 1)) / 2, n - 2);
            lo[a] = i0;
            hi[a] = i0 + 1;
          }
          const VecI<Dim> box = hi - lo + VecI<Dim>::Ones();
          for (int k = 0; k < box.prod() && deep; ++k) {
            const int g = grid_.face_index(c, lo + lattice_coord<Dim>(k, box));
            deep = weights_.fluid_face[g] == 0.0 || wall_face(g);
          }
        }
        fixed_face_deep_[i] = deep;
      }
    }
    const bool use_deep =
        skip_deep && !unbounded && static_cast<int>(fixed_face_deep_.size()) == fixed_total;
    // (listed in blocks on the team, joined in block order: the ascending list of the serial
    // loop for any team; the bunny's shell has ~100k faces)
    rows = gather_in_order<int>(count, [&](int j, std::vector<int>& out) {
      const int i = use_deep ? solid_face_fixed_[j] : -1;
      if (i >= 0 && fixed_face_deep_[i]) {
        const auto [axis, coord] = grid_.face_coord(faces[j]);
        if (far_from_bodies(grid_.face_center(axis, coord))) return;
      }
      out.push_back(j);
    });
    constrained_left_out_ += count - static_cast<long>(rows.size());
  }
  const int nrows = static_cast<int>(rows.size());
  // the new values (every read before any write), then after the barrier their writes: each
  // listed face is one face of the ascending, distinct list, written by one thread
#pragma omp parallel num_threads(team_threads(nrows))
  {
#pragma omp for schedule(static)
    for (int r = 0; r < nrows; ++r) {
      const int j = rows[r];
      const int f = faces[j];
      const auto [axis, coord] = grid_.face_coord(f);
      const Vec<Dim> x = grid_.face_center(axis, coord);
      Vec<Dim> n;
      if (same_pose) {
        n = solid_frame_[j].normal;
      } else if (split && solid_face_fixed_[j] >= 0) {
        const FixedFaceFrame& frame = fixed_face_frame_[solid_face_fixed_[j]];
        double d = frame.distance;
        std::size_t best = frame.nearest;
        nearest_solid<Dim>(solid_field_shapes_, solid_field_boxes_, far, x, fixed_shapes,
                           solid_field_shapes_.size(), d, best);
        n = best < fixed_shapes ? frame.normal : solid_field_shapes_[best]->gradient(x);
      } else {
        n = solids_.gradient(x);
      }
      const Vec<Dim> vs = same_pose ? solid_frame_[j].velocity
                                    : (coupled_ ? solid_velocity(x, bounds) : Vec<Dim>::Zero());
      const double own = u_[f];
      if (keep) solid_frame_[j] = {n, vs, own};
      // A face the guard of advect left NaN (not reached: std::numeric_limits' quiet NaN) is one of
      // the corners its component's interpolation reads (x is its centre; a weight of 0 still
      // gives NaN), so v[axis] and then vn are that NaN, passed on unchanged by the arithmetic
      // (no invalid operation makes a new one), and the value is vn: the face's own value. It is
      // kept without the interpolation (about half of the bunny's shell faces once the liquid
      // has landed, every one while it falls)
      if (std::isnan(own)) {
        values[j] = own;
        continue;
      }
      Vec<Dim> v = grid_.interpolate_velocity(u_, x);
      const double vn = (v - vs).dot(n);
      if (vn < 0.0) v -= vn * n;
      // (a NaN in any component, a face the guard of advect marks unread, makes the value NaN: the
      // comparison above would drop it)
      values[j] = std::isnan(vn) ? vn : v[axis];
    }
#pragma omp for schedule(static)
    for (int r = 0; r < nrows; ++r) u_[faces[rows[r]]] = values[rows[r]];
  }
}

template <int Dim>
void Simulation<Dim>::check_finite(const char* after, bool solve_outputs) const {
  // every check in one parallel region (a region per vector cost up to four fork-joins per
  // call): logical ands and the smallest index of a particle that is not finite, the same
  // answer for any split
  const long np = static_cast<long>(particles_.size());
  const auto blocks = [](const VectorX& v) { return (static_cast<long>(v.size()) + 4095) / 4096; };
  // (band23) a pressure that is +0 outside the cells pressure_cells_ lists is finite there: only
  // those cells are read (its pages beyond the liquid are never provided, not even as zero pages)
  const bool listed = solve_outputs && pressure_cells_.holds(pressure_);
  const long nu = blocks(u_), npr = solve_outputs && !listed ? blocks(pressure_) : 0,
             ns = solve_outputs ? blocks(stress_) : 0;
  const int* pc = pressure_cells_.cells.data();
  const long npc = listed ? static_cast<long>(pressure_cells_.cells.size()) : 0;
  bool finite_u = true, finite_p = true, finite_s = true;
  long first = np;
  const auto segment_finite = [](const VectorX& v, long b) {
    const Eigen::Index i = static_cast<Eigen::Index>(b) * 4096;
    return v.segment(i, std::min<Eigen::Index>(4096, v.size() - i)).allFinite();
  };
#pragma omp parallel reduction(&& : finite_u, finite_p, finite_s) reduction(min : first) \
    num_threads(team_threads(std::max<long>(4096 * (nu + npr + ns) + npc, np)))
  {
#pragma omp for schedule(static) nowait
    for (long b = 0; b < nu; ++b) finite_u = finite_u && segment_finite(u_, b);
#pragma omp for schedule(static) nowait
    for (long b = 0; b < npr; ++b) finite_p = finite_p && segment_finite(pressure_, b);
#pragma omp for schedule(static) nowait
    for (long k = 0; k < npc; ++k) finite_p = finite_p && std::isfinite(pressure_[pc[k]]);
#pragma omp for schedule(static) nowait
    for (long b = 0; b < ns; ++b) finite_s = finite_s && segment_finite(stress_, b);
#pragma omp for schedule(static) nowait
    for (long p = 0; p < np; ++p)
      if (!particles_.x[p].allFinite() || !particles_.v[p].allFinite()) first = std::min(first, p);
  }
  std::string what;
  if (!finite_u) what = "non-finite grid velocity";
  if (!finite_p) what = "non-finite pressure";
  if (!finite_s) what = "non-finite viscous stress";
  if (what.empty() && first < np)
    what = "non-finite particle position or velocity (particle " + std::to_string(first) + ")";
  if (what.empty()) return;
  std::ostringstream msg;
  msg << "t = " << time_ << " s (frame " << frame_ + 1 << "): " << what << " after " << after;
  throw SimulationError(msg.str());
}

template <int Dim>
FrameStats Simulation<Dim>::advance_frame() {
  const Stopwatch frame_watch;
  // a frame stopped at a step boundary goes on with the statistics gathered so far
  if (!mid_frame_) {
    stats_ = FrameStats{};
    frame_ledger_ = EnergyLedger{};
    stats_.solver.scheme = scene_.solver.scheme;
    stats_.dt_min = std::numeric_limits<double>::infinity();
  }
  mid_frame_ = false;
  // substeps that land exactly on the frame time (frame + 1) / fps
  const double frame_end = (frame_ + 1) / scene_.time.fps;
  while (time_ < frame_end) {
    const double remaining = frame_end - time_;
    // equal substeps no longer than the CFL limit, the last one ending on the frame time
    const double dt_cfl = cfl_dt();
    const double n = std::max(1.0, std::ceil(remaining / dt_cfl - 1e-9));
    const double dt = remaining / n;
    const long iterations_before = stats_.solver.iterations;
    step(dt);
    stats_.solver.max_step_iterations =
        std::max(stats_.solver.max_step_iterations, stats_.solver.iterations - iterations_before);
    time_ = n == 1.0 ? frame_end : time_ + dt;
    ++stats_.steps;
    stats_.dt_min = std::min(stats_.dt_min, dt);
    stats_.dt_max = std::max(stats_.dt_max, dt);
    if (stop_ && *stop_ && time_ < frame_end) {
      mid_frame_ = true;
      stats_.timing[FramePhase::total] += frame_watch.seconds();
      return stats_;
    }
  }
  ++frame_;
  export_sink_ = nullptr;  // a request covers one frame
  stats_.frame = frame_;
  stats_.time = frame_end;
  if (stats_.steps == 0) stats_.dt_min = 0.0;
  // the solid and liquid weights of the final state (reused by the next step, unless its first
  // half drift moves the particles first: then the stress weights are left for that step's own
  // weights, unless there are stress solves, whose clamp of W_L^u (departures item 23) needs W_L^s; the level set (pictures), the volume (statistics) and
  // W_L^u (the next step's CFL limit reads the trusted faces) are made as before)
  if (coupled_) update_moving_solids();
  const bool reused = !split_drift();
  // With split_drift the next step makes every weight again after its first half drift: of this
  // frame's end only the level set (pictures) and the volume (statistics) are read, and W_L^u by
  // the next frame's first CFL limit, unless that limit is max_dt whatever W_L^u is. Then W_L^p,
  // W_L^u and eta per cell are made only if read before the next step (weights(), cell_eta():
  // the same values; liquid_volume_from_phi)
  const bool solids = !solid_shapes_.empty() || coupled_;
  make_liquid_phi();
  if (!reused && solids && !switches_.divergence_free_air && frame_end_dt_is_max())
    liquid_volume_from_phi();
  else
    liquid_weights_from_phi(reused || sequence_ != SolveSequence::pressure, true);
  liquid_weights_current_ = reused;
  fill_state_stats(stats_);
  ledger_ = frame_ledger_;
  stats_.timing[FramePhase::total] += frame_watch.seconds();
  return stats_;
}

namespace {

/// The statistics a frame gathers step by step (those of fill_state_stats are derived at the
/// frame's end): part of the state when a run stops between two steps of a frame.
template <class Archive>
void step_stats_fields(Archive& a, FrameStats& s) {
  a(s.steps);
  a(s.dt_min);
  a(s.dt_max);
  a(s.contact_count);
  a(s.max_penetration);
  SolverStats& v = s.solver;
  a(v.iterations);
  a(v.max_step_iterations);
  a(v.staggered_iterations);
  a(v.max_relative_residual);
  a(v.converged);
  std::uint64_t n = v.unconverged.size();
  a(n);
  if (n > (1u << 24)) throw InputError("checkpoint: implausible count of unconverged solves");
  v.unconverged.resize(n);
  for (auto& u : v.unconverged) {
    a(u.solve);
    a(u.time);
    a(u.iterations);
    a(u.relative_residual);
  }
  a(v.dofs_pressure);
  a(v.dofs_stress);
  a(v.dofs_contact);
  a(v.dofs_friction);
  a(v.fluid_iterations);
  a(v.contact_iterations);
  a(v.coupled_iterations);
  a(v.fluid_seconds);
  a(v.contact_seconds);
  a(v.coupled_seconds);
  a(v.viscosity_residuals);
  a(v.max_viscosity_residual);
  // the preconditioners booked so far in the frame (a run stopped mid-frame resumes with them)
  a(v.stokes_solves_multigrid);
  a(v.stokes_solves_ssor);
  a(v.max_stokes_stiffness);
  a(v.preconditioner_fallbacks);
  a(v.unsettled_steps);
  for (const FramePhase p : enum_values<FramePhase>()) a(s.timing[p]);
}

}  // namespace

template <int Dim>
template <class Archive>
void Simulation<Dim>::state_fields(Archive& a) {
  // layout check: a state of the other dimension is refused before anything is read into place
  int dim = Dim;
  a(dim);
  if (dim != Dim) throw InputError("checkpoint: a state of a " + std::to_string(dim) + "D scene");
  // time and step counters; a frame stopped between two steps and what it gathered so far
  a(time_);
  a(frame_);
  a(mid_frame_);
  step_stats_fields(a, stats_);
  // the liquid: particles (APIC), grid velocity (the CFL step and the probes read it), the last
  // solve's pressure and stress (warm-start data), the effective viscosity per cell and
  // Algorithm 2's shear rate of the previous step (non-Newtonian liquids)
  a(particles_.x);
  a(particles_.v);
  a(particles_.c);
  a(particles_.mass);
  a(particles_.density);
  a(particles_.liquid);
  a(u_);
  a(pressure_);
  a(stress_);
  a(cell_eta_);
  a(previous_shear_rate_);
  a(liquid_weights_current_);
  // Line15Energy::balance's credit (the default since slosh11; absent under `free` and
  // `per_step`)
  if (switches_.line15_energy == Line15Energy::balance ||
      switches_.line15_energy == Line15Energy::balance_local)
    a(line15_credit_);
  // SurfaceDeficits::to_solve: the last density projection's listed deficits, the next step's
  // divergence source (empty under every other setting)
  a(volume_errors_);
  // the velocity the next step's first half drift reads, extended to every face it can read
  // (drift_guarded: resolve_drift_velocity; absent when nothing is kept for that drift)
  bool drift = drift_resolved_.size() > 0;
  a(drift);
  if (drift) a(drift_resolved_);
  // the bodies: poses, velocities, the last contacts and forces (RigidWorld::state_fields)
  bool bodies = rigid_ != nullptr;
  a(bodies);
  if (bodies != (rigid_ != nullptr)) throw InputError("checkpoint: bodies do not match the scene's");
  if (rigid_) rigid_->state_fields(a);
  // no random number generator runs after seeding (seed_particles draws once, in the constructor)
}

template <int Dim>
std::vector<char> Simulation<Dim>::save_state() const {
  // the guarded first half drift's velocity, fully extended, goes into the checkpoint; the run
  // itself goes on with its guard (the same values read either way)
  auto* self = const_cast<Simulation*>(this);
  const bool resolve = drift_guard_;
  if (cell_eta_pending_) update_cell_eta(/*stress_eta_made=*/false);
  self->resolve_drift_velocity();
  StateWriter w;
  self->state_fields(w);
  if (resolve) self->drift_resolved_ = VectorX();
  return w.take();
}

template <int Dim>
void Simulation<Dim>::load_state(const std::vector<char>& bytes) {
  StateReader r(bytes, "checkpoint");
  // (the guard's state of the run before is not this state's: the checkpoint brings its own)
  drop_drift_guard();
  reached_u_ = VectorX();
  pressure_cells_.forget();  // (band23: the checkpoint's pressure is written over it)
  state_fields(r);
  r.finish();
  const std::size_t n = particles_.x.size();
  if (particles_.v.size() != n || particles_.c.size() != n || particles_.mass.size() != n ||
      particles_.density.size() != n || particles_.liquid.size() != n ||
      u_.size() != grid_.num_faces() || pressure_.size() != grid_.num_cells() ||
      (stress_.size() != stress_grid_.num_dofs() &&
       !(stress_.size() == 0 && sequence_ == SolveSequence::pressure)) ||
      (drift_resolved_.size() != 0 && drift_resolved_.size() != grid_.num_faces()))
    r.fail("sizes that do not match the scene's grid or particles");
  for (const auto& deficit : volume_errors_)
    if (deficit.first < 0 || deficit.first >= grid_.num_cells())
      r.fail("a listed volume deficit outside the scene's grid");
  // (checkpoints written before the stress field was dropped without stress solves hold zeros)
  if (sequence_ == SolveSequence::pressure) stress_ = VectorX();
  // what is derived from the state: the solids at the bodies' pose and the liquid weights, as
  // advance_frame leaves them at a frame's end (a step that needs them fresh recomputes them);
  // their wall time is not the restored frame's, so the frame's timing is kept as saved
  const auto timing = stats_.timing;
  if (coupled_) update_moving_solids();
  update_liquid_weights();
  stats_.timing = timing;
  if (!mid_frame_) fill_state_stats(stats_);
}

template <int Dim>
void Simulation<Dim>::fill_state_stats(FrameStats& s) const {
  // liquid volume = sum W_L^p dx^Dim
  s.liquid_volume = liquid_volume_;
  s.particles = static_cast<long>(particles_.size());
  // particle bounding box and kinetic energy sum 1/2 m |v|^2
  s.liquid_bounds_lower.clear();
  s.liquid_bounds_upper.clear();
  if (particles_.size() > 0) {
    Vec<Dim> lo = particles_.x[0], hi = particles_.x[0];
    for (const auto& x : particles_.x) {
      lo = lo.cwiseMin(x);
      hi = hi.cwiseMax(x);
    }
    s.liquid_bounds_lower = to_std<Dim>(lo);
    s.liquid_bounds_upper = to_std<Dim>(hi);
  }
  s.kinetic_energy_liquid = particle_kinetic_energy();
  s.kinetic_energy_bodies = rigid_ ? rigid_->kinetic_energy() : 0.0;
  s.potential_energy_liquid = liquid_potential_energy();
  s.potential_energy_bodies = body_potential_energy();
  s.line15_banked_energy = -line15_credit_;
  s.bodies = rigid_ ? rigid_->body_stats() : std::vector<BodyStats>{};
  // probes: grid velocity and cell pressure interpolated at the probe
  s.probes.clear();
  for (const auto& probe : scene_.probes) {
    ProbeStats ps;
    ps.name = probe.name;
    ps.position = probe.position;
    const Vec<Dim> x = to_vec<Dim>(probe.position, Vec<Dim>::Zero());
    ps.velocity = to_std<Dim>(grid_.interpolate_velocity(u_, x));
    ps.pressure = grid_.interpolate_cell(pressure_, x);
    s.probes.push_back(ps);
  }
}

template <int Dim>
double Simulation<Dim>::face_kinetic_energy() const {
  double energy = 0.0;
  // (between the extrapolation and the advection, a face not reached is NaN: its value is the
  // solve's, reached_u_, as it was before the guard)
  for (int f = 0; f < grid_.num_faces(); ++f) {
    const double u = std::isnan(u_[f]) ? reached_u_[f] : u_[f];
    energy += 0.5 * face_mass_[f] * u * u;
  }
  return energy;
}

template <int Dim>
double Simulation<Dim>::particle_kinetic_energy() const {
  double energy = 0.0;
  for (std::size_t p = 0; p < particles_.size(); ++p)
    energy += 0.5 * particles_.mass[p] * particles_.v[p].squaredNorm();
  return energy;
}

template <int Dim>
double Simulation<Dim>::body_potential_energy() const {
  double energy = 0.0;
  if (rigid_)
    for (const auto& b : rigid_->bodies())
      if (b.is_dynamic()) energy -= b.mass * gravity_.dot(b.position);
  return energy;
}

template <int Dim>
double Simulation<Dim>::liquid_potential_energy() const {
  double energy = 0.0;
  for (std::size_t p = 0; p < particles_.size(); ++p)
    energy -= particles_.mass[p] * gravity_.dot(particles_.x[p]);
  return energy;
}

void AnySimulation::load_state(const std::vector<char>&) {
  throw InputError("checkpoint: this simulation cannot be restored from a checkpoint");
}

std::unique_ptr<AnySimulation> make_simulation(const SceneDesc& scene) {
  return make_simulation(scene, StageSwitches{});
}

std::unique_ptr<AnySimulation> make_simulation(const SceneDesc& scene,
                                               const StageSwitches& switches) {
  if (scene.dim == 3) return std::make_unique<Simulation<3>>(scene, switches);
  return std::make_unique<Simulation<2>>(scene, switches);
}

template class Simulation<2>;
template class Simulation<3>;

}  // namespace monolith
