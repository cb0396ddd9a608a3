// Tests of the 2D and 3D frame renderers (dim2/render_2d.cpp, dim3/render_3d.cpp) on hand-made
// RenderViews: an analytic liquid sampled on the half lattice, analytic solids.
#include <catch2/catch.hpp>

#include <omp.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>

#include "reference/render.hpp"

using namespace monolith;

namespace {

// --- analytic shapes for the tests ---------------------------------------------------------------

template <int Dim>
class TestBall : public Shape<Dim> {
 public:
  TestBall(const Vec<Dim>& c, double r) : c_(c), r_(r) {}
  double distance(const Vec<Dim>& x) const override { return (x - c_).norm() - r_; }
  Vec<Dim> gradient(const Vec<Dim>& x) const override {
    const Vec<Dim> d = x - c_;
    return d.norm() > 0 ? Vec<Dim>(d.normalized()) : Vec<Dim>(Vec<Dim>::UnitX());
  }
  Box<Dim> bounds() const override {
    return Box<Dim>(c_ - Vec<Dim>::Constant(r_), c_ + Vec<Dim>::Constant(r_));
  }

 private:
  Vec<Dim> c_;
  double r_;
};

template <int Dim>
class TestBox : public Shape<Dim> {
 public:
  TestBox(const Vec<Dim>& c, const Vec<Dim>& half) : c_(c), h_(half) {}
  double distance(const Vec<Dim>& x) const override {
    const Vec<Dim> q = (x - c_).cwiseAbs() - h_;
    return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
  }
  Vec<Dim> gradient(const Vec<Dim>& x) const override {
    Vec<Dim> g;
    const double e = 1e-6;
    for (int a = 0; a < Dim; ++a) {
      Vec<Dim> d = Vec<Dim>::Zero();
      d[a] = e;
      g[a] = (distance(x + d) - distance(x - d)) / (2 * e);
    }
    return g.normalized();
  }
  Box<Dim> bounds() const override { return Box<Dim>(c_ - h_, c_ + h_); }

 private:
  Vec<Dim> c_, h_;
};

// --- a hand-made scene: unit domain, liquid ball, one solid box ---------------------------------

template <int Dim>
struct TestScene {
  MacGrid<Dim> grid;
  VectorX phi, velocity, pressure, viscosity;
  std::vector<Vec<Dim>> particles;
  RenderView<Dim> view;
  Vec<Dim> liquid_center;
  double liquid_radius = 0.25;

  explicit TestScene(int n) {
    std::array<bool, Dim> periodic{};
    grid = MacGrid<Dim>(Vec<Dim>::Zero(), 1.0 / n, VecI<Dim>::Constant(n), periodic);
    liquid_center = Vec<Dim>::Constant(0.5);
    liquid_center[1] = 0.4;
    const SampleLattice<Dim> lattice = half_lattice(grid);
    phi.resize(lattice.size());
    for (int k = 0; k < lattice.size(); ++k)
      phi[k] = (lattice.position(lattice.coord(k)) - liquid_center).norm() - liquid_radius;
    // a shear flow u_x = 4 (y - 0.15): slow at the bottom of the ball, fast at its top
    velocity = VectorX::Zero(grid.num_faces());
    for (int i = 0; i < grid.num_faces(); ++i) {
      const auto [axis, f] = grid.face_coord(i);
      if (axis == 0) velocity[i] = 4.0 * (grid.face_center(axis, f)[1] - 0.15);
    }
    // hydrostatic pressure below y = 0.65
    pressure = VectorX::Zero(grid.num_cells());
    viscosity = VectorX::Zero(grid.num_cells());
    for (int c = 0; c < grid.num_cells(); ++c) {
      const Vec<Dim> x = grid.cell_center(grid.cell_coord(c));
      pressure[c] = 1000.0 * 9.81 * (0.65 - x[1]);
      viscosity[c] = x[0];
    }
    view.grid = &grid;
    view.liquid_phi = &phi;
    view.velocity = &velocity;
    view.pressure = &pressure;
    view.viscosity = &viscosity;
    view.boundary.fill(BoundaryType::wall);
    view.time = 1.25;
    Vec<Dim> bc = Vec<Dim>::Constant(0.5);
    bc[0] = 0.8;
    bc[1] = 0.8;
    view.solids.push_back({std::make_shared<TestBox<Dim>>(bc, Vec<Dim>::Constant(0.08)), Rgb{170, 140, 110}});
  }
};

int color_distance(Rgb a, Rgb b) {
  return std::abs(a[0] - b[0]) + std::abs(a[1] - b[1]) + std::abs(a[2] - b[2]);
}
int brightness(Rgb c) { return c[0] + c[1] + c[2]; }

// writes the image where MONOLITH_TEST_PICTURES points (for looking at it), if set
void keep_picture(const Image& img, const std::string& name) {
  if (const char* dir = std::getenv("MONOLITH_TEST_PICTURES")) {
    std::filesystem::create_directories(dir);
    img.write_ppm(std::string(dir) + "/" + name + ".ppm");
  }
}

// pixel of world point (x, y) in a 2D picture of the unit square domain: the renderer keeps a
// margin and centres the domain; find the domain by its mapping at the image centre
struct Map2 {
  int w, h;
  double scale, ox, oy;
  Map2(int width, int height) : w(width), h(height) {
    const int margin = std::max(4, static_cast<int>(std::lround(0.035 * std::min(width, height))));
    scale = std::min(width - 2.0 * margin, height - 2.0 * margin);
    ox = 0.5 * (width - scale);
    oy = 0.5 * (height - scale);
  }
  int i(double x) const { return static_cast<int>(ox + x * scale); }
  int j(double y) const { return static_cast<int>(oy + (1.0 - y) * scale); }
};

}  // namespace

