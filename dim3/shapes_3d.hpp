#pragma once
/// \file shapes_3d.hpp
/// Shapes that exist only in 3D: triangle meshes from OBJ files and the built-in bunny.

#include <memory>

#include "dim3/mesh.hpp"
#include "dim3/mesh_sdf.hpp"
#include "reference/geometry/shape.hpp"

namespace monolith {

/// The SDF of a closed triangle mesh, in the frame its vertices are given in: distance() is the
/// cached look-up of MeshSdf, gradient() the exact one.
class MeshShape : public Shape<3> {
 public:
  explicit MeshShape(std::shared_ptr<const MeshSdf> sdf) : sdf_(std::move(sdf)) {}
  double distance(const Vec<3>& x) const override { return sdf_->distance(x); }
  Vec<3> gradient(const Vec<3>& x) const override { return sdf_->exact(x).normal; }
  Box<3> bounds() const override { return sdf_->bounds(); }
  const MeshSdf& sdf() const { return *sdf_; }

 private:
  std::shared_ptr<const MeshSdf> sdf_;
};

/// A shape scaled uniformly by s about the origin of its frame and moved to `center`:
/// d(x) = s d_0((x - center) / s). Uniform scaling keeps an exact SDF exact.
class ScaledMeshShape : public Shape<3> {
 public:
  ScaledMeshShape(std::shared_ptr<const MeshSdf> sdf, double scale, const Vec<3>& center)
      : sdf_(std::move(sdf)), scale_(scale), center_(center) {}
  double distance(const Vec<3>& x) const override {
    return scale_ * sdf_->distance((x - center_) / scale_);
  }
  Vec<3> gradient(const Vec<3>& x) const override {
    return sdf_->exact((x - center_) / scale_).normal;
  }
  Box<3> bounds() const override {
    const Box<3> b = sdf_->bounds();
    return Box<3>(center_ + scale_ * b.min(), center_ + scale_ * b.max());
  }

 private:
  std::shared_ptr<const MeshSdf> sdf_;
  double scale_;
  Vec<3> center_;
};

/// The SDF (with its cache) of the bunny normalised to size 1 and centred at the origin, built
/// once per process on first use and shared by every bunny shape.
std::shared_ptr<const MeshSdf> unit_bunny_sdf();

/// The embedded bunny mesh (npm "bunny" 1.0.1, 1839 vertices, 3674 triangles), as read.
const TriangleMesh& bunny_mesh();

/// The bunny placed like the scene's `bunny {center, size}`: scaled so that the longest
/// bounding-box extent equals `size`, bounding-box centre moved to `center`.
TriangleMesh placed_bunny_mesh(const Vec<3>& center, double size);

}  // namespace monolith
