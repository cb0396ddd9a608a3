/// \file render_3d.cpp
/// The 3D frame renderer: sphere tracing of min(liquid level set, solid SDFs) from a default
/// camera, Blinn-Phong shading with a key light, soft ambient, a Fresnel rim on the liquid, soft
/// shadows from one shadow ray, the domain's wall faces as a light room (checkered floor) and
/// its edges as an outline. docs/rendering.md describes the picture and the camera.

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

using V3 = Vec<3>;
constexpr double kInf = std::numeric_limits<double>::infinity();

// --- colours (linear 0..1 floats while shading, 8-bit at the end) -------------------------------

V3 to_v3(Rgb c) { return V3(c[0], c[1], c[2]) / 255.0; }
Rgb to_rgb(const V3& c) {
  Rgb r;
  for (int k = 0; k < 3; ++k) r[k] = static_cast<std::uint8_t>(std::lround(255.0 * std::clamp(c[k], 0.0, 1.0)));
  return r;
}

const V3 kWater = V3(40, 126, 206) / 255.0;
const V3 kSkyTop = V3(178, 196, 220) / 255.0;
const V3 kSkyHorizon = V3(236, 239, 244) / 255.0;
const V3 kFloorA = V3(222, 225, 230) / 255.0;
const V3 kFloorB = V3(196, 201, 209) / 255.0;
const V3 kWallColor = V3(226, 229, 235) / 255.0;
const Rgb kEdge{64, 70, 84};
const Rgb kInk{30, 32, 40};

V3 sky(const V3& dir) {
  const double t = std::clamp(dir[1] * 1.6 + 0.35, 0.0, 1.0);
  return (1 - t) * kSkyHorizon + t * kSkyTop;
}

// --- the default camera ------------------------------------------------------------------------

/// Looks at the domain from direction (1, 0.8, 1.4) (front-right-above), 40 degree field of view
/// across the smaller image side; the view is panned so that the projected domain box is centred
/// and placed at the distance where its 8 corners fit within 92% of the frame.
struct Camera {
  V3 eye, forward, right, up;
  double tan_x = 0.0, tan_y = 0.0;  // half extents of the image plane at distance 1
  int width = 1, height = 1;

  Camera(const Box<3>& domain, int w, int h) : width(w), height(h) {
    const V3 center = domain.center();
    const V3 back = V3(1.0, 0.8, 1.4).normalized();  // from the centre towards the eye
    forward = -back;
    right = forward.cross(V3::UnitY()).normalized();
    up = right.cross(forward);
    const double t = std::tan(20.0 * M_PI / 180.0);
    tan_x = w >= h ? t * w / h : t;
    tan_y = w >= h ? t : t * h / w;
    // pan so that the projected box is centred, then move back until it fits (a few rounds)
    V3 target = center;
    double dist = 0.0;
    for (int round = 0; round < 4; ++round) {
      dist = 0.0;
      for (int k = 0; k < 8; ++k) {
        const V3 p = domain.corner(static_cast<Box<3>::CornerType>(k)) - target;
        const double along = p.dot(back);
        dist = std::max(dist, along + std::abs(p.dot(right)) / (0.92 * tan_x));
        dist = std::max(dist, along + std::abs(p.dot(up)) / (0.92 * tan_y));
      }
      double xmin = kInf, xmax = -kInf, ymin = kInf, ymax = -kInf;
      for (int k = 0; k < 8; ++k) {
        const V3 p = domain.corner(static_cast<Box<3>::CornerType>(k)) - (target + dist * back);
        const double z = p.dot(forward);
        xmin = std::min(xmin, p.dot(right) / z);
        xmax = std::max(xmax, p.dot(right) / z);
        ymin = std::min(ymin, p.dot(up) / z);
        ymax = std::max(ymax, p.dot(up) / z);
      }
      target += dist * (0.5 * (xmin + xmax) * right + 0.5 * (ymin + ymax) * up);
    }
    eye = target + dist * back;
  }
  /// Unit ray direction through image point (px, py) (pixel centres at integer + 1/2, y down).
  V3 ray(double px, double py) const {
    const double x = (2.0 * px / width - 1.0) * tan_x;
    const double y = (1.0 - 2.0 * py / height) * tan_y;
    return (forward + x * right + y * up).normalized();
  }
  /// Image position of a world point and its distance from the eye (ray parameter).
  bool project(const V3& p, double& px, double& py, double& depth) const {
    const V3 d = p - eye;
    const double z = d.dot(forward);
    if (z <= 1e-9) return false;
    px = (d.dot(right) / z / tan_x + 1.0) * 0.5 * width;
    py = (1.0 - d.dot(up) / z / tan_y) * 0.5 * height;
    depth = d.norm();
    return true;
  }
};

