#pragma once
/// \file embedded_file.hpp
/// A file compiled into the program by cmake/embed_files.cmake (the core's geometry assets,
/// reference/geometry/embedded_assets.hpp; the application's built-in scenes,
/// reference/app/embedded_scenes.hpp), so the program runs from anywhere without the source tree.

#include <string_view>

namespace monolith {

struct EmbeddedFile {
  std::string_view name;
  std::string_view data;
};

}  // namespace monolith
