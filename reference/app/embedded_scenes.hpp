#pragma once
/// \file embedded_scenes.hpp
/// The built-in scenes (dim2/scenes/*.json, dim3/scenes/*.json, named by file stem), compiled
/// into the application by cmake/embed_files.cmake: `monolith list`, and `monolith run NAME`
/// without the source tree.

#include <vector>

#include "reference/core/embedded_file.hpp"

namespace monolith {

const std::vector<EmbeddedFile>& embedded_scenes();

}  // namespace monolith
