/// \file make_bunny_silhouette.cpp
/// Generates dim2/assets/bunny_silhouette.txt, the 2D bunny: the side view (projection onto the
/// x-y plane, y up) of dim3/assets/bunny.obj, as one simple polygon in the mesh's units.
///
/// Steps: rasterise the projected triangles on a fine pixel grid; extract the outer contour of
/// the covered set by marching squares; simplify it by Douglas-Peucker with the largest
/// tolerance that keeps the vertex count near the target; write "x y" lines.
///
/// Build and run from the repository root (not part of the CMake build; see docs/geometry.md):
///   g++ -O2 -std=c++17 -I. -I/usr/include/eigen3 dim2/tools/make_bunny_silhouette.cpp dim3/mesh.cpp -o /tmp/make_bunny_silhouette
///   /tmp/make_bunny_silhouette dim3/assets/bunny.obj dim2/assets/bunny_silhouette.txt

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <map>
#include <vector>

#include "dim3/mesh.hpp"

using monolith::Vec;

namespace {

constexpr int kPixels = 2048;      // raster resolution along the longest side
constexpr int kTargetVertices = 300;

double cross(const Vec<2>& a, const Vec<2>& b) { return a[0] * b[1] - a[1] * b[0]; }

double signed_area(const std::vector<Vec<2>>& loop) {
  double a = 0.0;
  for (std::size_t i = 0; i < loop.size(); ++i) a += cross(loop[i], loop[(i + 1) % loop.size()]);
  return 0.5 * a;
}

/// Distance from p to the segment a-b.
double segment_distance(const Vec<2>& p, const Vec<2>& a, const Vec<2>& b) {
  const Vec<2> e = b - a;
  const double l2 = e.squaredNorm();
  const double t = l2 > 0.0 ? std::clamp((p - a).dot(e) / l2, 0.0, 1.0) : 0.0;
  return (p - a - t * e).norm();
}

/// Douglas-Peucker on the open chain pts[first..last], marking kept vertices.
void simplify(const std::vector<Vec<2>>& pts, int first, int last, double tol,
              std::vector<char>& keep) {
  double worst = -1.0;
  int index = -1;
  for (int i = first + 1; i < last; ++i) {
    const double d = segment_distance(pts[i], pts[first], pts[last]);
    if (d > worst) { worst = d; index = i; }
  }
  if (index < 0 || worst <= tol) return;
  keep[index] = 1;
  simplify(pts, first, index, tol, keep);
  simplify(pts, index, last, tol, keep);
}

/// Simplifies a closed loop: split at vertex 0 and at the vertex farthest from it.
std::vector<Vec<2>> simplify_loop(const std::vector<Vec<2>>& loop, double tol) {
  const int n = static_cast<int>(loop.size());
  int far = 0;
  for (int i = 0; i < n; ++i) {
    if ((loop[i] - loop[0]).norm() > (loop[far] - loop[0]).norm()) far = i;
  }
  std::vector<Vec<2>> pts(loop);
  pts.push_back(loop[0]);
  std::vector<char> keep(pts.size(), 0);
  keep[0] = keep[far] = keep[n] = 1;
  simplify(pts, 0, far, tol, keep);
  simplify(pts, far, n, tol, keep);
  std::vector<Vec<2>> out;
  for (int i = 0; i < n; ++i) {
    if (keep[i]) out.push_back(pts[i]);
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::cerr << "usage: make_bunny_silhouette BUNNY.obj OUT.txt\n";
    return 2;
  }
  const monolith::TriangleMesh mesh = monolith::load_obj(argv[1], "bunny");
  const monolith::Box<3> box = mesh.bounds();

  // pixel grid: 4 pixels of padding around the projected bounding box
  const double extent = std::max(box.sizes()[0], box.sizes()[1]);
  const double px = extent / kPixels;
  const Vec<2> origin(box.min()[0] - 4 * px, box.min()[1] - 4 * px);
  const int w = static_cast<int>(std::ceil(box.sizes()[0] / px)) + 9;
  const int h = static_cast<int>(std::ceil(box.sizes()[1] / px)) + 9;
  std::vector<char> covered(static_cast<std::size_t>(w) * h, 0);
  auto centre = [&](int i, int j) { return Vec<2>(origin[0] + i * px, origin[1] + j * px); };

  // rasterise: a pixel centre is covered if it lies in any projected triangle
  for (const auto& t : mesh.triangles) {
    const Vec<2> a = mesh.vertices[t[0]].head<2>(), b = mesh.vertices[t[1]].head<2>(),
                 c = mesh.vertices[t[2]].head<2>();
    const double area = cross(b - a, c - a);
    if (area == 0.0) continue;
    const int i0 = std::max(0, static_cast<int>(std::floor((std::min({a[0], b[0], c[0]}) - origin[0]) / px)));
    const int i1 = std::min(w - 1, static_cast<int>(std::ceil((std::max({a[0], b[0], c[0]}) - origin[0]) / px)));
    const int j0 = std::max(0, static_cast<int>(std::floor((std::min({a[1], b[1], c[1]}) - origin[1]) / px)));
    const int j1 = std::min(h - 1, static_cast<int>(std::ceil((std::max({a[1], b[1], c[1]}) - origin[1]) / px)));
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) {
        const Vec<2> p = centre(i, j);
        const double s0 = cross(b - a, p - a) / area, s1 = cross(c - b, p - b) / area,
                     s2 = cross(a - c, p - c) / area;
        if (s0 >= 0.0 && s1 >= 0.0 && s2 >= 0.0) covered[static_cast<std::size_t>(j) * w + i] = 1;
      }
    }
  }

  // marching squares: contour segments between edge midpoints of the pixel-centre lattice;
  // edge ids: 2 (j w + i) for the edge (i, j)-(i+1, j), 2 (j w + i) + 1 for (i, j)-(i, j+1)
  auto at = [&](int i, int j) { return covered[static_cast<std::size_t>(j) * w + i] != 0; };
  auto edge_point = [&](long id) {
    const long cell = id / 2;
    const int i = static_cast<int>(cell % w), j = static_cast<int>(cell / w);
    return id % 2 == 0 ? Vec<2>(centre(i, j) + Vec<2>(0.5 * px, 0.0))
                       : Vec<2>(centre(i, j) + Vec<2>(0.0, 0.5 * px));
  };
  std::map<long, std::vector<long>> links;
  auto link = [&](long a, long b) {
    links[a].push_back(b);
    links[b].push_back(a);
  };
  for (int j = 0; j + 1 < h; ++j) {
    for (int i = 0; i + 1 < w; ++i) {
      const bool c00 = at(i, j), c10 = at(i + 1, j), c01 = at(i, j + 1), c11 = at(i + 1, j + 1);
      const long bottom = 2L * (static_cast<long>(j) * w + i);
      const long top = 2L * (static_cast<long>(j + 1) * w + i);
      const long left = 2L * (static_cast<long>(j) * w + i) + 1;
      const long right = 2L * (static_cast<long>(j) * w + i + 1) + 1;
      // edges whose two ends differ carry a contour point
      std::vector<long> cut;
      if (c00 != c10) cut.push_back(bottom);
      if (c10 != c11) cut.push_back(right);
      if (c11 != c01) cut.push_back(top);
      if (c01 != c00) cut.push_back(left);
      if (cut.size() == 2) {
        link(cut[0], cut[1]);
      } else if (cut.size() == 4) {
        // saddle: keep the covered diagonal connected
        if (c00) { link(bottom, right); link(top, left); }
        else { link(bottom, left); link(right, top); }
      }
    }
  }

  // walk the loops; keep the one enclosing the largest area
  std::map<long, bool> visited;
  std::vector<Vec<2>> best;
  for (const auto& [start, unused] : links) {
    if (visited[start]) continue;
    std::vector<Vec<2>> loop;
    long prev = -1, cur = start;
    while (!visited[cur]) {
      visited[cur] = true;
      loop.push_back(edge_point(cur));
      const auto& nb = links[cur];
      const long next = nb[0] != prev ? nb[0] : nb[1];
      prev = cur;
      cur = next;
    }
    if (std::abs(signed_area(loop)) > std::abs(signed_area(best))) best = loop;
  }
  if (signed_area(best) < 0.0) std::reverse(best.begin(), best.end());

  // simplify: the largest tolerance (bisection) giving at least the target count
  double lo = 0.0, hi = 50.0 * px;
  for (int it = 0; it < 50; ++it) {
    const double mid = 0.5 * (lo + hi);
    if (static_cast<int>(simplify_loop(best, mid).size()) >= kTargetVertices) lo = mid;
    else hi = mid;
  }
  const std::vector<Vec<2>> out = simplify_loop(best, lo);

  // write
  std::ofstream file(argv[2]);
  file << "# Bunny silhouette: side view (x right, y up) of dim3/assets/bunny.obj, in its units.\n"
       << "# Generated by dim2/tools/make_bunny_silhouette.cpp: " << kPixels
       << " px raster, marching squares, Douglas-Peucker tolerance " << lo << ".\n"
       << "# " << out.size() << " vertices, counter-clockwise; contour area " << signed_area(best)
       << ", polygon area " << signed_area(out) << ".\n";
  char buf[64];
  for (const auto& p : out) {
    std::snprintf(buf, sizeof buf, "%.6f %.6f\n", p[0], p[1]);
    file << buf;
  }
  std::cout << "contour " << best.size() << " points, polygon " << out.size()
            << " vertices, tolerance " << lo << ", areas " << signed_area(best) << " "
            << signed_area(out) << "\n";
  return 0;
}
