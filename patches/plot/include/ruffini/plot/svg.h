#pragma once
// Small self-contained figure builder producing standalone SVG 1.1 text: line/point series, an optional
// heat map (embedded PNG) with a colour bar, markers, dashed reference lines, linear or log10 x axis.
// Output is deterministic (fixed number formatting via std::to_chars, no locale, no timestamps).
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace ruffini::plot {

struct Series {
  enum class Style { kLine, kPoints, kLinePoints };
  std::string label;
  std::vector<double> x, y;  // non-finite points (and x <= 0 on a log axis) are skipped and break lines
  std::string colour = "";   // any SVG colour; empty = next palette colour
  Style style = Style::kLine;
};

// Uniform grid in axis coordinates (with a log x axis the cells are uniform in log10 x).
struct HeatLayer {
  int cols = 0, rows = 0;
  std::vector<double> values;  // row-major, cols * rows, row 0 = y_min; NaN cells are drawn light grey
  double x_min = 0.0, x_max = 1.0, y_min = 0.0, y_max = 1.0;
  double v_min = std::numeric_limits<double>::quiet_NaN();  // colour scale; NaN = from the finite values
  double v_max = std::numeric_limits<double>::quiet_NaN();
  std::string colourbar_label;
  double black_at_or_below = std::numeric_limits<double>::quiet_NaN();  // cells <= this drawn black
};

struct Marker {
  double x = 0.0, y = 0.0;
  std::string text;
};

class Figure {
 public:
  Figure(std::string title, std::string x_label, std::string y_label, int width_px = 640, int height_px = 420);

  Figure& Add(Series s);
  // Heat map drawn as an embedded PNG filling its extent, plus a colour bar at the right.
  // Throws std::invalid_argument if values.size() != cols * rows or the grid is empty.
  Figure& SetHeat(HeatLayer h);
  Figure& AddMarker(Marker m);  // small cross + text
  // Explicit ranges; otherwise from data, markers, reference lines and heat extent (padded 5 %, except
  // that a heat map containing all data fills the plot area exactly). Degenerate ranges are widened.
  Figure& SetXRange(double lo, double hi);
  Figure& SetYRange(double lo, double hi);
  Figure& SetLogX(bool on = true);  // log10 x axis
  // Drawn to scale: a unit of x as long as a unit of y (the ranges widen about their centres to fit the plot
  // area; ignored on a log x axis). For positions in space.
  Figure& SetEqualAspect(bool on = true);
  Figure& AddHLine(double y, std::string label);  // dashed reference lines
  Figure& AddVLine(double x, std::string label);

  // Throws std::invalid_argument if an explicit x range is not positive on a log axis.
  [[nodiscard]] std::string Render() const;
  void Save(const std::string& path) const;  // throws std::runtime_error naming the path

 private:
  struct RefLine {
    double v;
    std::string label;
  };
  std::string title_, x_label_, y_label_;
  int width_, height_;
  std::vector<Series> series_;
  std::optional<HeatLayer> heat_;
  std::vector<Marker> markers_;
  std::optional<std::pair<double, double>> x_range_, y_range_;
  bool log_x_ = false;
  bool equal_aspect_ = false;
  std::vector<RefLine> hlines_, vlines_;
};

}  // namespace ruffini::plot
