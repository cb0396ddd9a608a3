/// \file simulation.cpp
/// Simulation<Dim>: the time loop of Algorithm 1 (simulation.hpp). Liquids beside static solids
/// only take the solves of eq. (8) that the scheme picks (solve_sequence): the pressure alone,
/// the unified pressure-viscosity (Stokes) solve, or the decoupled pressure / viscosity /
/// pressure sequence of section 6.2. With moving bodies the step runs the coupled solve of the
/// scheme (solve_coupled_step); bodies without liquid step through RigidWorld.

#include "reference/sim/simulation.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <utility>

#include "reference/core/errors.hpp"
#include "reference/core/timer.hpp"
#include "reference/coupling/coupled_schemes.hpp"
#include "reference/coupling/coupling.hpp"
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

bool all_finite(const VectorX& v) {
  return v.allFinite();
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
    for (std::size_t k = 0; k < shapes.size(); ++k) {
      const double dk = bounded_distance<Dim>(*shapes[k], boxes[k], far, x);
      if (dk < d) {
        d = dk;
        best = k;
      }
    }
    return shapes[best]->gradient(x);
  };
  return field;
}

/// Faces whose weight W_F^u W_L^u in the energy of eq. (8) (W_L^u the geometric liquid fraction,
/// before the clamp) is below this keep their solved velocity out of the particles: it is
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

}  // namespace

SolveSequence solve_sequence(CouplingScheme scheme, bool viscous) {
  // without viscous liquid (or under a scheme that leaves viscosity out) there are no stress
  // unknowns: every scheme is the pressure solve
  if (!viscous || !scheme_uses_viscosity(scheme)) return SolveSequence::pressure;
  if (scheme == CouplingScheme::pc_vc_pc_unified) return SolveSequence::decoupled;
  return SolveSequence::unified;
}

template <int Dim>
Simulation<Dim>::Simulation(const SceneDesc& scene) : scene_(scene) {
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
  // W_F^u from the solid level set shrunk by zeta (section 4.4.6)
  solid_phi_ =
      solid_phi_on_lattice(grid_, lattice_, solid_shapes_, scene.solver.shrink * grid_.dx());
  weights_.fluid_face = fluid_face_weights(grid_, lattice_, solid_phi_, boundary_);
  // moving bodies: the rigid world; next to a liquid they enter the weights of every step
  // (W_F^u, W_F^s from their pose) and the particles never start inside them
  for (const auto& b : scene.bodies)
    if (b.motion != BodyMotion::fixed) {
      rigid_ = std::make_unique<RigidWorld<Dim>>(scene);
      break;
    }
  coupled_ = rigid_ && !scene.liquids.empty();

  // viscosity: which solves the scheme runs, and the stress DOFs with W_F^s (static solids)
  liquid_eta_ = liquid_viscosities(scene.liquids);
  non_newtonian_ = has_non_newtonian(scene.liquids);
  const bool viscous = non_newtonian_ || std::any_of(liquid_eta_.begin(), liquid_eta_.end(),
                                                     [](double eta) { return eta > 0.0; });
  if (non_newtonian_)
    for (const auto& l : scene.liquids)
      mixture_.models.push_back(HerschelBulkley::from_spec(l.viscosity));
  sequence_ = solve_sequence(scene.solver.scheme, viscous);
  stress_grid_ = StressGrid<Dim>(grid_);
  if (non_newtonian_ && sequence_ != SolveSequence::pressure)
    deformation_rate_ = std::make_shared<const SparseMatrix>(deformation_rate_matrix(stress_grid_));
  if (sequence_ != SolveSequence::pressure)
    stress_fluid_ = stress_fluid_weights(stress_grid_, lattice_, solid_phi_, boundary_);
  stress_ = VectorX::Zero(stress_grid_.num_dofs());
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
  if (scene.particles.position_correction)
    project_particle_density(particles_, grid_, lattice_, weights_.fluid_face, solids_, boundary_,
                             kSeedProjectionIterations);
  // frame 0: the seeded state on the grid (no pressure yet)
  particles_to_grid(particles_, grid_, u_, face_mass_, face_density_);
  update_liquid_weights();
  liquid_weights_current_ = true;
  pressure_ = VectorX::Zero(grid_.num_cells());
  stats_.frame = 0;
  stats_.time = 0.0;
  stats_.solver.scheme = scene.solver.scheme;
  fill_state_stats(stats_);
}

