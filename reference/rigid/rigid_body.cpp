/// \file rigid_body.cpp
/// Rigid-body state, posed SDF, time integration, kinematic paths, surface samples and
/// make_bodies. docs/rigid-bodies.md describes the conventions.

#include "reference/rigid/rigid_body.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

#include "dim2/shapes_2d.hpp"
#include "dim3/shapes_3d.hpp"
#include "reference/core/errors.hpp"
#include "reference/core/periodic_image.hpp"
#include "reference/geometry/shape_tools.hpp"

namespace monolith {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kInf = std::numeric_limits<double>::infinity();

/// The image x + k period (k integer per axis) of x nearest `center` along the axes with
/// period[a] > 0 (RigidBody::set_periodic).
template <int Dim>
Vec<Dim> nearest_periodic_image(const Vec<Dim>& x, const Vec<Dim>& center, const Vec<Dim>& period) {
  return x - periodic_image_shift<Dim>(x - center, period);
}

/// The rest shape seen at a pose: distance(x) = rest.distance(R^T (x - p) + c_rest), the
/// gradient rotated by R. A rigid motion keeps an exact SDF exact.
template <int Dim>
class PosedShape : public Shape<Dim> {
 public:
  PosedShape(ShapePtr<Dim> rest, const Mat<Dim>& r, const Vec<Dim>& position,
             const Vec<Dim>& rest_com, const Box<Dim>& bounds,
             const Vec<Dim>& period = Vec<Dim>::Zero())
      : rest_(std::move(rest)), r_(r), position_(position), rest_com_(rest_com), bounds_(bounds),
        period_(period), periodic_(period.maxCoeff() > 0.0) {}
  double distance(const Vec<Dim>& x) const override { return rest_->distance(to_rest(x)); }
  Vec<Dim> gradient(const Vec<Dim>& x) const override { return r_ * rest_->gradient(to_rest(x)); }
  Box<Dim> bounds() const override { return bounds_; }

 private:
  Vec<Dim> to_rest(const Vec<Dim>& x) const {
    // periodic axes: the image of x nearest the body (RigidBody::set_periodic)
    if (periodic_) return r_.transpose() * (nearest_periodic_image<Dim>(x, position_, period_) - position_) + rest_com_;
    return r_.transpose() * (x - position_) + rest_com_;
  }
  ShapePtr<Dim> rest_;
  Mat<Dim> r_;
  Vec<Dim> position_, rest_com_;
  Box<Dim> bounds_;
  Vec<Dim> period_;
  bool periodic_ = false;
};

/// A box (centre c, half sizes h, rotated by R about c) with the exact SDF gradient: the
/// shape library's box differentiates numerically, which errs by about step / (4 d) next to an
/// edge (d the distance), i.e. badly for the resting contacts of stacked boxes whose edges
/// line up. distance() is the wrapped shape's.
template <int Dim>
class ExactBoxGradient : public Shape<Dim> {
 public:
  ExactBoxGradient(ShapePtr<Dim> box, const Vec<Dim>& c, const Vec<Dim>& h, const Mat<Dim>& r)
      : box_(std::move(box)), c_(c), h_(h), r_(r) {}
  double distance(const Vec<Dim>& x) const override { return box_->distance(x); }
  Vec<Dim> gradient(const Vec<Dim>& x) const override {
    // box frame: q = |y| - h; outside the direction of max(q, 0), inside (and on the
    // surface) the nearest face, or the bisector of the faces tied within rounding (edges and
    // corners: the mean of the one-sided normals)
    const Vec<Dim> y = r_.transpose() * (x - c_);
    const Vec<Dim> q = y.cwiseAbs() - h_;
    const double tol = 1e-10 * h_.maxCoeff();
    Vec<Dim> g = Vec<Dim>::Zero();
    if (q.maxCoeff() > tol) {
      // components within rounding of a face plane count as on it
      for (int a = 0; a < Dim; ++a) g[a] = q[a] > tol ? q[a] : 0.0;
    } else {
      for (int a = 0; a < Dim; ++a) g[a] = q[a] >= q.maxCoeff() - tol ? 1.0 : 0.0;
    }
    g.normalize();
    for (int a = 0; a < Dim; ++a) g[a] = y[a] < 0.0 ? -g[a] : g[a];
    return r_ * g;
  }
  Box<Dim> bounds() const override { return box_->bounds(); }

