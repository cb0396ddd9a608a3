#include "reference/viz/plot.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>

namespace monolith {

namespace {

// --- the 5x7 font: 7 rows of 5 columns ('#' = ink); g j p q y have two more rows of descent ----
struct Glyph {
  char c;
  const char* rows;  // 35 or 45 characters
};

const Glyph kGlyphs[] = {
    {'0', ".###." "#...#" "#..##" "#.#.#" "##..#" "#...#" ".###."},
    {'1', "..#.." ".##.." "..#.." "..#.." "..#.." "..#.." ".###."},
    {'2', ".###." "#...#" "....#" "...#." "..#.." ".#..." "#####"},
    {'3', ".###." "#...#" "....#" "..##." "....#" "#...#" ".###."},
    {'4', "...#." "..##." ".#.#." "#..#." "#####" "...#." "...#."},
    {'5', "#####" "#...." "####." "....#" "....#" "#...#" ".###."},
    {'6', "..##." ".#..." "#...." "####." "#...#" "#...#" ".###."},
    {'7', "#####" "....#" "...#." "..#.." ".#..." ".#..." ".#..."},
    {'8', ".###." "#...#" "#...#" ".###." "#...#" "#...#" ".###."},
    {'9', ".###." "#...#" "#...#" ".####" "....#" "...#." ".##.."},
    {' ', "....." "....." "....." "....." "....." "....." "....."},
    {'.', "....." "....." "....." "....." "....." ".##.." ".##.."},
    {',', "....." "....." "....." "....." ".##.." "..#.." ".#..."},
    {'-', "....." "....." "....." ".####" "....." "....." "....."},
    {'+', "....." "..#.." "..#.." "#####" "..#.." "..#.." "....."},
    {'=', "....." "....." "#####" "....." "#####" "....." "....."},
    {':', "....." ".##.." ".##.." "....." ".##.." ".##.." "....."},
    {'(', "...#." "..#.." ".#..." ".#..." ".#..." "..#.." "...#."},
    {')', ".#..." "..#.." "...#." "...#." "...#." "..#.." ".#..."},
    {'[', ".###." ".#..." ".#..." ".#..." ".#..." ".#..." ".###."},
    {']', ".###." "...#." "...#." "...#." "...#." "...#." ".###."},
    {'/', "....." "....#" "...#." "..#.." ".#..." "#...." "....."},
    {'%', "##..." "##..#" "...#." "..#.." ".#..." "#..##" "...##"},
    {'_', "....." "....." "....." "....." "....." "....." "#####"},
    {'\'', "..#.." "..#.." ".#..." "....." "....." "....." "....."},
    {'&', ".##.." "#..#." "#.#.." ".#..." "#.#.#" "#..#." ".##.#"},
    {'^', "..#.." ".#.#." "#...#" "....." "....." "....." "....."},
    {'*', "....." "..#.." "#.#.#" ".###." "#.#.#" "..#.." "....."},
    {'|', "..#.." "..#.." "..#.." "..#.." "..#.." "..#.." "..#.."},
    {'<', "...#." "..#.." ".#..." "#...." ".#..." "..#.." "...#."},
    {'>', ".#..." "..#.." "...#." "....#" "...#." "..#.." ".#..."},
    {'!', "..#.." "..#.." "..#.." "..#.." "..#.." "....." "..#.."},
    {'?', ".###." "#...#" "....#" "...#." "..#.." "....." "..#.."},
    {'#', ".#.#." ".#.#." "#####" ".#.#." "#####" ".#.#." ".#.#."},
    {'A', ".###." "#...#" "#...#" "#####" "#...#" "#...#" "#...#"},
    {'B', "####." "#...#" "#...#" "####." "#...#" "#...#" "####."},
    {'C', ".###." "#...#" "#...." "#...." "#...." "#...#" ".###."},
    {'D', "###.." "#..#." "#...#" "#...#" "#...#" "#..#." "###.."},
    {'E', "#####" "#...." "#...." "####." "#...." "#...." "#####"},
    {'F', "#####" "#...." "#...." "####." "#...." "#...." "#...."},
    {'G', ".###." "#...#" "#...." "#.###" "#...#" "#...#" ".####"},
    {'H', "#...#" "#...#" "#...#" "#####" "#...#" "#...#" "#...#"},
    {'I', ".###." "..#.." "..#.." "..#.." "..#.." "..#.." ".###."},
    {'J', "..###" "...#." "...#." "...#." "...#." "#..#." ".##.."},
    {'K', "#...#" "#..#." "#.#.." "##..." "#.#.." "#..#." "#...#"},
    {'L', "#...." "#...." "#...." "#...." "#...." "#...." "#####"},
    {'M', "#...#" "##.##" "#.#.#" "#.#.#" "#...#" "#...#" "#...#"},
    {'N', "#...#" "#...#" "##..#" "#.#.#" "#..##" "#...#" "#...#"},
    {'O', ".###." "#...#" "#...#" "#...#" "#...#" "#...#" ".###."},
    {'P', "####." "#...#" "#...#" "####." "#...." "#...." "#...."},
    {'Q', ".###." "#...#" "#...#" "#...#" "#.#.#" "#..#." ".##.#"},
    {'R', "####." "#...#" "#...#" "####." "#.#.." "#..#." "#...#"},
    {'S', ".####" "#...." "#...." ".###." "....#" "....#" "####."},
    {'T', "#####" "..#.." "..#.." "..#.." "..#.." "..#.." "..#.."},
    {'U', "#...#" "#...#" "#...#" "#...#" "#...#" "#...#" ".###."},
    {'V', "#...#" "#...#" "#...#" "#...#" "#...#" ".#.#." "..#.."},
    {'W', "#...#" "#...#" "#...#" "#.#.#" "#.#.#" "#.#.#" ".#.#."},
    {'X', "#...#" "#...#" ".#.#." "..#.." ".#.#." "#...#" "#...#"},
    {'Y', "#...#" "#...#" ".#.#." "..#.." "..#.." "..#.." "..#.."},
    {'Z', "#####" "....#" "...#." "..#.." ".#..." "#...." "#####"},
    {'a', "....." "....." ".###." "....#" ".####" "#...#" ".####"},
    {'b', "#...." "#...." "####." "#...#" "#...#" "#...#" "####."},
    {'c', "....." "....." ".###." "#...." "#...." "#...#" ".###."},
    {'d', "....#" "....#" ".####" "#...#" "#...#" "#...#" ".####"},
    {'e', "....." "....." ".###." "#...#" "#####" "#...." ".###."},
    {'f', "..##." ".#..#" ".#..." "###.." ".#..." ".#..." ".#..."},
    {'g', "....." "....." ".####" "#...#" "#...#" "#...#" ".####" "....#" ".###."},
    {'h', "#...." "#...." "#.##." "##..#" "#...#" "#...#" "#...#"},
    {'i', "..#.." "....." ".##.." "..#.." "..#.." "..#.." ".###."},
    {'j', "...#." "....." "..##." "...#." "...#." "...#." "...#." "#..#." ".##.."},
    {'k', "#...." "#...." "#..#." "#.#.." "##..." "#.#.." "#..#."},
    {'l', ".##.." "..#.." "..#.." "..#.." "..#.." "..#.." ".###."},
    {'m', "....." "....." "##.#." "#.#.#" "#.#.#" "#.#.#" "#.#.#"},
    {'n', "....." "....." "#.##." "##..#" "#...#" "#...#" "#...#"},
    {'o', "....." "....." ".###." "#...#" "#...#" "#...#" ".###."},
    {'p', "....." "....." "####." "#...#" "#...#" "#...#" "####." "#...." "#...."},
    {'q', "....." "....." ".####" "#...#" "#...#" "#...#" ".####" "....#" "....#"},
    {'r', "....." "....." "#.##." "##..#" "#...." "#...." "#...."},
    {'s', "....." "....." ".####" "#...." ".###." "....#" "####."},
    {'t', ".#..." ".#..." "###.." ".#..." ".#..." ".#..#" "..##."},
    {'u', "....." "....." "#...#" "#...#" "#...#" "#..##" ".##.#"},
    {'v', "....." "....." "#...#" "#...#" "#...#" ".#.#." "..#.."},
    {'w', "....." "....." "#...#" "#...#" "#.#.#" "#.#.#" ".#.#."},
    {'x', "....." "....." "#...#" ".#.#." "..#.." ".#.#." "#...#"},
    {'y', "....." "....." "#...#" "#...#" "#...#" "#...#" ".####" "....#" ".###."},
    {'z', "....." "....." "#####" "...#." "..#.." ".#..." "#####"},
};

const char* glyph_rows(char c) {
  for (const Glyph& g : kGlyphs)
    if (g.c == c) return g.rows;
  return nullptr;
}

// ink of glyph row r, column k (an unknown character is an outlined box)
bool glyph_ink(const char* rows, int r, int k) {
  if (!rows) return r < 7 && (r == 0 || r == 6 || k == 0 || k == 4);
  const int n = static_cast<int>(std::char_traits<char>::length(rows)) / 5;
  return r < n && rows[r * 5 + k] == '#';
}

double clamp01(double v) { return std::clamp(v, 0.0, 1.0); }

// distance from point p to segment a-b
double segment_distance(double px, double py, double ax, double ay, double bx, double by) {
  const double vx = bx - ax, vy = by - ay;
  const double len2 = vx * vx + vy * vy;
  double t = len2 > 0.0 ? ((px - ax) * vx + (py - ay) * vy) / len2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  const double dx = px - (ax + t * vx), dy = py - (ay + t * vy);
  return std::sqrt(dx * dx + dy * dy);
}

}  // namespace

// --- text -----------------------------------------------------------------------------------------

int text_width(const std::string& text, int scale) {
  if (text.empty()) return 0;
  return (6 * static_cast<int>(text.size()) - 1) * scale;
}

int text_height(int scale) { return 7 * scale; }

void draw_text(Image& img, int x, int y, const std::string& text, Rgb color, int scale) {
  for (size_t i = 0; i < text.size(); ++i) {
    const char* rows = glyph_rows(text[i]);
    const int gx = x + static_cast<int>(i) * 6 * scale;
    for (int r = 0; r < 9; ++r)
      for (int k = 0; k < 5; ++k)
        if (glyph_ink(rows, r, k))
          fill_rect(img, gx + k * scale, y + r * scale, gx + (k + 1) * scale, y + (r + 1) * scale,
                    color);
  }
}

void draw_text_vertical(Image& img, int x, int y, const std::string& text, Rgb color, int scale) {
  // glyph pixel (column k, row r) of character i goes to (x + r, y + total - 1 - (6 i + k))
  const int total = text_width(text, 1);
  for (size_t i = 0; i < text.size(); ++i) {
    const char* rows = glyph_rows(text[i]);
    for (int r = 0; r < 9; ++r)
      for (int k = 0; k < 5; ++k)
        if (glyph_ink(rows, r, k)) {
          const int px = x + r * scale;
          const int py = y + (total - 1 - (6 * static_cast<int>(i) + k)) * scale;
          fill_rect(img, px, py, px + scale, py + scale, color);
        }
  }
}

// --- shapes -------------------------------------------------------------------------------------

void draw_line(Image& img, double x0, double y0, double x1, double y1, Rgb color, double width,
               double alpha) {
  if (!std::isfinite(x0) || !std::isfinite(y0) || !std::isfinite(x1) || !std::isfinite(y1)) return;
  // visit the pixels of the segment's bounding box grown by the half width, clipped to the image
  const double pad = 0.5 * width + 1.0;
  const int xa = std::max(0, static_cast<int>(std::floor(std::min(x0, x1) - pad)));
  const int xb = std::min(img.width - 1, static_cast<int>(std::ceil(std::max(x0, x1) + pad)));
  const int ya = std::max(0, static_cast<int>(std::floor(std::min(y0, y1) - pad)));
  const int yb = std::min(img.height - 1, static_cast<int>(std::ceil(std::max(y0, y1) + pad)));
  if (xa > xb || ya > yb) return;
  const double len = std::hypot(x1 - x0, y1 - y0);
  const bool steep = std::abs(y1 - y0) > std::abs(x1 - x0);
  // iterate along the major axis and only a band across it (long lines stay cheap)
  const int major_a = steep ? ya : xa, major_b = steep ? yb : xb;
  for (int m = major_a; m <= major_b; ++m) {
    const double mc = m + 0.5;
    double cross_center;
    if (len == 0.0) {
      cross_center = steep ? x0 : y0;
    } else if (steep) {
      const double t = std::clamp((mc - y0) / (y1 - y0), 0.0, 1.0);
      cross_center = x0 + t * (x1 - x0);
    } else {
      const double t = std::clamp((mc - x0) / (x1 - x0), 0.0, 1.0);
      cross_center = y0 + t * (y1 - y0);
    }
    const double slope = len == 0.0 ? 0.0 : (steep ? std::abs((x1 - x0) / (y1 - y0))
                                                   : std::abs((y1 - y0) / (x1 - x0)));
    const double reach = pad * std::sqrt(1.0 + slope * slope) + 1.0;
    const int ca = static_cast<int>(std::floor(cross_center - reach));
    const int cb = static_cast<int>(std::ceil(cross_center + reach));
    for (int c = ca; c <= cb; ++c) {
      const int px = steep ? c : m, py = steep ? m : c;
      if (px < xa || px > xb || py < ya || py > yb) continue;
      const double d = segment_distance(px + 0.5, py + 0.5, x0, y0, x1, y1);
      const double cover = clamp01(0.5 * width + 0.5 - d);
      if (cover > 0.0) img.blend(px, py, color, alpha * cover);
    }
  }
}

void draw_dashed_line(Image& img, double x0, double y0, double x1, double y1, Rgb color,
                      double width, double dash, double gap, double alpha) {
  const double len = std::hypot(x1 - x0, y1 - y0);
  if (dash <= 0.0 || len == 0.0) {
    draw_line(img, x0, y0, x1, y1, color, width, alpha);
    return;
  }
  const double ux = (x1 - x0) / len, uy = (y1 - y0) / len;
  for (double s = 0.0; s < len; s += dash + gap) {
    const double e = std::min(len, s + dash);
    draw_line(img, x0 + s * ux, y0 + s * uy, x0 + e * ux, y0 + e * uy, color, width, alpha);
  }
}

void fill_disk(Image& img, double cx, double cy, double r, Rgb color, double alpha) {
  const int xa = static_cast<int>(std::floor(cx - r - 1)), xb = static_cast<int>(std::ceil(cx + r + 1));
  const int ya = static_cast<int>(std::floor(cy - r - 1)), yb = static_cast<int>(std::ceil(cy + r + 1));
  for (int y = std::max(0, ya); y <= std::min(img.height - 1, yb); ++y)
    for (int x = std::max(0, xa); x <= std::min(img.width - 1, xb); ++x) {
      const double d = std::hypot(x + 0.5 - cx, y + 0.5 - cy);
      const double cover = clamp01(r + 0.5 - d);
      if (cover > 0.0) img.blend(x, y, color, alpha * cover);
    }
}

void fill_rect(Image& img, int x0, int y0, int x1, int y1, Rgb color, double alpha) {
  x0 = std::max(x0, 0);
  y0 = std::max(y0, 0);
  x1 = std::min(x1, img.width);
  y1 = std::min(y1, img.height);
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) {
      if (alpha >= 1.0)
        img.set(x, y, color);
      else
        img.blend(x, y, color, alpha);
    }
}

