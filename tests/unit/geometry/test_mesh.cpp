/// \file test_mesh.cpp
/// Tests of dim3/mesh.cpp (OBJ reading), dim3/mesh_sdf.cpp (exact and cached mesh SDF) and the
/// mesh and bunny shapes of dim3/shapes_3d.cpp.

#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include "dim3/mesh.hpp"
#include "dim3/mesh_sdf.hpp"
#include "dim3/shapes_3d.hpp"
#include "reference/core/errors.hpp"
#include "reference/geometry/shape.hpp"
#include "reference/geometry/shape_tools.hpp"

using namespace monolith;

namespace {

/// The cube [-1, 1]^3 with outward quads, exercising every face-index form.
const char* kCubeObj = R"(# a cube
o cube
v -1 -1 -1
v  1 -1 -1
v  1  1 -1
v -1  1 -1
v -1 -1  1
v  1 -1  1
v  1  1  1
v -1  1  1
vt 0 0
vn 0 0 1
s off
usemtl none
f 1 4 3 2
f 5/1 6/1 7/1 8/1
f 1//1 2//1 6//1 5//1
f 4/1/1 8/1/1 7/1/1 3/1/1
f -8 -4 -1 -5
f 2 3 7 6
)";

/// The same cube with every face reversed (inward-facing).
const char* kInwardCubeObj = R"(v -1 -1 -1
v  1 -1 -1
v  1  1 -1
v -1  1 -1
v -1 -1  1
v  1 -1  1
v  1  1  1
v -1  1  1
f 2 3 4 1
f 8 7 6 5
f 5 6 2 1
f 3 7 8 4
f 4 8 5 1
f 6 7 3 2
)";

double box_distance(const Vec<3>& x, const Vec<3>& c, const Vec<3>& h) {
  const Vec<3> q = (x - c).cwiseAbs() - h;
  return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
}

Vec<3> random_point(std::mt19937& rng, double lo, double hi) {
  std::uniform_real_distribution<double> u(lo, hi);
  return Vec<3>(u(rng), u(rng), u(rng));
}

std::filesystem::path temp_file(const std::string& name, const std::string& text) {
  const auto dir = std::filesystem::temp_directory_path() / "monolith_test_mesh";
  std::filesystem::create_directories(dir);
  const auto path = dir / name;
  std::ofstream(path) << text;
  return path;
}

}  // namespace

TEST_CASE("OBJ reader: vertices, every face form, negative indices, polygon fans", "[unit]") {
  const TriangleMesh m = parse_obj(kCubeObj, "cube.obj", "bodies[0].shape.file");
  CHECK(m.vertices.size() == 8);
  CHECK(m.triangles.size() == 12);
  CHECK(m.signed_volume() == Approx(8.0).epsilon(1e-14));
  CHECK((m.bounds().min() - Vec<3>::Constant(-1)).norm() == 0.0);
  // the negative-index face -8 -4 -1 -5 is 1 5 8 4, fanned from its first corner
  CHECK(m.triangles[8] == std::array<int, 3>{0, 4, 7});
  CHECK(m.triangles[9] == std::array<int, 3>{0, 7, 3});
  TriangleMesh inward = parse_obj(kInwardCubeObj, "in.obj", "k");
  CHECK(inward.signed_volume() == Approx(-8.0).epsilon(1e-14));
  inward.flip();
  CHECK(inward.signed_volume() == Approx(8.0).epsilon(1e-14));
}

TEST_CASE("mesh SDF of an OBJ cube matches the box SDF", "[unit][dense-reference]") {
  const MeshSdf sdf(parse_obj(kCubeObj, "cube.obj", "k"));
  const MeshSdf inward(parse_obj(kInwardCubeObj, "in.obj", "k"));
  CHECK_FALSE(sdf.was_flipped());
  CHECK(inward.was_flipped());
  const Vec<3> c = Vec<3>::Zero(), h = Vec<3>::Ones();
  std::mt19937 rng(5);
  double cache_err = 0.0;
  for (int k = 0; k < 4000; ++k) {
    const Vec<3> x = random_point(rng, -2.5, 2.5);
    const double exact = box_distance(x, c, h);
    // exact path to round-off, with either input orientation
    REQUIRE(sdf.exact_distance(x) == Approx(exact).margin(1e-9));
    REQUIRE(inward.exact_distance(x) == Approx(exact).margin(1e-9));
    cache_err = std::max(cache_err, std::abs(sdf.distance(x) - exact));
    // the exact gradient is the box's
    if (std::abs(exact) > 1e-3) {
      const Vec<3> g = sdf.exact(x).normal;
      const double e = 1e-6;
      Vec<3> fd;
      for (int a = 0; a < 3; ++a) {
        fd[a] = (box_distance(x + e * Vec<3>::Unit(a), c, h) -
                 box_distance(x - e * Vec<3>::Unit(a), c, h)) / (2 * e);
      }
      if (std::abs(fd.norm() - 1.0) < 1e-6) CHECK((g - fd).norm() < 1e-4);
    }
  }
  // cached path: the documented bound 0.3 h (docs/geometry.md): trilinear interpolation of the
  // cone |x - corner| with the apex on a node errs by (3 + 3 sqrt 2 + sqrt 3)/8 - sqrt 3/2 =
  // 0.256 h at the cell centre; where the SDF is linear within a cell the cache is exact
  INFO("max cache error " << cache_err << ", spacing " << sdf.cache_spacing());
  CHECK(sdf.cache_spacing() == Approx(2.0 / 64));
  CHECK(cache_err < 0.3 * sdf.cache_spacing());
  // points on faces, edges and corners are at distance 0
  CHECK(std::abs(sdf.exact_distance(Vec<3>(1, 0.3, -0.2))) < 1e-15);
  CHECK(std::abs(sdf.exact_distance(Vec<3>(1, 1, 0.5))) < 1e-15);
  CHECK(std::abs(sdf.exact_distance(Vec<3>(-1, 1, -1))) < 1e-15);
  // winding number: 1 inside, 0 outside
  CHECK(sdf.winding_number(Vec<3>(0.2, -0.3, 0.9)) == Approx(1.0).epsilon(1e-12));
  CHECK(sdf.winding_number(Vec<3>(1.2, -0.3, 0.9)) == Approx(0.0).margin(1e-12));
}

