// Tests of the PPM line plots and the raster toolkit of reference/viz/plot.hpp.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "reference/viz/plot.hpp"

using namespace monolith;

namespace {

bool dark(Rgb c) { return c[0] < 90 && c[1] < 90 && c[2] < 90; }

// distance in colour space
int color_distance(Rgb a, Rgb b) {
  return std::abs(a[0] - b[0]) + std::abs(a[1] - b[1]) + std::abs(a[2] - b[2]);
}

// true if some pixel within `r` of (x, y) is close to colour c
bool near_color(const Image& img, double x, double y, Rgb c, int r = 1, int tol = 60) {
  const int cx = static_cast<int>(std::floor(x)), cy = static_cast<int>(std::floor(y));
  for (int j = cy - r; j <= cy + r; ++j)
    for (int i = cx - r; i <= cx + r; ++i)
      if (i >= 0 && j >= 0 && i < img.width && j < img.height && color_distance(img.get(i, j), c) <= tol)
        return true;
  return false;
}

// writes the image where MONOLITH_TEST_PICTURES points (for looking at it), if set
void keep_picture(const Image& img, const std::string& name) {
  if (const char* dir = std::getenv("MONOLITH_TEST_PICTURES")) {
    std::filesystem::create_directories(dir);
    img.write_ppm(std::string(dir) + "/" + name + ".ppm");
  }
}

PlotSpec line_spec() {
  PlotSpec spec;
  spec.title = "Test plot";
  spec.x_label = "x";
  spec.y_label = "y";
  PlotSeries s;
  s.label = "y = 2x";
  s.x = {0.0, 1.0, 2.0, 3.0, 4.0};
  s.y = {0.0, 2.0, 4.0, 6.0, 8.0};
  s.color = Rgb{200, 20, 20};
  spec.series.push_back(s);
  spec.legend = false;
  return spec;
}

}  // namespace

TEST_CASE("text is drawn with the built-in font", "[unit]") {
  Image img(80, 20, Rgb{255, 255, 255});
  draw_text(img, 2, 2, "t=1.25 s", Rgb{0, 0, 0}, 1);
  int ink = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) ink += dark(img.get(x, y));
  CHECK(ink > 40);
  CHECK(text_width("t=1.25 s", 1) == 8 * 6 - 1);
  CHECK(text_width("12", 2) == 22);
  // nothing is drawn right of the text block
  for (int y = 0; y < img.height; ++y)
    for (int x = 2 + text_width("t=1.25 s", 1); x < img.width; ++x) CHECK_FALSE(dark(img.get(x, y)));
  // a '1' has its stem in the middle column
  Image one(7, 9, Rgb{255, 255, 255});
  draw_text(one, 1, 1, "1", Rgb{0, 0, 0}, 1);
  for (int r = 0; r < 7; ++r) CHECK(dark(one.get(1 + 2, 1 + r)));
}

TEST_CASE("numbers are formatted compactly", "[unit]") {
  CHECK(format_number(0.0) == "0");
  CHECK(format_number(0.25) == "0.25");
  CHECK(format_number(12.5) == "12.5");
  CHECK(format_number(-3.0) == "-3");
  CHECK(format_number(1.5e-4) == "1.5e-04");
  CHECK(format_number(2e6) == "2e+06");
  CHECK(format_number(1.23456) == "1.23");
}

TEST_CASE("percentile picks the nearest rank and skips non-finite values", "[unit]") {
  std::vector<double> v;
  for (int i = 0; i <= 100; ++i) v.push_back(i);
  v.push_back(std::nan(""));
  CHECK(percentile(v, 0.99) == Approx(99.0));
  CHECK(percentile(v, 0.0) == Approx(0.0));
  CHECK(percentile(v, 1.0) == Approx(100.0));
  CHECK(percentile({}, 0.5) == 0.0);
}

