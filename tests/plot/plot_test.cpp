#include <gtest/gtest.h>
#include <png.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "progress.h"
#include "ruffini/plot/png.h"
#include "ruffini/plot/svg.h"

namespace ruffini::plot {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

bool ContainsNanOrInf(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s.find("nan") != std::string::npos || s.find("inf") != std::string::npos;
}

std::size_t Count(const std::string& hay, const std::string& needle) {
  std::size_t n = 0;
  for (auto p = hay.find(needle); p != std::string::npos; p = hay.find(needle, p + 1)) ++n;
  return n;
}

TEST(Png, EncodeRoundTrip) {
  Image img(5, 3, {10, 20, 30});
  img.at(0, 0) = {255, 0, 0};
  img.at(4, 2) = {0, 0, 255};
  img.FillRect(1, 1, 2, 1, {0, 255, 0});
  img.FillRect(-3, -3, 2, 2, {1, 1, 1});  // fully outside: no-op
  const std::string png = EncodePng(img);
  ASSERT_GE(png.size(), 8u);
  EXPECT_EQ(png.substr(0, 8), std::string("\x89PNG\r\n\x1a\n", 8));
  EXPECT_EQ(EncodePng(img), png);  // deterministic

  png_image dec{};
  dec.version = PNG_IMAGE_VERSION;
  ASSERT_NE(png_image_begin_read_from_memory(&dec, png.data(), png.size()), 0) << dec.message;
  EXPECT_EQ(dec.width, 5u);
  EXPECT_EQ(dec.height, 3u);
  dec.format = PNG_FORMAT_RGB;
  std::vector<std::uint8_t> buf(PNG_IMAGE_SIZE(dec));
  ASSERT_NE(png_image_finish_read(&dec, nullptr, buf.data(), 0, nullptr), 0) << dec.message;
  ASSERT_EQ(buf.size(), img.pixels.size() * 3);
  for (std::size_t i = 0; i < img.pixels.size(); ++i) {
    EXPECT_EQ(buf[3 * i], img.pixels[i].r) << i;
    EXPECT_EQ(buf[3 * i + 1], img.pixels[i].g) << i;
    EXPECT_EQ(buf[3 * i + 2], img.pixels[i].b) << i;
  }
}

TEST(Png, EmptyImageAndBadPathThrow) {
  EXPECT_THROW((void)EncodePng(Image(0, 0)), std::runtime_error);
  try {
    WritePng("/nonexistent-dir/x.png", Image(2, 2));
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent-dir/x.png"), std::string::npos);
  }
}

TEST(Png, Viridis) {
  EXPECT_EQ(Viridis(0.0), (Rgb{68, 1, 84}));
  EXPECT_EQ(Viridis(1.0), (Rgb{253, 231, 37}));
  EXPECT_EQ(Viridis(-5.0), Viridis(0.0));
  EXPECT_EQ(Viridis(7.0), Viridis(1.0));
  EXPECT_EQ(Viridis(kNaN), (Rgb{211, 211, 211}));
  auto lum = [](Rgb c) { return 0.2126 * c.r + 0.7152 * c.g + 0.0722 * c.b; };
  double prev = -1.0;
  for (int i = 0; i <= 100; ++i) {
    const double l = lum(Viridis(i / 100.0));
    EXPECT_GT(l, prev - 0.5) << i;  // monotonic up to rounding
    prev = l;
  }
  EXPECT_GT(lum(Viridis(1.0)) - lum(Viridis(0.0)), 150.0);
}

TEST(Svg, TitleLabelsEscapingAndTicks) {
  Figure fig("Force <N> & more", "x \"in\"", "y");
  fig.Add({"a<b&c", {0, 1, 2, 3, 4, 5}, {0, 1, 4, 9, 16, 25}});
  fig.Add({"second", {0, 5}, {25, 0}, "", Series::Style::kLinePoints});
  fig.SetXRange(0, 5).SetYRange(0, 25);
  const std::string svg = fig.Render();
  EXPECT_EQ(svg.rfind("<?xml", 0), 0u);
  EXPECT_NE(svg.find("</svg>"), std::string::npos);
  EXPECT_NE(svg.find("Force &lt;N&gt; &amp; more"), std::string::npos);
  EXPECT_NE(svg.find("a&lt;b&amp;c"), std::string::npos);  // in the legend
  EXPECT_NE(svg.find("#999999"), std::string::npos);      // legend box
  EXPECT_EQ(svg.find("a<b"), std::string::npos);
  EXPECT_NE(svg.find("x &quot;in&quot;"), std::string::npos);
  for (const char* t : {">0</text>", ">1</text>", ">2</text>", ">3</text>", ">4</text>", ">5</text>", ">10</text>",
                        ">20</text>"})
    EXPECT_NE(svg.find(t), std::string::npos) << t;
  EXPECT_NE(svg.find("<circle"), std::string::npos);
  EXPECT_FALSE(ContainsNanOrInf(svg));
  EXPECT_EQ(fig.Render(), svg);  // deterministic
}

TEST(Svg, SkipsNonFinitePointsAndBreaksLines) {
  Figure fig("t", "x", "y");
  fig.Add({"s", {0, 1, 2, 3, 4, kNaN, 6}, {1, 2, kNaN, 4, kInf, 6, 7}, "", Series::Style::kLinePoints});
  fig.AddMarker({kNaN, 1.0, "hidden"}).AddHLine(kInf, "hidden too");
  const std::string svg = fig.Render();
  EXPECT_FALSE(ContainsNanOrInf(svg));
  EXPECT_EQ(Count(svg, "<circle"), 4u);  // (0,1) (1,2) (3,4) (6,7)
  // Three runs: 0-1, 3, 6 -> three "M" moves in the series path.
  const auto p = svg.find("<path d=\"");
  ASSERT_NE(p, std::string::npos);
  const std::string d = svg.substr(p, svg.find('"', p + 9) - p);
  EXPECT_EQ(Count(d, "M"), 3u) << d;
  EXPECT_EQ(svg.find("hidden"), std::string::npos);
  EXPECT_EQ(svg.find("#999999"), std::string::npos);  // one labelled series: no legend box
}

TEST(Svg, LogXAcrossDecades) {
  Figure fig("log", "force [N]", "signal");
  fig.SetLogX().Add({"", {0.001, 0.01, 0.1, 1.0, 0.0, -1.0}, {1, 2, 3, 4, 5, 6}});
  fig.AddVLine(0.05, "limit");
  const std::string svg = fig.Render();
  EXPECT_FALSE(ContainsNanOrInf(svg));
  for (const char* t : {">0.001</text>", ">0.01</text>", ">0.1</text>", ">1</text>"})
    EXPECT_NE(svg.find(t), std::string::npos) << t;
  EXPECT_NE(svg.find(">limit</text>"), std::string::npos);
  EXPECT_NE(svg.find("stroke-dasharray"), std::string::npos);
  EXPECT_THROW((void)Figure("a", "b", "c").SetLogX().SetXRange(0.0, 1.0).Render(), std::invalid_argument);
}

// Drawn to scale: the path of a unit square's corners (0,0) (1,0) (1,1) spans as many pixels across as up,
// whatever the figure's shape; without it, a wide figure stretches x.
TEST(Svg, EqualAspectDrawsToScale) {
  auto spans = [](bool equal) {
    Figure fig("square", "x (m)", "z (m)", 900, 300);
    fig.Add({"", {0, 1, 1}, {0, 0, 1}, "", Series::Style::kLine});
    fig.SetEqualAspect(equal);
    const std::string svg = fig.Render();
    EXPECT_FALSE(ContainsNanOrInf(svg));
    const auto p = svg.find("<path d=\"M");
    EXPECT_NE(p, std::string::npos);
    double x0 = 0, y0 = 0, x1 = 0, y1 = 0, x2 = 0, y2 = 0;
    EXPECT_EQ(std::sscanf(svg.c_str() + p + 10, "%lf %lf L%lf %lf L%lf %lf", &x0, &y0, &x1, &y1, &x2, &y2), 6)
        << svg.substr(p, 80);
    return std::make_pair(std::abs(x1 - x0), std::abs(y2 - y1));
  };
  const auto [wide_x, wide_y] = spans(false);
  EXPECT_GT(wide_x, 2.0 * wide_y);  // the 900 x 300 figure stretches x
  const auto [x, y] = spans(true);
  EXPECT_NEAR(x, y, 0.01 * y);
  EXPECT_GT(y, 100.0);  // and still fills the plot's height
}

TEST(Svg, DegenerateRanges) {
  Figure fig("flat", "x", "y");
  fig.Add({"", {1, 2, 3}, {5, 5, 5}});
  std::string svg = fig.Render();
  EXPECT_FALSE(ContainsNanOrInf(svg));
  EXPECT_NE(svg.find(">5.0</text>"), std::string::npos);

  Figure single("one", "x", "y");
  single.Add({"", {2}, {0}}).SetLogX();
  EXPECT_FALSE(ContainsNanOrInf(single.Render()));
  Figure empty("", "", "");
  EXPECT_FALSE(ContainsNanOrInf(empty.Render()));
  Figure fixed("fixed", "x", "y");
  fixed.SetXRange(3, 3).SetYRange(-1, -1).Add({"", {3}, {-1}});
  EXPECT_FALSE(ContainsNanOrInf(fixed.Render()));
}

TEST(Svg, HeatMap) {
  HeatLayer h;
  h.cols = 4;
  h.rows = 3;
  h.values = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, kNaN};
  h.x_min = 0, h.x_max = 40, h.y_min = 0, h.y_max = 30;
  h.colourbar_label = "pressure <kPa>";
  h.black_at_or_below = 1.0;
  Figure fig("heat", "x [mm]", "y [mm]");
  fig.SetHeat(h).AddMarker({10, 10, "peak"});
  const std::string svg = fig.Render();
  EXPECT_NE(svg.find("data:image/png;base64,"), std::string::npos);
  EXPECT_NE(svg.find("pressure &lt;kPa&gt;"), std::string::npos);
  EXPECT_NE(svg.find("ruffini-viridis"), std::string::npos);
  EXPECT_NE(svg.find(">peak</text>"), std::string::npos);
  EXPECT_NE(svg.find("fill=\"#000000\"/>"), std::string::npos);  // black part of the colour bar
  h.values.pop_back();
  EXPECT_THROW(fig.SetHeat(h), std::invalid_argument);
}

