#pragma once
// Raster images and PNG encoding (libpng simplified API). Output is deterministic: no tIME or text chunks.
#include <cstdint>
#include <string>
#include <vector>

namespace ruffini::plot {

struct Rgb {
  std::uint8_t r = 0, g = 0, b = 0;
  friend bool operator==(const Rgb&, const Rgb&) = default;
};

// 8-bit RGB image, row-major, top row first.
struct Image {
  int width = 0, height = 0;
  std::vector<Rgb> pixels;

  Image(int w, int h, Rgb fill = {});  // throws std::invalid_argument on negative size
  [[nodiscard]] Rgb& at(int x, int y) { return pixels[static_cast<std::size_t>(y) * width + x]; }
  [[nodiscard]] const Rgb& at(int x, int y) const { return pixels[static_cast<std::size_t>(y) * width + x]; }
  // Fills the rectangle clipped to the image; a rectangle outside it is a no-op.
  void FillRect(int x, int y, int w, int h, Rgb c);
};

// Encodes img as an 8-bit RGB PNG in memory. Throws std::runtime_error on failure (e.g. an empty image).
[[nodiscard]] std::string EncodePng(const Image& img);
// Writes img to path. Throws std::runtime_error naming the path on failure.
void WritePng(const std::string& path, const Image& img);

// Viridis colour map, piecewise linear through 9 matplotlib anchors (exact at t = k/8). t is clamped to
// [0, 1]; NaN gives light grey.
[[nodiscard]] Rgb Viridis(double t);
// The anchors, for building matching gradients (e.g. an SVG colour bar); anchor k sits at t = k / 8.
inline constexpr Rgb kViridisAnchors[9] = {{68, 1, 84},    {71, 45, 123},  {59, 82, 139},
                                           {44, 114, 142}, {33, 145, 140}, {40, 174, 128},
                                           {94, 201, 98},  {173, 220, 48}, {253, 231, 37}};

}  // namespace ruffini::plot
