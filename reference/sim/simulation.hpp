#pragma once
/// \file simulation.hpp
/// The time loop of Algorithm 1. Simulation<Dim> owns the grid, particles, solids and solver
/// state of a scene (SceneDesc) and advances it frame by frame; AnySimulation erases the
/// dimension for the application. The state is read through Simulation's const accessors: the
/// pictures (reference/viz/render.hpp) draw it from outside the solver core.

#include <algorithm>
#include <array>
#include <csignal>
#include <functional>
#include <memory>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/coupling/coupled_schemes.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/coupling/coupling_scheme.hpp"
#include "reference/coupling/solve_sequence.hpp"
#include "reference/coupling/system_export.hpp"
#include "reference/fluid/herschel_bulkley.hpp"
#include "reference/fluid/pressure_projection.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/grid/boundary.hpp"
#include "reference/grid/box_rows.hpp"
#include "reference/grid/boxed_union_phi.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/grid/volume_fractions.hpp"
#include "reference/particles/particles.hpp"
#include "reference/rigid/rigid_world.hpp"
#include "reference/sim/frame_stats.hpp"
#include "reference/sim/scene_desc.hpp"
#include "reference/solvers/pcg.hpp"

namespace monolith {

/// What pays for the potential energy line 15's moves (correct_positions, the density projection)
/// add to the liquid (StageSwitches::line15_energy).
enum class Line15Energy {
  free,  ///< nothing: the moves change the energy as they do (the default before slosh11)
  /// each step whose line 15 raises -sum m g . x by dPE > 0 takes dPE from the liquid's kinetic
  /// energy (every particle's v and c, and with split_advection the grid velocity the next half
  /// drift reads, scaled by sqrt(max(0, 1 - dPE / KE)), KE = sum 1/2 m |v|^2); a drop is lost
  per_step,
  /// the same, but a drop is banked: the kinetic energy pays only when line 15's summed change
  /// since the start would otherwise be positive (credit = min(0, credit + dPE), pay the rest),
  /// so line 15 never adds energy over the run (a rise larger than the kinetic energy is paid
  /// with all of it, the rest carried as a debt with StageSwitches::line15_carry_debt, dropped
  /// without) and loses only what it did not take back (the default)
  balance,
  /// `balance`'s credit and amount (kept over the whole liquid), but paid locally: the amount is
  /// shared among the cells in proportion to line 15's net potential energy rise within
  /// StageSwitches::line15_pay_reach cells of each, and each cell's share is taken from the
  /// kinetic energy of the particles within that reach of it (Simulation::pay_line15_energy_locally;
  /// what a neighbourhood without kinetic energy cannot pay is taken by the uniform scaling)
  balance_local,
};

/// (docs/derivations.md departures item 17) The factor by which line 15's moves are scaled so
/// that their potential energy rise `rise` (> 0) with the account's `credit` (<= 0 banked, > 0
/// owed) costs exactly what the kinetic energy `can_pay` holds: 1 when rise + credit <= can_pay,
/// else (can_pay - credit) / rise clamped to [0, 1] (PE is linear in the positions, so the scaled
/// moves raise it by s rise).
inline double line15_lift_scale(double rise, double credit, double can_pay) {
  if (!(rise > 0.0) || rise + credit <= can_pay) return 1.0;
  return std::clamp((can_pay - credit) / rise, 0.0, 1.0);
}

/// Stages of the step that a diagnosis can switch off or replace, to measure what each one
/// contributes (tests/bench/bench_still_water.cpp; docs/particles.md, "Still water"). The defaults
/// are the simulator; scene files do not reach these switches.
struct StageSwitches {
  bool position_correction = true;  ///< correct_positions (Algorithm 1, line 15)
  bool density_projection = true;   ///< project_particle_density (line 15)
  bool apic = true;                 ///< false: PIC, the particles' affine matrices c are dropped
  /// u* extrapolated kAirVelocityLayers faces beyond the particles' reach before the solve
  bool air_velocity = true;
  /// Only faces with W_F^u W_L^u >= kTrustedLiquidFaceFraction hand their solved velocity to the
  /// particles (false: every face with W_L^u > 0 does)
  bool trusted_faces = true;
  /// Faces that carry particle mass but no liquid fraction (W_L^u = 0) keep u* (false: they are
  /// extrapolated like the air)
  bool unreached_faces_keep_u_star = true;
  /// Those faces (Simulation::ballistic_face) keep the particles' PIC velocity plus g dt, not the
  /// APIC one: a particle a wall supports (the face below it the wall's, the one above
  /// ballistic) otherwise stores one more step of free fall g dt / dx in its affine matrix each
  /// step, which the transfers release (issue 16; docs/particles.md, "Energy regains over long
  /// runs"). false: the APIC value of P2G plus g dt, as before.
  bool ballistic_faces_pic = true;
  /// With ballistic_faces_pic: every ballistic face takes the PIC value (false, the default: only
  /// those beside a wall or solid along their own axis, Simulation::ballistic_face_beside_support;
  /// everywhere it also took APIC's rotation from the surface faces of a free spinning blob)
  bool ballistic_faces_pic_everywhere = false;
  /// The velocity is extrapolated from the trusted faces after the solve (false: every other
  /// face keeps what the solve, or the extrapolation before it, left there)
  bool extrapolate_after_solve = true;
  /// The extrapolation after the solve reaches ceil(cfl) + 2 layers whatever the step's speed
  /// (false, the default: in scenes without moving bodies as far as the step's fastest velocity
  /// can carry a particle, see Simulation::extrapolation_layers; the same particles bit for bit,
  /// only the far air differs)
  bool extrapolate_cfl_layers = false;
  /// The particles drift half a step with the last step's velocity before the solve and half a
  /// step with the new one after it (drift-kick-drift, second order in time; the default, in
  /// scenes without moving bodies, which keep the whole drift); false: the whole step's drift
  /// after the solve (symplectic Euler, the default before slosh11). With it free fall conserves
  /// energy exactly, so line 15's small moves show in the total energy: line15_energy's default
  /// pays them (docs/particles.md, "Sloshing" and "Line 15's energy paid: the defaults (slosh11)").
  bool split_advection = true;
  /// After the extrapolation, the air cells beside the liquid get a divergence-free velocity
  /// (divergence_free_air_velocity; off: the extrapolated averages as they are). A measurement
  /// switch (docs/particles.md "Sloshing"): it halves the liquid's volume loss without the density
  /// projection but does not lower the sloshing tank's energy rise.
  bool divergence_free_air = false;
  /// With divergence_free_air: also the liquid's surface cells (centre within one dx below the
  /// level set) whose outer face is not trusted, so the solve's value there was replaced by the
  /// extrapolation (divergence_free_air_velocity's liquid_reach). A measurement switch
  /// (docs/particles.md "Sloshing"): it removes the compression of the surface band that the
  /// density projection answered, but not the sloshing tank's energy rise.
  bool divergence_free_surface_cells = false;
  /// false: the density projection runs on the seeded particles only (before frame 0), not in
  /// the steps (line 15). A measurement switch (docs/particles.md "Sloshing").
  bool density_projection_in_steps = true;
  /// What the density projection (of the seeded particles and in the steps) does with a deficit
  /// on the liquid side of the surface band (1/2 <= T_c < 0.999): by default (`all`) corrects it;
  /// `none` and `beyond_dead_band` are measurement switches (docs/particles.md "Sloshing": the
  /// dead band passes the 2D sloshing tank with split_advection and the divergence-free surface
  /// cells, but still water and the floating box then move more than their bounds allow).
  SurfaceDeficits density_projection_surface_deficits = SurfaceDeficits::all;
  /// With SurfaceDeficits::to_solve: the deficits e_c the density projection listed (surface
  /// band, liquid side) become the next solve's divergence source d_c = gain e_c / dt (eq. (8) /
  /// (24) with W_L^p G^T W_F^u u = -W_L^p d; docs/derivations.md "volume feedback"), so the
  /// velocity closes them and its energy shows in the solve's column of the ledger. A measurement
  /// switch (docs/particles.md, "Volume correction through the solve"); 0: listed, not used.
  double volume_source_gain = 1.0;
  /// (docs/derivations.md, departures item 15) A liquid that touches nothing (more than a cell
  /// from every face of the domain and from every solid: a drop in flight, also inside a
  /// container) keeps its centre of mass through line 15's moves
  /// (correct_volume; docs/particles.md "A drop in flight: line 15 may not carry it"). false:
  /// the moves may carry it (the behaviour before; a comparison switch).
  bool line15_keeps_free_centre = true;
  /// (docs/derivations.md, departures items 16 and 18) A wall face that holds no liquid (no
  /// particle mass at the step's transfer, no liquid in the cell beside it) and lies within
  /// air_wall_layers layers of the extrapolation from a trusted face keeps the extrapolated air
  /// velocity after the solve instead of the wall's zero: the wall stops a particle when it
  /// reaches it (the advection's clamp), not a cell before. The zero read there slowed the drift
  /// of liquid still in flight towards a wall that the solve had not seen, while the particles
  /// kept the velocity of that flight: potential energy not lost that the kick had paid for
  /// (viscous-pour-3d's landing, docs/particles.md "The landing frame of a viscous pour" and its
  /// second form). Wall faces farther from the trusted faces keep the zero (item 16 as merged
  /// freed them all, and splash particles carried by the deeper extrapolation piled up at the far
  /// walls: dam-break-2d lost 1.44 % of its volume). false: every wall face zero (before pour18).
  bool air_walls_extrapolated = true;
  /// (docs/derivations.md, departures item 18) The wall faces air_walls_extrapolated frees: those
  /// within this many layers of the extrapolation from a trusted face (steps of one face along
  /// one axis), whatever depth the extrapolation reaches; their values are then the same bits
  /// for any depth. 0: none. A measurement switch (bench_energy_regain's air-walls-N).
  int air_wall_layers = 2;
  /// Measure the energy change of every stage (energy_ledger()): several extra sweeps over the
  /// faces and particles per step, so off unless a diagnosis asks for it.
  bool energy_ledger = false;
  /// Every face a particle reads after the solve (grid_to_particles, the advection's path, the
  /// solid faces interpolated from them) holds the extrapolated velocity: a particle that would
  /// read a face the extrapolation did not reach is transferred and moved again after a deeper
  /// extrapolation (Simulation::extend_extrapolation; docs/particles.md "Velocity
  /// extrapolation"). false: such faces keep what the solve left there (the behaviour before
  /// particles7; a comparison switch).
  bool extend_to_every_read = true;
  /// A test switch: the faces the extrapolation did not reach stay NaN while the particles read
  /// the velocity (no fallback to the solve's value when even the deepest extrapolation cannot
  /// reach them; with extend_to_every_read off, no deeper extrapolation either), so a particle
  /// that reads one fails the step's finite check (tests/validation/test_unreached_faces.cpp).
  bool poison_unreached_faces = false;
  /// A test switch: the extrapolation after the solve reaches every face it can (as many layers
  /// as the face lattices' diameter), whatever the step's speed.
  bool extrapolate_everywhere = false;
  /// A test switch: n > 0: the extrapolation after the solve reaches n layers whatever the step's
  /// speed (scenes without moving bodies), so that the guards of the particles' reads
  /// (extend_to_every_read: advect and, with split_advection, the next first half drift) must
  /// extend it (tests/validation/test_unreached_faces.cpp); 0: the step's reach.
  int extrapolation_layers = 0;
  /// Whether the potential energy the moves of line 15 (correct_positions and the density
  /// projection) add is paid by the liquid's kinetic energy (Line15Energy; docs/particles.md,
  /// "Line 15's potential energy paid by the kinetic energy (slosh9)"). Default `balance` since
  /// slosh11 (with line15_carry_debt): line 15 never adds energy over a run; `free` is the
  /// behaviour before.
  Line15Energy line15_energy = Line15Energy::balance;
  /// With `balance` / `balance_local`: what the kinetic energy cannot pay (a rise larger than it,
  /// as in a liquid nearly at rest) stays owed (the credit may turn positive) and is paid by the
  /// next drops and the later motion, instead of being dropped (false: dropped, slosh9's form).
  /// On by default (docs/particles.md, slosh11: the floating box's pool at rest).
  bool line15_carry_debt = true;
  /// With `balance`: line 15 lifts the liquid only by what it can pay. When its moves would raise
  /// the potential energy by more than the account's credit and the liquid's relative kinetic
  /// energy hold, every particle's move is scaled back by one factor so that the rise equals
  /// that (docs/derivations.md departures item 17): a liquid held at rest out of equilibrium (packed against a
  /// jammed raft of bodies) keeps its packing instead of being lifted for free every step.
  /// false: the moves stay whole and the unpaid rise is a debt (line15_carry_debt).
  bool line15_lift_within_energy = true;
  /// Line15Energy::balance_local's neighbourhoods: boxes of (2 reach + 1)^Dim cells
  int line15_pay_reach = 1;
  /// (docs/derivations.md departures item 25, rise26) Line 15's density projection leaves the
  /// error of every cell whose centre lies closer than this many dx to a moving body (at its new
  /// pose) uncorrected. There the particle level set cut by the body and the particles' splat
  /// disagree by the body's sweep of the step (an excess under a rising box, a deficit over it),
  /// and correcting it lifted liquid past the body every step: about the energy the body's
  /// buoyancy releases, which line 15's payment took from the flow, so a light box released near
  /// the floor stalled in 3D (check25; docs/particles.md "A rising body and line 15's payment").
  /// 0: every cell corrected. Scenes without moving bodies never read it. Off by default (0):
  /// the hold also leaves the liquid that a moving container carries without its volume
  /// correction (hollow-spheres-inviscid-3d's liquid volume drifted up to 10.4 % and ended at
  /// -4.1 %, against 3.3 % and -0.04 % without it; docs/particles.md "A rising body and line
  /// 15's payment"); 1.5 is the reach that lets the box rise (the tests' opt-in).
  double density_held_beside_moving_bodies = 0.0;
  /// A test switch: false makes the per-step passes that follow the liquid and the moving bodies
  /// dense again (issue 20, docs/benchmarks.md "eleventh part"): the faces in solids searched in
  /// the whole union's box every step with every shape's normal evaluated, the liquid level
  /// set's extension into the solids over the solids' box and its negative points searched over
  /// the lattice. The same results either way (tests/unit/sim/test_restricted_passes.cpp).
  bool restricted_passes = true;
  /// A test switch (band24): false keeps P's fallback density rho_0 on every face of the
  /// densities' storage (written whole in frame 0) instead of +0 outside the faces the last
  /// diagonal filled. The same results either way (docs/derivations.md, "Passes restricted to
  /// boxes", "The faces' densities +0 beyond their layers").
  bool densities_zero_outside = true;
  /// A measurement switch: false makes the liquid solve's operator allocate its face-, cell- and
  /// stress-sized vectors per step instead of keeping them in stokes_workspace_ (the band is
  /// used either way). The same results either way (docs/preconditioners.md section 39).
  bool kept_solve_storage = true;
};

/// Energy changes of the liquid (and the moving bodies) per stage of the step, summed over a
/// frame's steps, in J (2D: J per metre of depth). Kinetic energy is measured on the particles
/// (1/2 m |v|^2) and on the faces (1/2 m_f u_f^2 with the face masses of particles_to_grid, and
/// the bodies' kinetic energy), potential energy on the particles (-m g . x) and the dynamic
/// bodies' centres of mass. Their sum is the frame's change of kinetic + potential energy.
struct EnergyLedger {
  double to_grid = 0.0;             ///< particles_to_grid: face KE - particle KE
  double forces_and_solve = 0.0;    ///< gravity, the solve (eq. (8) / (24)): KE after - before
  double velocity_extension = 0.0;  ///< trusted faces, extrapolation, walls, solids (face KE)
  double to_particles = 0.0;        ///< grid_to_particles: particle KE - face KE
  double advection = 0.0;           ///< advect_particles and the bodies' positions: PE change
  double position_correction = 0.0;  ///< correct_positions: PE after - before
  double density_projection = 0.0;   ///< project_particle_density: PE after - before
  double total() const {
    return to_grid + forces_and_solve + velocity_extension + to_particles + advection +
           position_correction + density_projection;
  }
};

/// Dimension-erased interface used by the application (runner) and tests.
class AnySimulation {
 public:
  virtual ~AnySimulation() = default;
  /// Statistics of the current state (frame 0 before any step).
  virtual FrameStats current_stats() const = 0;
  /// Advances to the next frame time with CFL-limited substeps that land exactly on it, and
  /// returns that frame's statistics. Throws SimulationError on a non-finite state or a solver
  /// breakdown.
  virtual FrameStats advance_frame() = 0;
  /// Gravitational potential energy of the liquid particles, -sum_p m_p g . x_p (J; 2D: J per
  /// metre of depth), zero at the origin; with the kinetic energy of FrameStats it gives the
  /// total energy that a liquid in a static container must never gain.
  virtual double liquid_potential_energy() const { return 0.0; }
  /// The energy ledger of the last frame (advance_frame): all zero before the first, and unless
  /// the simulation was made with StageSwitches::energy_ledger.
  virtual EnergyLedger energy_ledger() const { return {}; }
  /// The oracle (reference/coupling/system_export.hpp): during the next advance_frame only, hand
  /// the coupled system of eq. (24) of that frame's step `step` (1 = its first step) to `sink`.
  /// The sink is not called when that step does not exist or has no coupled solve (no moving
  /// body next to a liquid). Simulations without coupled steps ignore the request.
  virtual void request_system_export(int step, std::function<void(const SystemExport&)> sink) {
    (void)step;
    (void)sink;
  }

