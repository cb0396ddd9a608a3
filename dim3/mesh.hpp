#pragma once
/// \file mesh.hpp
/// Triangle meshes and Wavefront OBJ loading (3D only).

#include <array>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "reference/core/common.hpp"

namespace monolith {

/// An indexed triangle mesh. Triangles are counter-clockwise seen from outside for a
/// positively oriented closed mesh (signed_volume() > 0).
struct TriangleMesh {
  std::vector<Vec<3>> vertices;
  std::vector<std::array<int, 3>> triangles;

  /// Axis-aligned bounding box of the vertices.
  Box<3> bounds() const;
  /// Enclosed volume by the divergence theorem, sum over triangles of (a . (b x c)) / 6;
  /// positive for outward-facing triangles of a closed mesh.
  double signed_volume() const;
  /// Reverses the orientation of every triangle.
  void flip();
  /// Applies x -> scale (component-wise) * x + translate to every vertex.
  void transform(const Vec<3>& scale, const Vec<3>& translate);
};

/// Parses OBJ text: `v x y z` and `f` with i, i/j, i//k, i/j/k (1-based or negative = relative)
/// indices; polygon faces are fan-triangulated; vn, vt, o, g, s, usemtl, mtllib, l and comments
/// are ignored. Throws InputError with lines `LABEL:LINE: KEY_PATH: problem (what is allowed)`
/// for a bad number, a non-finite coordinate, an index out of range, a face with fewer than 3
/// vertices, an unknown statement, or a file without faces.
TriangleMesh parse_obj(std::string_view text, const std::string& label,
                       const std::string& key_path);

/// Reads and parses an OBJ file; a missing or unreadable file throws InputError.
TriangleMesh load_obj(const std::filesystem::path& file, const std::string& key_path);

}  // namespace monolith
