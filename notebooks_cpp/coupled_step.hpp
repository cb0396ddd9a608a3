#pragma once
/// \file coupled_step.hpp
/// The inputs of one coupled liquid-body step for notebooks 08, 09 and 11: the grid and the
/// dynamic bodies of a scene, the solid weights of the posed bodies (section 4.4.6), the weights
/// of eq. (8) for a liquid given by a level set, a uniform u*, the contacts (detect_contacts)
/// and their ContactSystem with alpha = 1/dx^Dim (section 4.1). What the simulator gets from
/// particles (the liquid level set, u*) is given here in closed form, so that each notebook
/// shows one step of a scene small enough to print.

#include <algorithm>
#include <array>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/contact/collision.hpp"
#include "reference/contact/contact_system.hpp"
#include "reference/coupling/coupled_schemes.hpp"
#include "reference/coupling/coupling.hpp"
#include "reference/fluid/stokes_system.hpp"
#include "reference/grid/mac_grid.hpp"
#include "reference/rigid/rigid_body.hpp"

namespace notebook {

template <int Dim>
struct CoupledStep {
  monolith::MacGrid<Dim> grid;
  std::vector<monolith::RigidBody<Dim>> bodies;  ///< velocities are v* (gravity added)
  monolith::SolidWeights<Dim> solids;
  monolith::StokesWeights w;                     ///< eq. (8) weights with the bodies' W_F
  monolith::VectorX u_star;                      ///< face velocities after forces
  std::vector<monolith::Contact<Dim>> contacts;
  monolith::ContactSystem<Dim> contact_system;
  double dt = 0.0;
};

/// One step of `scene` (domain, bodies, solver.shrink/contact_margin/baumgarte): liquid where
/// liquid_phi(x) < 0 (sampled on the half lattice), density rho and viscosity eta, every face
/// velocity set to the component of u0, the dynamic bodies' velocities increased by dt g (v*,
/// eq. (10)). Contacts are searched up to the margin plus 0.1 dx plus what the bodies close in
/// two steps, as RigidWorld does.
template <int Dim, class Phi>
CoupledStep<Dim> make_coupled_step(const monolith::SceneDesc& scene, const Phi& liquid_phi,
                                   double rho, double eta, double dt,
                                   const monolith::Vec<Dim>& u0) {
  using namespace monolith;
  CoupledStep<Dim> s;
  const double dx = scene.dx();
  Vec<Dim> lower;
  VecI<Dim> cells;
  for (int a = 0; a < Dim; ++a) {
    lower[a] = scene.domain.lower[a];
    cells[a] = scene.domain.cells[a];
  }
  s.grid = MacGrid<Dim>(lower, dx, cells, std::array<bool, Dim>{});
  s.dt = dt;
  // v* = v + dt g on the dynamic bodies
  Vec<Dim> g = Vec<Dim>::Zero();
  g[1] = -9.81;
  if (static_cast<int>(scene.gravity.size()) == Dim)
    for (int a = 0; a < Dim; ++a) g[a] = scene.gravity[a];
  s.bodies = make_bodies<Dim>(scene);
  double speed = 0.0;
  for (RigidBody<Dim>& b : s.bodies) {
    if (b.motion == BodyMotion::dynamic) b.velocity += dt * g;
    speed = std::max(speed, b.velocity.norm());
  }
  std::array<BoundaryType, 2 * Dim> boundary;
  for (int f = 0; f < 2 * Dim; ++f) boundary[f] = scene.domain.boundary[f];
  // solid weights of the posed bodies, shrunk by zeta (section 4.4.6)
  s.solids = solid_weights<Dim>(s.grid, coupling_bodies(s.bodies), {}, boundary,
                                scene.solver.shrink * dx);
  // eq. (8) weights: the liquid from its level set, W_F^u and W_F^s from the bodies
  const SampleLattice<Dim> lattice = half_lattice(s.grid);
  VectorX phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) phi[k] = liquid_phi(lattice.position(lattice.coord(k)));
  s.w = coupled_stokes_weights<Dim>(s.grid, s.solids, phi, rho, eta);
  s.u_star.resize(s.grid.num_faces());
  for (int a = 0; a < Dim; ++a)
    s.u_star.segment(s.grid.face_offset(a), s.grid.num_faces(a)).setConstant(u0[a]);
  // contacts and the contact blocks with alpha = 1/dx^Dim
  const double search = (scene.solver.contact_margin + 0.1) * dx + 2.0 * dt * speed;
  s.contacts = detect_contacts<Dim>(s.bodies, Walls<Dim>::from_scene(scene), search);
  ContactParameters params;
  params.dt = dt;
  params.dx = dx;
  params.baumgarte = scene.solver.baumgarte;
  params.margin_cells = scene.solver.contact_margin;
  params.restitution_threshold = 2.0 * g.norm() * dt;
  s.contact_system = ContactSystem<Dim>(s.bodies, s.contacts, params);
  return s;
}

}  // namespace notebook
