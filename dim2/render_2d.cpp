/// \file render_2d.cpp
/// The 2D frame renderer: the domain fills the picture (aspect ratio kept, y up), the liquid is
/// an anti-aliased region from its level set, coloured by speed / pressure / viscosity or a plain
/// water blue, with solids, walls, a colour bar and the time drawn over it. docs/rendering.md
/// describes the picture.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "reference/viz/plot.hpp"
#include "reference/viz/render.hpp"

namespace monolith {

namespace {

// palette of the 2D pictures
const Rgb kMargin{233, 236, 241};
const Rgb kSkyTop{252, 252, 254};
const Rgb kSkyBottom{231, 236, 243};
const Rgb kWater{36, 118, 196};
const Rgb kWaterDeep{20, 78, 158};
const Rgb kWall{52, 57, 68};
const Rgb kPeriodic{120, 126, 138};
const Rgb kInk{30, 32, 40};

Rgb mix(Rgb a, Rgb b, double t) {
  t = std::clamp(t, 0.0, 1.0);
  Rgb c;
  for (int k = 0; k < 3; ++k) c[k] = static_cast<std::uint8_t>(std::lround((1 - t) * a[k] + t * b[k]));
  return c;
}

Rgb scaled(Rgb a, double f) {
  Rgb c;
  for (int k = 0; k < 3; ++k)
    c[k] = static_cast<std::uint8_t>(std::clamp(std::lround(a[k] * f), 0L, 255L));
  return c;
}

double smoothstep(double e0, double e1, double x) {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3 - 2 * t);
}

/// World <-> pixel mapping: the domain box scaled uniformly into the picture minus a margin,
/// centred, y up. Pixel centres are at integer + 1/2.
struct View2 {
  Vec<2> lo, hi;
  double scale = 1.0;  // pixels per metre
  double ox = 0.0, oy = 0.0;  // pixel position of the domain's top-left corner (lo.x, hi.y)

  double px(double x) const { return ox + (x - lo[0]) * scale; }
  double py(double y) const { return oy + (hi[1] - y) * scale; }
  Vec<2> world(double pxc, double pyc) const {
    return Vec<2>(lo[0] + (pxc - ox) / scale, hi[1] - (pyc - oy) / scale);
  }
  /// Fraction of pixel (i, j) inside the domain rectangle (1 inside, ramps over one pixel).
  double inside(int i, int j) const {
    const double x = i + 0.5, y = j + 0.5;
    const double cx = std::clamp(std::min(x - ox, ox + (hi[0] - lo[0]) * scale - x) + 0.5, 0.0, 1.0);
    const double cy = std::clamp(std::min(y - oy, oy + (hi[1] - lo[1]) * scale - y) + 0.5, 0.0, 1.0);
    return cx * cy;
  }
};

View2 make_view(const Box<2>& domain, int width, int height, int margin) {
  View2 v;
  v.lo = domain.min();
  v.hi = domain.max();
  const Vec<2> size = v.hi - v.lo;
  v.scale = std::min((width - 2.0 * margin) / size[0], (height - 2.0 * margin) / size[1]);
  v.ox = 0.5 * (width - size[0] * v.scale);
  v.oy = 0.5 * (height - size[1] * v.scale);
  return v;
}


/// The colour field at a point (the face velocity's magnitude, or a cell field interpolated).
double field_at(const RenderView<2>& view, ColorBy color_by, const Vec<2>& x) {
  const MacGrid<2>& grid = *view.grid;
  if (color_by == ColorBy::speed) return grid.interpolate_velocity(*view.velocity, x).norm();
  if (color_by == ColorBy::pressure) return grid.interpolate_cell(*view.pressure, x);
  return view.viscosity ? grid.interpolate_cell(*view.viscosity, x) : 0.0;
}

}  // namespace

