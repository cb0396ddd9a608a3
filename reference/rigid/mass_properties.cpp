/// \file mass_properties.cpp
/// Rigid-body cross products and mass properties from the true geometry (§4.4.7): closed forms
/// per shape type, exact polygon and triangle-mesh integrals, and lattice integration of the
/// SDF for union/difference. docs/rigid-bodies.md lists the formulas.

#include "reference/rigid/mass_properties.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "dim2/shapes_2d.hpp"
#include "dim3/shapes_3d.hpp"
#include "reference/core/errors.hpp"
#include "reference/core/parallel.hpp"
#include "reference/geometry/shape_tools.hpp"

namespace monolith {

// --- cross products and orientations -----------------------------------------------------------

template <>
Vec<2> angular_cross<2>(const AngularVec<2>& w, const Vec<2>& r) {
  return Vec<2>(-w[0] * r[1], w[0] * r[0]);
}
template <>
Vec<3> angular_cross<3>(const AngularVec<3>& w, const Vec<3>& r) {
  return w.cross(r);
}
template <>
AngularVec<2> moment<2>(const Vec<2>& r, const Vec<2>& f) {
  return AngularVec<2>(r[0] * f[1] - r[1] * f[0]);
}
template <>
AngularVec<3> moment<3>(const Vec<3>& r, const Vec<3>& f) {
  return r.cross(f);
}
template <>
Mat<2> orientation_matrix<2>(const double& angle) {
  return Eigen::Rotation2Dd(angle).toRotationMatrix();
}
template <>
Mat<3> orientation_matrix<3>(const Eigen::Quaterniond& q) {
  return q.normalized().toRotationMatrix();
}

namespace {

constexpr double kPi = 3.14159265358979323846;

/// Raw integrals of a uniform unit-density region: volume, first moment sum_x, second moment
/// S = int x x^T (about the origin of the frame used).
template <int Dim>
struct Moments {
  double volume = 0.0;
  Vec<Dim> first = Vec<Dim>::Zero();
  Mat<Dim> second = Mat<Dim>::Zero();
};

/// Inertia about the centre of mass from the covariance C = rho int (x - c)(x - c)^T:
/// 3D I = tr(C) Id - C; 2D the polar moment tr(C) (1x1).
template <int Dim>
AngularMat<Dim> inertia_from_covariance(const Mat<Dim>& c) {
  if constexpr (Dim == 2) {
    return AngularMat<2>::Constant(c.trace());
  } else {
    return Mat<3>::Identity() * c.trace() - c;
  }
}

/// Mass properties from the raw moments about the frame origin (the caller adds the origin
/// back to the centre of mass).
template <int Dim>
MassProperties<Dim> finish(const Moments<Dim>& m, double density) {
  MassProperties<Dim> p;
  p.volume = m.volume;
  p.mass = density * m.volume;
  p.center_of_mass = m.first / m.volume;
  // covariance about the centre of mass, scaled by density
  const Mat<Dim> cov =
      density * (m.second - m.volume * p.center_of_mass * p.center_of_mass.transpose());
  p.inertia = inertia_from_covariance<Dim>(cov);
  return p;
}

/// Applies the shape's rotation R about `pivot`: c -> R (c - pivot) + pivot, I -> R I R^T
/// (2D: the polar moment is invariant).
template <int Dim>
MassProperties<Dim> rotate(MassProperties<Dim> p, const ShapeSpec& spec, const Vec<Dim>& pivot) {
  const Mat<Dim> r = rotation_matrix<Dim>(spec.rotation);
  p.center_of_mass = r * (p.center_of_mass - pivot) + pivot;
  if constexpr (Dim == 3) p.inertia = r * p.inertia * r.transpose();
  return p;
}

/// Box of half sizes h: V = prod 2h, I_aa = m/12 sum_{b != a} (2 h_b)^2 (2D polar:
/// m (w^2 + h^2) / 12).
template <int Dim>
MassProperties<Dim> box_properties(const Vec<Dim>& c, const Vec<Dim>& h, double density) {
  MassProperties<Dim> p;
  const Vec<Dim> size = 2.0 * h;
  p.volume = size.prod();
  p.mass = density * p.volume;
  p.center_of_mass = c;
  const Vec<Dim> sq = size.cwiseAbs2();
  if constexpr (Dim == 2) {
    p.inertia(0, 0) = p.mass * (sq[0] + sq[1]) / 12.0;
  } else {
    p.inertia.setZero();
    for (int a = 0; a < 3; ++a) p.inertia(a, a) = p.mass * (sq.sum() - sq[a]) / 12.0;
  }
  return p;
}

/// Solid ball minus the concentric ball of radius r_in (r_in = 0: a full ball / disk).
/// 3D: V = 4/3 pi (R^3 - r^3), I = 2/5 rho 4/3 pi (R^5 - r^5) on every axis.
/// 2D: A = pi (R^2 - r^2), I = rho pi (R^4 - r^4) / 2 (= m (R^2 + r^2) / 2).
template <int Dim>
MassProperties<Dim> ball_properties(const Vec<Dim>& c, double radius, double r_in,
                                    double density) {
  MassProperties<Dim> p;
  p.center_of_mass = c;
  if constexpr (Dim == 2) {
    p.volume = kPi * (radius * radius - r_in * r_in);
    p.mass = density * p.volume;
    p.inertia(0, 0) = density * kPi * (std::pow(radius, 4) - std::pow(r_in, 4)) / 2.0;
  } else {
    p.volume = 4.0 / 3.0 * kPi * (std::pow(radius, 3) - std::pow(r_in, 3));
    p.mass = density * p.volume;
    p.inertia = Mat<3>::Identity() * (density * 8.0 / 15.0 * kPi *
                                      (std::pow(radius, 5) - std::pow(r_in, 5)));
  }
  return p;
}

/// Bowl = the lower half (y <= c_y) of the shell r_in <= |x - c| <= R.
/// 2D half ring: A = pi/2 (R^2 - r^2), first moment int y = -2/3 (R^3 - r^3), polar moment
/// about c = pi/4 (R^4 - r^4). 3D half shell: V = 2/3 pi (R^3 - r^3), int y = -pi/4 (R^4 - r^4),
/// I about c = 4/15 pi (R^5 - r^5) on every axis (half of the full shell's, by symmetry).
/// Then the parallel-axis shift to the centre of mass c + (0, y_c, 0).
template <int Dim>
MassProperties<Dim> bowl_properties(const Vec<Dim>& c, double radius, double r_in,
                                    double density) {
  MassProperties<Dim> p;
  double first_y = 0.0;
  if constexpr (Dim == 2) {
    p.volume = 0.5 * kPi * (radius * radius - r_in * r_in);
    first_y = -2.0 / 3.0 * (std::pow(radius, 3) - std::pow(r_in, 3));
  } else {
    p.volume = 2.0 / 3.0 * kPi * (std::pow(radius, 3) - std::pow(r_in, 3));
    first_y = -kPi / 4.0 * (std::pow(radius, 4) - std::pow(r_in, 4));
  }
  p.mass = density * p.volume;
  const double yc = first_y / p.volume;
  p.center_of_mass = c;
  p.center_of_mass[1] += yc;
  // about c, then shift: axes perpendicular to y lose m yc^2
  if constexpr (Dim == 2) {
    const double ic = density * kPi / 4.0 * (std::pow(radius, 4) - std::pow(r_in, 4));
    p.inertia(0, 0) = ic - p.mass * yc * yc;
  } else {
    const double ic = density * 4.0 / 15.0 * kPi * (std::pow(radius, 5) - std::pow(r_in, 5));
    p.inertia = Mat<3>::Identity() * ic;
    p.inertia(0, 0) -= p.mass * yc * yc;
    p.inertia(2, 2) -= p.mass * yc * yc;
  }
  return p;
}

/// The closed forms and exact integrals of the dimension-specific shapes (polygon, bunny,
/// mesh); returns false when the type has none.
bool dimension_properties(const ShapeSpec& spec, double density, MassProperties<2>* out) {
  std::vector<Vec<2>> outline;
  Vec<2> pivot;
  if (!unrotated_geometry(spec, &outline, &pivot)) return false;
  *out = rotate<2>(polygon_mass_properties(outline, density), spec, pivot);
  return true;
}

bool dimension_properties(const ShapeSpec& spec, double density, MassProperties<3>* out) {
  TriangleMesh m;
  Vec<3> pivot;
  if (!unrotated_geometry(spec, &m, &pivot)) return false;
  *out = rotate<3>(triangle_mesh_mass_properties(m.vertices, m.triangles, density), spec, pivot);
  return true;
}

}  // namespace

bool unrotated_geometry(const ShapeSpec& spec, std::vector<Vec<2>>* outline, Vec<2>* pivot) {
  if (spec.type == ShapeType::polygon) {
    // the vertices as given, rotated about their mean
    outline->clear();
    for (const auto& q : spec.points) outline->emplace_back(q[0], q[1]);
    Vec<2> centroid = Vec<2>::Zero();
    for (const auto& q : *outline) centroid += q;
    *pivot = centroid / static_cast<double>(outline->size());
    return true;
  }
  if (spec.type == ShapeType::bunny) {
    *pivot = to_vec<2>(spec.center);
    *outline = bunny_outline(*pivot, spec.size);
    return true;
  }
  return false;
}

bool unrotated_geometry(const ShapeSpec& spec, TriangleMesh* mesh, Vec<3>* pivot) {
  if (spec.type == ShapeType::mesh) {
    // the unrotated mesh, as make_shape reads it (flipped if inward-oriented)
    ShapeSpec plain = spec;
    plain.rotation.clear();
    const ShapePtr<3> shape = make_shape<3>(plain, "mesh");
    const auto* mesh_shape = dynamic_cast<const MeshShape*>(shape.get());
    if (!mesh_shape) return false;
    *mesh = mesh_shape->sdf().mesh();
    *pivot = spec.translate.empty() ? Vec<3>(Vec<3>::Zero()) : to_vec<3>(spec.translate);
    return true;
  }
  if (spec.type == ShapeType::bunny) {
    *pivot = to_vec<3>(spec.center);
    *mesh = placed_bunny_mesh(*pivot, spec.size);
    return true;
  }
  return false;
}

std::vector<Vec<2>> bunny_outline(const Vec<2>& center, double size) {
  const auto& raw = bunny_silhouette_points();
  Box<2> b;
  for (const auto& p : raw) b.extend(p);
  const double s = size / b.sizes().maxCoeff();
  std::vector<Vec<2>> pts;
  pts.reserve(raw.size());
  for (const auto& p : raw) pts.push_back(center + s * (p - b.center()));
  return pts;
}

// --- exact polygon and mesh integrals ---------------------------------------------------------

MassProperties<2> polygon_mass_properties(const std::vector<Vec<2>>& points, double density) {
  // Green's theorem per edge (p, q), relative to the first vertex for accuracy, with
  // c = p x q: A = 1/2 sum c, int x = 1/6 sum c (p + q),
  // int x x^T = 1/12 sum c (p p^T + q q^T + (p q^T + q p^T) / 2)
  const std::size_t n = points.size();
  const Vec<2> o = points.front();
  Moments<2> m;
  for (std::size_t i = 0; i < n; ++i) {
    const Vec<2> p = points[i] - o;
    const Vec<2> q = points[(i + 1) % n] - o;
    const double c = p[0] * q[1] - p[1] * q[0];
    m.volume += 0.5 * c;
    m.first += c * (p + q) / 6.0;
    m.second += c / 12.0 *
                (p * p.transpose() + q * q.transpose() +
                 0.5 * (p * q.transpose() + q * p.transpose()));
  }
  // clockwise vertices give negated integrals
  if (m.volume < 0.0) {
    m.volume = -m.volume;
    m.first = -m.first;
    m.second = -m.second;
  }
  MassProperties<2> r = finish<2>(m, density);
  r.center_of_mass += o;
  return r;
}

MassProperties<3> triangle_mesh_mass_properties(const std::vector<Vec<3>>& vertices,
                                                const std::vector<std::array<int, 3>>& triangles,
                                                double density) {
  // signed tetrahedra (o, a, b, c) with o the bounding-box centre: V = det / 6,
  // int x = V (a + b + c) / 4, int x x^T = V / 20 (sum v v^T + s s^T), s = a + b + c (o = 0)
  Box<3> box;
  for (const auto& v : vertices) box.extend(v);
  const Vec<3> o = box.center();
  Moments<3> m;
  for (const auto& t : triangles) {
    const Vec<3> a = vertices[t[0]] - o, b = vertices[t[1]] - o, c = vertices[t[2]] - o;
    const double v = a.dot(b.cross(c)) / 6.0;
    const Vec<3> s = a + b + c;
    m.volume += v;
    m.first += v * s / 4.0;
    m.second += v / 20.0 *
                (a * a.transpose() + b * b.transpose() + c * c.transpose() + s * s.transpose());
  }
  MassProperties<3> r = finish<3>(m, density);
  r.center_of_mass += o;
  return r;
}

// --- numerical integration ----------------------------------------------------------------------

template <int Dim>
MassProperties<Dim> integrate_mass_properties(const Shape<Dim>& shape, const Box<Dim>& region,
                                              int cells_per_axis, double density) {
  // cubic cells of width h covering region, padded by one cell
  const double h = region.sizes().maxCoeff() / std::max(cells_per_axis, 1);
  const Vec<Dim> origin = region.min().array() - h;
  VecI<Dim> n;
  long long total = 1;
  for (int a = 0; a < Dim; ++a) {
    n[a] = static_cast<int>(std::ceil(region.sizes()[a] / h)) + 2;
    total *= n[a];
  }
  const Vec<Dim> ref = region.center();
  const double cell_volume = std::pow(h, Dim);
  // each cell: fraction clamp(1/2 - d/h, 0, 1) of its volume at its centre, plus its own
  // second moment h^2/12 per axis
  // Partial sums over fixed blocks of cells, added in block order: the same bits for any thread
  // count and any run (a critical section would add the threads' sums in arrival order).
  constexpr long long kBlock = 4096;
  const long long blocks = (total + kBlock - 1) / kBlock;
  std::vector<double> vol_b(static_cast<std::size_t>(blocks), 0.0);
  std::vector<Vec<Dim>> first_b(static_cast<std::size_t>(blocks), Vec<Dim>::Zero());
  std::vector<Mat<Dim>> second_b(static_cast<std::size_t>(blocks), Mat<Dim>::Zero());
#pragma omp parallel for schedule(static) num_threads(process_threads())
  for (long long b = 0; b < blocks; ++b) {
    double vol_t = 0.0;
    Vec<Dim> first_t = Vec<Dim>::Zero();
    Mat<Dim> second_t = Mat<Dim>::Zero();
    const long long end = std::min(total, (b + 1) * kBlock);
    for (long long i = b * kBlock; i < end; ++i) {
      long long r = i;
      Vec<Dim> x;
      for (int a = 0; a < Dim; ++a) {
        x[a] = origin[a] + (static_cast<double>(r % n[a]) + 0.5) * h;
        r /= n[a];
      }
      const double f = std::clamp(0.5 - shape.distance(x) / h, 0.0, 1.0);
      if (f == 0.0) continue;
      const Vec<Dim> y = x - ref;
      vol_t += f;
      first_t += f * y;
      second_t += f * (y * y.transpose() + Mat<Dim>::Identity() * (h * h / 12.0));
    }
    vol_b[b] = vol_t;
    first_b[b] = first_t;
    second_b[b] = second_t;
  }
  double vol = 0.0;
  std::vector<double> acc(Dim + Dim * Dim, 0.0);
  for (long long b = 0; b < blocks; ++b) {
    vol += vol_b[b];
    for (int a = 0; a < Dim; ++a) acc[a] += first_b[b][a];
    for (int a = 0; a < Dim * Dim; ++a) acc[Dim + a] += second_b[b].data()[a];
  }
  Moments<Dim> m;
  m.volume = vol * cell_volume;
  for (int a = 0; a < Dim; ++a) m.first[a] = acc[a] * cell_volume;
  for (int a = 0; a < Dim * Dim; ++a) m.second.data()[a] = acc[Dim + a] * cell_volume;
  if (!(m.volume > 0.0)) {
    MassProperties<Dim> empty;
    empty.center_of_mass = ref;
    return empty;
  }
  MassProperties<Dim> p = finish<Dim>(m, density);
  p.center_of_mass += ref;
  return p;
}

// --- mass_properties ----------------------------------------------------------------------------

template <int Dim>
MassProperties<Dim> mass_properties(const ShapeSpec& spec, const Shape<Dim>& shape,
                                    double density) {
  const ShapeType t = spec.type;
  if (t == ShapeType::box) {
    const Vec<Dim> c = to_vec<Dim>(spec.center);
    return rotate<Dim>(box_properties<Dim>(c, to_vec<Dim>(spec.half_size), density), spec, c);
  }
  if (t == ShapeType::sphere) return ball_properties<Dim>(to_vec<Dim>(spec.center), spec.radius, 0.0, density);
  if (t == ShapeType::shell) {
    return ball_properties<Dim>(to_vec<Dim>(spec.center), spec.radius,
                                spec.radius - spec.thickness, density);
  }
  if (t == ShapeType::bowl) {
    const Vec<Dim> c = to_vec<Dim>(spec.center);
    return rotate<Dim>(bowl_properties<Dim>(c, spec.radius, spec.radius - spec.thickness, density),
                       spec, c);
  }
  if (t == ShapeType::halfspace) {
    throw InputError("shape.type: a halfspace has no finite volume (a bounded shape for a "
                     "dynamic or kinematic body)");
  }
  MassProperties<Dim> p;
  if (dimension_properties(spec, density, &p)) return p;
  // union, difference, anything else: lattice integration of the SDF
  const Box<Dim> b = shape.bounds();
  if (b.isEmpty() || !b.min().allFinite() || !b.max().allFinite()) {
    throw InputError("shape.type: \"" + enum_name(t) +
                     "\" is unbounded (a bounded shape for a dynamic or kinematic body)");
  }
  return integrate_mass_properties<Dim>(shape, b, Dim == 2 ? kIntegrationCells2d
                                                            : kIntegrationCells3d, density);
}

template MassProperties<2> mass_properties<2>(const ShapeSpec&, const Shape<2>&, double);
template MassProperties<3> mass_properties<3>(const ShapeSpec&, const Shape<3>&, double);
template MassProperties<2> integrate_mass_properties<2>(const Shape<2>&, const Box<2>&, int, double);
template MassProperties<3> integrate_mass_properties<3>(const Shape<3>&, const Box<3>&, int, double);

}  // namespace monolith
