#pragma once
/// \file first_touch.hpp
/// A fresh buffer made resident in one call before it is first written (issue 20, branch
/// kern25; docs/benchmarks.md, "The first touch in one call").
///
/// The kernel provides the pages of freshly allocated memory when they are first written: one
/// page-fault exception per 4 KiB page. On the development host (a paravirtualised guest) the
/// exception itself is the cost, 1.6-2.1 s of kernel time per GiB, not the zeroing of the page
/// (clear_page was 0.35 % of a profile). `madvise(MADV_POPULATE_WRITE)` (Linux 5.14 and later)
/// fills the page tables of a range in one system call, as if every page had been written, but
/// without one exception per page: a quarter of a second per GiB on that host. The contents do
/// not change (a fresh page reads as zero either way, a resident page is left as it is), so
/// results are the same bits with or without it.
///
/// - populate_for_writing: MADV_POPULATE_WRITE on the page-aligned interior of a range (the
///   partial pages at its two ends are left to the first write, at most two faults). Meant for
///   buffers that are written whole right after (a buffer written in a band only would take
///   memory for pages it never writes: use zero_by_release there, core/huge_pages.hpp). A no-op
///   off Linux, where the kernel does not know the advice (EINVAL before 5.14) and when switched
///   off (MONOLITH_POPULATE=0, for A/B measurements in one binary).
/// - make_resident: advise_huge_pages (when huge pages are switched on, core/huge_pages.hpp)
///   and then populate_for_writing, for a buffer whose storage was just made.
/// - populate_for_reading: MADV_POPULATE_READ likewise, for kernel zeros read whole first.
/// - resize_resident (an Eigen vector), reserve_resident and assign_resident (a std::vector):
///   resized, reserved or filled, with their storage made resident when that made new
///   storage. Populating pages already resident costs a page-table walk per page (0.07 s per
///   GiB on the development host), so the callers populate only storage that is new, never
///   every step.
///
/// Advice on the process's own heap memory (private anonymous memory, with the allocator
/// settings of core/memory_policy.hpp or without): it never changes a value, whichever thread
/// owns the neighbouring bytes.

#include <atomic>
#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "reference/core/env_switch.hpp"
#include "reference/core/huge_pages.hpp"

#if defined(__linux__)
#include <sys/mman.h>
#include <unistd.h>
#endif

namespace monolith {

/// The switch of populate_for_writing and populate_for_reading: -1 until decided, then 0 (off)
/// or 1 (on).
inline std::atomic<int>& populate_flag() {
  static std::atomic<int> flag{-1};
  return flag;
}

/// Whether the populate calls act: on unless the environment sets MONOLITH_POPULATE=0 (read the
/// first time it is asked) or set_populate(false) was called first. On by default: it changes no
/// value and lowers the kernel's time (docs/benchmarks.md, "The first touch in one call").
inline bool populate_enabled() { return env_switch(populate_flag(), "MONOLITH_POPULATE", true); }

/// Decides the switch for the process (tests; a program that embeds the core).
inline void set_populate(bool on) { populate_flag().store(on ? 1 : 0); }

/// Below this many bytes populate_for_writing does nothing (a system call for a few pages costs
/// about what their faults do).
constexpr std::size_t kPopulateMinBytes = std::size_t{1} << 20;

namespace detail {
/// madvise(advice) on the page-aligned interior of [data, data + bytes); the bytes advised or 0
/// (see populate_for_writing). `unknown`: set when the kernel answers that it does not know the
/// advice (EINVAL, ENOSYS: before Linux 5.14), after which the advice is not asked again.
inline std::size_t populate_interior(const void* data, std::size_t bytes, int advice,
                                     std::atomic<bool>& unknown) {
#if defined(__linux__)
  if (data == nullptr || bytes < kPopulateMinBytes || !populate_enabled()) return 0;
  if (unknown.load(std::memory_order_relaxed)) return 0;
  static const std::size_t page = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
  const AddressSpan span = aligned_interior(reinterpret_cast<std::uintptr_t>(data), bytes, page);
  if (span.empty()) return 0;
  if (madvise(reinterpret_cast<void*>(span.begin), span.bytes(), advice) != 0) {
    if (errno == EINVAL || errno == ENOSYS) unknown.store(true, std::memory_order_relaxed);
    return 0;  // (ENOMEM, EFAULT, EINTR: the first accesses fault the pages in as before)
  }
  return span.bytes();
#else
  (void)data;
  (void)bytes;
  (void)advice;
  (void)unknown;
  return 0;
#endif
}
}  // namespace detail

// the values of Linux's uapi header (5.14 and later), for C libraries that predate them
constexpr int kMadvPopulateRead = 22;
constexpr int kMadvPopulateWrite = 23;

/// Makes the whole pages inside [data, data + bytes) resident and writable (see the file
/// comment). Returns the bytes populated: 0 for a range below kPopulateMinBytes or without a
/// whole page, when switched off, when the kernel does not know the advice or refuses it, or off
/// Linux. The values in the range never change.
inline std::size_t populate_for_writing(const void* data, std::size_t bytes) {
  static std::atomic<bool> unknown{false};
  return detail::populate_interior(data, bytes, kMadvPopulateWrite, unknown);
}

/// The same with MADV_POPULATE_READ, for a buffer whose zeros came from the kernel
/// (zero_by_release) and that a pass reads whole before it is written in a band only: each page
/// is mapped as a read of it would map it (a kernel with a shared zero page maps that page and
/// provides no memory; the development host's kernel provides a page per read, as the read
/// would), in one call instead of one exception per page. Same threshold, switch and return as
/// populate_for_writing; the values never change.
inline std::size_t populate_for_reading(const void* data, std::size_t bytes) {
  static std::atomic<bool> unknown{false};
  return detail::populate_interior(data, bytes, kMadvPopulateRead, unknown);
}

/// A buffer whose storage was just made, before anything writes it: its 2 MiB-aligned interior
/// advised for huge pages when they are switched on (advise_huge_pages), then its pages made
/// resident (populate_for_writing). Returns the bytes populated.
inline std::size_t make_resident(const void* data, std::size_t bytes) {
  advise_huge_pages(data, bytes);
  return populate_for_writing(data, bytes);
}

/// `v` (an Eigen vector) becomes n entries; storage made here (a size other than n before) is
/// made resident before anything writes it (make_resident), and its entries are unspecified, as
/// resize leaves them. A vector that already has n entries keeps its storage and values. For
/// buffers written whole after (a buffer written in a band only: resize_to_released_zeros).
template <class Vector>
void resize_resident(Vector& v, long n) {
  if (static_cast<long>(v.size()) == n) return;
  v.resize(n);
  if (n > 0) make_resident(v.data(), sizeof(*v.data()) * static_cast<std::size_t>(n));
}

/// `v`'s capacity becomes at least n; when that needs new storage, the storage is made and made
/// resident (make_resident) before v's entries are copied into it. v keeps its entries. Then a
/// copy, assign or resize up to n entries writes resident pages.
template <class T>
void reserve_resident(std::vector<T>& v, std::size_t n) {
  if (n <= v.capacity()) return;
  std::vector<T> fresh;
  fresh.reserve(n);
  make_resident(fresh.data(), sizeof(T) * n);
  fresh.assign(v.begin(), v.end());
  v.swap(fresh);
}

/// `v` becomes n copies of `value` (v.assign(n, value)), its storage made resident first when
/// the assign needs new storage (reserve_resident).
template <class T>
void assign_resident(std::vector<T>& v, std::size_t n, const T& value) {
  reserve_resident(v, n);
  v.assign(n, value);
}

}  // namespace monolith