// --- numbers and colour scales ----------------------------------------------------------------------

std::string format_number(double v, int digits) {
  if (!std::isfinite(v)) return v != v ? "nan" : (v > 0 ? "inf" : "-inf");
  if (v == 0.0) return "0";
  char buf[64];
  const double a = std::abs(v);
  if (a >= 1e-3 && a < 1e5) {
    // fixed notation with `digits` significant digits, trailing zeros removed
    const int magnitude = static_cast<int>(std::floor(std::log10(a)));
    const int decimals = std::max(0, digits - 1 - magnitude);
    std::snprintf(buf, sizeof(buf), "%.*f", decimals, v);
    std::string s = buf;
    if (s.find('.') != std::string::npos) {
      while (s.back() == '0') s.pop_back();
      if (s.back() == '.') s.pop_back();
    }
    return s == "-0" ? "0" : s;
  }
  std::snprintf(buf, sizeof(buf), "%.*e", std::max(0, digits - 1), v);
  std::string s = buf;
  // drop trailing zeros of the mantissa: 1.50e-04 -> 1.5e-04
  const size_t e = s.find('e');
  std::string mant = s.substr(0, e), expo = s.substr(e);
  if (mant.find('.') != std::string::npos) {
    while (mant.back() == '0') mant.pop_back();
    if (mant.back() == '.') mant.pop_back();
  }
  return mant + expo;
}