template <int Dim>
void Simulation<Dim>::update_liquid_weights() {
  liquid_phi_ = liquid_phi_on_lattice(particles_, grid_, lattice_);
  // the weights of eq. (8) see the liquid level set extended into the static solids, so that a
  // wall's fluid sliver next to the liquid is not a free surface (extend_liquid_into_solids)
  const bool solids = !solid_shapes_.empty() || coupled_;
  const VectorX phi = !solids
                          ? liquid_phi_
                          : extend_liquid_into_solids(grid_, liquid_phi_, solid_phi_,
                                                      kLiquidSolidReach * grid_.dx());
  weights_.liquid_cell = liquid_cell_weights(grid_, lattice_, phi);
  weights_.liquid_face = liquid_face_weights(grid_, lattice_, phi, weights_.liquid_cell);
  raw_liquid_face_ = face_negative_fractions(grid_, lattice_, phi);
  // W_L^s from the same extended level set, eta per stress DOF and per cell from the particles
  if (sequence_ != SolveSequence::pressure) {
    stress_liquid_ = stress_liquid_weights(stress_grid_, lattice_, phi);
    stress_eta_ = stress_viscosity(stress_grid_, particles_, liquid_eta_);
    if (non_newtonian_) {
      mixture_.fractions = liquid_stress_fractions(stress_grid_, particles_,
                                                   static_cast<int>(mixture_.models.size()));
      // n = 1, tau0 = 0 for all: the Newtonian path's eta per DOF (bit for bit the same run)
      if (mixture_.is_newtonian()) {
        std::vector<double> k;
        for (const auto& m : mixture_.models) k.push_back(m.k);
        mixture_.constant = stress_viscosity(stress_grid_, particles_, k);
      }
    }
  }
  if (!non_newtonian_) {
    cell_eta_ = cell_viscosity(grid_, particles_, liquid_eta_);
  } else if (cell_eta_.size() != grid_.num_cells()) {
    // before the first solve: each liquid at rest, the limiting viscosity eta0 of eq. (27)
    std::vector<double> eta0;
    for (const auto& m : mixture_.models) eta0.push_back(m.limiting_viscosity());
    cell_eta_ = cell_viscosity(grid_, particles_, eta0);
  }
  // the reported volume is that of the particles' own level set (the extension lies in solids)
  liquid_volume_ = (!solids ? weights_.liquid_cell
                                          : liquid_cell_weights(grid_, lattice_, liquid_phi_))
                       .sum() *
                   grid_.cell_volume();
}

template <int Dim>
double Simulation<Dim>::cfl_dt() const {
  const double speed = std::max(max_particle_speed(particles_),
                                u_.size() ? u_.template lpNorm<Eigen::Infinity>() : 0.0);
  const double max_dt = scene_.time.max_dt;
  double dt = speed > 0.0 ? std::min(max_dt, scene_.time.cfl * grid_.dx() / speed) : max_dt;
  // a body point moves at most a fraction of a cell per step (contacts are linearised in time)
  const double body_speed = rigid_ ? rigid_->max_point_speed() : 0.0;
  if (body_speed > 0.0) dt = std::min(dt, kBodyCellFraction * grid_.dx() / body_speed);
  return dt;
}

template <int Dim>
void Simulation<Dim>::step_bodies(double dt) {
  const RigidStepStats s = rigid_->step(dt, time_, gravity_);
  stats_.contact_count = std::max(stats_.contact_count, s.contacts);
  stats_.max_penetration = std::max(stats_.max_penetration, s.max_penetration);
  stats_.solver.iterations += s.iterations;
  stats_.solver.contact_iterations += s.iterations;
  stats_.solver.contact_seconds += s.solve_seconds;
  stats_.solver.staggered_iterations += s.staggered_iterations;
  stats_.solver.max_relative_residual =
      std::max(stats_.solver.max_relative_residual, s.max_relative_residual);
  stats_.solver.converged = stats_.solver.converged && s.converged;
  stats_.solver.dofs_contact = std::max(stats_.solver.dofs_contact, s.dofs_contact);
  stats_.solver.dofs_friction = std::max(stats_.solver.dofs_friction, s.dofs_friction);
  stats_.timing[FramePhase::solve] += s.solve_seconds;
}

