#pragma once
/// \file mesh_sdf.hpp
/// Signed distance to a closed triangle mesh: exact unsigned distance (closest point on the
/// triangles, found through a bounding-volume hierarchy), sign from angle-weighted
/// pseudo-normals (Baerentzen & Aanaes 2005), and a trilinear cache of the exact SDF on a
/// lattice for fast look-ups near the surface. Everything is in the mesh's own frame.

#include <array>
#include <vector>

#include "dim3/mesh.hpp"
#include "reference/core/common.hpp"

namespace monolith {

/// Result of an exact query.
struct MeshQuery {
  double distance = 0.0;  ///< signed: negative inside
  Vec<3> closest;         ///< nearest point on the surface
  Vec<3> normal;          ///< outward unit SDF gradient at the query point
};

class MeshSdf {
 public:
  /// Builds the hierarchy and the pseudo-normals. A mesh whose signed volume is negative
  /// (inward-facing triangles) is flipped first. `cache_cells` is the number of lattice cells
  /// along the longest bounding-box extent (0 = no cache).
  explicit MeshSdf(TriangleMesh mesh, int cache_cells = 64);

  /// Signed distance: the cached trilinear value inside the lattice where it lies within the
  /// band |d| < band(), else the exact one.
  double distance(const Vec<3>& x) const;
  /// Exact signed distance, nearest point and gradient (BVH + pseudo-normal sign).
  MeshQuery exact(const Vec<3>& x) const;
  double exact_distance(const Vec<3>& x) const { return exact(x).distance; }
  /// Generalized winding number (Jacobson et al. 2013) by direct summation of the triangles'
  /// signed solid angles / 4 pi: 1 inside, 0 outside a closed outward-oriented mesh. O(#tri).
  double winding_number(const Vec<3>& x) const;

  const TriangleMesh& mesh() const { return mesh_; }
  Box<3> bounds() const { return bounds_; }
  /// True if the input mesh had inward-facing orientation and was flipped.
  bool was_flipped() const { return flipped_; }
  /// Lattice spacing of the cache (0 without a cache) and the band of cached look-ups.
  double cache_spacing() const { return h_; }
  double band() const { return band_; }

 private:
  struct Node {
    Box<3> box;
    int left = -1, right = -1;  ///< children, or -1 for a leaf
    int begin = 0, end = 0;     ///< leaf range in order_
  };
  int build(int begin, int end);
  void build_pseudo_normals();
  void build_cache(int cells);

  TriangleMesh mesh_;
  Box<3> bounds_;
  bool flipped_ = false;
  std::vector<Node> nodes_;
  std::vector<int> order_;                     ///< triangle ids, permuted by the hierarchy
  std::vector<Vec<3>> face_normal_;            ///< unit, per triangle
  std::vector<std::array<Vec<3>, 3>> edge_normal_;  ///< per triangle edge (k, k+1)
  std::vector<Vec<3>> vertex_normal_;          ///< angle-weighted, per vertex
  // cache lattice
  double h_ = 0.0, band_ = 0.0;
  Vec<3> origin_ = Vec<3>::Zero();
  std::array<int, 3> dims_{0, 0, 0};
  std::vector<double> values_;
};

}  // namespace monolith
