/// \file test_shapes.cpp
/// Tests of the signed distance functions of reference/geometry/shape.cpp and dim2/shapes_2d.cpp:
/// exact values, unit gradients, rotations, combinators, the bowl, polygons, volume_inside.

#include <catch2/catch.hpp>
#include <cmath>
#include <limits>
#include <random>

#include "dim2/shapes_2d.hpp"
#include "reference/core/errors.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/geometry/shape_tools.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using monolith::testing::as_std;
using monolith::testing::box_spec;
using monolith::testing::round_spec;

namespace {

template <int Dim>
std::vector<double> rep(double value) {
  return std::vector<double>(Dim, value);
}

/// A rotation value of the given angle: 2D the angle, 3D about the axis (1, 2, 3)/|.|.
template <int Dim>
std::vector<double> rotation_value(double angle) {
  if constexpr (Dim == 2) {
    return {angle};
  } else {
    const Vec<3> axis = Vec<3>(1, 2, 3).normalized() * angle;
    return {axis[0], axis[1], axis[2]};
  }
}

template <int Dim>
Vec<Dim> random_point(std::mt19937& rng, double lo, double hi) {
  std::uniform_real_distribution<double> u(lo, hi);
  Vec<Dim> x;
  for (int a = 0; a < Dim; ++a) x[a] = u(rng);
  return x;
}

}  // namespace

TEMPLATE_TEST_CASE_SIG("box: exact distances inside, outside, on faces, edges and corners",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  const Vec<Dim> c = Vec<Dim>::Constant(0.5);
  Vec<Dim> h = Vec<Dim>::Constant(0.2);
  h[0] = 0.3;
  const auto box = make_shape<Dim>(box_spec<Dim>(c, h), "liquids[0].shape");
  // centre: minus the smallest half size
  CHECK(box->distance(c) == Approx(-0.2).margin(1e-15));
  // on a face, beyond a face, inside near a face
  Vec<Dim> x = c;
  x[0] += 0.3;
  CHECK(box->distance(x) == Approx(0.0).margin(1e-15));
  x[0] += 0.1;
  CHECK(box->distance(x) == Approx(0.1).margin(1e-15));
  x = c;
  x[1] -= 0.15;
  CHECK(box->distance(x) == Approx(-0.05).margin(1e-15));
  // beyond a corner: Euclidean distance to the corner
  const Vec<Dim> corner = c + h;
  const Vec<Dim> off = Vec<Dim>::Constant(0.1);
  CHECK(box->distance(corner + off) == Approx(off.norm()).epsilon(1e-14));
  // beyond an edge (3D) / a corner in one axis pair: distance in the two axes only
  x = c;
  x[0] += 0.3 + 0.03;
  x[1] += 0.2 + 0.04;
  CHECK(box->distance(x) == Approx(0.05).epsilon(1e-13));
  // bounds
  CHECK((box->bounds().min() - (c - h)).norm() < 1e-15);
  CHECK((box->bounds().max() - (c + h)).norm() < 1e-15);
}

