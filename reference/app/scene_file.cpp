/// \file scene_file.cpp
/// Parsing and validation of "monolith-scene/1" scene files (docs/scene-format.md) into
/// SceneFile, `--set` overrides and built-in scene lookup. The format's option strings become
/// the core's enums here, through parse_enum and the EnumNames table next to each enum.
///
/// Validation collects every problem it finds (it never stops at the first) and throws one
/// InputError whose lines read `LABEL: key.path: what is wrong (what is allowed)`.

#include "reference/app/scene_file.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <memory>
#include <optional>
#include <set>
#include <sstream>

#include "reference/app/embedded_scenes.hpp"
#include "reference/core/errors.hpp"
#include "reference/geometry/shape.hpp"

namespace monolith {

using nlohmann::json;

namespace {

constexpr const char* kFormat = "monolith-scene/1";
constexpr double kInf = std::numeric_limits<double>::infinity();
/// Nesting limit of union/difference shapes (guards the recursion against hostile input).
constexpr int kMaxShapeDepth = 32;
/// Upper limit of the cell count, before the memory estimate is even considered.
constexpr double kMaxCells = 1.0e9;

const std::vector<std::string> kFaceNames = {"x-", "x+", "y-", "y+", "z-", "z+"};

std::string join(const std::vector<std::string>& items, const std::string& sep = ", ") {
  std::string out;
  for (std::size_t i = 0; i < items.size(); ++i) out += (i ? sep : "") + items[i];
  return out;
}

std::string quoted_list(const std::vector<std::string>& items) {
  std::vector<std::string> q;
  for (const auto& s : items) q.push_back("\"" + s + "\"");
  return join(q);
}

/// Levenshtein distance, for "did you mean" suggestions.
std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t sub = prev[j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1);
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, sub});
    }
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

/// The allowed key closest to `key`, or "" if none is close enough to be a typo.
std::string closest(const std::string& key, const std::vector<std::string>& allowed) {
  std::string best;
  std::size_t best_d = std::numeric_limits<std::size_t>::max();
  auto lower = [](std::string t) {
    for (char& c : t) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return t;
  };
  for (const auto& a : allowed) {
    const std::size_t d = edit_distance(lower(key), lower(a));
    if (d < best_d) best_d = d, best = a;
  }
  const std::size_t limit = std::max<std::size_t>(2, key.size() / 3);
  return best_d <= limit ? best : std::string();
}

std::string key_at(const std::string& path, const std::string& key) {
  return path.empty() ? key : path + "." + key;
}
std::string index_at(const std::string& path, std::size_t i) {
  return path + "[" + std::to_string(i) + "]";
}

/// A short printable form of a number for messages.
std::string num(double x) {
  std::ostringstream s;
  s.precision(10);
  s << x;
  return s.str();
}

/// A short description of a JSON value for messages (never dumps large or nested values).
std::string describe(const json& v) {
  if (v.is_number()) return num(v.get<double>());
  if (v.is_boolean()) return v.get<bool>() ? "true" : "false";
  if (v.is_string()) {
    std::string s = v.get<std::string>();
    if (s.size() > 40) s = s.substr(0, 40) + "...";
    for (char& c : s)
      if (static_cast<unsigned char>(c) < 32) c = '?';
    return "the string \"" + s + "\"";
  }
  if (v.is_null()) return "null";
  if (v.is_array()) return "an array of " + std::to_string(v.size());
  return "an object";
}

/// An allowed interval of a number, with its text for messages.
struct Range {
  double lo = -kInf, hi = kInf;
  bool lo_open = false, hi_open = false;
  std::string text = "a finite number";
  bool contains(double x) const {
    if (lo_open ? !(x > lo) : !(x >= lo)) return false;
    if (hi_open ? !(x < hi) : !(x <= hi)) return false;
    return true;
  }
};
const Range kAnyNumber{};
const Range kPositive{0.0, kInf, true, false, "a finite number > 0"};
const Range kNonNegative{0.0, kInf, false, false, "a finite number >= 0"};
const Range kUnitClosed{0.0, 1.0, false, false, "a number in [0, 1]"};
const Range kUnitOpen{0.0, 1.0, true, true, "a number in (0, 1)"};

/// The validating reader: every helper records problems instead of throwing.
class SceneParser {
 public:
  SceneParser(std::string label, std::filesystem::path base_dir)
      : label_(std::move(label)), base_dir_(std::move(base_dir)) {}

  std::vector<std::string> problems;
  int dim = 0;  ///< 0 while `dim` is unknown or invalid (lengths are then not checked)

  void add(const std::string& path, const std::string& what, const std::string& allowed) {
    problems.push_back(label_ + ": " + (path.empty() ? std::string("(root)") : path) + ": " +
                       what + " (" + allowed + ")");
  }

  // --- structure --------------------------------------------------------------------------------
  bool expect_object(const json& v, const std::string& path, const std::string& allowed) {
    if (v.is_object()) return true;
    add(path, "expected an object, got " + describe(v), allowed);
    return false;
  }

  /// Reports every key of `obj` that is not in `allowed`, with the closest allowed key.
  void check_keys(const json& obj, const std::string& path, const std::vector<std::string>& allowed) {
    for (auto it = obj.begin(); it != obj.end(); ++it) {
      if (std::find(allowed.begin(), allowed.end(), it.key()) != allowed.end()) continue;
      std::string key = it.key();
      if (key.size() > 60) key = key.substr(0, 60) + "...";
      const std::string guess = closest(it.key(), allowed);
      std::string what = "unknown key";
      if (!guess.empty()) what += " (did you mean \"" + guess + "\"?)";
      add(key_at(path, key), what, "allowed here: " + join(allowed));
    }
  }

  /// The member `key` of `obj`, or nullptr; a missing required member is a problem.
  const json* member(const json& obj, const std::string& key, const std::string& path,
                     bool required, const std::string& allowed) {
    auto it = obj.find(key);
    if (it != obj.end()) return &*it;
    if (required) add(key_at(path, key), "missing required key", allowed);
    return nullptr;
  }

  // --- scalars ----------------------------------------------------------------------------------
  bool read_number(const json& v, const std::string& path, const Range& r, double& out) {
    if (!v.is_number()) {
      add(path, "expected a number, got " + describe(v), r.text);
      return false;
    }
    const double x = v.get<double>();
    if (!std::isfinite(x)) {
      add(path, "not a finite number", r.text);
      return false;
    }
    if (!r.contains(x)) {
      add(path, "out of range: " + num(x), r.text);
      return false;
    }
    out = x;
    return true;
  }

  bool read_int(const json& v, const std::string& path, long long lo, long long hi,
                const std::string& allowed, long long& out) {
    double x = 0.0;
    if (!v.is_number()) {
      add(path, "expected an integer, got " + describe(v), allowed);
      return false;
    }
    x = v.get<double>();
    if (!std::isfinite(x) || std::floor(x) != x) {
      add(path, "expected an integer, got " + describe(v), allowed);
      return false;
    }
    if (x < static_cast<double>(lo) || x > static_cast<double>(hi)) {
      add(path, "out of range: " + describe(v), allowed);
      return false;
    }
    out = v.is_number_float() ? static_cast<long long>(x)
                              : (v.is_number_unsigned() ? static_cast<long long>(v.get<unsigned long long>())
                                                        : v.get<long long>());
    return true;
  }

