#include "ruffini/plot/png.h"

#include <png.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <stdexcept>

namespace ruffini::plot {

Image::Image(int w, int h, Rgb fill) : width(w), height(h) {
  if (w < 0 || h < 0) throw std::invalid_argument("ruffini::plot::Image: negative size");
  pixels.assign(static_cast<std::size_t>(w) * static_cast<std::size_t>(h), fill);
}

void Image::FillRect(int x, int y, int w, int h, Rgb c) {
  const int x0 = std::max(x, 0), y0 = std::max(y, 0);
  const int x1 = std::min(x + w, width), y1 = std::min(y + h, height);
  for (int yy = y0; yy < y1; ++yy)
    for (int xx = x0; xx < x1; ++xx) at(xx, yy) = c;
}

std::string EncodePng(const Image& img) {
  if (img.width <= 0 || img.height <= 0 ||
      img.pixels.size() != static_cast<std::size_t>(img.width) * static_cast<std::size_t>(img.height))
    throw std::runtime_error("ruffini::plot::EncodePng: empty or inconsistent image");
  std::vector<std::uint8_t> rgb;
  rgb.reserve(img.pixels.size() * 3);
  for (const Rgb& p : img.pixels) rgb.insert(rgb.end(), {p.r, p.g, p.b});

  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  image.width = static_cast<png_uint_32>(img.width);
  image.height = static_cast<png_uint_32>(img.height);
  image.format = PNG_FORMAT_RGB;
  // First call sizes the buffer, second call writes it.
  png_alloc_size_t size = 0;
  if (png_image_write_to_memory(&image, nullptr, &size, 0, rgb.data(), 0, nullptr) == 0)
    throw std::runtime_error(std::string("ruffini::plot::EncodePng: ") + image.message);
  std::string out(size, '\0');
  if (png_image_write_to_memory(&image, out.data(), &size, 0, rgb.data(), 0, nullptr) == 0)
    throw std::runtime_error(std::string("ruffini::plot::EncodePng: ") + image.message);
  out.resize(size);
  png_image_free(&image);
  return out;
}

void WritePng(const std::string& path, const Image& img) {
  const std::string data = EncodePng(img);
  std::ofstream f(path, std::ios::binary);
  f.write(data.data(), static_cast<std::streamsize>(data.size()));
  f.close();
  if (!f) throw std::runtime_error("ruffini::plot::WritePng: cannot write " + path);
}

Rgb Viridis(double t) {
  if (std::isnan(t)) return {211, 211, 211};
  const double s = std::clamp(t, 0.0, 1.0) * 8.0;
  const int k = std::min(static_cast<int>(s), 7);
  const double f = s - k;
  const Rgb& a = kViridisAnchors[k];
  const Rgb& b = kViridisAnchors[k + 1];
  auto mix = [f](std::uint8_t u, std::uint8_t v) {
    return static_cast<std::uint8_t>(std::lround(u + (static_cast<double>(v) - u) * f));
  };
  return {mix(a.r, b.r), mix(a.g, b.g), mix(a.b, b.b)};
}

}  // namespace ruffini::plot
