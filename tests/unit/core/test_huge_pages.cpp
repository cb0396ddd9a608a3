// The first-touch facility (reference/core/huge_pages.hpp, issue 20, branch huge21): the aligned
// interior that advise_huge_pages advises for ranges below, at and above 2 MiB and from
// unaligned starts; advice that leaves a buffer's values as they were; zero_by_release zeroing
// exactly its range (whole pages given back, the ends written) and nothing beside it; and the
// kept zero vector of the solve's workspace (KeptZeros), lent fresh (zeros from the kernel) and
// then reused across steps with moving and shrinking written spans, equal to a fresh zero vector
// at every lend.
#include <catch2/catch.hpp>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "reference/core/huge_pages.hpp"
#include "reference/fluid/stokes_workspace.hpp"

using namespace monolith;

namespace {
constexpr std::uintptr_t H = kHugePageBytes;  // 2 MiB
}  // namespace

TEST_CASE("aligned_interior: the whole 2 MiB blocks inside a range (huge21)", "[unit]") {
  // below 2 MiB: no whole block, aligned start or not
  CHECK(aligned_interior(10 * H, H - 1, H).empty());
  CHECK(aligned_interior(10 * H + 4096, H / 2, H).empty());
  CHECK(aligned_interior(10 * H, 0, H).bytes() == 0);
  // exactly 2 MiB: one block from an aligned start, none from an unaligned one
  {
    const AddressSpan s = aligned_interior(10 * H, H, H);
    CHECK(s.begin == 10 * H);
    CHECK(s.end == 11 * H);
    CHECK(s.bytes() == H);
  }
  CHECK(aligned_interior(10 * H + 16, H, H).empty());
  // just below two blocks from an unaligned start: one block
  {
    const AddressSpan s = aligned_interior(10 * H + 16, 2 * H - 32, H);
    CHECK(s.begin == 11 * H);
    CHECK(s.end == 11 * H);  // 10H + 16 + 2H - 32 < 12H: the block [11H, 12H) is not whole
    CHECK(s.empty());
  }
  // above: from 5H + 100 over 3H bytes (to 8H + 100): the blocks [6H, 8H)
  {
    const AddressSpan s = aligned_interior(5 * H + 100, 3 * H, H);
    CHECK(s.begin == 6 * H);
    CHECK(s.end == 8 * H);
    CHECK(s.bytes() == 2 * H);
  }
  // a range ending exactly on a boundary keeps its last block
  {
    const AddressSpan s = aligned_interior(5 * H + 100, 3 * H - 100, H);
    CHECK(s.begin == 6 * H);
    CHECK(s.end == 8 * H);
  }
  // the same arithmetic with small pages (zero_by_release's interior)
  {
    const AddressSpan s = aligned_interior(4096 * 3 + 8, 4096 * 4, 4096);
    CHECK(s.begin == 4096 * 4);
    CHECK(s.end == 4096 * 7);
  }
}

TEST_CASE("advise_huge_pages advises the aligned interior and leaves the values (huge21)",
          "[unit]") {
  // 9 MiB + 24 bytes of doubles from wherever the heap puts them: the interior is 3 or 4 blocks
  const long n = static_cast<long>((9 * H + 24) / sizeof(double));
  VectorX v(n);
  for (long i = 0; i < n; ++i) v[i] = 0.5 * static_cast<double>(i) - 7.0;
  const VectorX copy = v;
  const std::size_t bytes = sizeof(double) * static_cast<std::size_t>(n);
  const AddressSpan interior = aligned_interior(reinterpret_cast<std::uintptr_t>(v.data()), bytes, H);
  CHECK(interior.bytes() >= 3 * H);
  CHECK(interior.bytes() % H == 0);
  // off unless asked for (MONOLITH_HUGE_PAGES=1 or set_huge_pages): switched off, nothing is
  // advised; then switched on for the checks below, and back to what it was
  const bool was = huge_pages_enabled();
  set_huge_pages(false);
  CHECK(advise_huge_pages(v.data(), bytes) == 0);
  set_huge_pages(true);
  const std::size_t advised = advise_huge_pages(v.data(), bytes);
  // the interior or nothing (switched off, or a kernel without transparent huge pages)
  CHECK((advised == interior.bytes() || advised == 0));
#if defined(__linux__)
  if (huge_pages_enabled() && std::ifstream("/sys/kernel/mm/transparent_hugepage/enabled").good())
    CHECK(advised == interior.bytes());
#endif
  CHECK(std::memcmp(v.data(), copy.data(), bytes) == 0);
  // a range without a whole block is not advised
  CHECK(advise_huge_pages(v.data() + 1, H / 2) == 0);
  CHECK(advise_huge_pages(nullptr, 4 * H) == 0);
  set_huge_pages(was);
  // resize_on_huge_pages: the same size keeps storage and values; another size makes n entries
  const double* before = v.data();
  resize_on_huge_pages(v, n);
  CHECK(v.data() == before);
  CHECK(std::memcmp(v.data(), copy.data(), bytes) == 0);
  std::vector<int> ints;
  resize_on_huge_pages(ints, 3 * static_cast<long>(H / sizeof(int)));
  CHECK(ints.size() == 3 * H / sizeof(int));
  CHECK(ints.front() == 0);
  CHECK(ints.back() == 0);
}

