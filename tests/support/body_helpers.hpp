#pragma once
/// \file body_helpers.hpp
/// Rigid bodies and wall contacts posed by hand for the coupled tests and benchmarks: one step of
/// a scene without the rigid world's contact search.

#include <string>
#include <vector>

#include "reference/contact/collision.hpp"
#include "reference/core/common.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/rigid/body_spec.hpp"
#include "reference/rigid/mass_properties.hpp"
#include "reference/rigid/rigid_body.hpp"
#include "tests/support/test_helpers.hpp"

namespace monolith::testing {

/// Walls on every face of the unit box [0, 1]^Dim with the given friction coefficient.
template <int Dim>
Walls<Dim> unit_box_walls(double friction = 0.0) {
  Walls<Dim> walls;
  walls.lower = Vec<Dim>::Zero();
  walls.upper = Vec<Dim>::Ones();
  walls.is_wall.fill(true);
  walls.friction = friction;
  return walls;
}

/// A rigid body of `shape` (named after its type) with the given density (kg/m^3), friction
/// coefficient and motion, at rest; mass properties from mass_properties.
template <int Dim>
RigidBody<Dim> make_body(const ShapeSpec& shape, double density, double friction = 0.0,
                         BodyMotion motion = BodyMotion::dynamic) {
  BodySpec spec;
  spec.name = enum_name(shape.type);
  spec.motion = motion;
  spec.shape = shape;
  spec.density = density;
  spec.friction = friction;
  const ShapePtr<Dim> rest = make_shape<Dim>(shape, "test");
  return RigidBody<Dim>(spec, rest, mass_properties<Dim>(shape, *rest, density));
}

/// An axis-aligned box body of centre `centre` and half sizes `half` (make_body).
template <int Dim>
RigidBody<Dim> make_box(const Vec<Dim>& centre, const Vec<Dim>& half, double density,
                        double friction = 0.0, BodyMotion motion = BodyMotion::dynamic) {
  return make_body<Dim>(box_spec<Dim>(centre, half), density, friction, motion);
}

/// Contacts of the bottom corners of the axis-aligned box `body` (centre, half sizes) with the
/// floor wall y = 0, or with `ceiling` of its top corners with the ceiling wall y = 1 (the unit
/// domain): 2 corners in 2D, 4 in 3D, normal into the domain, gap phi = the corners' distance to
/// the wall (negative when beyond it), friction coefficient mu.
template <int Dim>
std::vector<Contact<Dim>> floor_contacts(int body, const Vec<Dim>& centre, const Vec<Dim>& half,
                                         double mu, bool ceiling = false) {
  std::vector<Contact<Dim>> out;
  for (int k = 0; k < (Dim == 2 ? 2 : 4); ++k) {
    Contact<Dim> c;
    c.body_a = body;
    c.body_b = -1;
    c.wall_face = ceiling ? 3 : 2;
    c.point = centre;
    c.point[0] += (k & 1) ? half[0] : -half[0];
    if constexpr (Dim == 3) c.point[2] += (k & 2) ? half[2] : -half[2];
    c.point[1] = ceiling ? 1.0 : 0.0;
    c.normal = ceiling ? Vec<Dim>(-Vec<Dim>::Unit(1)) : Vec<Dim>(Vec<Dim>::Unit(1));
    c.phi = ceiling ? 1.0 - (centre[1] + half[1]) : centre[1] - half[1];
    c.friction = mu;
    out.push_back(c);
  }
  return out;
}

}  // namespace monolith::testing
