#pragma once
/// \file rigid_body.hpp
/// Rigid bodies (§3.2, §4.4.7): state (centre of mass, orientation, linear and angular
/// velocity), inertia, the posed signed distance, time integration of the positions, kinematic
/// paths and the rest-frame surface samples used by collision detection (collision.hpp).
/// docs/rigid-bodies.md describes the conventions.

#include <string>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/rigid/body_spec.hpp"
#include "reference/rigid/mass_properties.hpp"
#include "reference/sim/scene_desc.hpp"

namespace monolith {

template <int Dim>
class RigidBody {
 public:
  using Orientation = typename RigidTraits<Dim>::Orientation;

  /// shape: the SDF of the shape at its rest pose (world frame, t = 0), as make_shape builds it.
  /// sample_spacing: target spacing of the surface samples (<= 0: 1/8 of the smallest extent of
  /// the shape's bounds); it is never larger than 1/4 of the smallest extent, so thin bodies
  /// are sampled across their thickness.
  RigidBody(const BodySpec& spec, ShapePtr<Dim> shape, const MassProperties<Dim>& mass,
            double sample_spacing = 0.0);

  std::string name;
  BodyMotion motion = BodyMotion::dynamic;
  double friction = 0, restitution = 0;
  PathSpec path;
  bool has_path = false;
  double mass = 0;                ///< +infinity-like semantics are NOT used: check motion instead
  double volume = 0;              ///< true geometric volume (area in 2D)
  AngularMat<Dim> inertia_body;   ///< about the COM in the body frame (= rest-pose world axes)
  Vec<Dim> position;              ///< centre of mass (world)
  Orientation orientation;        ///< body frame -> world
  Vec<Dim> velocity;              ///< world frame
  AngularVec<Dim> angular_velocity;  ///< world frame

  bool is_dynamic() const { return motion == BodyMotion::dynamic; }
  /// True for bodies whose state changes in time (dynamic and kinematic).
  bool moves() const { return motion != BodyMotion::fixed; }

  Mat<Dim> rotation() const;                     ///< R (body -> world)
  AngularMat<Dim> world_inertia() const;         ///< R I R^T (2D: I)
  AngularMat<Dim> world_inverse_inertia() const; ///< R I^-1 R^T (2D: 1/I)
  Vec<Dim> to_world(const Vec<Dim>& x_rest) const;  ///< R (x_rest - c_rest) + position
  Vec<Dim> to_rest(const Vec<Dim>& x_world) const;  ///< R^T (x_world - position) + c_rest
  Vec<Dim> point_velocity(const Vec<Dim>& x_world) const;  ///< v + omega x (x - position)
  /// Periodic domain axes (docs/rigid-bodies.md, "Bodies in a periodic domain"): period[a] > 0
  /// on a periodic axis a of the domain box starting at lower[a], 0 elsewhere. The body is then
  /// seen at every image x + k period: to_rest, point_velocity, distance and gradient take the
  /// image of x nearest the centre of mass (exact for bodies narrower than half the period),
  /// bounds() spans the whole axis where the posed shape crosses the domain's faces on it, and
  /// integrate() keeps the centre of mass inside [lower, lower + period). Without this (all
  /// zero, the default) nothing changes.
  void set_periodic(const Vec<Dim>& lower, const Vec<Dim>& period);
  bool periodic() const { return periodic_; }
  const Vec<Dim>& period() const { return period_; }
  /// The image of x nearest the centre of mass along the periodic axes (x itself without any).
  Vec<Dim> nearest_image(const Vec<Dim>& x_world) const;
  double distance(const Vec<Dim>& x_world) const;    ///< posed SDF (negative inside)
  Vec<Dim> gradient(const Vec<Dim>& x_world) const;  ///< outward unit normal, world frame
  Box<Dim> bounds() const;  ///< world AABB of the posed shape (rotated rest bounds: conservative)
  /// A Shape<Dim> view of the current pose (for rendering and, later, the grid weights); holds
  /// a copy of the pose.
  ShapePtr<Dim> posed_shape() const;
  const ShapePtr<Dim>& rest_shape() const { return rest_shape_; }
  const Vec<Dim>& rest_center_of_mass() const { return rest_com_; }

  /// The body's block of the velocity coordinates v of §3.2 (eqs. (10), (13)): (v, omega).
  BodyVec<Dim> generalized_velocity() const;
  void set_generalized_velocity(const BodyVec<Dim>& u);
  /// Kinetic energy 1/2 m |v|^2 + 1/2 omega . I_w omega (dynamic bodies; 0 for the others).
  double kinetic_energy() const;
  /// Angular momentum about the centre of mass, I_w omega (world frame).
  AngularVec<Dim> angular_momentum() const;