double percentile(std::vector<double> values, double q) {
  values.erase(std::remove_if(values.begin(), values.end(),
                              [](double v) { return !std::isfinite(v); }),
               values.end());
  if (values.empty()) return 0.0;
  const size_t k = static_cast<size_t>(std::llround(clamp01(q) * (values.size() - 1)));
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
  return values[k];
}

int draw_color_bar(Image& img, int x, int y, int w, int h, Rgb (*map)(double), double lo,
                   double hi, const std::string& label, int scale) {
  const Rgb ink{40, 40, 48};
  int bar_x = x;
  if (!label.empty()) {
    draw_text(img, x, y + (h - text_height(scale)) / 2, label, ink, scale);
    bar_x = x + text_width(label, scale) + 4 * scale;
  }
  // the colour ramp and its frame
  for (int i = 0; i < w; ++i) {
    const Rgb c = map(w > 1 ? static_cast<double>(i) / (w - 1) : 0.0);
    fill_rect(img, bar_x + i, y, bar_x + i + 1, y + h, c);
  }
  const Rgb frame{60, 60, 68};
  fill_rect(img, bar_x - 1, y - 1, bar_x + w + 1, y, frame);
  fill_rect(img, bar_x - 1, y + h, bar_x + w + 1, y + h + 1, frame);
  fill_rect(img, bar_x - 1, y, bar_x, y + h, frame);
  fill_rect(img, bar_x + w, y, bar_x + w + 1, y + h, frame);
  // end values under the ends of the bar
  const std::string lo_s = format_number(lo), hi_s = format_number(hi);
  const int ty = y + h + 3 * scale;
  draw_text(img, bar_x, ty, lo_s, ink, scale);
  draw_text(img, bar_x + w - text_width(hi_s, scale), ty, hi_s, ink, scale);
  return h + 3 * scale + text_height(scale) + 2 * scale;
}