/// Slab test: entry and exit ray parameters of box b, and the face the ray exits through
/// (2 axis + (1 if the upper face)); false if the ray misses.
bool ray_box(const V3& o, const V3& d, const Box<3>& b, double& t0, double& t1, int& exit_face) {
  t0 = 0.0;
  t1 = kInf;
  exit_face = -1;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-300) {
      if (o[a] < b.min()[a] || o[a] > b.max()[a]) return false;
      continue;
    }
    double ta = (b.min()[a] - o[a]) / d[a], tb = (b.max()[a] - o[a]) / d[a];
    int fb = 2 * a + 1;
    if (ta > tb) {
      std::swap(ta, tb);
      fb = 2 * a;
    }
    t0 = std::max(t0, ta);
    if (tb < t1) {
      t1 = tb;
      exit_face = fb;
    }
  }
  return t1 >= t0;
}

// --- the scene as a signed distance ------------------------------------------------------------

/// Trilinear liquid level set on the half lattice; outside the lattice box the distance to the
/// box plus the (non-negative part of the) value at the nearest lattice point: a lower bound of
/// the distance to the liquid, so sphere tracing stays safe.
struct LiquidField {
  const double* q = nullptr;
  int nx = 0, ny = 0, nz = 0;
  double inv_h = 1.0;
  V3 lo, hi;

  // the liquid wets the walls: inside the domain within 3/4 dx of a wall face, the level set is
  // read 3/4 dx inside (particles are kept a little clear of walls)
  V3 dom_lo, dom_hi, wet_lo, wet_hi;

  double sample(const V3& x0) const {
    V3 x = x0;
    for (int a = 0; a < 3; ++a) {
      if (x[a] >= dom_lo[a] && x[a] < wet_lo[a]) x[a] = wet_lo[a];
      if (x[a] <= dom_hi[a] && x[a] > wet_hi[a]) x[a] = wet_hi[a];
    }
    const V3 c = x.cwiseMax(lo).cwiseMin(hi);
    const double outside = (x - c).norm();
    const double v = trilinear(c);
    return outside > 0.0 ? outside + std::max(v, 0.0) : v;
  }
  double trilinear(const V3& c) const {
    const double sx = (c[0] - lo[0]) * inv_h, sy = (c[1] - lo[1]) * inv_h, sz = (c[2] - lo[2]) * inv_h;
    const int i = std::min(static_cast<int>(sx), nx - 2), j = std::min(static_cast<int>(sy), ny - 2),
              k = std::min(static_cast<int>(sz), nz - 2);
    const double fx = sx - i, fy = sy - j, fz = sz - k;
    const double* p = q + (static_cast<size_t>(k) * ny + j) * nx + i;
    const size_t sy_ = static_cast<size_t>(nx), sz_ = static_cast<size_t>(nx) * ny;
    const double c00 = p[0] + fx * (p[1] - p[0]);
    const double c10 = p[sy_] + fx * (p[sy_ + 1] - p[sy_]);
    const double c01 = p[sz_] + fx * (p[sz_ + 1] - p[sz_]);
    const double c11 = p[sz_ + sy_] + fx * (p[sz_ + sy_ + 1] - p[sz_ + sy_]);
    const double c0 = c00 + fy * (c10 - c00), c1 = c01 + fy * (c11 - c01);
    return c0 + fz * (c1 - c0);
  }
};

enum Material : int { kNothing = 0, kWall = 1, kLiquid = 2, kSolid = 3 };  // solid k: kSolid + k

