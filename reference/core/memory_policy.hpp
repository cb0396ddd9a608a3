#pragma once
/// \file memory_policy.hpp
/// A process-wide allocator setting for long simulation runs. It is the application's choice,
/// not the library's: `monolith` (reference/app/main.cpp) sets it; a program that embeds the
/// core decides for itself (the core never changes process-wide settings on its own).
///
/// The first touch of fresh buffers (issue 20, kern25) is not a process-wide setting: the core
/// advises the buffers it makes itself (core/first_touch.hpp: made resident in one
/// madvise(MADV_POPULATE_WRITE) call, on by default, MONOLITH_POPULATE=0 or set_populate(false)
/// turns it off) and changes no value. Whether those buffers also get huge pages is the
/// program's choice (core/huge_pages.hpp: set_huge_pages, or MONOLITH_HUGE_PAGES=1 for
/// `monolith`); `monolith` keeps them off, as the core's default: on the development host
/// (a virtual machine) huge pages took fewer faults but more kernel and more user time in every
/// run of Fig. 2's paper grid measured, on one and on two threads, after a run with small pages
/// and right after one with huge pages (docs/benchmarks.md, "The first touch in one call").

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace monolith {

/// Grid-sized vectors (weights, level sets, right-hand sides) are built and released every
/// step. glibc serves blocks above its mmap threshold (at most 32 MB, about a 128^3 grid's face
/// vector) with fresh mappings and returns them on free, so every step paid for the kernel
/// faulting in and zeroing those pages again: 12% of a 128^3 Fig. 2 profile (docs/benchmarks.md).
/// Served from the heap and kept there (no trimming), a released block is reused by the next
/// step's allocation of the same size. Results are unaffected. Call once, early in main().
inline void keep_freed_memory_for_reuse() {
#if defined(__GLIBC__)
  mallopt(M_MMAP_MAX, 0);
  // -1: never trim (mallopt(3)). The largest int, 2 GB, was not enough: at 128^3 a coupled
  // step releases more than 2 GB at its end, glibc returned it to the kernel and the next step
  // faulted it in again (clear_page_erms 13% of the samples of a 128^3 Fig. 2 frame, issue 20).
  mallopt(M_TRIM_THRESHOLD, -1);
#endif
}

}  // namespace monolith