// --- 2D ---------------------------------------------------------------------------------------------

TEST_CASE("2D: image size as requested, liquid, background, solid", "[unit][render]") {
  TestScene<2> scene(32);
  RenderSpec spec;
  spec.size = {300, 200};
  spec.color_by = "none";
  const Image img = render_frame<2>(scene.view, spec);
  keep_picture(img, "render2d_none");
  REQUIRE(img.width == 300);
  REQUIRE(img.height == 200);
  const Map2 m(300, 200);
  const Rgb centre = img.get(m.i(0.5), m.j(0.4));
  // water blue at the liquid centre
  CHECK(centre[2] > centre[0] + 80);
  CHECK(centre[2] > centre[1] + 20);
  // light background outside the liquid, away from the labels
  const Rgb air = img.get(m.i(0.3), m.j(0.85));
  CHECK(brightness(air) > 650);
  CHECK(color_distance(air, centre) > 200);
  // the solid box in its colour at its centre
  CHECK(color_distance(img.get(m.i(0.8), m.j(0.8)), Rgb{170, 140, 110}) < 30);
  // the liquid edge is anti-aliased: some pixel along a row through the ball is between colours
  int partial = 0;
  for (int i = m.i(0.2); i < m.i(0.3); ++i) {
    const Rgb c = img.get(i, m.j(0.4));
    if (brightness(c) < brightness(air) - 40 && brightness(c) > brightness(centre) + 40) ++partial;
  }
  CHECK(partial >= 1);
}

TEST_CASE("2D: walls are dark bands at the borders, open faces are not", "[unit][render]") {
  TestScene<2> scene(32);
  RenderSpec spec;
  spec.size = {256, 256};
  spec.color_by = "none";
  const Map2 m(256, 256);
  const Image walls = render_frame<2>(scene.view, spec);
  // every wall face: the middle of its band (just outside the domain) is dark
  const int band_mid = static_cast<int>(std::lround(0.5 * std::max(2.0, std::round(0.55 * 9))));
  CHECK(brightness(walls.get(m.i(0.0) - band_mid, 128)) < 250);
  CHECK(brightness(walls.get(m.i(1.0) + band_mid, 128)) < 250);
  CHECK(brightness(walls.get(128, m.j(0.0) + band_mid)) < 250);
  CHECK(brightness(walls.get(128, m.j(1.0) - band_mid)) < 250);
  scene.view.boundary.fill(BoundaryType::open);
  const Image open = render_frame<2>(scene.view, spec);
  CHECK(brightness(open.get(m.i(0.0) - band_mid, 128)) > 600);
  CHECK(brightness(open.get(m.i(1.0) + band_mid, 128)) > 600);
  // periodic x: a dashed line on the face, so some but not all pixels along it are darker
  scene.view.boundary[0] = scene.view.boundary[1] = BoundaryType::periodic;
  const Image periodic = render_frame<2>(scene.view, spec);
  keep_picture(periodic, "render2d_periodic");
  int darker = 0, total = 0;
  for (int j = m.j(0.95); j < m.j(0.6); ++j, ++total)
    darker += brightness(periodic.get(m.i(1.0), j)) < brightness(open.get(m.i(1.0), j)) - 60;
  CHECK(darker > total / 5);
  CHECK(darker < total);
}