struct Scene {
  const RenderView<3>* view = nullptr;
  bool has_liquid = false;
  LiquidField liquid;
  Box<3> domain, trace_box;
  double feature = 1.0;  // dx: the scale of surface detail
  /// Misses closer than this soften shadows: 2 dx, or half the largest level set value when the
  /// level set is capped (a particle reconstruction is a constant about one dx away from liquid).
  double penumbra_reach = 2.0;
  int max_steps = 400;  // sphere-tracing steps per ray (grows with the grid)
  std::vector<Box<3>> solid_boxes;

  double solid_distance(size_t k, const V3& x) const {
    // cheap bound from the solid's box first: far away, the box distance is enough
    const double box_d = solid_boxes[k].exteriorDistance(x);
    if (box_d > 4.0 * feature) return box_d;
    return view->solids[k].shape->distance(x);
  }
  /// min over liquid and solids; `what` receives the material of the minimum.
  double distance(const V3& x, int& what) const {
    double d = kInf;
    what = kNothing;
    if (has_liquid) {
      d = liquid.sample(x);
      what = kLiquid;
    }
    for (size_t k = 0; k < view->solids.size(); ++k) {
      if (!view->solids[k].shape) continue;
      const double ds = solid_distance(k, x);
      if (ds < d) {
        d = ds;
        what = kSolid + static_cast<int>(k);
      }
    }
    return d;
  }
  double distance(const V3& x) const {
    int what;
    return distance(x, what);
  }
  V3 normal(const V3& x, int what) const {
    if (what == kLiquid) {
      // central differences over two lattice spacings (one cell) smooth the trilinear facets and
      // the particle-scale bumps of a reconstructed surface
      const double h = 2.0 / liquid.inv_h;
      V3 g;
      for (int a = 0; a < 3; ++a) {
        V3 e = V3::Zero();
        e[a] = h;
        g[a] = liquid.sample(x + e) - liquid.sample(x - e);
      }
      return g.norm() > 0 ? V3(g.normalized()) : V3(V3::UnitY());
    }
    const V3 g = view->solids[what - kSolid].shape->gradient(x);
    return g.norm() > 0 ? V3(g.normalized()) : V3(V3::UnitY());
  }
  /// Sphere tracing along o + t d for t in [t0, t1]; returns the hit parameter or +inf.
  double trace(const V3& o, const V3& d, double t0, double t1, double pixel_angle, int& what) const {
    double t = t0;
    for (int step = 0; step < max_steps && t <= t1; ++step) {
      const double dist = distance(o + t * d, what);
      const double eps = std::max(0.35 * pixel_angle * t, 1e-4 * feature);
      if (dist < eps) return t;
      t += std::max(0.9 * dist, 0.5 * eps);
    }
    what = kNothing;
    return kInf;
  }
  /// Soft shadow towards the light: 1 lit, 0 fully shadowed (penumbra from the closest miss).
  double shadow(const V3& p, const V3& l) const {
    double t0, t1;
    int face;
    if (!ray_box(p, l, trace_box, t0, t1, face)) return 1.0;
    double t = 2.0 * feature, lit = 1.0;
    for (int step = 0; step < 160 && t < t1; ++step) {
      const double dist = distance(p + t * l);
      if (dist < 1e-3 * feature) return 0.0;
      // penumbra from near misses only: far from the surface a level set need not be a distance
      // (particle reconstructions are capped a few dx out), which would darken long shadow rays
      if (dist < penumbra_reach) lit = std::min(lit, 10.0 * dist / t);
      t += std::clamp(dist, 0.2 * feature, 4.0 * feature);
    }
    return std::clamp(lit, 0.0, 1.0);
  }
};

// --- shading -------------------------------------------------------------------------------------

struct Sample {
  V3 color = V3::Zero();
  double depth = kInf;
  int what = kNothing;
};

struct Renderer {
  Scene scene;
  Camera camera;
  ColorScale scale;
  ColorBy color_by = ColorBy::none;
  V3 light = V3(0.3, 1.0, 0.55).normalized();
  double pixel_angle = 0.0;
  std::array<bool, 6> wall{};