 private:
  ShapePtr<Dim> box_;
  Vec<Dim> c_, h_;
  Mat<Dim> r_;
};

template <int Dim>
Vec<Dim> vec_or_zero(const std::vector<double>& v) {
  return static_cast<int>(v.size()) == Dim ? to_vec<Dim>(v) : Vec<Dim>(Vec<Dim>::Zero());
}

template <int Dim>
AngularVec<Dim> angular_or_zero(const std::vector<double>& v) {
  AngularVec<Dim> w = AngularVec<Dim>::Zero();
  if (static_cast<int>(v.size()) == kAngularDofs<Dim>) {
    for (int a = 0; a < kAngularDofs<Dim>; ++a) w[a] = v[a];
  }
  return w;
}

/// Orientation after rotating `q` by the world-frame rotation vector w (exact exponential).
double rotate_orientation(double angle, const AngularVec<2>& w) { return angle + w[0]; }
Eigen::Quaterniond rotate_orientation(const Eigen::Quaterniond& q, const AngularVec<3>& w) {
  const double angle = w.norm();
  if (angle == 0.0) return q;
  return (Eigen::Quaterniond(Eigen::AngleAxisd(angle, w / angle)) * q).normalized();
}

bool is_bounded(const Box<2>& b) { return !b.isEmpty() && b.min().allFinite() && b.max().allFinite(); }
bool is_bounded(const Box<3>& b) { return !b.isEmpty() && b.min().allFinite() && b.max().allFinite(); }

// --- surface samples ---------------------------------------------------------------------------

/// Removes samples closer than a quarter spacing to an earlier one (quantised keys), keeping
/// the first occurrence: deterministic.
template <int Dim>
std::vector<Vec<Dim>> deduplicate(const std::vector<Vec<Dim>>& pts, double spacing) {
  const double q = 0.25 * spacing;
  std::set<std::array<long long, Dim>> seen;
  std::vector<Vec<Dim>> out;
  out.reserve(pts.size());
  for (const auto& p : pts) {
    std::array<long long, Dim> key;
    for (int a = 0; a < Dim; ++a) key[a] = std::llround(p[a] / q);
    if (seen.insert(key).second) out.push_back(p);
  }
  return out;
}

/// Box surface: the nodes of a lattice of about `spacing` that lie on the faces (corners and
/// edges included once).
template <int Dim>
std::vector<Vec<Dim>> box_samples(const Vec<Dim>& c, const Vec<Dim>& h, double spacing) {
  VecI<Dim> n;
  for (int a = 0; a < Dim; ++a) n[a] = std::max(1, static_cast<int>(std::ceil(2.0 * h[a] / spacing)));
  std::vector<Vec<Dim>> pts;
  // face (a, side): index of axis a fixed at 0 or n_a; axes b < a strictly interior so that
  // shared edges and corners are generated by the lowest axis only
  for (int a = 0; a < Dim; ++a) {
    for (int side = 0; side < 2; ++side) {
      VecI<Dim> lo = VecI<Dim>::Zero(), hi = n;
      for (int b = 0; b < a; ++b) {
        lo[b] = 1;
        hi[b] = n[b] - 1;
      }
      lo[a] = hi[a] = side ? n[a] : 0;
      bool empty = false;
      for (int b = 0; b < Dim; ++b) empty = empty || lo[b] > hi[b];
      if (empty) continue;
      VecI<Dim> i = lo;
      while (true) {
        Vec<Dim> x;
        for (int b = 0; b < Dim; ++b) x[b] = c[b] - h[b] + 2.0 * h[b] * i[b] / n[b];
        pts.push_back(x);
        int b = 0;
        for (; b < Dim; ++b) {
          if (++i[b] <= hi[b]) break;
          i[b] = lo[b];
        }
        if (b == Dim) break;
      }
    }
  }
  return pts;
}

/// Sphere: 2D evenly spaced on the circle; 3D a Fibonacci lattice of about area / spacing^2
/// points.
template <int Dim>
std::vector<Vec<Dim>> sphere_samples(const Vec<Dim>& c, double r, double spacing) {
  std::vector<Vec<Dim>> pts;
  if constexpr (Dim == 2) {
    const int n = std::max(8, static_cast<int>(std::ceil(2.0 * kPi * r / spacing)));
    for (int i = 0; i < n; ++i) {
      const double t = 2.0 * kPi * i / n;
      pts.push_back(c + r * Vec<2>(std::cos(t), std::sin(t)));
    }
  } else {
    const int n = std::max(20, static_cast<int>(std::ceil(4.0 * kPi * r * r / (spacing * spacing))));
    const double golden = kPi * (3.0 - std::sqrt(5.0));
    for (int i = 0; i < n; ++i) {
      const double y = 1.0 - 2.0 * (i + 0.5) / n;
      const double rho = std::sqrt(std::max(0.0, 1.0 - y * y));
      const double t = golden * i;
      pts.push_back(c + r * Vec<3>(rho * std::cos(t), y, rho * std::sin(t)));
    }
  }
  return pts;
}

/// Closed polygon: the vertices and points along every edge at about `spacing`.
std::vector<Vec<2>> polyline_samples(const std::vector<Vec<2>>& v, double spacing) {
  std::vector<Vec<2>> pts;
  for (std::size_t i = 0; i < v.size(); ++i) {
    const Vec<2>& a = v[i];
    const Vec<2>& b = v[(i + 1) % v.size()];
    const int n = std::max(1, static_cast<int>(std::ceil((b - a).norm() / spacing)));
    for (int k = 0; k < n; ++k) pts.push_back(a + (b - a) * (static_cast<double>(k) / n));
  }
  return pts;
}

/// Triangle mesh: the vertices plus, on triangles whose longest edge exceeds `spacing`, the
/// points of a barycentric lattice with m = ceil(longest / spacing) intervals per edge.
std::vector<Vec<3>> mesh_samples(const TriangleMesh& mesh, double spacing) {
  std::vector<Vec<3>> pts = mesh.vertices;
  for (const auto& t : mesh.triangles) {
    const Vec<3>& a = mesh.vertices[t[0]];
    const Vec<3>& b = mesh.vertices[t[1]];
    const Vec<3>& c = mesh.vertices[t[2]];
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    if (longest <= spacing) continue;
    const int m = static_cast<int>(std::ceil(longest / spacing));
    for (int i = 0; i <= m; ++i) {
      for (int j = 0; i + j <= m; ++j) {
        if ((i == 0 && j == 0) || (i == m) || (j == m)) continue;  // the vertices
        pts.push_back(a + (b - a) * (static_cast<double>(i) / m) + (c - a) * (static_cast<double>(j) / m));
      }
    }
  }
  return pts;
}

/// Any bounded shape: lattice nodes (spacing apart) within half a spacing of the surface,
/// projected onto it by three Newton steps x -= d grad d; kept if |d| < 1e-3 spacing after.
template <int Dim>
std::vector<Vec<Dim>> level_set_samples(const Shape<Dim>& shape, double spacing) {
  const Box<Dim> b = shape.bounds();
  std::vector<Vec<Dim>> pts;
  if (!is_bounded(b)) return pts;
  const Vec<Dim> origin = b.min().array() - spacing;
  VecI<Dim> n;
  long long total = 1;
  for (int a = 0; a < Dim; ++a) {
    n[a] = static_cast<int>(std::ceil(b.sizes()[a] / spacing)) + 3;
    total *= n[a];
  }
  for (long long i = 0; i < total; ++i) {
    long long r = i;
    Vec<Dim> x;
    for (int a = 0; a < Dim; ++a) {
      x[a] = origin[a] + static_cast<double>(r % n[a]) * spacing;
      r /= n[a];
    }
    double d = shape.distance(x);
    if (std::abs(d) >= 0.5 * spacing) continue;
    for (int k = 0; k < 3 && std::abs(d) > 1e-9 * spacing; ++k) {
      x -= d * shape.gradient(x);
      d = shape.distance(x);
    }
    if (std::abs(d) < 1e-3 * spacing) pts.push_back(x);
  }
  return pts;
}

/// Applies the shape's rotation about `pivot` to rest-frame points of the unrotated shape.
template <int Dim>
void rotate_points(std::vector<Vec<Dim>>* pts, const ShapeSpec& spec, const Vec<Dim>& pivot) {
  const Mat<Dim> r = rotation_matrix<Dim>(spec.rotation);
  for (auto& p : *pts) p = r * (p - pivot) + pivot;
}

/// Samples of the dimension-specific shapes (2D polygon and bunny outline, 3D mesh and bunny);
/// false when the type is not one of them.
bool dimension_samples(const ShapeSpec& spec, double spacing, std::vector<Vec<2>>* out) {
  std::vector<Vec<2>> outline;
  Vec<2> pivot;
  if (!unrotated_geometry(spec, &outline, &pivot)) return false;
  *out = polyline_samples(outline, spacing);
  rotate_points<2>(out, spec, pivot);
  return true;
}

bool dimension_samples(const ShapeSpec& spec, double spacing, std::vector<Vec<3>>* out) {
  TriangleMesh m;
  Vec<3> pivot;
  if (!unrotated_geometry(spec, &m, &pivot)) return false;
  *out = mesh_samples(m, spacing);
  rotate_points<3>(out, spec, pivot);
  return true;
}

}  // namespace