  bool read_bool(const json& v, const std::string& path, bool& out) {
    if (!v.is_boolean()) {
      add(path, "expected true or false, got " + describe(v), "true or false");
      return false;
    }
    out = v.get<bool>();
    return true;
  }

  bool read_string(const json& v, const std::string& path, const std::string& allowed,
                   std::string& out) {
    if (!v.is_string()) {
      add(path, "expected a string, got " + describe(v), allowed);
      return false;
    }
    out = v.get<std::string>();
    return true;
  }

  /// One of the names of the enum E (its EnumNames table): the one place a scene's option
  /// strings become enums.
  template <class E>
  bool read_enum(const json& v, const std::string& path, E& out) {
    const std::vector<std::string> values = enum_names<E>();
    const std::string allowed = "one of " + quoted_list(values);
    std::string s;
    if (!read_string(v, path, allowed, s)) return false;
    const std::optional<E> value = parse_enum<E>(s);
    if (!value) {
      std::string what = "unknown value \"" + (s.size() > 40 ? s.substr(0, 40) + "..." : s) + "\"";
      const std::string guess = closest(s, values);
      if (!guess.empty()) what += " (did you mean \"" + guess + "\"?)";
      add(path, what, allowed);
      return false;
    }
    out = *value;
    return true;
  }

  /// A vector of `n` finite numbers (n = 0: any length >= 1); each entry must lie in r.
  bool read_vector(const json& v, const std::string& path, std::size_t n, const Range& r,
                   std::vector<double>& out) {
    const std::string allowed =
        n ? "an array of " + std::to_string(n) + " numbers" + (dim ? " in " + std::to_string(dim) + "D" : "")
          : "an array of numbers";
    if (!v.is_array()) {
      add(path, "expected an array, got " + describe(v), allowed);
      return false;
    }
    if ((n && v.size() != n) || (!n && v.empty())) {
      add(path, "wrong length " + std::to_string(v.size()), allowed);
      return false;
    }
    std::vector<double> vals;
    bool ok = true;
    for (std::size_t i = 0; i < v.size(); ++i) {
      double x = 0.0;
      if (read_number(v[i], index_at(path, i), r, x))
        vals.push_back(x);
      else
        ok = false;
    }
    if (ok) out = vals;
    return ok;
  }

  /// dim-vector (length unchecked while dim is unknown).
  bool read_dim_vector(const json& v, const std::string& path, const Range& r,
                       std::vector<double>& out) {
    return read_vector(v, path, static_cast<std::size_t>(dim), r, out);
  }

  // --- optional members with ranges -------------------------------------------------------------
  void opt_number(const json& obj, const std::string& path, const std::string& key, const Range& r,
                  double& out, bool required = false) {
    if (const json* v = member(obj, key, path, required, r.text)) read_number(*v, key_at(path, key), r, out);
  }
  template <class Int>
  void opt_int(const json& obj, const std::string& path, const std::string& key, long long lo,
               long long hi, const std::string& allowed, Int& out) {
    long long x = 0;
    if (const json* v = member(obj, key, path, false, allowed))
      if (read_int(*v, key_at(path, key), lo, hi, allowed, x)) out = static_cast<Int>(x);
  }
  void opt_bool(const json& obj, const std::string& path, const std::string& key, bool& out) {
    if (const json* v = member(obj, key, path, false, "true or false")) read_bool(*v, key_at(path, key), out);
  }
  template <class E>
  void opt_enum(const json& obj, const std::string& path, const std::string& key, E& out) {
    if (const json* v = member(obj, key, path, false, "one of " + quoted_list(enum_names<E>())))
      read_enum(*v, key_at(path, key), out);
  }

  /// angular_velocity: 2D a number, 3D a 3-vector.
  void opt_angular(const json& obj, const std::string& path, std::vector<double>& out) {
    const std::string p = key_at(path, "angular_velocity");
    const json* v = member(obj, "angular_velocity", path, false, "");
    if (!v) return;
    if (dim == 2) {
      double w = 0.0;
      if (read_number(*v, p, Range{-kInf, kInf, false, false, "a number (rad/s) in 2D"}, w)) out = {w};
    } else if (dim == 3) {
      read_vector(*v, p, 3, kAnyNumber, out);
    }
  }

  // --- names ------------------------------------------------------------------------------------
  /// A name: non-empty printable text; unique within `seen`.
  void read_name(const json& obj, const std::string& path, const std::string& fallback,
                 std::vector<std::string>& seen, std::string& out) {
    out = fallback;
    const std::string allowed = "a unique, non-empty name without control characters";
    if (const json* v = member(obj, "name", path, false, allowed)) {
      std::string s;
      if (read_string(*v, key_at(path, "name"), allowed, s)) {
        const bool printable = std::all_of(s.begin(), s.end(), [](char c) {
          return static_cast<unsigned char>(c) >= 32 && c != 127;
        });
        if (s.empty() || !printable)
          add(key_at(path, "name"), "invalid name", allowed);
        else
          out = s;
      }
    }
    if (std::find(seen.begin(), seen.end(), out) != seen.end())
      add(key_at(path, "name"), "duplicate name \"" + out + "\"", allowed);
    seen.push_back(out);
  }

