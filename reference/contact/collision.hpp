#pragma once
/// \file collision.hpp
/// Collision detection between rigid bodies and with the domain walls (§3.2.4): broad phase on
/// world bounding boxes, narrow phase by surface samples tested against the other body's
/// signed distance (both directions; spheres exactly from their centres), normals from SDF
/// gradients, then contact reduction per pair. docs/rigid-bodies.md describes it.

#include <array>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/rigid/rigid_body.hpp"
#include "reference/sim/scene_desc.hpp"

namespace monolith {

/// The domain's wall faces as half-spaces.
template <int Dim>
struct Walls {
  Vec<Dim> lower = Vec<Dim>::Zero(), upper = Vec<Dim>::Zero();
  /// Per face in the order x-, x+, y-, y+ (, z-, z+): true for a `wall` boundary.
  std::array<bool, 2 * Dim> is_wall{};
  double friction = 0, restitution = 0;
  static Walls from_scene(const SceneDesc& scene);
  /// Inward unit normal of face f (pointing into the domain).
  static Vec<Dim> face_normal(int face);
  /// Signed distance of x from the plane of face f (positive inside the domain).
  double face_distance(int face, const Vec<Dim>& x) const;
};

template <int Dim>
struct Contact {
  int body_a = -1;  ///< index into bodies: always a dynamic body
  int body_b = -1;  ///< index into bodies, or -1 for a domain wall
  int wall_face = -1;  ///< face index (x-, x+, y-, ...) when body_b == -1
  Vec<Dim> point = Vec<Dim>::Zero();   ///< world contact point (on the surface of body_b / the wall)
  Vec<Dim> normal = Vec<Dim>::Zero();  ///< unit, from b towards a: the direction in which a must
                                       ///< move to separate
  double phi = 0;  ///< one entry of the constraint vector phi(x) >= 0 of eqs. (9) and (16):
                   ///< the signed gap along normal (negative = penetration), WITHOUT the
                   ///< margin epsilon of §3.2.4 (the contact model adds it)
  double friction = 0, restitution = 0;  ///< combined per pair: sqrt(mu_a mu_b), max(e_a, e_b);
                                         ///< a wall counts as a body with Walls::friction and
                                         ///< Walls::restitution (the scene contract's rule)
  /// The point on the surface of body_a: point + phi * normal.
  Vec<Dim> point_a() const { return point + phi * normal; }
};

/// Parameters of the contact reduction.
struct ContactReduction {
  /// A sample x of body P tested against body Q is a candidate only if the contact normal,
  /// seen as an outward direction of P, lies within this angle (cosine) of P's normal cone at
  /// x (RigidBody::normal_cone_cosine). For boxes the cone is exact (a face's normal, an
  /// edge's or corner's fan), so the test can be tight: it drops the side faces of a box
  /// next to a floor and the fan of normals that parallel edges would otherwise produce.
  double box_cone_cosine = 0.9;
  /// The same for other shapes, whose cone is approximated by the SDF gradient at x (a
  /// polygon's or mesh's vertex has a single averaged normal: 0.5 keeps 3D corners, at 0.58).
  double accept_cosine = 0.5;
  /// Candidates whose normals are within this angle (cosine) of a cluster's normal form one
  /// patch.
  double cluster_cosine = 0.95;
  /// Points kept per patch: 2 in 2D, 4 in 3D (the extreme points of the patch).
  int max_points_2d = 2, max_points_3d = 4;
  /// After the reduction, a point of a smaller patch within this distance of a point already
  /// kept from a larger patch is dropped (the same place seen with a second normal, e.g.
  /// where the edges of two equal stacked boxes coincide). <= 0: detect_contacts uses half
  /// the larger sample spacing of the pair.
  double merge_distance = 0.0;
};

/// Algorithm 1, line 6 ("detect collisions between rigid bodies"): the rows of phi(x) of
/// eqs. (9)-(16) with their points and normals, from which J_lambda and J_z are built.
/// All contacts with phi < search_distance between pairs of bodies (not both non-dynamic) and
/// between dynamic bodies and walls. body_a is the dynamic body of a pair (the lower index if
/// both are dynamic), body_b the other one (fixed, kinematic, dynamic, or -1 for a wall).
/// Broad phase on world AABBs (grown by search_distance), then surface samples of each body
/// against the other's SDF, both directions, normals from SDF gradients (sphere-sphere and
/// sphere-wall exactly: one contact from centre distances; a sphere against any other body:
/// the nearest point to its centre plus the other's samples facing the centre, one point per
/// normal patch), then contact reduction per pair: the candidates are clustered by normal and
/// each patch keeps its deepest point and the points that span it (<= 4 in 3D, 2 in 2D).
/// Order: body pairs by (min, max) index, then walls by body and face; deterministic and
/// independent of the number of threads. docs/rigid-bodies.md has the details.
template <int Dim>
std::vector<Contact<Dim>> detect_contacts(const std::vector<RigidBody<Dim>>& bodies,
                                          const Walls<Dim>& walls, double search_distance,
                                          const ContactReduction& reduction = {});

/// Reduces candidate contacts of one pair (same body_a, body_b) to a few extreme points per
/// normal cluster (exposed for tests).
template <int Dim>
std::vector<Contact<Dim>> reduce_contacts(std::vector<Contact<Dim>> candidates,
                                          const ContactReduction& reduction = {});

}  // namespace monolith
