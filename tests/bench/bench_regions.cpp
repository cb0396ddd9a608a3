// Benchmark (not a test) of the fixed cost of an OpenMP parallel region and of a barrier on this
// machine (issue 16, docs/benchmarks.md "The step outside the solve on two threads: the regions'
// fixed cost"). Everything is measured in this one process with a team of 2 (or --threads N):
//
//   hot region    an empty region right after the previous one (the other thread still spins)
//   cold region   an empty region after G microseconds of serial work on the calling thread (the
//                 other thread has gone to sleep on a futex once its spin count ran out): the
//                 region's time on the caller and the delay until the woken thread runs
//   barrier       a barrier inside a region where both threads arrive together, and one where the
//                 caller arrives G microseconds late (the other thread sleeps meanwhile): the
//                 delay from the caller's arrival until the waiting thread leaves
//   spin          the CPU time a thread burns while it waits 5 ms at a barrier (the spin before
//                 it sleeps; independent of the load)
//   TeamScope     one AdaptiveTeam choose + record (reference/core/parallel.hpp)
//
// GNU OpenMP reads GOMP_SPINCOUNT only when it loads, so compare spin counts by running the
// program once per value (`GOMP_SPINCOUNT=0 build/bench/bench_regions`); the program does not
// set one (without it libgomp spins its default, about 300k iterations; `monolith` sets 10000).
// Prints medians and the 10th-90th percentiles of each, in microseconds.
//
//   build/bench/bench_regions [--threads N] [--reps R]
#include <omp.h>
#include <sched.h>
#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "reference/core/parallel.hpp"

using namespace monolith;

namespace {

using Clock = std::chrono::steady_clock;

double now_us() {
  return std::chrono::duration<double, std::micro>(Clock::now().time_since_epoch()).count();
}

/// The body of an "empty" region (a region without a body is compiled away).
std::atomic<long> touched{0};
void touch() { touched.fetch_add(1, std::memory_order_relaxed); }

/// Busy work on the calling thread for `us` microseconds (no sleep: the core stays taken).
void spin_for(double us) {
  const double end = now_us() + us;
  while (now_us() < end) {
  }
}

struct Spread {
  double p10, median, p90;
};
Spread spread(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const auto at = [&](double q) { return v[std::min(v.size() - 1, static_cast<std::size_t>(q * v.size()))]; };
  return {at(0.1), at(0.5), at(0.9)};
}
void print(const char* what, const Spread& s) {
  std::printf("  %-46s %9.2f us  (p10 %8.2f, p90 %8.2f)\n", what, s.median, s.p10, s.p90);
}

}  // namespace

int main(int argc, char** argv) {
  int threads = 2, reps = 2000;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--threads" && i + 1 < argc) threads = std::atoi(argv[++i]);
    else if (a == "--reps" && i + 1 < argc) reps = std::atoi(argv[++i]);
    else {
      std::fprintf(stderr, "usage: %s [--threads N] [--reps R]\n", argv[0]);
      return 2;
    }
  }
  const char* spin = std::getenv("GOMP_SPINCOUNT");
  const char* policy = std::getenv("OMP_WAIT_POLICY");
  std::printf("bench_regions: team %d, %d repetitions, GOMP_SPINCOUNT=%s, OMP_WAIT_POLICY=%s\n", threads, reps,
              spin ? spin : "(unset: libgomp default)", policy ? policy : "(unset)");
  omp_set_dynamic(0);