  // Checkpoints and interruption (the application writes the bytes to files, docs/checkpoints.md)
  /// The whole state needed to continue bit for bit, as plain bytes; empty for a simulation
  /// that cannot be checkpointed.
  virtual std::vector<char> save_state() const { return {}; }
  /// Restores a state of save_state() into a simulation built from the same scene; throws
  /// InputError on bytes that do not fit it.
  virtual void load_state(const std::vector<char>& bytes);
  /// While *flag is non-zero, advance_frame stops after the step it is in (a step boundary) and
  /// returns with mid_frame() true; the next advance_frame finishes that frame. Null: never.
  /// The flag may be set from a signal handler.
  virtual void set_stop_flag(const volatile std::sig_atomic_t* flag) { (void)flag; }
  /// True when the last advance_frame stopped at a step boundary before the frame's end.
  virtual bool mid_frame() const { return false; }
};

/// Algorithm 1 for one scene: liquids (particles, eq. (8) with or without stress unknowns,
/// herschel-bulkley liquids by Algorithm 2), static, dynamic and kinematic bodies with
/// frictional contact, and the coupled solve of the scene's scheme (section 6).
template <int Dim>
class Simulation : public AnySimulation {
 public:
  explicit Simulation(const SceneDesc& scene, const StageSwitches& switches = {});
  FrameStats current_stats() const override { return stats_; }
  FrameStats advance_frame() override;
  double liquid_potential_energy() const override;
  EnergyLedger energy_ledger() const override { return ledger_; }
  void request_system_export(int step, std::function<void(const SystemExport&)> sink) override {
    export_step_ = step;
    export_sink_ = std::move(sink);
    // the export reads W_F^s, which coupled steps without stress solves do not keep
    // (lean_coupled_weights): the weights of the current state are made again by the next
    // step (the same values), this time with it
    if (coupled_ && coupled_in_.solids.fluid_stress.size() == 0) liquid_weights_current_ = false;
  }
  std::vector<char> save_state() const override;
  void load_state(const std::vector<char>& bytes) override;
  void set_stop_flag(const volatile std::sig_atomic_t* flag) override { stop_ = flag; }
  bool mid_frame() const override { return mid_frame_; }