ColorScale make_color_scale(ColorBy color_by, const std::vector<double>& values) {
  ColorScale scale;
  // no liquid sample: nothing is coloured and no colour bar is drawn
  if (values.empty()) return scale;
  if (color_by == ColorBy::speed || color_by == ColorBy::viscosity) {
    scale.active = true;
    scale.map = colormap_viridis;
    scale.lo = 0.0;
    scale.hi = std::max(percentile(values, 0.99), 1e-12);
    scale.label = color_by == ColorBy::speed ? "|u| (m/s)" : "eta (Pa s)";
  } else if (color_by == ColorBy::pressure) {
    scale.active = true;
    scale.map = colormap_coolwarm;
    double lo = percentile(values, 0.01), hi = percentile(values, 0.99);
    if (lo < 0.0 && hi > 0.0) {
      // a diverging map centred on zero
      hi = std::max(-lo, hi);
      lo = -hi;
    }
    if (!(hi - lo > 1e-12 * std::max(1.0, std::abs(hi)))) {
      lo -= 0.5;
      hi += 0.5;
    }
    scale.lo = lo;
    scale.hi = hi;
    scale.label = "p (Pa)";
  }
  return scale;
}

// --- line plots -----------------------------------------------------------------------------------

Rgb plot_palette(int index) {
  static const Rgb colors[8] = {{0, 114, 178},  {213, 94, 0},   {0, 158, 115}, {204, 121, 167},
                                {230, 159, 0},  {86, 180, 233}, {90, 90, 90},  {240, 228, 66}};
  return colors[((index % 8) + 8) % 8];
}