TEMPLATE_TEST_CASE_SIG("sphere, shell and halfspace: exact distances", "[unit]",
                       ((int Dim), Dim), 2, 3) {
  const Vec<Dim> c = Vec<Dim>::Constant(1.0);
  const Vec<Dim> e = Vec<Dim>::Unit(Dim - 1);
  const auto sphere = make_shape<Dim>(round_spec<Dim>(ShapeType::sphere, c, 0.5), "s");
  CHECK(sphere->distance(c) == Approx(-0.5));
  CHECK(sphere->distance(c + 0.5 * e) == Approx(0.0).margin(1e-15));
  CHECK(sphere->distance(c + 2.0 * e) == Approx(1.5));
  // shell of outer radius 0.5 and inner radius 0.4
  const auto shell = make_shape<Dim>(round_spec<Dim>(ShapeType::shell, c, 0.5, 0.1), "s");
  CHECK(shell->distance(c) == Approx(0.4));
  CHECK(shell->distance(c + 0.45 * e) == Approx(-0.05));
  CHECK(shell->distance(c + 0.42 * e) == Approx(-0.02));
  CHECK(shell->distance(c + 0.8 * e) == Approx(0.3));
  CHECK(shell->distance(c + 0.3 * e) == Approx(0.1));
  // halfspace with an unnormalised normal: inside n.x <= offset
  ShapeSpec hs;
  hs.type = ShapeType::halfspace;
  hs.normal = rep<Dim>(0.0);
  hs.normal[1] = 2.0;
  hs.offset = 1.0;  // y <= 0.5
  const auto half = make_shape<Dim>(hs, "s");
  Vec<Dim> x = Vec<Dim>::Constant(7.0);
  x[1] = 0.2;
  CHECK(half->distance(x) == Approx(-0.3));
  x[1] = 0.9;
  CHECK(half->distance(x) == Approx(0.4));
  // bounded above along y only
  CHECK(half->bounds().max()[1] == Approx(0.5));
  CHECK(std::isinf(half->bounds().min()[1]));
  CHECK(std::isinf(half->bounds().max()[0]));
}

TEMPLATE_TEST_CASE_SIG("bowl: cavity outside, wall inside, rim rounded off", "[unit]",
                       ((int Dim), Dim), 2, 3) {
  const Vec<Dim> c = Vec<Dim>::Constant(0.5);
  const Vec<Dim> up = Vec<Dim>::Unit(1);
  const Vec<Dim> side = Vec<Dim>::Unit(0);
  const auto bowl = make_shape<Dim>(round_spec<Dim>(ShapeType::bowl, c, 0.3, 0.05), "bodies[0].shape");
  // cavity: centre and a point below the centre inside the inner radius
  CHECK(bowl->distance(c) > 0.0);
  CHECK(bowl->distance(c - 0.1 * up) == Approx(0.15));
  // the wall below the centre
  CHECK(bowl->distance(c - 0.27 * up) == Approx(-0.02));
  CHECK(bowl->distance(c - 0.275 * up) == Approx(-0.025));
  // wall just below the rim: the rim plane is the nearest boundary
  CHECK(bowl->distance(c + 0.275 * side - 0.01 * up) == Approx(-0.01));
  // above the rim: distance to the rim segment, rounded at its corners
  CHECK(bowl->distance(c + 0.275 * side + 0.04 * up) == Approx(0.04));
  CHECK(bowl->distance(c + 0.35 * side + 0.03 * up) == Approx(std::hypot(0.05, 0.03)));
  CHECK(bowl->distance(c + 0.2 * side + 0.04 * up) == Approx(std::hypot(0.05, 0.04)));
  // the centre is above the inner wall: nearest is the inner rim corner at distance r_in
  CHECK(bowl->distance(c) == Approx(0.25));
  // below and outside: radial distance to the outer sphere
  CHECK(bowl->distance(c - 0.5 * up) == Approx(0.2));
  // a point above the bowl is outside
  CHECK(bowl->distance(c + 0.2 * up) > 0.0);
  // bounds: the lower half box
  CHECK(bowl->bounds().max()[1] == Approx(0.5));
  CHECK(bowl->bounds().min()[1] == Approx(0.2));
  // volume: half of the shell
  const double inner = 0.25, outer = 0.3;
  const double shell = Dim == 2 ? EIGEN_PI * (outer * outer - inner * inner)
                                : 4.0 / 3.0 * EIGEN_PI * (std::pow(outer, 3) - std::pow(inner, 3));
  const Box<Dim> region(c.array() - 0.32, c.array() + 0.32);
  const double v = volume_inside<Dim>(*bowl, region, Dim == 2 ? 800 : 160);
  CHECK(v == Approx(0.5 * shell).epsilon(0.01));
}