  // --- shapes -----------------------------------------------------------------------------------
  ShapeSpec read_shape(const json& v, const std::string& path, int depth) {
    ShapeSpec s;
    const std::vector<std::string> types = enum_names<ShapeType>();
    if (!expect_object(v, path, "a shape object with \"type\": one of " + quoted_list(types))) return s;
    if (depth > kMaxShapeDepth) {
      add(path, "shapes nested too deeply", "at most " + std::to_string(kMaxShapeDepth) + " levels");
      return s;
    }
    const json* t = member(v, "type", path, true, "one of " + quoted_list(types));
    if (!t || !read_enum(*t, key_at(path, "type"), s.type)) return s;

    // the keys each type takes
    std::vector<std::string> keys = {"type", "rotation"};
    const ShapeType ty = s.type;
    using T = ShapeType;
    if (ty == T::box) keys.insert(keys.end(), {"center", "half_size"});
    if (ty == T::sphere) keys.insert(keys.end(), {"center", "radius"});
    if (ty == T::bowl || ty == T::shell) keys.insert(keys.end(), {"center", "radius", "thickness"});
    if (ty == T::halfspace) keys.insert(keys.end(), {"normal", "offset"});
    if (ty == T::polygon) keys.insert(keys.end(), {"points"});
    if (ty == T::mesh) keys.insert(keys.end(), {"file", "scale", "translate"});
    if (ty == T::bunny) keys.insert(keys.end(), {"center", "size"});
    if (ty == T::set_union || ty == T::set_difference) keys.insert(keys.end(), {"shapes"});
    check_keys(v, path, keys);

    // types per dimension
    if (ty == T::polygon && dim == 3) add(key_at(path, "type"), "polygon is 2D only", "in 3D use mesh, box, sphere, ...");
    if (ty == T::mesh && dim == 2) add(key_at(path, "type"), "mesh is 3D only", "in 2D use polygon, box, sphere, ...");

    // rotation: 2D an angle, 3D an axis-angle vector
    if (const json* r = member(v, "rotation", path, false, "")) {
      if (dim == 2) {
        double a = 0.0;
        if (read_number(*r, key_at(path, "rotation"), Range{-kInf, kInf, false, false, "an angle in radians in 2D"}, a))
          s.rotation = {a};
      } else if (dim == 3) {
        read_vector(*r, key_at(path, "rotation"), 3, kAnyNumber, s.rotation);
      }
    }

    // the parameters of the type
    const std::string need = "required for " + enum_name(ty);
    if (ty == T::box || ty == T::sphere || ty == T::bowl || ty == T::shell || ty == T::bunny) {
      if (const json* c = member(v, "center", path, true, "an array of " + std::to_string(dim ? dim : 2) + " numbers; " + need))
        read_dim_vector(*c, key_at(path, "center"), kAnyNumber, s.center);
    }
    if (ty == T::box) {
      if (const json* h = member(v, "half_size", path, true, "positive numbers; " + need))
        read_dim_vector(*h, key_at(path, "half_size"), kPositive, s.half_size);
    }
    if (ty == T::sphere || ty == T::bowl || ty == T::shell) opt_number(v, path, "radius", kPositive, s.radius, true);
    if (ty == T::bowl || ty == T::shell) {
      const bool had_radius = s.radius > 0.0;
      const Range thick{0.0, had_radius ? s.radius : kInf, true, true, "0 < thickness < radius"};
      opt_number(v, path, "thickness", thick, s.thickness, true);
    }
    if (ty == T::halfspace) {
      if (const json* n = member(v, "normal", path, true, "a non-zero vector; " + need)) {
        if (read_dim_vector(*n, key_at(path, "normal"), kAnyNumber, s.normal)) {
          double len2 = 0.0;
          for (double x : s.normal) len2 += x * x;
          if (!(len2 > 1e-24)) add(key_at(path, "normal"), "zero-length normal", "a non-zero vector");
        }
      }
      opt_number(v, path, "offset", kAnyNumber, s.offset, true);
    }
    if (ty == T::polygon) {
      const std::string allowed = "an array of at least 3 points [x, y]";
      if (const json* pts = member(v, "points", path, true, allowed)) {
        const std::string pp = key_at(path, "points");
        if (!pts->is_array() || pts->size() < 3) {
          add(pp, pts->is_array() ? "too few points (" + std::to_string(pts->size()) + ")" : "expected an array, got " + describe(*pts), allowed);
        } else {
          for (std::size_t i = 0; i < pts->size(); ++i) {
            std::vector<double> q;
            if (read_vector((*pts)[i], index_at(pp, i), 2, kAnyNumber, q)) s.points.push_back(q);
          }
        }
      }
    }
    if (ty == T::mesh) {
      if (const json* f = member(v, "file", path, true, "a Wavefront OBJ path relative to the scene file")) {
        std::string file;
        if (read_string(*f, key_at(path, "file"), "a Wavefront OBJ path relative to the scene file", file)) {
          // the path as written, resolved against the scene's folder
          if (file.empty())
            add(key_at(path, "file"), "empty file name", "a Wavefront OBJ path relative to the scene file");
          else {
            s.file = std::filesystem::path(file).is_absolute() ? std::filesystem::path(file) : base_dir_ / file;
            input_files.push_back(s.file);
          }
        }
      }
      if (const json* sc = member(v, "scale", path, false, "")) {
        const std::string sp = key_at(path, "scale");
        if (sc->is_number()) {
          double x = 1.0;
          if (read_number(*sc, sp, kPositive, x)) s.scale = {x};
        } else if (sc->is_array()) {
          read_dim_vector(*sc, sp, kPositive, s.scale);
        } else {
          add(sp, "expected a number or an array, got " + describe(*sc), "a number > 0 or " + std::to_string(dim ? dim : 3) + " numbers > 0");
        }
      }
      if (const json* tr = member(v, "translate", path, false, ""))
        read_dim_vector(*tr, key_at(path, "translate"), kAnyNumber, s.translate);
    }
    if (ty == T::bunny) opt_number(v, path, "size", kPositive, s.size, true);
    if (ty == T::set_union || ty == T::set_difference) {
      const std::string allowed = "a non-empty array of shapes";
      if (const json* sh = member(v, "shapes", path, true, allowed)) {
        const std::string sp = key_at(path, "shapes");
        if (!sh->is_array() || sh->empty()) {
          add(sp, sh->is_array() ? "empty array" : "expected an array, got " + describe(*sh), allowed);
        } else {
          for (std::size_t i = 0; i < sh->size(); ++i) s.shapes.push_back(read_shape((*sh)[i], index_at(sp, i), depth + 1));
        }
      }
    }
    return s;
  }

 private:
  std::string label_;
  std::filesystem::path base_dir_;

 public:
  std::vector<std::filesystem::path> input_files;  ///< mesh files met while parsing, in order
};

/// Nesting depth of a JSON value, computed without recursion (hostile input may be deep).
std::size_t json_depth(const json& root, std::size_t limit) {
  std::vector<std::pair<const json*, std::size_t>> stack{{&root, 1}};
  std::size_t deepest = 0;
  while (!stack.empty()) {
    const auto [v, d] = stack.back();
    stack.pop_back();
    deepest = std::max(deepest, d);
    if (deepest > limit) return deepest;
    if (v->is_structured())
      for (const auto& child : *v) stack.push_back({&child, d + 1});
  }
  return deepest;
}

/// Deepest nesting a scene document may have (shapes nest at most kMaxShapeDepth levels).
constexpr std::size_t kMaxJsonDepth = 2 * kMaxShapeDepth + 16;

/// A shape whose spec parsed cleanly, to be built and checked against the domain.
struct PlacedShape {
  const ShapeSpec* spec;
  std::string path;     ///< e.g. "liquids[0].shape"
  std::string owner;    ///< e.g. "liquids[0]"
  bool is_liquid;
  bool needs_volume = false;  ///< a dynamic or kinematic body: its mass needs a bounded shape
};