namespace {

int auto_font_scale(const PlotSpec& spec) {
  if (spec.font_scale > 0) return spec.font_scale;
  return std::max(1, static_cast<int>(std::lround(std::min(spec.width, spec.height) / 320.0)));
}

// axis value -> coordinate used for layout (log10 on log axes)
double axis_coord(double v, bool log_axis) { return log_axis ? std::log10(v) : v; }

struct Tick {
  double value;
  bool major;
};

// "nice" tick step (1, 2 or 5 times a power of ten) for about `count` intervals over `range`
double nice_step(double range, int count) {
  const double raw = range / std::max(1, count);
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  const double f = raw / p;
  return (f < 1.5 ? 1.0 : f < 3.5 ? 2.0 : f < 7.5 ? 5.0 : 10.0) * p;
}

std::vector<Tick> make_ticks(double lo, double hi, bool log_axis, int count) {
  std::vector<Tick> ticks;
  if (!(hi > lo)) return ticks;
  if (log_axis) {
    const double a = std::log10(lo), b = std::log10(hi);
    if (b - a >= 1.0) {
      // decades are the major ticks, 2..9 times a decade the minor ones
      const int stride = std::max(1, static_cast<int>(std::ceil((b - a) / 8.0)));
      for (int e = static_cast<int>(std::floor(a)); e <= static_cast<int>(std::ceil(b)); ++e) {
        const double d = std::pow(10.0, e);
        if (d >= lo * (1 - 1e-9) && d <= hi * (1 + 1e-9)) ticks.push_back({d, e % stride == 0});
        if (stride == 1)
          for (int m = 2; m <= 9; ++m)
            if (m * d >= lo && m * d <= hi) ticks.push_back({m * d, false});
      }
      return ticks;
    }
    // less than a decade: linear ticks in value
  }
  const double step = nice_step(hi - lo, count);
  for (double k = std::ceil(lo / step - 1e-9); k * step <= hi + 1e-9 * step; k += 1.0) {
    const double v = k * step;
    ticks.push_back({std::abs(v) < 1e-12 * step ? 0.0 : v, true});
  }
  return ticks;
}

// data range along one axis, honouring the fixed ends of the spec
void data_range(const PlotSpec& spec, bool x_axis, double& lo, double& hi) {
  const bool log_axis = x_axis ? spec.log_x : spec.log_y;
  lo = std::numeric_limits<double>::infinity();
  hi = -lo;
  for (const PlotSeries& s : spec.series) {
    const std::vector<double>& v = x_axis ? s.x : s.y;
    for (double t : v)
      if (std::isfinite(t) && (!log_axis || t > 0.0)) {
        lo = std::min(lo, t);
        hi = std::max(hi, t);
      }
  }
  if (!std::isfinite(lo)) {
    lo = log_axis ? 1.0 : 0.0;
    hi = log_axis ? 10.0 : 1.0;
  }
  if (hi <= lo) {
    // a single value: open a range around it
    if (log_axis) {
      lo /= 2.0;
      hi *= 2.0;
    } else {
      const double pad = lo != 0.0 ? 0.1 * std::abs(lo) : 1.0;
      lo -= pad;
      hi += pad;
    }
  } else {
    // pad by 4% (in log space on log axes)
    const double a = axis_coord(lo, log_axis), b = axis_coord(hi, log_axis);
    const double pad = 0.04 * (b - a);
    lo = log_axis ? std::pow(10.0, a - pad) : a - pad;
    hi = log_axis ? std::pow(10.0, b + pad) : b + pad;
  }
  const std::optional<double>& fmin = x_axis ? spec.x_min : spec.y_min;
  const std::optional<double>& fmax = x_axis ? spec.x_max : spec.y_max;
  if (fmin) lo = *fmin;
  if (fmax) hi = *fmax;
  if (!(hi > lo)) hi = log_axis ? lo * 10.0 : lo + 1.0;
}

std::string tick_label(double v, bool log_axis) {
  if (log_axis) {
    const double e = std::log10(v);
    if (std::abs(e - std::round(e)) < 1e-9) {
      const int k = static_cast<int>(std::lround(e));
      if (k >= -3 && k <= 4) return format_number(v, 1);
      return "1e" + std::to_string(k);
    }
  }
  return format_number(v, 4);
}

}  // namespace

