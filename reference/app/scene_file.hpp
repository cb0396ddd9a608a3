#pragma once
/// \file scene_file.hpp
/// The scene file format "monolith-scene/1" (docs/scene-format.md is the complete reference):
/// parsing and validation into the core's plain description (SceneDesc, reference/sim/
/// scene_desc.hpp), `--set` overrides, built-in scene lookup. This is the one place where the
/// format's strings become enums (parse_enum, reference/core/enum_names.hpp).

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "reference/sim/scene_desc.hpp"
#include "reference/viz/render_spec.hpp"

namespace monolith {

/// A parsed scene: the description the simulation takes, plus what only the application uses
/// (the pictures' settings, the source for messages, the JSON as run for summary.json).
struct SceneFile : SceneDesc {
  std::string description;
  RenderSpec render;
  std::string source_label;        ///< file path, or "builtin:NAME", used in messages
  std::filesystem::path base_dir;  ///< folder that relative mesh paths resolve against
  nlohmann::json as_run;           ///< the scene JSON after --set overrides
  /// The files the scene reads besides itself (the mesh shapes' OBJ files, resolved), in the
  /// order they appear; a checkpoint records their contents so that resume notices an edit.
  std::vector<std::filesystem::path> input_files;
};

/// Parses and validates a scene. Collects every problem it finds and throws one InputError that
/// lists them all (one line each: `LABEL: key.path: what is wrong (what is allowed)`).
SceneFile parse_scene(const nlohmann::json& j, const std::string& label,
                      const std::filesystem::path& base_dir);

/// Loads a scene from a JSON file path or a built-in scene name, applies `--set KEY=VALUE`
/// overrides (dotted paths, e.g. solver.tolerance=1e-8 or liquids.0.density=800), then parses.
SceneFile load_scene(const std::string& path_or_name, const std::vector<std::string>& overrides);

/// Applies `KEY=VALUE` overrides to a scene JSON (VALUE as JSON if it parses, else a string;
/// a path through a missing array index or a non-object throws InputError). `label` prefixes
/// the messages.
nlohmann::json apply_overrides(nlohmann::json j, const std::string& label,
                               const std::vector<std::string>& overrides);

/// Peak memory estimate in bytes used to refuse scenes up front (docs/scene-format.md).
double estimate_memory_bytes(int dim, const std::vector<int>& cells, double particles);

}  // namespace monolith