template <int Dim>
void Simulation<Dim>::step(double dt) {
  // a scene of bodies without liquid: (3), (6), (8), (10), (12), (13) through RigidWorld
  if (rigid_ && scene_.liquids.empty()) {
    step_bodies(dt);
    return;
  }
  // (1) map velocity from particles to grid (APIC)
  particles_to_grid(particles_, grid_, u_, face_mass_, face_density_);
  // (2) add external force (gravity) on the faces that carry mass; (3) on the dynamic bodies
  for (int f = 0; f < grid_.num_faces(); ++f)
    if (face_mass_[f] > 0.0) u_[f] += dt * gravity_[grid_.face_coord(f).first];
  if (coupled_) rigid_->apply_gravity(dt, gravity_);
  // (4) liquid/air domain: level set from the particles on the half lattice
  // (5) volume fractions: W_F^u, W_F^s from the solids at the bodies' pose (section 4.4.6),
  // W_L^p, W_L^u, W_L^s from the liquid; the particles and bodies have not moved since the end
  // of the last frame if that is where we are
  if (!liquid_weights_current_) {
    if (coupled_) update_moving_solids();
    update_liquid_weights();
  }
  liquid_weights_current_ = false;
  weights_.face_density = density_diagonal(grid_, face_density_, reference_density_);
  // the solve reads u* on faces the particles did not reach: with stress unknowns D reads the
  // air faces next to the surface (b1 of eq. (24)), and the weighted divergence of a surface
  // cell (b2) reads its faces towards the air, whose W_L^u is small but not zero. Extend u*
  // there from the faces that carry mass, so the surface sees the liquid's own velocity (close
  // to traction-free) rather than air at rest (a no-slip lid, and a spurious divergence: a
  // liquid ball in free fall felt a pressure of 1e-4 rho g dx), as Batty & Bridson (2008)
  // extrapolate before their viscosity solve
  {
    std::vector<char> carried(grid_.num_faces(), 0);
    for (int f = 0; f < grid_.num_faces(); ++f) carried[f] = face_mass_[f] > 0.0;
    extrapolate_velocity(grid_, u_, carried, kAirVelocityLayers);
  }
  // (6) contacts, (7)-(10) active DOFs, assembly (or stencil set-up) and the solves of the
  // scheme; (11) velocity update u = u* - dt P^-1 (W_L^u)^-1 (G W_L^p p + D^T M W_L^s tau) and
  // (12) the bodies' velocities (eq. (21))
  {
    ScopedTimer timer(stats_.timing[FramePhase::solve]);
    if (coupled_) {
      solve_coupled(dt);
    } else {
      solve_liquid(dt);
      stats_.solver.fluid_seconds += timer.seconds();
    }
  }
  check_finite("the pressure/viscosity/contact solve");
  // extrapolate the velocity from the trusted liquid faces into air and solid, then zero the
  // normal velocity on walls and give fully solid faces their solid's velocity (zero for
  // static solids), and remove the inflow into solids
  std::vector<char> valid(grid_.num_faces(), 0);
  for (int f = 0; f < grid_.num_faces(); ++f)
    valid[f] =
        weights_.fluid_face[f] > 0.0 &&
        (weights_.fluid_face[f] * raw_liquid_face_[f] >= kTrustedLiquidFaceFraction ||
         (weights_.liquid_face[f] == 0.0 && face_mass_[f] > 0.0));
  const int layers = static_cast<int>(std::ceil(scene_.time.cfl)) + 2;
  extrapolate_velocity(grid_, u_, valid, layers);
  for (int f = 0; f < grid_.num_faces(); ++f) {
    const auto [axis, coord] = grid_.face_coord(f);
    const bool wall = grid_.is_boundary_face(axis, coord) &&
                      boundary_[2 * axis + (coord[axis] == 0 ? 0 : 1)] == BoundaryType::wall;
    if (wall)
      u_[f] = 0.0;
    else if (weights_.fluid_face[f] == 0.0)
      u_[f] = coupled_ ? solid_velocity(grid_.face_center(axis, coord))[axis] : 0.0;
  }
  constrain_velocity_in_solids();
  // (13) body positions; the particles then see the solids at the new pose
  if (coupled_) {
    rigid_->integrate(dt, time_, "the coupled solve");
    std::vector<ShapePtr<Dim>> shapes = solid_shapes_;
    for (const auto& b : rigid_->bodies())
      if (b.moves()) shapes.push_back(b.posed_shape());
    solids_ = make_solid_field<Dim>(shapes, grid_.dx());
  }
  // (14) grid to particles (APIC), then advect (RK2) through the extrapolated field; particles
  // leaving through open faces are removed, particles that end up inside a solid are pushed out
  grid_to_particles(particles_, grid_, u_);
  advect_particles(particles_, grid_, u_, dt, solids_, boundary_);
  // (15) position correction for volume preservation
  // and the grid density projection that keeps the particle volume and the level set's volume
  // equal (docs/particles.md)
  if (scene_.particles.position_correction) {
    correct_positions(particles_, grid_, dt, solids_, boundary_);
    project_particle_density(particles_, grid_, lattice_, weights_.fluid_face, solids_, boundary_);
  }
  check_finite("advection");
}