  // The current state, read-only (pictures: render_view in reference/viz/render.hpp).
  const SceneDesc& scene() const { return scene_; }
  double time() const { return time_; }
  /// Frames completed (0 before the first advance_frame).
  int frame() const { return frame_; }
  const MacGrid<Dim>& grid() const { return grid_; }
  const std::array<BoundaryType, 2 * Dim>& boundary() const { return boundary_; }
  const Particles<Dim>& particles() const { return particles_; }
  /// Liquid signed distance of the particles (negative inside) on half_lattice(grid()), as a
  /// frame's end (and the set-up) leaves it; empty while a frame is stopped between two steps
  /// (a step releases it after its weights: release_liquid_phi). Every lattice point's value,
  /// made on demand from the band the level set is stored in (liquid_phi_; a lattice-sized
  /// vector per call).
  VectorX liquid_phi() const { return liquid_phi_.materialise(); }
  /// The weights of the last step (W_F^u, W_L^p, W_L^u, P) for diagnosis; at a frame's end
  /// those of the final state (made here when the frame's end left them to the next step:
  /// complete_frame_end_weights).
  /// (band24) With restricted passes and the matrix-free back end P (face_density) is +0 instead
  /// of rho_0 on the faces beyond the layers its last diagonal filled, where W_L^u = +0
  /// (density_zero_record()).
  const PressureWeights& weights() const {
    if (liquid_weights_pending_) const_cast<Simulation*>(this)->complete_frame_end_weights();
    return weights_;
  }
  /// The inclusive box of `axis`'s face coordinates outside which no face off the walls has
  /// W_F^u = 0 (from the box of the solids' negative lattice points; lo > hi: none), the faces
  /// apply_wall_and_solid_velocities visits (docs/derivations.md, "Passes restricted to boxes").
  std::pair<VecI<Dim>, VecI<Dim>> solid_face_box(int axis) const;
  /// (tests, band18) With `on`, every solve given the step's liquid band checks, over every
  /// face, that its starting velocity is +-0 outside the band's speed boxes (the promise
  /// weighted_face_speed relies on): solves seen, solves with the promise, faces the boxes
  /// left out and those of them with a non-zero velocity, summed over the solves.
  /// (tests, band24) The densities' record: whether weights().face_density is +0 outside
  /// `kept` (the face ranges its last diagonal filled), and how often a solve found W_L^u
  /// outside them and wrote rho_0 there instead.
  struct DensityZeroRecord {
    bool zero_outside = false;
    std::vector<std::pair<long, long>> kept;
    long fallbacks = 0;
  };
  DensityZeroRecord density_zero_record() const {
    DensityZeroRecord r;
    r.zero_outside = density_spans_zero_ && density_spans_data_ == weights_.face_density.data();
    r.kept = density_spans_.kept;
    r.fallbacks = density_zero_fallbacks_;
    return r;
  }
  struct SpeedBoxCheck {
    bool on = false;
    long solves = 0, promised = 0, left_out = 0, nonzero_outside = 0;
  };
  void check_speed_boxes(bool on) { speed_box_check_.on = on; }
  const SpeedBoxCheck& speed_box_check() const { return speed_box_check_; }
  /// Face velocities (MacGrid face numbering).
  const VectorX& velocity() const { return u_; }
  /// Cell pressures of the last solve (Pa; zero before the first step).
  const VectorX& pressure() const { return pressure_; }
  /// (band23) While it holds pressure()'s storage, pressure() is +0 outside the cells this
  /// record lists (the last coupled solve's DOF cells); tests.
  const ZerosOutsideCells& pressure_cells() const { return pressure_cells_; }
  /// eta per cell: the liquids' viscosity, or for herschel-bulkley liquids the effective
  /// viscosity of the last solve (Pa s).
  const VectorX& cell_eta() const {
    if (cell_eta_pending_) update_cell_eta(/*stress_eta_made=*/false);
    return cell_eta_;
  }
  /// The static bodies' shapes (fixed for the whole run).
  const std::vector<ShapePtr<Dim>>& static_shapes() const { return solid_shapes_; }
  /// The moving bodies with their contacts (null in scenes without dynamic or kinematic bodies).
  const RigidWorld<Dim>* rigid_world() const { return rigid_.get(); }
  /// Particles transferred or moved again after a deeper extrapolation since the start
  /// (StageSwitches::extend_to_every_read), counted once per pass; for tests.
  long reread_particles() const { return reread_particles_; }
  /// Faces in solids that constrain_velocity_in_solids left out (deep in a fixed solid, far from
  /// the moving bodies: their value stays +0) since the start; for tests.
  long constrained_faces_left_out() const { return constrained_left_out_; }
  /// The wall faces beside air that kept their extrapolated velocity in the last step
  /// (ascending; air_walls_), and the wall faces the last step asked about them (those within
  /// reach of the trusted boxes: apply_wall_and_solid_velocities); for tests.
  const std::vector<int>& air_walls() const { return air_walls_; }
  long wall_faces_asked() const { return wall_faces_asked_; }
  /// Whether the last frame's end left W_L^p, W_L^u to be made when read (weights(): see
  /// liquid_volume_from_phi); for tests.
  bool frame_end_weights_pending() const { return liquid_weights_pending_; }
  /// Of those, the particles moved again in first half drifts (drift_guarded).
  long drift_reread_particles() const { return drift_reread_particles_; }

