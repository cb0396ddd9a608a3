#pragma once
/// \file boundary.hpp
/// The condition on each face of the domain box (docs/scene-format.md, `domain.boundary`), in
/// the face order x-, x+, y-, y+ (, z-, z+).

#include "reference/core/enum_names.hpp"

namespace monolith {

/// wall: a fixed solid wall (no flow through it, contacts with bodies); open: air outside
/// (particles leaving through it are removed); periodic: the face is glued to the opposite one
/// (both faces of the axis must be periodic).
enum class BoundaryType { wall, open, periodic };

template <>
struct EnumNames<BoundaryType> {
  static constexpr std::array<std::pair<BoundaryType, const char*>, 3> values{
      {{BoundaryType::wall, "wall"}, {BoundaryType::open, "open"}, {BoundaryType::periodic, "periodic"}}};
};

}  // namespace monolith
