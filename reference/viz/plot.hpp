#pragma once
/// \file plot.hpp
/// Line plots written as PPM (the project draws its own figures: no plotting library), and the
/// small raster toolkit they share with the frame renderers: a built-in 5x7 pixel font,
/// anti-aliased lines and disks, rectangles, colour bars and number formatting.

#include <optional>
#include <string>
#include <vector>

#include "reference/viz/image.hpp"
#include "reference/viz/render_spec.hpp"

namespace monolith {

// --- text: a built-in 5x7 pixel font (digits, letters, common punctuation) ---------------------

/// Width in pixels of `text` at integer magnification `scale` (6 scale per character, less the
/// trailing gap).
int text_width(const std::string& text, int scale = 1);
/// Height of a line of text above the baseline (7 scale); descenders add 2 scale below it.
int text_height(int scale = 1);
/// Draws `text` with its top-left corner at (x, y). Characters without a glyph draw as a box.
void draw_text(Image& img, int x, int y, const std::string& text, Rgb color, int scale = 1);
/// Draws `text` rotated a quarter turn counter-clockwise (read bottom to top); (x, y) is the
/// top-left corner of the rotated block, which is text_height wide and text_width tall.
void draw_text_vertical(Image& img, int x, int y, const std::string& text, Rgb color, int scale = 1);

// --- shapes (anti-aliased, pixel centres at integer + 1/2) -------------------------------------

/// A line segment of the given width (pixels) from (x0, y0) to (x1, y1), in image coordinates
/// (y down); coverage from the distance of each pixel centre to the segment.
void draw_line(Image& img, double x0, double y0, double x1, double y1, Rgb color,
               double width = 1.0, double alpha = 1.0);
/// A dashed segment: `dash` pixels drawn, `gap` pixels skipped, starting with a dash.
void draw_dashed_line(Image& img, double x0, double y0, double x1, double y1, Rgb color,
                      double width, double dash, double gap, double alpha = 1.0);
/// A filled disk of radius r pixels centred at (cx, cy).
void fill_disk(Image& img, double cx, double cy, double r, Rgb color, double alpha = 1.0);
/// Fills the pixels x0 <= x < x1, y0 <= y < y1 (clipped to the image).
void fill_rect(Image& img, int x0, int y0, int x1, int y1, Rgb color, double alpha = 1.0);

// --- numbers and colour scales ------------------------------------------------------------------

/// The simulation-time label "t=1.234 s" (dark text on a light panel) with its top-left corner
/// at (x, y), font magnified by `scale`; used by both frame renderers.
void draw_time_label(Image& img, double time, int x, int y, int scale);

/// A short label for v with about `digits` significant digits: "0", "0.25", "12.5", "-3",
/// "1.5e-04", "2e+06" (exponent form outside [1e-3, 1e5)).
std::string format_number(double v, int digits = 3);
/// The q-quantile (q in [0, 1]) of the finite values, by nearest rank; 0 for an empty list.
double percentile(std::vector<double> values, double q);
/// A horizontal colour bar at (x, y) of size w x h with `map` from lo (left) to hi (right), a
/// thin dark frame, the end values printed below it and `label` to its left when not empty.
/// Returns the height used, labels included.
int draw_color_bar(Image& img, int x, int y, int w, int h, Rgb (*map)(double), double lo,
                   double hi, const std::string& label, int scale = 1);

/// How the renderers colour the liquid for RenderSpec::color_by.
struct ColorScale {
  bool active = false;            ///< false: the plain liquid colour (color_by none, or no field)
  Rgb (*map)(double) = nullptr;   ///< colormap_viridis or colormap_coolwarm
  double lo = 0.0, hi = 1.0;      ///< field values mapped to the ends of the colour map
  std::string label;              ///< colour bar caption, e.g. "|u| (m/s)"
  Rgb color(double v) const { return map(hi > lo ? (v - lo) / (hi - lo) : 0.5); }
};
/// The colour scale for color_by (speed, pressure, viscosity; none, or no values (no liquid in
/// the picture), gives an inactive scale) from the field's values over the liquid: speed and viscosity map [0, p99]
/// with viridis (p99 = 99th percentile, robust to a few fast spray samples); pressure maps
/// [p1, p99] with coolwarm, symmetric about zero when the range contains zero.
ColorScale make_color_scale(ColorBy color_by, const std::vector<double>& values);

// --- line plots -------------------------------------------------------------------------------

enum class Marker { none, circle, square, cross };

struct PlotSeries {
  std::string label;             ///< legend text; series with an empty label are not listed
  std::vector<double> x, y;      ///< equal lengths; non-finite points break the line
  std::optional<Rgb> color;      ///< default: plot_palette(series index)
  bool line = true;              ///< join consecutive points
  double line_width = 2.0;       ///< pixels
  double dash = 0.0;             ///< dash length in pixels; 0 = solid
  Marker marker = Marker::none;
  double marker_size = 4.0;      ///< radius in pixels
};

struct PlotSpec {
  std::string title, x_label, y_label;
  std::vector<PlotSeries> series;
  int width = 720, height = 480;
  bool log_x = false, log_y = false;
  /// Axis ranges; unset ends are taken from the data (padded by 4% on linear axes).
  std::optional<double> x_min, x_max, y_min, y_max;
  bool legend = true;
  bool grid = true;              ///< light grid lines at the major ticks
  int font_scale = 0;            ///< 0: chosen from the image size
};

/// Where the data rectangle of a plot lies in the image and how data maps onto it.
struct PlotAxes {
  int left = 0, top = 0, right = 0, bottom = 0;  ///< pixel bounds of the data rectangle
  double x0 = 0, x1 = 1, y0 = 0, y1 = 1;         ///< data range shown (not logarithms)
  bool log_x = false, log_y = false;
  /// Image x coordinate (continuous; pixel centres at integer + 1/2) of data value x.
  double px(double x) const;
  /// Image y coordinate (y down) of data value y.
  double py(double y) const;
};

/// The default series colours (a colour-blind-friendly cycle of 8).
Rgb plot_palette(int index);
/// The layout and data ranges plot_lines uses for spec.
PlotAxes plot_axes(const PlotSpec& spec);
/// Draws the plot: frame, ticks with numeric labels, optional grid, the series (lines and/or
/// markers), title, axis labels and legend (in the corner of the data rectangle that covers the
/// fewest data samples).
Image plot_lines(const PlotSpec& spec);
/// plot_lines(spec).write_ppm(path).
void write_plot(const PlotSpec& spec, const std::string& path);

}  // namespace monolith
