#pragma once
/// \file shapes_2d.hpp
/// Shapes that exist only in 2D: simple polygons (exact SDF, sign by winding number) and the
/// bunny's silhouette (a polygon read from the embedded asset bunny_silhouette.txt).

#include <string>
#include <string_view>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/geometry/shape.hpp"

namespace monolith {

/// A closed polygon given by its vertices (either orientation; the last vertex connects to the
/// first). distance = +-(exact distance to the nearest edge), negative where the winding number
/// of the boundary around x is non-zero, so both orientations give the same sign.
/// Polygons with many vertices (the bunny) are accelerated without losing exactness: the
/// nearest edge is found through a hierarchy of edge boxes, and the sign is read from a coarse
/// lattice of exact signed distances wherever the interpolated value is farther from zero than
/// its error bound (bilinear interpolation of a 1-Lipschitz function errs by at most
/// sqrt(2)/2 lattice spacings); only near the boundary is the winding number summed.
class PolygonShape : public Shape<2> {
 public:
  explicit PolygonShape(std::vector<Vec<2>> points);
  double distance(const Vec<2>& x) const override;
  Vec<2> gradient(const Vec<2>& x) const override;
  Box<2> bounds() const override { return bounds_; }
  const std::vector<Vec<2>>& points() const { return points_; }
  /// Signed area (shoelace formula): positive for counter-clockwise vertices.
  double signed_area() const;
  /// Winding number of the boundary around x (0 outside, +-1 inside a simple polygon).
  int winding_number(const Vec<2>& x) const;

 private:
  /// Unsigned distance and the nearest boundary point (hierarchy, or all edges if small).
  double nearest(const Vec<2>& x, Vec<2>* point) const;
  /// Brute force over all edges.
  double nearest_all(const Vec<2>& x, Vec<2>* point) const;
  /// True if x is inside (winding number non-zero), using the sign lattice where decisive.
  bool inside(const Vec<2>& x) const;
  int build(int begin, int end);
  void build_sign_lattice();

  struct Node {
    Box<2> box;
    int left = -1, right = -1;  ///< children, or -1 for a leaf
    int begin = 0, end = 0;     ///< leaf range in order_
  };
  std::vector<Vec<2>> points_;
  Box<2> bounds_;
  std::vector<Node> nodes_;     ///< empty for small polygons
  std::vector<int> order_;      ///< edge ids, permuted by the hierarchy
  double h_ = 0.0;              ///< sign lattice spacing (0: no lattice)
  Vec<2> origin_ = Vec<2>::Zero();
  int nx_ = 0, ny_ = 0;
  std::vector<double> lattice_;  ///< exact signed distance at the lattice nodes
};

/// Parses "x y" lines (blank lines and lines starting with # skipped) into points; throws
/// InputError naming `label`, the line and `key_path` on a malformed line.
std::vector<Vec<2>> parse_point_list(std::string_view text, const std::string& label,
                                     const std::string& key_path);

/// The bunny silhouette outline in the mesh's units (x right, y up), from the embedded asset.
const std::vector<Vec<2>>& bunny_silhouette_points();

}  // namespace monolith