TEST_CASE("mesh shape from a file: scale, translate, rotation about translate", "[unit]") {
  const auto path = temp_file("cube.obj", kCubeObj);
  ShapeSpec s;
  s.type = ShapeType::mesh;
  s.file = path;
  s.scale = {0.5, 0.25, 1.0};
  s.translate = {2.0, 3.0, 4.0};
  const auto shape = make_shape<3>(s, "bodies[0].shape");
  const Vec<3> c(2, 3, 4), h(0.5, 0.25, 1.0);
  std::mt19937 rng(9);
  for (int k = 0; k < 500; ++k) {
    const Vec<3> x = c + random_point(rng, -1.5, 1.5);
    REQUIRE(shape->distance(x) == Approx(box_distance(x, c, h)).margin(0.3 * 2.0 / 64));
  }
  CHECK((shape->bounds().min() - (c - h)).norm() < 1e-14);
  // uniform scale 1 number, rotated by 90 degrees about z around `translate`
  s.scale = {0.5};
  s.rotation = {0.0, 0.0, 0.5 * EIGEN_PI};
  s.translate = {0.0, 0.0, 0.0};
  const auto turned = make_shape<3>(s, "k");
  CHECK(turned->distance(Vec<3>(0.3, 0.2, 0.1)) == Approx(-0.2).margin(1e-3));
  CHECK(turned->distance(Vec<3>(0.0, 0.0, 0.8)) == Approx(0.3).margin(1e-3));
}

