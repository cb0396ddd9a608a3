#pragma once
/// \file embedded_assets.hpp
/// The geometry data of the built-in `bunny` shape, compiled into the core by
/// cmake/embed_files.cmake: dim3/assets/bunny.obj and dim2/assets/bunny_silhouette.txt, named by
/// file name.

#include <vector>

#include "reference/core/embedded_file.hpp"

namespace monolith {

const std::vector<EmbeddedFile>& embedded_assets();

}  // namespace monolith