  V3 field_color(const V3& x) const {
    const RenderView<3>& v = *scene.view;
    const MacGrid<3>& grid = *v.grid;
    double value = 0.0;
    if (color_by == ColorBy::speed) value = grid.interpolate_velocity(*v.velocity, x).norm();
    else if (color_by == ColorBy::pressure) value = grid.interpolate_cell(*v.pressure, x);
    else if (v.viscosity) value = grid.interpolate_cell(*v.viscosity, x);
    return to_v3(scale.color(value));
  }

  Sample shade_ray(const V3& dir) const {
    Sample s;
    const V3& o = camera.eye;
    double t0, t1, td0, td1;
    int face, dface;
    // the domain box's exit face, if a wall, is an opaque backdrop
    double t_wall = kInf;
    if (ray_box(o, dir, scene.domain, td0, td1, dface) && dface >= 0 && wall[dface]) t_wall = td1;
    double t_hit = kInf;
    int what = kNothing;
    if (ray_box(o, dir, scene.trace_box, t0, t1, face))
      t_hit = scene.trace(o, dir, t0, std::min(t1, t_wall), pixel_angle, what);
    if (t_hit == kInf && t_wall == kInf) {
      s.color = sky(dir);
      return s;
    }
    const V3 h = (light - dir).normalized();
    if (t_hit <= t_wall) {
      // liquid or solid surface
      const V3 x = o + t_hit * dir;
      const V3 n = scene.normal(x, what);
      const double ndl = std::max(0.0, n.dot(light));
      const double sh = ndl > 0.0 ? scene.shadow(x + 1.5 * scene.feature * n, light) : 0.0;
      const double ambient = 0.32 + 0.14 * n[1];
      const double ndv = std::max(0.0, -n.dot(dir));
      if (what == kLiquid) {
        const V3 base = scale.active ? field_color(x - 0.5 * scene.feature * n) : kWater;
        // liquid is a little self-lit (light scattered inside it), so its shadowed sides stay clear
        V3 c = base * (ambient + 0.2 + 0.55 * ndl * sh);
        const double fresnel = 0.04 + 0.96 * std::pow(1.0 - ndv, 5.0);
        const V3 reflect_dir = dir - 2.0 * dir.dot(n) * n;
        c = (1.0 - 0.7 * fresnel) * c + 0.7 * fresnel * sky(reflect_dir);
        c += V3::Constant(0.75 * std::pow(std::max(0.0, n.dot(h)), 90.0) * sh);
        s.color = c;
      } else {
        const V3 base = to_v3(scene.view->solids[what - kSolid].color);
        V3 c = base * (ambient + 0.7 * ndl * sh);
        c += V3::Constant(0.18 * std::pow(std::max(0.0, n.dot(h)), 24.0) * sh);
        // a darker rim at grazing angles outlines the body
        c *= 0.75 + 0.25 * std::min(1.0, 3.0 * ndv);
        s.color = c;
      }
      s.depth = t_hit;
      s.what = what;
      return s;
    }
    // the wall: inward normal, checkered on the floor (y-)
    const V3 x = o + t_wall * dir;
    V3 n = V3::Zero();
    n[dface / 2] = dface % 2 == 0 ? 1.0 : -1.0;
    V3 base = kWallColor;
    if (dface == 2) {
      const Vec<3> size = scene.domain.sizes();
      const double cell = std::max(size[0], size[2]) / 10.0;
      const long cx = static_cast<long>(std::floor((x[0] - scene.domain.min()[0]) / cell));
      const long cz = static_cast<long>(std::floor((x[2] - scene.domain.min()[2]) / cell));
      base = ((cx + cz) & 1) ? kFloorB : kFloorA;
    }
    const double ndl = std::max(0.0, n.dot(light));
    const double sh = ndl > 0.0 ? scene.shadow(x + 0.5 * scene.feature * n, light) : 0.0;
    // walls stay light (a backdrop, not a subject); shadows darken them by up to a third
    const double shade = 0.84 + 0.2 * ndl;
    s.color = base * shade * (1.0 - (ndl > 0.0 ? 0.33 * (1.0 - sh) : 0.0));
    s.depth = t_wall;
    s.what = kWall;
    return s;
  }
};


}  // namespace

