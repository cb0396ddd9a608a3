#pragma once
/// \file simulation.hpp
/// The time loop of Algorithm 1. Simulation<Dim> owns the grid, particles, solids and solver
/// state of a scene (SceneDesc) and advances it frame by frame; AnySimulation erases the
/// dimension for the application. The state is read through Simulation's const accessors: the
/// pictures (reference/viz/render.hpp) draw it from outside the solver core.

#include <array>
#include <memory>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/coupling/coupling_scheme.hpp"
#include "reference/fluid/herschel_bulkley.hpp"
#include "reference/fluid/pressure_projection.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/grid/boundary.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/grid/stress_grid.hpp"
#include "reference/particles/particles.hpp"
#include "reference/rigid/rigid_world.hpp"
#include "reference/sim/frame_stats.hpp"
#include "reference/sim/scene_desc.hpp"
#include "reference/solvers/pcg.hpp"

namespace monolith {

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
};

/// The solves of lines 7-11 of Algorithm 1 for the liquid, without dynamic bodies.
enum class SolveSequence {
  pressure,   ///< eq. (8) without stress (solve_pressure)
  unified,    ///< eq. (8) in (tau, p) together, reduced stress (solve_stokes)
  decoupled,  ///< section 6.2: pressure, then stress only (p = 0), then pressure again
};

/// The sequence a scheme runs when no body is dynamic: P-C, C-P, PC-iterative, PC-unified ->
/// pressure (viscosity ignored); PV-C, C-PV, PVC-iterative, PVC-unified -> unified;
/// PC-VC-PC-unified -> decoupled. Without viscous liquid (`viscous` false) always pressure.
SolveSequence solve_sequence(CouplingScheme scheme, bool viscous);

/// Algorithm 1 for one scene: liquids (particles, eq. (8) with or without stress unknowns,
/// herschel-bulkley liquids by Algorithm 2), static, dynamic and kinematic bodies with
/// frictional contact, and the coupled solve of the scene's scheme (section 6).
template <int Dim>
class Simulation : public AnySimulation {
 public:
  explicit Simulation(const SceneDesc& scene);
  FrameStats current_stats() const override { return stats_; }
  FrameStats advance_frame() override;
  double liquid_potential_energy() const override;

  // The current state, read-only (pictures: render_view in reference/viz/render.hpp).
  const SceneDesc& scene() const { return scene_; }
  double time() const { return time_; }
  /// Frames completed (0 before the first advance_frame).
  int frame() const { return frame_; }
  const MacGrid<Dim>& grid() const { return grid_; }
  const std::array<BoundaryType, 2 * Dim>& boundary() const { return boundary_; }
  const Particles<Dim>& particles() const { return particles_; }
  /// Liquid signed distance of the particles (negative inside) on half_lattice(grid()).
  const VectorX& liquid_phi() const { return liquid_phi_; }
  /// Face velocities (MacGrid face numbering).
  const VectorX& velocity() const { return u_; }
  /// Cell pressures of the last solve (Pa; zero before the first step).
  const VectorX& pressure() const { return pressure_; }
  /// eta per cell: the liquids' viscosity, or for herschel-bulkley liquids the effective
  /// viscosity of the last solve (Pa s).
  const VectorX& cell_eta() const { return cell_eta_; }
  /// The static bodies' shapes (fixed for the whole run).
  const std::vector<ShapePtr<Dim>>& static_shapes() const { return solid_shapes_; }
  /// The moving bodies with their contacts (null in scenes without dynamic or kinematic bodies).
  const RigidWorld<Dim>* rigid_world() const { return rigid_.get(); }

