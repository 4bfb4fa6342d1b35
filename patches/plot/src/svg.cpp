#include "ruffini/plot/svg.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <stdexcept>

#include "ruffini/plot/png.h"

namespace ruffini::plot {
namespace {

constexpr const char* kPalette[] = {"#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd",
                                    "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf"};
constexpr double kCharW = 0.6;  // average glyph width / font size, for layout estimates

std::string Esc(const std::string& s) {
  std::string out;
  out.reserve(s.size());
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&apos;"; break;
      default: out += c;
    }
  }
  return out;
}

// Fixed-point, locale-independent; non-finite values never reach the output.
std::string Num(double v, int prec = 2) {
  if (!std::isfinite(v)) v = 0.0;
  v = std::clamp(v, -1e7, 1e7);
  if (std::fabs(v) < 0.5 * std::pow(10.0, -prec)) v = 0.0;  // no "-0.00"
  char buf[64];
  const auto res = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::fixed, prec);
  return std::string(buf, res.ptr);
}

// Tick label for v on a grid of spacing step: just enough decimals, scientific for extreme magnitudes.
std::string TickLabel(double v, double step) {
  if (std::fabs(v) < step * 1e-6) return "0";
  const int step_exp = static_cast<int>(std::floor(std::log10(step) + 1e-9));
  const double mag = std::max(std::fabs(v), step);
  char buf[64];
  if (mag >= 1e6 || mag < 1e-4) {
    const int v_exp = v == 0.0 ? step_exp : static_cast<int>(std::floor(std::log10(std::fabs(v)) + 1e-9));
    const auto res = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::scientific,
                                   std::max(0, v_exp - step_exp));
    std::string s(buf, res.ptr);  // "2.5e-05" -> "2.5e-5"
    const auto e = s.find('e');
    std::string exp = s.substr(e + 1);
    const bool neg = exp[0] == '-';
    exp.erase(0, exp.find_first_not_of("+-0"));
    return s.substr(0, e + 1) + (neg ? "-" : "") + (exp.empty() ? "0" : exp);
  }
  const auto res = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::fixed, std::max(0, -step_exp));
  return std::string(buf, res.ptr);
}

double NiceStep(double span, int target) {
  const double raw = span / std::max(target, 1);
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  const double f = raw / mag;
  return (f < 1.5 ? 1.0 : f < 3.5 ? 2.0 : f < 7.5 ? 5.0 : 10.0) * mag;
}

struct Tick {
  double pos;  // axis coordinate (log10 x on a log axis)
  std::string label;  // empty = minor tick
};

std::vector<Tick> LinearTicks(double lo, double hi, int target) {
  std::vector<Tick> ticks;
  const double step = NiceStep(hi - lo, target);
  if (!(hi > lo) || !std::isfinite(step) || step <= 0.0) return ticks;
  for (double k = std::ceil(lo / step - 1e-9); k * step <= hi + step * 1e-9 && ticks.size() < 50; k += 1.0)
    ticks.push_back({k * step, TickLabel(k * step, step)});
  return ticks;
}

// Decades labelled; 2 and 5 labelled too when fewer than 3 decades show; linear fallback below that.
std::vector<Tick> LogTicks(double lo, double hi, int target) {
  const auto d0 = static_cast<int>(std::floor(lo)), d1 = static_cast<int>(std::ceil(hi));
  const int every = std::max(1, (d1 - d0 + target - 1) / std::max(target, 1));
  const bool with_25 = d1 - d0 <= 3;
  std::vector<Tick> ticks;
  int labelled = 0;
  for (int d = d0; d <= d1; ++d) {
    for (int m = 1; m <= 9; ++m) {
      const double pos = d + std::log10(static_cast<double>(m));
      if (pos < lo - 1e-9 || pos > hi + 1e-9 || (every > 1 && (m != 1 || (d % every + every) % every != 0))) continue;
      const bool label = m == 1 || (with_25 && (m == 2 || m == 5));
      ticks.push_back({pos, label ? TickLabel(m * std::pow(10.0, d), std::pow(10.0, d)) : ""});
      labelled += label ? 1 : 0;
    }
  }
  if (labelled >= 2) return ticks;
  ticks.clear();
  const double vlo = std::pow(10.0, lo), vhi = std::pow(10.0, hi);
  for (Tick& t : LinearTicks(vlo, vhi, target))
    if (t.pos > 0.0) ticks.push_back({std::log10(t.pos), t.label});
  return ticks;
}

