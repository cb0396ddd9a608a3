// The first touch in one call (reference/core/first_touch.hpp, issue 20, branch kern25): the
// populate calls leave a buffer's values as they were (fresh zeros and written data, aligned or
// unaligned ranges, and the bytes beside the range), make exactly the range's whole pages
// resident (mincore), do nothing for an empty, small or null range or when switched off; and
// the resize and assign helpers keep or make storage with the values of Eigen's resize and
// std::vector::assign.
#include <catch2/catch.hpp>

#include <cstdint>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "reference/core/common.hpp"
#include "reference/core/first_touch.hpp"

#if defined(__linux__)
#include <sys/mman.h>
#include <sys/utsname.h>
#include <unistd.h>
#endif

using namespace monolith;

namespace {

#if defined(__linux__)
/// Whether the running kernel is at least 5.14 (the first with MADV_POPULATE_*).
bool kernel_has_populate() {
  utsname u{};
  if (uname(&u) != 0) return false;
  int major = 0, minor = 0;
  if (std::sscanf(u.release, "%d.%d", &major, &minor) != 2) return false;
  return major > 5 || (major == 5 && minor >= 14);
}

/// The number of resident pages among the `pages` pages from the page-aligned `start`.
std::size_t resident_pages(const void* start, std::size_t pages) {
  const std::size_t page = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
  std::vector<unsigned char> in(pages);
  REQUIRE(mincore(const_cast<void*>(start), pages * page, in.data()) == 0);
  std::size_t n = 0;
  for (unsigned char c : in) n += (c & 1);
  return n;
}
#endif

/// Restores the populate switch when it goes out of scope.
struct SwitchGuard {
  bool was = populate_enabled();
  ~SwitchGuard() { set_populate(was); }
};

}  // namespace

TEST_CASE("populate_for_writing keeps a buffer's values, aligned or not, and the bytes beside "
          "it (kern25)", "[unit]") {
  SwitchGuard guard;
  set_populate(true);
  // 5 MiB + 3000 bytes of data from wherever the heap puts them
  const std::size_t total = (std::size_t{5} << 20) + 3000;
  std::vector<unsigned char> buffer(total);
  for (std::size_t i = 0; i < total; ++i) buffer[i] = static_cast<unsigned char>(7 + i % 253);
  const std::vector<unsigned char> copy = buffer;
  const std::size_t page = 4096;
  // (begin, bytes): the whole buffer, unaligned inside it, an odd length to near its end
  const std::size_t cases[][2] = {
      {0, total}, {3, (std::size_t{3} << 20) + 5}, {page + 1, total - page - 17}};
  for (const auto& c : cases) {
    INFO("begin " << c[0] << ", bytes " << c[1]);
    const auto start = reinterpret_cast<std::uintptr_t>(buffer.data() + c[0]);
    const AddressSpan interior = aligned_interior(start, c[1], page);
    const std::size_t written = populate_for_writing(buffer.data() + c[0], c[1]);
    const std::size_t read = populate_for_reading(buffer.data() + c[0], c[1]);
    CHECK((written == interior.bytes() || written == 0));
    CHECK((read == interior.bytes() || read == 0));
#if defined(__linux__)
    if (kernel_has_populate()) {
      CHECK(written == interior.bytes());
      CHECK(read == interior.bytes());
    }
#endif
    CHECK(std::memcmp(buffer.data(), copy.data(), total) == 0);
  }
}

TEST_CASE("populate_for_writing makes a fresh mapping's whole pages resident, as zeros, and no "
          "page beside them (kern25)", "[unit]") {
#if defined(__linux__)
  SwitchGuard guard;
  set_populate(true);
  const std::size_t page = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
  const std::size_t pages = 1024;  // 4 MiB with 4 KiB pages
  void* map = mmap(nullptr, pages * page, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS,
                   -1, 0);
  REQUIRE(map != MAP_FAILED);
  auto* bytes = static_cast<unsigned char*>(map);
  CHECK(resident_pages(map, pages) == 0);
  // from the middle of page 10 to the middle of page 700: the whole pages 11..699
  const std::size_t begin = 10 * page + page / 2, end = 700 * page + 100;
  const std::size_t populated = populate_for_writing(bytes + begin, end - begin);
  if (kernel_has_populate()) {
    CHECK(populated == 689 * page);
    CHECK(resident_pages(map, pages) == 689);
    CHECK(resident_pages(bytes + 11 * page, 689) == 689);
    CHECK(resident_pages(bytes + 10 * page, 1) == 0);
    CHECK(resident_pages(bytes + 700 * page, 1) == 0);
  }
  // the read advice on the rest: pages 700..1023 whole
  const std::size_t read = populate_for_reading(bytes + 700 * page, 324 * page);
  if (kernel_has_populate()) CHECK(read == 324 * page);
  bool zeros = true;
  for (std::size_t i = 0; i < pages * page; ++i) zeros = zeros && bytes[i] == 0;
  CHECK(zeros);
  munmap(map, pages * page);
#endif
}

TEST_CASE("populate does nothing for an empty, small or null range or when switched off "
          "(kern25)", "[unit]") {
  SwitchGuard guard;
  set_populate(true);
  std::vector<double> v(std::size_t{1} << 19, 2.5);  // 4 MiB
  CHECK(populate_for_writing(v.data(), 0) == 0);
  CHECK(populate_for_reading(v.data(), 0) == 0);
  CHECK(populate_for_writing(nullptr, std::size_t{8} << 20) == 0);
  CHECK(populate_for_writing(v.data(), kPopulateMinBytes - 1) == 0);
  CHECK(make_resident(v.data(), 100) == 0);
  set_populate(false);
  CHECK(populate_for_writing(v.data(), sizeof(double) * v.size()) == 0);
  CHECK(populate_for_reading(v.data(), sizeof(double) * v.size()) == 0);
  CHECK(make_resident(v.data(), sizeof(double) * v.size()) == 0);
  CHECK(v == std::vector<double>(std::size_t{1} << 19, 2.5));
}

TEST_CASE("resize_resident and assign_resident: the values of resize and assign, storage kept "
          "when it fits (kern25)", "[unit]") {
  SwitchGuard guard;
  set_populate(true);
  const long n = (3L << 20) / static_cast<long>(sizeof(double)) + 7;  // 3 MiB + 56 bytes
  VectorX v = VectorX::LinSpaced(n, -1.0, 4.0);
  const VectorX copy = v;
  const double* before = v.data();
  resize_resident(v, n);  // the same size: storage and values kept
  CHECK(v.data() == before);
  CHECK(std::memcmp(v.data(), copy.data(), sizeof(double) * static_cast<std::size_t>(n)) == 0);
  resize_resident(v, 2 * n);  // another size: 2n entries, writable
  REQUIRE(v.size() == 2 * n);
  v.setConstant(0.25);
  CHECK(v.sum() == 0.25 * static_cast<double>(2 * n));
  resize_resident(v, 0);
  CHECK(v.size() == 0);

  std::vector<int> ints(10, 3);
  const std::size_t m = (std::size_t{5} << 20) / sizeof(int) + 3;
  assign_resident(ints, m, -1);  // above the capacity: new storage
  REQUIRE(ints.size() == m);
  CHECK(ints == std::vector<int>(m, -1));
  const int* kept = ints.data();
  assign_resident(ints, m / 2, 7);  // within the capacity: the same storage, as assign
  CHECK(ints.data() == kept);
  CHECK(ints == std::vector<int>(m / 2, 7));
  std::vector<char> empty;
  assign_resident(empty, 0, char{1});
  CHECK(empty.empty());
}
