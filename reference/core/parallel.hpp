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
/// re-executing the program once: libgomp reads it only when it loads), `auto` threads = the
/// cores of the affinity mask that are currently idle, and a team size per kernel chosen by
/// measurement (AdaptiveTeam), all under one process-wide team size that follows the cores other
/// processes take (ProcessTeam, process_threads(); loops outside the measured kernels take it
/// through team_threads()).

#include <Eigen/Core>
#include <omp.h>
#include <sched.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "reference/core/env_switch.hpp"

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

/// Whether parallel kernels choose their team size by measurement (AdaptiveTeam, the default)
/// or always take the whole team of omp_get_max_threads(). Set once from the environment
/// (MONOLITH_ADAPTIVE_THREADS=0 switches it off) unless set_adaptive_teams was called first;
/// benchmarks switch it to time a fixed team.
inline std::atomic<int>& adaptive_teams_flag() {
  static std::atomic<int> flag{-1};  // -1: not decided yet
  return flag;
}
/// A switch that is on unless MONOLITH_ADAPTIVE_THREADS=0, read from the environment the first
/// time it is asked (flag -1) unless a set_... call decided it before.
inline bool adaptive_switch(std::atomic<int>& flag) {
  return env_switch(flag, "MONOLITH_ADAPTIVE_THREADS", true);
}
inline bool adaptive_teams() { return adaptive_switch(adaptive_teams_flag()); }
inline void set_adaptive_teams(bool on) { adaptive_teams_flag().store(on ? 1 : 0); }

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
    if (line.compare(0, 3, "cpu") != 0) {
      if (!out.empty()) break;  // the per-CPU lines come first; skip the long "intr" line
      continue;
    }
    if (line.size() < 4 || !std::isdigit(static_cast<unsigned char>(line[3]))) continue;
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

/// Whether the process-wide team follows the cores other processes take (ProcessTeam). On
/// unless MONOLITH_ADAPTIVE_THREADS=0 (then every region takes the whole cap); tests of the
/// per-site policy switch it off so the machine's load does not change their cap.
inline std::atomic<int>& core_monitor_flag() {
  static std::atomic<int> flag{-1};  // -1: not decided yet
  return flag;
}
inline bool core_monitor() { return adaptive_switch(core_monitor_flag()); }
inline void set_core_monitor(bool on) { core_monitor_flag().store(on ? 1 : 0); }

/// The process-wide team size for the next window, from the cores other processes used in the
/// last one: `cpus` = the CPUs of the affinity mask, `team` = the current size, `others` = the
/// CPUs' busy time minus this process's own CPU time, in cores. Every thread of a team needs a
/// core of its own (a thread sharing a core with another process makes every barrier wait for
/// it), so the team is the cores left over: cpus - others, rounded with a hysteresis of
/// +-0.1 core around the half (down when others exceeds the free share by 0.6 core, up when it
/// is below it by 0.6, i.e. others < cpus - team - 0.4), so a measurement noise of a tick or
/// two per window does not make the team flip. In 1..cpus.
inline int next_process_team(int cpus, int team, double others) {
  cpus = std::max(1, cpus);
  team = std::clamp(team, 1, cpus);
  const int down = cpus - static_cast<int>(std::ceil(others - 0.6));
  const int up = cpus - static_cast<int>(std::ceil(others - 0.4));
  if (down < team) team = down;
  else if (up > team) team = up;
  return std::clamp(team, 1, cpus);
}

/// The process-wide team size (issue 19): how many threads every parallel loop of the process
/// may use now, from how much CPU time other processes take on the CPUs of the affinity mask.
/// Every kMinWindow (at the first team query after it) it reads the busy time of each CPU
/// (/proc/stat) and this process's own CPU time (CLOCK_PROCESS_CPUTIME_ID); the difference over
/// the window is the cores the other processes used, and next_process_team turns it into the
/// team for the next window. No trial runs: a kernel never runs with a team just to find out
/// whether it is faster (short kernels' trials landed on the busy core and lost for the wrong
/// reason), and no kernel pays for a slow probe. It reacts within one window (100 ms) when
/// another process takes a core or gives it back. Without /proc/stat it keeps the whole mask.
/// One instance per process (instance()); thread-safe (a query that finds another thread
/// updating returns the current size).
class ProcessTeam {
 public:
  static constexpr double kMinWindow = 0.1;  // seconds