struct Extent {
  double lo = std::numeric_limits<double>::infinity(), hi = -std::numeric_limits<double>::infinity();
  void Add(double v) {
    if (std::isfinite(v)) lo = std::min(lo, v), hi = std::max(hi, v);
  }
  [[nodiscard]] bool empty() const { return lo > hi; }
};

// Widens degenerate ranges; optionally pads 5 % each side. Empty -> [0, 1].
std::pair<double, double> Finish(Extent e, bool pad, bool log_axis) {
  if (e.empty()) return {0.0, 1.0};
  const double span = e.hi - e.lo;
  if (span <= 1e-12 * std::max({1.0, std::fabs(e.lo), std::fabs(e.hi)})) {
    const double d = log_axis ? 0.5 : (e.lo == 0.0 ? 1.0 : 0.1 * std::fabs(e.lo));
    return {e.lo - d, e.hi + d};
  }
  const double d = pad ? 0.05 * span : 0.0;
  return {e.lo - d, e.hi + d};
}

std::string Colour(Rgb c) {
  char buf[8];
  std::snprintf(buf, sizeof buf, "#%02x%02x%02x", c.r, c.g, c.b);
  return buf;
}

std::string Base64(const std::string& in) {
  static constexpr char kTab[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((in.size() + 2) / 3 * 4);
  for (std::size_t i = 0; i < in.size(); i += 3) {
    std::uint32_t n = static_cast<std::uint32_t>(static_cast<unsigned char>(in[i])) << 16;
    if (i + 1 < in.size()) n |= static_cast<std::uint32_t>(static_cast<unsigned char>(in[i + 1])) << 8;
    if (i + 2 < in.size()) n |= static_cast<unsigned char>(in[i + 2]);
    out += kTab[(n >> 18) & 63];
    out += kTab[(n >> 12) & 63];
    out += i + 1 < in.size() ? kTab[(n >> 6) & 63] : '=';
    out += i + 2 < in.size() ? kTab[n & 63] : '=';
  }
  return out;
}

// Text with a white halo so it stays legible over heat maps and lines.
std::string HaloText(double x, double y, const std::string& text, const char* extra = "") {
  const std::string attrs = " x=\"" + Num(x) + "\" y=\"" + Num(y) + "\" font-size=\"11\"" + extra + ">" +
                            Esc(text) + "</text>\n";
  return "<text stroke=\"#ffffff\" stroke-width=\"3\" stroke-linejoin=\"round\" fill=\"#ffffff\"" + attrs +
         "<text fill=\"#000000\"" + attrs;
}

}  // namespace

Figure::Figure(std::string title, std::string x_label, std::string y_label, int width_px, int height_px)
    : title_(std::move(title)),
      x_label_(std::move(x_label)),
      y_label_(std::move(y_label)),
      width_(std::max(width_px, 200)),
      height_(std::max(height_px, 150)) {}

Figure& Figure::Add(Series s) { return series_.push_back(std::move(s)), *this; }
Figure& Figure::AddMarker(Marker m) { return markers_.push_back(std::move(m)), *this; }
Figure& Figure::SetXRange(double lo, double hi) { return x_range_ = std::minmax(lo, hi), *this; }
Figure& Figure::SetYRange(double lo, double hi) { return y_range_ = std::minmax(lo, hi), *this; }
Figure& Figure::SetEqualAspect(bool on) { return equal_aspect_ = on, *this; }
Figure& Figure::SetLogX(bool on) { return log_x_ = on, *this; }
Figure& Figure::AddHLine(double y, std::string label) { return hlines_.push_back({y, std::move(label)}), *this; }
Figure& Figure::AddVLine(double x, std::string label) { return vlines_.push_back({x, std::move(label)}), *this; }