template <int Dim>
void Simulation<Dim>::update_moving_solids() {
  // every body is a coupling body (fixed ones one-way at zero velocity), so the weights are
  // indexed like the bodies of the contact system; the static shapes are those fixed bodies
  solid_weights_ = solid_weights<Dim>(grid_, coupling_bodies(rigid_->bodies()), {}, boundary_,
                                      scene_.solver.shrink * grid_.dx());
  solid_phi_ = solid_weights_.lattice_phi;
  weights_.fluid_face = solid_weights_.fluid_face;
  if (sequence_ != SolveSequence::pressure) stress_fluid_ = solid_weights_.fluid_stress;
  std::vector<ShapePtr<Dim>> shapes = solid_shapes_;
  for (const auto& b : rigid_->bodies())
    if (b.moves()) shapes.push_back(b.posed_shape());
  solids_ = make_solid_field<Dim>(shapes, grid_.dx());
}

template <int Dim>
Vec<Dim> Simulation<Dim>::solid_velocity(const Vec<Dim>& x) const {
  if (!rigid_) return Vec<Dim>::Zero();
  const auto& bodies = rigid_->bodies();
  double best = std::numeric_limits<double>::infinity();
  int which = -1;
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    // a point outside a body's bounds is not inside it (and only inside points matter here)
    const Box<Dim> box = bodies[i].bounds();
    if (box.min().allFinite() && box.max().allFinite() &&
        ((x.array() < box.min().array()).any() || (x.array() > box.max().array()).any()))
      continue;
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
  CoupledStepInput<Dim> in;
  in.grid = grid_;
  in.dt = dt;
  in.u_star = u_;
  in.bodies = rigid_->bodies();
  in.solids = solid_weights_;
  // (6) contacts at the step's start pose, with the pair's friction and restitution
  RigidStepStats contact_stats;
  in.contacts = rigid_->find_contacts(dt, contact_stats);
  in.contact_params = rigid_->contact_parameters(dt, gravity_);
  stats_.contact_count = std::max(stats_.contact_count, contact_stats.contacts);
  stats_.max_penetration = std::max(stats_.max_penetration, contact_stats.max_penetration);
  // the weights of eq. (24): W_F from the bodies' pose, W_L from the liquid; the P.. C schemes
  // and inviscid liquids have no stress unknowns (eta = 0 leaves every stress DOF inactive)
  in.weights.pressure = weights_;
  in.weights.fluid_stress = solid_weights_.fluid_stress;
  const bool stress = sequence_ != SolveSequence::pressure;
  in.weights.liquid_stress = stress ? stress_liquid_ : VectorX::Zero(stress_grid_.num_dofs());
  in.weights.viscosity = stress ? stress_eta_ : VectorX::Zero(stress_grid_.num_dofs());
  // (7)-(11) the scheme's solves (section 6)
  StaggeredSettings ss;
  ss.max_iterations = std::max(1, scene_.solver.staggered_iterations);
  ss.tolerance = scene_.solver.tolerance;
  ss.diagonal_boost = scene_.solver.diagonal_boost;
  ss.mprgp.tolerance = scene_.solver.tolerance;
  ss.mprgp.max_iterations = scene_.solver.max_iterations;
  // non-Newtonian liquids: Algorithm 2 alongside the scheme's staggered rounds (section 5)
  CoupledSchemeOptions options;
  std::unique_ptr<NonNewtonianViscosity<Dim>> model;
  VectorX eta;
  if (non_newtonian_ && stress) {
    model = std::make_unique<NonNewtonianViscosity<Dim>>(
        stress_grid_, deformation_rate_, solid_weights_.fluid_stress, stress_liquid_, mixture_);
    options.initial_viscosity = [&](const VectorX& u_star) {
      eta = model->initial_viscosity(solid_weights_.fluid_face, u_star, previous_shear_rate_);
      return eta;
    };
    options.update_viscosity = [&](const VectorX& tau, const VectorX& used) {
      eta = model->update(tau, used);
      return eta;
    };
  }
  const CoupledSolveResult r =
      solve_coupled_step<Dim>(in, scene_.solver.scheme, scene_.solver.backend, ss, options);
  if (eta.size() == stress_grid_.num_dofs())
    cell_eta_ = eta.segment(stress_grid_.offset(0), grid_.num_cells());
  if (model) {
    record_viscosity_rounds(model->residuals());
    if (scene_.solver.viscosity_warm_start) previous_shear_rate_ = model->previous_shear_rate();
  }
  u_ = r.u;
  pressure_ = r.pressure;
  stress_ = r.stress;
  // (12) the bodies' velocities (eq. (21))
  rigid_->set_velocities(r.body_velocity, r.body_dof);
  StaggeredResult kept;
  kept.lambda = r.lambda;
  kept.z = r.z;
  rigid_->remember(std::move(in.contacts), kept);
  // statistics: the phases of the paper's Tables 1-3
  SolverStats& st = stats_.solver;
  st.iterations += r.fluid_iterations + r.contact_iterations + r.coupled_iterations;
  st.fluid_iterations += r.fluid_iterations;
  st.contact_iterations += r.contact_iterations;
  st.coupled_iterations += r.coupled_iterations;
  st.fluid_seconds += r.fluid_seconds;
  st.contact_seconds += r.contact_seconds;
  st.coupled_seconds += r.coupled_seconds;
  st.staggered_iterations += r.staggered_iterations;
  st.converged = st.converged && r.converged;
  st.max_relative_residual = std::max(st.max_relative_residual, r.max_relative_residual);
  st.dofs_pressure = std::max(st.dofs_pressure, r.pressure_dofs);
  st.dofs_stress = std::max(st.dofs_stress, r.stress_dofs);
  st.dofs_contact = std::max(st.dofs_contact, r.contact_dofs);
  st.dofs_friction = std::max(st.dofs_friction, r.friction_dofs);
}

