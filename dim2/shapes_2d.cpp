/// \file shapes_2d.cpp
/// 2D-only shapes (polygon, bunny silhouette) and make_dimension_shape<2>.

#include "dim2/shapes_2d.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "reference/embedded_data.hpp"
#include "reference/errors.hpp"
#include "reference/shape_tools.hpp"

namespace monolith {

namespace {

/// z-component of the cross product of 2D vectors.
double cross(const Vec<2>& a, const Vec<2>& b) { return a[0] * b[1] - a[1] * b[0]; }

}  // namespace

PolygonShape::PolygonShape(std::vector<Vec<2>> points) : points_(std::move(points)) {
  for (const auto& p : points_) bounds_.extend(p);
}

double PolygonShape::signed_area() const {
  double a = 0.0;
  const std::size_t n = points_.size();
  for (std::size_t i = 0; i < n; ++i) a += cross(points_[i], points_[(i + 1) % n]);
  return 0.5 * a;
}

int PolygonShape::winding_number(const Vec<2>& x) const {
  // count signed crossings of the upward ray through x (Sunday's crossing rule)
  int w = 0;
  const std::size_t n = points_.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Vec<2>& a = points_[i];
    const Vec<2>& b = points_[(i + 1) % n];
    const double side = cross(b - a, x - a);  // > 0: x left of a->b
    if (a[1] <= x[1]) {
      if (b[1] > x[1] && side > 0.0) ++w;  // upward edge, x on its left
    } else if (b[1] <= x[1] && side < 0.0) {
      --w;  // downward edge, x on its right
    }
  }
  return w;
}

double PolygonShape::nearest(const Vec<2>& x, Vec<2>* point) const {
  // exact distance: minimum over the edges of the distance to a segment
  double best = std::numeric_limits<double>::infinity();
  const std::size_t n = points_.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Vec<2>& a = points_[i];
    const Vec<2> e = points_[(i + 1) % n] - a;
    const double len2 = e.squaredNorm();
    const double t = len2 > 0.0 ? std::clamp((x - a).dot(e) / len2, 0.0, 1.0) : 0.0;
    const Vec<2> q = a + t * e;
    const double d2 = (x - q).squaredNorm();
    if (d2 < best) {
      best = d2;
      if (point) *point = q;
    }
  }
  return std::sqrt(best);
}

double PolygonShape::distance(const Vec<2>& x) const {
  const double d = nearest(x, nullptr);
  return winding_number(x) != 0 ? -d : d;
}

Vec<2> PolygonShape::gradient(const Vec<2>& x) const {
  // direction from the nearest boundary point, pointing outwards
  Vec<2> q;
  const double d = nearest(x, &q);
  if (d < 1e-12 * (1.0 + bounds_.sizes().norm())) return Shape<2>::gradient(x);
  const Vec<2> g = (x - q) / d;
  return winding_number(x) != 0 ? Vec<2>(-g) : g;
}

std::vector<Vec<2>> parse_point_list(std::string_view text, const std::string& label,
                                     const std::string& key_path) {
  std::vector<Vec<2>> points;
  std::istringstream in{std::string(text)};
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream ls(line);
    double x = 0.0, y = 0.0;
    std::string rest;
    if (!(ls >> x >> y) || (ls >> rest) || !std::isfinite(x) || !std::isfinite(y)) {
      throw InputError(label + ":" + std::to_string(line_no) + ": " + key_path +
                       ": malformed point \"" + line + "\" (two finite numbers \"x y\")");
    }
    points.emplace_back(x, y);
  }
  return points;
}

const std::vector<Vec<2>>& bunny_silhouette_points() {
  static const std::vector<Vec<2>> points = [] {
    for (const auto& f : embedded_assets()) {
      if (f.name == "bunny_silhouette.txt") {
        return parse_point_list(f.data, "builtin:bunny_silhouette.txt", "bunny");
      }
    }
    return std::vector<Vec<2>>{};
  }();
  return points;
}

template <>
ShapePtr<2> make_dimension_shape<2>(const ShapeSpec& spec, const std::string& key_path) {
  if (spec.type == "polygon") {
    // at least three points, non-zero area
    std::vector<Vec<2>> pts;
    for (std::size_t i = 0; i < spec.points.size(); ++i) {
      const auto& p = spec.points[i];
      if (p.size() != 2 || !std::isfinite(p[0]) || !std::isfinite(p[1])) {
        throw InputError(key_path + ".points[" + std::to_string(i) +
                         "]: is not a point (two finite numbers [x, y])");
      }
      pts.emplace_back(p[0], p[1]);
    }
    if (pts.size() < 3) {
      throw InputError(key_path + ".points: has " + std::to_string(pts.size()) +
                       " points (at least 3)");
    }
    auto poly = std::make_shared<PolygonShape>(pts);
    if (!(std::abs(poly->signed_area()) > 0.0)) {
      throw InputError(key_path + ".points: the polygon has zero area (a non-degenerate polygon)");
    }
    // rotation centre: the vertex centroid
    Vec<2> centroid = Vec<2>::Zero();
    for (const auto& p : pts) centroid += p;
    centroid /= static_cast<double>(pts.size());
    return apply_rotation<2>(poly, spec, centroid);
  }
  if (spec.type == "bunny") {
    const auto& raw = bunny_silhouette_points();
    if (raw.size() < 3) {
      throw InputError(key_path + ": the embedded bunny silhouette is missing from this build "
                       "(rebuild with dim2/assets/bunny_silhouette.txt)");
    }
    if (spec.center.size() != 2) {
      throw InputError(key_path + ".center: has " + std::to_string(spec.center.size()) +
                       " numbers (2 numbers)");
    }
    if (!(spec.size > 0.0) || !std::isfinite(spec.size)) {
      throw InputError(key_path + ".size: must be a finite number > 0");
    }
    // scale the longest bounding-box extent to `size`, centre the box at `center`
    Box<2> b;
    for (const auto& p : raw) b.extend(p);
    const double s = spec.size / b.sizes().maxCoeff();
    const Vec<2> c = to_vec<2>(spec.center);
    std::vector<Vec<2>> pts;
    pts.reserve(raw.size());
    for (const auto& p : raw) pts.push_back(c + s * (p - b.center()));
    return apply_rotation<2>(std::make_shared<PolygonShape>(std::move(pts)), spec, c);
  }
  if (spec.type == "mesh") {
    throw InputError(key_path + ".type: \"mesh\" is 3D only (in 2D: polygon or bunny)");
  }
  return nullptr;
}

}  // namespace monolith
