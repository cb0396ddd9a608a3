#pragma once
/// \file parallel.hpp
/// Thread policy of the project (issue 19, docs/cli.md "Threads"): how many OpenMP threads a run
/// uses, how idle threads wait, and below which size a loop stays on one thread.
///
/// Every parallel loop of the library writes each output entry from exactly one thread and sums
/// in a fixed order, so the thread count never changes a result; it only changes the time. Two
/// things make extra threads slower than one on a busy machine: a parallel region or barrier per
/// small piece of work (every barrier waits for the slowest thread, and a thread whose core is
/// taken by another process may wait a whole scheduler time slice), and GNU OpenMP's default of
/// spinning up to ~300k iterations in a barrier, which burns the very core the late thread needs.
/// The remedies here: few regions (the sweeps run their colours inside one region), a serial
/// fall-back below kParallelMinWork, a short spin before sleeping (GOMP_SPINCOUNT, applied by
/// re-executing the program once: libgomp reads it only when it loads), and `auto` threads =
/// the cores of the affinity mask that are currently idle.

#include <omp.h>
#include <sched.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace monolith {

/// Loops over fewer entries than this (rows x entries, unknowns, grid cells) run on one thread:
/// below it the parallel region and its barriers cost more than the second thread saves. From
/// bench_threads (docs/benchmarks.md, "Threads"): at 16k entries a 3D stencil pass takes ~50 us
/// on one thread, a region with two barriers about 5-20 us idle and up to milliseconds when a
/// core is busy.
constexpr long kParallelMinWork = 16384;

/// The chunk of a dynamically shared loop of `count` iterations: about 8 chunks per thread of the
/// current (or the next) team. Threads take chunks on demand, so a thread whose core is taken by
/// another process does not hold half the work until the barrier; balanced enough on an idle
/// machine. Used only on loops whose iterations write disjoint entries and read nothing another
/// iteration of the same loop writes, so the split never changes a result.
inline int dynamic_chunk(long count) {
  const int threads = omp_in_parallel() ? omp_get_num_threads() : omp_get_max_threads();
  return static_cast<int>(std::max(1L, count / (8L * std::max(1, threads))));
}

/// The spin count GNU OpenMP gets when the user set neither OMP_WAIT_POLICY nor GOMP_SPINCOUNT:
/// about 10-30 us of spinning in a barrier before the thread sleeps on a futex (the default,
/// 300000, spins ~1 ms, which on a core shared with another process is a millisecond taken from
/// the thread everyone waits for).
constexpr const char* kDefaultSpinCount = "10000";

/// The CPUs this process may run on (sched_getaffinity), in increasing order; {0..n-1} from
/// hardware_concurrency when the mask cannot be read.
inline std::vector<int> affinity_cpus() {
  std::vector<int> cpus;
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof(set), &set) == 0) {
    for (int c = 0; c < CPU_SETSIZE; ++c)
      if (CPU_ISSET(c, &set)) cpus.push_back(c);
  }
  if (cpus.empty()) {
    const int n = std::max(1u, std::thread::hardware_concurrency());
    for (int c = 0; c < n; ++c) cpus.push_back(c);
  }
  return cpus;
}

namespace detail {
/// Busy and total jiffies per CPU from /proc/stat ("cpuN user nice system idle iowait irq
/// softirq steal ..."); index = CPU number; empty when unreadable.
inline std::vector<std::pair<unsigned long long, unsigned long long>> cpu_jiffies() {
  std::vector<std::pair<unsigned long long, unsigned long long>> out;
  std::ifstream in("/proc/stat");
  std::string line;
  while (std::getline(in, line)) {
    if (line.compare(0, 3, "cpu") != 0 || line.size() < 4 || !std::isdigit(static_cast<unsigned char>(line[3])))
      continue;
    std::istringstream s(line.substr(3));
    int cpu = -1;
    s >> cpu;
    unsigned long long v[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    for (auto& x : v) s >> x;
    if (cpu < 0) continue;
    if (static_cast<int>(out.size()) <= cpu) out.resize(cpu + 1, {0, 0});
    unsigned long long total = 0;
    for (auto x : v) total += x;
    out[cpu] = {total - v[3] - v[4], total};  // busy = all but idle and iowait
  }
  return out;
}
}  // namespace detail

/// The number of CPUs of the affinity mask that are free now: sampled from /proc/stat over
/// `sample_ms`, a CPU counts as free when it was idle at least half of that time. At least 1.
/// Without /proc/stat: the size of the affinity mask.
inline int free_cores(int sample_ms = 100) {
  const std::vector<int> cpus = affinity_cpus();
  const auto before = detail::cpu_jiffies();
  if (before.empty()) return static_cast<int>(cpus.size());
  std::this_thread::sleep_for(std::chrono::milliseconds(sample_ms));
  const auto after = detail::cpu_jiffies();
  int free = 0;
  for (int c : cpus) {
    if (c >= static_cast<int>(before.size()) || c >= static_cast<int>(after.size())) {
      ++free;  // not listed: assume free
      continue;
    }
    const double busy = static_cast<double>(after[c].first - before[c].first);
    const double total = static_cast<double>(after[c].second - before[c].second);
    if (total <= 0.0 || busy <= 0.5 * total) ++free;
  }
  return std::max(1, free);
}

/// The result of parsing a thread-count value (`--threads`, MONOLITH_THREADS).
struct ThreadSpec {
  bool valid = false;
  bool automatic = false;  ///< "auto"
  int count = 0;           ///< 1..1024 when not automatic
};

/// "auto" or an integer in 1..1024 (surrounding blanks not allowed).
inline ThreadSpec parse_thread_spec(const std::string& value) {
  ThreadSpec spec;
  if (value == "auto") {
    spec.valid = spec.automatic = true;
    return spec;
  }
  if (value.empty() || value.size() > 4) return spec;
  for (char ch : value)
    if (!std::isdigit(static_cast<unsigned char>(ch))) return spec;
  const int n = std::atoi(value.c_str());
  if (n < 1 || n > 1024) return spec;
  spec.valid = true;
  spec.count = n;
  return spec;
}

/// The thread count of `auto`: the free cores of the affinity mask (free_cores), never more.
inline int automatic_thread_count() { return free_cores(); }

/// Call first thing in main(). When the user set neither OMP_WAIT_POLICY nor GOMP_SPINCOUNT (and
/// MONOLITH_KEEP_WAIT_POLICY is not set), sets GOMP_SPINCOUNT=kDefaultSpinCount and re-executes
/// the program once (/proc/self/exe, the same arguments), because GNU OpenMP reads the variable
/// only when it is loaded, before main(). MONOLITH_WAIT_POLICY_SET marks the second start, so it
/// happens at most once. Returns only when no re-exec took place (or it failed: then the
/// program runs on with libgomp's default).
inline void apply_default_wait_policy(char** argv) {
  if (std::getenv("OMP_WAIT_POLICY") || std::getenv("GOMP_SPINCOUNT") ||
      std::getenv("MONOLITH_KEEP_WAIT_POLICY") || std::getenv("MONOLITH_WAIT_POLICY_SET"))
    return;
  setenv("GOMP_SPINCOUNT", kDefaultSpinCount, 1);
  setenv("MONOLITH_WAIT_POLICY_SET", "1", 1);
  execv("/proc/self/exe", argv);
  // exec failed (no /proc): carry on with the default policy; the variables stay for children
}

}  // namespace monolith