template <int Dim>
StokesSolveOptions Simulation<Dim>::stokes_options() const {
  StokesSolveOptions o;
  o.preconditioner = scene_.solver.preconditioner;
  if (o.preconditioner != PreconditionerKind::ssor && scene_.solver.stokes_warm_start) {
    o.initial_stress = &stress_;
    o.initial_pressure = &pressure_;
  }
  return o;
}

template <int Dim>
void Simulation<Dim>::solve_liquid(double dt) {
  // pressure only: eq. (8) without stress
  if (sequence_ == SolveSequence::pressure) {
    const PressureSolveResult solve =
        solve_pressure(grid_, weights_, dt, scene_.solver.backend, pcg_settings_, u_);
    pressure_ = solve.pressure;
    record_solve(solve.pcg, solve.dofs, 0, "pressure");
    return;
  }
  if (non_newtonian_) {
    solve_liquid_non_newtonian(dt);
    return;
  }
  StokesWeights w;
  w.pressure = weights_;
  w.fluid_stress = stress_fluid_;
  w.liquid_stress = stress_liquid_;
  w.viscosity = stress_eta_;
  if (sequence_ == SolveSequence::unified) {
    // PVC without bodies: eq. (8) in (tau, p) at once, reduced stress (section 4.4.2)
    const StokesSolveResult solve =
        solve_stokes(grid_, w, dt, StokesUnknowns::pressure_and_stress, StressForm::reduced,
                     scene_.solver.backend, pcg_settings_, u_, stokes_options());
    pressure_ = solve.pressure;
    stress_ = solve.stress;
    record_solve(solve.pcg, solve.pressure_dofs, solve.stress_dofs, "Stokes");
    return;
  }
  // PC-VC-PC without bodies (section 6.2): pressure, viscosity with stress unknowns (p = 0; the
  // full form, since the trace vanishes only together with the pressure), pressure again
  const PressureSolveResult first =
      solve_pressure(grid_, weights_, dt, scene_.solver.backend, pcg_settings_, u_);
  record_solve(first.pcg, first.dofs, 0, "first pressure");
  const StokesSolveResult viscous = solve_stokes(grid_, w, dt, StokesUnknowns::stress_only,
                                                 StressForm::full, scene_.solver.backend,
                                                 pcg_settings_, u_, stokes_options());
  record_solve(viscous.pcg, 0, viscous.stress_dofs, "viscosity");
  const PressureSolveResult second =
      solve_pressure(grid_, weights_, dt, scene_.solver.backend, pcg_settings_, u_);
  record_solve(second.pcg, second.dofs, 0, "second pressure");
  pressure_ = first.pressure + second.pressure;
  stress_ = viscous.stress;
}