double PlotAxes::px(double x) const {
  const double a = axis_coord(x0, log_x), b = axis_coord(x1, log_x);
  return left + (axis_coord(x, log_x) - a) / (b - a) * (right - left);
}

double PlotAxes::py(double y) const {
  const double a = axis_coord(y0, log_y), b = axis_coord(y1, log_y);
  return bottom - (axis_coord(y, log_y) - a) / (b - a) * (bottom - top);
}

PlotAxes plot_axes(const PlotSpec& spec) {
  const int s = auto_font_scale(spec);
  PlotAxes ax;
  ax.log_x = spec.log_x;
  ax.log_y = spec.log_y;
  data_range(spec, true, ax.x0, ax.x1);
  data_range(spec, false, ax.y0, ax.y1);
  // left margin: room for the widest y tick label and the rotated y label
  int label_w = 0;
  for (const Tick& t : make_ticks(ax.y0, ax.y1, ax.log_y, 6))
    if (t.major) label_w = std::max(label_w, text_width(tick_label(t.value, ax.log_y), s));
  const int y_label_w = spec.y_label.empty() ? 0 : text_height(s) + 8 * s;
  ax.left = 10 * s + y_label_w + label_w + 6 * s;
  ax.right = spec.width - 14 * s;
  ax.top = (spec.title.empty() ? 10 : 22) * s;
  ax.bottom = spec.height - (text_height(s) + 12 * s) - (spec.x_label.empty() ? 0 : text_height(s) + 8 * s);
  if (ax.right <= ax.left + 10) ax.right = ax.left + 10;
  if (ax.bottom <= ax.top + 10) ax.bottom = ax.top + 10;
  return ax;
}

