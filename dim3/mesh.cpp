/// \file mesh.cpp
/// Triangle meshes and the OBJ reader.

#include "dim3/mesh.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "reference/core/errors.hpp"

namespace monolith {

Box<3> TriangleMesh::bounds() const {
  Box<3> b;
  for (const auto& v : vertices) b.extend(v);
  return b;
}

double TriangleMesh::signed_volume() const {
  // divergence theorem: each triangle spans a tetrahedron with the origin
  double v = 0.0;
  for (const auto& t : triangles) {
    v += vertices[t[0]].dot(vertices[t[1]].cross(vertices[t[2]]));
  }
  return v / 6.0;
}

void TriangleMesh::flip() {
  for (auto& t : triangles) std::swap(t[1], t[2]);
}

void TriangleMesh::transform(const Vec<3>& scale, const Vec<3>& translate) {
  for (auto& v : vertices) v = scale.cwiseProduct(v) + translate;
  // a mirror (odd number of negative scale factors) reverses the orientation
  if (scale.prod() < 0.0) flip();
}

namespace {

/// Parses one whole token as a double; false on trailing garbage.
bool parse_double(const std::string& token, double* value) {
  if (token.empty()) return false;
  char* end = nullptr;
  errno = 0;
  *value = std::strtod(token.c_str(), &end);
  return end == token.c_str() + token.size() && errno != ERANGE;
}

/// Parses one whole token as an integer; false on trailing garbage.
bool parse_int(const std::string& token, long* value) {
  if (token.empty()) return false;
  char* end = nullptr;
  errno = 0;
  *value = std::strtol(token.c_str(), &end, 10);
  return end == token.c_str() + token.size() && errno != ERANGE;
}

}  // namespace

TriangleMesh parse_obj(std::string_view text, const std::string& label,
                       const std::string& key_path) {
  TriangleMesh mesh;
  std::istringstream in{std::string(text)};
  std::string line;
  int line_no = 0;
  auto fail = [&](const std::string& what) {
    throw InputError(label + ":" + std::to_string(line_no) + ": " + key_path + ": " + what);
  };
  while (std::getline(in, line)) {
    ++line_no;
    // strip comments and carriage returns
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream ls(line);
    std::string cmd;
    if (!(ls >> cmd)) continue;
    if (cmd == "v") {
      // a vertex: three finite coordinates (an optional fourth w or colour is ignored)
      std::string tok[3];
      Vec<3> p;
      for (int a = 0; a < 3; ++a) {
        if (!(ls >> tok[a])) fail("vertex with fewer than 3 coordinates (v x y z)");
        if (!parse_double(tok[a], &p[a])) {
          fail("bad number \"" + tok[a] + "\" in a vertex (v x y z with decimal numbers)");
        }
        if (!std::isfinite(p[a])) fail("non-finite coordinate \"" + tok[a] + "\" (finite numbers)");
      }
      mesh.vertices.push_back(p);
    } else if (cmd == "f") {
      // a face: i, i/j, i//k or i/j/k per corner; negative indices count back from the end
      std::vector<int> corners;
      std::string tok;
      const long nv = static_cast<long>(mesh.vertices.size());
      while (ls >> tok) {
        const std::string head = tok.substr(0, tok.find('/'));
        long idx = 0;
        if (!parse_int(head, &idx)) {
          fail("bad face index \"" + tok + "\" (i, i/j, i//k or i/j/k with integer i)");
        }
        const long resolved = idx > 0 ? idx - 1 : nv + idx;
        if (idx == 0 || resolved < 0 || resolved >= nv) {
          fail("face index " + std::to_string(idx) + " is out of range (1.." +
               std::to_string(nv) + " or -" + std::to_string(nv) + "..-1 for the " +
               std::to_string(nv) + " vertices defined so far)");
        }
        corners.push_back(static_cast<int>(resolved));
      }
      if (corners.size() < 3) {
        fail("face with " + std::to_string(corners.size()) + " vertices (at least 3)");
      }
      // fan triangulation of polygon faces
      for (std::size_t k = 1; k + 1 < corners.size(); ++k) {
        mesh.triangles.push_back({corners[0], corners[k], corners[k + 1]});
      }
    } else if (cmd == "vn" || cmd == "vt" || cmd == "vp" || cmd == "o" || cmd == "g" ||
               cmd == "s" || cmd == "usemtl" || cmd == "mtllib" || cmd == "l") {
      continue;
    } else {
      fail("unknown statement \"" + cmd + "\" (v, f; vn, vt, o, g, s, usemtl, mtllib are ignored)");
    }
  }
  if (mesh.triangles.empty()) {
    line_no = std::max(line_no, 1);
    fail("the file has no faces (a closed triangle mesh with f lines)");
  }
  return mesh;
}

TriangleMesh load_obj(const std::filesystem::path& file, const std::string& key_path) {
  std::ifstream in(file, std::ios::binary);
  if (!in) {
    throw InputError(file.string() + ": " + key_path + ": cannot open the mesh file (an existing, "
                     "readable Wavefront OBJ file; relative paths start at the scene's folder)");
  }
  std::ostringstream s;
  s << in.rdbuf();
  return parse_obj(s.str(), file.string(), key_path);
}

}  // namespace monolith
