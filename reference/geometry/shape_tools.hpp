#pragma once
/// \file shape_tools.hpp
/// Building blocks shared by the dimension-generic shapes (reference/geometry/shape.cpp) and the
/// dimension-specific ones (dim2/shapes_2d.cpp: polygon, bunny silhouette; dim3/shapes_3d.cpp:
/// triangle meshes, the bunny): rotations from the scene's `rotation` key, a rotated wrapper,
/// the factory hook that make_shape<Dim> calls for dimension-specific types, and volume_inside.

#include <string>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/geometry/shape.hpp"

namespace monolith {

/// Rotation matrix of a scene `rotation` value: 2D one angle (radians, counter-clockwise),
/// 3D an axis-angle 3-vector (direction = axis, length = angle in radians). Empty = identity.
/// Specialised for Dim = 2 and Dim = 3 (the only place where the two differ).
template <int Dim>
Mat<Dim> rotation_matrix(const std::vector<double>& rotation);

/// Converts a scene vector (already validated to have Dim entries) to Vec<Dim>.
template <int Dim>
Vec<Dim> to_vec(const std::vector<double>& v);

/// A shape rotated by R about `pivot`: distance(x) = inner.distance(R^T (x - pivot) + pivot).
/// Rigid motions preserve distances, so an exact inner SDF stays exact.
template <int Dim>
class RotatedShape : public Shape<Dim> {
 public:
  RotatedShape(ShapePtr<Dim> inner, const Mat<Dim>& rotation, const Vec<Dim>& pivot);
  double distance(const Vec<Dim>& x) const override;
  Vec<Dim> gradient(const Vec<Dim>& x) const override;
  /// The box around the rotated corners of the inner bounds (infinite if those are).
  Box<Dim> bounds() const override;

 private:
  Vec<Dim> to_inner(const Vec<Dim>& x) const;
  ShapePtr<Dim> inner_;
  Mat<Dim> rotation_;
  Vec<Dim> pivot_;
};

/// Wraps `shape` in a RotatedShape about `pivot` when spec.rotation is non-trivial.
template <int Dim>
ShapePtr<Dim> apply_rotation(ShapePtr<Dim> shape, const ShapeSpec& spec, const Vec<Dim>& pivot);

/// Builds the shape types that exist only in one dimension (2D: polygon, bunny silhouette;
/// 3D: mesh, bunny), rotation included. Defined in dim2/shapes_2d.cpp for Dim = 2 and in
/// dim3/shapes_3d.cpp for Dim = 3. Returns nullptr when `spec.type` is not one of them; throws
/// InputError for a type of the other dimension or an unbuildable shape.
template <int Dim>
ShapePtr<Dim> make_dimension_shape(const ShapeSpec& spec, const std::string& key_path);

/// Midpoint-rule volume (area in 2D) of {x in region : shape.distance(x) < 0}, with
/// samples_per_axis^Dim samples at the centres of a uniform subdivision of `region`.
/// The error is O(surface measure * h) for h = region extent / samples_per_axis.
template <int Dim>
double volume_inside(const Shape<Dim>& shape, const Box<Dim>& region, int samples_per_axis);

}  // namespace monolith