/// Renders the 2D frame: background, liquid (from liquid_phi on the half lattice, coverage
/// clamp(1/2 - phi / pixel, 0, 1)), particles where the liquid is thin, solids with outlines,
/// walls / periodic markers, colour bar and time label.
template <>
Image render_frame<2>(const RenderView<2>& view, const RenderSpec& spec) {
  const int width = std::max(1, spec.size[0]), height = std::max(1, spec.size[1]);
  Image img(width, height, kMargin);
  const int s = std::max(1, (std::min(width, height) + 200) / 400);  // font magnification
  if (!view.grid) {
    draw_time_label(img, view.time, 4 * s, 4 * s, s);
    return img;
  }
  const MacGrid<2>& grid = *view.grid;
  const int margin = std::max(4, static_cast<int>(std::lround(0.035 * std::min(width, height))));
  const View2 v = make_view(grid.domain_box(), width, height, margin);
  const double pixel = 1.0 / v.scale;  // metres per pixel
  const double dx = grid.dx();
  const SampleLattice<2> lattice = half_lattice(grid);
  const bool has_phi = view.liquid_phi && view.liquid_phi->size() == lattice.size();

  // the colour scale of the liquid (inactive without the field it needs)
  ColorScale scale;
  const bool field_ok = (spec.color_by == ColorBy::speed && view.velocity) ||
                        (spec.color_by == ColorBy::pressure && view.pressure) ||
                        spec.color_by == ColorBy::viscosity;
  if (has_phi && field_ok) scale = make_color_scale(spec.color_by, liquid_field_values(view, lattice, spec.color_by));

  // the level set at every pixel centre inside the domain (+inf outside it or without liquid)
  const size_t npx = static_cast<size_t>(width) * height;
  // The liquid is drawn wetting the walls: within 3/4 dx of a wall face the level set is read
  // 3/4 dx inside (particles are kept a little clear of walls, which would otherwise show as a
  // hairline gap between the liquid and the wall).
  Vec<2> wet_lo = v.lo, wet_hi = v.hi;
  for (int a = 0; a < 2; ++a) {
    if (view.boundary[2 * a] == BoundaryType::wall) wet_lo[a] += 0.75 * dx;
    if (view.boundary[2 * a + 1] == BoundaryType::wall) wet_hi[a] -= 0.75 * dx;
  }
  std::vector<double> phi_px(npx, std::numeric_limits<double>::infinity());
  if (has_phi) {
#pragma omp parallel for schedule(dynamic, 8)
    for (int j = 0; j < height; ++j)
      for (int i = 0; i < width; ++i)
        if (v.inside(i, j) > 0.0) {
          const Vec<2> x = v.world(i + 0.5, j + 0.5).cwiseMax(wet_lo).cwiseMin(wet_hi);
          phi_px[static_cast<size_t>(j) * width + i] = lattice.interpolate(*view.liquid_phi, x);
        }
  }
  const auto coverage = [&](size_t k) { return std::clamp(0.5 - phi_px[k] / pixel, 0.0, 1.0); };
  // depth below the free surface straight above, in pixels (water darkens with depth)
  std::vector<float> depth_px(npx, 0.0f);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < width; ++i) {
    int top = -1;
    for (int j = 0; j < height; ++j) {
      const size_t k = static_cast<size_t>(j) * width + i;
      if (phi_px[k] < 0.0) {
        if (top < 0) top = j;
        depth_px[k] = static_cast<float>(j - top);
      } else {
        top = -1;
      }
    }
  }

  // background and liquid, pixel by pixel (rows are independent: deterministic in parallel)
  const double deep = std::max(12.0 * dx, 0.3 * (v.hi[1] - v.lo[1])) / pixel;  // darkest depth, pixels