 private:
  /// One step of Algorithm 1 of length dt: the liquid with its solids and bodies (the coupled
  /// solve when bodies move), or for scenes of bodies without liquid the body lines 3, 6, 8,
  /// 10, 12 and 13 through RigidWorld.
  void step(double dt);
  /// The body part of a step: RigidWorld::step, with its statistics added to the frame's.
  void step_bodies(double dt);
  /// The CFL-limited step size: min(max_dt, cfl dx / max speed), and with moving bodies at most
  /// kBodyCellFraction dx / (largest |v| + |omega| R of a body point).
  double cfl_dt() const;
  /// Liquid level set and the liquid weights W_L^p, W_L^u from the particles (lines 4-5).
  void update_liquid_weights();
  /// On faces whose centre lies inside a solid, removes the velocity component into the solid
  /// relative to the solid's own velocity (v <- v - min((v - v_s).n, 0) n, n the solid's outward
  /// normal, v_s zero for static solids and the body's point velocity for moving ones), so
  /// particles near a solid are not carried into it.
  void constrain_velocity_in_solids();
  /// Sections 3.1.2, 4.4.6 with moving bodies: W_F^u, W_F^s and the solid level set from every
  /// body at its current pose (fixed bodies included, as one-way bodies), shrunk by zeta, and the
  /// SolidField of the particles (static shapes and posed bodies).
  void update_moving_solids();
  /// Lines 6-12 of Algorithm 1 with moving bodies next to a liquid: contacts, the coupled
  /// pressure / viscosity / contact solve of the scene's scheme (section 6), and the new body
  /// velocities (eq. (21)). Updates u_ to the solved face velocities.
  void solve_coupled(double dt);
  /// Velocity of the solid at a point x inside the solids: the point velocity of the moving
  /// body whose (unshrunk) SDF is smallest there when that is a moving body, zero otherwise.
  Vec<Dim> solid_velocity(const Vec<Dim>& x) const;
  /// Throws SimulationError if the state holds a non-finite value.
  void check_finite(const char* after) const;
  /// Fills the frame statistics that describe the state (volume, particles, energy, probes).
  void fill_state_stats(FrameStats& s) const;
  /// Lines 7-11 of Algorithm 1 for the liquid: the solves of solve_sequence(scheme) on u_, their
  /// statistics added to stats_.
  void solve_liquid(double dt);
  /// solve_liquid for scenes with a herschel-bulkley liquid (section 5): the unified or decoupled
  /// sequence with Algorithm 2 around its viscous solve (staggered_iterations rounds), started
  /// from the previous step's shear rate where there is one (departure: line 1 as printed only
  /// in the first step and on newly active DOFs; docs/non-newtonian.md, departure 4).
  void solve_liquid_non_newtonian(double dt);
  /// Algorithm 2's model for the current weights (W_F^s, W_L^s, the liquids' mass fractions).
  NonNewtonianViscosity<Dim> non_newtonian_model() const;
  /// The residuals of one step's viscosity rounds into stats_ (SolverStats::viscosity_residuals).
  void record_viscosity_rounds(const std::vector<double>& residuals);
  /// Adds one solve's iterations, residual and DOF counts to stats_; throws SimulationError on a
  /// breakdown (`what` names the solve).
  void record_solve(const PcgResult& pcg, long pressure_dofs, long stress_dofs, const char* what);

  SceneDesc scene_;
  MacGrid<Dim> grid_;
  SampleLattice<Dim> lattice_;
  std::array<BoundaryType, 2 * Dim> boundary_{};
  Vec<Dim> gravity_;
  double reference_density_ = 1000.0;
  // static solids: shapes, their SolidField, and W_F^u (fixed for the whole run)
  std::vector<ShapePtr<Dim>> solid_shapes_;
  SolidField<Dim> solids_;
  VectorX solid_phi_;
  PressureWeights weights_;
  // viscosity (section 3.1): eta of each liquid, the stress DOF layout, W_F^s (fixed), W_L^s,
  // eta per stress DOF and per cell (render), the last stress solution
  std::vector<double> liquid_eta_;
  SolveSequence sequence_ = SolveSequence::pressure;
  StressGrid<Dim> stress_grid_;
  VectorX stress_fluid_, stress_liquid_, stress_eta_, cell_eta_, stress_;
  // non-Newtonian liquids (section 5): the liquids' models and mass fractions per stress DOF;
  // cell_eta_ is then the effective viscosity of the last solve (its cell-centred diagonal DOFs)
  bool non_newtonian_ = false;
  ViscosityMixture mixture_;
  std::shared_ptr<const SparseMatrix> deformation_rate_;  ///< D of eq. (8), built once
  /// Algorithm 2's start (departure, docs/non-newtonian.md): the shear rate s per stress DOF at
  /// the end of the previous step, NaN where that step had no unknown (line 1 there); empty
  /// before the first step or with solver.viscosity_warm_start off
  VectorX previous_shear_rate_;
  // liquid state
  Particles<Dim> particles_;
  VectorX liquid_phi_;
  VectorX raw_liquid_face_;              ///< W_L^u before the clamp of kMinLiquidFaceFraction
  double liquid_volume_ = 0.0;          ///< sum W_L^p dx^Dim of liquid_phi_ (not extended)
  bool liquid_weights_current_ = false;  ///< liquid_phi_ and the weights match the particles
  VectorX u_, face_mass_, face_density_, pressure_;
  PcgSettings pcg_settings_;
  /// The preconditioner and initial guess of the solve_stokes calls (solver.preconditioner).
  StokesSolveOptions stokes_options() const;
  // time and statistics
  int frame_ = 0;
  double time_ = 0.0;
  FrameStats stats_;
  // rigid bodies with contact (scenes with dynamic or kinematic bodies)
  std::unique_ptr<RigidWorld<Dim>> rigid_;
  /// Moving bodies next to a liquid: the coupled step (update_moving_solids, solve_coupled).
  bool coupled_ = false;
  SolidWeights<Dim> solid_weights_;  ///< of the last update_moving_solids
};


/// Builds the simulation for scene.dim.
std::unique_ptr<AnySimulation> make_simulation(const SceneDesc& scene);

extern template class Simulation<2>;
extern template class Simulation<3>;

}  // namespace monolith
