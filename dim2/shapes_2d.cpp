/// \file shapes_2d.cpp
/// 2D-only shapes (polygon, bunny silhouette) and make_dimension_shape<2>.

#include "dim2/shapes_2d.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "reference/core/errors.hpp"
#include "reference/geometry/embedded_assets.hpp"
#include "reference/geometry/shape_tools.hpp"

namespace monolith {

namespace {

/// z-component of the cross product of 2D vectors.
double cross(const Vec<2>& a, const Vec<2>& b) { return a[0] * b[1] - a[1] * b[0]; }

}  // namespace

PolygonShape::PolygonShape(std::vector<Vec<2>> points) : points_(std::move(points)) {
  for (const auto& p : points_) bounds_.extend(p);
  // acceleration for many vertices: edge hierarchy and sign lattice
  if (points_.size() > 32) {
    order_.resize(points_.size());
    for (std::size_t i = 0; i < order_.size(); ++i) order_[i] = static_cast<int>(i);
    nodes_.reserve(2 * order_.size());
    build(0, static_cast<int>(order_.size()));
    build_sign_lattice();
  }
}

int PolygonShape::build(int begin, int end) {
  // node box over edges [begin, end) of order_
  const int id = static_cast<int>(nodes_.size());
  nodes_.emplace_back();
  const std::size_t n = points_.size();
  Box<2> box, mids;
  for (int i = begin; i < end; ++i) {
    const Vec<2>& a = points_[order_[i]];
    const Vec<2>& b = points_[(order_[i] + 1) % n];
    box.extend(a);
    box.extend(b);
    mids.extend(Vec<2>(0.5 * (a + b)));
  }
  nodes_[id].box = box;
  nodes_[id].begin = begin;
  nodes_[id].end = end;
  if (end - begin <= 4) return id;
  // median split of the edge midpoints along the longer axis
  int axis = 0;
  mids.sizes().maxCoeff(&axis);
  const int mid = (begin + end) / 2;
  std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end,
                   [&](int l, int r) {
                     return points_[l][axis] + points_[(l + 1) % n][axis] <
                            points_[r][axis] + points_[(r + 1) % n][axis];
                   });
  const int left = build(begin, mid);
  const int right = build(mid, end);
  nodes_[id].left = left;
  nodes_[id].right = right;
  return id;
}

void PolygonShape::build_sign_lattice() {
  // exact signed distances at the nodes of a lattice over the bounds, padded by 2 cells
  h_ = bounds_.sizes().maxCoeff() / 128.0;
  origin_ = bounds_.min().array() - 2.0 * h_;
  nx_ = static_cast<int>(std::ceil(bounds_.sizes()[0] / h_)) + 5;
  ny_ = static_cast<int>(std::ceil(bounds_.sizes()[1] / h_)) + 5;
  lattice_.resize(static_cast<std::size_t>(nx_) * ny_);
  const std::size_t n = points_.size();
  // Winding numbers row by row: each edge crossing the row's line adds +-1 to the run of nodes
  // left of the crossing (O(n + nx) per row instead of O(n) per node), and distances through the
  // edge hierarchy (the same minimum as nearest_all, which tests every edge). The lattice is the
  // same as evaluating winding_number and nearest_all at every node, at a fraction of the cost:
  // a 2D bunny body used to spend ~30 ms here, and scenes with ten bunnies build ten lattices.
  std::vector<int> delta(static_cast<std::size_t>(nx_) + 1);
  for (int j = 0; j < ny_; ++j) {
    std::fill(delta.begin(), delta.end(), 0);
    const double y = (origin_ + h_ * Vec<2>(0, j))[1];
    for (std::size_t e = 0; e < n; ++e) {
      const Vec<2>& a = points_[e];
      const Vec<2>& b = points_[(e + 1) % n];
      // Sunday's rule (winding_number): an upward edge counts +1 for the nodes on its left, a
      // downward edge -1 for the nodes on its right; on this row both are the nodes with x left
      // of the crossing
      int sign = 0;
      if (a[1] <= y) {
        if (b[1] > y) sign = 1;
      } else if (b[1] <= y) {
        sign = -1;
      }
      if (sign == 0) continue;
      const double xc = a[0] + (b[0] - a[0]) * ((y - a[1]) / (b[1] - a[1]));
      const double sc = std::clamp((xc - origin_[0]) / h_, -4.0, static_cast<double>(nx_) + 4.0);
      // nodes [0, lo) lie left of the crossing, [hi, nx_) right of it; [lo, hi) are tested with
      // winding_number's own expression, so the result is the same as calling it at every node
      const int lo = std::clamp(static_cast<int>(std::floor(sc)) - 2, 0, nx_);
      const int hi = std::clamp(static_cast<int>(std::floor(sc)) + 3, 0, nx_);
      delta[0] += sign;
      delta[static_cast<std::size_t>(lo)] -= sign;
      for (int i = lo; i < hi; ++i) {
        const double side = cross(b - a, Vec<2>(origin_ + h_ * Vec<2>(i, j)) - a);
        if (sign > 0 ? side > 0.0 : side < 0.0) {
          delta[static_cast<std::size_t>(i)] += sign;
          delta[static_cast<std::size_t>(i) + 1] -= sign;
        }
      }
    }
    int w = 0;
    for (int i = 0; i < nx_; ++i) {
      w += delta[static_cast<std::size_t>(i)];
      const Vec<2> x = origin_ + h_ * Vec<2>(i, j);
      const double d = nearest(x, nullptr);
      lattice_[static_cast<std::size_t>(j) * nx_ + i] = w != 0 ? -d : d;
    }
  }
}

