/// \file shapes_3d.cpp
/// 3D-only shapes (mesh, bunny) and make_dimension_shape<3>.

#include "dim3/shapes_3d.hpp"

#include <cmath>
#include <map>
#include <mutex>
#include <sstream>

#include "reference/core/errors.hpp"
#include "reference/geometry/embedded_assets.hpp"
#include "reference/geometry/shape_tools.hpp"

namespace monolith {

const TriangleMesh& bunny_mesh() {
  static const TriangleMesh mesh = [] {
    for (const auto& f : embedded_assets()) {
      if (f.name == "bunny.obj") return parse_obj(f.data, "builtin:bunny.obj", "bunny");
    }
    throw InputError("builtin:bunny.obj: bunny: the embedded bunny mesh is missing from this "
                     "build (dim3/assets/bunny.obj)");
  }();
  return mesh;
}

TriangleMesh placed_bunny_mesh(const Vec<3>& center, double size) {
  TriangleMesh m = bunny_mesh();
  const Box<3> b = m.bounds();
  const double s = size / b.sizes().maxCoeff();
  m.transform(Vec<3>::Constant(s), center - s * b.center());
  return m;
}

std::shared_ptr<const MeshSdf> unit_bunny_sdf() {
  // thread-safe one-time construction (a function-local static)
  static const std::shared_ptr<const MeshSdf> sdf =
      std::make_shared<MeshSdf>(placed_bunny_mesh(Vec<3>::Zero(), 1.0));
  return sdf;
}

namespace {

/// Mesh SDFs already built in this process, by file, modification time, scale and translate
/// (the scene validator and the simulation both build the scene's shapes). Held, not weakly
/// referenced: the validator's shapes are gone before the simulation builds its own, so a weak
/// reference had expired by then and the hierarchy and cache were built a second time.
std::shared_ptr<const MeshSdf> memoized_mesh_sdf(const std::filesystem::path& file,
                                                 const Vec<3>& scale, const Vec<3>& translate,
                                                 const std::string& key_path) {
  static std::mutex mutex;
  static std::map<std::string, std::shared_ptr<const MeshSdf>> built;
  std::error_code ec;
  const auto stamp = std::filesystem::last_write_time(file, ec);
  std::ostringstream key;
  key.precision(17);
  key << file.string() << '|' << (ec ? 0 : stamp.time_since_epoch().count()) << '|'
      << scale.transpose() << '|' << translate.transpose();
  {
    const std::lock_guard<std::mutex> lock(mutex);
    if (auto found = built[key.str()]) return found;
  }
  TriangleMesh mesh = load_obj(file, key_path);
  mesh.transform(scale, translate);
  auto sdf = std::make_shared<const MeshSdf>(std::move(mesh));
  const std::lock_guard<std::mutex> lock(mutex);
  built[key.str()] = sdf;
  return sdf;
}

Vec<3> vec3_param(const std::vector<double>& v, const std::string& key_path, const char* key,
                  const Vec<3>& fallback) {
  if (v.empty()) return fallback;
  if (v.size() != 3) {
    throw InputError(key_path + "." + key + ": has " + std::to_string(v.size()) +
                     " numbers (3 numbers)");
  }
  const Vec<3> r(v[0], v[1], v[2]);
  if (!r.allFinite()) throw InputError(key_path + "." + key + ": (finite numbers)");
  return r;
}

}  // namespace

template <>
ShapePtr<3> make_dimension_shape<3>(const ShapeSpec& spec, const std::string& key_path) {
  if (spec.type == ShapeType::mesh) {
    // scale in the file's frame, then translate; rotation about `translate`
    Vec<3> scale = Vec<3>::Ones();
    if (spec.scale.size() == 1) {
      scale.setConstant(spec.scale[0]);
    } else if (!spec.scale.empty()) {
      scale = vec3_param(spec.scale, key_path, "scale", scale);
    }
    if (!scale.allFinite() || scale.cwiseAbs().minCoeff() == 0.0) {
      throw InputError(key_path + ".scale: has a zero or non-finite factor (non-zero numbers)");
    }
    const Vec<3> translate = vec3_param(spec.translate, key_path, "translate", Vec<3>::Zero());
    auto shape = std::make_shared<MeshShape>(
        memoized_mesh_sdf(spec.file, scale, translate, key_path + ".file"));
    return apply_rotation<3>(shape, spec, translate);
  }
  if (spec.type == ShapeType::bunny) {
    const Vec<3> center = vec3_param(spec.center, key_path, "center", Vec<3>::Zero());
    if (!(spec.size > 0.0) || !std::isfinite(spec.size)) {
      throw InputError(key_path + ".size: must be a finite number > 0");
    }
    // the shared unit bunny, scaled to `size` about `center`
    auto shape = std::make_shared<ScaledMeshShape>(unit_bunny_sdf(), spec.size, center);
    return apply_rotation<3>(shape, spec, center);
  }
  if (spec.type == ShapeType::polygon) {
    throw InputError(key_path + ".type: \"polygon\" is 2D only (in 3D: mesh or bunny)");
  }
  return nullptr;
}

}  // namespace monolith