/// Renders the 3D frame: one sphere-traced ray per pixel plus four more on edges between
/// materials or strong contrast, then the domain outline (depth tested), colour bar and time.
template <>
Image render_frame<3>(const RenderView<3>& view, const RenderSpec& spec) {
  const int width = std::max(1, spec.size[0]), height = std::max(1, spec.size[1]);
  const int s = std::max(1, (std::min(width, height) + 200) / 400);  // font magnification
  if (!view.grid) {
    Image img(width, height, to_rgb(kSkyHorizon));
    draw_time_label(img, view.time, 4 * s, 4 * s, s);
    return img;
  }
  const MacGrid<3>& grid = *view.grid;
  const Box<3> domain = grid.domain_box();
  Renderer r{Scene{}, Camera(domain, width, height), ColorScale{}, spec.color_by};
  r.pixel_angle = 2.0 * r.camera.tan_y / height;
  for (int f = 0; f < 6; ++f) r.wall[f] = view.boundary[f] == BoundaryType::wall;

  // the scene: liquid field, solids' boxes, and the box that rays are traced through
  Scene& sc = r.scene;
  sc.view = &view;
  sc.domain = domain;
  sc.feature = grid.dx();
  sc.penumbra_reach = 2.0 * grid.dx();
  sc.max_steps = 300 + 2 * grid.cells().sum();
  const SampleLattice<3> lattice = half_lattice(grid);
  sc.has_liquid = view.liquid_phi && view.liquid_phi->size() == lattice.size() && lattice.dims.minCoeff() >= 2;
  if (sc.has_liquid) {
    sc.liquid.q = view.liquid_phi->data();
    sc.liquid.nx = lattice.dims[0];
    sc.liquid.ny = lattice.dims[1];
    sc.liquid.nz = lattice.dims[2];
    sc.liquid.inv_h = 1.0 / lattice.spacing;
    sc.liquid.lo = lattice.origin;
    sc.liquid.hi = lattice.position(lattice.dims - VecI<3>::Ones());
    const double phi_max = view.liquid_phi->maxCoeff();
    if (std::isfinite(phi_max) && phi_max > 0.0) sc.penumbra_reach = std::min(sc.penumbra_reach, 0.5 * phi_max);
    sc.liquid.dom_lo = sc.liquid.wet_lo = domain.min();
    sc.liquid.dom_hi = sc.liquid.wet_hi = domain.max();
    for (int a = 0; a < 3; ++a) {
      if (r.wall[2 * a]) sc.liquid.wet_lo[a] += 0.75 * grid.dx();
      if (r.wall[2 * a + 1]) sc.liquid.wet_hi[a] -= 0.75 * grid.dx();
    }
  }
  const Vec<3> grow = 0.25 * domain.sizes();
  const Box<3> limit(domain.min() - grow, domain.max() + grow);
  sc.trace_box = Box<3>(domain.min() - 0.01 * domain.sizes(), domain.max() + 0.01 * domain.sizes());
  for (const RenderSolid<3>& solid : view.solids) {
    Box<3> b = solid.shape ? solid.shape->bounds() : Box<3>();
    if (solid.shape) b = b.intersection(limit);
    sc.solid_boxes.push_back(b);
    if (!b.isEmpty()) sc.trace_box.extend(b);
  }

  // colour scale of the liquid
  const bool field_ok = (spec.color_by == ColorBy::speed && view.velocity) ||
                        (spec.color_by == ColorBy::pressure && view.pressure) ||
                        spec.color_by == ColorBy::viscosity;
  if (sc.has_liquid && field_ok)
    r.scale = make_color_scale(spec.color_by, liquid_field_values(view, lattice, spec.color_by));

  // pass 1: one ray per pixel centre (rows are independent: deterministic in parallel)
  std::vector<V3> color(static_cast<size_t>(width) * height);
  std::vector<double> depth(color.size());
  std::vector<int> what(color.size());
#pragma omp parallel for schedule(dynamic, 2)
  for (int j = 0; j < height; ++j)
    for (int i = 0; i < width; ++i) {
      const Sample smp = r.shade_ray(r.camera.ray(i + 0.5, j + 0.5));
      const size_t k = static_cast<size_t>(j) * width + i;
      color[k] = smp.color;
      depth[k] = smp.depth;
      what[k] = smp.what;
    }

  // pass 2: anti-aliasing where the material changes or the colour jumps (4 more rays)
  std::vector<V3> refined = color;
#pragma omp parallel for schedule(dynamic, 2)
  for (int j = 0; j < height; ++j)
    for (int i = 0; i < width; ++i) {
      const size_t k = static_cast<size_t>(j) * width + i;
      bool edge = false;
      const int ni[4] = {i - 1, i + 1, i, i};
      const int nj[4] = {j, j, j - 1, j + 1};
      for (int q = 0; q < 4 && !edge; ++q) {
        if (ni[q] < 0 || nj[q] < 0 || ni[q] >= width || nj[q] >= height) continue;
        const size_t kn = static_cast<size_t>(nj[q]) * width + ni[q];
        edge = what[kn] != what[k] || (color[kn] - color[k]).cwiseAbs().maxCoeff() > 0.12;
      }
      if (!edge) continue;
      // rotated-grid offsets
      static const double off[4][2] = {{0.125, 0.375}, {0.375, -0.125}, {-0.125, -0.375}, {-0.375, 0.125}};
      V3 sum = color[k];
      for (const auto& o : off) sum += r.shade_ray(r.camera.ray(i + 0.5 + o[0], j + 0.5 + o[1])).color;
      refined[k] = sum / 5.0;
    }
  Image img(width, height);
  for (int j = 0; j < height; ++j)
    for (int i = 0; i < width; ++i) img.set(i, j, to_rgb(refined[static_cast<size_t>(j) * width + i]));

  // domain outline: the 12 edges, depth tested against the picture (hidden parts faint)
  for (int a = 0; a < 3; ++a)
    for (int m = 0; m < 4; ++m) {
      V3 p0 = domain.min(), p1;
      const int b = (a + 1) % 3, c = (a + 2) % 3;
      if (m & 1) p0[b] = domain.max()[b];
      if (m & 2) p0[c] = domain.max()[c];
      p1 = p0;
      p1[a] = domain.max()[a];
      double x0, y0, d0, x1, y1, d1;
      if (!r.camera.project(p0, x0, y0, d0) || !r.camera.project(p1, x1, y1, d1)) continue;
      const int pieces = std::max(1, static_cast<int>(std::hypot(x1 - x0, y1 - y0) / 3.0));
      for (int q = 0; q < pieces; ++q) {
        const V3 pa = p0 + (p1 - p0) * (static_cast<double>(q) / pieces);
        const V3 pb = p0 + (p1 - p0) * (static_cast<double>(q + 1) / pieces);
        double xa = 0, ya = 0, da = 0, xb = 0, yb = 0, db = 0, xm = 0, ym = 0, dm = 0;
        if (!r.camera.project(pa, xa, ya, da) || !r.camera.project(pb, xb, yb, db) ||
            !r.camera.project(0.5 * (pa + pb), xm, ym, dm))
          continue;
        const int pi = std::clamp(static_cast<int>(xm), 0, width - 1), pj = std::clamp(static_cast<int>(ym), 0, height - 1);
        const bool visible = dm <= depth[static_cast<size_t>(pj) * width + pi] + 2.0 * sc.feature;
        draw_line(img, xa, ya, xb, yb, kEdge, 1.2, visible ? 0.6 : 0.15);
      }
    }

  // labels: time (top left) and the colour bar (top right)
  draw_time_label(img, view.time, 4 * s, 4 * s, s);
  if (r.scale.active) {
    const int bar_w = std::clamp(width / 4, 40, 220), bar_h = 5 * s + 2;
    const int label_w = text_width(r.scale.label, s) + 4 * s;
    const int panel_w = label_w + bar_w + 8 * s, panel_h = bar_h + text_height(s) + 11 * s;
    const int px0 = width - 4 * s - panel_w;
    if (px0 > text_width("t=0.000 s", s) + 16 * s) {
      fill_rect(img, px0, 4 * s, px0 + panel_w, 4 * s + panel_h, Rgb{255, 255, 255}, 0.78);
      draw_color_bar(img, px0 + 4 * s, 8 * s, bar_w, bar_h, r.scale.map, r.scale.lo, r.scale.hi, r.scale.label, s);
    }
  }
  return img;
}

}  // namespace monolith