TEMPLATE_TEST_CASE_SIG("SDF gradients have unit length away from the medial axis",
                       "[property]", ((int Dim), Dim), 2, 3) {
  std::mt19937 rng(7);
  const Vec<Dim> c = Vec<Dim>::Constant(0.5);
  std::vector<ShapeSpec> specs;
  specs.push_back(box_spec<Dim>(c, Vec<Dim>::Constant(0.2)));
  specs.push_back(round_spec<Dim>(ShapeType::sphere, c, 0.3));
  specs.push_back(round_spec<Dim>(ShapeType::shell, c, 0.3, 0.1));
  specs.push_back(round_spec<Dim>(ShapeType::bowl, c, 0.3, 0.1));
  specs.back().rotation = rotation_value<Dim>(0.4);
  int checked = 0;
  for (const auto& spec : specs) {
    const auto shape = make_shape<Dim>(spec, "s");
    for (int k = 0; k < 200; ++k) {
      const Vec<Dim> x = random_point<Dim>(rng, -0.2, 1.2);
      // stay away from the medial axis: the default central difference is at step ~1e-6
      const Vec<Dim> g = shape->gradient(x);
      const double d = shape->distance(x);
      // finite-difference consistency along the gradient
      const double eps = 1e-4;
      const double slope = (shape->distance(x + eps * g) - shape->distance(x - eps * g)) / (2 * eps);
      if (std::abs(slope - 1.0) > 1e-3) continue;  // a kink of the SDF within eps
      CHECK(g.norm() == Approx(1.0).epsilon(1e-6));
      // the nearest surface point x - d g lies on the zero level
      CHECK(std::abs(shape->distance(x - d * g)) < 1e-6);
      ++checked;
    }
  }
  CHECK(checked > 600);
}

TEMPLATE_TEST_CASE_SIG("rotation: a rotated box at a rotated point equals the unrotated one",
                       "[property]", ((int Dim), Dim), 2, 3) {
  std::mt19937 rng(11);
  const Vec<Dim> c = Vec<Dim>::Constant(0.4);
  Vec<Dim> h = Vec<Dim>::Constant(0.1);
  h[0] = 0.25;
  ShapeSpec plain = box_spec<Dim>(c, h);
  ShapeSpec turned = plain;
  const double angle = 0.7;
  turned.rotation = rotation_value<Dim>(angle);
  const auto a = make_shape<Dim>(plain, "a");
  const auto b = make_shape<Dim>(turned, "b");
  const Mat<Dim> r = rotation_matrix<Dim>(turned.rotation);
  for (int k = 0; k < 500; ++k) {
    const Vec<Dim> x = random_point<Dim>(rng, -0.5, 1.5);
    const Vec<Dim> xr = c + r * (x - c);
    REQUIRE(b->distance(xr) == Approx(a->distance(x)).margin(1e-14));
    // gradients rotate with the shape
    CHECK((b->gradient(xr) - r * a->gradient(x)).norm() < 1e-5);
  }
  // the rotation changes the shape (a 90-degree turn swaps the long axis)
  ShapeSpec quarter = plain;
  quarter.rotation = rotation_value<Dim>(0.5 * EIGEN_PI);
  Vec<Dim> probe = c;
  probe[0] += 0.2;
  CHECK(a->distance(probe) < 0.0);
  CHECK(make_shape<Dim>(quarter, "q")->distance(probe) > 0.0);
  // bounds contain the rotated corners
  const Box<Dim> bb = b->bounds();
  for (int corner = 0; corner < (1 << Dim); ++corner) {
    Vec<Dim> p;
    for (int d = 0; d < Dim; ++d) p[d] = (corner >> d) & 1 ? h[d] : -h[d];
    CHECK(bb.exteriorDistance(Vec<Dim>(c + r * p)) < 1e-12);
  }
}