/// Builds each shape and checks it overlaps the domain; returns the number of cells covered by
/// the liquids' bounds (for the particle part of the memory estimate).
template <int Dim>
double check_shapes_in_domain(const SceneFile& s, const std::vector<PlacedShape>& shapes,
                              SceneParser& p) {
  // domain box
  Box<Dim> domain;
  for (int a = 0; a < Dim; ++a) {
    domain.min()[a] = s.domain.lower[a];
    domain.max()[a] = s.domain.upper[a];
  }
  const double dx = s.dx();
  double liquid_cells = 0.0;
  for (const auto& ps : shapes) {
    try {
      // overlap of the shape's bounds with the domain, of positive extent on every axis
      const ShapePtr<Dim> shape = make_shape<Dim>(*ps.spec, ps.path);
      const Box<Dim> b = shape->bounds();
      if (ps.needs_volume && !b.isEmpty() && !(b.min().allFinite() && b.max().allFinite())) {
        // what make_bodies would refuse when the run starts (mass_properties), found by check too
        p.add(ps.path, "a dynamic or kinematic body needs a shape of finite volume; this one is unbounded (a halfspace, or a union or difference with one)",
              "a bounded shape, or \"motion\": \"static\"");
        continue;
      }
      bool overlaps = !b.isEmpty();
      double covered = 1.0;
      for (int a = 0; a < Dim && overlaps; ++a) {
        const double lo = std::max(b.min()[a], domain.min()[a]);
        const double hi = std::min(b.max()[a], domain.max()[a]);
        if (!(hi > lo)) overlaps = false;
        covered *= std::ceil((hi - lo) / dx - 1e-9);
      }
      if (!overlaps)
        p.add(ps.path, std::string(ps.is_liquid ? "the liquid" : "the body") + " lies entirely outside the domain",
              "at least part of every liquid and body inside domain.lower..domain.upper");
      else if (ps.is_liquid)
        liquid_cells += covered;
    } catch (const InputError& e) {
      for (const auto& line : e.problems()) p.problems.push_back(line);
    } catch (const std::exception& e) {
      p.add(ps.path, std::string("cannot build the shape: ") + e.what(), "a well-formed shape");
    }
  }
  return liquid_cells;
}

/// Bytes of memory a scene may use: MONOLITH_MEMORY_LIMIT_GIB when set (a number > 0, in GiB),
/// else min(16 GiB, MemAvailable of /proc/meminfo). `source` names where the limit came from.
double memory_limit_bytes(std::string& source) {
  constexpr double kGiB = 1024.0 * 1024.0 * 1024.0;
  if (const char* env = std::getenv("MONOLITH_MEMORY_LIMIT_GIB")) {
    char* end = nullptr;
    const double g = std::strtod(env, &end);
    if (end == env || *end != '\0' || !(g > 0.0) || !std::isfinite(g))
      throw InputError({std::string("environment variable MONOLITH_MEMORY_LIMIT_GIB: expected a number > 0 (GiB), got '") +
                        env + "'"});
    source = "set by MONOLITH_MEMORY_LIMIT_GIB";
    return g * kGiB;
  }
  double limit = 16.0 * kGiB;
  source = "on this machine (min of 16 GiB and MemAvailable; MONOLITH_MEMORY_LIMIT_GIB overrides it)";
  std::ifstream in("/proc/meminfo");
  std::string key;
  double kb = 0.0;
  std::string unit;
  while (in >> key >> kb) {
    std::getline(in, unit);
    if (key == "MemAvailable:") {
      limit = std::min(limit, kb * 1024.0);
      break;
    }
  }
  return limit;
}

std::string gib(double bytes) {
  std::ostringstream s;
  s.precision(3);
  s << bytes / (1024.0 * 1024.0 * 1024.0) << " GiB";
  return s.str();
}

std::string default_name(const std::string& label) {
  const std::string builtin = "builtin:";
  if (label.rfind(builtin, 0) == 0) return label.substr(builtin.size());
  std::string stem = std::filesystem::path(label).stem().string();
  return stem.empty() ? std::string("scene") : stem;
}

}  // namespace

/// Estimated peak memory of a scene in bytes (docs/scene-format.md, "Memory estimate"):
/// 8 bytes x (16 per cell + 8 per face + 2 per half-lattice sample + (2 Dim + Dim^2 + 3) per
/// particle) x a safety factor of 1.5.
double estimate_memory_bytes(int dim, const std::vector<int>& cells, double particles) {
  double n_cells = 1.0, n_half = 1.0, n_faces = 0.0;
  for (int a = 0; a < dim; ++a) {
    n_cells *= cells[a];
    n_half *= 2.0 * cells[a] + 1.0;
  }
  for (int a = 0; a < dim; ++a) {
    double f = 1.0;
    for (int b = 0; b < dim; ++b) f *= cells[b] + (a == b ? 1.0 : 0.0);
    n_faces += f;
  }
  const double per_particle = 2.0 * dim + dim * dim + 3.0;
  return 8.0 * (16.0 * n_cells + 8.0 * n_faces + 2.0 * n_half + per_particle * particles) * 1.5;
}

