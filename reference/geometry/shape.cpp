/// \file shape.cpp
/// The dimension-generic signed distance functions (box, sphere, bowl, shell, halfspace, union,
/// difference), the rotation wrapper, make_shape<Dim> and volume_inside. Shapes that exist in
/// one dimension only come from make_dimension_shape<Dim> (dim2/shapes_2d.cpp,
/// dim3/shapes_3d.cpp). docs/geometry.md describes every shape and its rotation centre.

#include "reference/geometry/shape.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "reference/core/errors.hpp"
#include "reference/core/parallel.hpp"
#include "reference/geometry/shape_tools.hpp"

namespace monolith {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

/// Box<Dim> with every side unbounded.
template <int Dim>
Box<Dim> infinite_box() {
  return Box<Dim>(Vec<Dim>::Constant(-kInf), Vec<Dim>::Constant(kInf));
}

/// Axis-aligned box {center, half_size}: the exact SDF |max(q, 0)| + min(max_i q_i, 0) with
/// q = |x - c| - h (component-wise).
template <int Dim>
class BoxShape : public Shape<Dim> {
 public:
  BoxShape(const Vec<Dim>& center, const Vec<Dim>& half_size)
      : center_(center), half_size_(half_size) {}
  double distance(const Vec<Dim>& x) const override {
    // q > 0 along the axes where x lies beyond a face
    const Vec<Dim> q = (x - center_).cwiseAbs() - half_size_;
    return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
  }
  /// Exact gradient: outside, the direction from the nearest surface point (normalised positive
  /// part of q, with the signs of x - c); inside, the normal of the nearest face (the axis of
  /// the largest q; ties take the lowest axis). Central differences would blur it within a
  /// step of every edge, which tilts resting-contact normals.
  Vec<Dim> gradient(const Vec<Dim>& x) const override {
    const Vec<Dim> d = x - center_;
    const Vec<Dim> q = d.cwiseAbs() - half_size_;
    Vec<Dim> g = Vec<Dim>::Zero();
    if (q.maxCoeff() > 0.0) {
      for (int a = 0; a < Dim; ++a) g[a] = q[a] > 0.0 ? (d[a] < 0.0 ? -q[a] : q[a]) : 0.0;
      return g / g.norm();
    }
    int axis = 0;
    for (int a = 1; a < Dim; ++a)
      if (q[a] > q[axis]) axis = a;
    g[axis] = d[axis] < 0.0 ? -1.0 : 1.0;
    return g;
  }
  Box<Dim> bounds() const override { return Box<Dim>(center_ - half_size_, center_ + half_size_); }

 private:
  Vec<Dim> center_, half_size_;
};

/// Ball {center, radius} (a disk in 2D): |x - c| - r, exact.
template <int Dim>
class SphereShape : public Shape<Dim> {
 public:
  SphereShape(const Vec<Dim>& center, double radius) : center_(center), radius_(radius) {}
  double distance(const Vec<Dim>& x) const override { return (x - center_).norm() - radius_; }
  Vec<Dim> gradient(const Vec<Dim>& x) const override {
    const Vec<Dim> d = x - center_;
    const double n = d.norm();
    if (n == 0.0) return Vec<Dim>::UnitX();
    return d / n;
  }
  Box<Dim> bounds() const override {
    return Box<Dim>(center_.array() - radius_, center_.array() + radius_);
  }

 private:
  Vec<Dim> center_;
  double radius_;
};

/// Closed hollow sphere (a ring in 2D) r_in <= |x - c| <= r: | |x - c| - r_mid | - t/2 with
/// r_mid = r - t/2, exact.
template <int Dim>
class ShellShape : public Shape<Dim> {
 public:
  ShellShape(const Vec<Dim>& center, double radius, double thickness)
      : center_(center), radius_(radius), thickness_(thickness) {}
  double distance(const Vec<Dim>& x) const override {
    const double r_mid = radius_ - 0.5 * thickness_;
    return std::abs((x - center_).norm() - r_mid) - 0.5 * thickness_;
  }
  Box<Dim> bounds() const override {
    return Box<Dim>(center_.array() - radius_, center_.array() + radius_);
  }

