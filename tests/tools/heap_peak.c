/* heap_peak.c: an LD_PRELOAD heap profile of the large blocks of a run (docs/benchmarks.md,
 * issue 20). Every malloc/calloc/realloc/aligned allocation of at least HEAP_PEAK_MIN bytes
 * (environment, default 4 MiB) is recorded with its call stack while it lives; at the moment the
 * sum of the live large blocks peaks, the live list is copied. At exit the peak list goes to
 * stderr (or HEAP_PEAK_OUT): size, then the return addresses as offsets into the executable,
 * which tests/tools/heap_peak_report.py turns into function names (nm).
 *   cc -O2 -shared -fPIC -o heap_peak.so tests/tools/heap_peak.c -ldl
 *   LD_PRELOAD=./heap_peak.so HEAP_PEAK_OUT=peak.txt build/bin/monolith run ...
 * Not thread-safe beyond a spin lock around the table (the allocations it records are rare). */
#define _GNU_SOURCE
#include <execinfo.h>
#include <link.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <malloc.h>

extern void* __libc_malloc(size_t);
extern void* __libc_calloc(size_t, size_t);
extern void* __libc_realloc(void*, size_t);
extern void __libc_free(void*);
extern void* __libc_memalign(size_t, size_t);

#define MAX_LIVE 4096
#define DEPTH 14
typedef struct { void* p; size_t n; int depth; void* stack[DEPTH]; } Block;
static Block live[MAX_LIVE], peak[MAX_LIVE];
static int nlive, npeak;
static size_t live_bytes, peak_bytes, min_bytes;
static volatile int lock_word;
static __thread int inside;

static void lock(void) { while (__sync_lock_test_and_set(&lock_word, 1)) {} }
static void unlock(void) { __sync_lock_release(&lock_word); }

static size_t threshold(void) {
  if (!min_bytes) {
    const char* s = getenv("HEAP_PEAK_MIN");
    min_bytes = s ? (size_t)atoll(s) : (size_t)4 << 20;
  }
  return min_bytes;
}

static void note_alloc(void* p, size_t n) {
  if (!p || n < threshold() || inside) return;
  inside = 1;
  Block b;
  b.p = p;
  b.n = n;
  b.depth = backtrace(b.stack, DEPTH);
  lock();
  if (nlive < MAX_LIVE) live[nlive++] = b;
  live_bytes += n;
  if (live_bytes > peak_bytes) {
    peak_bytes = live_bytes;
    memcpy(peak, live, sizeof(Block) * nlive);
    npeak = nlive;
  }
  unlock();
  inside = 0;
}

static void note_free(void* p) {
  if (!p) return;
  lock();
  for (int i = nlive - 1; i >= 0; --i)
    if (live[i].p == p) {
      live_bytes -= live[i].n;
      live[i] = live[--nlive];
      break;
    }
  unlock();
}

void* malloc(size_t n) { void* p = __libc_malloc(n); note_alloc(p, n); return p; }
void* calloc(size_t a, size_t b) { void* p = __libc_calloc(a, b); note_alloc(p, a * b); return p; }
void free(void* p) { note_free(p); __libc_free(p); }
void* realloc(void* q, size_t n) {
  note_free(q);
  void* p = __libc_realloc(q, n);
  note_alloc(p, n);
  return p;
}
void* memalign(size_t a, size_t n) { void* p = __libc_memalign(a, n); note_alloc(p, n); return p; }
void* aligned_alloc(size_t a, size_t n) { return memalign(a, n); }
int posix_memalign(void** out, size_t a, size_t n) {
  void* p = __libc_memalign(a, n);
  if (!p) return 12;
  note_alloc(p, n);
  *out = p;
  return 0;
}

static int find_base(struct dl_phdr_info* info, size_t size, void* data) {
  (void)size;
  if (info->dlpi_name[0] == 0) { *(unsigned long*)data = info->dlpi_addr; return 1; }
  return 0;
}

__attribute__((destructor)) static void report(void) {
  unsigned long base = 0;
  dl_iterate_phdr(find_base, &base);
  const char* path = getenv("HEAP_PEAK_OUT");
  FILE* f = path ? fopen(path, "w") : stderr;
  if (!f) return;
  fprintf(f, "peak %zu bytes in %d blocks of >= %zu bytes\n", peak_bytes, npeak, min_bytes);
  for (int i = 0; i < npeak; ++i) {
    fprintf(f, "block %zu", peak[i].n);
    for (int k = 1; k < peak[i].depth; ++k)
      fprintf(f, " %lx", (unsigned long)peak[i].stack[k] - base);
    fprintf(f, "\n");
  }
  if (f != stderr) fclose(f);
}
