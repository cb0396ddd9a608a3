#pragma once
/// \file scene.hpp
/// The scene description of format "monolith-scene/1" (docs/scene-format.md is the complete
/// reference). A SceneDesc is dimension-agnostic: vectors are std::vector<double> whose lengths
/// have been validated against `dim`. The simulation converts them to Vec<Dim>.

#include <array>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace monolith {

enum class BoundaryType { wall, open, periodic };

/// One shape of the scene (shape.type and its parameters). Only the fields of its type are
/// meaningful; parse_scene checks that exactly those keys were given.
struct ShapeSpec {
  std::string type;  ///< box, sphere, bowl, shell, halfspace, polygon, mesh, bunny, union, difference
  std::vector<double> center;     ///< box, sphere, bowl, shell, bunny
  std::vector<double> half_size;  ///< box
  double radius = 0.0;            ///< sphere, bowl, shell (outer radius)
  double thickness = 0.0;         ///< bowl, shell (inner radius = radius - thickness)
  std::vector<double> normal;     ///< halfspace: inside is normal . x <= offset
  double offset = 0.0;            ///< halfspace
  std::vector<std::vector<double>> points;  ///< polygon (2D only), counter-clockwise or not
  std::string file;                ///< mesh (3D only): path as written in the scene
  std::filesystem::path resolved_file;  ///< mesh: `file` resolved against the scene's folder
  std::vector<double> scale;       ///< mesh: 1 number (uniform) or dim numbers; default [1]
  std::vector<double> translate;   ///< mesh: default zero
  double size = 0.0;               ///< bunny: extent of its bounding box along its longest axis
  std::vector<double> rotation;    ///< optional: 2D one angle, 3D axis-angle 3-vector; empty = none
  std::vector<ShapeSpec> shapes;   ///< union, difference (first minus the rest)
};

/// viscosity: `newtonian` (eta) or `herschel-bulkley` (k, n, tau0, gamma0), eq. (27).
struct ViscositySpec {
  std::string model = "newtonian";
  double eta = 0.0;
  double k = 0.0;
  double n = 1.0;
  double tau0 = 0.0;
  double gamma0 = 1e-3;
  /// herschel-bulkley only: the named set it started from (`"preset"`, viscosity_preset), or
  /// empty; explicit keys next to it have overridden its values above.
  std::string preset = "";
  /// True when this liquid needs stress unknowns (any non-zero viscosity).
  bool is_viscous() const { return model != "newtonian" || eta > 0.0; }
};

struct LiquidSpec {
  std::string name;
  ShapeSpec shape;
  double density = 0.0;
  std::vector<double> velocity;          ///< dim numbers
  std::vector<double> angular_velocity;  ///< 2D: 1 number, 3D: 3 numbers (about shape centre)
  ViscositySpec viscosity;
};

/// Prescribed path of a kinematic body: position offset = axis * amplitude * sin(2 pi f t).
struct PathSpec {
  std::string type = "oscillate";
  std::vector<double> axis;
  double amplitude = 0.0;
  double frequency = 0.0;
};

struct BodySpec {
  std::string name;
  std::string motion = "dynamic";  ///< dynamic, static, kinematic
  ShapeSpec shape;
  double density = 0.0;
  std::vector<double> velocity;
  std::vector<double> angular_velocity;
  double restitution = 0.0;
  double friction = 0.0;
  bool has_path = false;
  PathSpec path;
};

struct ProbeSpec {
  std::string name;
  std::vector<double> position;
};

struct DomainSpec {
  std::vector<double> lower, upper;
  std::vector<int> cells;
  /// Per face in the order x-, x+, y-, y+, z-, z+ (the first 2*dim are used).
  std::array<BoundaryType, 6> boundary{BoundaryType::wall, BoundaryType::wall, BoundaryType::wall,
                                       BoundaryType::wall, BoundaryType::wall, BoundaryType::wall};
  double wall_friction = 0.0;
  double wall_restitution = 0.0;
};

struct TimeSpec {
  double fps = 50.0;
  int frames = 100;
  double cfl = 3.0;
  double max_dt = 0.02;
};