template <int Dim>
NonNewtonianViscosity<Dim> Simulation<Dim>::non_newtonian_model() const {
  return NonNewtonianViscosity<Dim>(stress_grid_, deformation_rate_, stress_fluid_, stress_liquid_,
                                    mixture_);
}

template <int Dim>
void Simulation<Dim>::solve_liquid_non_newtonian(double dt) {
  StokesWeights w;
  w.pressure = weights_;
  w.fluid_stress = stress_fluid_;
  w.liquid_stress = stress_liquid_;
  NonNewtonianViscosity<Dim> model = non_newtonian_model();
  const int rounds = std::max(1, scene_.solver.staggered_iterations);
  VectorX eta;
  if (sequence_ == SolveSequence::unified) {
    // Algorithm 2 around the unified solve: each round eq. (29) in (tau, p) from the same u*
    // with N(eta^k), so each round ends with tau, p optimal for the current viscosity
    const VectorX u_star = u_;
    eta = run_algorithm2<Dim>(model, weights_.fluid_face, u_star, rounds, [&](const VectorX& e) {
      w.viscosity = e;
      u_ = u_star;
      const StokesSolveResult solve =
          solve_stokes(grid_, w, dt, StokesUnknowns::pressure_and_stress, StressForm::reduced,
                       scene_.solver.backend, pcg_settings_, u_, stokes_options());
      record_solve(solve.pcg, solve.pressure_dofs, solve.stress_dofs, "Stokes");
      pressure_ = solve.pressure;
      stress_ = solve.stress;
      return solve.stress;
    }, previous_shear_rate_);
  } else {
    // PC-VC-PC: Algorithm 2 around the viscosity solve, from the first pressure solve's u
    const PressureSolveResult first =
        solve_pressure(grid_, weights_, dt, scene_.solver.backend, pcg_settings_, u_);
    record_solve(first.pcg, first.dofs, 0, "first pressure");
    const VectorX u_first = u_;
    eta = run_algorithm2<Dim>(model, weights_.fluid_face, u_first, rounds, [&](const VectorX& e) {
      w.viscosity = e;
      u_ = u_first;
      const StokesSolveResult viscous =
          solve_stokes(grid_, w, dt, StokesUnknowns::stress_only, StressForm::full,
                       scene_.solver.backend, pcg_settings_, u_, stokes_options());
      record_solve(viscous.pcg, 0, viscous.stress_dofs, "viscosity");
      stress_ = viscous.stress;
      return viscous.stress;
    }, previous_shear_rate_);
    const PressureSolveResult second =
        solve_pressure(grid_, weights_, dt, scene_.solver.backend, pcg_settings_, u_);
    record_solve(second.pcg, second.dofs, 0, "second pressure");
    pressure_ = first.pressure + second.pressure;
  }
  // the effective viscosity of the step's flow on its cell-centred DOFs (component 0)
  cell_eta_ = eta.segment(stress_grid_.offset(0), grid_.num_cells());
  record_viscosity_rounds(model.residuals());
  // the next step starts from this step's rate (departure from line 1, docs/non-newtonian.md)
  if (scene_.solver.viscosity_warm_start) previous_shear_rate_ = model.previous_shear_rate();
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
  stats_.solver.iterations += pcg.iterations;
  stats_.solver.fluid_iterations += pcg.iterations;
  stats_.solver.staggered_iterations += 1;
  stats_.solver.max_relative_residual =
      std::max(stats_.solver.max_relative_residual, pcg.relative_residual);
  stats_.solver.converged = stats_.solver.converged && pcg.converged;
  stats_.solver.dofs_pressure = std::max(stats_.solver.dofs_pressure, pressure_dofs);
  stats_.solver.dofs_stress = std::max(stats_.solver.dofs_stress, stress_dofs);
}