template <int Dim>
std::vector<Vec<Dim>> make_surface_samples(const ShapeSpec& spec, const Shape<Dim>& shape,
                                           double spacing) {
  std::vector<Vec<Dim>> pts;
  if (!is_bounded(shape.bounds()) || !(spacing > 0.0)) return pts;
  if (spec.type == ShapeType::box) {
    const Vec<Dim> c = to_vec<Dim>(spec.center);
    pts = box_samples<Dim>(c, to_vec<Dim>(spec.half_size), spacing);
    rotate_points<Dim>(&pts, spec, c);
  } else if (spec.type == ShapeType::sphere) {
    pts = sphere_samples<Dim>(to_vec<Dim>(spec.center), spec.radius, spacing);
  } else if (spec.type == ShapeType::shell) {
    // outer and inner spheres
    const Vec<Dim> c = to_vec<Dim>(spec.center);
    pts = sphere_samples<Dim>(c, spec.radius, spacing);
    const auto inner = sphere_samples<Dim>(c, spec.radius - spec.thickness, spacing);
    pts.insert(pts.end(), inner.begin(), inner.end());
  } else if (!dimension_samples(spec, spacing, &pts)) {
    pts = level_set_samples<Dim>(shape, spacing);
  }
  return deduplicate<Dim>(pts, spacing);
}