 private:
  Vec<Dim> center_;
  double radius_, thickness_;
};

/// Bowl: the lower half of a spherical shell, {r_in <= |x - c| <= r, (x - c).y <= 0}, open at
/// the top with a flat annular rim in the plane y = c.y.
/// It is a solid of revolution about the vertical axis through c, so its exact SDF is the 2D
/// distance, in the meridian half-plane (rho, y) with rho = distance from that axis, to the
/// quarter annulus Q = {r_in <= |(rho, y)| <= r, y <= 0}:
///  - y > 0: the nearest point of Q is on the rim segment {(s, 0) : r_in <= s <= r} (the
///    nearest points of both arcs lie above y = 0, so on the arcs the minimum is at the rim
///    corners): distance = |(rho - clamp(rho, r_in, r), y)|, which rounds off the rim;
///  - y <= 0: outside the annulus the radial projection lies in Q, so d = | |p| - r_mid | - t/2;
///    inside, the nearest boundary is an arc or the rim plane: d = max(| |p| - r_mid | - t/2, y).
template <int Dim>
class BowlShape : public Shape<Dim> {
 public:
  BowlShape(const Vec<Dim>& center, double radius, double thickness)
      : center_(center), radius_(radius), thickness_(thickness) {}
  double distance(const Vec<Dim>& x) const override {
    const Vec<Dim> p = x - center_;
    const double y = p[1];
    const double r_in = radius_ - thickness_;
    // above the rim plane: distance to the rim segment
    if (y > 0.0) {
      const double rho = std::sqrt(std::max(p.squaredNorm() - y * y, 0.0));
      const double s = std::clamp(rho, r_in, radius_);
      return std::hypot(rho - s, y);
    }
    // below: the shell distance, cut by the rim plane inside the wall
    const double r_mid = radius_ - 0.5 * thickness_;
    const double shell = std::abs(p.norm() - r_mid) - 0.5 * thickness_;
    return shell <= 0.0 ? std::max(shell, y) : shell;
  }
  Box<Dim> bounds() const override {
    Vec<Dim> upper = center_.array() + radius_;
    upper[1] = center_[1];
    return Box<Dim>(center_.array() - radius_, upper);
  }

 private:
  Vec<Dim> center_;
  double radius_, thickness_;
};

/// Half-space {n . x <= offset}. The normal is normalised (and the offset divided by the given
/// normal's length), so distance = n . x - offset is exact.
template <int Dim>
class HalfspaceShape : public Shape<Dim> {
 public:
  HalfspaceShape(const Vec<Dim>& normal, double offset)
      : normal_(normal.normalized()), offset_(offset / normal.norm()) {}
  double distance(const Vec<Dim>& x) const override { return normal_.dot(x) - offset_; }
  Vec<Dim> gradient(const Vec<Dim>&) const override { return normal_; }
  /// Bounded only along an axis the normal is parallel to.
  Box<Dim> bounds() const override {
    Box<Dim> b = infinite_box<Dim>();
    for (int a = 0; a < Dim; ++a) {
      if (std::abs(std::abs(normal_[a]) - 1.0) > 1e-14) continue;
      if (normal_[a] > 0.0) b.max()[a] = offset_ / normal_[a];
      else b.min()[a] = offset_ / normal_[a];
    }
    return b;
  }

 private:
  Vec<Dim> normal_;
  double offset_;
};

/// Union: min over the children (exact outside, a lower bound on |d| inside).
template <int Dim>
class UnionShape : public Shape<Dim> {
 public:
  explicit UnionShape(std::vector<ShapePtr<Dim>> children) : children_(std::move(children)) {}
  double distance(const Vec<Dim>& x) const override {
    double d = kInf;
    for (const auto& c : children_) d = std::min(d, c->distance(x));
    return d;
  }
  Vec<Dim> gradient(const Vec<Dim>& x) const override {
    // the gradient of the active (minimal) child
    double d = kInf;
    const Shape<Dim>* best = children_.front().get();
    for (const auto& c : children_) {
      const double dc = c->distance(x);
      if (dc < d) { d = dc; best = c.get(); }
    }
    return best->gradient(x);
  }
  Box<Dim> bounds() const override {
    Box<Dim> b;  // empty
    for (const auto& c : children_) b.extend(c->bounds());
    return b;
  }