std::string DecodeBase64(const std::string& in) {
  const std::string tab = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  std::uint32_t acc = 0;
  int bits = 0;
  for (char c : in) {
    const auto k = tab.find(c);
    if (k == std::string::npos) break;  // '=' padding or end
    acc = (acc << 6) | static_cast<std::uint32_t>(k);
    bits += 6;
    if (bits >= 8) bits -= 8, out += static_cast<char>((acc >> bits) & 0xFF);
  }
  return out;
}

TEST(Svg, HeatMapPixelsOrientedWithRowZeroAtBottom) {
  HeatLayer h;
  h.cols = 2;
  h.rows = 2;
  h.values = {-1.0, 0.0, 1.0, kNaN};  // row 0 (y_min): black, min; row 1 (y_max): max, NaN
  h.v_min = 0.0;
  h.v_max = 1.0;
  h.black_at_or_below = -0.5;
  Figure fig("heat", "x", "y");
  fig.SetHeat(h);
  const std::string svg = fig.Render();
  const std::string key = "data:image/png;base64,";
  const auto p = svg.find(key);
  ASSERT_NE(p, std::string::npos);
  const std::string png = DecodeBase64(svg.substr(p + key.size(), svg.find('"', p) - p - key.size()));
  png_image dec{};
  dec.version = PNG_IMAGE_VERSION;
  ASSERT_NE(png_image_begin_read_from_memory(&dec, png.data(), png.size()), 0) << dec.message;
  dec.format = PNG_FORMAT_RGB;
  std::vector<std::uint8_t> buf(PNG_IMAGE_SIZE(dec));
  ASSERT_NE(png_image_finish_read(&dec, nullptr, buf.data(), 0, nullptr), 0) << dec.message;
  const auto w = dec.width, hgt = dec.height;
  auto px = [&](std::uint32_t x, std::uint32_t y) {
    const std::size_t i = 3 * (static_cast<std::size_t>(y) * w + x);
    return Rgb{buf[i], buf[i + 1], buf[i + 2]};
  };
  EXPECT_EQ(px(0, hgt - 1), (Rgb{0, 0, 0}));        // bottom-left: black hot spot
  EXPECT_EQ(px(w - 1, hgt - 1), Viridis(0.0));      // bottom-right
  EXPECT_EQ(px(0, 0), Viridis(1.0));                // top-left
  EXPECT_EQ(px(w - 1, 0), Viridis(kNaN));           // top-right: NaN grey
}