 private:
  /// One step of Algorithm 1 of length dt: the liquid with its solids and bodies (the coupled
  /// solve when bodies move), or for scenes of bodies without liquid the body lines 3, 6, 8,
  /// 10, 12 and 13 through RigidWorld.
  void step(double dt);
  // The stages of step, in Algorithm 1's order.
  /// Lines 1-3: APIC particles to grid, gravity on the faces that carry mass and on the
  /// dynamic bodies.
  void particles_to_grid_with_forces(double dt);
  /// Lines 4-5: the solid weights at the bodies' pose and the liquid weights (unless the end of
  /// the last frame left them current), and the density diagonal P.
  void update_step_weights();
  /// u* extended kAirVelocityLayers faces beyond the faces that carry mass (the surface's b1, b2
  /// read them).
  void extrapolate_into_air();
  /// Lines 6-12: solve_coupled with moving bodies, solve_liquid otherwise, timed.
  void solve_step(double dt);
  /// The faces whose solved velocity is fed back to the particles: W_F^u > 0 and W_F^u W_L^u
  /// (unclamped) >= kTrustedLiquidFaceFraction, or mass outside the liquid weights.
  void trusted_faces(std::vector<char>& trusted) const;
  /// One face of trusted_faces (weights of the step's start).
  bool trusted_face(int f) const;
  /// Layers of the extrapolation after a step of dt: the reach of the step's fastest velocity in
  /// faces (docs/particles.md "Velocity extrapolation"), at most ceil(cfl) + 2 (always that with
  /// moving bodies).
  int extrapolation_layers(double dt) const;
  /// The solved velocity extrapolated from the trusted faces, extrapolation_layers(dt) deep.
  void extrapolate_from_trusted_faces(double dt);
  /// Walls: zero normal velocity (but the walls beside air, StageSwitches::
  /// air_walls_extrapolated); fully solid faces: the solid's velocity; then
  /// constrain_velocity_in_solids.
  void apply_wall_and_solid_velocities();
  /// The wall faces that kept their extrapolated velocity in the step's
  /// apply_wall_and_solid_velocities (ascending): no particle mass at the step's transfer, no
  /// liquid in the cell beside them, a trusted face within air_wall_layers layers (item 18). They are air faces from then on: a deeper extrapolation
  /// (extend_extrapolation) fills them and line 15's payment scales them with the air
  /// (rescale_face_velocity).
  std::vector<int> air_walls_;
  long wall_faces_asked_ = 0;
  /// The air cells beside the liquid made divergence-free (StageSwitches::divergence_free_air).
  void divergence_free_air();
  /// Whether the faces the extrapolation did not reach are marked (NaN) while the particles read
  /// the velocity (extend_to_every_read or poison_unreached_faces).
  bool guards_reads() const;
  /// the capacity of the buffers every step keeps, given at the set-up (heap placement)
  void reserve_step_buffers();
  /// The faces the extrapolation after the solve left unreached get the values of one twice as
  /// deep (from the solve's velocity, reached_u_), then the walls' and solids' velocities; faces
  /// already reached keep their values bit for bit. Returns false once the extrapolation reaches
  /// every face it can (then unreached faces hold the solve's value, unless poisoned).
  /// `drift`: for the next step's first half drift (drift_guarded): from the trusted faces the
  /// step kept (drift_trusted_), and the deeper values then scaled as line 15's payments since
  /// scaled u_ (drift_rescales_).
  bool extend_extrapolation(bool drift = false);
  /// Whether the next step's first half drift reads u_ through the guard of advect (the faces
  /// the extrapolation did not reach NaN, a particle that reads one moved again after a deeper
  /// extrapolation), so that the extrapolation after the solve needs only the step's reach:
  /// split_drift with extend_to_every_read, without moving bodies, divergence_free_air or
  /// Line15Energy::balance_local (whose payment scales u_ face by face).
  bool drift_guarded() const;
  /// The guard's state for the next first half drift dropped (its memory back to the heap).
  void drop_drift_guard();
  /// drift_resolved_: the velocity the next first half drift would read through its guard with
  /// every face extended (for a checkpoint: the resumed drift reads it bit for bit as the
  /// guarded one reads u_ and its deeper extrapolations).
  void resolve_drift_velocity();
  /// Line 13: the bodies' poses (coupled scenes) and the particles' SolidField at the new pose.
  void move_bodies(double dt);
  /// The particles' SolidField from the static shapes and the posed moving bodies.
  void rebuild_solid_field();
  /// Line 14: grid to particles (APIC) and RK2 advection.
  void advect(double dt);
  /// Whether the step splits the particles' drift around the kick (StageSwitches::split_advection;
  /// scenes with moving bodies keep the whole drift after the solve, as the bodies do).
  bool split_drift() const;
  /// Line 14's first half under the split: half a step through the last solved velocity.
  void first_half_drift(double dt);
  /// Line 15: position correction and the particle density projection (when enabled).
  void correct_volume(double dt);
  /// Frame 0's state on the grid and its statistics (the constructor, again after settle).
  void frame_zero();
  /// particles.settle_steps: `steps` whole steps before t = 0, the liquid's and the dynamic
  /// bodies' velocities zeroed before each (static and kinematic bodies at the scene's pose),
  /// then the initial velocities given back.
  void settle(int steps);
  /// StageSwitches::line15_energy: takes `gain` (J, > 0) of potential energy that line 15 added
  /// from the liquid's kinetic energy (uniform scaling of the particles' v and c; all of it if
  /// the kinetic energy holds less)
  void pay_line15_energy(double gain);
  /// StageSwitches::line15_lift_within_energy: line 15's moves since `before` scaled back so that
  /// the potential energy they add is what the account and the kinetic energy can pay; returns
  /// the liquid's potential energy after it (liquid_potential_energy())
  double limit_line15_lift(const std::vector<Vec<Dim>>& before, double potential_before);
  /// Line 15's move of one particle from `from` to `to`, across a periodic face taken as the
  /// shortest one (a move that wrapped is the small step it was, not a jump of the domain's
  /// length; exactly `to - from` where nothing wrapped)
  Vec<Dim> line15_move(const Vec<Dim>& from, const Vec<Dim>& to) const;
  /// True when gravity has a component along a periodic axis: there the potential energy
  /// -m g.x jumps by m |g_a| L when a particle wraps, so line 15's change is summed over its moves
  /// (line15_potential_change) instead of taken as a difference of liquid_potential_energy()
  bool gravity_along_periodic_axis() const;
  /// Line 15's potential energy change since `before`, -sum_p m_p g.line15_move(before_p, x_p)
  double line15_potential_change(const std::vector<Vec<Dim>>& before) const;
  /// Line15Energy::balance_local: `gain` taken from the particles near line 15's rises, from
  /// the positions before line 15's moves (docs/particles.md, slosh11)
  void pay_line15_energy_locally(double gain, const std::vector<Vec<Dim>>& before);
  /// Line15Energy::balance: line 15's summed potential energy change not yet paid (<= 0, J)
  double line15_credit_ = 0.0;
  /// The particles' positions before line 15's moves (balance_local's payment, item 17's scaling)
  std::vector<Vec<Dim>> line15_before_;
  /// The energy ledger (only with StageSwitches::energy_ledger; otherwise nothing is measured):
  /// adds now() - (the energy after the previous stage) to stage and makes now() the energy
  /// after this one.
  template <class Energy>
  void account(double& stage, Energy now) {
    if (!switches_.energy_ledger) return;
    const double e = now();
    stage += e - ledger_energy_;
    ledger_energy_ = e;
  }
  /// The energy ledger starts a new account from now() (a change of the energy measured).
  template <class Energy>
  void restart_ledger(Energy now) {
    if (switches_.energy_ledger) ledger_energy_ = now();
  }
  /// Face kinetic energy plus, in coupled scenes, the moving bodies'.
  double grid_and_body_kinetic_energy() const;
  /// Kinetic energy on the faces, sum 1/2 m_f u_f^2 (face masses of the last particles_to_grid).
  double face_kinetic_energy() const;
  /// Kinetic energy of the particles, sum 1/2 m_p |v_p|^2.
  double particle_kinetic_energy() const;
  /// The liquid's mass-weighted mean velocity vbar and its kinetic energy relative to it,
  /// KE_rel = sum_p 1/2 m_p |v_p - vbar|^2 (J; 2D: J/m): what pay_line15_energy can take
  struct RelativeMotion {
    bool has_mass = false;  ///< false: no particle mass (mean and kinetic are zero)
    Vec<Dim> mean = Vec<Dim>::Zero();
    double kinetic = 0.0;
  };
  RelativeMotion relative_motion() const;
  /// Potential energy of the dynamic bodies, -sum m g . x_c (x_c the centre of mass).
  double body_potential_energy() const;
  /// The body part of a step: RigidWorld::step, with its statistics added to the frame's.
  void step_bodies(double dt);
  /// The CFL-limited step size: min(max_dt, cfl dx / max speed), and with moving bodies at most
  /// kBodyCellFraction dx / (largest |v| + |omega| R of a body point).
  double cfl_dt() const;
  /// Liquid level set and the liquid weights W_L^p, W_L^u from the particles (lines 4-5).
  /// `stress` false: without W_L^s and eta per stress DOF (read by the solve only), for a
  /// frame's end whose weights no step reuses (split_drift: the next step's first half drift
  /// moves the particles and its weights are made again). `volume` false: liquid_volume_ is left
  /// as it was (it is read at a frame's end only: fill_state_stats).
  void update_liquid_weights(bool stress = true, bool volume = true);
  /// eta per cell from the particles (the render's colour and the checkpoint; update_liquid_weights'
  /// part): `stress_eta_made` when stress_eta_ was just made from the same particles. Const: a
  /// frame's end may leave eta per cell pending, made when first read (cell_eta(), save_state)
  /// into the mutable cell_eta_ from the particles, which have not moved since.
  void update_cell_eta(bool stress_eta_made) const;
  /// A frame's end whose weights no step reuses (split_drift) and whose first CFL limit is
  /// max_dt whatever the trusted faces (frame_end_dt_is_max): from the level set just made, the
  /// reported volume only (the same values as update_liquid_weights(false, true)); W_L^p, W_L^u and
  /// eta per cell are left pending until read (weights(), cell_eta(), save_state) or made anew
  /// by the next step's weights (docs/benchmarks.md, particles18).
  void liquid_volume_from_phi();
  /// update_liquid_weights' two parts: the level set (liquid_phi_, liquid_band_) and what is
  /// made from it.
  void make_liquid_phi();
  void liquid_weights_from_phi(bool stress, bool volume);
  /// Whether cfl_dt would return max_dt (or the bodies' limit) with any set of trusted faces:
  /// the particles' speed and the largest |u| on the faces with W_F^u > 0 (a bound of the
  /// trusted faces' speed) already allow max_dt. Reads the band of the frame's end level set
  /// (made first).
  bool frame_end_dt_is_max() const;
  /// The pending parts of a frame's end (liquid_volume_from_phi) as update_liquid_weights(false,
  /// true) makes them; the frame's timing is kept.
  void complete_frame_end_weights();
  /// The reported volume with solids (update_liquid_weights, liquid_volume_from_phi): the cell
  /// fractions of the fluid level set max(phi_L, -phi_S) (liquid_phi_ holds phi_L) classified in
  /// the box [liquid_lo, liquid_hi] outside which phi_L is nowhere negative, its values written
  /// into liquid_phi_ in that box (grown by a point with `grow`) when `extend` and undone after.
  double fluid_volume_in_box(const VecI<Dim>& liquid_lo, const VecI<Dim>& liquid_hi, bool grow,
                             bool extend);
  /// On faces whose centre lies inside a solid, removes the velocity component into the solid
  /// relative to the solid's own velocity (v <- v - min((v - v_s).n, 0) n, n the solid's outward
  /// normal, v_s zero for static solids and the body's point velocity for moving ones), so
  /// particles near a solid are not carried into it.
  /// same_pose (the guard's deeper extrapolation, after the bodies moved): the normals and solid
  /// velocities of the step's first call.
  void constrain_velocity_in_solids(bool same_pose = false);
  /// Whether face f lies on a wall of the domain.
  bool wall_face(int f) const;
  /// The faces whose centre lies in a solid (solid_phi_ < 0 there) into solid_faces_, from the
  /// box of the solids' negative points: wherever solid_phi_ is made.
  void find_faces_in_solids();
  /// Appends to `faces` the faces of `axis` whose centre point k (index) of the half lattice has
  /// test(k, index), among those of the box of points [point_lo, point_hi], in face order.
  template <class Test>
  void faces_with_centre(int axis, const VecI<Dim>& point_lo, const VecI<Dim>& point_hi,
                         const Test& test, std::vector<int>& faces) const;
  /// Sections 3.1.2, 4.4.6 with moving bodies: W_F^u, W_F^s and the solid level set from every
  /// body at its current pose (fixed bodies included, as one-way bodies), shrunk by zeta, and the
  /// SolidField of the particles (static shapes and posed bodies).
  void update_moving_solids();
  /// Releases the liquid level set before the solve: nothing in the rest of the step reads it
  /// (unless divergence_free_air), and the next weights make it again.
  void release_liquid_phi();
  /// Lines 6-12 of Algorithm 1 with moving bodies next to a liquid: contacts, the coupled
  /// pressure / viscosity / contact solve of the scene's scheme (section 6), and the new body
  /// velocities (eq. (21)). Updates u_ to the solved face velocities.
  void solve_coupled(double dt);
  /// Velocity of the solid at a point x inside the solids: the point velocity of the moving
  /// body whose (unshrunk) SDF is smallest there when that is a moving body, zero otherwise.
  /// `bounds` are the bodies' bounds at their pose (body_bounds: posed once for a pass over many
  /// points instead of once per body and point).
  Vec<Dim> solid_velocity(const Vec<Dim>& x, const std::vector<Box<Dim>>& bounds) const;
  /// RigidBody::bounds of every body at its pose (empty without bodies).
  std::vector<Box<Dim>> body_bounds() const;
  /// The state of a checkpoint, every field once, in order (reference/core/state_io.hpp): what
  /// evolves during a run. Everything else is rebuilt from the scene (constructor) or derived
  /// from these fields (load_state recomputes the weights). A new evolving member goes here.
  template <class Archive>
  void state_fields(Archive& a);
  /// Throws SimulationError if the state holds a non-finite value. Without `solve_outputs` the
  /// pressure and the stress are not read (a check after the stages that follow the solve, which
  /// do not write them: the solve's check covered them).
  void check_finite(const char* after, bool solve_outputs = true) const;
  /// Fills the frame statistics that describe the state (volume, particles, energy, probes).
  void fill_state_stats(FrameStats& s) const;
  /// Lines 7-11 of Algorithm 1 for the liquid beside static solids: the solves of
  /// solve_sequence(scheme) (run_solve_sequence, solve_sequence.hpp) on u_, their statistics
  /// added to stats_. Herschel-bulkley liquids (section 5) run Algorithm 2 around the viscous
  /// solve (staggered_iterations rounds), started from the previous step's shear rate where there
  /// is one (departure: line 1 as printed only in the first step and on newly active DOFs;
  /// docs/non-newtonian.md, departure 4).
  void solve_liquid(double dt);
  /// Algorithm 2's model for the current weights (W_F^s, W_L^s, the liquids' mass fractions).
  NonNewtonianViscosity<Dim> non_newtonian_model() const;
  /// The residuals of one step's viscosity rounds into stats_ (SolverStats::viscosity_residuals).
  void record_viscosity_rounds(const std::vector<double>& residuals);
  /// Adds one solve's iterations, residual and DOF counts to stats_; throws SimulationError on a
  /// breakdown (`what` names the solve).
  void record_solve(const PcgResult& pcg, long pressure_dofs, long stress_dofs, const char* what);
  /// Marks the frame unconverged and lists the solve `what` with its iterations and residual.
  void note_unconverged(const std::string& what, long iterations, double residual);

