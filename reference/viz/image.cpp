#include "reference/viz/image.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <stdexcept>

namespace monolith {

Image::Image(int w, int h, Rgb fill) : width(w), height(h), rgb(static_cast<size_t>(w) * h * 3) {
  for (size_t i = 0; i < rgb.size(); i += 3) {
    rgb[i] = fill[0];
    rgb[i + 1] = fill[1];
    rgb[i + 2] = fill[2];
  }
}

Rgb Image::get(int x, int y) const {
  const size_t i = (static_cast<size_t>(y) * width + x) * 3;
  return {rgb[i], rgb[i + 1], rgb[i + 2]};
}

void Image::set(int x, int y, Rgb c) {
  if (x < 0 || y < 0 || x >= width || y >= height) return;
  const size_t i = (static_cast<size_t>(y) * width + x) * 3;
  rgb[i] = c[0];
  rgb[i + 1] = c[1];
  rgb[i + 2] = c[2];
}

void Image::blend(int x, int y, Rgb c, double a) {
  if (x < 0 || y < 0 || x >= width || y >= height) return;
  a = std::clamp(a, 0.0, 1.0);
  const size_t i = (static_cast<size_t>(y) * width + x) * 3;
  for (int k = 0; k < 3; ++k)
    rgb[i + k] = static_cast<std::uint8_t>(std::lround((1.0 - a) * rgb[i + k] + a * c[k]));
}

std::string Image::ppm_bytes() const {
  std::string bytes = "P6\n" + std::to_string(width) + " " + std::to_string(height) + "\n255\n";
  bytes.append(reinterpret_cast<const char*>(rgb.data()), rgb.size());
  return bytes;
}

void Image::write_ppm(const std::string& path) const {
  std::ofstream out(path, std::ios::binary);
  if (!out) throw std::runtime_error("cannot write " + path);
  const std::string bytes = ppm_bytes();
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  out.close();
  if (!out) throw std::runtime_error("cannot write " + path);
}

namespace {
std::uint32_t crc32(const std::uint8_t* data, size_t n, std::uint32_t crc = 0) {
  // the CRC-32 of the PNG specification (polynomial 0xEDB88320), bitwise
  crc = ~crc;
  for (size_t i = 0; i < n; ++i) {
    crc ^= data[i];
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}
void put_u32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int s = 24; s >= 0; s -= 8) out.push_back(static_cast<std::uint8_t>(v >> s));
}
void put_chunk(std::ofstream& out, const char* type, const std::vector<std::uint8_t>& data) {
  std::vector<std::uint8_t> body(type, type + 4);
  body.insert(body.end(), data.begin(), data.end());
  std::vector<std::uint8_t> head;
  put_u32(head, static_cast<std::uint32_t>(data.size()));
  std::vector<std::uint8_t> tail;
  put_u32(tail, crc32(body.data(), body.size()));
  out.write(reinterpret_cast<const char*>(head.data()), 4);
  out.write(reinterpret_cast<const char*>(body.data()), static_cast<std::streamsize>(body.size()));
  out.write(reinterpret_cast<const char*>(tail.data()), 4);
}
}  // namespace

void Image::write_png(const std::string& path) const {
  // raw scanlines, each prefixed by filter type 0
  std::vector<std::uint8_t> raw;
  raw.reserve(static_cast<size_t>(height) * (3 * width + 1));
  for (int y = 0; y < height; ++y) {
    raw.push_back(0);
    raw.insert(raw.end(), rgb.begin() + static_cast<long>(y) * width * 3,
               rgb.begin() + static_cast<long>(y + 1) * width * 3);
  }
  // zlib stream of stored deflate blocks (at most 65535 bytes each) and the Adler-32 checksum
  std::vector<std::uint8_t> z = {0x78, 0x01};
  for (size_t pos = 0; pos < raw.size() || pos == 0; pos += 65535) {
    const size_t n = std::min<size_t>(65535, raw.size() - pos);
    z.push_back(pos + n >= raw.size() ? 1 : 0);
    z.push_back(static_cast<std::uint8_t>(n & 0xff));
    z.push_back(static_cast<std::uint8_t>(n >> 8));
    z.push_back(static_cast<std::uint8_t>(~n & 0xff));
    z.push_back(static_cast<std::uint8_t>((~n >> 8) & 0xff));
    z.insert(z.end(), raw.begin() + static_cast<long>(pos), raw.begin() + static_cast<long>(pos + n));
    if (raw.empty()) break;
  }
  std::uint32_t a = 1, b = 0;
  for (std::uint8_t byte : raw) {
    a = (a + byte) % 65521u;
    b = (b + a) % 65521u;
  }
  put_u32(z, (b << 16) | a);
  std::vector<std::uint8_t> header;
  put_u32(header, static_cast<std::uint32_t>(width));
  put_u32(header, static_cast<std::uint32_t>(height));
  header.insert(header.end(), {8, 2, 0, 0, 0});  // 8-bit RGB, no interlace
  std::ofstream out(path, std::ios::binary);
  if (!out) throw std::runtime_error("cannot write " + path);
  const std::uint8_t signature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  out.write(reinterpret_cast<const char*>(signature), 8);
  put_chunk(out, "IHDR", header);
  put_chunk(out, "IDAT", z);
  put_chunk(out, "IEND", {});
  if (!out) throw std::runtime_error("cannot write " + path);
}

Image Image::read_ppm(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read " + path);
  std::string magic;
  int w = 0, h = 0, maxval = 0;
  in >> magic >> w >> h >> maxval;
  if (magic != "P6" || w <= 0 || h <= 0 || maxval != 255 || w > 1 << 15 || h > 1 << 15)
    throw std::runtime_error(path + ": not a binary 8-bit PPM");
  in.get();
  Image img(w, h);
  in.read(reinterpret_cast<char*>(img.rgb.data()), static_cast<std::streamsize>(img.rgb.size()));
  if (!in) throw std::runtime_error(path + ": truncated PPM");
  return img;
}

namespace {
Rgb lerp_table(const double (*table)[3], int n, double t) {
  t = std::clamp(std::isfinite(t) ? t : 0.0, 0.0, 1.0) * (n - 1);
  const int i = std::min(static_cast<int>(t), n - 2);
  const double f = t - i;
  Rgb c;
  for (int k = 0; k < 3; ++k)
    c[k] = static_cast<std::uint8_t>(std::lround(255.0 * ((1 - f) * table[i][k] + f * table[i + 1][k])));
  return c;
}
}  // namespace

Rgb colormap_viridis(double t) {
  // viridis sampled at 9 points (the published colour map's values)
  static const double table[9][3] = {{0.267, 0.005, 0.329}, {0.283, 0.141, 0.458},
                                     {0.254, 0.265, 0.530}, {0.207, 0.372, 0.553},
                                     {0.164, 0.471, 0.558}, {0.128, 0.567, 0.551},
                                     {0.135, 0.659, 0.518}, {0.478, 0.821, 0.318},
                                     {0.993, 0.906, 0.144}};
  return lerp_table(table, 9, t);
}

Rgb colormap_coolwarm(double t) {
  static const double table[5][3] = {{0.230, 0.299, 0.754}, {0.552, 0.690, 0.996},
                                     {0.865, 0.865, 0.865}, {0.958, 0.603, 0.482},
                                     {0.706, 0.016, 0.150}};
  return lerp_table(table, 5, t);
}

}  // namespace monolith