// --- RigidBody -----------------------------------------------------------------------------------

template <int Dim>
RigidBody<Dim>::RigidBody(const BodySpec& spec, ShapePtr<Dim> shape,
                          const MassProperties<Dim>& props, double sample_spacing)
    : name(spec.name),
      motion(spec.motion),
      friction(spec.friction),
      restitution(spec.restitution),
      path(spec.path),
      has_path(spec.has_path),
      mass(props.mass),
      volume(props.volume),
      inertia_body(props.inertia),
      position(props.center_of_mass),
      orientation(RigidTraits<Dim>::identity()),
      velocity(Vec<Dim>::Zero()),
      angular_velocity(AngularVec<Dim>::Zero()),
      rest_shape_(std::move(shape)),
      rest_com_(props.center_of_mass),
      shape_type_(spec.shape.type) {
  if (spec.shape.type == ShapeType::box) {
    // exact gradients for boxes (collision normals at edges)
    is_box_ = true;
    box_center_ = to_vec<Dim>(spec.shape.center);
    box_half_ = to_vec<Dim>(spec.shape.half_size);
    box_rotation_ = rotation_matrix<Dim>(spec.shape.rotation);
    rest_shape_ = std::make_shared<ExactBoxGradient<Dim>>(rest_shape_, box_center_, box_half_,
                                                          box_rotation_);
  }
  rest_bounds_ = rest_shape_->bounds();
  initial_velocity_ = vec_or_zero<Dim>(spec.velocity);
  initial_angular_velocity_ = angular_or_zero<Dim>(spec.angular_velocity);
  // principal axes of the body inertia (3D torque-free integration)
  if constexpr (Dim == 3) {
    if (inertia_body.trace() > 0.0) {
      Eigen::SelfAdjointEigenSolver<Mat<3>> eig(inertia_body);
      principal_axes_ = eig.eigenvectors();
      if (principal_axes_.determinant() < 0.0) principal_axes_.col(2) *= -1.0;
      principal_moments_ = eig.eigenvalues();
    }
  }
  // surface samples: spacing from the argument or the body size, never above 1/4 of the
  // smallest extent
  if (is_bounded(rest_bounds_)) {
    const double smallest = rest_bounds_.sizes().minCoeff();
    double s = sample_spacing > 0.0 ? sample_spacing : smallest / 8.0;
    s = std::min(s, smallest / 4.0);
    sample_spacing_ = s;
    samples_ = make_surface_samples<Dim>(spec.shape, *rest_shape_, s);
  }
  if (spec.shape.type == ShapeType::sphere) {
    is_sphere_ = true;
    sphere_radius_ = spec.shape.radius;
  }
  // initial state by motion type
  if (motion == BodyMotion::dynamic) {
    velocity = initial_velocity_;
    angular_velocity = initial_angular_velocity_;
  } else if (motion == BodyMotion::kinematic) {
    set_kinematic_state(0.0);
  }
}

