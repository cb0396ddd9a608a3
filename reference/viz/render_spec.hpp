#pragma once
/// \file render_spec.hpp
/// How the frame pictures are drawn (a scene's `render` object, docs/scene-format.md): whether
/// they are written, their size, and the field that colours the liquid.

#include <array>

#include "reference/core/enum_names.hpp"

namespace monolith {

/// The field that colours the liquid: none (plain water), speed |u|, pressure p, or the
/// effective viscosity eta.
enum class ColorBy { none, speed, pressure, viscosity };

template <>
struct EnumNames<ColorBy> {
  static constexpr std::array<std::pair<ColorBy, const char*>, 4> values{{{ColorBy::none, "none"},
                                                                          {ColorBy::speed, "speed"},
                                                                          {ColorBy::pressure, "pressure"},
                                                                          {ColorBy::viscosity, "viscosity"}}};
};

struct RenderSpec {
  bool enabled = true;
  std::array<int, 2> size{512, 512};
  ColorBy color_by = ColorBy::speed;
};

}  // namespace monolith