bool PolygonShape::inside(const Vec<2>& x) const {
  // outside the bounds: outside
  if (bounds_.exteriorDistance(x) > 0.0) return false;
  if (!lattice_.empty()) {
    // bilinear value; decisive when farther from zero than its error bound sqrt(2)/2 h
    const Vec<2> s = (x - origin_) / h_;
    const int i = std::clamp(static_cast<int>(s[0]), 0, nx_ - 2);
    const int j = std::clamp(static_cast<int>(s[1]), 0, ny_ - 2);
    const double fx = s[0] - i, fy = s[1] - j;
    const double* r0 = &lattice_[static_cast<std::size_t>(j) * nx_ + i];
    const double* r1 = r0 + nx_;
    const double v = (r0[0] * (1 - fx) + r0[1] * fx) * (1 - fy) + (r1[0] * (1 - fx) + r1[1] * fx) * fy;
    if (std::abs(v) > 0.75 * h_) return v < 0.0;
  }
  return winding_number(x) != 0;
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
  if (nodes_.empty()) return nearest_all(x, point);
  // depth-first through the edge hierarchy, nearer child first, pruned by box distance
  const std::size_t n = points_.size();
  double best = std::numeric_limits<double>::infinity();
  int stack[96];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& node = nodes_[stack[--top]];
    if (node.box.squaredExteriorDistance(x) >= best) continue;
    if (node.left < 0) {
      for (int k = node.begin; k < node.end; ++k) {
        const Vec<2>& a = points_[order_[k]];
        const Vec<2> e = points_[(order_[k] + 1) % n] - a;
        const double len2 = e.squaredNorm();
        const double t = len2 > 0.0 ? std::clamp((x - a).dot(e) / len2, 0.0, 1.0) : 0.0;
        const Vec<2> q = a + t * e;
        const double d2 = (x - q).squaredNorm();
        if (d2 < best) {
          best = d2;
          if (point) *point = q;
        }
      }
      continue;
    }
    const double dl = nodes_[node.left].box.squaredExteriorDistance(x);
    const double dr = nodes_[node.right].box.squaredExteriorDistance(x);
    stack[top++] = dl <= dr ? node.right : node.left;
    stack[top++] = dl <= dr ? node.left : node.right;
  }
  return std::sqrt(best);
}

double PolygonShape::nearest_all(const Vec<2>& x, Vec<2>* point) const {
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
  return inside(x) ? -d : d;
}

Vec<2> PolygonShape::gradient(const Vec<2>& x) const {
  // direction from the nearest boundary point, pointing outwards
  Vec<2> q;
  const double d = nearest(x, &q);
  if (d < 1e-12 * (1.0 + bounds_.sizes().norm())) return Shape<2>::gradient(x);
  const Vec<2> g = (x - q) / d;
  return inside(x) ? Vec<2>(-g) : g;
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
  if (spec.type == ShapeType::polygon) {
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
  if (spec.type == ShapeType::bunny) {
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
  if (spec.type == ShapeType::mesh) {
    throw InputError(key_path + ".type: \"mesh\" is 3D only (in 2D: polygon or bunny)");
  }
  return nullptr;
}

}  // namespace monolith
