/// \file checkpoint.cpp
/// Checkpoint files and atomic output writes (docs/checkpoints.md has the byte layout).

#include "reference/app/checkpoint.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <iterator>
#include <sstream>

#include "reference/core/errors.hpp"
#include "reference/core/state_io.hpp"

#ifndef MONOLITH_VERSION
#define MONOLITH_VERSION "0.0.0"
#endif

namespace monolith {

namespace fs = std::filesystem;

namespace {

constexpr char kMagic[8] = {'M', 'O', 'N', 'O', 'C', 'K', 'P', 'T'};
// 2: thread count and input-file digests; 3: the state's listed volume deficits; 4: line 15's
// energy credit in every state of the default settings (slosh11: line15_energy = balance)
constexpr std::uint32_t kFormatVersion = 7;
/// magic, version, reserved, payload length
constexpr std::size_t kHeaderBytes = 8 + 4 + 4 + 8;
constexpr std::size_t kChecksumBytes = 8;

/// FNV-1a, 64 bits: the checksum of the file's header and payload.
std::uint64_t fnv1a(const char* data, std::size_t n, std::uint64_t h = 1469598103934665603ULL) {
  for (std::size_t i = 0; i < n; ++i) {
    h ^= static_cast<unsigned char>(data[i]);
    h *= 1099511628211ULL;
  }
  return h;
}

std::string system_reason() { return std::strerror(errno); }

/// write(2) until every byte is written; false (errno set) on failure.
bool write_all(int fd, const char* data, std::size_t n) {
  while (n > 0) {
    const ssize_t w = ::write(fd, data, n);
    if (w < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    data += w;
    n -= static_cast<std::size_t>(w);
  }
  return true;
}

}  // namespace

void write_file_atomic(const fs::path& path, const std::string& bytes, bool sync) {
  const fs::path tmp = path.string() + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw OutputError(tmp.string() + ": cannot create the file: " + system_reason());
  bool ok = write_all(fd, bytes.data(), bytes.size());
  std::string reason = ok ? "" : system_reason();
  if (ok && sync && ::fsync(fd) != 0) {
    ok = false;
    reason = system_reason();
  }
  if (::close(fd) != 0 && ok) {
    ok = false;
    reason = system_reason();
  }
  if (ok && std::rename(tmp.c_str(), path.c_str()) != 0) {
    ok = false;
    reason = system_reason();
  }
  if (!ok) {
    ::unlink(tmp.c_str());
    throw OutputError(path.string() + ": cannot write the file: " + reason);
  }
}

LineFile::LineFile(const fs::path& path, bool truncate) : path_(path) {
  fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC | (truncate ? O_TRUNC : 0), 0644);
  if (fd_ < 0) throw OutputError(path.string() + ": cannot open the file for writing: " + system_reason());
}

LineFile::~LineFile() {
  if (fd_ >= 0) ::close(fd_);
}

void LineFile::append_line(const std::string& text) {
  const std::string line = text + "\n";
  struct stat st {};
  if (::fstat(fd_, &st) != 0) throw OutputError(path_.string() + ": cannot append: " + system_reason());
  if (!write_all(fd_, line.data(), line.size())) {
    const std::string reason = system_reason();
    // never leave a partial line behind
    const bool cut = ::ftruncate(fd_, st.st_size) == 0;
    throw OutputError(path_.string() + ": cannot append a line: " + reason +
                      (cut ? "" : " (and the partial line could not be removed)"));
  }
}

fs::path checkpoint_path(const fs::path& dir) { return dir / "checkpoint.mckpt"; }

std::uint64_t file_digest(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return 0;
  std::uint64_t h = 1469598103934665603ULL;
  char buf[1 << 16];
  while (in) {
    in.read(buf, sizeof buf);
    h = fnv1a(buf, static_cast<std::size_t>(in.gcount()), h);
  }
  return h;
}

const std::string& build_id() {
  static const std::string id = [] {
    std::ifstream exe("/proc/self/exe", std::ios::binary);
    std::uint64_t h = 1469598103934665603ULL;
    std::uint64_t size = 0;
    char buf[1 << 16];
    while (exe) {
      exe.read(buf, sizeof buf);
      const std::size_t n = static_cast<std::size_t>(exe.gcount());
      h = fnv1a(buf, n, h);
      size += n;
    }
    std::ostringstream o;
    o << MONOLITH_VERSION << "+";
    if (size > 0)
      o << std::hex << h;
    else
      o << "compiled-" << __DATE__ << "-" << __TIME__;
    return o.str();
  }();
  return id;
}

void write_checkpoint(const fs::path& path, const CheckpointRecord& record) {
  StateWriter w;
  w(record);
  const std::vector<char>& payload = w.bytes();
  std::string bytes;
  bytes.reserve(kHeaderBytes + payload.size() + kChecksumBytes);
  bytes.append(kMagic, sizeof kMagic);
  const std::uint32_t version = kFormatVersion, reserved = 0;
  const std::uint64_t length = payload.size();
  bytes.append(reinterpret_cast<const char*>(&version), 4);
  bytes.append(reinterpret_cast<const char*>(&reserved), 4);
  bytes.append(reinterpret_cast<const char*>(&length), 8);
  bytes.append(payload.data(), payload.size());
  const std::uint64_t sum = fnv1a(bytes.data(), bytes.size());
  bytes.append(reinterpret_cast<const char*>(&sum), 8);
  write_file_atomic(path, bytes, true);
}

CheckpointRecord read_checkpoint(const fs::path& path, bool accept_other_build) {
  const std::string label = path.string() + ": ";
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(label + "no checkpoint to resume from (a run folder written with --checkpoint-every, or an interrupted run)");
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (bytes.size() < kHeaderBytes || std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0)
    throw InputError(label + "not a monolith checkpoint (the file does not start with its header)");
  std::uint32_t version = 0;
  std::uint64_t length = 0;
  std::memcpy(&version, bytes.data() + 8, 4);
  std::memcpy(&length, bytes.data() + 16, 8);
  if (version != kFormatVersion)
    throw InputError(label + "checkpoint format version " + std::to_string(version) + " (this build reads version " +
                     std::to_string(kFormatVersion) + "; a checkpoint of another format continues only in the build that wrote it)");
  const std::uint64_t expected = kHeaderBytes + length + kChecksumBytes;
  if (length > bytes.size() || bytes.size() != expected)
    throw InputError(label + "truncated or extended checkpoint: " + std::to_string(bytes.size()) + " bytes, its header says " +
                     std::to_string(expected));
  std::uint64_t sum = 0;
  std::memcpy(&sum, bytes.data() + kHeaderBytes + length, 8);
  if (sum != fnv1a(bytes.data(), kHeaderBytes + length))
    throw InputError(label + "corrupted checkpoint (checksum mismatch)");
  const std::vector<char> payload(bytes.begin() + kHeaderBytes, bytes.begin() + static_cast<std::ptrdiff_t>(kHeaderBytes + length));
  CheckpointRecord record;
  StateReader r(payload, path.string());
  r(record);
  r.finish();
  if (record.build_id != build_id() && !accept_other_build)
    throw InputError(label + "written by another build (" + record.build_id + "; this is " + build_id() +
                     "): a checkpoint continues bit for bit only in the build that wrote it (resume --any-build "
                     "continues it anyway, not bit for bit)");
  return record;
}

}  // namespace monolith
