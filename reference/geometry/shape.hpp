#pragma once
/// \file shape.hpp
/// Signed distance functions (SDFs) for the shape types of the scene format, in 2D and 3D.
/// Convention: negative inside, positive outside, |gradient| = 1 where differentiable. Primitive
/// shapes are exact; union/difference are min/max combinations (exact outside a union and inside
/// a difference, a bound elsewhere), as is standard.

#include <memory>
#include <string>

#include "reference/core/common.hpp"
#include "reference/geometry/shape_spec.hpp"

namespace monolith {

template <int Dim>
class Shape {
 public:
  virtual ~Shape() = default;
  /// Signed distance from x to the surface (negative inside).
  virtual double distance(const Vec<Dim>& x) const = 0;
  /// Outward unit normal at the surface point nearest to x (the SDF gradient). The default takes
  /// central differences of distance().
  virtual Vec<Dim> gradient(const Vec<Dim>& x) const;
  /// Axis-aligned bounds of the inside region; unbounded directions hold +-infinity.
  virtual Box<Dim> bounds() const = 0;
};

template <int Dim>
using ShapePtr = std::shared_ptr<const Shape<Dim>>;

/// Builds the SDF of a validated ShapeSpec. `key_path` (e.g. "bodies[1].shape") is used in error
/// messages; throws InputError for shapes that cannot be built (an unreadable or malformed mesh
/// file, a degenerate polygon).
template <int Dim>
ShapePtr<Dim> make_shape(const ShapeSpec& spec, const std::string& key_path);

}  // namespace monolith
