#pragma once
/// \file particles.hpp
/// Liquid particles and everything that moves them: seeding, the APIC transfers (Jiang et al.
/// 2015) between particles and the MAC grid, velocity extrapolation, advection, position
/// correction, and the liquid level set reconstructed from the particles (Zhu & Bridson 2005).

#include <functional>
#include <utility>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/fluid/liquid_spec.hpp"
#include "reference/fluid/stokes_workspace.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/grid/boundary.hpp"
#include "reference/grid/boxed_lattice.hpp"
#include "reference/grid/mac_grid.hpp"

namespace monolith {

/// Liquid particles (structure of arrays).
template <int Dim>
struct Particles {
  std::vector<Vec<Dim>> x;     ///< positions
  std::vector<Vec<Dim>> v;     ///< velocities
  std::vector<Mat<Dim>> c;     ///< APIC affine matrices: row a is the gradient of velocity component a
  std::vector<double> mass;    ///< kg (2D: kg per metre of depth)
  std::vector<double> density; ///< kg/m^3 of the liquid the particle belongs to
  std::vector<int> liquid;     ///< index into SceneDesc::liquids

  std::size_t size() const { return x.size(); }
  /// Removes particles whose flag is non-zero (order of the rest preserved).
  void remove_flagged(const std::vector<char>& flag);
};

/// Where the solids are (static bodies now; walls are the domain boundary and handled by the
/// grid). distance < 0 inside a solid; gradient is the outward unit normal.
template <int Dim>
struct SolidField {
  std::function<double(const Vec<Dim>&)> distance;
  std::function<Vec<Dim>(const Vec<Dim>&)> gradient;
  bool empty() const { return !distance; }
};

/// Seeds `per_cell` jittered particles per cell inside each liquid's shape (never inside a solid,
/// never outside the domain), with the liquid's velocity plus its rigid rotation about the
/// shape's centre (APIC matrix c set to that rotation's velocity gradient). Deterministic for a
/// given seed.
template <int Dim>
Particles<Dim> seed_particles(const MacGrid<Dim>& grid, const std::vector<LiquidSpec>& liquids,
                              const std::vector<ShapePtr<Dim>>& liquid_shapes,
                              const SolidField<Dim>& solids, int per_cell, unsigned seed);

/// The face layers (along the last axis) beyond the particles' cell layers that hold every face
/// the diagonal of P reads after particles_to_grid (density_diagonal_in_place: the faces with a
/// density, their cells' faces, and those faces' cells' faces): 3 (docs/derivations.md,
/// "Passes restricted to boxes", "The faces' densities written where they change").
constexpr int kDensityReadLayers = 3;

/// Sorted, disjoint face index ranges [first, second).
using FaceIndexRanges = std::vector<std::pair<long, long>>;

/// The faces' densities of particles_to_grid kept across calls whose caller turns them into
/// P's diagonal in place (issue 20, kern22). That diagonal is one value (the fallback density)
/// on every face without a density and not next to one, so between two calls the storage holds
/// it outside the layers the last call wrote; a call then writes the densities' zeros only in
/// those layers and its own, not on every face.
struct DensitySpans {
  /// in: face_density holds the caller's value on every face outside `kept` (false: unknown;
  /// every face is written, as without this struct)
  bool known = false;
  FaceIndexRanges kept;
  /// out: the faces this call wrote in face_density: `layers` joined with `kept` (every face
  /// when `known` was false). The caller writes its value on the faces of these without a
  /// density; after that the storage holds it outside `layers`
  FaceIndexRanges written;
  /// out: per component lattice, its face layers within kDensityReadLayers of the particles'
  /// cell layers (every layer on a periodic last axis or when a position is not finite)
  FaceIndexRanges layers;
};

/// APIC particle-to-grid transfer onto the faces. Outputs, per face: u (momentum / mass, zero where
/// no particle contributes), face_mass (sum of weighted particle masses), face_density
/// (mass-weighted particle density, the diagonal of P; zero where face_mass is zero).
/// With `density_spans` (see DensitySpans) face_density is written only on the faces of
/// density_spans->written, which hold every face with a density and every face within
/// kDensityReadLayers layers of the particles' layers; its other faces keep their values.
template <int Dim>
void particles_to_grid(const Particles<Dim>& particles, const MacGrid<Dim>& grid, VectorX& u,
                       VectorX& face_mass, VectorX& face_density,
                       DensitySpans* density_spans = nullptr);

/// The union of two lists of sorted, disjoint ranges (touching ranges joined).
FaceIndexRanges union_of_ranges(const FaceIndexRanges& a, const FaceIndexRanges& b);

/// The face layers (along the last axis) beyond the particles' cell layers that
/// particles_to_grid zeroes before its sums: 1, the stencils' reach (a particle in cell layer c
/// reaches face layers c - 1 .. c + 1). The faces outside get their zeros after the sums. A
/// test hook (tests/unit/particles/test_apic.cpp sets 0 and sees stale values survive).
int& particles_to_grid_zero_margin();

/// The PIC velocity of the listed faces only: pic[i] = sum_p w_fp m_p v_p / sum_p w_fp m_p for
/// f = faces[i] (the particles' velocities without their affine part c_p (x_f - x_p); zero where
/// no particle reaches f). `faces` sorted ascending, no repeats. Both sums run over the particles
/// in particle order with P2G's weights and products, so pic[i] has the bits of
/// particles_to_grid's u at f for the same particles with c = 0, for any thread count. Visits
/// only the particles in the cells around the listed faces: the simulation asks for the few
/// ballistic faces beside a support (Simulation::ballistic_faces_take_pic; docs/particles.md,
/// "Energy regains over long runs"), so nothing face-sized is kept for them.
template <int Dim>
void pic_velocity_on_faces(const Particles<Dim>& particles, const MacGrid<Dim>& grid,
                           const std::vector<int>& faces, std::vector<double>& pic);

/// APIC grid-to-particle transfer: v and c from the face velocities u.
/// With `unread` (the guard against unreadable faces, which the caller set to NaN in u;
/// docs/particles.md "Velocity extrapolation"): when empty (or of another size) every particle is
/// transferred and unread[p] = 1 marks those whose v or c came out non-finite; when it has one
/// flag per particle, only the flagged ones are transferred again and their flags updated.
/// Returns the number flagged (0 without `unread`).
template <int Dim>
long grid_to_particles(Particles<Dim>& particles, const MacGrid<Dim>& grid, const VectorX& u,
                       std::vector<char>* unread = nullptr);

/// Makes the extrapolated velocity divergence-free in the air cells beside the liquid: for each
/// cell whose centre lies outside the liquid (0 < phi < layers dx, phi the liquid level set on the
/// half lattice), in order of increasing phi, the face on the cell's outer side (along the axis of
/// the level set's largest gradient component, towards larger phi) is set so that the cell's
/// divergence vanishes, unless that face is trusted (trusted[f] != 0), a wall or cut by a solid.
/// Cells with a face cut by a solid (0 < fluid_face < 1) or a fluid face the extrapolation did
/// not reach (valid[f] == 0) are left as they are. With liquid_reach > 0 the liquid cells of the
/// surface (-liquid_reach dx < phi <= 0 at the centre) are treated first in the same way: their
/// outer face, when it is not trusted (the solve's weight W_F^u W_L^u below the trusted fraction,
/// so its solved value was replaced by the extrapolation), closes the cell's divergence.
template <int Dim>
void divergence_free_air_velocity(const MacGrid<Dim>& grid, const SampleLattice<Dim>& lattice,
                                  const VectorX& phi, const VectorX& fluid_face,
                                  const std::vector<char>& trusted,
                                  const std::vector<char>& valid, int layers,
                                  double liquid_reach, VectorX& u);

/// Extends u from faces with valid[f] != 0 into the others, `layers` rings deep (averaging valid
/// neighbours of the same component); marks the filled faces valid.
template <int Dim>
void extrapolate_velocity(const MacGrid<Dim>& grid, VectorX& u, std::vector<char>& valid,
                          int layers);
/// The same, given per axis an inclusive box of face coordinates (box_lo[a] > box_hi[a] on some
/// axis: none) outside which every valid[f] is 0: the first layer's search visits the boxes'
/// faces instead of every face (issue 20); the same values, flags and order of work.
template <int Dim>
void extrapolate_velocity(const MacGrid<Dim>& grid, VectorX& u, std::vector<char>& valid,
                          int layers, const std::array<VecI<Dim>, Dim>& box_lo,
                          const std::array<VecI<Dim>, Dim>& box_hi);

/// Moves particles through the (extrapolated) grid velocity u for dt with a second-order
/// Runge-Kutta scheme, in substeps of at most half a cell so that thin solids are not tunnelled
/// through at large CFL numbers; after every substep pushes particles inside a solid back out
/// along its gradient,
/// keeps them inside walls, wraps periodic axes. Particles that leave through an open face are
/// removed; returns how many were removed.
/// With `unread` (as in grid_to_particles: empty for a first pass over every particle, one flag
/// per particle to move the flagged ones only): a particle whose v or c is non-finite or that
/// reads a non-finite velocity anywhere along its path stays where it was, flagged; the others'
/// flags are cleared. The flags follow the particles through the removal.
template <int Dim>
long advect_particles(Particles<Dim>& particles, const MacGrid<Dim>& grid, const VectorX& u,
                      double dt, const SolidField<Dim>& solids,
                      const std::array<BoundaryType, 2 * Dim>& boundary,
                      std::vector<char>* unread = nullptr);

/// Moves every particle along a straight line through its own velocity v for dt, in substeps of
/// at most kAdvectionSubstep dx, each settled as in advect_particles (solids, walls, periodic
/// wrap, removal beyond open faces). A particle at rest is not touched. The first half drift of
/// the very first step (no grid velocity has been solved yet): the particles' velocities are then
/// the scene's initial ones, and an APIC particle's velocity field at its own position is v.
/// Returns how many particles were removed.
template <int Dim>
long drift_particles_own_velocity(Particles<Dim>& particles, const MacGrid<Dim>& grid, double dt,
                                  const SolidField<Dim>& solids,
                                  const std::array<BoundaryType, 2 * Dim>& boundary);

/// Buffers correct_positions keeps between calls when given them (speed only: nothing in them
/// carries over from one call to the next): the per-thread lists of each particle's neighbours,
/// which otherwise grow by doubling in every call (8.4 + 16.8 + 33.6 MB at Fig. 2's paper grid,
/// copied at each doubling); kept, they stay at the largest call's size.
struct PositionCorrectionBuffers {
  std::vector<std::vector<int>> neighbour_slots;
};

/// Position correction that keeps particles evenly spread so the liquid volume stays steady
/// (Algorithm 1, line 15); respects solids, walls and periodicity. `buffers` (optional) are
/// reused across calls (the same result with or without them).
template <int Dim>
void correct_positions(Particles<Dim>& particles, const MacGrid<Dim>& grid, double dt,
                       const SolidField<Dim>& solids,
                       const std::array<BoundaryType, 2 * Dim>& boundary,
                       PositionCorrectionBuffers* buffers = nullptr);

/// What project_particle_density did (for statistics and tests).
struct DensityProjectionStats {
  int cells = 0;              ///< unknowns of the Poisson problem
  int iterations = 0;         ///< conjugate gradient iterations
  double error_before = 0.0;  ///< sum_c |e_c| dx^Dim before the move (m^Dim), e_c as in particles.cpp
  double max_move = 0.0;      ///< largest particle displacement (m)
  /// With SurfaceDeficits::beyond_dead_band (else 0): sum_c T_c / sum_c rho~_c - 1 over the
  /// unknowns, how much more the level set encloses than the particles (relative); and the share
  /// of the surface band's deficits corrected
  double volume_mismatch = 0.0;
  double deficit_share = 1.0;
  /// With SurfaceDeficits::to_solve: the deficits on the liquid side of the surface band that
  /// were not corrected, (cell index, e_c = rho~_c - T_c < 0 in cell volumes), cells increasing;
  /// of the last iteration
  std::vector<std::pair<int, double>> surface_deficits;
};

/// What the density projection does with a deficit of particle volume (rho~_c < T_c) on the
/// liquid side of the surface band (1/2 <= T_c < 0.999, docs/particles.md "Sloshing").
enum class SurfaceDeficits {
  all,   ///< always corrected (the default)
  none,  ///< never, only an excess as on the air side (a measurement switch)
  /// A measurement switch: corrected only in the share of a volume feedback with a dead band:
  /// none while the level set encloses at most 0.3 % more than the particle volume (the level
  /// set's response to the disorder of particles under a smooth surface), all from 0.6 % on (thin
  /// sheets, splashes)
  beyond_dead_band,
  /// A measurement switch (docs/particles.md, "Volume correction through the solve"): not moved
  /// but listed (DensityProjectionStats::surface_deficits), for the simulation to hand them to
  /// the next step's solve as a divergence source (the correction then done by the velocity)
  to_solve,
};

/// Grid-based implicit density projection after Kugelstadt, Bender, Fernandez-Fernandez, Jeske,
/// Loschner and Longva (2019), "Implicit density projection for volume conserving liquids",
/// IEEE TVCG 27(4). Compares, per cell, the particle volume fraction (each particle's volume m/rho
/// spread over a box of its rest spacing and weighted by the hat function of the cell centre)
/// with the liquid fraction of the particle level set (liquid_phi_on_lattice on `lattice`)
/// weighted by the same hat function, solves
/// a Poisson problem with the face weights `fluid_face` (W_F^u: Neumann at walls and solids,
/// Dirichlet 0 in air) for the error and moves every particle by the gradient of the solution,
/// so over-full cells empty into under-full ones and the reconstructed volume follows the
/// particle volume (a form of Algorithm 1, line 15). On the air side of the reconstructed
/// surface (hat-weighted liquid fraction below 1/2) only an excess of particle volume is
/// corrected, so water at rest is a fixed point (docs/particles.md, "Still water"). `iterations` repeats the whole (reconstruction, solve, move); the stats are
/// those of the first iteration (error_before) and the sums over all (iterations, max_move the
/// largest). Respects solids, walls and periodicity; deterministic for any thread count.
/// `surface_deficits`: on the liquid side of the surface band (1/2 <= T_c < 0.999) a deficit is
/// corrected in the share SurfaceDeficits says (by default always; the other rules are
/// measurement switches, docs/particles.md "Sloshing").
/// `move_scratch` (issue 20, p2g21): the face-sized displacement's storage, kept by the caller
/// across calls (0 outside its dirty spans, which are the faces the last call wrote: each call
/// zeroes only those, so after the first call no page beyond the liquid's faces is touched, and
/// the first call's zeros come from the kernel). Without it every call makes its own (one per
/// call, kept over its iterations). The results are the same bits either way.
/// `held_near`, `held_reach` (rise26, docs/derivations.md departures item 25): a cell whose centre
/// lies closer than held_reach dx to `held_near` (the moving bodies at their new pose) keeps its
/// error e_c uncorrected (0 on the right-hand side). Beside a body that moved this step the target
/// (the particle level set cut by the body) and the particles' splat disagree by the body's own
/// sweep: under a rising box an excess, over it a deficit, every step; correcting them moved that
/// volume around the body and lifted it by the body's height, energy line 15's payment then took
/// from the flow the body drives (docs/particles.md "A rising body and line 15's payment").
/// nullptr or held_reach <= 0: every cell corrected (the behaviour before).
template <int Dim>
DensityProjectionStats project_particle_density(Particles<Dim>& particles, const MacGrid<Dim>& grid,
                                                const SampleLattice<Dim>& lattice,
                                                const VectorX& fluid_face,
                                                const SolidField<Dim>& solids,
                                                const std::array<BoundaryType, 2 * Dim>& boundary,
                                                int iterations = 1,
                                                SurfaceDeficits surface_deficits =
                                                    SurfaceDeficits::all,
                                                KeptZeros* move_scratch = nullptr,
                                                const SolidField<Dim>* held_near = nullptr,
                                                double held_reach = 0.0);

/// Iterations of project_particle_density applied to freshly seeded particles (the simulation
/// does this once before frame 0, so the particle volume and the level set's agree from the
/// start; measured in docs/particles.md).
inline constexpr int kSeedProjectionIterations = 2;

/// The liquid's signed distance (negative inside) sampled on `lattice` (normally half_lattice of
/// the grid), reconstructed from the particles after Zhu & Bridson (2005). Calibrated so that a
/// uniformly seeded block of liquid gives a zero level set on the block's boundary (within a
/// small fraction of dx) and so the volume of {phi < 0} matches the seeded volume. Particles
/// within the kernel support of a `wall` face of `boundary` are mirrored across it (and across
/// two walls at a corner), so liquid against a wall reads as liquid up to and beyond the wall:
/// without the images a lattice point near a wall averages particles on one side only, the
/// level set bulges inward there and the cells along the wall get liquid fractions below one,
/// which drives a flow in liquid at rest (docs/particles.md, "Still water"). Particles within
/// the support of a solid of `solids` are mirrored across its nearest surface point in the same
/// way (x' = x - 2 d n, d the solid distance, n its gradient), the image reaching the lattice
/// points its particle reaches and those inside a solid within 2 R of the particle: liquid
/// against a solid body reads as liquid up to the body and a little into it (what
/// extend_liquid_into_solids builds on), and nothing leaks through a thin solid to its dry side.
template <int Dim>
VectorX liquid_phi_on_lattice(const Particles<Dim>& particles, const MacGrid<Dim>& grid,
                              const SampleLattice<Dim>& lattice,
                              const std::array<BoundaryType, 2 * Dim>& boundary,
                              const SolidField<Dim>& solids = {});
/// The same level set written into `phi` (resized to the lattice; its buffer is reused across
/// calls). The splat's sums live in tiles of 8^Dim lattice points made only where a particle or
/// one of its images reaches (reference/grid/tiled_lattice.hpp), so its memory and its passes
/// follow the liquid, not the box (issue 20); every other point reads the kernel support.
template <int Dim>
void liquid_phi_on_lattice(const Particles<Dim>& particles, const MacGrid<Dim>& grid,
                           const SampleLattice<Dim>& lattice,
                           const std::array<BoundaryType, 2 * Dim>& boundary,
                           const SolidField<Dim>& solids, VectorX& phi);

/// Where liquid_phi_on_lattice wrote a value of its own: every lattice point outside the
/// inclusive box [lo, hi] (lo > hi on some axis: no point) holds `background` (the kernel
/// support, or 3 dx without particles), so a reader that only looks for values below the
/// background can scan the box instead of the lattice (issue 20: the liquid's band).
template <int Dim>
struct LiquidPhiBand {
  double background = 0.0;
  VecI<Dim> lo = VecI<Dim>::Zero(), hi = -VecI<Dim>::Ones();
  bool empty() const { return (lo.array() > hi.array()).any(); }
};
/// The same level set, with its band.
template <int Dim>
void liquid_phi_on_lattice(const Particles<Dim>& particles, const MacGrid<Dim>& grid,
                           const SampleLattice<Dim>& lattice,
                           const std::array<BoundaryType, 2 * Dim>& boundary,
                           const SolidField<Dim>& solids, VectorX& phi, LiquidPhiBand<Dim>& band);
/// The same level set stored over its band (issue 20, branch band19): when the background is at
/// least `boxed_from`, `phi` keeps the band's box grown by `margin` points on every side
/// (clamped to the lattice; empty with the band) and the background outside it, so the call
/// fills and touches no lattice-sized vector; otherwise phi's box is the whole lattice (the
/// same values as the VectorX form). Every stored value has the VectorX form's bits.
template <int Dim>
void liquid_phi_on_lattice(const Particles<Dim>& particles, const MacGrid<Dim>& grid,
                           const SampleLattice<Dim>& lattice,
                           const std::array<BoundaryType, 2 * Dim>& boundary,
                           const SolidField<Dim>& solids, BoxedLattice<Dim>& phi,
                           LiquidPhiBand<Dim>& band, int margin, double boxed_from);

/// Largest particle speed (for the CFL condition).
template <int Dim>
double max_particle_speed(const Particles<Dim>& particles);

}  // namespace monolith
