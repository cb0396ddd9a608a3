#pragma once
/// \file memory_policy.hpp
/// A process-wide allocator setting for long simulation runs. It is the application's choice,
/// not the library's: `monolith` (reference/app/main.cpp) sets it; a program that embeds the
/// core decides for itself (the core never changes process-wide settings on its own).

#if defined(__GLIBC__)
#include <malloc.h>
#endif
#include <limits>

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
  mallopt(M_TRIM_THRESHOLD, std::numeric_limits<int>::max());
#endif
}

}  // namespace monolith