TEMPLATE_TEST_CASE_SIG("union and difference: signs", "[unit]", ((int Dim), Dim), 2, 3) {
  const Vec<Dim> e = Vec<Dim>::Unit(0);
  const Vec<Dim> c0 = Vec<Dim>::Constant(0.5);
  ShapeSpec u;
  u.type = ShapeType::set_union;
  u.shapes = {round_spec<Dim>(ShapeType::sphere, c0 - 0.2 * e, 0.25), round_spec<Dim>(ShapeType::sphere, c0 + 0.2 * e, 0.25)};
  ShapeSpec d = u;
  d.type = ShapeType::set_difference;
  const auto un = make_shape<Dim>(u, "u");
  const auto di = make_shape<Dim>(d, "d");
  // in both, in only the first, in only the second, in neither
  CHECK(un->distance(c0) < 0.0);
  CHECK(di->distance(c0) > 0.0);
  CHECK(un->distance(c0 - 0.35 * e) < 0.0);
  CHECK(di->distance(c0 - 0.35 * e) < 0.0);
  CHECK(un->distance(c0 + 0.35 * e) < 0.0);
  CHECK(di->distance(c0 + 0.35 * e) > 0.0);
  CHECK(un->distance(c0 + 0.6 * e) > 0.0);
  CHECK(di->distance(c0 + 0.6 * e) > 0.0);
  // exact outside a union: distance to the nearer sphere
  CHECK(un->distance(c0 + 0.7 * e) == Approx(0.25));
  // exact inside a difference near the cut: distance to the subtracted sphere
  CHECK(di->distance(c0 - 0.1 * e) == Approx(-0.05));
  // bounds: union covers both, difference the first
  CHECK(un->bounds().max()[0] == Approx(0.95));
  CHECK(di->bounds().max()[0] == Approx(0.55));
  // gradient of the difference at the cut points into the subtracted sphere
  const Vec<Dim> g = di->gradient(c0 - 0.1 * e);
  CHECK(g[0] == Approx(1.0).epsilon(1e-6));
}

TEMPLATE_TEST_CASE_SIG("volume_inside converges to the exact volume", "[convergence]",
                       ((int Dim), Dim), 2, 3) {
  const Vec<Dim> c = Vec<Dim>::Constant(0.5);
  const auto sphere = make_shape<Dim>(round_spec<Dim>(ShapeType::sphere, c, 0.3), "s");
  const double exact = Dim == 2 ? EIGEN_PI * 0.09 : 4.0 / 3.0 * EIGEN_PI * 0.027;
  const Box<Dim> region(Vec<Dim>::Zero(), Vec<Dim>::Ones());
  const double coarse = std::abs(volume_inside<Dim>(*sphere, region, 40) - exact);
  const double fine = std::abs(volume_inside<Dim>(*sphere, region, Dim == 2 ? 640 : 160));
  const double fine_err = std::abs(fine - exact);
  CHECK(fine_err / exact < 2e-3);
  CHECK(fine_err < coarse + 1e-15);
  // a box aligned with the samples is exact
  const auto box = make_shape<Dim>(box_spec<Dim>(c, Vec<Dim>::Constant(0.25)), "b");
  CHECK(volume_inside<Dim>(*box, region, 40) == Approx(std::pow(0.5, Dim)).epsilon(1e-12));
}

TEMPLATE_TEST_CASE_SIG("make_shape rejects bad specs with InputError naming the key",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  ShapeSpec s = round_spec<Dim>(ShapeType::sphere, Vec<Dim>::Zero(), -1.0);
  CHECK_THROWS_WITH(make_shape<Dim>(s, "bodies[2].shape"),
                    Catch::Contains("bodies[2].shape.radius"));
  ShapeSpec sh = round_spec<Dim>(ShapeType::shell, Vec<Dim>::Zero(), 0.1, 0.2);
  CHECK_THROWS_AS(make_shape<Dim>(sh, "x"), InputError);
  ShapeSpec b = box_spec<Dim>(Vec<Dim>::Zero(), Vec<Dim>::Ones());
  b.rotation = {1.0, 2.0};
  CHECK_THROWS_WITH(make_shape<Dim>(b, "liquids[0].shape"),
                    Catch::Contains("liquids[0].shape.rotation"));
  ShapeSpec wrong_dim;
  wrong_dim.type = Dim == 2 ? ShapeType::mesh : ShapeType::polygon;
  CHECK_THROWS_AS(make_shape<Dim>(wrong_dim, "x"), InputError);
}