  /// Algorithm 1, line 13 ("update rigid body positions"), after the velocity update of
  /// eq. (13) by the caller. Symplectic-Euler position update. Dynamic: x += dt v; orientation by the exact rotation
  /// of omega over dt in 2D; in 3D the torque-free motion over dt is integrated with the
  /// symplectic splitting of the free rigid body into rotations about the principal axes
  /// (Dullweber, Leimkuhler & McLachlan 1997), which keeps the world angular momentum
  /// L = I_w omega exactly and the kinetic energy without drift; omega is then I_w^-1 L at the
  /// new pose. Quaternions are renormalised. Kinematic bodies take their prescribed state at
  /// t_new (set_kinematic_state); fixed bodies do nothing.
  void integrate(double dt, double t_new);
  /// Kinematic state at time t: position = c_rest + axis * amplitude * sin(2 pi f t),
  /// velocity = axis * amplitude * 2 pi f cos(2 pi f t) (axis as given, not normalised, as the
  /// scene contract writes it); orientation = the initial angular velocity held constant,
  /// rotated by omega t; without a path the position stays at rest.
  void set_kinematic_state(double t);
  /// Rest-frame surface points (collision): box corners, edge and face points; polygon vertices
  /// and edge points; mesh vertices plus points on large triangles; other shapes: lattice
  /// points projected onto the zero level set. Empty for unbounded shapes.
  const std::vector<Vec<Dim>>& surface_samples() const { return samples_; }
  double sample_spacing() const { return sample_spacing_; }
  /// True for a sphere (disk) shape: collision uses its centre and radius exactly.
  bool is_sphere() const { return is_sphere_; }
  double sphere_radius() const { return sphere_radius_; }
  /// True for a box shape: normal_cone_cosine is exact for it.
  bool is_box() const { return is_box_; }
  /// How well the outward unit direction n fits the body's normal cone at the surface point x
  /// (world frame): the cosine of the angle between n and the cone. Boxes: the cone spanned by
  /// the outward normals of the faces through x (one face, an edge's two, a corner's three);
  /// other shapes: n . gradient(x).
  double normal_cone_cosine(const Vec<Dim>& x_world, const Vec<Dim>& n_world) const;
  /// Boxes: true when the surface point x lies inside one face (not on an edge or a corner);
  /// `normal` receives that face's outward normal (world). False for other shapes.
  bool box_face_normal(const Vec<Dim>& x_world, Vec<Dim>* normal) const;
  /// The type of the body's shape.
  ShapeType shape_type() const { return shape_type_; }

 private:
  ShapePtr<Dim> rest_shape_;
  Vec<Dim> rest_com_;
  Box<Dim> rest_bounds_;
  Vec<Dim> initial_velocity_;
  AngularVec<Dim> initial_angular_velocity_;
  std::vector<Vec<Dim>> samples_;
  double sample_spacing_ = 0;
  bool is_sphere_ = false;
  bool is_box_ = false;
  Vec<Dim> box_center_ = Vec<Dim>::Zero(), box_half_ = Vec<Dim>::Zero();  ///< rest frame
  Mat<Dim> box_rotation_ = Mat<Dim>::Identity();                         ///< rest frame
  double sphere_radius_ = 0;
  ShapeType shape_type_ = ShapeType::box;
  bool periodic_ = false;
  Vec<Dim> period_ = Vec<Dim>::Zero(), domain_lower_ = Vec<Dim>::Zero();  ///< set_periodic
  Mat<Dim> principal_axes_ = Mat<Dim>::Identity();      ///< body frame, columns (3D only)
  Vec<Dim> principal_moments_ = Vec<Dim>::Zero();       ///< 3D only
};

/// Rest-frame surface samples of a shape at spacing about `spacing` (see
/// RigidBody::surface_samples).
template <int Dim>
std::vector<Vec<Dim>> make_surface_samples(const ShapeSpec& spec, const Shape<Dim>& shape,
                                           double spacing);

/// All bodies of the scene, in scene order, with mass properties from mass_properties() and
/// surface samples at `sample_spacing` (<= 0: dx / 2 of the scene's grid). Fixed bodies with an
/// unbounded shape (a halfspace) get zero mass and no samples.
template <int Dim>
std::vector<RigidBody<Dim>> make_bodies(const SceneDesc& scene, double sample_spacing = 0.0);

}  // namespace monolith
