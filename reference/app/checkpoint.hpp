#pragma once
/// \file checkpoint.hpp
/// Checkpoint files of `monolith run --checkpoint-every N` and `monolith resume DIR`
/// (docs/checkpoints.md): a header (magic, format version), the run's record (build, scene as
/// run, counters and totals of the runner) with the simulation state bytes of
/// AnySimulation::save_state, and a checksum. Written atomically; read back with every check
/// (truncation, corruption, another build) before anything in the run folder is touched.
/// Also the atomic file writes every output of a run goes through.

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace monolith {

/// A failure to write an output file (unwritable folder, full disk): the message names the
/// path and the system's reason. A run that meets it ends as a failure (exit 3).
class OutputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Writes `bytes` to `path` completely or not at all: into a temporary file next to it
/// (`path` + ".tmp"), flushed to disk when `sync`, then renamed over `path`. Throws OutputError.
void write_file_atomic(const std::filesystem::path& path, const std::string& bytes, bool sync = false);

/// Appends one whole line (text + '\n') to a file with a single write; if the write cannot be
/// completed (a full disk), the file is cut back to where it was, so it only ever ends with
/// whole lines. Throws OutputError.
class LineFile {
 public:
  LineFile() = default;
  /// Opens `path` for appending (created if missing; truncated when `truncate`).
  LineFile(const std::filesystem::path& path, bool truncate);
  LineFile(const LineFile&) = delete;
  LineFile& operator=(const LineFile&) = delete;
  ~LineFile();
  void append_line(const std::string& text);

 private:
  std::filesystem::path path_;
  int fd_ = -1;
};

/// A 64-bit FNV-1a digest of a file's bytes (0 for a file that cannot be read): a checkpoint
/// keeps one per input file so that `resume` refuses a scene whose meshes were edited.
std::uint64_t file_digest(const std::filesystem::path& path);

/// What a checkpoint records besides the simulation state.
struct CheckpointRecord {
  std::string build_id;        ///< build_id() of the writer
  std::string scene_json;      ///< the scene as run (after --set), JSON text
  std::string source_label;    ///< SceneFile::source_label
  std::string base_dir;        ///< SceneFile::base_dir (mesh paths)
  std::string source_path;     ///< the scene file the run was started from ("" for built-ins)
  std::vector<std::string> overrides;  ///< the run's --set overrides, in order
  int frame = 0;               ///< frames completed (stats.jsonl rows 0..frame are final)
  bool mid_frame = false;      ///< the state lies between two steps of frame + 1
  std::int64_t total_steps = 0;
  double initial_volume = 0.0, volume = 0.0;
  double wall_time = 0.0;      ///< seconds of the run so far
  std::int32_t checkpoint_every = 0;  ///< the run's --checkpoint-every (resume keeps it)
  std::int32_t threads = 0;    ///< OpenMP threads of the run (resume keeps them unless --threads)
  std::vector<std::string> input_files;     ///< SceneFile::input_files (the meshes), resolved
  std::vector<std::uint64_t> input_digests; ///< file_digest of each, when the checkpoint was written
  std::vector<char> state;     ///< AnySimulation::save_state

  template <class Archive>
  void state_fields(Archive& a) {
    a(build_id);
    a(scene_json);
    a(source_label);
    a(base_dir);
    a(source_path);
    a(overrides);
    a(frame);
    a(mid_frame);
    a(total_steps);
    a(initial_volume);
    a(volume);
    a(wall_time);
    a(checkpoint_every);
    a(threads);
    a(input_files);
    a(input_digests);
    a(state);
  }
};

/// The checkpoint file of a run folder.
std::filesystem::path checkpoint_path(const std::filesystem::path& dir);

/// An identifier of this build: the version and a hash of the running executable's bytes (two
/// builds from different sources or with different compilers differ).
const std::string& build_id();

/// Writes a checkpoint atomically (flushed to disk before the rename). Throws OutputError.
void write_checkpoint(const std::filesystem::path& path, const CheckpointRecord& record);

/// Reads and checks a checkpoint: the file exists, has the magic, this format version, its full
/// length and a matching checksum, and came from this build. Throws InputError naming the file
/// and what is wrong. With `accept_other_build` (`monolith resume --any-build`) a checkpoint of
/// another build of the same format version is returned too (its `build_id` tells the caller);
/// every other check still holds.
CheckpointRecord read_checkpoint(const std::filesystem::path& path, bool accept_other_build = false);

}  // namespace monolith
