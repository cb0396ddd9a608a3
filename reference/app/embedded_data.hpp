#pragma once
/// \file embedded_data.hpp
/// Files compiled into the binary by cmake/embed_files.cmake: the built-in scenes
/// (dim2/scenes/*.json, dim3/scenes/*.json, named by file stem) and assets (dim3/assets/bunny.obj,
/// dim2/assets/bunny_silhouette.txt, named by file name).

#include <string_view>
#include <vector>

namespace monolith {

struct EmbeddedFile {
  std::string_view name;
  std::string_view data;
};

const std::vector<EmbeddedFile>& embedded_scenes();
const std::vector<EmbeddedFile>& embedded_assets();

}  // namespace monolith