 private:
  std::vector<ShapePtr<Dim>> children_;
};

/// Difference: first minus the rest, max(d_0, -d_1, ..., -d_k) (exact inside near a single
/// active piece, a bound elsewhere).
template <int Dim>
class DifferenceShape : public Shape<Dim> {
 public:
  explicit DifferenceShape(std::vector<ShapePtr<Dim>> children)
      : children_(std::move(children)) {}
  double distance(const Vec<Dim>& x) const override {
    double d = children_.front()->distance(x);
    for (std::size_t i = 1; i < children_.size(); ++i) d = std::max(d, -children_[i]->distance(x));
    return d;
  }
  Vec<Dim> gradient(const Vec<Dim>& x) const override {
    // the gradient of the active piece, negated for a subtracted child
    double d = children_.front()->distance(x);
    std::size_t best = 0;
    for (std::size_t i = 1; i < children_.size(); ++i) {
      const double di = -children_[i]->distance(x);
      if (di > d) { d = di; best = i; }
    }
    const Vec<Dim> g = children_[best]->gradient(x);
    return best == 0 ? g : Vec<Dim>(-g);
  }
  Box<Dim> bounds() const override { return children_.front()->bounds(); }

 private:
  std::vector<ShapePtr<Dim>> children_;
};

std::string describe(const std::vector<double>& v) {
  std::ostringstream s;
  s << "[";
  for (std::size_t i = 0; i < v.size(); ++i) s << (i ? ", " : "") << v[i];
  s << "]";
  return s.str();
}

/// Checks the length of a vector parameter (the scene parser validates these already; shapes
/// built directly in code get the same message).
template <int Dim>
Vec<Dim> vec_param(const std::vector<double>& v, const std::string& key_path,
                   const char* key) {
  if (static_cast<int>(v.size()) != Dim) {
    throw InputError(key_path + "." + key + ": has " + std::to_string(v.size()) +
                     " numbers " + describe(v) + " (" + std::to_string(Dim) + " numbers)");
  }
  return to_vec<Dim>(v);
}

void require_positive(double value, const std::string& key_path, const char* key) {
  if (!(value > 0.0) || !std::isfinite(value)) {
    std::ostringstream s;
    s << key_path << "." << key << ": " << value << " (a finite number > 0)";
    throw InputError(s.str());
  }
}

}  // namespace

// --- Shape<Dim>::gradient ----------------------------------------------------------------------

template <int Dim>
Vec<Dim> Shape<Dim>::gradient(const Vec<Dim>& x) const {
  // central differences with a step relative to the magnitude of x
  const double h = 1e-6 * (1.0 + x.cwiseAbs().maxCoeff());
  Vec<Dim> g;
  for (int a = 0; a < Dim; ++a) {
    Vec<Dim> xp = x, xm = x;
    xp[a] += h;
    xm[a] -= h;
    g[a] = (distance(xp) - distance(xm)) / (2.0 * h);
  }
  const double n = g.norm();
  return n > 0.0 ? Vec<Dim>(g / n) : Vec<Dim>(Vec<Dim>::UnitX());
}

// --- rotations ---------------------------------------------------------------------------------

template <>
Mat<2> rotation_matrix<2>(const std::vector<double>& rotation) {
  if (rotation.empty()) return Mat<2>::Identity();
  return Eigen::Rotation2Dd(rotation[0]).toRotationMatrix();
}

template <>
Mat<3> rotation_matrix<3>(const std::vector<double>& rotation) {
  if (rotation.empty()) return Mat<3>::Identity();
  const Vec<3> w(rotation[0], rotation[1], rotation[2]);
  const double angle = w.norm();
  if (angle == 0.0) return Mat<3>::Identity();
  return Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
}

template <int Dim>
Vec<Dim> to_vec(const std::vector<double>& v) {
  Vec<Dim> r;
  for (int a = 0; a < Dim; ++a) r[a] = v[a];
  return r;
}

