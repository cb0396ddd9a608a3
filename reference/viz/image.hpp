#pragma once
/// \file image.hpp
/// An 8-bit RGB image and its binary PPM (P6) writer: the project's only picture format.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace monolith {

using Rgb = std::array<std::uint8_t, 3>;

struct Image {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> rgb;  ///< row-major, top row first, 3 bytes per pixel

  Image() = default;
  Image(int w, int h, Rgb fill = {0, 0, 0});
  Rgb get(int x, int y) const;
  void set(int x, int y, Rgb c);
  /// Alpha-blends c over pixel (x, y) with opacity a in [0, 1]; ignores pixels outside.
  void blend(int x, int y, Rgb c, double a);
  /// Writes binary PPM (P6); throws std::runtime_error if the file cannot be written.
  void write_ppm(const std::string& path) const;
  /// The bytes of the binary PPM (P6) that write_ppm writes.
  std::string ppm_bytes() const;
  /// Writes an uncompressed PNG (deflate "stored" blocks, no compression library), for pictures
  /// that must display in a web page such as the README. Throws std::runtime_error on failure.
  void write_png(const std::string& path) const;
  /// Reads a binary PPM (P6) as written by write_ppm; throws std::runtime_error on bad input.
  static Image read_ppm(const std::string& path);
};

/// Colour maps used by the renderers and plots: t in [0, 1] (clamped).
Rgb colormap_viridis(double t);
Rgb colormap_coolwarm(double t);

}  // namespace monolith
