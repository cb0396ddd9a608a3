#pragma once
/// \file shape_spec.hpp
/// The plain description of a shape (a scene's `shape` objects, docs/scene-format.md), from
/// which make_shape (shape.hpp) builds the signed distance function. Vectors are
/// std::vector<double> of the scene's dimension; the scene parser has checked their lengths.

#include <filesystem>
#include <vector>

#include "reference/core/enum_names.hpp"

namespace monolith {

/// The shape types. polygon is 2D only, mesh 3D only; set_union and set_difference combine
/// the shapes of ShapeSpec::shapes.
enum class ShapeType {
  box,
  sphere,
  bowl,
  shell,
  halfspace,
  polygon,
  mesh,
  bunny,
  set_union,
  set_difference
};

template <>
struct EnumNames<ShapeType> {
  static constexpr std::array<std::pair<ShapeType, const char*>, 10> values{
      {{ShapeType::box, "box"},
       {ShapeType::sphere, "sphere"},
       {ShapeType::bowl, "bowl"},
       {ShapeType::shell, "shell"},
       {ShapeType::halfspace, "halfspace"},
       {ShapeType::polygon, "polygon"},
       {ShapeType::mesh, "mesh"},
       {ShapeType::bunny, "bunny"},
       {ShapeType::set_union, "union"},
       {ShapeType::set_difference, "difference"}}};
};

/// One shape: its type and the parameters of that type (the other fields are unused).
struct ShapeSpec {
  ShapeType type = ShapeType::box;
  std::vector<double> center;     ///< box, sphere, bowl, shell, bunny
  std::vector<double> half_size;  ///< box
  double radius = 0.0;            ///< sphere, bowl, shell (outer radius)
  double thickness = 0.0;         ///< bowl, shell (inner radius = radius - thickness)
  std::vector<double> normal;     ///< halfspace: inside is normal . x <= offset
  double offset = 0.0;            ///< halfspace
  std::vector<std::vector<double>> points;  ///< polygon (2D only), counter-clockwise or not
  std::filesystem::path file;      ///< mesh (3D only): the Wavefront OBJ file to read
  std::vector<double> scale{1.0};  ///< mesh: 1 number (uniform) or dim numbers
  std::vector<double> translate;   ///< mesh: empty = zero
  double size = 0.0;               ///< bunny: extent of its bounding box along its longest axis
  std::vector<double> rotation;    ///< optional: 2D one angle, 3D axis-angle 3-vector; empty = none
  std::vector<ShapeSpec> shapes;   ///< set_union, set_difference (first minus the rest)
};

}  // namespace monolith