  static ProcessTeam& instance() {
    static ProcessTeam team;
    return team;
  }

  /// The team size now (1..the CPUs of the affinity mask), updated when a window has passed.
  int size() {
    const auto now = std::chrono::steady_clock::now();
    if (std::chrono::duration<double>(now - last_).count() >= kMinWindow) {
      std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
      if (lock.owns_lock() && std::chrono::duration<double>(now - last_).count() >= kMinWindow)
        update(now);
    }
    return team_.load(std::memory_order_relaxed);
  }

  /// The cores other processes used in the last window (for benchmarks and logs).
  double others() const { return others_.load(std::memory_order_relaxed); }

 private:
  ProcessTeam() : cpus_(affinity_cpus()), team_(static_cast<int>(cpus_.size())) {
    last_ = std::chrono::steady_clock::now();
    jiffies_ = detail::cpu_jiffies();
    own_ = own_seconds();
  }
  static double own_seconds() {
    timespec ts{};
    if (clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts) != 0) return 0.0;
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
  }
  void update(std::chrono::steady_clock::time_point now) {
    const auto jiffies = detail::cpu_jiffies();
    const double own = own_seconds();
    const double wall = std::chrono::duration<double>(now - last_).count();
    if (!jiffies.empty() && !jiffies_.empty() && wall > 0.0) {
      double busy = 0.0;  // in cores: the sum of each CPU's busy fraction over the window
      for (int c : cpus_) {
        if (c >= static_cast<int>(jiffies.size()) || c >= static_cast<int>(jiffies_.size())) continue;
        const double b = static_cast<double>(jiffies[c].first - jiffies_[c].first);
        const double t = static_cast<double>(jiffies[c].second - jiffies_[c].second);
        if (t > 0.0) busy += std::clamp(b / t, 0.0, 1.0);
      }
      const double others = std::max(0.0, busy - (own - own_) / wall);
      others_.store(others, std::memory_order_relaxed);
      team_.store(next_process_team(static_cast<int>(cpus_.size()), team_.load(), others),
                  std::memory_order_relaxed);
    }
    jiffies_ = jiffies;
    own_ = own;
    last_ = now;
  }

  std::mutex mutex_;
  std::vector<int> cpus_;
  std::atomic<int> team_;
  std::atomic<double> others_{0.0};
  std::chrono::steady_clock::time_point last_;
  std::vector<std::pair<unsigned long long, unsigned long long>> jiffies_;
  double own_ = 0.0;
};

/// The team size of every parallel region of the library: at most omp_get_max_threads() (the
/// cap, `--threads N`), and no more than ProcessTeam's free cores (unless MONOLITH_ADAPTIVE_THREADS=0
/// or set_core_monitor(false)); 1 inside a parallel region.
///
/// Eigen's own OpenMP loops (a row-major sparse matrix times a dense vector above 20000
/// non-zeros, dense matrix products) follow it too: each call hands the size to
/// Eigen::setNbThreads when it changed (those loops write each output entry from one thread,
/// so their results do not depend on it either).
inline int process_threads() {
  if (omp_in_parallel()) return 1;
  const int cap = omp_get_max_threads();
  const int team = core_monitor() ? std::max(1, std::min(cap, ProcessTeam::instance().size())) : cap;
  static std::atomic<int> eigen_threads{0};
  if (eigen_threads.load(std::memory_order_relaxed) != team) {
    eigen_threads.store(team, std::memory_order_relaxed);
    Eigen::setNbThreads(team);
  }
  return team;
}

/// The hook for a parallel loop over `work` entries (rows, cells, particles) outside the
/// measured kernels: 1 below kParallelMinWork (the region would cost more than it saves), else
/// process_threads(). Use as
///   #pragma omp parallel for schedule(static) num_threads(team_threads(n))
/// Any team size gives the same result in a loop whose iterations write disjoint entries.
inline int team_threads(long work) { return work < kParallelMinWork ? 1 : process_threads(); }

