#pragma once
/// \file body_spec.hpp
/// The plain description of a rigid body (a scene's `bodies` entries, docs/scene-format.md),
/// from which RigidBody (rigid_body.hpp) and make_bodies build the bodies.

#include <string>
#include <vector>

#include "reference/core/enum_names.hpp"
#include "reference/geometry/shape_spec.hpp"

namespace monolith {

/// Motion type of a body: `dynamic` (two-way coupled), `fixed` ("static" in scenes) and
/// `kinematic` (prescribed path, one-way).
enum class BodyMotion { dynamic, fixed, kinematic };

template <>
struct EnumNames<BodyMotion> {
  static constexpr std::array<std::pair<BodyMotion, const char*>, 3> values{
      {{BodyMotion::dynamic, "dynamic"}, {BodyMotion::fixed, "static"}, {BodyMotion::kinematic, "kinematic"}}};
};

/// The prescribed paths of kinematic bodies.
enum class PathType { oscillate };

template <>
struct EnumNames<PathType> {
  static constexpr std::array<std::pair<PathType, const char*>, 1> values{{{PathType::oscillate, "oscillate"}}};
};

/// Prescribed path of a kinematic body: position offset = axis * amplitude * sin(2 pi f t).
struct PathSpec {
  PathType type = PathType::oscillate;
  std::vector<double> axis;
  double amplitude = 0.0;
  double frequency = 0.0;
};

struct BodySpec {
  std::string name;
  BodyMotion motion = BodyMotion::dynamic;
  ShapeSpec shape;
  double density = 0.0;
  std::vector<double> velocity;          ///< dim numbers; empty = zero
  std::vector<double> angular_velocity;  ///< 2D: 1 number, 3D: 3 numbers; empty = zero
  double restitution = 0.0;
  double friction = 0.0;
  bool has_path = false;  ///< kinematic bodies: `path` is set
  PathSpec path;
};

}  // namespace monolith
