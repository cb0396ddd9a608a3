// libFuzzer target for the Wavefront OBJ reader (dim3/mesh.cpp): any bytes in, either a mesh or
// an InputError out, never a crash or a sanitizer report. A mesh that parses has its bounds and
// signed volume computed (they read every vertex of every triangle). docs/validation.md,
// "Sanitizers and fuzzing".
#include <cstdint>
#include <string_view>

#include "dim3/mesh.hpp"
#include "reference/core/errors.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const monolith::TriangleMesh mesh =
        monolith::parse_obj(std::string_view(reinterpret_cast<const char*>(data), size), "fuzz.obj", "shape.file");
    for (const auto& t : mesh.triangles)
      for (int i : t)
        if (i < 0 || i >= static_cast<int>(mesh.vertices.size())) __builtin_trap();  // an index past the vertices
    (void)mesh.bounds();
    (void)mesh.signed_volume();
  } catch (const monolith::InputError&) {
  }
  return 0;
}