#pragma omp parallel num_threads(threads)
  {
  }  // create the team once

  {  // hot regions: back to back
    std::vector<double> t(reps);
    for (int r = 0; r < reps; ++r) {
      const double t0 = now_us();
#pragma omp parallel num_threads(threads)
      touch();
      t[r] = now_us() - t0;
    }
    print("hot empty region", spread(t));
  }
  {  // a team of one (num_threads(1)): the region's own overhead
    std::vector<double> t(reps);
    for (int r = 0; r < reps; ++r) {
      const double t0 = now_us();
#pragma omp parallel num_threads(1)
      touch();
      t[r] = now_us() - t0;
    }
    print("region with a team of one", spread(t));
  }
  for (double gap : {20.0, 100.0, 500.0, 2000.0}) {  // cold regions after `gap` us of serial work
    const int n = std::max(50, static_cast<int>(std::min<double>(reps, 2.0e6 / (gap + 50.0))));
    std::vector<double> region(n), wake(n);
    for (int r = 0; r < n; ++r) {
      spin_for(gap);
      std::atomic<double> started{0.0};
      const double t0 = now_us();
#pragma omp parallel num_threads(threads)
      {
        if (omp_get_thread_num() == 1) started.store(now_us(), std::memory_order_relaxed);
      }
      const double t1 = now_us();
      region[r] = t1 - t0;
      wake[r] = started.load() - t0;
    }
    char name[96];
    std::snprintf(name, sizeof name, "empty region after %.0f us serial: region", gap);
    print(name, spread(region));
    std::snprintf(name, sizeof name, "  ... the other thread starts after");
    print(name, spread(wake));
  }
  {  // barriers where both arrive together; which CPU each thread is on after each
    const int k = reps;
    double total = 0.0;
    std::vector<int> cpu0(k, -1), cpu1(k, -2);
    const double t0 = now_us();
#pragma omp parallel num_threads(threads)
    {
      for (int i = 0; i < k; ++i) {
#pragma omp barrier
        if (omp_get_thread_num() == 0) cpu0[i] = sched_getcpu();
        if (omp_get_thread_num() == 1) cpu1[i] = sched_getcpu();
      }
    }
    total = now_us() - t0;
    int same = 0;
    for (int i = 0; i < k; ++i) same += cpu0[i] == cpu1[i];
    std::printf("  %-46s %9.2f us  (mean of %d)\n", "barrier, both threads arrive together", total / k, k);
    std::printf("  %-46s %9.1f %%   (of %d)\n", "  ... threads 0 and 1 on the same CPU after it", 100.0 * same / k, k);
  }
  for (double late : {20.0, 100.0, 500.0, 2000.0}) {  // the caller arrives `late` us after the other
    const int n = std::max(50, static_cast<int>(std::min<double>(reps, 2.0e6 / (late + 50.0))));
    std::vector<double> delay(n);
#pragma omp parallel num_threads(threads)
    {
      for (int r = 0; r < n; ++r) {
        static double arrive;  // shared: the caller's arrival
        if (omp_get_thread_num() == 0) {
          spin_for(late);
          arrive = now_us();
        }
#pragma omp barrier
        if (omp_get_thread_num() == 1) delay[r] = now_us() - arrive;
#pragma omp barrier
      }
    }
    char name[96];
    std::snprintf(name, sizeof name, "barrier, caller %.0f us late: other leaves after", late);
    print(name, spread(delay));
  }
  {  // how long a waiting thread spins before it sleeps: its own CPU time while the caller
     // sleeps (not spins) 5 ms before the barrier; the CPU time does not depend on the load
    const int n = 100;
    std::vector<double> cpu(n);
#pragma omp parallel num_threads(threads)
    {
      for (int r = 0; r < n; ++r) {
        timespec a{}, b{};
        if (omp_get_thread_num() == 0) std::this_thread::sleep_for(std::chrono::milliseconds(5));
        if (omp_get_thread_num() == 1) clock_gettime(CLOCK_THREAD_CPUTIME_ID, &a);
#pragma omp barrier
        if (omp_get_thread_num() == 1) {
          clock_gettime(CLOCK_THREAD_CPUTIME_ID, &b);
          cpu[r] = 1e6 * static_cast<double>(b.tv_sec - a.tv_sec) + 1e-3 * static_cast<double>(b.tv_nsec - a.tv_nsec);
        }
#pragma omp barrier
      }
    }
    print("CPU of a thread waiting 5 ms at a barrier", spread(cpu));
  }
  {  // the AdaptiveTeam bookkeeping of one call
    static AdaptiveTeam site;
    const int n = reps * 10;
    const double t0 = now_us();
    for (int r = 0; r < n; ++r) {
      TeamScope team(site, 1L << 20);
      if (team.threads() < 1) std::abort();
    }
    std::printf("  %-46s %9.2f us  (mean of %d)\n", "TeamScope choose + record", (now_us() - t0) / n, n);
  }
  return 0;
}