TEST_CASE("zero_by_release zeroes exactly its range, small and large, aligned or not (huge21)",
          "[unit]") {
  const std::size_t total = 3 * H + 5000;
  std::vector<unsigned char> buffer(total);
  const auto fill = [&] {
    for (std::size_t i = 0; i < total; ++i) buffer[i] = static_cast<unsigned char>(1 + i % 251);
  };
  // (begin, bytes): below the release threshold, large from an unaligned start, large up to
  // the buffer's end, the whole buffer
  const std::size_t cases[][2] = {{13, 1000}, {13, kReleaseMinBytes - 1}, {4097 + 3, 2 * H + 777},
                                  {100, total - 100}, {0, total}};
  for (const auto& c : cases) {
    INFO("begin " << c[0] << ", bytes " << c[1]);
    fill();
    const std::size_t released = zero_by_release(buffer.data() + c[0], c[1]);
    const AddressSpan pages =
        aligned_interior(reinterpret_cast<std::uintptr_t>(buffer.data() + c[0]), c[1], 4096);
    if (c[1] < kReleaseMinBytes) CHECK(released == 0);
#if defined(__linux__)
    if (c[1] >= kReleaseMinBytes) CHECK(released == pages.bytes());
#endif
    CHECK(released <= pages.bytes());
    long wrong = 0;
    for (std::size_t i = 0; i < total; ++i) {
      const bool inside = i >= c[0] && i < c[0] + c[1];
      const unsigned char expected = inside ? 0 : static_cast<unsigned char>(1 + i % 251);
      wrong += buffer[i] != expected;
    }
    CHECK(wrong == 0);
    // the released pages take writes again (provided anew by the kernel)
    buffer[c[0] + c[1] / 2] = 9;
    CHECK(buffer[c[0] + c[1] / 2] == 9);
  }
}

TEST_CASE("KeptZeros: a fresh lend and every reuse with moving, shrinking spans equal zeros "
          "(huge21)", "[unit]") {
  // 3 MiB of doubles: the fresh lend's zeros come from the kernel (zero_by_release)
  const long n = static_cast<long>(3 * H / sizeof(double)) + 11;
  KeptZeros kept;
  // the written spans of successive "steps": moving, shrinking, growing, empty, the whole
  const std::vector<std::vector<std::pair<long, long>>> steps = {
      {{1000, 200000}},
      {{150000, 160000}, {300000, 350000}},
      {{5, 6}},
      {},
      {{0, n}},
      {{n - 10, n}},
  };
  VectorX out = VectorX::Constant(7, 3.0);  // a borrower's vector of another size at first
  for (std::size_t s = 0; s <= steps.size(); ++s) {
    INFO("lend " << s);
    kept.lend(n, out);
    REQUIRE(out.size() == n);
    CHECK(out.isZero(0.0));
    long nonzero_bits = 0;
    for (long i = 0; i < n; ++i) {
      std::uint64_t bits;
      std::memcpy(&bits, &out[i], sizeof bits);
      nonzero_bits += bits != 0;  // +0.0 exactly (no -0.0)
    }
    CHECK(nonzero_bits == 0);
    if (s == steps.size()) break;
    // the borrower writes its spans and gives the storage back with them
    for (const auto& [b, e] : steps[s])
      for (long i = b; i < e; ++i) out[i] = 1.0 + static_cast<double>(i % 17);
    kept.values.swap(out);
    kept.dirty = steps[s];
    out = VectorX();
  }
  // a lend of another size drops the storage and gives fresh zeros of that size
  kept.values = VectorX::Constant(n, 1.0);
  kept.lend(n / 2, out);
  CHECK(out.size() == n / 2);
  CHECK(out.isZero(0.0));
  CHECK(kept.values.size() == 0);
}

TEST_CASE("KeptIndexPlusOne: a fresh lend and every reuse with moving, shrinking entries give "
          "0 (no index) everywhere; a forgotten entry stays (band23)",
          "[unit]") {
  // 3 MiB of ints: the fresh lend's zeros come from the kernel (zero_by_release)
  const long n = static_cast<long>(3 * H / sizeof(int)) + 5;
  KeptIndexPlusOne kept;
  // the entries the borrower writes in successive "steps" (index + 1 each): a block, a moved
  // and smaller one, a single entry, none, the last entries
  const std::vector<std::pair<long, long>> steps = {
      {1000, 90000}, {400000, 410000}, {7, 8}, {0, 0}, {n - 100, n}};
  Eigen::VectorXi out = Eigen::VectorXi::Constant(9, 4);  // another size at first
  for (std::size_t s = 0; s <= steps.size(); ++s) {
    INFO("lend " << s);
    kept.lend(n, out);
    REQUIRE(out.size() == n);
    CHECK((out.array() == 0).all());
    if (s == steps.size()) break;
    const auto [b, e] = steps[s];
    for (long i = b; i < e; ++i) out[i] = static_cast<int>(i - b) + 1;
    kept.values.swap(out);
    kept.dirty.clear();
    for (long i = b; i < e; ++i) kept.dirty.push_back(static_cast<int>(i));
    out = Eigen::VectorXi();
  }
  // negative control: an entry written but not listed keeps its index after the lend
  kept.values.swap(out);
  kept.values[12] = 3;
  kept.values[13] = 4;
  kept.dirty = {12};
  kept.lend(n, out);
  CHECK(out[12] == 0);
  CHECK(out[13] == 4);
  // a lend of another size drops the storage and gives fresh zeros of that size
  kept.values = Eigen::VectorXi::Constant(n, 2);
  kept.lend(n / 2, out);
  CHECK(out.size() == n / 2);
  CHECK((out.array() == 0).all());
  CHECK(kept.values.size() == 0);
}