TEST_CASE("polygon: exact distance, both orientations give the same sign", "[unit]") {
  // an L-shaped polygon, counter-clockwise
  ShapeSpec ccw;
  ccw.type = ShapeType::polygon;
  ccw.points = {{0, 0}, {2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}};
  ShapeSpec cw = ccw;
  std::reverse(cw.points.begin(), cw.points.end());
  const auto a = make_shape<2>(ccw, "p");
  const auto b = make_shape<2>(cw, "p");
  std::mt19937 rng(3);
  int inside = 0;
  for (int k = 0; k < 2000; ++k) {
    const Vec<2> x = random_point<2>(rng, -0.5, 2.5);
    REQUIRE(a->distance(x) == b->distance(x));
    inside += a->distance(x) < 0.0;
  }
  CHECK(inside > 0);
  // chosen points: inside the arm, the reflex corner region, outside near the notch
  CHECK(a->distance(Vec<2>(0.5, 0.5)) == Approx(-0.5));
  CHECK(a->distance(Vec<2>(1.5, 0.8)) == Approx(-0.2));
  CHECK(a->distance(Vec<2>(1.5, 1.5)) == Approx(0.5));
  CHECK(a->distance(Vec<2>(0.5, 2.5)) == Approx(0.5));
  CHECK(a->distance(Vec<2>(2.3, 1.4)) == Approx(0.5));
  CHECK(a->distance(Vec<2>(1.2, 1.6)) == Approx(0.2));
  CHECK(a->distance(Vec<2>(3.0, 1.0)) == Approx(1.0));
  CHECK(a->distance(Vec<2>(1.0, 1.0)) == Approx(0.0).margin(1e-15));
  // gradient at a point outside a corner
  const Vec<2> g = a->gradient(Vec<2>(3.0, 2.0));
  CHECK((g - Vec<2>(1.0, 1.0).normalized()).norm() < 1e-12);
  // area by midpoint rule vs exact 3
  CHECK(volume_inside<2>(*b, Box<2>(Vec<2>(0, 0), Vec<2>(2, 2)), 200) == Approx(3.0));
  // rotation about the vertex centroid (1, 1) by 180 degrees maps (0.5, 0.5) to (1.5, 1.5)
  ShapeSpec turned = ccw;
  turned.rotation = {EIGEN_PI};
  CHECK(make_shape<2>(turned, "p")->distance(Vec<2>(1.5, 1.5)) == Approx(-0.5));
  // degenerate input
  ShapeSpec line;
  line.type = ShapeType::polygon;
  line.points = {{0, 0}, {1, 1}, {2, 2}};
  CHECK_THROWS_AS(make_shape<2>(line, "p"), InputError);
  line.points = {{0, 0}, {1, 1}};
  CHECK_THROWS_WITH(make_shape<2>(line, "liquids[1].shape"),
                    Catch::Contains("liquids[1].shape.points"));
}

TEST_CASE("bunny in 2D: the embedded silhouette placed by center and size", "[unit]") {
  // the asset: a few hundred vertices, counter-clockwise, the mesh's side-view extent
  const auto& raw = bunny_silhouette_points();
  CHECK(raw.size() >= 200);
  CHECK(raw.size() <= 400);
  const PolygonShape outline(raw);
  CHECK(outline.signed_area() > 0.0);
  CHECK(outline.bounds().sizes()[0] == Approx(9.91).margin(0.05));
  CHECK(outline.bounds().sizes()[1] == Approx(9.65).margin(0.05));
  ShapeSpec s;
  s.type = ShapeType::bunny;
  s.center = {0.5, 0.4};
  s.size = 0.3;
  const auto bunny = make_shape<2>(s, "bodies[0].shape");
  const Box<2> b = bunny->bounds();
  CHECK(b.sizes().maxCoeff() == Approx(0.3).epsilon(1e-12));
  CHECK((b.center() - Vec<2>(0.5, 0.4)).norm() < 1e-12);
  // the body (lower middle) is inside, the space between the ears and the back outside
  CHECK(bunny->distance(Vec<2>(0.5, 0.4 - 0.05)) < 0.0);
  CHECK(bunny->distance(Vec<2>(0.5, 0.9)) == Approx(0.9 - b.max()[1]).margin(0.05));
  // area scales with size^2, both from the polygon and the midpoint rule
  const double scale = 0.3 / outline.bounds().sizes().maxCoeff();
  const double area = outline.signed_area() * scale * scale;
  CHECK(volume_inside<2>(*bunny, b, 400) == Approx(area).epsilon(0.01));
  // a rotation by pi about the centre turns it upside down
  s.rotation = {EIGEN_PI};
  const auto flipped = make_shape<2>(s, "k");
  const Vec<2> probe(0.5 + 0.02, 0.4 - 0.11);
  CHECK(flipped->distance(Vec<2>(1.0, 0.8) - probe) == Approx(bunny->distance(probe)).margin(1e-12));
}

