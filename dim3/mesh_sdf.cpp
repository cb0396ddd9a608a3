/// \file mesh_sdf.cpp
/// Exact signed distance to a closed triangle mesh, and its lattice cache.

#include "dim3/mesh_sdf.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <utility>

namespace monolith {

namespace {

/// Closest point on triangle (a, b, c) to p, by the Voronoi regions of its vertices, edges and
/// face. `feature` is 0, 1, 2 for the vertices a, b, c; 3, 4, 5 for the edges ab, bc, ca; 6 for
/// the interior.
Vec<3> closest_on_triangle(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c,
                           int* feature) {
  const Vec<3> ab = b - a, ac = c - a, ap = p - a;
  // vertex a
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) { *feature = 0; return a; }
  // vertex b
  const Vec<3> bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) { *feature = 1; return b; }
  // edge ab
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
    *feature = 3;
    return a + (d1 / (d1 - d3)) * ab;
  }
  // vertex c
  const Vec<3> cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) { *feature = 2; return c; }
  // edge ca
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
    *feature = 5;
    return a + (d2 / (d2 - d6)) * ac;
  }
  // edge bc
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0) {
    *feature = 4;
    return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  }
  // interior: barycentric coordinates from the three sub-areas
  const double denom = 1.0 / (va + vb + vc);
  *feature = 6;
  return a + ab * (vb * denom) + ac * (vc * denom);
}

/// Angle at corner `a` of a triangle (a, b, c).
double corner_angle(const Vec<3>& a, const Vec<3>& b, const Vec<3>& c) {
  const Vec<3> u = b - a, v = c - a;
  return std::atan2(u.cross(v).norm(), u.dot(v));
}

}  // namespace

MeshSdf::MeshSdf(TriangleMesh mesh, int cache_cells) : mesh_(std::move(mesh)) {
  // orientation: a closed mesh with outward triangles encloses a positive volume
  if (mesh_.signed_volume() < 0.0) {
    mesh_.flip();
    flipped_ = true;
  }
  bounds_ = mesh_.bounds();
  // hierarchy over all triangles
  order_.resize(mesh_.triangles.size());
  for (std::size_t i = 0; i < order_.size(); ++i) order_[i] = static_cast<int>(i);
  nodes_.reserve(2 * order_.size());
  build(0, static_cast<int>(order_.size()));
  build_pseudo_normals();
  if (cache_cells > 0) build_cache(cache_cells);
}

int MeshSdf::build(int begin, int end) {
  // node box and the bounds of the triangle centroids
  const int id = static_cast<int>(nodes_.size());
  nodes_.emplace_back();
  Box<3> box, centroids;
  for (int i = begin; i < end; ++i) {
    const auto& t = mesh_.triangles[order_[i]];
    Vec<3> c = Vec<3>::Zero();
    for (int k = 0; k < 3; ++k) {
      box.extend(mesh_.vertices[t[k]]);
      c += mesh_.vertices[t[k]];
    }
    centroids.extend(Vec<3>(c / 3.0));
  }
  nodes_[id].box = box;
  nodes_[id].begin = begin;
  nodes_[id].end = end;
  if (end - begin <= 4) return id;
  // split at the median centroid along the longest axis
  int axis = 0;
  centroids.sizes().maxCoeff(&axis);
  const int mid = (begin + end) / 2;
  auto centroid = [&](int tri) {
    const auto& t = mesh_.triangles[tri];
    return mesh_.vertices[t[0]][axis] + mesh_.vertices[t[1]][axis] + mesh_.vertices[t[2]][axis];
  };
  std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end,
                   [&](int l, int r) { return centroid(l) < centroid(r); });
  const int left = build(begin, mid);
  const int right = build(mid, end);
  nodes_[id].left = left;
  nodes_[id].right = right;
  return id;
}