/// The team size of one parallel kernel (a "site": the Stokes apply, a pressure sweep, ...),
/// chosen by measuring it (issue 19). Every kernel of the library gives bitwise the same result
/// for any team size, so the team may change from one call to the next without changing a
/// result; only the time changes. The cap is process_threads(): at most omp_get_max_threads()
/// (`--threads N`) and at most the cores other processes leave free (ProcessTeam); a change of
/// the cap starts the site afresh at the new cap.
///
/// Policy: the site runs with its current team size t (at first the cap) and keeps the seconds
/// per unit of work of its last 3 calls at t; their median is t's current estimate. Now and then
/// one call runs with a neighbouring size (t - 1 or t + 1, alternately, within 1..cap), a probe:
/// after 4 calls, then after twice as many calls each time a probe loses, at most every
/// kMaxProbeInterval calls, and at once when t's estimate rose above kAlarmAbove times its
/// long-run average (another process took a core). A probe wins when its time per unit of work
/// is below kSwitchBelow times t's estimate; a winning probe is repeated once, and the site moves
/// to that size only when the repeat wins too (one lucky time slice does not move it). On an
/// idle machine the probes of a smaller team lose and become rare (at most one call at the
/// slower size every kMaxProbeInterval calls); when another process takes a core, the barriers
/// of a full team wait for a thread that is not running, a smaller team wins and the site runs
/// with it until a probe of the larger team wins again (the other process ended).
///
/// Calls below kParallelMinWork, calls inside a parallel region and calls with a cap of 1 run on
/// one thread and are not measured. Thread-safe (a mutex around the bookkeeping).
class AdaptiveTeam {
 public:
  static constexpr int kFirstProbeInterval = 4;
  static constexpr int kMaxProbeInterval = 64;
  /// A probe wins when its time per unit of work is below this fraction of the current estimate.
  static constexpr double kSwitchBelow = 0.97;
  /// The current size's estimate above this many times its long-run average: probe now.
  static constexpr double kAlarmAbove = 1.5;
  /// Weight of a new call in the long-run average.
  static constexpr double kAverageWeight = 0.125;

  /// The team size for the next call over `work` entries; 0 means "one thread, do not record".
  int choose(long work) {
    if (omp_in_parallel()) return 0;
    const int cap = process_threads();  // (updates the process-wide team now and then)
    if (work < kParallelMinWork || cap <= 1) return 0;
    if (!adaptive_teams()) return cap;
    std::lock_guard<std::mutex> lock(mutex_);
    if (current_ < 1 || cap != cap_) {
      reset(cap);
      cap_ = cap;
    }
    if (confirm_ >= 1 && confirm_ <= cap) return confirm_;  // repeat a winning probe
    confirm_ = 0;
    if (++calls_ < interval_) return current_;
    calls_ = 0;
    // the neighbour on the side of the last direction, else the other side
    int probe = current_ + direction_;
    if (probe < 1 || probe > cap) {
      direction_ = -direction_;
      probe = current_ + direction_;
    }
    direction_ = -direction_;  // the other side next time
    if (probe < 1 || probe > cap) return current_;
    return probe;
  }

  /// Records that a call over `work` entries took `seconds` with `team` threads (team from
  /// choose, > 0).
  void record(int team, long work, double seconds) {
    if (!adaptive_teams() || work <= 0) return;
    const double rate = seconds / static_cast<double>(work);
    std::lock_guard<std::mutex> lock(mutex_);
    if (current_ < 1) reset(team);
    if (team == current_) {
      recent_[count_++ % 3] = rate;
      average_ = average_ > 0.0 ? (1.0 - kAverageWeight) * average_ + kAverageWeight * rate : rate;
      if (count_ >= 3 && estimate() > kAlarmAbove * average_) {
        calls_ = interval_;  // probe on the next call
        average_ = estimate();
      }
      return;
    }
    // a probe (or its repeat)
    const bool wins = rate < kSwitchBelow * estimate();
    if (wins && confirm_ != team) {
      confirm_ = team;  // repeat it once
      return;
    }
    confirm_ = 0;
    if (wins) {
      direction_ = team > current_ ? 1 : -1;  // keep going that way
      current_ = team;
      count_ = 0;
      recent_[count_++] = rate;
      average_ = rate;
      interval_ = kFirstProbeInterval;
      calls_ = 0;
    } else {
      interval_ = std::min(2 * interval_, kMaxProbeInterval);
    }
  }

