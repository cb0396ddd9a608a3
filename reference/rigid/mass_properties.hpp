#pragma once
/// \file mass_properties.hpp
/// Rigid-body degrees of freedom (the angular part differs between 2D and 3D) and mass
/// properties from density and the true geometry (§4.4.7). reference/rigid/rigid_body.hpp includes
/// this header, so users of RigidBody get the traits below from there.

#include <Eigen/Geometry>
#include <array>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/geometry/shape_spec.hpp"

namespace monolith {

/// Angular degrees of freedom of a rigid body: 2D one angle (counter-clockwise), 3D a unit
/// quaternion. Specialised for Dim = 2 and Dim = 3 only.
template <int Dim>
struct RigidTraits;

template <>
struct RigidTraits<2> {
  static constexpr int kAngular = 1;
  using Orientation = double;  ///< angle (radians, counter-clockwise)
  static Orientation identity() { return 0.0; }
};

template <>
struct RigidTraits<3> {
  static constexpr int kAngular = 3;
  using Orientation = Eigen::Quaterniond;  ///< unit quaternion, body -> world
  static Orientation identity() { return Eigen::Quaterniond::Identity(); }
};

template <int Dim>
inline constexpr int kAngularDofs = RigidTraits<Dim>::kAngular;
template <int Dim>
inline constexpr int kBodyDofs = Dim + kAngularDofs<Dim>;  ///< 3 in 2D, 6 in 3D
template <int Dim>
using AngularVec = Eigen::Matrix<double, kAngularDofs<Dim>, 1>;
template <int Dim>
using AngularMat = Eigen::Matrix<double, kAngularDofs<Dim>, kAngularDofs<Dim>>;
/// Generalised velocity (v, omega): rows 0..Dim-1 linear, then the angular rows.
template <int Dim>
using BodyVec = Eigen::Matrix<double, kBodyDofs<Dim>, 1>;

/// omega x r: 2D (0, 0, w) x (r, 0) = w (-r_y, r_x); 3D the usual cross product.
template <int Dim>
Vec<Dim> angular_cross(const AngularVec<Dim>& w, const Vec<Dim>& r);
/// r x f: 2D the scalar r_x f_y - r_y f_x (the z torque); 3D the usual cross product.
template <int Dim>
AngularVec<Dim> moment(const Vec<Dim>& r, const Vec<Dim>& f);
/// Rotation matrix of an orientation (body -> world).
template <int Dim>
Mat<Dim> orientation_matrix(const typename RigidTraits<Dim>::Orientation& q);

/// §4.4.7: mass from density x the TRUE geometric volume (never the grid fractions).
template <int Dim>
struct MassProperties {
  double volume = 0, mass = 0;
  Vec<Dim> center_of_mass = Vec<Dim>::Zero();         ///< world frame at rest (t = 0)
  AngularMat<Dim> inertia = AngularMat<Dim>::Zero();  ///< about the centre of mass, world axes at
                                                      ///< rest; 2D: 1x1 (kg m^2 per m)
};

/// Mass properties of a shape of uniform density. Closed forms for box, sphere (disk), bowl,
/// shell (2D ring; the 2D bowl is a half ring), polygon (exact, any simple polygon, by the
/// shoelace-type sums over edges), mesh and 3D bunny (exact for closed triangle meshes by the
/// divergence theorem on signed tetrahedra), with the shape's rotation applied
/// (c -> R (c - pivot) + pivot, I -> R I R^T). Union, difference (and any other type):
/// numerical integration of the SDF on a lattice (integrate_mass_properties). `shape` must be
/// make_shape<Dim>(spec) (it is used for the numerical integration and the bounds).
/// Throws InputError for an unbounded shape (halfspace).
template <int Dim>
MassProperties<Dim> mass_properties(const ShapeSpec& spec, const Shape<Dim>& shape, double density);

/// Lattice resolution (cells along the longest side of the bounds) that mass_properties uses
/// for union/difference.
inline constexpr int kIntegrationCells2d = 2048;
inline constexpr int kIntegrationCells3d = 160;

/// Numerical integration of volume, centre of mass and inertia over {distance < 0} inside
/// `region`, on a lattice of `cells_per_axis` cells along the longest side of `region`. Each
/// cell contributes the fraction clamp(1/2 - d / h, 0, 1) of its volume, d the SDF at the
/// cell centre (a first-order smoothed Heaviside: second-order accurate for smooth surfaces,
/// first order at corners), plus the cell's own second moment h^2/12 per axis. Measured
/// relative errors (tests/test_mass_properties.cpp): a 3D ball minus a concentric ball at 160
/// cells, inertia 2.0e-4 and mass 5.2e-5; a rotated 3D box, inertia 6.1e-4; 2D shapes at 2048
/// cells, below 1e-5.
template <int Dim>
MassProperties<Dim> integrate_mass_properties(const Shape<Dim>& shape, const Box<Dim>& region,
                                              int cells_per_axis, double density);

/// The unrotated 2D bunny outline placed as make_shape places it (longest extent = size,
/// bounding-box centre at `center`).
std::vector<Vec<2>> bunny_outline(const Vec<2>& center, double size);

struct TriangleMesh;

/// The geometry of a 2D "polygon" or "bunny" spec before its rotation: the outline points (as
/// make_shape places them) and the pivot of the spec's rotation (the vertex mean for a polygon,
/// the centre for the bunny); false for any other type. Shared by the mass properties and the
/// body surface samples so both see the same outline.
bool unrotated_geometry(const ShapeSpec& spec, std::vector<Vec<2>>* outline, Vec<2>* pivot);
/// The same for a 3D "mesh" (as make_shape reads it, flipped if inward-oriented; pivot: the
/// translation) or "bunny" (pivot: the centre) spec: the unrotated triangle mesh.
bool unrotated_geometry(const ShapeSpec& spec, TriangleMesh* mesh, Vec<3>* pivot);

/// Exact mass properties of a simple polygon (either orientation).
MassProperties<2> polygon_mass_properties(const std::vector<Vec<2>>& points, double density);

/// Exact mass properties of a closed triangle mesh (3D), by the divergence theorem on signed
/// tetrahedra against the bounding-box centre; outward orientation assumed (an inward-oriented
/// mesh gives a negative volume: callers flip it).
MassProperties<3> triangle_mesh_mass_properties(const std::vector<Vec<3>>& vertices,
                                                const std::vector<std::array<int, 3>>& triangles,
                                                double density);

}  // namespace monolith