template <int Dim>
Mat<Dim> RigidBody<Dim>::rotation() const {
  return orientation_matrix<Dim>(orientation);
}

template <int Dim>
AngularMat<Dim> RigidBody<Dim>::world_inertia() const {
  if constexpr (Dim == 2) {
    return inertia_body;
  } else {
    const Mat<3> r = rotation();
    return r * inertia_body * r.transpose();
  }
}

template <int Dim>
AngularMat<Dim> RigidBody<Dim>::world_inverse_inertia() const {
  // zero for bodies without inertia (fixed bodies of zero density)
  if (!(inertia_body.trace() > 0.0)) return AngularMat<Dim>::Zero();
  if constexpr (Dim == 2) {
    return AngularMat<2>::Constant(1.0 / inertia_body(0, 0));
  } else {
    const Mat<3> r = rotation();
    return r * inertia_body.inverse() * r.transpose();
  }
}

template <int Dim>
Vec<Dim> RigidBody<Dim>::to_world(const Vec<Dim>& x_rest) const {
  return rotation() * (x_rest - rest_com_) + position;
}

template <int Dim>
Vec<Dim> RigidBody<Dim>::to_rest(const Vec<Dim>& x_world) const {
  if (periodic_) return rotation().transpose() * (nearest_image(x_world) - position) + rest_com_;
  return rotation().transpose() * (x_world - position) + rest_com_;
}

