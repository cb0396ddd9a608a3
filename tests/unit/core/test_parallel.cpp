// The thread policy of reference/core/parallel.hpp (issue 19): the values --threads and
// MONOLITH_THREADS accept, the free-core count of `auto`, the chunk of dynamically shared loops.
#include <omp.h>

#include <catch2/catch.hpp>

#include "reference/core/parallel.hpp"

using namespace monolith;

TEST_CASE("thread specs: auto or an integer in 1..1024, nothing else", "[unit]") {
  CHECK(parse_thread_spec("auto").valid);
  CHECK(parse_thread_spec("auto").automatic);
  for (const auto& [text, n] : std::vector<std::pair<std::string, int>>{{"1", 1}, {"2", 2}, {"1024", 1024}, {"0064", 64}}) {
    CAPTURE(text);
    const ThreadSpec s = parse_thread_spec(text);
    CHECK(s.valid);
    CHECK_FALSE(s.automatic);
    CHECK(s.count == n);
  }
  for (const char* bad : {"", "0", "1025", "-1", "+2", " 2", "2 ", "2.0", "Auto", "AUTO", "two", "99999", "1e3"}) {
    CAPTURE(bad);
    CHECK_FALSE(parse_thread_spec(bad).valid);
  }
}

TEST_CASE("auto threads: between 1 and the CPUs of the affinity mask", "[unit]") {
  const int cpus = static_cast<int>(affinity_cpus().size());
  REQUIRE(cpus >= 1);
  const int free = free_cores(20);
  CHECK(free >= 1);
  CHECK(free <= cpus);
  // with the process-wide team on, auto caps at the whole mask (the team follows the free
  // cores during the run); without it, the cores free at the start
  const bool monitor = core_monitor();
  set_core_monitor(true);
  CHECK(automatic_thread_count() == cpus);
  set_core_monitor(false);
  CHECK(automatic_thread_count() >= 1);
  CHECK(automatic_thread_count() <= cpus);
  set_core_monitor(monitor);
}

TEST_CASE("dynamic chunks: at least 1, about 8 per thread of the team", "[unit]") {
  const int saved = omp_get_max_threads();
  omp_set_num_threads(2);
  CHECK(dynamic_chunk(0) == 1);
  CHECK(dynamic_chunk(10) == 1);
  CHECK(dynamic_chunk(1600) == 100);
  int inside = 0;
#pragma omp parallel num_threads(4)
  {
#pragma omp single
    inside = dynamic_chunk(3200) * omp_get_num_threads();
  }
  CHECK(inside == 3200 / 8);
  omp_set_num_threads(saved);
}