TEST_CASE("2D: color_by speed separates slow and fast liquid", "[unit][render]") {
  TestScene<2> scene(32);
  RenderSpec spec;
  spec.size = {256, 256};
  spec.color_by = "speed";
  const Map2 m(256, 256);
  const Image img = render_frame<2>(scene.view, spec);
  keep_picture(img, "render2d_speed");
  // |u| = 4 |y - 0.15|: bottom of the ball (y = 0.17) slow, top (y = 0.62) fast
  const Rgb slow = img.get(m.i(0.5), m.j(0.17));
  const Rgb fast = img.get(m.i(0.5), m.j(0.62));
  CHECK(color_distance(slow, fast) > 200);
  // viridis: slow is dark purple-blue, fast is green-yellow
  CHECK(brightness(slow) < brightness(fast) - 150);
  CHECK(fast[1] > fast[2]);
  // a slower field everywhere gives the same picture (the scale follows the field) but
  // color_by none differs
  spec.color_by = "none";
  const Image plain = render_frame<2>(scene.view, spec);
  CHECK(color_distance(plain.get(m.i(0.5), m.j(0.62)), fast) > 100);
}

TEST_CASE("2D: color_by pressure and viscosity use their fields", "[unit][render]") {
  TestScene<2> scene(32);
  RenderSpec spec;
  spec.size = {256, 256};
  const Map2 m(256, 256);
  spec.color_by = "pressure";
  const Image p = render_frame<2>(scene.view, spec);
  keep_picture(p, "render2d_pressure");
  // coolwarm: high pressure (bottom) red, low (top) blue-ish
  const Rgb bottom = p.get(m.i(0.5), m.j(0.18)), top = p.get(m.i(0.5), m.j(0.62));
  CHECK(bottom[0] > bottom[2] + 60);
  CHECK(top[2] > top[0]);
  spec.color_by = "viscosity";
  const Image v = render_frame<2>(scene.view, spec);
  keep_picture(v, "render2d_viscosity");
  CHECK(color_distance(v.get(m.i(0.3), m.j(0.4)), v.get(m.i(0.7), m.j(0.4))) > 150);
  // a null viscosity field is zero everywhere: one colour across the ball
  scene.view.viscosity = nullptr;
  const Image z = render_frame<2>(scene.view, spec);
  CHECK(color_distance(z.get(m.i(0.3), m.j(0.4)), z.get(m.i(0.7), m.j(0.4))) < 10);
}

TEST_CASE("2D: particles show where the liquid is thin", "[unit][render]") {
  TestScene<2> scene(32);
  // a drop of particles well outside the liquid
  for (int k = 0; k < 5; ++k) scene.particles.push_back(Vec<2>(0.2 + 0.01 * k, 0.9));
  scene.view.particles = &scene.particles;
  RenderSpec spec;
  spec.size = {256, 256};
  spec.color_by = "none";
  const Map2 m(256, 256);
  const Image with = render_frame<2>(scene.view, spec);
  scene.view.particles = nullptr;
  const Image without = render_frame<2>(scene.view, spec);
  CHECK(color_distance(with.get(m.i(0.22), m.j(0.9)), without.get(m.i(0.22), m.j(0.9))) > 60);
  // particles deep inside the ball are not drawn
  CHECK(with.get(m.i(0.5), m.j(0.4)) == without.get(m.i(0.5), m.j(0.4)));
}

TEST_CASE("2D: deterministic, and the same for 1 and 2 threads", "[unit][render]") {
  TestScene<2> scene(32);
  RenderSpec spec;
  spec.size = {200, 160};
  omp_set_num_threads(1);
  const Image a = render_frame<2>(scene.view, spec);
  omp_set_num_threads(2);
  const Image b = render_frame<2>(scene.view, spec);
  const Image c = render_frame<2>(scene.view, spec);
  CHECK(a.rgb == b.rgb);
  CHECK(b.rgb == c.rgb);
}

TEST_CASE("2D: the time is written in a corner", "[unit][render]") {
  TestScene<2> scene(32);
  RenderSpec spec;
  spec.size = {256, 256};
  spec.color_by = "none";
  const Image a = render_frame<2>(scene.view, spec);
  scene.view.time = 7.5;
  const Image b = render_frame<2>(scene.view, spec);
  // the two pictures differ only in the top-left label
  int diff_label = 0, diff_elsewhere = 0;
  for (int j = 0; j < 256; ++j)
    for (int i = 0; i < 256; ++i)
      if (a.get(i, j) != b.get(i, j)) (i < 128 && j < 40 ? diff_label : diff_elsewhere)++;
  CHECK(diff_label > 5);
  CHECK(diff_elsewhere == 0);
}