namespace {

/// A parser callback for json::parse that lists, as key paths (`domain.cells`,
/// `bodies[1].shape.radius`), every key met a second time in the same object. Only the first
/// kMaxJsonDepth levels are followed: a document nested deeper is refused by parse_scene, and a
/// frame (with its path) per level of 10^5 nested arrays would take memory quadratic in the
/// depth (the paths grow with it: 17.8 GB and 93 s for a fuzzer's 10^5 brackets).
json::parser_callback_t duplicate_key_finder(std::vector<std::string>& duplicates) {
  struct Frame {
    bool array = false;
    std::string path, last_key;
    std::set<std::string> keys;
    long index = -1;
  };
  struct State {
    std::vector<Frame> stack;
    std::size_t levels_beyond = 0;  ///< open arrays and objects below the followed levels
  };
  auto state = std::make_shared<State>();
  auto child = [](const Frame& f, bool advance_index) {
    if (f.array) return f.path + "[" + std::to_string(f.index + (advance_index ? 1 : 0)) + "]";
    return f.path.empty() ? f.last_key : f.path + "." + f.last_key;
  };
  return [state, child, &duplicates](int, json::parse_event_t event, json& parsed) {
    using E = json::parse_event_t;
    std::vector<Frame>* stack = &state->stack;
    const bool beyond = state->levels_beyond > 0;
    switch (event) {
      case E::object_start:
      case E::array_start: {
        if (beyond || stack->size() >= kMaxJsonDepth) {
          ++state->levels_beyond;
          break;
        }
        Frame f;
        f.array = event == E::array_start;
        if (!stack->empty()) {
          f.path = child(stack->back(), true);
          if (stack->back().array) ++stack->back().index;
        }
        stack->push_back(std::move(f));
        break;
      }
      case E::object_end:
      case E::array_end:
        if (beyond)
          --state->levels_beyond;
        else if (!stack->empty())
          stack->pop_back();
        break;
      case E::key:
        if (!beyond && !stack->empty() && parsed.is_string()) {
          Frame& f = stack->back();
          f.last_key = parsed.get<std::string>();
          if (!f.keys.insert(f.last_key).second) duplicates.push_back(child(f, false));
        }
        break;
      case E::value:
        if (!beyond && !stack->empty() && stack->back().array) ++stack->back().index;
        break;
    }
    return true;
  };
}

/// "domain": lower, upper, cells (cubic, at most kMaxCells), boundary, wall coefficients. true when
/// the box is usable for the checks against it.
bool parse_domain(SceneParser& p, const json& j, SceneFile& s) {
  const int dim = p.dim;
  const std::size_t n = static_cast<std::size_t>(s.dim);
  // domain
  bool domain_ok = false;
  if (const json* dj = p.member(j, "domain", "", true, "an object with lower, upper, cells")) {
    const std::size_t before = p.problems.size();
    std::size_t geometry_problems = 0;
    if (p.expect_object(*dj, "domain", "an object with lower, upper, cells")) {
      const json& d = *dj;
      p.check_keys(d, "domain", {"lower", "upper", "cells", "boundary", "wall_friction", "wall_restitution"});
      if (const json* v = p.member(d, "lower", "domain", true, "an array of dim numbers"))
        p.read_dim_vector(*v, "domain.lower", kAnyNumber, s.domain.lower);
      if (const json* v = p.member(d, "upper", "domain", true, "an array of dim numbers"))
        p.read_dim_vector(*v, "domain.upper", kAnyNumber, s.domain.upper);
      if (const json* v = p.member(d, "cells", "domain", true, "an array of dim integers >= 1")) {
        const std::string allowed = "an array of " + std::to_string(s.dim) + " integers >= 1";
        if (!v->is_array() || (dim && v->size() != n) || v->empty()) {
          p.add("domain.cells", v->is_array() ? "wrong length " + std::to_string(v->size()) : "expected an array, got " + describe(*v), allowed);
        } else {
          std::vector<int> cells;
          for (std::size_t i = 0; i < v->size(); ++i) {
            long long c = 0;
            if (p.read_int((*v)[i], index_at("domain.cells", i), 1, 1 << 24, "an integer in 1..16777216", c))
              cells.push_back(static_cast<int>(c));
          }
          if (cells.size() == v->size()) {
            double total = 1.0;
            for (int c : cells) total *= c;
            if (total > kMaxCells)
              p.add("domain.cells", "too many cells (" + num(total) + ")", "at most " + num(kMaxCells) + " cells in total");
            s.domain.cells = cells;
          }
        }
      }
      // lower < upper and cubic cells
      if (s.domain.lower.size() == n && s.domain.upper.size() == n && s.domain.cells.size() == n && dim) {
        bool ordered = true;
        for (std::size_t a = 0; a < n; ++a) {
          if (!(s.domain.upper[a] > s.domain.lower[a])) {
            p.add(index_at("domain.upper", a), "upper " + num(s.domain.upper[a]) + " is not above lower " + num(s.domain.lower[a]), "upper > lower on every axis");
            ordered = false;
          }
        }
        // the box itself is usable for the overlap checks even if the cells are not cubic
        geometry_problems = p.problems.size() - before;
        if (ordered) {
          const double dx0 = (s.domain.upper[0] - s.domain.lower[0]) / s.domain.cells[0];
          for (std::size_t a = 1; a < n; ++a) {
            const double dxa = (s.domain.upper[a] - s.domain.lower[a]) / s.domain.cells[a];
            if (std::abs(dxa - dx0) > 1e-9 * std::max(dx0, dxa))
              p.add("domain.cells", "cells are not cubic: dx along axis " + std::to_string(a) + " is " + num(dxa) + " but along x it is " + num(dx0),
                    "(upper - lower) / cells equal on every axis within 1e-9");
          }
        }
      }
      // boundary faces
      if (const json* b = p.member(d, "boundary", "domain", false, "")) {
        const std::vector<std::string> faces(kFaceNames.begin(), kFaceNames.begin() + 2 * s.dim);
        if (p.expect_object(*b, "domain.boundary", "an object with keys " + join(faces))) {
          p.check_keys(*b, "domain.boundary", faces);
          for (std::size_t f = 0; f < faces.size(); ++f) {
            if (const json* fv = p.member(*b, faces[f], "domain.boundary", false, ""))
              p.read_enum(*fv, "domain.boundary." + faces[f], s.domain.boundary[f]);
          }
          for (std::size_t a = 0; a < n; ++a) {
            const bool lo = s.domain.boundary[2 * a] == BoundaryType::periodic;
            const bool hi = s.domain.boundary[2 * a + 1] == BoundaryType::periodic;
            if (lo != hi)
              p.add("domain.boundary." + faces[2 * a + (lo ? 1 : 0)], "periodic on only one face of the axis",
                    "\"periodic\" on both " + faces[2 * a] + " and " + faces[2 * a + 1] + ", or on neither");
          }
        }
      }
      p.opt_number(d, "domain", "wall_friction", kNonNegative, s.domain.wall_friction);
      p.opt_number(d, "domain", "wall_restitution", kUnitClosed, s.domain.wall_restitution);
    }
    domain_ok = geometry_problems == 0 && dim && s.domain.cells.size() == n && s.domain.lower.size() == n &&
                s.domain.upper.size() == n;
  }
  return domain_ok;
}

/// "gravity", "time", "solver" and "particles": the scalar settings.
void parse_settings(SceneParser& p, const json& j, SceneFile& s) {
  // gravity
  s.gravity = default_gravity(s.dim);
  if (const json* g = p.member(j, "gravity", "", false, "")) p.read_dim_vector(*g, "gravity", kAnyNumber, s.gravity);

  // time
  if (const json* t = p.member(j, "time", "", false, "")) {
    if (p.expect_object(*t, "time", "an object with fps, frames, cfl, max_dt")) {
      p.check_keys(*t, "time", {"fps", "frames", "cfl", "max_dt"});
      p.opt_number(*t, "time", "fps", kPositive, s.time.fps);
      p.opt_int(*t, "time", "frames", 0, 100000000, "an integer in 0..100000000", s.time.frames);
      p.opt_number(*t, "time", "cfl", kPositive, s.time.cfl);
      p.opt_number(*t, "time", "max_dt", kPositive, s.time.max_dt);
    }
  }

  // solver
  if (const json* sv = p.member(j, "solver", "", false, "")) {
    if (p.expect_object(*sv, "solver", "an object with the solver settings")) {
      const json& o = *sv;
      p.check_keys(o, "solver", {"scheme", "tolerance", "max_iterations", "staggered_iterations", "backend",
                                 "preconditioner", "baumgarte", "contact_margin", "shrink", "diagonal_boost",
                                 "on_nonconvergence", "pressure_preconditioner", "max_recovery_speed"});
      p.opt_enum(o, "solver", "scheme", s.solver.scheme);
      p.opt_number(o, "solver", "tolerance", kUnitOpen, s.solver.tolerance);
      p.opt_int(o, "solver", "max_iterations", 1, 100000000, "an integer in 1..100000000", s.solver.max_iterations);
      p.opt_int(o, "solver", "staggered_iterations", 1, 100000, "an integer in 1..100000", s.solver.staggered_iterations);
      p.opt_enum(o, "solver", "backend", s.solver.backend);
      p.opt_enum(o, "solver", "preconditioner", s.solver.preconditioner);
      p.opt_enum(o, "solver", "pressure_preconditioner", s.solver.pressure_preconditioner);
      p.opt_number(o, "solver", "baumgarte", kUnitClosed, s.solver.baumgarte);
      p.opt_number(o, "solver", "max_recovery_speed", kPositive, s.solver.max_recovery_speed);
      p.opt_number(o, "solver", "contact_margin", kNonNegative, s.solver.contact_margin);
      p.opt_number(o, "solver", "shrink", kNonNegative, s.solver.shrink);
      p.opt_number(o, "solver", "diagonal_boost", kNonNegative, s.solver.diagonal_boost);
      p.opt_enum(o, "solver", "on_nonconvergence", s.solver.on_nonconvergence);
    }
  }

  // particles
  if (const json* pj = p.member(j, "particles", "", false, "")) {
    if (p.expect_object(*pj, "particles",
                        "an object with per_cell, seed, position_correction, settle_steps")) {
      p.check_keys(*pj, "particles", {"per_cell", "seed", "position_correction", "settle_steps"});
      p.opt_int(*pj, "particles", "per_cell", 1, 64, "an integer in 1..64", s.particles.per_cell);
      p.opt_int(*pj, "particles", "seed", 0, 4294967295LL, "an integer in 0..4294967295", s.particles.seed);
      p.opt_bool(*pj, "particles", "position_correction", s.particles.position_correction);
      p.opt_int(*pj, "particles", "settle_steps", 0, 100000, "an integer in 0..100000",
                s.particles.settle_steps);
    }
  }
}

/// "liquids": each liquid's shape (added to `placed`), density, velocity and viscosity model.
void parse_liquids(SceneParser& p, const json& j, SceneFile& s, std::vector<PlacedShape>& placed) {
  const std::size_t n = static_cast<std::size_t>(s.dim);
  // liquids
  if (const json* lj = p.member(j, "liquids", "", false, "")) {
    if (!lj->is_array()) {
      p.add("liquids", "expected an array, got " + describe(*lj), "an array of liquid objects");
    } else {
      std::vector<std::string> names;
      s.liquids.resize(lj->size());
      for (std::size_t i = 0; i < lj->size(); ++i) {
        const std::string path = index_at("liquids", i);
        LiquidSpec& l = s.liquids[i];
        l.velocity.assign(n, 0.0);
        l.angular_velocity.assign(s.dim == 2 ? 1 : 3, 0.0);
        const json& o = (*lj)[i];
        if (!p.expect_object(o, path, "a liquid object with shape and density")) continue;
        p.check_keys(o, path, {"name", "shape", "density", "velocity", "angular_velocity", "viscosity"});
        p.read_name(o, path, "liquid" + std::to_string(i), names, l.name);
        if (const json* sh = p.member(o, "shape", path, true, "a shape object")) {
          const std::size_t before = p.problems.size();
          l.shape = p.read_shape(*sh, path + ".shape", 0);
          if (p.problems.size() == before) placed.push_back({&l.shape, path + ".shape", path, true});
        }
        p.opt_number(o, path, "density", kPositive, l.density, true);
        if (const json* v = p.member(o, "velocity", path, false, "")) p.read_dim_vector(*v, path + ".velocity", kAnyNumber, l.velocity);
        p.opt_angular(o, path, l.angular_velocity);
        if (const json* vj = p.member(o, "viscosity", path, false, "")) {
          const std::string vp = path + ".viscosity";
          if (p.expect_object(*vj, vp, "an object with model and its parameters")) {
            p.opt_enum(*vj, vp, "model", l.viscosity.model);
            if (l.viscosity.model == ViscosityModel::newtonian) {
              p.check_keys(*vj, vp, {"model", "eta"});
              p.opt_number(*vj, vp, "eta", kNonNegative, l.viscosity.eta);
            } else {
              p.check_keys(*vj, vp, {"model", "preset", "k", "n", "tau0", "gamma0"});
              // a named section 6.4.1 set first; explicit keys next to it override it
              ViscosityPreset preset = ViscosityPreset::newtonian;
              if (const json* pj = p.member(*vj, "preset", vp, false, "one of " + quoted_list(enum_names<ViscosityPreset>())))
                if (p.read_enum(*pj, vp + ".preset", preset)) {
                  const ViscositySpec set = viscosity_preset(preset);
                  l.viscosity.k = set.k;
                  l.viscosity.n = set.n;
                  l.viscosity.tau0 = set.tau0;
                  l.viscosity.gamma0 = set.gamma0;
                  l.viscosity.preset = preset;
                }
              p.opt_number(*vj, vp, "k", kNonNegative, l.viscosity.k);
              p.opt_number(*vj, vp, "n", kPositive, l.viscosity.n);
              p.opt_number(*vj, vp, "tau0", kNonNegative, l.viscosity.tau0);
              p.opt_number(*vj, vp, "gamma0", kPositive, l.viscosity.gamma0);
            }
          }
        }
      }
    }
  }
}

/// "bodies": each body's motion, shape (added to `placed`), density, velocities, coefficients and
/// kinematic path.
void parse_bodies(SceneParser& p, const json& j, SceneFile& s, std::vector<PlacedShape>& placed) {
  const std::size_t n = static_cast<std::size_t>(s.dim);
  // bodies
  if (const json* bj = p.member(j, "bodies", "", false, "")) {
    if (!bj->is_array()) {
      p.add("bodies", "expected an array, got " + describe(*bj), "an array of body objects");
    } else {
      std::vector<std::string> names;
      s.bodies.resize(bj->size());
      for (std::size_t i = 0; i < bj->size(); ++i) {
        const std::string path = index_at("bodies", i);
        BodySpec& b = s.bodies[i];
        b.velocity.assign(n, 0.0);
        b.angular_velocity.assign(s.dim == 2 ? 1 : 3, 0.0);
        const json& o = (*bj)[i];
        if (!p.expect_object(o, path, "a body object with shape (and density unless static)")) continue;
        p.check_keys(o, path, {"name", "motion", "shape", "density", "velocity", "angular_velocity",
                               "restitution", "friction", "path"});
        p.read_name(o, path, "body" + std::to_string(i), names, b.name);
        p.opt_enum(o, path, "motion", b.motion);
        if (const json* sh = p.member(o, "shape", path, true, "a shape object")) {
          const std::size_t before = p.problems.size();
          b.shape = p.read_shape(*sh, path + ".shape", 0);
          if (p.problems.size() == before)
            placed.push_back({&b.shape, path + ".shape", path, false, b.motion != BodyMotion::fixed});
        }
        // density: required (> 0) unless static
        if (b.motion == BodyMotion::fixed)
          p.opt_number(o, path, "density", kNonNegative, b.density);
        else
          p.opt_number(o, path, "density", Range{0.0, kInf, true, false, "a finite number > 0; required for " + enum_name(b.motion) + " bodies"}, b.density, true);
        if (const json* v = p.member(o, "velocity", path, false, "")) p.read_dim_vector(*v, path + ".velocity", kAnyNumber, b.velocity);
        p.opt_angular(o, path, b.angular_velocity);
        p.opt_number(o, path, "restitution", kUnitClosed, b.restitution);
        p.opt_number(o, path, "friction", kNonNegative, b.friction);
        // path: required for kinematic bodies, refused for the others
        const json* pj = p.member(o, "path", path, false, "");
        const std::string pp = path + ".path";
        if (b.motion == BodyMotion::kinematic && !pj) {
          p.add(pp, "missing: kinematic bodies need a path", "{\"type\": \"oscillate\", \"axis\": [...], \"amplitude\": a, \"frequency\": f}");
        } else if (pj && b.motion != BodyMotion::kinematic) {
          p.add(pp, "only kinematic bodies take a path (motion is \"" + enum_name(b.motion) + "\")", "set \"motion\": \"kinematic\" or remove the path");
        } else if (pj && p.expect_object(*pj, pp, "an object with type, axis, amplitude, frequency")) {
          b.has_path = true;
          p.check_keys(*pj, pp, {"type", "axis", "amplitude", "frequency"});
          p.opt_enum(*pj, pp, "type", b.path.type);
          if (const json* ax = p.member(*pj, "axis", pp, true, "a non-zero vector of dim numbers")) {
            if (p.read_dim_vector(*ax, pp + ".axis", kAnyNumber, b.path.axis)) {
              double len2 = 0.0;
              for (double x : b.path.axis) len2 += x * x;
              if (!(len2 > 1e-24)) p.add(pp + ".axis", "zero-length axis", "a non-zero vector");
            }
          }
          p.opt_number(*pj, pp, "amplitude", kNonNegative, b.path.amplitude, true);
          p.opt_number(*pj, pp, "frequency", kNonNegative, b.path.frequency, true);
        }
      }
    }
  }
}

/// "probes": named points, inside the domain when it is usable.
void parse_probes(SceneParser& p, const json& j, SceneFile& s, bool domain_ok) {
  const std::size_t n = static_cast<std::size_t>(s.dim);
  // probes
  if (const json* pj = p.member(j, "probes", "", false, "")) {
    if (!pj->is_array()) {
      p.add("probes", "expected an array, got " + describe(*pj), "an array of probe objects");
    } else {
      std::vector<std::string> names;
      s.probes.resize(pj->size());
      for (std::size_t i = 0; i < pj->size(); ++i) {
        const std::string path = index_at("probes", i);
        ProbeSpec& pr = s.probes[i];
        const json& o = (*pj)[i];
        if (!p.expect_object(o, path, "a probe object with position")) continue;
        p.check_keys(o, path, {"name", "position"});
        p.read_name(o, path, "probe" + std::to_string(i), names, pr.name);
        if (const json* v = p.member(o, "position", path, true, "a point inside the domain")) {
          if (p.read_dim_vector(*v, path + ".position", kAnyNumber, pr.position) && domain_ok) {
            for (std::size_t a = 0; a < n; ++a) {
              if (pr.position[a] < s.domain.lower[a] || pr.position[a] > s.domain.upper[a]) {
                p.add(path + ".position", "outside the domain along axis " + std::to_string(a) + " (" + num(pr.position[a]) + ")",
                      "a point inside [" + num(s.domain.lower[a]) + ", " + num(s.domain.upper[a]) + "] on that axis");
                break;
              }
            }
          }
        }
      }
    }
  }
}

/// "render": enabled, size, color_by.
void parse_render(SceneParser& p, const json& j, SceneFile& s) {
  // render
  if (const json* rj = p.member(j, "render", "", false, "")) {
    if (p.expect_object(*rj, "render", "an object with enabled, size, color_by")) {
      p.check_keys(*rj, "render", {"enabled", "size", "color_by"});
      p.opt_bool(*rj, "render", "enabled", s.render.enabled);
      if (const json* sz = p.member(*rj, "size", "render", false, "")) {
        const std::string allowed = "[width, height], integers in 16..8192";
        if (!sz->is_array() || sz->size() != 2) {
          p.add("render.size", sz->is_array() ? "wrong length " + std::to_string(sz->size()) : "expected an array, got " + describe(*sz), allowed);
        } else {
          for (std::size_t i = 0; i < 2; ++i) {
            long long v = 0;
            if (p.read_int((*sz)[i], index_at("render.size", i), 16, 8192, allowed, v)) s.render.size[i] = static_cast<int>(v);
          }
        }
      }
      p.opt_enum(*rj, "render", "color_by", s.render.color_by);
    }
  }
}

/// The placed shapes against the domain, then the memory estimate of the grid and the particles
/// (estimate_memory_bytes) against memory_limit_bytes. Needs a usable domain.
void check_domain_contents(SceneParser& p, SceneFile& s, const std::vector<PlacedShape>& placed) {
  const int dim = p.dim;
  double liquid_cells = 0.0;
  if (dim == 2)
    liquid_cells = check_shapes_in_domain<2>(s, placed, p);
  else
    liquid_cells = check_shapes_in_domain<3>(s, placed, p);
  const int per_cell = s.particles.count_per_cell(dim);
  double total_cells = 1.0;
  for (int c : s.domain.cells) total_cells *= c;
  if (total_cells <= kMaxCells) {
    const double particles = per_cell * std::min(liquid_cells, total_cells);
    const double bytes = estimate_memory_bytes(dim, s.domain.cells, particles);
    std::string source;
    const double limit = memory_limit_bytes(source);
    if (bytes > limit)
      p.add("domain.cells", "the scene would need about " + gib(bytes) + " of memory (grid of " + num(total_cells) +
                                " cells, about " + num(particles) + " particles)",
            "at most " + gib(limit) + " " + source + ": use fewer cells or particles.per_cell");
  }
}

}  // namespace