template <int Dim>
Vec<Dim> RigidBody<Dim>::point_velocity(const Vec<Dim>& x_world) const {
  if (periodic_) return velocity + angular_cross<Dim>(angular_velocity, nearest_image(x_world) - position);
  return velocity + angular_cross<Dim>(angular_velocity, x_world - position);
}

template <int Dim>
void RigidBody<Dim>::set_periodic(const Vec<Dim>& lower, const Vec<Dim>& period) {
  domain_lower_ = lower;
  period_ = period.cwiseMax(0.0);
  periodic_ = period_.maxCoeff() > 0.0;
}

template <int Dim>
Vec<Dim> RigidBody<Dim>::nearest_image(const Vec<Dim>& x_world) const {
  return periodic_ ? nearest_periodic_image<Dim>(x_world, position, period_) : x_world;
}

template <int Dim>
double RigidBody<Dim>::distance(const Vec<Dim>& x_world) const {
  return rest_shape_->distance(to_rest(x_world));
}

template <int Dim>
Vec<Dim> RigidBody<Dim>::gradient(const Vec<Dim>& x_world) const {
  return rotation() * rest_shape_->gradient(to_rest(x_world));
}

template <int Dim>
double RigidBody<Dim>::normal_cone_cosine(const Vec<Dim>& x_world, const Vec<Dim>& n_world) const {
  if (!is_box_) return n_world.dot(gradient(x_world));
  // box frame: the faces through x are the axes with |y_a| = h_a (within rounding); the
  // nearest direction of the cone keeps the components of n along those axes that point
  // outwards, so its cosine with the unit n is the norm of that part
  const Mat<Dim> r = rotation() * box_rotation_;
  const Vec<Dim> y = box_rotation_.transpose() * (to_rest(x_world) - box_center_);
  const Vec<Dim> n = r.transpose() * n_world;
  const double tol = 1e-9 * box_half_.maxCoeff();
  Vec<Dim> m = Vec<Dim>::Zero();
  for (int a = 0; a < Dim; ++a) {
    if (std::abs(y[a]) < box_half_[a] - tol) continue;
    m[a] = std::max(y[a] < 0.0 ? -n[a] : n[a], 0.0);
  }
  return m.norm();
}

template <int Dim>
bool RigidBody<Dim>::box_face_normal(const Vec<Dim>& x_world, Vec<Dim>* normal) const {
  if (!is_box_) return false;
  // the axes whose face planes pass through x (within rounding)
  const Vec<Dim> y = box_rotation_.transpose() * (to_rest(x_world) - box_center_);
  const double tol = 1e-9 * box_half_.maxCoeff();
  int active = 0, axis = 0;
  for (int a = 0; a < Dim; ++a) {
    if (std::abs(y[a]) >= box_half_[a] - tol) {
      ++active;
      axis = a;
    }
  }
  if (active != 1) return false;
  Vec<Dim> n = Vec<Dim>::Zero();
  n[axis] = y[axis] < 0.0 ? -1.0 : 1.0;
  *normal = rotation() * (box_rotation_ * n);
  return true;
}

template <int Dim>
Box<Dim> RigidBody<Dim>::bounds() const {
  const Mat<Dim> r = rotation();
  const Vec<Dim> shift = position - rest_com_;
  if (!is_bounded(rest_bounds_)) {
    // unbounded: only a pure translation keeps the bounds
    if ((r - Mat<Dim>::Identity()).norm() > 1e-14) {
      return Box<Dim>(Vec<Dim>::Constant(-kInf), Vec<Dim>::Constant(kInf));
    }
    return Box<Dim>(rest_bounds_.min() + shift, rest_bounds_.max() + shift);
  }
  // the box of the 2^Dim posed corners of the rest bounds
  Box<Dim> b;
  for (int corner = 0; corner < (1 << Dim); ++corner) {
    Vec<Dim> c;
    for (int a = 0; a < Dim; ++a) c[a] = (corner >> a) & 1 ? rest_bounds_.max()[a] : rest_bounds_.min()[a];
    b.extend(to_world(c));
  }
  if (periodic_) {
    // a shape across a face of a periodic axis is also seen at its image on the other side:
    // the whole axis (set_periodic)
    for (int a = 0; a < Dim; ++a) {
      if (!(period_[a] > 0.0)) continue;
      const double lo = domain_lower_[a], hi = domain_lower_[a] + period_[a];
      if (b.min()[a] < lo || b.max()[a] > hi) {
        b.min()[a] = lo;
        b.max()[a] = hi;
      }
    }
  }
  return b;
}