Image plot_lines(const PlotSpec& spec) {
  const int s = auto_font_scale(spec);
  const PlotAxes ax = plot_axes(spec);
  Image img(spec.width, spec.height, Rgb{255, 255, 255});
  const Rgb ink{30, 30, 36}, grid{226, 229, 234}, minor_grid{242, 243, 246};

  // grid lines, ticks and tick labels
  const std::vector<Tick> xt = make_ticks(ax.x0, ax.x1, ax.log_x, std::max(3, (ax.right - ax.left) / (60 * s)));
  const std::vector<Tick> yt = make_ticks(ax.y0, ax.y1, ax.log_y, std::max(3, (ax.bottom - ax.top) / (45 * s)));
  // axis-parallel 1-pixel lines are snapped to pixel centres so that they stay crisp
  auto snap = [](double v) { return std::floor(v) + 0.5; };
  for (const Tick& t : xt) {
    const double x = snap(ax.px(t.value));
    if (spec.grid) draw_line(img, x, ax.top, x, ax.bottom, t.major ? grid : minor_grid, 1.0);
  }
  for (const Tick& t : yt) {
    const double y = snap(ax.py(t.value));
    if (spec.grid) draw_line(img, ax.left, y, ax.right, y, t.major ? grid : minor_grid, 1.0);
  }
  for (const Tick& t : xt) {
    const double x = snap(ax.px(t.value));
    const double len = (t.major ? 5.0 : 3.0) * s;
    draw_line(img, x, ax.bottom, x, ax.bottom + len, ink, 1.0);
    if (!t.major) continue;
    const std::string label = tick_label(t.value, ax.log_x);
    draw_text(img, static_cast<int>(std::lround(x)) - text_width(label, s) / 2, ax.bottom + 8 * s,
              label, ink, s);
  }
  for (const Tick& t : yt) {
    const double y = snap(ax.py(t.value));
    const double len = (t.major ? 5.0 : 3.0) * s;
    draw_line(img, ax.left - len, y, ax.left, y, ink, 1.0);
    if (!t.major) continue;
    const std::string label = tick_label(t.value, ax.log_y);
    draw_text(img, ax.left - 8 * s - text_width(label, s),
              static_cast<int>(std::lround(y)) - text_height(s) / 2, label, ink, s);
  }

  // the series, clipped to the data rectangle by drawing into a sub-image
  Image area(ax.right - ax.left, ax.bottom - ax.top, Rgb{0, 0, 0});
  for (int y = 0; y < area.height; ++y)
    for (int x = 0; x < area.width; ++x) area.set(x, y, img.get(ax.left + x, ax.top + y));
  for (size_t k = 0; k < spec.series.size(); ++k) {
    const PlotSeries& ser = spec.series[k];
    const Rgb color = ser.color ? *ser.color : plot_palette(static_cast<int>(k));
    const size_t n = std::min(ser.x.size(), ser.y.size());
    auto ok = [&](size_t i) {
      return std::isfinite(ser.x[i]) && std::isfinite(ser.y[i]) && (!ax.log_x || ser.x[i] > 0) &&
             (!ax.log_y || ser.y[i] > 0);
    };
    if (ser.line) {
      double carried = 0.0;  // dash phase carried across segments
      for (size_t i = 1; i < n; ++i) {
        if (!ok(i - 1) || !ok(i)) continue;
        const double xa = ax.px(ser.x[i - 1]) - ax.left, ya = ax.py(ser.y[i - 1]) - ax.top;
        const double xb = ax.px(ser.x[i]) - ax.left, yb = ax.py(ser.y[i]) - ax.top;
        if (ser.dash > 0.0) {
          const double len = std::hypot(xb - xa, yb - ya);
          const double period = 2.0 * ser.dash;
          for (double t = -carried; t < len; t += period) {
            const double t0 = std::max(0.0, t), t1 = std::min(len, t + ser.dash);
            if (t1 > t0 && len > 0)
              draw_line(area, xa + (xb - xa) * t0 / len, ya + (yb - ya) * t0 / len,
                        xa + (xb - xa) * t1 / len, ya + (yb - ya) * t1 / len, color, ser.line_width);
          }
          carried = std::fmod(carried + len, period);
        } else {
          draw_line(area, xa, ya, xb, yb, color, ser.line_width);
        }
      }
    }
    if (ser.marker != Marker::none)
      for (size_t i = 0; i < n; ++i) {
        if (!ok(i)) continue;
        const double x = ax.px(ser.x[i]) - ax.left, y = ax.py(ser.y[i]) - ax.top;
        const double r = ser.marker_size;
        switch (ser.marker) {
          case Marker::circle:
            fill_disk(area, x, y, r, color);
            fill_disk(area, x, y, std::max(0.0, r - 1.5), Rgb{255, 255, 255}, 0.55);
            break;
          case Marker::square:
            fill_rect(area, static_cast<int>(std::lround(x - r)), static_cast<int>(std::lround(y - r)),
                      static_cast<int>(std::lround(x + r)), static_cast<int>(std::lround(y + r)), color);
            break;
          case Marker::cross:
            draw_line(area, x - r, y - r, x + r, y + r, color, 1.5);
            draw_line(area, x - r, y + r, x + r, y - r, color, 1.5);
            break;
          case Marker::none:
            break;
        }
      }
  }
  for (int y = 0; y < area.height; ++y)
    for (int x = 0; x < area.width; ++x) img.set(ax.left + x, ax.top + y, area.get(x, y));

  // frame of the data rectangle
  fill_rect(img, ax.left - 1, ax.top - 1, ax.right + 1, ax.top, ink);
  fill_rect(img, ax.left - 1, ax.bottom, ax.right + 1, ax.bottom + 1, ink);
  fill_rect(img, ax.left - 1, ax.top, ax.left, ax.bottom, ink);
  fill_rect(img, ax.right, ax.top, ax.right + 1, ax.bottom, ink);

  // title and axis labels
  if (!spec.title.empty()) {
    // twice the label size when it fits, else the label size
    const int ts = text_width(spec.title, 2 * s) <= spec.width - 8 * s ? 2 * s : s;
    draw_text(img, std::max(0, (spec.width - text_width(spec.title, ts)) / 2),
              std::max(0, (ax.top - text_height(ts)) / 2), spec.title, ink, ts);
  }
  if (!spec.x_label.empty())
    draw_text(img, (ax.left + ax.right - text_width(spec.x_label, s)) / 2,
              spec.height - text_height(s) - 6 * s, spec.x_label, ink, s);
  if (!spec.y_label.empty())
    draw_text_vertical(img, 6 * s, (ax.top + ax.bottom - text_width(spec.y_label, s)) / 2,
                       spec.y_label, ink, s);

  // legend in the top-right corner of the data rectangle
  if (spec.legend) {
    std::vector<size_t> listed;
    int widest = 0;
    for (size_t k = 0; k < spec.series.size(); ++k)
      if (!spec.series[k].label.empty()) {
        listed.push_back(k);
        widest = std::max(widest, text_width(spec.series[k].label, s));
      }
    if (!listed.empty()) {
      const int row_h = text_height(s) + 6 * s, sample_w = 22 * s;
      const int box_w = sample_w + widest + 14 * s, box_h = static_cast<int>(listed.size()) * row_h + 6 * s;
      // the corner of the data rectangle that the fewest data samples fall into
      int bx = ax.right - box_w - 8 * s, by = ax.top + 8 * s;
      long best = -1;
      for (int corner = 0; corner < 4; ++corner) {
        const int cx = corner % 2 == 0 ? ax.right - box_w - 8 * s : ax.left + 8 * s;
        const int cy = corner < 2 ? ax.top + 8 * s : ax.bottom - box_h - 8 * s;
        long hits = 0;
        for (const PlotSeries& ser : spec.series) {
          const size_t n = std::min(ser.x.size(), ser.y.size());
          for (size_t i = 0; i < n; ++i) {
            // the point itself and (for lines) samples along the segment to the next one
            const int steps = ser.line && i + 1 < n ? 16 : 1;
            for (int q = 0; q < steps; ++q) {
              const double f = static_cast<double>(q) / steps;
              const double x = q == 0 ? ax.px(ser.x[i]) : (1 - f) * ax.px(ser.x[i]) + f * ax.px(ser.x[i + 1]);
              const double y = q == 0 ? ax.py(ser.y[i]) : (1 - f) * ax.py(ser.y[i]) + f * ax.py(ser.y[i + 1]);
              hits += x >= cx - 4 * s && x <= cx + box_w + 4 * s && y >= cy - 4 * s && y <= cy + box_h + 4 * s;
            }
          }
        }
        if (best < 0 || hits < best) {
          best = hits;
          bx = cx;
          by = cy;
        }
      }
      fill_rect(img, bx, by, bx + box_w, by + box_h, Rgb{255, 255, 255}, 0.88);
      fill_rect(img, bx, by, bx + box_w, by + 1, Rgb{190, 190, 196});
      fill_rect(img, bx, by + box_h - 1, bx + box_w, by + box_h, Rgb{190, 190, 196});
      fill_rect(img, bx, by, bx + 1, by + box_h, Rgb{190, 190, 196});
      fill_rect(img, bx + box_w - 1, by, bx + box_w, by + box_h, Rgb{190, 190, 196});
      for (size_t r = 0; r < listed.size(); ++r) {
        const PlotSeries& ser = spec.series[listed[r]];
        const Rgb color = ser.color ? *ser.color : plot_palette(static_cast<int>(listed[r]));
        const int cy = by + 3 * s + static_cast<int>(r) * row_h + row_h / 2;
        const double x0 = bx + 5 * s, x1 = bx + 5 * s + sample_w - 4 * s;
        if (ser.line) {
          if (ser.dash > 0)
            draw_dashed_line(img, x0, cy, x1, cy, color, ser.line_width, std::min(ser.dash, 6.0 * s), std::min(ser.dash, 6.0 * s));
          else
            draw_line(img, x0, cy, x1, cy, color, ser.line_width);
        }
        if (ser.marker == Marker::circle) fill_disk(img, 0.5 * (x0 + x1), cy, ser.marker_size, color);
        if (ser.marker == Marker::square)
          fill_rect(img, static_cast<int>(0.5 * (x0 + x1) - ser.marker_size), static_cast<int>(cy - ser.marker_size),
                    static_cast<int>(0.5 * (x0 + x1) + ser.marker_size), static_cast<int>(cy + ser.marker_size), color);
        if (ser.marker == Marker::cross) {
          const double m = 0.5 * (x0 + x1), r2 = ser.marker_size;
          draw_line(img, m - r2, cy - r2, m + r2, cy + r2, color, 1.5);
          draw_line(img, m - r2, cy + r2, m + r2, cy - r2, color, 1.5);
        }
        draw_text(img, bx + sample_w + 8 * s, cy - text_height(s) / 2, ser.label, ink, s);
      }
    }
  }
  return img;
}

void write_plot(const PlotSpec& spec, const std::string& path) { plot_lines(spec).write_ppm(path); }

void draw_time_label(Image& img, double time, int x, int y, int scale) {
  char buf[48];
  std::snprintf(buf, sizeof(buf), "t=%.3f s", time);
  const std::string text = buf;
  fill_rect(img, x, y, x + text_width(text, scale) + 6 * scale, y + text_height(scale) + 6 * scale,
            Rgb{255, 255, 255}, 0.78);
  draw_text(img, x + 3 * scale, y + 3 * scale, text, Rgb{30, 32, 40}, scale);
}

}  // namespace monolith