void MeshSdf::build_pseudo_normals() {
  const auto& v = mesh_.vertices;
  const std::size_t nt = mesh_.triangles.size();
  face_normal_.assign(nt, Vec<3>::Zero());
  vertex_normal_.assign(v.size(), Vec<3>::Zero());
  edge_normal_.assign(nt, {Vec<3>::Zero(), Vec<3>::Zero(), Vec<3>::Zero()});
  // face normals; vertex normals weighted by the incident angles
  std::map<std::pair<int, int>, Vec<3>> edge_sum;
  for (std::size_t f = 0; f < nt; ++f) {
    const auto& t = mesh_.triangles[f];
    const Vec<3> n = (v[t[1]] - v[t[0]]).cross(v[t[2]] - v[t[0]]);
    const double len = n.norm();
    face_normal_[f] = len > 0.0 ? Vec<3>(n / len) : Vec<3>(Vec<3>::Zero());
    for (int k = 0; k < 3; ++k) {
      vertex_normal_[t[k]] +=
          corner_angle(v[t[k]], v[t[(k + 1) % 3]], v[t[(k + 2) % 3]]) * face_normal_[f];
      // (Eigen vectors are not zero-initialised: insert an explicit zero first)
      const std::pair<int, int> key = std::minmax(t[k], t[(k + 1) % 3]);
      edge_sum.try_emplace(key, Vec<3>::Zero()).first->second += face_normal_[f];
    }
  }
  // edge normals: the sum of the normals of the faces sharing the edge
  for (std::size_t f = 0; f < nt; ++f) {
    const auto& t = mesh_.triangles[f];
    for (int k = 0; k < 3; ++k) {
      edge_normal_[f][k] = edge_sum.at(std::minmax(t[k], t[(k + 1) % 3]));
    }
  }
}

MeshQuery MeshSdf::exact(const Vec<3>& x) const {
  // nearest triangle: depth-first through the hierarchy, nearer child first, pruned by boxes
  double best2 = std::numeric_limits<double>::infinity();
  int best_tri = -1, best_feature = 6;
  Vec<3> best_point = Vec<3>::Zero();
  int stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& node = nodes_[stack[--top]];
    if (node.box.squaredExteriorDistance(x) >= best2) continue;
    if (node.left < 0) {
      for (int i = node.begin; i < node.end; ++i) {
        const auto& t = mesh_.triangles[order_[i]];
        int feature = 6;
        const Vec<3> q = closest_on_triangle(x, mesh_.vertices[t[0]], mesh_.vertices[t[1]],
                                             mesh_.vertices[t[2]], &feature);
        const double d2 = (x - q).squaredNorm();
        if (d2 < best2) {
          best2 = d2;
          best_tri = order_[i];
          best_feature = feature;
          best_point = q;
        }
      }
      continue;
    }
    const double dl = nodes_[node.left].box.squaredExteriorDistance(x);
    const double dr = nodes_[node.right].box.squaredExteriorDistance(x);
    if (dl <= dr) {
      stack[top++] = node.right;
      stack[top++] = node.left;
    } else {
      stack[top++] = node.left;
      stack[top++] = node.right;
    }
  }
  // a mesh of degenerate triangles only has no surface to measure against
  if (best_tri < 0) {
    MeshQuery none;
    none.distance = std::numeric_limits<double>::infinity();
    none.closest = x;
    none.normal = Vec<3>::UnitY();
    return none;
  }
  // sign: the angle-weighted pseudo-normal of the nearest feature
  const auto& t = mesh_.triangles[best_tri];
  Vec<3> pseudo;
  if (best_feature < 3) pseudo = vertex_normal_[t[best_feature]];
  else if (best_feature < 6) pseudo = edge_normal_[best_tri][best_feature - 3];
  else pseudo = face_normal_[best_tri];
  const Vec<3> diff = x - best_point;
  const double d = std::sqrt(best2);
  const bool inside = diff.dot(pseudo) < 0.0;
  MeshQuery q;
  q.distance = inside ? -d : d;
  q.closest = best_point;
  if (d > 1e-12 * (1.0 + bounds_.sizes().norm())) {
    q.normal = inside ? Vec<3>(-diff / d) : Vec<3>(diff / d);
  } else {
    const double n = pseudo.norm();
    q.normal = n > 0.0 ? Vec<3>(pseudo / n) : Vec<3>(Vec<3>::UnitY());
  }
  return q;
}