Figure& Figure::SetHeat(HeatLayer h) {
  if (h.cols <= 0 || h.rows <= 0 || h.values.size() != static_cast<std::size_t>(h.cols) * h.rows)
    throw std::invalid_argument("ruffini::plot::Figure::SetHeat: values.size() != cols * rows");
  heat_ = std::move(h);
  return *this;
}

std::string Figure::Render() const {
  // x values in axis coordinates: log10 on a log axis, NaN when not representable there.
  auto tx = [this](double x) {
    return !log_x_ ? x : x > 0.0 ? std::log10(x) : std::numeric_limits<double>::quiet_NaN();
  };

  // ---- ranges
  Extent ex, ey, hx, hy;
  for (const Series& s : series_)
    for (std::size_t i = 0; i < std::min(s.x.size(), s.y.size()); ++i)
      if (std::isfinite(tx(s.x[i])) && std::isfinite(s.y[i])) ex.Add(tx(s.x[i])), ey.Add(s.y[i]);
  for (const Marker& m : markers_) ex.Add(tx(m.x)), ey.Add(m.y);
  for (const RefLine& l : vlines_) ex.Add(tx(l.v));
  for (const RefLine& l : hlines_) ey.Add(l.v);
  if (heat_) hx.Add(tx(heat_->x_min)), hx.Add(tx(heat_->x_max)), hy.Add(heat_->y_min), hy.Add(heat_->y_max);
  auto auto_range = [](Extent data, Extent heat, bool log_axis) {
    const bool inside = !heat.empty() && (data.empty() || (data.lo >= heat.lo && data.hi <= heat.hi));
    data.Add(heat.lo), data.Add(heat.hi);
    return Finish(data, !inside, log_axis);
  };
  std::pair<double, double> xr = auto_range(ex, hx, log_x_), yr = auto_range(ey, hy, false);
  if (x_range_) {
    if (log_x_ && !(x_range_->first > 0.0))
      throw std::invalid_argument("ruffini::plot::Figure: log x range must be positive");
    Extent e;
    e.Add(tx(x_range_->first)), e.Add(tx(x_range_->second));
    if (!e.empty()) xr = Finish(e, false, log_x_);
  }
  if (y_range_) {
    Extent e;
    e.Add(y_range_->first), e.Add(y_range_->second);
    if (!e.empty()) yr = Finish(e, false, false);
  }

  // ---- colour scale
  double v_lo = 0.0, v_hi = 1.0;
  if (heat_) {
    Extent ev;
    for (double v : heat_->values) ev.Add(v);
    v_lo = std::isfinite(heat_->v_min) ? heat_->v_min : ev.empty() ? 0.0 : ev.lo;
    v_hi = std::isfinite(heat_->v_max) ? heat_->v_max : ev.empty() ? 1.0 : ev.hi;
    if (v_lo > v_hi) std::swap(v_lo, v_hi);
  }

  // ---- layout
  const double top = title_.empty() ? 16.0 : 38.0, bottom = x_label_.empty() ? 34.0 : 52.0;
  std::vector<Tick> yticks = LinearTicks(yr.first, yr.second, std::max(2, (height_ - 90) / 50));
  std::size_t ylab = 1;
  for (const Tick& t : yticks) ylab = std::max(ylab, t.label.size());
  const double left = (y_label_.empty() ? 12.0 : 30.0) + 12.0 + kCharW * 12.0 * static_cast<double>(ylab);
  std::vector<Tick> cticks;
  double right = 20.0;
  if (heat_) {
    const std::pair<double, double> cr = Finish(Extent{v_lo, v_hi}, false, false);
    v_lo = cr.first, v_hi = cr.second;
    cticks = LinearTicks(v_lo, v_hi, std::max(2, (height_ - 90) / 50));
    std::size_t clab = 1;
    for (const Tick& t : cticks) clab = std::max(clab, t.label.size());
    right = 14.0 + 14.0 + 10.0 + kCharW * 12.0 * static_cast<double>(clab) +
            (heat_->colourbar_label.empty() ? 8.0 : 30.0);
  }
  const double px0 = left, px1 = std::max(width_ - right, left + 20.0), py0 = top, py1 = height_ - bottom;
  const double pw = px1 - px0, ph = py1 - py0;
  if (equal_aspect_ && !log_x_) {
    // One unit as long on both axes: widen the range that has fewer units per pixel about its centre (the y
    // ticks' labels, which set the left margin, are recomputed; their width barely changes).
    const double u = std::max((xr.second - xr.first) / pw, (yr.second - yr.first) / ph);
    const double cx = (xr.first + xr.second) / 2, cy = (yr.first + yr.second) / 2;
    xr = {cx - u * pw / 2, cx + u * pw / 2};
    yr = {cy - u * ph / 2, cy + u * ph / 2};
    yticks = LinearTicks(yr.first, yr.second, std::max(2, (height_ - 90) / 50));
  }
  const int xtarget = std::max(2, static_cast<int>(pw / 90.0));
  const std::vector<Tick> xticks =
      log_x_ ? LogTicks(xr.first, xr.second, xtarget) : LinearTicks(xr.first, xr.second, xtarget);
  auto X = [&](double axis_x) { return px0 + (axis_x - xr.first) / (xr.second - xr.first) * pw; };
  auto Y = [&](double y) { return py1 - (y - yr.first) / (yr.second - yr.first) * ph; };

  // ---- document
  std::string o;
  o += "<?xml version=\"1.0\" encoding=\"UTF-8\" standalone=\"no\"?>\n";
  o += "<svg xmlns=\"http://www.w3.org/2000/svg\" xmlns:xlink=\"http://www.w3.org/1999/xlink\" version=\"1.1\"";
  o += " width=\"" + std::to_string(width_) + "\" height=\"" + std::to_string(height_) + "\" viewBox=\"0 0 " +
       std::to_string(width_) + " " + std::to_string(height_) + "\" font-family=\"DejaVu Sans, Arial, sans-serif\">\n";
  o += "<defs><clipPath id=\"ruffini-plot-area\"><rect x=\"" + Num(px0) + "\" y=\"" + Num(py0) + "\" width=\"" +
       Num(pw) + "\" height=\"" + Num(ph) + "\"/></clipPath>";
  if (heat_) {
    o += "<linearGradient id=\"ruffini-viridis\" x1=\"0\" y1=\"1\" x2=\"0\" y2=\"0\">";
    for (int k = 0; k < 9; ++k)
      o += "<stop offset=\"" + Num(k / 8.0, 3) + "\" stop-color=\"" + Colour(kViridisAnchors[k]) + "\"/>";
    o += "</linearGradient>";
  }
  o += "</defs>\n<rect width=\"100%\" height=\"100%\" fill=\"#ffffff\"/>\n";
  if (!title_.empty())
    o += "<text x=\"" + Num(width_ / 2.0) + "\" y=\"24\" text-anchor=\"middle\" font-size=\"15\" font-weight=\"bold\">" +
         Esc(title_) + "</text>\n";

  // Grid (only without a heat map, which would hide it anyway).
  if (!heat_) {
    o += "<g stroke=\"#e4e4e4\" stroke-width=\"1\">\n";
    for (const Tick& t : xticks)
      if (!t.label.empty())
        o += "<line x1=\"" + Num(X(t.pos)) + "\" y1=\"" + Num(py0) + "\" x2=\"" + Num(X(t.pos)) + "\" y2=\"" + Num(py1) + "\"/>\n";
    for (const Tick& t : yticks)
      o += "<line x1=\"" + Num(px0) + "\" y1=\"" + Num(Y(t.pos)) + "\" x2=\"" + Num(px1) + "\" y2=\"" + Num(Y(t.pos)) + "\"/>\n";
    o += "</g>\n";
  }

  o += "<g clip-path=\"url(#ruffini-plot-area)\">\n";
  if (heat_) {
    const HeatLayer& h = *heat_;
    // Upscale cells so renderers that smooth images still show crisp cells.
    const int f = std::clamp(static_cast<int>(std::ceil(std::max(pw, ph) / std::max(h.cols, h.rows))), 1, 8);
    Image img(h.cols * f, h.rows * f);
    for (int r = 0; r < h.rows; ++r)
      for (int c = 0; c < h.cols; ++c) {
        const double v = h.values[static_cast<std::size_t>(r) * h.cols + c];
        const Rgb col = v <= h.black_at_or_below ? Rgb{0, 0, 0}
                        : std::isnan(v)          ? Viridis(v)
                                                 : Viridis(v_hi > v_lo ? (v - v_lo) / (v_hi - v_lo) : 0.5);
        img.FillRect(c * f, (h.rows - 1 - r) * f, f, f, col);  // image top row = y_max
      }
    const double x0 = X(tx(h.x_min)), x1 = X(tx(h.x_max)), y0 = Y(h.y_max), y1 = Y(h.y_min);
    if (std::isfinite(x0) && std::isfinite(x1))
      o += "<image x=\"" + Num(std::min(x0, x1)) + "\" y=\"" + Num(std::min(y0, y1)) + "\" width=\"" +
           Num(std::fabs(x1 - x0)) + "\" height=\"" + Num(std::fabs(y1 - y0)) +
           "\" preserveAspectRatio=\"none\" image-rendering=\"optimizeSpeed\" style=\"image-rendering:pixelated\""
           " xlink:href=\"data:image/png;base64," + Base64(EncodePng(img)) + "\"/>\n";
  }
  std::vector<std::pair<double, double>> busy;  // pixels the legend should avoid
  auto busy_text = [&busy](double x, double y, std::size_t chars, bool anchor_end) {
    const double w = kCharW * 11.0 * static_cast<double>(chars);
    for (double f = 0.0; f <= 1.0; f += 0.25) busy.emplace_back(anchor_end ? x - f * w : x + f * w, y - 4.0);
  };
  for (const RefLine& l : hlines_) {
    if (!std::isfinite(l.v)) continue;
    busy_text(px1 - 4.0, Y(l.v) - 4.0, l.label.size(), true);
    o += "<line x1=\"" + Num(px0) + "\" y1=\"" + Num(Y(l.v)) + "\" x2=\"" + Num(px1) + "\" y2=\"" + Num(Y(l.v)) +
         "\" stroke=\"#444444\" stroke-width=\"1.2\" stroke-dasharray=\"6,4\"/>\n";
    if (!l.label.empty()) o += HaloText(px1 - 4.0, Y(l.v) - 4.0, l.label, " text-anchor=\"end\"");
  }
  for (const RefLine& l : vlines_) {
    if (!std::isfinite(tx(l.v))) continue;
    const double x = X(tx(l.v));
    busy_text(x + 4.0, py0 + 13.0, l.label.size(), false);
    o += "<line x1=\"" + Num(x) + "\" y1=\"" + Num(py0) + "\" x2=\"" + Num(x) + "\" y2=\"" + Num(py1) +
         "\" stroke=\"#444444\" stroke-width=\"1.2\" stroke-dasharray=\"6,4\"/>\n";
    if (!l.label.empty()) o += HaloText(x + 4.0, py0 + 13.0, l.label);
  }
  struct LegendEntry {
    std::string label, colour;
    Series::Style style;
  };
  std::vector<LegendEntry> legend;
  for (std::size_t si = 0; si < series_.size(); ++si) {
    const Series& s = series_[si];
    const std::string colour = Esc(s.colour.empty() ? kPalette[si % std::size(kPalette)] : s.colour);
    std::string path, dots;
    bool pen = false;
    for (std::size_t i = 0; i < std::min(s.x.size(), s.y.size()); ++i) {
      const double ax = tx(s.x[i]);
      if (!std::isfinite(ax) || !std::isfinite(s.y[i])) {
        pen = false;
        continue;
      }
      const double px = X(ax), py = Y(s.y[i]);
      const auto prev = pen ? busy.back() : std::pair{px, py};  // sample the segment, ending at (px, py)
      for (int k = pen && s.style != Series::Style::kPoints ? 7 : 0; k >= 0; --k)
        busy.emplace_back(px + (prev.first - px) * k / 8.0, py + (prev.second - py) * k / 8.0);
      const std::string xy = Num(px) + " " + Num(py);
      path += (pen ? " L" : " M") + xy;
      pen = true;
      dots += "<circle cx=\"" + Num(X(ax)) + "\" cy=\"" + Num(Y(s.y[i])) + "\" r=\"2.6\"/>";
    }
    if (s.style != Series::Style::kPoints && !path.empty())
      o += "<path d=\"" + path.substr(1) + "\" fill=\"none\" stroke=\"" + colour +
           "\" stroke-width=\"1.8\" stroke-linejoin=\"round\"/>\n";
    if (s.style != Series::Style::kLine && !dots.empty()) o += "<g fill=\"" + colour + "\">" + dots + "</g>\n";
    if (!s.label.empty()) legend.push_back({s.label, colour, s.style});
  }
  for (const Marker& m : markers_) {
    if (!std::isfinite(tx(m.x)) || !std::isfinite(m.y)) continue;
    const double x = X(tx(m.x)), y = Y(m.y);
    busy.emplace_back(x, y);
    busy_text(x + 6.0, y - 6.0, m.text.size(), false);
    const std::string d = "M" + Num(x - 4) + " " + Num(y - 4) + " L" + Num(x + 4) + " " + Num(y + 4) + " M" +
                          Num(x - 4) + " " + Num(y + 4) + " L" + Num(x + 4) + " " + Num(y - 4);
    o += "<path d=\"" + d + "\" stroke=\"#ffffff\" stroke-width=\"3.5\"/><path d=\"" + d +
         "\" stroke=\"#000000\" stroke-width=\"1.5\"/>\n";
    if (!m.text.empty()) o += HaloText(x + 6.0, y - 6.0, m.text);
  }
  o += "</g>\n";

  // ---- frame, ticks, labels
  o += "<rect x=\"" + Num(px0) + "\" y=\"" + Num(py0) + "\" width=\"" + Num(pw) + "\" height=\"" + Num(ph) +
       "\" fill=\"none\" stroke=\"#000000\" stroke-width=\"1\"/>\n<g font-size=\"12\" stroke=\"#000000\">\n";
  for (const Tick& t : xticks) {
    const double x = X(t.pos), len = t.label.empty() ? 3.0 : 5.0;
    o += "<line x1=\"" + Num(x) + "\" y1=\"" + Num(py1) + "\" x2=\"" + Num(x) + "\" y2=\"" + Num(py1 + len) + "\"/>";
    if (!t.label.empty())
      o += "<text x=\"" + Num(x) + "\" y=\"" + Num(py1 + 18.0) + "\" text-anchor=\"middle\" stroke=\"none\">" +
           Esc(t.label) + "</text>";
    o += "\n";
  }
  for (const Tick& t : yticks)
    o += "<line x1=\"" + Num(px0 - 5.0) + "\" y1=\"" + Num(Y(t.pos)) + "\" x2=\"" + Num(px0) + "\" y2=\"" +
         Num(Y(t.pos)) + "\"/><text x=\"" + Num(px0 - 8.0) + "\" y=\"" + Num(Y(t.pos) + 4.0) +
         "\" text-anchor=\"end\" stroke=\"none\">" + Esc(t.label) + "</text>\n";
  o += "</g>\n";
  if (!x_label_.empty())
    o += "<text x=\"" + Num(px0 + pw / 2.0) + "\" y=\"" + Num(height_ - 12.0) +
         "\" text-anchor=\"middle\" font-size=\"13\">" + Esc(x_label_) + "</text>\n";
  if (!y_label_.empty())
    o += "<text transform=\"translate(18," + Num(py0 + ph / 2.0) + ") rotate(-90)\" text-anchor=\"middle\" "
         "font-size=\"13\">" + Esc(y_label_) + "</text>\n";

  // ---- legend: inside the plot area, in the corner covering the fewest busy pixels
  if (legend.size() > 1) {
    std::size_t chars = 1;
    for (const LegendEntry& e : legend) chars = std::max(chars, e.label.size());
    const double w = 38.0 + kCharW * 11.0 * static_cast<double>(chars), h = 8.0 + 16.0 * static_cast<double>(legend.size());
    double lx = px1 - 8.0 - w, ly = py0 + 8.0;
    std::size_t best = std::numeric_limits<std::size_t>::max();
    for (const auto& [cx, cy] : {std::pair{px1 - 8.0 - w, py0 + 8.0}, std::pair{px0 + 8.0, py0 + 8.0},
                                 std::pair{px1 - 8.0 - w, py1 - 8.0 - h}, std::pair{px0 + 8.0, py1 - 8.0 - h}}) {
      const auto n = static_cast<std::size_t>(std::count_if(busy.begin(), busy.end(), [&](const auto& b) {
        return b.first >= cx - 4.0 && b.first <= cx + w + 4.0 && b.second >= cy - 4.0 && b.second <= cy + h + 4.0;
      }));
      if (n < best) best = n, lx = cx, ly = cy;
    }
    o += "<g font-size=\"11\"><rect x=\"" + Num(lx) + "\" y=\"" + Num(ly) + "\" width=\"" + Num(w) + "\" height=\"" +
         Num(h) + "\" fill=\"#ffffff\" fill-opacity=\"0.85\" stroke=\"#999999\"/>\n";
    for (std::size_t i = 0; i < legend.size(); ++i) {
      const LegendEntry& e = legend[i];
      const double y = ly + 12.0 + 16.0 * static_cast<double>(i);
      if (e.style != Series::Style::kPoints)
        o += "<line x1=\"" + Num(lx + 6.0) + "\" y1=\"" + Num(y) + "\" x2=\"" + Num(lx + 28.0) + "\" y2=\"" + Num(y) +
             "\" stroke=\"" + e.colour + "\" stroke-width=\"1.8\"/>";
      if (e.style != Series::Style::kLine)
        o += "<circle cx=\"" + Num(lx + 17.0) + "\" cy=\"" + Num(y) + "\" r=\"2.6\" fill=\"" + e.colour + "\"/>";
      o += "<text x=\"" + Num(lx + 33.0) + "\" y=\"" + Num(y + 4.0) + "\">" + Esc(e.label) + "</text>\n";
    }
    o += "</g>\n";
  }

  // ---- colour bar (gradient identical to Viridis(); values <= black_at_or_below shown black)
  if (heat_) {
    const double bx = px1 + 14.0, bw = 14.0;
    auto C = [&](double v) { return py1 - (v - v_lo) / (v_hi - v_lo) * ph; };
    o += "<rect x=\"" + Num(bx) + "\" y=\"" + Num(py0) + "\" width=\"" + Num(bw) + "\" height=\"" + Num(ph) +
         "\" fill=\"url(#ruffini-viridis)\"/>\n";
    if (heat_->black_at_or_below >= v_lo) {
      const double yt = C(std::min(heat_->black_at_or_below, v_hi));
      o += "<rect x=\"" + Num(bx) + "\" y=\"" + Num(yt) + "\" width=\"" + Num(bw) + "\" height=\"" + Num(py1 - yt) +
           "\" fill=\"#000000\"/>\n";
    }
    o += "<rect x=\"" + Num(bx) + "\" y=\"" + Num(py0) + "\" width=\"" + Num(bw) + "\" height=\"" + Num(ph) +
         "\" fill=\"none\" stroke=\"#000000\"/>\n<g font-size=\"12\" stroke=\"#000000\">\n";
    for (const Tick& t : cticks)
      o += "<line x1=\"" + Num(bx + bw) + "\" y1=\"" + Num(C(t.pos)) + "\" x2=\"" + Num(bx + bw + 4.0) + "\" y2=\"" +
           Num(C(t.pos)) + "\"/><text x=\"" + Num(bx + bw + 7.0) + "\" y=\"" + Num(C(t.pos) + 4.0) +
           "\" stroke=\"none\">" + Esc(t.label) + "</text>\n";
    o += "</g>\n";
    if (!heat_->colourbar_label.empty())
      o += "<text transform=\"translate(" + Num(width_ - 12.0) + "," + Num(py0 + ph / 2.0) +
           ") rotate(-90)\" text-anchor=\"middle\" font-size=\"13\">" + Esc(heat_->colourbar_label) + "</text>\n";
  }
  o += "</svg>\n";
  return o;
}

void Figure::Save(const std::string& path) const {
  const std::string svg = Render();
  std::ofstream f(path, std::ios::binary);
  f.write(svg.data(), static_cast<std::streamsize>(svg.size()));
  f.close();
  if (!f) throw std::runtime_error("ruffini::plot::Figure::Save: cannot write " + path);
}

}  // namespace ruffini::plot