#pragma omp parallel for schedule(dynamic, 8)
  for (int j = 0; j < height; ++j) {
    for (int i = 0; i < width; ++i) {
      const double in = v.inside(i, j);
      if (in <= 0.0) continue;
      const size_t k = static_cast<size_t>(j) * width + i;
      const Vec<2> x = v.world(i + 0.5, j + 0.5);
      const double h = (x[1] - v.lo[1]) / (v.hi[1] - v.lo[1]);
      Rgb c = mix(kSkyBottom, kSkyTop, h);
      const double phi = phi_px[k];
      const double cover = std::clamp(0.5 - phi / pixel, 0.0, 1.0);
      if (cover > 0.0) {
        // body colour: plain water darkening with depth, or the colour field
        Rgb body = scale.active ? scale.color(field_at(view, spec.color_by, x))
                                : mix(kWater, kWaterDeep, smoothstep(0.0, deep, depth_px[k]));
        // a thin darker rim on the liquid's edge pixels makes the interface crisp; edges are found
        // in the picture (a neighbour inside the domain with less liquid), because a level set
        // rebuilt from particles is shallow in the bulk and its value alone cannot tell
        double least = cover;
        const int ni[4] = {i - 1, i + 1, i, i}, nj[4] = {j, j, j - 1, j + 1};
        for (int q = 0; q < 4; ++q)
          if (ni[q] >= 0 && nj[q] >= 0 && ni[q] < width && nj[q] < height && v.inside(ni[q], nj[q]) >= 1.0)
            least = std::min(least, coverage(static_cast<size_t>(nj[q]) * width + ni[q]));
        const double rim = cover - least;
        body = mix(body, scaled(body, 0.62), 0.8 * rim);
        c = mix(c, body, cover);
      }
      img.set(i, j, mix(kMargin, c, in));
    }
  }

  // particles: light dots where the liquid is thin (a sheet or filament under 3 dx across, or
  // spray outside the level set), none in the bulk. A level set rebuilt from particles is only a
  // distance near its surface (it is about -dx/3 all through the bulk), so thinness is judged by
  // looking 1.5 dx to both sides of the particle along four directions.
  if (view.particles && has_phi) {
    const double r = std::clamp(0.14 * dx * v.scale, 0.6, 3.0);
    const double reach = 1.5 * dx, c = std::sqrt(0.5);
    const Vec<2> dirs[4] = {Vec<2>(1, 0), Vec<2>(0, 1), Vec<2>(c, c), Vec<2>(c, -c)};
    for (const Vec<2>& p : *view.particles) {
      if (!grid.domain_box().contains(p)) continue;
      const double phi = lattice.interpolate(*view.liquid_phi, p);
      bool thin = phi > 0.0;
      for (int d = 0; d < 4 && !thin; ++d)
        thin = lattice.interpolate(*view.liquid_phi, p + reach * dirs[d]) > 0.0 &&
               lattice.interpolate(*view.liquid_phi, p - reach * dirs[d]) > 0.0;
      if (thin) fill_disk(img, v.px(p[0]), v.py(p[1]), r, phi > 0.0 ? kWater : Rgb{178, 218, 250}, phi > 0.0 ? 0.8 : 0.5);
    }
  }

  // solids: anti-aliased fill from the SDF, darker outline just inside the surface
  for (const RenderSolid<2>& solid : view.solids) {
    if (!solid.shape) continue;
    Box<2> b = solid.shape->bounds();
    b = b.intersection(grid.domain_box());
    if (b.isEmpty()) continue;
    const int i0 = std::max(0, static_cast<int>(std::floor(v.px(b.min()[0]))) - 2);
    const int i1 = std::min(width - 1, static_cast<int>(std::ceil(v.px(b.max()[0]))) + 2);
    const int j0 = std::max(0, static_cast<int>(std::floor(v.py(b.max()[1]))) - 2);
    const int j1 = std::min(height - 1, static_cast<int>(std::ceil(v.py(b.min()[1]))) + 2);
    const Rgb outline = scaled(solid.color, 0.55);
#pragma omp parallel for schedule(dynamic, 8)
    for (int j = j0; j <= j1; ++j)
      for (int i = i0; i <= i1; ++i) {
        const double in = v.inside(i, j);
        if (in <= 0.0) continue;
        const double d = solid.shape->distance(v.world(i + 0.5, j + 0.5)) / pixel;  // in pixels
        const double cover = std::clamp(0.5 - d, 0.0, 1.0) * in;
        if (cover <= 0.0) continue;
        const double edge = std::clamp(1.0 - std::abs(-d - 1.0) / 1.2, 0.0, 1.0);
        img.blend(i, j, mix(solid.color, outline, edge), cover);
      }
  }

  // domain boundary: a dark band outside wall faces, a dashed line on periodic faces
  const double L = v.ox, R = v.px(v.hi[0]), T = v.oy, B = v.py(v.lo[1]);
  const double band = std::max(2.0, std::round(0.55 * margin));
  for (int f = 0; f < 4; ++f) {
    const int axis = f / 2;
    const bool upper = f % 2 == 1;
    const BoundaryType type = view.boundary[f];
    double x0, y0, x1, y1;  // the face as a pixel segment
    if (axis == 0) {
      x0 = x1 = upper ? R : L;
      y0 = T;
      y1 = B;
    } else {
      y0 = y1 = upper ? T : B;
      x0 = L;
      x1 = R;
    }
    if (type == BoundaryType::wall) {
      // a band of `band` pixels outside the face, covering the corners
      const double ext = band;
      double bx0, by0, bx1, by1;
      if (axis == 0) {
        bx0 = upper ? R : L - band;
        bx1 = upper ? R + band : L;
        by0 = T - ext;
        by1 = B + ext;
      } else {
        by0 = upper ? T - band : B;
        by1 = upper ? T : B + band;
        bx0 = L - ext;
        bx1 = R + ext;
      }
      for (int j = std::max(0, static_cast<int>(std::floor(by0))); j < std::min(height, static_cast<int>(std::ceil(by1))); ++j)
        for (int i = std::max(0, static_cast<int>(std::floor(bx0))); i < std::min(width, static_cast<int>(std::ceil(bx1))); ++i) {
          // fractional coverage at the band's edges
          const double cx = std::clamp(std::min(i + 1.0, bx1) - std::max(static_cast<double>(i), bx0), 0.0, 1.0);
          const double cy = std::clamp(std::min(j + 1.0, by1) - std::max(static_cast<double>(j), by0), 0.0, 1.0);
          img.blend(i, j, kWall, cx * cy);
        }
    } else if (type == BoundaryType::periodic) {
      draw_dashed_line(img, x0, y0, x1, y1, kPeriodic, 1.5, 6.0 * s, 4.0 * s);
    }
  }

  // labels: time (top left) and the colour bar (top right), inside the domain
  const int lx = static_cast<int>(std::ceil(L)) + 4 * s, ly = static_cast<int>(std::ceil(T)) + 4 * s;
  draw_time_label(img, view.time, lx, ly, s);
  if (scale.active) {
    const int bar_w = std::clamp(static_cast<int>((R - L) / 4), 40, 220), bar_h = 5 * s + 2;
    const int label_w = text_width(scale.label, s) + 4 * s;
    const int panel_w = label_w + bar_w + 8 * s, panel_h = bar_h + text_height(s) + 11 * s;
    const int px0 = static_cast<int>(std::floor(R)) - 4 * s - panel_w;
    if (px0 > lx + text_width("t=0.000 s", s) + 8 * s) {
      fill_rect(img, px0, ly, px0 + panel_w, ly + panel_h, Rgb{255, 255, 255}, 0.78);
      draw_color_bar(img, px0 + 4 * s, ly + 4 * s, bar_w, bar_h, scale.map, scale.lo, scale.hi, scale.label, s);
    }
  }
  return img;
}

}  // namespace monolith