template <int Dim>
RotatedShape<Dim>::RotatedShape(ShapePtr<Dim> inner, const Mat<Dim>& rotation,
                                const Vec<Dim>& pivot)
    : inner_(std::move(inner)), rotation_(rotation), pivot_(pivot) {}

template <int Dim>
Vec<Dim> RotatedShape<Dim>::to_inner(const Vec<Dim>& x) const {
  return rotation_.transpose() * (x - pivot_) + pivot_;
}

template <int Dim>
double RotatedShape<Dim>::distance(const Vec<Dim>& x) const {
  return inner_->distance(to_inner(x));
}

template <int Dim>
Vec<Dim> RotatedShape<Dim>::gradient(const Vec<Dim>& x) const {
  return rotation_ * inner_->gradient(to_inner(x));
}

template <int Dim>
Box<Dim> RotatedShape<Dim>::bounds() const {
  const Box<Dim> b = inner_->bounds();
  if (b.isEmpty()) return b;
  const bool finite = b.min().allFinite() && b.max().allFinite();
  if (!finite) {
    // an unbounded inner shape keeps its bounds only under a trivial rotation
    if ((rotation_ - Mat<Dim>::Identity()).norm() > 1e-14) return infinite_box<Dim>();
    return b;
  }
  // the box of the 2^Dim rotated corners
  Box<Dim> r;
  for (int corner = 0; corner < (1 << Dim); ++corner) {
    Vec<Dim> c;
    for (int a = 0; a < Dim; ++a) c[a] = (corner >> a) & 1 ? b.max()[a] : b.min()[a];
    r.extend(Vec<Dim>(rotation_ * (c - pivot_) + pivot_));
  }
  return r;
}

template <int Dim>
ShapePtr<Dim> apply_rotation(ShapePtr<Dim> shape, const ShapeSpec& spec, const Vec<Dim>& pivot) {
  const Mat<Dim> r = rotation_matrix<Dim>(spec.rotation);
  if ((r - Mat<Dim>::Identity()).norm() == 0.0) return shape;
  return std::make_shared<RotatedShape<Dim>>(std::move(shape), r, pivot);
}

// --- make_shape --------------------------------------------------------------------------------