template <int Dim>
ShapePtr<Dim> RigidBody<Dim>::posed_shape() const {
  if (periodic_)
    return std::make_shared<PosedShape<Dim>>(rest_shape_, rotation(), position, rest_com_, bounds(), period_);
  return std::make_shared<PosedShape<Dim>>(rest_shape_, rotation(), position, rest_com_, bounds());
}

template <int Dim>
BodyVec<Dim> RigidBody<Dim>::generalized_velocity() const {
  BodyVec<Dim> u;
  u.template head<Dim>() = velocity;
  u.template tail<kAngularDofs<Dim>>() = angular_velocity;
  return u;
}

template <int Dim>
void RigidBody<Dim>::set_generalized_velocity(const BodyVec<Dim>& u) {
  velocity = u.template head<Dim>();
  angular_velocity = u.template tail<kAngularDofs<Dim>>();
}

template <int Dim>
double RigidBody<Dim>::kinetic_energy() const {
  if (motion != BodyMotion::dynamic) return 0.0;
  return 0.5 * mass * velocity.squaredNorm() +
         0.5 * angular_velocity.dot(world_inertia() * angular_velocity);
}

template <int Dim>
AngularVec<Dim> RigidBody<Dim>::angular_momentum() const {
  return world_inertia() * angular_velocity;
}

template <int Dim>
void RigidBody<Dim>::integrate(double dt, double t_new) {
  if (motion == BodyMotion::fixed) return;
  if (motion == BodyMotion::kinematic) {
    set_kinematic_state(t_new);
    return;
  }
  // symplectic Euler: the new velocity moves the position
  position += dt * velocity;
  if (periodic_) {
    // a centre of mass that left through a periodic face comes back through the other
    for (int a = 0; a < Dim; ++a) {
      if (!(period_[a] > 0.0)) continue;
      const double k = std::floor((position[a] - domain_lower_[a]) / period_[a]);
      if (k != 0.0) position[a] -= k * period_[a];
    }
  }
  if constexpr (Dim == 2) {
    // 2D: omega is constant without torque, the rotation is exact
    orientation += dt * angular_velocity[0];
  } else {
    if (!(principal_moments_.minCoeff() > 0.0) || angular_velocity.squaredNorm() == 0.0) {
      orientation = rotate_orientation(orientation, AngularVec<3>(dt * angular_velocity));
      return;
    }
    // torque-free motion: body angular momentum in principal coordinates m = P^T I R^T omega,
    // Strang splitting H = H_0 + H_1 + H_2 (H_k = m_k^2 / (2 I_k)) as 0(h/2) 1(h/2) 2(h)
    // 1(h/2) 0(h/2); the flow of H_k rotates the body about principal axis k by
    // theta = m_k / I_k tau and m by -theta about e_k, so L = R P m is kept exactly
    Mat<3> r = rotation();
    Vec<3> m = principal_axes_.transpose() * (inertia_body * (r.transpose() * angular_velocity));
    static constexpr int kAxes[5] = {0, 1, 2, 1, 0};
    static constexpr double kWeights[5] = {0.5, 0.5, 1.0, 0.5, 0.5};
    Eigen::Quaterniond q = orientation;
    for (int s = 0; s < 5; ++s) {
      const int k = kAxes[s];
      const double theta = m[k] / principal_moments_[k] * kWeights[s] * dt;
      q = q * Eigen::Quaterniond(Eigen::AngleAxisd(theta, principal_axes_.col(k)));
      m = Eigen::AngleAxisd(-theta, Vec<3>::Unit(k)) * m;
    }
    orientation = q.normalized();
    // omega = R I^-1 L_body at the new pose
    r = rotation();
    angular_velocity = r * (inertia_body.inverse() * (principal_axes_ * m));
  }
}