TEST_CASE("malformed OBJ input throws InputError naming the file, line and key", "[unit]") {
  const std::string key = "bodies[3].shape.file";
  struct Case {
    const char* what;
    const char* text;
    int line;
  };
  const Case cases[] = {
      {"bad number", "v 0 0 0\nv 1 0 0\nv 0 1.5.2 0\nf 1 2 3\n", 3},
      {"vertex with 2 coordinates", "v 0 0 0\nv 1 0\n", 2},
      {"non-finite coordinate", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan 0 0\nf 1 2 3\n", 4},
      {"infinite coordinate", "v 0 0 0\nv inf 0 0\n", 2},
      {"index out of range", "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 4\n", 5},
      {"zero index", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", 4},
      {"negative index out of range", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n", 4},
      {"two-vertex face", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", 4},
      {"bad index token", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x3\n", 4},
      {"no faces", "# only vertices\nv 0 0 0\nv 1 0 0\nv 0 1 0\n", 4},
      {"unknown statement", "v 0 0 0\nvx 1 0 0\n", 2},
      {"face before its vertices", "f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n", 1},
  };
  for (const auto& c : cases) {
    INFO(c.what);
    bool thrown = false;
    try {
      parse_obj(c.text, "broken.obj", key);
    } catch (const InputError& e) {
      thrown = true;
      const std::string msg = e.what();
      INFO(msg);
      CHECK(msg.find("broken.obj:" + std::to_string(c.line) + ": ") == 0);
      CHECK(msg.find(key) != std::string::npos);
      REQUIRE(e.problems().size() == 1);
    }
    CHECK(thrown);
  }
  // a missing file, through make_shape
  ShapeSpec s;
  s.type = ShapeType::mesh;
  s.file = std::filesystem::temp_directory_path() / "monolith_no_such_dir" / "nowhere.obj";
  CHECK_THROWS_WITH(make_shape<3>(s, "bodies[1].shape"),
                    Catch::Contains("nowhere.obj") && Catch::Contains("bodies[1].shape.file"));
  // a malformed file on disk names its path and line
  s.file = temp_file("bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
  CHECK_THROWS_WITH(make_shape<3>(s, "bodies[1].shape"),
                    Catch::Contains("bad.obj:4:") && Catch::Contains("bodies[1].shape.file"));
}

TEST_CASE("bunny: volume by divergence theorem vs volume_inside, signs", "[unit][validation]") {
  // the embedded mesh as committed
  const TriangleMesh& raw = bunny_mesh();
  CHECK(raw.vertices.size() == 1839);
  CHECK(raw.triangles.size() == 3674);
  const Box<3> rb = raw.bounds();
  CHECK(rb.min()[1] == Approx(0.0).margin(0.05));
  CHECK(rb.max()[1] == Approx(9.65).margin(0.05));
  // placed: longest extent `size`, box centre `center`
  const Vec<3> center(0.5, 0.4, 0.3);
  const double size = 0.6;
  ShapeSpec s;
  s.type = ShapeType::bunny;
  s.center = {center[0], center[1], center[2]};
  s.size = size;
  const auto t0 = std::chrono::steady_clock::now();
  const auto bunny = make_shape<3>(s, "bodies[0].shape");
  const double build_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const Box<3> b = bunny->bounds();
  CHECK(b.sizes().maxCoeff() == Approx(size).epsilon(1e-12));
  CHECK((b.center() - center).norm() < 1e-12);
  // volume: divergence theorem vs midpoint rule of the SDF
  const TriangleMesh placed = placed_bunny_mesh(center, size);
  const double v_mesh = placed.signed_volume();
  const Box<3> region(b.min().array() - 0.01, b.max().array() + 0.01);
  const auto t1 = std::chrono::steady_clock::now();
  const double v_sdf = volume_inside<3>(*bunny, region, 96);
  const double vol_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
  WARN("bunny: cache build " << build_s << " s, volume_inside(96^3) " << vol_s << " s, V_mesh "
       << v_mesh << ", V_sdf " << v_sdf << ", rel diff " << std::abs(v_sdf / v_mesh - 1));
  CHECK(v_mesh > 0.0);
  CHECK(v_sdf == Approx(v_mesh).epsilon(0.01));
  // sign: the centroid region is inside, far away outside
  Vec<3> centroid = Vec<3>::Zero();
  for (const auto& v : placed.vertices) centroid += v;
  centroid /= static_cast<double>(placed.vertices.size());
  const MeshSdf sdf(placed, 0);
  const Vec<3> body_center = Vec<3>(center[0], b.min()[1] + 0.3 * b.sizes()[1], center[2]);
  CHECK(bunny->distance(body_center) < 0.0);
  CHECK(sdf.winding_number(body_center) == Approx(1.0).epsilon(1e-6));
  CHECK(bunny->distance(center + Vec<3>(3, 0, 0)) == Approx(sdf.exact_distance(center + Vec<3>(3, 0, 0))));
  CHECK(bunny->distance(center + Vec<3>(3, 0, 0)) > 2.5);
  CHECK(bunny->distance(center + Vec<3>(0, -2, 1)) > 1.5);
  // pseudo-normal signs agree with the winding number at random points near the bunny
  std::mt19937 rng(13);
  int agree = 0, total = 0;
  for (int k = 0; k < 300; ++k) {
    const Vec<3> x = b.center() + 0.6 * random_point(rng, -1, 1).cwiseProduct(b.sizes());
    const double w = sdf.winding_number(x);
    const bool inside_w = w > 0.5;
    const bool inside_d = sdf.exact_distance(x) < 0.0;
    ++total;
    agree += inside_w == inside_d;
    CHECK(std::min(std::abs(w), std::abs(w - 1.0)) < 1e-6);
  }
  CHECK(agree == total);
  // the cached, scaled bunny agrees with the exact SDF of the placed mesh within 0.3 h
  const double h = size / 64.0;
  double worst = 0.0;
  for (int k = 0; k < 2000; ++k) {
    const Vec<3> x = b.center() + 0.7 * random_point(rng, -1, 1).cwiseProduct(b.sizes());
    worst = std::max(worst, std::abs(bunny->distance(x) - sdf.exact_distance(x)));
  }
  INFO("bunny cache error " << worst << " = " << worst / h << " h");
  CHECK(worst < 0.3 * h);
  // the gradient is the exact unit normal; a second bunny reuses the shared SDF (fast)
  CHECK(bunny->gradient(centroid).norm() == Approx(1.0));
  const auto t2 = std::chrono::steady_clock::now();
  s.size = 2.0;
  const auto big = make_shape<3>(s, "bodies[1].shape");
  CHECK(std::chrono::duration<double>(std::chrono::steady_clock::now() - t2).count() < 0.05);
  // uniform scaling about the centre scales the distance
  for (int k = 0; k < 20; ++k) {
    const Vec<3> x = b.center() + 0.7 * random_point(rng, -1, 1).cwiseProduct(b.sizes());
    const Vec<3> xs = center + (2.0 / size) * (x - center);
    CHECK(big->distance(xs) == Approx((2.0 / size) * bunny->distance(x)).margin(1e-12));
  }
}