TEST_CASE("anti-aliased line covers its pixels and nothing far away", "[unit]") {
  Image img(40, 40, Rgb{255, 255, 255});
  draw_line(img, 5.0, 20.0, 35.0, 20.0, Rgb{0, 0, 0}, 2.0);
  CHECK(dark(img.get(20, 19)));
  CHECK(dark(img.get(20, 20)));
  CHECK(img.get(20, 23) == (Rgb{255, 255, 255}));
  CHECK(img.get(2, 20) == (Rgb{255, 255, 255}));
}

TEST_CASE("plot has a frame and axes", "[unit]") {
  const PlotSpec spec = line_spec();
  const Image img = plot_lines(spec);
  keep_picture(img, "plot_linear");
  REQUIRE(img.width == spec.width);
  REQUIRE(img.height == spec.height);
  const PlotAxes ax = plot_axes(spec);
  REQUIRE(ax.left > 0);
  REQUIRE(ax.right < img.width);
  REQUIRE(ax.top > 0);
  REQUIRE(ax.bottom < img.height);
  // the left and bottom axis lines are dark along their whole length
  for (int y = ax.top; y < ax.bottom; y += 7) CHECK(dark(img.get(ax.left - 1, y)));
  for (int x = ax.left; x < ax.right; x += 7) CHECK(dark(img.get(x, ax.bottom)));
  // tick labels: some dark pixels left of the y axis and below the x axis
  int left_ink = 0, below_ink = 0;
  for (int y = ax.top; y < ax.bottom; ++y)
    for (int x = 0; x < ax.left - 8; ++x) left_ink += dark(img.get(x, y));
  for (int y = ax.bottom + 6; y < img.height; ++y)
    for (int x = ax.left; x < ax.right; ++x) below_ink += dark(img.get(x, y));
  CHECK(left_ink > 30);
  CHECK(below_ink > 30);
}

TEST_CASE("a line series passes through the expected pixels", "[unit]") {
  const PlotSpec spec = line_spec();
  const Image img = plot_lines(spec);
  const PlotAxes ax = plot_axes(spec);
  const Rgb red{200, 20, 20};
  for (double x = 0.0; x <= 4.0; x += 0.125) CHECK(near_color(img, ax.px(x), ax.py(2.0 * x), red));
  // and not through points off the line
  CHECK_FALSE(near_color(img, ax.px(1.0), ax.py(6.0), red, 2));
  CHECK_FALSE(near_color(img, ax.px(3.0), ax.py(1.0), red, 2));
}

TEST_CASE("log axes map decades evenly", "[unit]") {
  PlotSpec spec;
  spec.log_x = true;
  spec.log_y = true;
  spec.title = "Convergence";
  spec.x_label = "cells";
  spec.y_label = "error";
  PlotSeries s;
  s.label = "first order";
  s.marker = Marker::circle;
  for (double n : {1.0, 10.0, 100.0, 1000.0}) {
    s.x.push_back(n);
    s.y.push_back(1.0 / n);
  }
  s.color = Rgb{0, 90, 200};
  spec.series.push_back(s);
  PlotSeries t;
  t.label = "second order";
  t.dash = 8.0;
  for (double n : {1.0, 10.0, 100.0, 1000.0}) {
    t.x.push_back(n);
    t.y.push_back(1.0 / (n * n) + 1e-7);
  }
  spec.series.push_back(t);
  const PlotAxes ax = plot_axes(spec);
  const double d1 = ax.px(10.0) - ax.px(1.0), d2 = ax.px(100.0) - ax.px(10.0),
               d3 = ax.px(1000.0) - ax.px(100.0);
  CHECK(d1 > 10.0);
  CHECK(d2 == Approx(d1));
  CHECK(d3 == Approx(d1));
  const double e1 = ax.py(1e-1) - ax.py(1.0), e2 = ax.py(1e-2) - ax.py(1e-1);
  CHECK(e1 > 10.0);
  CHECK(e2 == Approx(e1));
  // half a decade sits at log10(sqrt(10)) = 1/2 of the way
  CHECK(ax.px(std::sqrt(10.0)) - ax.px(1.0) == Approx(0.5 * d1));
  const Image img = plot_lines(spec);
  keep_picture(img, "plot_log");
  // the straight line y = 1/x in log-log passes through its mid points
  const Rgb blue{0, 90, 200};
  CHECK(near_color(img, ax.px(std::sqrt(10.0)), ax.py(1.0 / std::sqrt(10.0)), blue));
  CHECK(near_color(img, ax.px(300.0), ax.py(1.0 / 300.0), blue));
  // major ticks at the decades on the x axis
  // (a 1-pixel tick at a fractional position shares its ink between two columns)
  for (double n : {1.0, 10.0, 100.0, 1000.0}) CHECK(near_color(img, ax.px(n), ax.bottom + 3.5, Rgb{30, 30, 36}, 1, 200));
}