template <int Dim>
void RigidBody<Dim>::set_kinematic_state(double t) {
  // constant initial velocity and spin, plus the oscillating path
  position = rest_com_ + t * initial_velocity_;
  velocity = initial_velocity_;
  if (has_path && static_cast<int>(path.axis.size()) == Dim) {
    const Vec<Dim> axis = to_vec<Dim>(path.axis);
    const double w = 2.0 * kPi * path.frequency;
    position += axis * (path.amplitude * std::sin(w * t));
    velocity += axis * (path.amplitude * w * std::cos(w * t));
  }
  angular_velocity = initial_angular_velocity_;
  orientation = rotate_orientation(RigidTraits<Dim>::identity(), AngularVec<Dim>(t * initial_angular_velocity_));
}

// --- make_bodies ---------------------------------------------------------------------------------

template <int Dim>
std::vector<RigidBody<Dim>> make_bodies(const SceneDesc& scene, double sample_spacing) {
  const double spacing = sample_spacing > 0.0 ? sample_spacing : 0.5 * scene.dx();
  std::vector<RigidBody<Dim>> bodies;
  bodies.reserve(scene.bodies.size());
  for (std::size_t i = 0; i < scene.bodies.size(); ++i) {
    const BodySpec& spec = scene.bodies[i];
    const std::string key = "bodies[" + std::to_string(i) + "].shape";
    ShapePtr<Dim> shape = make_shape<Dim>(spec.shape, key);
    MassProperties<Dim> props;
    const Box<Dim> b = shape->bounds();
    const bool lattice_only =
        spec.shape.type == ShapeType::set_union || spec.shape.type == ShapeType::set_difference;
    if (spec.motion == BodyMotion::fixed && (!is_bounded(b) || lattice_only)) {
      // fixed bodies need no mass: the reference point is the centre of the bounds (origin if
      // unbounded) and the lattice integration is skipped
      props.center_of_mass = is_bounded(b) ? Vec<Dim>(b.center()) : Vec<Dim>(Vec<Dim>::Zero());
    } else {
      try {
        props = mass_properties<Dim>(spec.shape, *shape, spec.density);
      } catch (const InputError& e) {
        throw InputError(key + ": " + e.what());
      }
    }
    bodies.emplace_back(spec, std::move(shape), props, spacing);
  }
  // periodic axes of the domain (RigidBody::set_periodic)
  Vec<Dim> lower = Vec<Dim>::Zero(), period = Vec<Dim>::Zero();
  for (int a = 0; a < Dim; ++a) {
    lower[a] = scene.domain.lower[a];
    if (scene.domain.boundary[2 * a] == BoundaryType::periodic)
      period[a] = scene.domain.upper[a] - scene.domain.lower[a];
  }
  if (period.maxCoeff() > 0.0)
    for (RigidBody<Dim>& b : bodies) b.set_periodic(lower, period);
  return bodies;
}

template class RigidBody<2>;
template class RigidBody<3>;
template std::vector<Vec<2>> make_surface_samples<2>(const ShapeSpec&, const Shape<2>&, double);
template std::vector<Vec<3>> make_surface_samples<3>(const ShapeSpec&, const Shape<3>&, double);
template std::vector<RigidBody<2>> make_bodies<2>(const SceneDesc&, double);
template std::vector<RigidBody<3>> make_bodies<3>(const SceneDesc&, double);

}  // namespace monolith