SceneFile parse_scene(const json& j, const std::string& label, const std::filesystem::path& base_dir) {
  SceneParser p(label, base_dir);
  // refuse absurdly deep documents before anything copies or walks them recursively
  if (json_depth(j, kMaxJsonDepth) > kMaxJsonDepth) {
    p.add("", "the document is nested too deeply", "at most " + std::to_string(kMaxJsonDepth) + " levels of arrays and objects");
    throw InputError(p.problems);
  }
  SceneFile s;
  s.source_label = label;
  s.base_dir = base_dir;
  s.as_run = j;

  // the root
  if (!j.is_object()) {
    p.add("", "expected a JSON object, got " + describe(j), "a scene object with \"format\": \"" + std::string(kFormat) + "\"");
    throw InputError(p.problems);
  }
  p.check_keys(j, "", {"format", "name", "description", "dim", "domain", "gravity", "time", "solver",
                       "particles", "liquids", "bodies", "probes", "render"});

  // format and dim first: every vector length depends on dim
  if (const json* f = p.member(j, "format", "", true, "\"" + std::string(kFormat) + "\"")) {
    std::string fs;
    if (p.read_string(*f, "format", "\"" + std::string(kFormat) + "\"", fs) && fs != kFormat)
      p.add("format", "unsupported format " + describe(*f), "\"" + std::string(kFormat) + "\"");
  }
  if (const json* d = p.member(j, "dim", "", true, "2 or 3")) {
    long long dv = 0;
    if (p.read_int(*d, "dim", 2, 3, "2 or 3", dv)) p.dim = static_cast<int>(dv);
  }
  s.dim = p.dim ? p.dim : 2;

  // name and description
  std::vector<std::string> scene_names;
  p.read_name(j, "", default_name(label), scene_names, s.name);
  if (const json* d = p.member(j, "description", "", false, "")) p.read_string(*d, "description", "a string", s.description);

  const bool domain_ok = parse_domain(p, j, s);
  parse_settings(p, j, s);
  // shapes to check against the domain once everything is parsed
  std::vector<PlacedShape> placed;
  parse_liquids(p, j, s, placed);
  parse_bodies(p, j, s, placed);
  parse_probes(p, j, s, domain_ok);
  parse_render(p, j, s);
  if (domain_ok) check_domain_contents(p, s, placed);
  if (!p.problems.empty()) throw InputError(p.problems);
  s.input_files = p.input_files;
  return s;
}

