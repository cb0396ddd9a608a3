// Image I/O: PPM round trip and the uncompressed PNG writer, decoded independently here.
#include <catch2/catch.hpp>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <vector>

#include "reference/viz/image.hpp"

using namespace monolith;

namespace {

Image test_pattern(int w, int h) {
  Image img(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      img.set(x, y, {static_cast<std::uint8_t>(x * 7 + y), static_cast<std::uint8_t>(y * 3),
                     static_cast<std::uint8_t>((x ^ y) & 0xff)});
  return img;
}

std::uint32_t be32(const std::vector<std::uint8_t>& d, size_t i) {
  return (std::uint32_t(d[i]) << 24) | (std::uint32_t(d[i + 1]) << 16) |
         (std::uint32_t(d[i + 2]) << 8) | std::uint32_t(d[i + 3]);
}

/// Table-driven CRC-32, written differently from the bitwise one in image.cpp.
std::uint32_t reference_crc(const std::uint8_t* p, size_t n) {
  static std::uint32_t table[256];
  static bool init = false;
  if (!init) {
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      table[i] = c;
    }
    init = true;
  }
  std::uint32_t c = 0xffffffffu;
  for (size_t i = 0; i < n; ++i) c = table[(c ^ p[i]) & 0xff] ^ (c >> 8);
  return c ^ 0xffffffffu;
}

}  // namespace

TEST_CASE("PPM round trip", "[unit][image]") {
  const auto path = std::filesystem::temp_directory_path() / "monolith_test_image.ppm";
  const Image img = test_pattern(37, 21);
  img.write_ppm(path.string());
  const Image back = Image::read_ppm(path.string());
  CHECK(back.width == 37);
  CHECK(back.height == 21);
  CHECK(back.rgb == img.rgb);
}

TEST_CASE("PNG writer produces a valid stored-deflate PNG with the same pixels", "[unit][image]") {
  // wide enough that the scanlines span several 65535-byte stored blocks
  const Image img = test_pattern(300, 250);
  const auto path = std::filesystem::temp_directory_path() / "monolith_test_image.png";
  img.write_png(path.string());
  std::ifstream in(path, std::ios::binary);
  const std::vector<std::uint8_t> d((std::istreambuf_iterator<char>(in)), {});
  REQUIRE(d.size() > 8);
  const std::uint8_t sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  CHECK(std::equal(sig, sig + 8, d.begin()));
  // walk the chunks, checking every CRC and collecting IDAT
  size_t i = 8;
  std::vector<std::uint8_t> idat;
  int width = 0, height = 0;
  bool saw_end = false;
  while (i + 12 <= d.size()) {
    const std::uint32_t n = be32(d, i);
    const std::string type(d.begin() + i + 4, d.begin() + i + 8);
    REQUIRE(i + 12 + n <= d.size());
    CHECK(reference_crc(&d[i + 4], n + 4) == be32(d, i + 8 + n));
    if (type == "IHDR") {
      width = static_cast<int>(be32(d, i + 8));
      height = static_cast<int>(be32(d, i + 12));
      CHECK(d[i + 16] == 8);
      CHECK(d[i + 17] == 2);
    } else if (type == "IDAT") {
      idat.insert(idat.end(), d.begin() + i + 8, d.begin() + i + 8 + n);
    } else if (type == "IEND") {
      saw_end = true;
    }
    i += 12 + n;
  }
  CHECK(saw_end);
  CHECK(width == 300);
  CHECK(height == 250);
  // inflate the stored blocks
  REQUIRE(idat.size() > 6);
  CHECK((idat[0] * 256 + idat[1]) % 31 == 0);
  std::vector<std::uint8_t> raw;
  size_t p = 2;
  bool last = false;
  while (!last) {
    REQUIRE(p + 5 <= idat.size());
    last = idat[p] & 1;
    CHECK(((idat[p] >> 1) & 3) == 0);
    const unsigned len = idat[p + 1] | (idat[p + 2] << 8);
    const unsigned nlen = idat[p + 3] | (idat[p + 4] << 8);
    CHECK((len ^ 0xffffu) == nlen);
    REQUIRE(p + 5 + len <= idat.size());
    raw.insert(raw.end(), idat.begin() + p + 5, idat.begin() + p + 5 + len);
    p += 5 + len;
  }
  REQUIRE(raw.size() == static_cast<size_t>(height) * (3 * width + 1));
  std::uint32_t a = 1, b = 0;
  for (auto byte : raw) a = (a + byte) % 65521, b = (b + a) % 65521;
  CHECK(be32(idat, p) == ((b << 16) | a));
  for (int y = 0; y < height; ++y) {
    CHECK(raw[y * (3 * width + 1)] == 0);
    CHECK(std::equal(raw.begin() + y * (3 * width + 1) + 1, raw.begin() + (y + 1) * (3 * width + 1),
                     img.rgb.begin() + y * 3 * width));
  }
}
