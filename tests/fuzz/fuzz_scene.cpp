// libFuzzer target for the scene parser (reference/app/scene_file.cpp): any bytes in, either a
// valid SceneFile or an InputError out, never a crash, a sanitizer report or a hang. The input
// is JSON text, optionally preceded by `--set` lines (KEY=VALUE, one a line) and a line "---",
// so that the override paths are fuzzed too. Mesh shapes resolve against a folder holding
// cube.obj. Build and run: docs/validation.md, "Sanitizers and fuzzing".
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "reference/app/scene_file.hpp"
#include "reference/core/errors.hpp"

namespace {

const std::filesystem::path& mesh_dir() {
  static const std::filesystem::path dir = [] {
    const std::filesystem::path d =
        std::filesystem::temp_directory_path() / ("monolith_fuzz_scene_" + std::to_string(::getpid()));
    std::filesystem::create_directories(d);
    std::ofstream(d / "cube.obj") << "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
                                     "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
    return d;
  }();
  return dir;
}

}  // namespace

/// One-time work before fuzzing: the built-in bunnies' distance fields (2D and 3D) are built once
/// per process and memoised (dim2/shapes_2d.cpp, dim3/shapes_3d.cpp); under the sanitizers on a
/// busy machine that first build takes longer than the per-input -timeout, so the first input
/// naming a bunny was reported as a hang. Parsing the built-in bunny scenes here builds them
/// before any input is timed.
extern "C" int LLVMFuzzerInitialize(int*, char***) {
  for (const char* warm : {"bunny-into-bowl-2d", "bunny-into-bowl-3d"}) {
    try {
      (void)monolith::load_scene(warm, {});
    } catch (const monolith::InputError&) {
    }
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::string text(reinterpret_cast<const char*>(data), size);
  // the fuzzer must not make the parser read devices or system files (a mesh path is a path)
  for (const char* path : {"/dev", "/proc", "/sys"})
    if (text.find(path) != std::string::npos) return 0;
  std::vector<std::string> overrides;
  const std::size_t split = text.find("\n---\n");
  if (split != std::string::npos) {
    std::string head = text.substr(0, split);
    text = text.substr(split + 5);
    std::size_t start = 0;
    while (start <= head.size()) {
      const std::size_t end = head.find('\n', start);
      overrides.push_back(head.substr(start, end == std::string::npos ? std::string::npos : end - start));
      if (end == std::string::npos) break;
      start = end + 1;
    }
  }
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded()) return 0;
  try {
    const nlohmann::json applied = overrides.empty() ? j : monolith::apply_overrides(j, "fuzz.json", overrides);
    const monolith::SceneFile scene = monolith::parse_scene(applied, "fuzz.json", mesh_dir());
    // a valid scene must also survive being written back and parsed again
    (void)monolith::parse_scene(nlohmann::json::parse(scene.as_run.dump()), "fuzz.json", mesh_dir());
  } catch (const monolith::InputError&) {
  }
  return 0;
}