// --- overrides and loading --------------------------------------------------------------------

namespace {

/// Splits `a.b[2].c` or `a.b.2.c` into {"a", "b", "2", "c"}; empty segments are errors.
bool split_key_path(const std::string& key, std::vector<std::string>& parts) {
  std::string cur;
  bool after_bracket = false;
  for (std::size_t i = 0; i < key.size(); ++i) {
    const char c = key[i];
    if (c == '.') {
      if (cur.empty() && !after_bracket) return false;
      if (!cur.empty()) parts.push_back(cur);
      cur.clear();
      after_bracket = false;
    } else if (c == '[') {
      if (cur.empty() && !after_bracket) return false;
      if (!cur.empty()) parts.push_back(cur);
      cur.clear();
      const std::size_t close = key.find(']', i);
      if (close == std::string::npos || close == i + 1) return false;
      parts.push_back(key.substr(i + 1, close - i - 1));
      i = close;
      after_bracket = true;
    } else {
      if (after_bracket) return false;
      cur += c;
    }
  }
  if (!cur.empty()) parts.push_back(cur);
  else if (!after_bracket) return false;
  return !parts.empty();
}

bool parse_index(const std::string& s, std::size_t& out) {
  if (s.empty() || s.size() > 9 || !std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; }))
    return false;
  out = static_cast<std::size_t>(std::stoul(s));
  return true;
}