template <int Dim>
ShapePtr<Dim> make_shape(const ShapeSpec& spec, const std::string& key_path) {
  // the rotation value must fit the dimension
  const std::size_t rotation_size = Dim == 2 ? 1 : 3;
  if (!spec.rotation.empty() && spec.rotation.size() != rotation_size) {
    throw InputError(key_path + ".rotation: has " + std::to_string(spec.rotation.size()) +
                     " numbers (" + (Dim == 2 ? "one angle in 2D" : "an axis-angle 3-vector in 3D") +
                     ")");
  }
  switch (spec.type) {
    case ShapeType::polygon:
    case ShapeType::mesh:
    case ShapeType::bunny:
      // the dimension-specific types (dim2/shapes_2d.cpp, dim3/shapes_3d.cpp)
      return make_dimension_shape<Dim>(spec, key_path);
    case ShapeType::box: {
      const Vec<Dim> c = vec_param<Dim>(spec.center, key_path, "center");
      const Vec<Dim> h = vec_param<Dim>(spec.half_size, key_path, "half_size");
      if (!(h.minCoeff() > 0.0)) {
        throw InputError(key_path + ".half_size: " + describe(spec.half_size) +
                         " (positive numbers)");
      }
      return apply_rotation<Dim>(std::make_shared<BoxShape<Dim>>(c, h), spec, c);
    }
    case ShapeType::sphere: {
      const Vec<Dim> c = vec_param<Dim>(spec.center, key_path, "center");
      require_positive(spec.radius, key_path, "radius");
      // a sphere is rotation invariant about its centre
      return std::make_shared<SphereShape<Dim>>(c, spec.radius);
    }
    case ShapeType::shell:
    case ShapeType::bowl: {
      const Vec<Dim> c = vec_param<Dim>(spec.center, key_path, "center");
      require_positive(spec.radius, key_path, "radius");
      require_positive(spec.thickness, key_path, "thickness");
      if (spec.thickness > spec.radius) {
        std::ostringstream s;
        s << key_path << ".thickness: " << spec.thickness << " exceeds the radius " << spec.radius
          << " (0 < thickness <= radius)";
        throw InputError(s.str());
      }
      if (spec.type == ShapeType::shell)
        return std::make_shared<ShellShape<Dim>>(c, spec.radius, spec.thickness);
      return apply_rotation<Dim>(std::make_shared<BowlShape<Dim>>(c, spec.radius, spec.thickness),
                                 spec, c);
    }
    case ShapeType::halfspace: {
      const Vec<Dim> n = vec_param<Dim>(spec.normal, key_path, "normal");
      if (!(n.norm() > 0.0) || !n.allFinite()) {
        throw InputError(key_path + ".normal: " + describe(spec.normal) + " (a non-zero vector)");
      }
      return apply_rotation<Dim>(std::make_shared<HalfspaceShape<Dim>>(n, spec.offset), spec,
                                 Vec<Dim>::Zero());
    }
    case ShapeType::set_union:
    case ShapeType::set_difference: {
      if (spec.shapes.empty()) {
        throw InputError(key_path + ".shapes: is empty (at least one shape)");
      }
      std::vector<ShapePtr<Dim>> children;
      for (std::size_t i = 0; i < spec.shapes.size(); ++i) {
        children.push_back(
            make_shape<Dim>(spec.shapes[i], key_path + ".shapes[" + std::to_string(i) + "]"));
      }
      // rotation centre: the centre of the first child's bounds (the origin if unbounded)
      const Box<Dim> first = children.front()->bounds();
      Vec<Dim> pivot = Vec<Dim>::Zero();
      if (!first.isEmpty() && first.min().allFinite() && first.max().allFinite()) {
        pivot = first.center();
      }
      ShapePtr<Dim> s;
      if (spec.type == ShapeType::set_union)
        s = std::make_shared<UnionShape<Dim>>(std::move(children));
      else
        s = std::make_shared<DifferenceShape<Dim>>(std::move(children));
      return apply_rotation<Dim>(std::move(s), spec, pivot);
    }
  }
  throw std::invalid_argument("make_shape: not a shape type");
}

// --- volume_inside -----------------------------------------------------------------------------

template <int Dim>
double volume_inside(const Shape<Dim>& shape, const Box<Dim>& region, int samples_per_axis) {
  const int n = std::max(samples_per_axis, 1);
  const Vec<Dim> h = region.sizes() / n;
  long long total = 1;
  for (int a = 0; a < Dim; ++a) total *= n;
  long long inside = 0;
  // midpoint rule: count the sample points with negative distance
#pragma omp parallel for reduction(+ : inside) schedule(static) num_threads(process_threads())
  for (long long i = 0; i < total; ++i) {
    long long r = i;
    Vec<Dim> x;
    for (int a = 0; a < Dim; ++a) {
      x[a] = region.min()[a] + (static_cast<double>(r % n) + 0.5) * h[a];
      r /= n;
    }
    if (shape.distance(x) < 0.0) ++inside;
  }
  return static_cast<double>(inside) * h.prod();
}

// --- explicit instantiations -------------------------------------------------------------------

template class Shape<2>;
template class Shape<3>;
template class RotatedShape<2>;
template class RotatedShape<3>;
template Vec<2> to_vec<2>(const std::vector<double>&);
template Vec<3> to_vec<3>(const std::vector<double>&);
template ShapePtr<2> apply_rotation<2>(ShapePtr<2>, const ShapeSpec&, const Vec<2>&);
template ShapePtr<3> apply_rotation<3>(ShapePtr<3>, const ShapeSpec&, const Vec<3>&);
template ShapePtr<2> make_shape<2>(const ShapeSpec&, const std::string&);
template ShapePtr<3> make_shape<3>(const ShapeSpec&, const std::string&);
template double volume_inside<2>(const Shape<2>&, const Box<2>&, int);
template double volume_inside<3>(const Shape<3>&, const Box<3>&, int);

}  // namespace monolith