TEST_CASE("plot is deterministic and writes a readable PPM", "[unit]") {
  const PlotSpec spec = line_spec();
  const Image a = plot_lines(spec), b = plot_lines(spec);
  CHECK(a.rgb == b.rgb);
  const std::string path = (std::filesystem::temp_directory_path() / "monolith_test_plot.ppm").string();
  write_plot(spec, path);
  const Image c = Image::read_ppm(path);
  CHECK(c.rgb == a.rgb);
  std::filesystem::remove(path);
}

TEST_CASE("legend lists the labelled series in their colours", "[unit]") {
  PlotSpec spec;
  spec.title = "Martin & Moyce (1952): surge front";
  spec.x_label = "T = t sqrt(2g/a)";
  spec.y_label = "Z = z/a";
  PlotSeries exp;
  exp.label = "experiment";
  exp.line = false;
  exp.marker = Marker::square;
  exp.color = Rgb{20, 20, 20};
  PlotSeries sim;
  sim.label = "simulation";
  sim.color = Rgb{0, 150, 60};
  for (int k = 0; k <= 10; ++k) {
    exp.x.push_back(0.3 * k);
    exp.y.push_back(1.0 + 0.25 * k * k * 0.1);
    sim.x.push_back(0.3 * k);
    sim.y.push_back(1.0 + 0.24 * k * k * 0.1);
  }
  PlotSeries unlisted;
  unlisted.x = {0.0, 3.0};
  unlisted.y = {1.0, 1.0};
  unlisted.color = Rgb{250, 0, 250};
  spec.series = {exp, sim, unlisted};
  const Image img = plot_lines(spec);
  keep_picture(img, "plot_legend");
  const PlotAxes ax = plot_axes(spec);
  // the legend avoids the data, so it sits top-left here: count series colours there
  int green = 0, magenta_in_legend = 0;
  const int x0 = ax.left, y1 = ax.top + (ax.bottom - ax.top) / 3;
  const int x1 = ax.left + (ax.right - ax.left) / 2;
  for (int y = ax.top; y < y1; ++y)
    for (int x = x0; x < x1; ++x) {
      green += color_distance(img.get(x, y), Rgb{0, 150, 60}) < 40;
      magenta_in_legend += color_distance(img.get(x, y), Rgb{250, 0, 250}) < 40;
    }
  CHECK(green > 10);
  CHECK(magenta_in_legend == 0);
  spec.legend = false;
  const Image bare = plot_lines(spec);
  CHECK(bare.rgb != img.rgb);
}

TEST_CASE("colour scales: active for the fields over liquid, inactive without liquid", "[unit]") {
  const std::vector<double> speeds{0.0, 0.5, 1.0, 2.0};
  for (const ColorBy field : {ColorBy::speed, ColorBy::viscosity, ColorBy::pressure}) {
    INFO(enum_name(field));
    const ColorScale scale = make_color_scale(field, speeds);
    CHECK(scale.active);
    CHECK(scale.hi > scale.lo);
    // a picture without liquid (rigid bodies only) gets no colour bar
    CHECK_FALSE(make_color_scale(field, {}).active);
  }
  CHECK_FALSE(make_color_scale(ColorBy::none, speeds).active);
}