TEST_CASE("polygon acceleration (edge hierarchy, sign lattice) is exact", "[dense-reference]") {
  // the bunny outline (302 vertices: accelerated) against a brute-force reference
  const auto& pts = bunny_silhouette_points();
  const PolygonShape poly(pts);
  auto reference = [&](const Vec<2>& x) {
    double best = std::numeric_limits<double>::infinity();
    bool odd = false;
    for (std::size_t i = 0; i < pts.size(); ++i) {
      const Vec<2>& a = pts[i];
      const Vec<2>& b = pts[(i + 1) % pts.size()];
      const Vec<2> e = b - a;
      const double t = std::clamp((x - a).dot(e) / e.squaredNorm(), 0.0, 1.0);
      best = std::min(best, (x - a - t * e).norm());
      // even-odd crossing of the ray to +x (a simple polygon)
      if ((a[1] > x[1]) != (b[1] > x[1]) && a[0] + (x[1] - a[1]) / (b[1] - a[1]) * e[0] > x[0]) {
        odd = !odd;
      }
    }
    return odd ? -best : best;
  };
  std::mt19937 rng(21);
  const Box<2> b = poly.bounds();
  int near = 0;
  for (int k = 0; k < 20000; ++k) {
    const Vec<2> x = b.center() + 0.7 * random_point<2>(rng, -1, 1).cwiseProduct(b.sizes());
    const double r = reference(x);
    REQUIRE(poly.distance(x) == Approx(r).margin(1e-12));
    near += std::abs(r) < 0.1;
  }
  CHECK(near > 100);
  // points just off the boundary, on both sides of edge midpoints
  for (std::size_t i = 0; i < pts.size(); i += 7) {
    const Vec<2> a = pts[i], e = pts[(i + 1) % pts.size()] - a;
    const Vec<2> n(e[1], -e[0]);
    for (double off : {-1e-3, 1e-3}) {
      const Vec<2> x = a + 0.5 * e + off * n.normalized();
      REQUIRE(poly.distance(x) == Approx(reference(x)).margin(1e-12));
    }
  }
}

TEST_CASE("polygon sign lattice: non-zero winding numbers of a doubly wound outline", "[unit]") {
  // a 48-gon traversed twice (96 vertices: accelerated): winding number 2 inside, so nonzero
  // winding counts it as inside where an even-odd rule would call it outside
  std::vector<Vec<2>> pts;
  const double pi = std::acos(-1.0);
  for (int turn = 0; turn < 2; ++turn)
    for (int k = 0; k < 48; ++k) pts.emplace_back(0.3 + 0.2 * std::cos(2 * pi * k / 48), 0.6 + 0.2 * std::sin(2 * pi * k / 48));
  const PolygonShape poly(pts);
  std::mt19937 rng(5);
  int inside = 0;
  for (int k = 0; k < 4000; ++k) {
    const Vec<2> x = Vec<2>(0.3, 0.6) + 0.3 * random_point<2>(rng, -1, 1);
    const double r = (x - Vec<2>(0.3, 0.6)).norm();
    // away from the polygon's chords (within 0.2 (1 - cos(pi / 48)) of the circle), the circle decides
    if (std::abs(r - 0.2) < 0.2 * (1.0 - std::cos(pi / 48)) + 1e-9) continue;
    CHECK((poly.distance(x) < 0.0) == (r < 0.2));
    inside += r < 0.2;
  }
  CHECK(inside > 1000);
}