double MeshSdf::winding_number(const Vec<3>& x) const {
  // signed solid angle of each triangle seen from x (van Oosterom & Strackee 1983)
  double omega = 0.0;
  for (const auto& t : mesh_.triangles) {
    const Vec<3> a = mesh_.vertices[t[0]] - x;
    const Vec<3> b = mesh_.vertices[t[1]] - x;
    const Vec<3> c = mesh_.vertices[t[2]] - x;
    const double la = a.norm(), lb = b.norm(), lc = c.norm();
    const double num = a.dot(b.cross(c));
    const double den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    omega += 2.0 * std::atan2(num, den);
  }
  return omega / (4.0 * EIGEN_PI);
}

void MeshSdf::build_cache(int cells) {
  // lattice: spacing = longest extent / cells, padded by 3 cells on every side
  const int pad = 3;
  h_ = bounds_.sizes().maxCoeff() / cells;
  band_ = 4.0 * h_;
  origin_ = bounds_.min().array() - pad * h_;
  for (int a = 0; a < 3; ++a) {
    dims_[a] = static_cast<int>(std::ceil(bounds_.sizes()[a] / h_)) + 2 * pad + 1;
  }
  const long n = static_cast<long>(dims_[0]) * dims_[1] * dims_[2];
  values_.assign(n, 0.0);
  // sample the exact SDF at every lattice node
#pragma omp parallel for schedule(dynamic, 256)
  for (long i = 0; i < n; ++i) {
    const int ix = static_cast<int>(i % dims_[0]);
    const int iy = static_cast<int>((i / dims_[0]) % dims_[1]);
    const int iz = static_cast<int>(i / (static_cast<long>(dims_[0]) * dims_[1]));
    values_[i] = exact_distance(origin_ + h_ * Vec<3>(ix, iy, iz));
  }
}

double MeshSdf::distance(const Vec<3>& x) const {
  if (values_.empty()) return exact_distance(x);
  // lattice coordinates; outside the lattice use the exact query
  const Vec<3> s = (x - origin_) / h_;
  int i[3];
  double f[3];
  for (int a = 0; a < 3; ++a) {
    if (!(s[a] >= 0.0) || s[a] > dims_[a] - 1) return exact_distance(x);
    i[a] = std::min(static_cast<int>(s[a]), dims_[a] - 2);
    f[a] = s[a] - i[a];
  }
  // trilinear interpolation of the 8 surrounding nodes
  const long sx = 1, sy = dims_[0], sz = static_cast<long>(dims_[0]) * dims_[1];
  const long base = i[0] + sy * i[1] + sz * i[2];
  auto at = [&](int dx, int dy, int dz) { return values_[base + dx * sx + dy * sy + dz * sz]; };
  const double c00 = at(0, 0, 0) * (1 - f[0]) + at(1, 0, 0) * f[0];
  const double c10 = at(0, 1, 0) * (1 - f[0]) + at(1, 1, 0) * f[0];
  const double c01 = at(0, 0, 1) * (1 - f[0]) + at(1, 0, 1) * f[0];
  const double c11 = at(0, 1, 1) * (1 - f[0]) + at(1, 1, 1) * f[0];
  const double c0 = c00 * (1 - f[1]) + c10 * f[1];
  const double c1 = c01 * (1 - f[1]) + c11 * f[1];
  const double d = c0 * (1 - f[2]) + c1 * f[2];
  // far from the surface: the exact value
  return std::abs(d) < band_ ? d : exact_distance(x);
}

}  // namespace monolith