struct SolverSpec {
  std::string scheme = "PVC-unified";
  double tolerance = 1e-6;
  int max_iterations = 2000;
  int staggered_iterations = 2;
  std::string backend = "matrixfree";
  double baumgarte = 0.2;
  double contact_margin = 0.1;  ///< epsilon of section 3.2.4, in units of dx
  double shrink = 0.01;         ///< zeta of section 4.4.6, in units of dx
  double diagonal_boost = 1e-4; ///< gamma of section 4.4.5
  /// Algorithm 2's line 1 in the simulator (section 5): true (default) starts each step's
  /// viscosity rounds from the previous step's shear rate where it has one, false from the rate
  /// of u* as printed (docs/non-newtonian.md). Not a scene key: set from C++ (tests, benches).
  bool viscosity_warm_start = true;
};

/// Particle seeding and maintenance (an addition to the contract's keys).
struct ParticleSpec {
  int per_cell = 0;                  ///< 0 = default (4 in 2D, 8 in 3D)
  unsigned seed = 1;                 ///< jitter seed: runs are reproducible
  bool position_correction = true;   ///< keep particles evenly spread (volume steady)
};

struct RenderSpec {
  bool enabled = true;
  std::array<int, 2> size{512, 512};
  std::string color_by = "speed";  ///< none, speed, pressure, viscosity
};

struct SceneDesc {
  std::string format = "monolith-scene/1";
  std::string name;
  std::string description;
  int dim = 2;
  DomainSpec domain;
  std::vector<double> gravity;  ///< default 9.81 along -y
  TimeSpec time;
  SolverSpec solver;
  ParticleSpec particles;
  std::vector<LiquidSpec> liquids;
  std::vector<BodySpec> bodies;
  std::vector<ProbeSpec> probes;
  RenderSpec render;

  std::string source_label;               ///< file path, or "builtin:NAME", used in messages
  std::filesystem::path base_dir;         ///< folder that relative mesh paths resolve against
  nlohmann::json as_run;                  ///< the scene JSON after --set overrides

  /// Cell width (cells are cubic: validated).
  double dx() const { return (domain.upper[0] - domain.lower[0]) / domain.cells[0]; }
};

/// The named herschel-bulkley sets of a scene's `"viscosity": {"model": "herschel-bulkley",
/// "preset": NAME}`: "newtonian", "shear-thinning", "shear-thickening", "bingham".
const std::vector<std::string>& viscosity_preset_names();
/// The section 6.4.1 (Fig. 10) set NAME as eq. (27)'s (k, n = r, tau0, gamma0): newtonian
/// (11, 1, 0, 1), shear-thinning (10, 0.5, 1, 1), shear-thickening (10, 2, 1, 1), bingham
/// (10, 1, 1e3, 1). Throws InputError for any other name.
ViscositySpec viscosity_preset(const std::string& name);

/// Parses and validates a scene. Collects every problem it finds and throws one InputError that
/// lists them all (one line each: `LABEL: key.path: what is wrong (what is allowed)`).
SceneDesc parse_scene(const nlohmann::json& j, const std::string& label,
                      const std::filesystem::path& base_dir);

/// Loads a scene from a JSON file path or a built-in scene name, applies `--set KEY=VALUE`
/// overrides (dotted paths, e.g. solver.tolerance=1e-8 or liquids.0.density=800), then parses.
SceneDesc load_scene(const std::string& path_or_name, const std::vector<std::string>& overrides);

/// Applies `KEY=VALUE` overrides to a scene JSON (VALUE as JSON if it parses, else a string;
/// a path through a missing array index or a non-object throws InputError). `label` prefixes
/// the messages.
nlohmann::json apply_overrides(nlohmann::json j, const std::string& label,
                               const std::vector<std::string>& overrides);

/// Throws InputError listing what the scene asks for that this build does not support yet, each
/// with its key path. Every physics of the format is supported now (herschel-bulkley liquids
/// since issue 6), so it accepts every parsed scene.
void require_supported(const SceneDesc& scene);

/// Peak memory estimate in bytes used to refuse scenes up front (docs/scene-format.md).
double estimate_memory_bytes(int dim, const std::vector<int>& cells, double particles);

}  // namespace monolith