TEST(Svg, SaveThrowsNamingPath) {
  try {
    Figure("a", "b", "c").Save("/nonexistent-dir/f.svg");
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent-dir/f.svg"), std::string::npos);
  }
}

std::string ReadAll(std::FILE* f) {
  std::rewind(f);
  std::string s;
  char buf[4096];
  for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, f)) > 0;) s.append(buf, n);
  return s;
}

TEST(ProgressBar, PlainLinesAtTenPercentSteps) {
  std::FILE* f = std::tmpfile();
  ASSERT_NE(f, nullptr);
  {
    ruffini::ProgressBar bar("frames", 1000, f);
    for (std::uint64_t i = 0; i <= 1000; ++i) bar.Update(i);
    bar.Update(1500);  // beyond total: no extra step line
    bar.Finish();
    bar.Finish();  // idempotent
  }  // destructor: no second finish line
  const std::string out = ReadAll(f);
  std::fclose(f);
  for (int p = 10; p <= 100; p += 10)
    EXPECT_EQ(Count(out, "frames  " + std::to_string(p) + "%"), 1u) << p << "\n" << out;
  EXPECT_EQ(Count(out, "%"), 10u) << out;
  EXPECT_EQ(Count(out, "\n"), 11u) << out;
  EXPECT_EQ(Count(out, "frames  done: 1.5k/1.0k in "), 1u) << out;
  EXPECT_EQ(out.find('\r'), std::string::npos);
}

TEST(ProgressBar, JumpsSmallAndUnknownTotals) {
  std::FILE* f = std::tmpfile();
  ASSERT_NE(f, nullptr);
  {
    ruffini::ProgressBar jump("jump", 3, f);
    jump.Update(2);  // 66 % -> one line for 60 %
    jump.Update(5);  // > total -> 100 % once
    jump.Update(std::numeric_limits<std::uint64_t>::max());
  }
  { ruffini::ProgressBar unknown("unknown", 0, f); unknown.Update(123); }
  const std::string out = ReadAll(f);
  std::fclose(f);
  EXPECT_EQ(Count(out, "jump  60%"), 1u) << out;
  EXPECT_EQ(Count(out, "jump  100%"), 1u) << out;
  EXPECT_EQ(Count(out, "jump  done:"), 1u) << out;
  EXPECT_EQ(Count(out, "unknown"), 1u) << out;
  EXPECT_NE(out.find("unknown  done: 123 in "), std::string::npos) << out;
}

}  // namespace
}  // namespace ruffini::plot