template <int Dim>
void Simulation<Dim>::constrain_velocity_in_solids() {
  if (solids_.empty()) return;
  const VectorX u_old = u_;
#pragma omp parallel for schedule(static)
  for (int f = 0; f < grid_.num_faces(); ++f) {
    const auto [axis, coord] = grid_.face_coord(f);
    // the face centre is lattice point 2 f + 1 - e_axis of the half lattice
    VecI<Dim> k = 2 * coord + VecI<Dim>::Ones();
    k[axis] -= 1;
    if (k[axis] >= lattice_.dims[axis]) k[axis] = 0;  // periodic seam
    if (!(solid_phi_[lattice_.index(k)] < 0.0)) continue;
    const Vec<Dim> x = grid_.face_center(axis, coord);
    const Vec<Dim> n = solids_.gradient(x);
    Vec<Dim> v = grid_.interpolate_velocity(u_old, x);
    const double vn = (v - (coupled_ ? solid_velocity(x) : Vec<Dim>::Zero())).dot(n);
    if (vn < 0.0) v -= vn * n;
    u_[f] = v[axis];
  }
}

template <int Dim>
void Simulation<Dim>::check_finite(const char* after) const {
  std::string what;
  if (!all_finite(u_)) what = "non-finite grid velocity";
  if (!all_finite(pressure_)) what = "non-finite pressure";
  if (!all_finite(stress_)) what = "non-finite viscous stress";
  for (std::size_t p = 0; p < particles_.size() && what.empty(); ++p)
    if (!particles_.x[p].allFinite() || !particles_.v[p].allFinite())
      what = "non-finite particle position or velocity (particle " + std::to_string(p) + ")";
  if (what.empty()) return;
  std::ostringstream msg;
  msg << "t = " << time_ << " s (frame " << frame_ + 1 << "): " << what << " after " << after;
  throw SimulationError(msg.str());
}

template <int Dim>
FrameStats Simulation<Dim>::advance_frame() {
  const Stopwatch frame_watch;
  stats_ = FrameStats{};
  stats_.solver.scheme = scene_.solver.scheme;
  stats_.dt_min = std::numeric_limits<double>::infinity();
  // substeps that land exactly on the frame time (frame + 1) / fps
  const double frame_end = (frame_ + 1) / scene_.time.fps;
  while (time_ < frame_end) {
    const double remaining = frame_end - time_;
    // equal substeps no longer than the CFL limit, the last one ending on the frame time
    const double dt_cfl = cfl_dt();
    const double n = std::max(1.0, std::ceil(remaining / dt_cfl - 1e-9));
    const double dt = remaining / n;
    step(dt);
    time_ = n == 1.0 ? frame_end : time_ + dt;
    ++stats_.steps;
    stats_.dt_min = std::min(stats_.dt_min, dt);
    stats_.dt_max = std::max(stats_.dt_max, dt);
  }
  ++frame_;
  stats_.frame = frame_;
  stats_.time = frame_end;
  if (stats_.steps == 0) stats_.dt_min = 0.0;
  // the solid and liquid weights of the final state (reused by the next step)
  if (coupled_) update_moving_solids();
  update_liquid_weights();
  liquid_weights_current_ = true;
  fill_state_stats(stats_);
  stats_.timing[FramePhase::total] = frame_watch.seconds();
  return stats_;
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
  double energy = 0.0;
  for (std::size_t p = 0; p < particles_.size(); ++p)
    energy += 0.5 * particles_.mass[p] * particles_.v[p].squaredNorm();
  s.kinetic_energy_liquid = energy;
  s.kinetic_energy_bodies = rigid_ ? rigid_->kinetic_energy() : 0.0;
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
double Simulation<Dim>::liquid_potential_energy() const {
  double energy = 0.0;
  for (std::size_t p = 0; p < particles_.size(); ++p)
    energy -= particles_.mass[p] * gravity_.dot(particles_.x[p]);
  return energy;
}

std::unique_ptr<AnySimulation> make_simulation(const SceneDesc& scene) {
  if (scene.dim == 3) return std::make_unique<Simulation<3>>(scene);
  return std::make_unique<Simulation<2>>(scene);
}

template class Simulation<2>;
template class Simulation<3>;

}  // namespace monolith