/// Applies one `KEY=VALUE` override to j; problems are appended to `problems`.
void apply_override(json& j, const std::string& label, const std::string& item, std::vector<std::string>& problems) {
  const std::string where = label + ": --set " + item.substr(0, 80);
  const std::size_t eq = item.find('=');
  if (eq == std::string::npos || eq == 0) {
    problems.push_back(where + ": expected KEY=VALUE (a dotted key path such as solver.tolerance=1e-8)");
    return;
  }
  const std::string key = item.substr(0, eq);
  const std::string text = item.substr(eq + 1);
  std::vector<std::string> parts;
  if (!split_key_path(key, parts)) {
    problems.push_back(label + ": " + key + ": malformed key path (dotted keys and indices, e.g. liquids.0.density or liquids[0].density)");
    return;
  }
  // the value: JSON if it parses, else a string
  json value = json::parse(text, nullptr, false);
  if (value.is_discarded()) value = text;

  // walk the path, creating missing object members on the way
  if (!j.is_object()) {
    problems.push_back(label + ": " + key + ": the scene is not a JSON object (a scene object)");
    return;
  }
  json* cur = &j;
  std::string walked;
  for (std::size_t i = 0; i < parts.size(); ++i) {
    const std::string& part = parts[i];
    const bool last = i + 1 == parts.size();
    if (cur->is_object()) {
      walked = key_at(walked, part);
      if (last) {
        (*cur)[part] = value;
        return;
      }
      if (!cur->contains(part)) (*cur)[part] = json::object();
      cur = &(*cur)[part];
    } else if (cur->is_array()) {
      std::size_t idx = 0;
      if (!parse_index(part, idx) || idx >= cur->size()) {
        problems.push_back(label + ": " + key + ": no element " + part + " in " + (walked.empty() ? "the scene" : walked) +
                           " (an index in 0.." + (cur->empty() ? std::string("(empty array)") : std::to_string(cur->size() - 1)) + ")");
        return;
      }
      walked = index_at(walked, idx);
      if (last) {
        (*cur)[idx] = value;
        return;
      }
      cur = &(*cur)[idx];
    } else {
      problems.push_back(label + ": " + key + ": " + walked + " is " + describe(*cur) +
                         ", not an object or array (a key path through objects and arrays)");
      return;
    }
  }
}

std::string builtin_names() {
  std::vector<std::string> names;
  for (const auto& f : embedded_scenes()) names.push_back(std::string(f.name));
  return join(names);
}

std::string strip_json_prefix(const std::string& what) {
  // "[json.exception.parse_error.101] parse error at line 1, column 2: ..." -> "parse error at ..."
  const std::size_t close = what.find("] ");
  return what.rfind("[json.exception", 0) == 0 && close != std::string::npos ? what.substr(close + 2) : what;
}

}  // namespace

json apply_overrides(json j, const std::string& label, const std::vector<std::string>& overrides) {
  std::vector<std::string> problems;
  for (const auto& o : overrides) apply_override(j, label, o, problems);
  if (!problems.empty()) throw InputError(problems);
  return j;
}

SceneFile load_scene(const std::string& path_or_name, const std::vector<std::string>& overrides) {
  std::string text, label;
  std::filesystem::path base_dir;
  std::error_code ec;
  const std::filesystem::path path(path_or_name);

  // a built-in name (unless a regular file of that name exists here) or a file path
  const EmbeddedFile* builtin = nullptr;
  if (!std::filesystem::is_regular_file(path, ec)) {
    for (const auto& f : embedded_scenes())
      if (f.name == path_or_name) builtin = &f;
  }
  if (builtin) {
    text = std::string(builtin->data);
    label = "builtin:" + path_or_name;
    base_dir = std::filesystem::current_path(ec);
  } else {
    label = path_or_name;
    if (std::filesystem::is_directory(path, ec))
      throw InputError(label + ": (file): is a directory (a JSON scene file or a built-in scene name: " + builtin_names() + ")");
    std::ifstream in(path, std::ios::binary);
    if (!in)
      throw InputError(label + ": (file): cannot read the file (a readable JSON scene file or a built-in scene name: " +
                       builtin_names() + ")");
    std::ostringstream ss;
    ss << in.rdbuf();
    if (in.bad()) throw InputError(label + ": (file): error while reading the file (a readable JSON scene file)");
    text = ss.str();
    base_dir = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
  }

  // JSON syntax, then overrides, then validation
  json j;
  std::vector<std::string> duplicates;
  try {
    j = json::parse(text, duplicate_key_finder(duplicates));
  } catch (const json::exception& e) {
    // syntax errors carry line and column; number overflow (406) is reported the same way
    throw InputError(label + ": (json): " + strip_json_prefix(e.what()) + " (a valid JSON document)");
  }
  if (!duplicates.empty()) {
    // a key given twice in one object: the parser keeps the last value, so the first would be
    // ignored without a word (the same class of mistake as an unknown key)
    std::vector<std::string> lines;
    for (const std::string& key : duplicates)
      lines.push_back(label + ": " + key + ": duplicate key, the later value would silently replace the earlier (each key once per object)");
    throw InputError(lines);
  }
  j = apply_overrides(std::move(j), label, overrides);
  return parse_scene(j, label, base_dir);
}

}  // namespace monolith