  // the scene, the grid and its boundary
  SceneDesc scene_;
  MacGrid<Dim> grid_;
  SampleLattice<Dim> lattice_;
  std::array<BoundaryType, 2 * Dim> boundary_{};
  Vec<Dim> gravity_;
  double reference_density_ = 1000.0;  ///< the first liquid's density (P of eq. (8) in air)
  // solids: the static bodies' shapes (fixed for the whole run); the particles' SolidField and
  // the solid level set on the half lattice, rebuilt at every pose when bodies move
  std::vector<ShapePtr<Dim>> solid_shapes_;
  SolidField<Dim> solids_;
  /// the moving bodies alone at their pose (rebuild_solid_field; empty without moving bodies or
  /// with StageSwitches::density_held_beside_moving_bodies 0, the default):
  /// the density projection of line 15 leaves the cells beside them uncorrected (departures item 25)
  SolidField<Dim> moving_solids_;
  /// (empty outside update_step_weights in coupled scenes: made again at every pose)
  VectorX solid_phi_;
  /// Inclusive box of the lattice points where solid_phi_ may be < 0 (lo > hi: none); set
  /// wherever solid_phi_ is: the velocity constraints in the solids visit only its faces.
  VecI<Dim> solid_lo_ = VecI<Dim>::Zero(), solid_hi_ = -VecI<Dim>::Ones();
  /// In coupled scenes between update_moving_solids and the end of update_liquid_weights: the
  /// solids' union in the bodies' box, solid_phi_ then empty (invalid: solid_phi_ holds it)
  BoxedUnionPhi<Dim> solid_box_phi_;
  /// The solids' union at lattice point k, from the union kept per body
  /// (solid_scratch_.union_parts, between update_moving_solids and the end of
  /// update_liquid_weights when solid_weights kept it so), solid_box_phi_ or solid_phi_.
  double solid_phi_at(int k) const {
    if (solid_scratch_.union_parts.valid()) return solid_scratch_.union_parts(k);
    return solid_box_phi_.valid() ? solid_box_phi_(k) : solid_phi_[k];
  }
  /// Whether the solids' union is < 0 at lattice point k (solid_phi_at(k) < 0.0, without the
  /// union's far values when it is kept per body).
  bool solid_negative_at(int k) const {
    if (solid_scratch_.union_parts.valid()) return solid_scratch_.union_parts.negative(k);
    return solid_phi_at(k) < 0.0;
  }
  /// The same at lattice point c of index k.
  bool solid_negative_at(const VecI<Dim>& c, int k) const {
    if (solid_scratch_.union_parts.valid()) return solid_scratch_.union_parts.negative(c, k);
    return solid_phi_at(k) < 0.0;
  }
  // moving bodies with contact (scenes with dynamic or kinematic bodies)
  std::unique_ptr<RigidWorld<Dim>> rigid_;
  /// Moving bodies next to a liquid: the coupled step (update_moving_solids, solve_coupled).
  bool coupled_ = false;
  /// The liquid solve's storage kept across steps (the matrix-free operator's face-, cell- and
  /// stress-sized vectors) and the liquid's band of the step (stokes_workspace.hpp; issue 20,
  /// docs/preconditioners.md section 39), given to solve_stokes and the coupled systems.
  /// Declared before every member that could hold a system or an operator (destroyed after
  /// them: an operator gives its storage back when destroyed).
  StokesWorkspace stokes_workspace_;
  /// The workspace with its band set from the boxes update_liquid_weights wrote W_L^p and W_L^u
  /// in (liquid_cell_box_, liquid_face_boxes_), when they are valid for `w`'s vectors (else no
  /// band: the set-up passes over the grid), and the speed boxes outside which the solve's
  /// starting velocity `u_start` is +-0 (band18; LiquidBand::speed_valid).
  StokesWorkspace* stokes_workspace_for(const PressureWeights& w, const VectorX& u_start);
  void check_speed_boxes(const LiquidBand& band, const VectorX& u_start);
  SpeedBoxCheck speed_box_check_;
  /// The coupled step's input, kept across steps so that its grid-sized vectors are reused:
  /// its `solids` are the weights of the last update_moving_solids (whose lattice_phi has moved
  /// to solid_phi_), the rest is filled by solve_coupled.
  CoupledStepInput<Dim> coupled_in_;
  /// Its result, kept likewise: solve_coupled swaps u, pressure and stress with u_, pressure_,
  /// stress_, so the next step's solve writes into the previous step's vectors.
  CoupledSolveResult coupled_out_;
  SolidWeightsScratch<Dim> solid_scratch_;  ///< solid_weights' buffers
  // the weights of eq. (8): W_F^u, W_L^p, W_L^u, P (weights_), W_F^s, W_L^s
  PressureWeights weights_;
  // buffers of update_liquid_weights kept across steps (no grid-sized allocation per step): the
  // lattice-cell sign classes (the liquid level set is extended into the solids in place, see
  // phi_undo_)
  /// the points of liquid_phi_ that update_liquid_weights overwrites in place (the extension
  /// into the solids, then the reported volume's level set) with their values, per thread
  std::vector<std::vector<std::pair<int, double>>> phi_undo_;
  /// the band of the last liquid level set (liquid_phi_on_lattice): its background value and
  /// the box of the points it wrote
  LiquidPhiBand<Dim> liquid_band_;
  LatticeSigns<Dim> liquid_signs_;
  // per-step buffers of the velocity stages: face flags (faces that carry mass, trusted faces)
  // and the faces whose centre lies in a solid (find_faces_in_solids) with their new values in
  // constrain_velocity_in_solids
  std::vector<char> face_flags_;
  /// correct_positions' neighbour lists, kept across steps (speed only; not state)
  PositionCorrectionBuffers correction_buffers_;
  /// The density projection's face-sized displacement, kept across steps (issue 20, p2g21):
  /// 0 outside the spans the last projection wrote, which the next zeroes (KeptZeros).
  KeptZeros density_move_;
  // the guard of the particles' reads (guards_reads): the velocity after the extrapolation
  // (before the faces not reached become NaN; on those the solve's values), a deeper extrapolation's velocity and flags, the particles that read a face
  // not reached, the layers of the last extrapolation
  VectorX reached_u_, extended_u_;
  std::vector<char> extended_flags_, unread_;
  int reached_layers_ = 0;
  // the guard of the next step's first half drift (drift_guarded; valid while drift_guard_): the
  // trusted faces of the step's extrapolation, the faces it and advect's deeper ones reached
  // (reached_u_ and reached_layers_ kept with them), the payments of line 15 that scaled u_
  // since (vbar, s of pay_line15_energy, in order); a restored checkpoint's drift velocity
  bool drift_guard_ = false;
  std::vector<char> drift_trusted_, drift_reached_;
  std::vector<std::pair<Vec<Dim>, double>> drift_rescales_;
  /// u_ <- mean + s (u_ - mean) on every face but the domain's walls (the walls beside air,
  /// air_walls_, included): line 15's payment as
  /// the next step's first half drift reads it (pay_line15_energy, and again after a deeper
  /// extrapolation for that drift: extend_extrapolation)
  void rescale_face_velocity(const Vec<Dim>& mean, double s);
  VectorX drift_resolved_;
  /// The first half drift's copy of u_ (u_ is NaN where the last step did not reach while the
  /// particles drift, then swapped back): kept across steps so that no face-sized vector is
  /// allocated and first touched every step (two23: 4.5-5.7 ms of CPU per step on two threads
  /// on the 64^3 bunny)
  VectorX drift_kept_;
  long reread_particles_ = 0, drift_reread_particles_ = 0;
  std::vector<int> solid_faces_;
  /// per face of solid_faces_: its index in the fixed faces (fixed_faces_, axis after axis), or -1
  std::vector<int> solid_face_fixed_;
  /// The faces whose centre lies in a fixed body (the union's dense parts), per axis in face
  /// order, found once while fixed_faces_key_ (those parts' phi and boxes) is the same
  std::array<std::vector<int>, Dim> fixed_faces_;
  std::vector<std::pair<const VectorX*, std::pair<VecI<Dim>, VecI<Dim>>>> fixed_faces_key_;
  bool fixed_faces_valid_ = false;
  std::vector<int> moving_faces_scratch_;
  /// per fixed face: the static shapes' part of the normal's search (make_solid_field's gradient
  /// over solid_shapes_, which lead solids_): the least distance, its shape and its gradient
  struct FixedFaceFrame {
    double distance = 0.0;
    std::size_t nearest = 0;
    Vec<Dim> normal = Vec<Dim>::Zero();
  };
  std::vector<FixedFaceFrame> fixed_face_frame_;
  /// the boxes of W_L^p and W_L^u (per axis) that the last update_liquid_weights wrote: the
  /// next one zeroes only those (WrittenBox)
  WrittenBox<Dim> liquid_cell_box_;
  std::array<WrittenBox<Dim>, Dim> liquid_face_boxes_;
  /// (huge21) the reported volume's cell fractions (fluid_volume_in_box) kept across steps with
  /// restricted passes: made in reserve_step_buffers with zeros from the kernel, reset where the
  /// last call wrote them (volume_cells_box_): only the liquid's band of it is ever written
  VectorX volume_cells_;
  WrittenBox<Dim> volume_cells_box_;
  /// per fixed face: 1 if every face that the interpolation of the velocity at its centre reads
  /// (each component's 2^Dim stencil of MacGrid::axis_stencil) had W_F^u = 0 (or
  /// was a wall's) while no moving body came near (constrain_velocity_in_solids); built with
  /// the fixed faces, dropped with them
  std::vector<char> fixed_face_deep_;
  /// the rows j of solid_faces_ that the step's constrain_velocity_in_solids evaluates (the
  /// others keep +0, their value already); the call at the same pose and the restore of
  /// extend_extrapolation read the same rows
  std::vector<int> constrained_rows_;
  long constrained_left_out_ = 0;
  /// the shapes of solids_ (static ones first) and their bounds, as make_solid_field has them
  std::vector<ShapePtr<Dim>> solid_field_shapes_;
  std::vector<Box<Dim>> solid_field_boxes_;
  std::vector<double> solid_values_;
  /// per face of solid_faces_ (with the guard of advect): the normal, the solid's velocity and the
  /// face's value before constrain_velocity_in_solids, as the step's first call had them
  struct SolidFaceFrame {
    Vec<Dim> normal, velocity;
    double before = 0.0;
  };
  std::vector<SolidFaceFrame> solid_frame_;
  VectorX stress_fluid_, stress_liquid_;
  bool liquid_weights_current_ = false;  ///< liquid_phi_ and the weights match the particles
  /// After liquid_volume_from_phi: W_L^p, W_L^u (and their classes) are the last step's, not
  /// the frame's end; cell_eta_ is not made yet. Both are cleared by the next weights.
  bool liquid_weights_pending_ = false;
  mutable bool cell_eta_pending_ = false;
  // viscosity (section 3.1): the solves the scheme runs, eta of each liquid, the stress DOF
  // layout, eta per stress DOF and per cell (render)
  SolveSequence sequence_ = SolveSequence::pressure;
  std::vector<double> liquid_eta_;
  StressGrid<Dim> stress_grid_;
  VectorX stress_eta_;
  mutable VectorX cell_eta_;  // (made when read while pending: update_cell_eta)
  // non-Newtonian liquids (section 5): the liquids' models and mass fractions per stress DOF;
  // cell_eta_ is then the effective viscosity of the last solve (its cell-centred diagonal DOFs)
  bool non_newtonian_ = false;
  ViscosityMixture mixture_;
  std::shared_ptr<const SparseMatrix> deformation_rate_;  ///< D of eq. (8), built once
  /// Algorithm 2's start (departure, docs/non-newtonian.md): the shear rate s per stress DOF at
  /// the end of the previous step, NaN where that step had no unknown (line 1 there); empty
  /// before the first step or with solver.viscosity_warm_start off
  VectorX previous_shear_rate_;
  // the liquid: particles, their level set and volume, and the grid fields of the last step
  Particles<Dim> particles_;
  /// the liquid level set on half_lattice(grid_), stored over its band (issue 20, band19): the
  /// box of liquid_band_ grown by kLiquidPhiMargin points, the background outside; the whole
  /// lattice when the passes are not restricted to the band (restricted_passes off, the
  /// divergence_free_air switch, a background below the extension's reach)
  BoxedLattice<Dim> liquid_phi_;
  double liquid_volume_ = 0.0;  ///< sum W_L^p dx^Dim of liquid_phi_ (not extended)
  /// (the faces' densities of particles_to_grid go straight into weights_.face_density)
  VectorX u_, face_mass_, pressure_, stress_;
  /// The faces that take the PIC value this step (ascending) and that value
  /// (pic_velocity_on_faces): lists as long as the ballistic faces beside a support, nothing
  /// face-sized (ballistic_faces_take_pic)
  std::vector<int> pic_faces_;
  std::vector<double> pic_values_;
  /// A face that carries particle mass but lies outside the liquid's level set (W_F^u > 0,
  /// W_L^u = 0, with unreached_faces_keep_u_star): it keeps u* through the solve and hands it to
  /// the particles (trusted_face)
  bool ballistic_face(int f) const;
  /// The ballistic faces' u* from the PIC velocity (StageSwitches::ballistic_faces_pic): after
  /// update_step_weights, which decides W_L^u
  void ballistic_faces_take_pic(double dt);
  bool ballistic_faces_pic() const;
  /// A face that is partly solid, or whose neighbour along its own axis is a wall face or partly
  /// solid: the faces where a ballistic value meets a support that does not fall with it
  bool face_beside_support(int f) const;
  /// face_mass_ > 0 per face, marked after every particles_to_grid: the trust test
  /// (trusted_face), gravity and the extrapolation into air read these flags, so the masses
  /// themselves are dead after them (masses_read_after_solve) and their storage is reused
  std::vector<char> mass_faces_;
  void mark_faces_with_mass();
  /// Boxes of faces per axis (inclusive; empty when some lo > hi), for the passes that follow
  /// the liquid (issue 20)
  struct FaceBoxes {
    std::array<VecI<Dim>, Dim> lo, hi;
  };
  /// One box of FaceBoxes as rows along x: rows() rows of nx faces each, row r's first face
  /// first(r) (face indices of the whole grid); no rows where the box is empty. The rows of the
  /// box in its axis's face lattice (BoxRows, grid/box_rows.hpp) and the axis's face offset.
  struct FaceRows {
    BoxRows<Dim> box;
    int nx = 0, offset = 0;
    int rows() const { return box.rows(); }
    int first(int r) const { return offset + box.first(r); }
  };
  FaceRows face_rows(const FaceBoxes& boxes, int axis) const;
  /// The faces a particle's stencil in particles_to_grid can reach (the cells of the particles'
  /// bounds grown by two, each face lattice's whole axis where it is periodic or the bounds are
  /// not finite): face_mass_ is 0 outside them
  FaceBoxes particle_face_boxes() const;
  /// fn(f) for every face of the boxes, on several threads (rows of each box; fn of distinct
  /// faces must be independent)
  template <class Fn>
  void for_faces_in_boxes(const FaceBoxes& boxes, Fn&& fn) const;
  /// The largest |v[f]| over the faces f of the boxes with keep(f) (0 for none), on several
  /// threads (a maximum: the same bits for any thread count): the CFL limit's trusted faces and
  /// the frame end's bound of them (frame_end_dt_is_max)
  template <class Keep>
  double max_abs_in_boxes(const FaceBoxes& boxes, const double* v, Keep&& keep) const;
  /// the boxes outside which mass_faces_ is 0 (valid for the storage mass_boxes_data_), and
  /// with W_L^u's boxes those outside which no face is trusted; false when not known
  FaceBoxes mass_boxes_;
  const char* mass_boxes_data_ = nullptr;
  bool mass_boxes_valid_ = false;
  bool trusted_boxes(FaceBoxes& boxes) const;
  /// Whether a face of `axis` within `layers` extrapolation layers of the face at `coord` is
  /// trusted (trusted_face): `ball` holds the nonzero offsets of L1 length <= layers
  /// (l1_ball_offsets), `boxes` (when `have_boxes`, trusted_boxes) the boxes outside which no face
  /// is trusted, so a face farther than `layers` from its axis's box along a non-periodic axis is
  /// answered without visiting the ball (the same answers).
  bool trusted_within(int axis, const VecI<Dim>& coord, int layers, const std::vector<VecI<Dim>>& ball,
                      bool have_boxes, const FaceBoxes& boxes) const;
  /// density_diagonal_in_place of the faces' densities that particles_to_grid just wrote
  void density_diagonal_in_place_after_transfer();
  /// particles_to_grid into u_, face_mass_ and weights_.face_density, the densities with
  /// density_spans_ when the passes are restricted (issue 20, kern22)
  void transfer_to_grid();
  /// The faces' densities kept between steps (particles_to_grid's DensitySpans): while
  /// weights_.face_density's storage is density_spans_data_ (with its size), it holds
  /// density_spans_value_ (P's diagonal of a face without a density and not next to one) on
  /// every face outside density_spans_.kept. Only particles_to_grid and the diagonal write that
  /// storage (the solves read it; its swaps into a solve's input and back keep it); any other
  /// storage or value makes the next transfer write every face, as before.
  DensitySpans density_spans_;
  /// (band23) pressure_'s storage is +0 outside these cells while the record holds it (the
  /// coupled solve's DOF cells, or none after frame_zero): the coupled solve's output then
  /// zeroes only the listed cells, and check_finite reads only them. Kept only when the passes
  /// are restricted; forgotten by every other writer of pressure_ (the liquid-only solves,
  /// restore).
  ZerosOutsideCells pressure_cells_;
  const double* density_spans_data_ = nullptr;
  double density_spans_value_ = 0.0;
  /// (band24) the value the storage holds outside density_spans_.kept is +0, not
  /// density_spans_value_: the diagonal's fallback was written on the particles' layers only
  /// (density_spans_.layers), and the storage's other faces are the kernel's zeros or P2G's.
  /// Every reader of P gives the same bits as with rho_0 there while W_L^u = +0 outside those
  /// layers, which densities_before_solve checks before each solve
  bool density_spans_zero_ = false;
  /// (band24) densities_before_solve found W_L^u beyond the layers (or a reader of every face,
  /// the oracle's export): rho_0 was written outside them and the zeros are not used again
  bool density_zero_dropped_ = false;
  /// (band24) the last transfer's mode (densities_zero_mode() when it ran)
  bool density_transfer_zero_ = false;
  long density_zero_fallbacks_ = 0;
  /// (band24) whether a transfer may leave +0 outside the diagonal's layers: restricted passes,
  /// the matrix-free back end (the explicit one's P^-1 is a matrix over every face) and the
  /// switch, until densities_before_solve drops it
  bool densities_zero_mode() const;
  /// (band24) before a solve reads P: where the densities' storage holds +0 outside the
  /// diagonal's layers, checks that W_L^u is +0 outside them (its written boxes within the
  /// layers) and no reader of every face is asked for; otherwise writes rho_0 there (once: the
  /// zeros are dropped for the run)
  void densities_before_solve();
  /// the last transfer used density_spans_ and its diagonal is not written yet
  bool density_transfer_pending_ = false;
  /// Something reads face_mass_ after the solve: the energy ledger's grid kinetic energy.
  bool masses_read_after_solve() const;
  PcgSettings pcg_settings_;
  /// The preconditioner and initial guess of a solve_stokes call with viscosities eta and time
  /// step dt: solver.preconditioner, "auto" resolved by the solve's stiffness
  /// eta_max dt / (rho dx^2) and the grid's largest cell count (choose_preconditioner); the
  /// choice and the stiffness are booked in the frame's solver stats.
  StokesSolveOptions stokes_options(const VectorX& eta, double dt);
  /// The coupled solve's weights carry no stress vectors (StokesWeights::inviscid) and W_F^s is
  /// not kept: the scene has no stress solves and no system export is requested.
  bool lean_coupled_weights() const {
    return sequence_ == SolveSequence::pressure && !export_sink_;
  }
  /// The smallest density of the scene's liquids (kg/m^3; 0 without liquids): the one of the
  /// largest stiffness eta dt / (rho dx^2), which the automatic preconditioner choice reads.
  double smallest_liquid_density() const;
  // time and statistics
  int frame_ = 0;
  double time_ = 0.0;
  FrameStats stats_;
  // diagnosis: stages switched off, and the energy changes per stage of the current frame
  StageSwitches switches_;
  /// SurfaceDeficits::to_solve: the last density projection's listed deficits (cell, e_c), the
  /// next solve's divergence source (volume_source); part of the state (state_fields), so that a
  /// resumed run with that measurement switch continues bit for bit
  std::vector<std::pair<int, double>> volume_errors_;
  /// The divergence source of the step's solve (cell field, 1/s), empty without listed deficits.
  VectorX volume_source(double dt) const;
  EnergyLedger ledger_, frame_ledger_;
  double ledger_energy_ = 0.0;  ///< the energy after the last accounted stage of the step
  /// request_system_export: the step of the next frame whose system goes to the sink
  int export_step_ = 0;
  std::function<void(const SystemExport&)> export_sink_;
  bool mid_frame_ = false;                         ///< advance_frame stopped before the frame's end
  const volatile std::sig_atomic_t* stop_ = nullptr;  ///< set_stop_flag
};


/// Builds the simulation for scene.dim.
std::unique_ptr<AnySimulation> make_simulation(const SceneDesc& scene);
/// The same with some stages switched off (diagnosis only).
std::unique_ptr<AnySimulation> make_simulation(const SceneDesc& scene,
                                               const StageSwitches& switches);

extern template class Simulation<2>;
extern template class Simulation<3>;

}  // namespace monolith
