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

#include "reference/app/embedded_scenes.hpp"
#include "reference/viz/render.hpp"
#include "tests/support/test_helpers.hpp"

using namespace monolith;
using namespace monolith::testing;

namespace {

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
  spec.color_by = ColorBy::none;
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
  spec.color_by = ColorBy::none;
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
  spec.color_by = ColorBy::speed;
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
  spec.color_by = ColorBy::none;
  const Image plain = render_frame<2>(scene.view, spec);
  CHECK(color_distance(plain.get(m.i(0.5), m.j(0.62)), fast) > 100);
}

TEST_CASE("2D: color_by pressure and viscosity use their fields", "[unit][render]") {
  TestScene<2> scene(32);
  RenderSpec spec;
  spec.size = {256, 256};
  const Map2 m(256, 256);
  spec.color_by = ColorBy::pressure;
  const Image p = render_frame<2>(scene.view, spec);
  keep_picture(p, "render2d_pressure");
  // coolwarm: high pressure (bottom) red, low (top) blue-ish
  const Rgb bottom = p.get(m.i(0.5), m.j(0.18)), top = p.get(m.i(0.5), m.j(0.62));
  CHECK(bottom[0] > bottom[2] + 60);
  CHECK(top[2] > top[0]);
  spec.color_by = ColorBy::viscosity;
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
  spec.color_by = ColorBy::none;
  const Map2 m(256, 256);
  const Image with = render_frame<2>(scene.view, spec);
  scene.view.particles = nullptr;
  const Image without = render_frame<2>(scene.view, spec);
  CHECK(color_distance(with.get(m.i(0.22), m.j(0.9)), without.get(m.i(0.22), m.j(0.9))) > 60);
  // particles deep inside the ball are not drawn
  CHECK(with.get(m.i(0.5), m.j(0.4)) == without.get(m.i(0.5), m.j(0.4)));
}