  /// The team size the site runs with now (0 before its first measured call).
  int current() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return current_;
  }

 private:
  void reset(int team) {
    current_ = team;
    count_ = 0;
    average_ = 0.0;
    confirm_ = 0;
    calls_ = 0;
    interval_ = kFirstProbeInterval;
  }
  /// The median of the last 3 calls at the current size (fewer: the latest).
  double estimate() const {
    if (count_ < 3) return recent_[(count_ + 2) % 3];
    return std::max(std::min(recent_[0], recent_[1]),
                    std::min(std::max(recent_[0], recent_[1]), recent_[2]));
  }

  mutable std::mutex mutex_;
  double recent_[3] = {0.0, 0.0, 0.0};  // seconds per unit of work of the last calls at current_
  int count_ = 0;                       // calls recorded at current_
  double average_ = 0.0;                // long-run average at current_
  int current_ = 0;
  int cap_ = 0;                         // the cap current_ was chosen under
  int confirm_ = 0;                     // a probe size to repeat on the next call, 0 none
  int calls_ = 0;
  int interval_ = kFirstProbeInterval;
  int direction_ = -1;
};

/// One call of an AdaptiveTeam site: picks the team size at construction and records the
/// elapsed time at destruction. Use as
///   static AdaptiveTeam site;
///   TeamScope team(site, work);
///   #pragma omp parallel num_threads(team.threads()) if (team.parallel())
class TeamScope {
 public:
  TeamScope(AdaptiveTeam& site, long work)
      : site_(site), work_(work), team_(site.choose(work)), start_(std::chrono::steady_clock::now()) {}
  ~TeamScope() {
    if (team_ > 0)
      site_.record(team_, work_,
                   std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count());
  }
  TeamScope(const TeamScope&) = delete;
  TeamScope& operator=(const TeamScope&) = delete;
  /// The team size of this call (at least 1).
  int threads() const { return std::max(1, team_); }
  /// Whether to open a parallel region (team size above 1).
  bool parallel() const { return team_ > 1; }

 private:
  AdaptiveTeam& site_;
  long work_;
  int team_;
  std::chrono::steady_clock::time_point start_;
};

/// The spin count GNU OpenMP gets when the user set neither OMP_WAIT_POLICY nor GOMP_SPINCOUNT:
/// about 10-30 us of spinning in a barrier before the thread sleeps on a futex (the default,
/// 300000, spins ~1 ms, which on a core shared with another process is a millisecond taken from
/// the thread everyone waits for).
constexpr const char* kDefaultSpinCount = "10000";

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

/// The thread count of `auto`: the CPUs of the affinity mask while the process-wide team follows
/// the free cores (ProcessTeam: a run started next to a busy core takes one thread within 0.1 s
/// and the second again when that core becomes free); without it (MONOLITH_ADAPTIVE_THREADS=0)
/// the cores free at the start (free_cores), decided once.
inline int automatic_thread_count() {
  return core_monitor() ? static_cast<int>(affinity_cpus().size()) : free_cores();
}

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

/// emit(i, out) for every i in [0, n) on several threads, each thread over a fixed contiguous
/// block into its own list, the lists joined in block order: the list of the serial loop.
template <class T, class Emit>
std::vector<T> gather_in_order(int n, Emit&& emit) {
  const int blocks = std::max(1, std::min(process_threads(), n / 4096 + 1));
  std::vector<std::vector<T>> part(blocks);
#pragma omp parallel for schedule(static, 1) num_threads(blocks)
  for (int b = 0; b < blocks; ++b) {
    const int lo = static_cast<int>(static_cast<long>(n) * b / blocks);
    const int hi = static_cast<int>(static_cast<long>(n) * (b + 1) / blocks);
    for (int i = lo; i < hi; ++i) emit(i, part[b]);
  }
  std::vector<T> out;
  std::size_t total = 0;
  for (const auto& v : part) total += v.size();
  out.reserve(total);
  for (const auto& v : part) out.insert(out.end(), v.begin(), v.end());
  return out;
}

}  // namespace monolith
