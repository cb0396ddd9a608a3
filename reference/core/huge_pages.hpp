#pragma once
/// \file huge_pages.hpp
/// The first touch of lattice-sized buffers (issue 20, branch huge21; docs/benchmarks.md, "The
/// first touch: huge pages and bytes written once").
///
/// At Fig. 2's paper grid (256x128x256) a face-sized vector is 202 MB. The kernel provides a
/// buffer's pages when they are first written, one fault per 4 KiB page (about 500k faults for
/// the 2 GB a run touches); on a virtual machine every fault is an exit to the host. Two tools:
///
/// - advise_huge_pages: asks the kernel (Linux, transparent huge pages in `madvise` mode or
///   `always`) to back the 2 MiB-aligned interior of a buffer with 2 MiB pages, one fault per
///   2 MiB instead of 512, and fewer TLB misses when the buffer is streamed. Meant for buffers
///   that are kept and written whole (a huge page is provided whole, so a buffer written in a
///   few rows only would take more memory with it). Call it before the buffer's first write:
///   pages already present stay small pages until the kernel's background collapse (if ever).
///   Opt-in: on with the environment variable MONOLITH_HUGE_PAGES=1 or set_huge_pages(true)
///   (docs/cli.md); a no-op elsewhere than Linux. Advice only: the values in the buffer never change.
/// - zero_by_release: zero bytes over a range without writing its whole pages. The kernel's
///   fresh anonymous pages are zero, so the pages inside the range are given back
///   (MADV_DONTNEED: private anonymous memory reads as zero afterwards and is provided again
///   only where written) and the partial pages at its two ends are written. For a freshly
///   allocated buffer that is then written in a band only, the pages outside the band are never
///   touched (read, they map the kernel's shared zero page). Not for a buffer that is written
///   whole next (its pages would be provided again, one fault each).
///
/// Both act on memory of the process's own heap (Eigen vectors, std::vector storage), which is
/// private anonymous memory with any allocator the project uses.

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>

#include "reference/core/env_switch.hpp"

#if defined(__linux__)
#include <sys/mman.h>
#include <unistd.h>
#endif

namespace monolith {

/// The size of a transparent huge page on x86-64 and of the alignment advise_huge_pages uses.
constexpr std::size_t kHugePageBytes = std::size_t{1} << 21;

/// Addresses [begin, end); empty when end <= begin.
struct AddressSpan {
  std::uintptr_t begin = 0, end = 0;
  constexpr bool empty() const { return end <= begin; }
  constexpr std::size_t bytes() const { return empty() ? 0 : end - begin; }
};

/// The largest span inside [start, start + bytes) whose two ends are multiples of `alignment`
/// (a power of two): the first multiple at or after start up to the last multiple at or before
/// start + bytes. Empty when the range holds no whole aligned block.
constexpr AddressSpan aligned_interior(std::uintptr_t start, std::size_t bytes,
                                       std::size_t alignment) {
  const std::uintptr_t mask = ~(static_cast<std::uintptr_t>(alignment) - 1);
  const std::uintptr_t begin = (start + alignment - 1) & mask;
  const std::uintptr_t end = (start + bytes) & mask;
  return begin < end ? AddressSpan{begin, end} : AddressSpan{begin, begin};
}

/// The switch of advise_huge_pages: -1 until decided, then 0 (off) or 1 (on).
inline std::atomic<int>& huge_pages_flag() {
  static std::atomic<int> flag{-1};
  return flag;
}

/// Whether advise_huge_pages advises: off unless the environment sets MONOLITH_HUGE_PAGES=1
/// (read the first time it is asked) or set_huge_pages(true) was called first. Off by default
/// because on the development machine (a virtual machine) the advice made the 64^3 viscous
/// bunny's frames 20-50 % slower on one thread in every alternated pair measured, while the
/// paper grid's run gained nothing measurable (docs/benchmarks.md, "The twentieth session's
/// merged tree on a quiet machine").
inline bool huge_pages_enabled() {
  return env_switch(huge_pages_flag(), "MONOLITH_HUGE_PAGES", false);
}

/// Decides the switch for the process (tests; a program that embeds the core).
inline void set_huge_pages(bool on) { huge_pages_flag().store(on ? 1 : 0); }

/// Advises the 2 MiB-aligned interior of [data, data + bytes) for transparent huge pages (see
/// the file comment). Returns the bytes advised: 0 for a range without a whole aligned 2 MiB
/// block, when switched off, when the kernel refuses, or off Linux.
inline std::size_t advise_huge_pages(const void* data, std::size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  if (!huge_pages_enabled() || data == nullptr) return 0;
  const AddressSpan span =
      aligned_interior(reinterpret_cast<std::uintptr_t>(data), bytes, kHugePageBytes);
  if (span.empty()) return 0;
  if (madvise(reinterpret_cast<void*>(span.begin), span.bytes(), MADV_HUGEPAGE) != 0) return 0;
  return span.bytes();
#else
  (void)data;
  (void)bytes;
  return 0;
#endif
}

/// `v` (an Eigen vector or a std::vector) becomes n entries; storage made here (a size other
/// than n before) is advised for huge pages before anything writes it, and its entries are
/// unspecified (Eigen) or value-initialised (std::vector), as resize leaves them. A vector
/// that already has n entries keeps its storage and values.
template <class Vector>
void resize_on_huge_pages(Vector& v, long n) {
  if (static_cast<long>(v.size()) == n) return;
  v.resize(n);
  if (n > 0) advise_huge_pages(v.data(), sizeof(*v.data()) * static_cast<std::size_t>(n));
}

/// Below this many bytes zero_by_release writes the zeros (a system call costs more).
constexpr std::size_t kReleaseMinBytes = std::size_t{1} << 20;

/// Sets every byte of [data, data + bytes) to 0 (see the file comment): the pages wholly inside
/// the range are released (MADV_DONTNEED), the rest is written. Returns the bytes released (0:
/// every byte written: a small range, off Linux, or the kernel refused). The memory must be
/// private anonymous (heap) memory that no other thread uses meanwhile.
inline std::size_t zero_by_release(void* data, std::size_t bytes) {
  auto* bytes_at = static_cast<unsigned char*>(data);
#if defined(__linux__) && defined(MADV_DONTNEED)
  if (bytes >= kReleaseMinBytes) {
    static const std::size_t page = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
    const auto start = reinterpret_cast<std::uintptr_t>(data);
    const AddressSpan span = aligned_interior(start, bytes, page);
    if (!span.empty() &&
        madvise(reinterpret_cast<void*>(span.begin), span.bytes(), MADV_DONTNEED) == 0) {
      std::memset(bytes_at, 0, span.begin - start);
      std::memset(reinterpret_cast<unsigned char*>(span.end), 0, start + bytes - span.end);
      return span.bytes();
    }
  }
#endif
  if (bytes > 0) std::memset(bytes_at, 0, bytes);
  return 0;
}

/// `v` (an Eigen vector or a std::vector of arithmetic values) becomes n zeros in fresh storage
/// whose zeros come from the kernel (zero_by_release): its pages are provided only where they
/// are written later. For a buffer written in a band only; its old contents are dropped.
template <class Vector>
void resize_to_released_zeros(Vector& v, long n) {
  v.resize(n);
  if (n > 0) zero_by_release(v.data(), sizeof(*v.data()) * static_cast<std::size_t>(n));
}

}  // namespace monolith