TEST_CASE("2D: particles inside a thin sheet are drawn, inside the bulk not", "[unit][render]") {
  TestScene<2> scene(32);
  // a horizontal sheet 0.04 thick (1.3 dx) at y = 0.8, beside the ball; the level set in the
  // ball is shallow, as a particle reconstruction gives (-dx/3 throughout)
  const SampleLattice<2> lattice = half_lattice(scene.grid);
  for (int k = 0; k < lattice.size(); ++k) {
    const Vec<2> x = lattice.position(lattice.coord(k));
    const double sheet = std::max(std::abs(x[1] - 0.8) - 0.02, std::abs(x[0] - 0.35) - 0.2);
    scene.phi[k] = std::min(std::max(scene.phi[k], -0.01), sheet);
  }
  scene.particles = {Vec<2>(0.3, 0.8), Vec<2>(0.5, 0.4)};
  scene.view.particles = &scene.particles;
  scene.view.solids.clear();
  RenderSpec spec;
  spec.size = {256, 256};
  spec.color_by = ColorBy::none;
  const Map2 m(256, 256);
  const Image with = render_frame<2>(scene.view, spec);
  keep_picture(with, "render2d_sheet");
  scene.view.particles = nullptr;
  const Image without = render_frame<2>(scene.view, spec);
  CHECK(color_distance(with.get(m.i(0.3), m.j(0.8)), without.get(m.i(0.3), m.j(0.8))) > 60);
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
  spec.color_by = ColorBy::none;
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

TEST_CASE("2D: a colour bar with its range is drawn only when colouring by a field", "[unit][render]") {
  TestScene<2> scene(32);
  RenderSpec spec;
  spec.size = {320, 320};
  const Map2 m(320, 320);
  // the top-right quarter of the domain's top band, away from the solid
  const auto ink_and_ramp = [&](const Image& img, int& ink, int& ramp) {
    ink = ramp = 0;
    for (int j = m.j(1.0); j < m.j(1.0) + 30; ++j)
      for (int i = m.i(0.5); i < m.i(1.0); ++i) {
        const Rgb c = img.get(i, j);
        ink += brightness(c) < 150;
        ramp += color_distance(c, colormap_viridis(1.0)) < 40;
      }
  };
  spec.color_by = ColorBy::speed;
  int ink = 0, ramp = 0;
  ink_and_ramp(render_frame<2>(scene.view, spec), ink, ramp);
  CHECK(ink > 30);   // digits of the range and the caption
  CHECK(ramp > 5);   // the yellow end of the ramp
  spec.color_by = ColorBy::none;
  ink_and_ramp(render_frame<2>(scene.view, spec), ink, ramp);
  CHECK(ink == 0);
  CHECK(ramp == 0);
}

TEST_CASE("renderers survive an empty view and a non-finite level set", "[unit][render]") {
  RenderSpec spec;
  spec.size = {64, 48};
  const Image e2 = render_frame<2>(RenderView<2>{}, spec);
  const Image e3 = render_frame<3>(RenderView<3>{}, spec);
  CHECK(e2.width == 64);
  CHECK(e2.height == 48);
  CHECK(e3.width == 64);
  CHECK(e3.height == 48);
  TestScene<2> s2(8);
  TestScene<3> s3(8);
  s2.phi.setConstant(std::nan(""));
  s3.phi.setConstant(std::nan(""));
  const Image n2 = render_frame<2>(s2.view, spec);
  const Image n3 = render_frame<3>(s3.view, spec);
  CHECK(n2.rgb.size() == 64u * 48u * 3u);
  CHECK(n3.rgb.size() == 64u * 48u * 3u);
}

// --- 3D ---------------------------------------------------------------------------------------------

namespace {

int count_solid_pixels(const Image& img) {
  // pixels in the hue of the solid's colour (170, 140, 110): red > green > blue, clearly brown
  int n = 0;
  for (int j = 0; j < img.height; ++j)
    for (int i = 0; i < img.width; ++i) {
      const Rgb c = img.get(i, j);
      if (c[0] > c[1] + 12 && c[1] > c[2] + 12 && c[0] > 60) ++n;
    }
  return n;
}

}  // namespace

TEST_CASE("3D: the liquid ball covers the image centre and is shaded", "[unit][render]") {
  TestScene<3> scene(24);
  RenderSpec spec;
  spec.size = {160, 120};
  spec.color_by = ColorBy::none;
  const Image img = render_frame<3>(scene.view, spec);
  keep_picture(img, "render3d_none");
  REQUIRE(img.width == 160);
  REQUIRE(img.height == 120);
  const Rgb centre = img.get(80, 60);
  CHECK(centre[2] > centre[0] + 60);
  // shading: brightness varies across the ball (a window around the centre)
  int lo = 1000, hi = 0;
  for (int j = 45; j < 75; ++j)
    for (int i = 65; i < 95; ++i) {
      const Rgb c = img.get(i, j);
      if (c[2] > c[0] + 40) {
        lo = std::min(lo, brightness(c));
        hi = std::max(hi, brightness(c));
      }
    }
  CHECK(hi - lo > 60);
}

TEST_CASE("3D: a solid is visible, background elsewhere", "[unit][render]") {
  TestScene<3> scene(24);
  RenderSpec spec;
  spec.size = {160, 120};
  spec.color_by = ColorBy::none;
  scene.view.boundary.fill(BoundaryType::open);
  const Image with = render_frame<3>(scene.view, spec);
  keep_picture(with, "render3d_open");
  const int solid_pixels = count_solid_pixels(with);
  CHECK(solid_pixels > 50);
  const auto solids = scene.view.solids;
  scene.view.solids.clear();
  const Image without = render_frame<3>(scene.view, spec);
  CHECK(count_solid_pixels(without) < 5);
  // no walls: the image corners show the light sky
  for (const auto& [i, j] : {std::pair{3, 116}, std::pair{156, 116}, std::pair{156, 60}}) {
    const Rgb c = with.get(i, j);
    CHECK(brightness(c) > 520);
    CHECK(c[2] >= c[0]);
  }
  // with walls, the floor is drawn where the sky was below the ball
  scene.view.solids = solids;
  scene.view.boundary.fill(BoundaryType::wall);
  const Image walls = render_frame<3>(scene.view, spec);
  keep_picture(walls, "render3d_walls");
  int changed = 0;
  for (int j = 100; j < 120; ++j)
    for (int i = 0; i < 160; ++i) changed += color_distance(walls.get(i, j), with.get(i, j)) > 20;
  CHECK(changed > 200);
}

TEST_CASE("3D: color_by speed colours the liquid", "[unit][render]") {
  TestScene<3> scene(24);
  RenderSpec spec;
  spec.size = {160, 120};
  spec.color_by = ColorBy::none;
  const Image plain = render_frame<3>(scene.view, spec);
  spec.color_by = ColorBy::speed;
  const Image speed = render_frame<3>(scene.view, spec);
  keep_picture(speed, "render3d_speed");
  // the ball's top is fast (green-yellow in viridis), unlike plain water blue
  int differ = 0;
  for (int j = 30; j < 90; ++j)
    for (int i = 50; i < 110; ++i) differ += color_distance(plain.get(i, j), speed.get(i, j)) > 60;
  CHECK(differ > 300);
}

TEST_CASE("3D: the time is written in a corner", "[unit][render]") {
  TestScene<3> scene(12);
  RenderSpec spec;
  spec.size = {160, 120};
  spec.color_by = ColorBy::none;
  const Image a = render_frame<3>(scene.view, spec);
  scene.view.time = 7.5;
  const Image b = render_frame<3>(scene.view, spec);
  int diff_label = 0, diff_elsewhere = 0;
  for (int j = 0; j < 120; ++j)
    for (int i = 0; i < 160; ++i)
      if (a.get(i, j) != b.get(i, j)) (i < 80 && j < 20 ? diff_label : diff_elsewhere)++;
  CHECK(diff_label > 5);
  CHECK(diff_elsewhere == 0);
}

TEST_CASE("3D: deterministic for 1 and 2 threads", "[unit][render]") {
  TestScene<3> scene(16);
  RenderSpec spec;
  spec.size = {96, 72};
  omp_set_num_threads(1);
  const Image a = render_frame<3>(scene.view, spec);
  omp_set_num_threads(2);
  const Image b = render_frame<3>(scene.view, spec);
  const Image c = render_frame<3>(scene.view, spec);
  CHECK(a.rgb == b.rgb);
  CHECK(b.rgb == c.rgb);
}

TEST_CASE("3D: 512x512 of a 64^3 scene (timing)", "[.][benchmark][render]") {
  TestScene<3> scene(64);
  RenderSpec spec;
  spec.size = {512, 512};
  omp_set_num_threads(1);
  const auto start = std::chrono::steady_clock::now();
  const Image img = render_frame<3>(scene.view, spec);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  keep_picture(img, "render3d_512");
  WARN("render_frame<3> 512x512, 64^3, 1 thread: " << seconds << " s");
  CHECK(img.get(256, 256)[2] > 0);
  // a level set shaped like a particle reconstruction: a plateau of 1 dx away from the liquid
  // and shallow (-dx/3) in the bulk, so sphere tracing takes short steps everywhere
  const double dx = scene.grid.dx();
  scene.phi = scene.phi.cwiseMin(dx).cwiseMax(-dx / 3.0);
  const auto start2 = std::chrono::steady_clock::now();
  const Image capped = render_frame<3>(scene.view, spec);
  const double seconds2 = std::chrono::duration<double>(std::chrono::steady_clock::now() - start2).count();
  keep_picture(capped, "render3d_512_capped");
  WARN("render_frame<3> 512x512, 64^3, capped level set, 1 thread: " << seconds2 << " s");
  CHECK(capped.get(256, 256)[2] > capped.get(256, 256)[0]);
}

// --- a gallery for looking at (hidden: run with "[gallery]" and MONOLITH_TEST_PICTURES set) ------

TEST_CASE("gallery: dam-break-like pictures in 2D and 3D", "[.][gallery][render]") {
  const auto dam = [](const auto& x) {
    // a column of liquid in the left corner, united with a falling drop
    using V = std::decay_t<decltype(x)>;
    V q = x;
    q[0] -= 0.2;
    q[1] -= 0.3;
    V h = V::Constant(0.2);
    h[1] = 0.3;
    const V a = q.cwiseAbs() - h;
    const double column = a.cwiseMax(0.0).norm() + std::min(a.maxCoeff(), 0.0);
    V c = V::Constant(0.5);
    c[0] = 0.65;
    c[1] = 0.55;
    const double drop = (x - c).norm() - 0.1;
    return std::min(column, drop);
  };
  {
    TestScene<2> scene(64);
    const SampleLattice<2> lattice = half_lattice(scene.grid);
    for (int k = 0; k < lattice.size(); ++k) scene.phi[k] = dam(lattice.position(lattice.coord(k)));
    for (int k = 0; k < 40; ++k) scene.particles.push_back(Vec<2>(0.5 + 0.004 * k, 0.7 + 0.05 * std::sin(0.5 * k)));
    scene.view.particles = &scene.particles;
    scene.view.boundary[3] = BoundaryType::open;
    RenderSpec spec;
    spec.size = {640, 480};
    for (const ColorBy by : {ColorBy::none, ColorBy::speed, ColorBy::pressure}) {
      spec.color_by = by;
      const Image img = render_frame<2>(scene.view, spec);
      keep_picture(img, std::string("gallery2d_") + enum_name(by));
      CHECK(img.width == 640);
    }
  }
  {
    TestScene<3> scene(64);
    const SampleLattice<3> lattice = half_lattice(scene.grid);
    for (int k = 0; k < lattice.size(); ++k) scene.phi[k] = dam(lattice.position(lattice.coord(k)));
    scene.view.solids[0].shape = std::make_shared<TestBall<3>>(Vec<3>(0.75, 0.15, 0.6), 0.12);
    scene.view.boundary[3] = BoundaryType::open;
    RenderSpec spec;
    spec.size = {640, 480};
    for (const ColorBy by : {ColorBy::none, ColorBy::speed, ColorBy::pressure}) {
      spec.color_by = by;
      const auto start = std::chrono::steady_clock::now();
      const Image img = render_frame<3>(scene.view, spec);
      const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      WARN("3D gallery " << enum_name(by) << ": " << seconds << " s");
      keep_picture(img, std::string("gallery3d_") + enum_name(by));
      CHECK(img.width == 640);
    }
  }
}

// --- built-in scenes at t = 0 (hidden: run with "[gallery]"): the shapes of make_shape ---------

namespace {

template <int Dim>
void render_initial_scene(const SceneFile& desc) {
  VecI<Dim> cells;
  Vec<Dim> lower;
  std::array<bool, Dim> periodic{};
  for (int a = 0; a < Dim; ++a) {
    cells[a] = desc.domain.cells[a];
    lower[a] = desc.domain.lower[a];
    periodic[a] = desc.domain.boundary[2 * a] == BoundaryType::periodic;
  }
  const MacGrid<Dim> grid(lower, desc.dx(), cells, periodic);
  const SampleLattice<Dim> lattice = half_lattice(grid);
  std::vector<ShapePtr<Dim>> liquids;
  for (size_t k = 0; k < desc.liquids.size(); ++k)
    liquids.push_back(make_shape<Dim>(desc.liquids[k].shape, "liquids"));
  VectorX phi(lattice.size());
  for (int k = 0; k < lattice.size(); ++k) {
    double d = 1e9;
    for (const auto& s : liquids) d = std::min(d, s->distance(lattice.position(lattice.coord(k))));
    phi[k] = d;
  }
  RenderView<Dim> view;
  view.grid = &grid;
  view.liquid_phi = &phi;
  for (int f = 0; f < 2 * Dim; ++f) view.boundary[f] = desc.domain.boundary[f];
  for (const BodySpec& b : desc.bodies) view.solids.push_back({make_shape<Dim>(b.shape, "bodies"), Rgb{170, 140, 110}});
  RenderSpec spec = desc.render;
  spec.color_by = ColorBy::none;
  const auto start = std::chrono::steady_clock::now();
  const Image img = render_frame<Dim>(view, spec);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  WARN(desc.name << ": " << seconds << " s");
  keep_picture(img, "scene_" + desc.name);
  CHECK(img.width == spec.size[0]);
}

}  // namespace

TEST_CASE("gallery: built-in scenes at t = 0", "[.][gallery][render]") {
  for (const EmbeddedFile& f : embedded_scenes()) {
    const SceneFile desc = load_scene(std::string(f.name), {});
    if (desc.dim == 2)
      render_initial_scene<2>(desc);
    else
      render_initial_scene<3>(desc);
  }
}