TEMPLATE_TEST_CASE_SIG("rotation centres: union about its first child's bounds, halfspace about the origin",
                       "[unit]", ((int Dim), Dim), 2, 3) {
  std::mt19937 rng(17);
  const Vec<Dim> c0 = Vec<Dim>::Constant(0.3), c1 = Vec<Dim>::Constant(0.6);
  ShapeSpec u;
  u.type = ShapeType::set_union;
  u.shapes = {box_spec<Dim>(c0, Vec<Dim>::Constant(0.1)), round_spec<Dim>(ShapeType::sphere, c1, 0.15)};
  ShapeSpec ur = u;
  ur.rotation = rotation_value<Dim>(1.1);
  const Mat<Dim> r = rotation_matrix<Dim>(ur.rotation);
  const auto a = make_shape<Dim>(u, "u");
  const auto b = make_shape<Dim>(ur, "u");
  // the pivot is the centre of the first child's bounds, c0
  for (int k = 0; k < 200; ++k) {
    const Vec<Dim> x = random_point<Dim>(rng, -0.5, 1.5);
    REQUIRE(b->distance(Vec<Dim>(c0 + r * (x - c0))) == Approx(a->distance(x)).margin(1e-14));
  }
  // halfspace y <= 0.2 rotated about the origin: the normal rotates, the offset stays
  ShapeSpec hs;
  hs.type = ShapeType::halfspace;
  hs.normal = rep<Dim>(0.0);
  hs.normal[1] = 1.0;
  hs.offset = 0.2;
  hs.rotation = rotation_value<Dim>(0.8);
  const auto h = make_shape<Dim>(hs, "h");
  const Vec<Dim> n = rotation_matrix<Dim>(hs.rotation) * Vec<Dim>::Unit(1);
  for (int k = 0; k < 50; ++k) {
    const Vec<Dim> x = random_point<Dim>(rng, -2, 2);
    REQUIRE(h->distance(x) == Approx(n.dot(x) - 0.2).margin(1e-14));
  }
  CHECK(std::isinf(h->bounds().max()[0]));
}

TEMPLATE_TEST_CASE_SIG("box gradients are exact next to edges and corners", "[unit]", ((int Dim), Dim),
                       2, 3) {
  ShapeSpec spec;
  spec.type = ShapeType::box;
  spec.center = std::vector<double>(Dim, 0.0);
  spec.half_size = std::vector<double>(Dim, 0.5);
  const ShapePtr<Dim> box = make_shape<Dim>(spec, "box");
  // just above the top face, 1e-6 from the edge: the face normal, not a blend
  Vec<Dim> x = Vec<Dim>::Constant(0.5 - 1e-6);
  x[1] = 0.5 + 1e-3;
  CHECK((box->gradient(x) - Vec<Dim>::Unit(1)).norm() < 1e-14);
  // just inside the top face near the edge: the top face is the nearest
  x[1] = 0.5 - 1e-8;
  CHECK((box->gradient(x) - Vec<Dim>::Unit(1)).norm() < 1e-14);
  // beyond a corner: along the diagonal
  const Vec<Dim> corner = Vec<Dim>::Constant(0.5);
  CHECK((box->gradient(corner + Vec<Dim>::Constant(0.1)) - Vec<Dim>::Ones().normalized()).norm() <
        1e-14);
  // and the gradient agrees with central differences of the distance away from edges
  const Vec<Dim> y = Vec<Dim>::Constant(0.2) + 0.6 * Vec<Dim>::Unit(0);
  Vec<Dim> fd;
  for (int a = 0; a < Dim; ++a) {
    const double h = 1e-6;
    fd[a] = (box->distance(y + h * Vec<Dim>::Unit(a)) - box->distance(y - h * Vec<Dim>::Unit(a))) /
            (2 * h);
  }
  CHECK((box->gradient(y) - fd).norm() < 1e-8);
}
