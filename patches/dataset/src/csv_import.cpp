// Importing a CSV recording (time, 16 wavelengths, optional labels) into the dataset layout.
#include "ruffini/dataset/csv_import.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <limits>
#include <string_view>
#include <system_error>
#include <vector>

#include "ruffini/error.h"
#include "ruffini/yaml_reader.h"  // FormatNumber

namespace ruffini::dataset {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr std::size_t kMaxColumns = 20;

std::string_view Trim(std::string_view s) {
  const auto is_space = [](char c) { return c == ' ' || c == '\t' || c == '\r'; };
  while (!s.empty() && is_space(s.front())) s.remove_prefix(1);
  while (!s.empty() && is_space(s.back())) s.remove_suffix(1);
  return s;
}

enum class Parse { kOk, kNotANumber, kOutOfRange };

// Parses a whole trimmed cell as a double (locale-free); a leading '+' is accepted.
Parse ParseNumber(std::string_view s, double& value) {
  if (!s.empty() && s.front() == '+') {
    s.remove_prefix(1);
    if (!s.empty() && (s.front() == '+' || s.front() == '-')) return Parse::kNotANumber;
  }
  const char* last = s.data() + s.size();
  const auto [ptr, ec] = std::from_chars(s.data(), last, value);
  if (ec == std::errc::result_out_of_range && ptr == last) return Parse::kOutOfRange;
  if (ec != std::errc() || ptr != last) return Parse::kNotANumber;
  return Parse::kOk;
}

class CsvImporter {
 public:
  CsvImporter(const std::string& path, const CsvImportOptions& options) : path_(path), options_(options) {}

  Dataset Run() {
    const std::string text = ReadFile();
    std::string_view rest(text);
    if (rest.substr(0, 3) == "\xEF\xBB\xBF") rest.remove_prefix(3);  // UTF-8 byte order mark

    Dataset data;
    data.info.source = "recording";
    data.info.patch_name = options_.patch_name;
    data.info.surface_radius_mm = options_.surface_radius_mm;
    data.info.reference_wavelength_nm = options_.reference_wavelength_nm;

    std::size_t line_no = 0;
    std::size_t first_blank_line = 0;  // a blank line is fine only if nothing but blank lines follows it
    while (!rest.empty()) {
      const std::size_t eol = rest.find('\n');
      const std::string_view line = rest.substr(0, eol);
      rest.remove_prefix(eol == std::string_view::npos ? rest.size() : eol + 1);
      ++line_no;

      if (Trim(line).empty()) {
        if (first_blank_line == 0) first_blank_line = line_no;
        continue;
      }
      if (first_blank_line != 0) {
        Fail(first_blank_line, "blank line in the middle of the data (blank lines are allowed only at the end)");
      }
      const std::size_t count = Split(line);
      if (line_no == 1) {
        double ignored = 0.0;
        if (ParseNumber(cells_[0], ignored) == Parse::kNotANumber) continue;  // a header row
      }
      if (columns_ == 0) {
        if (count != 17 && count != 18 && count != 20) {
          Fail(line_no, "expected 17, 18 or 20 columns, found " + std::to_string(count));
        }
        columns_ = count;
        first_data_line_ = line_no;
      } else if (count != columns_) {
        Fail(line_no, "expected " + std::to_string(columns_) + " columns like line " +
                          std::to_string(first_data_line_) + ", found " + std::to_string(count));
      }
      AddRow(line_no, data);
    }

    const std::size_t n = data.size();
    if (n < 2) {
      throw InputError(path_ + ": need at least 2 data rows to find the sample rate, found " + std::to_string(n));
    }
    data.info.sample_rate_hz = 1.0 / MedianStep(data.t_s);
    if (!(data.info.sample_rate_hz >= 1e-3 && data.info.sample_rate_hz <= 1e7)) {
      throw InputError(path_ + ": the median time step gives " + FormatNumber(data.info.sample_rate_hz) +
                       " Hz; expected 0.001 Hz to 10 MHz (is the time column in seconds?)");
    }
    AssignIndentations(data);
    return data;
  }

 private:
  [[noreturn]] void Fail(std::size_t line_no, const std::string& what) const {
    throw InputError(path_ + ":" + std::to_string(line_no) + ": " + what);
  }

  std::string ReadFile() const {
    std::ifstream in(path_, std::ios::binary | std::ios::ate);
    if (!in) throw InputError(path_ + ": cannot open CSV file");
    const std::streamoff size = in.tellg();
    if (size < 0) throw InputError(path_ + ": cannot read CSV file");
    std::string text(static_cast<std::size_t>(size), '\0');
    in.seekg(0);
    if (!in.read(text.data(), static_cast<std::streamsize>(size))) throw InputError(path_ + ": cannot read CSV file");
    return text;
  }

  // Splits a line at commas into trimmed cells_; returns the number of cells (all of them, even past
  // the ones kept).
  std::size_t Split(std::string_view line) {
    std::size_t count = 0;
    while (true) {
      const std::size_t comma = line.find(',');
      if (count < cells_.size()) cells_[count] = Trim(line.substr(0, comma));
      ++count;
      if (comma == std::string_view::npos) break;
      line.remove_prefix(comma + 1);
    }
    return count;
  }

  // Parses cells_[col] (0-based). Empty cells give NaN when allowed; "nan" is accepted as NaN there too.
  double Cell(std::size_t line_no, std::size_t col, bool empty_is_nan, const char* what) const {
    const std::string_view cell = cells_[col];
    const std::string column = "column " + std::to_string(col + 1);
    if (cell.empty()) {
      if (empty_is_nan) return kNaN;
      Fail(line_no, column + " (" + what + ") is empty");
    }
    double value = 0.0;
    switch (ParseNumber(cell, value)) {
      case Parse::kOk: break;
      case Parse::kOutOfRange: Fail(line_no, column + " ('" + std::string(cell) + "') is out of range");
      case Parse::kNotANumber: Fail(line_no, column + " ('" + std::string(cell) + "') is not a number");
    }
    if (std::isinf(value) || (std::isnan(value) && !empty_is_nan)) {
      Fail(line_no, column + " (" + what + ") must be finite" + (empty_is_nan ? " or empty" : "") + ", found '" +
                        std::string(cell) + "'");
    }
    return value;
  }

  // A label cell: empty = unknown; otherwise it must fit the f32 column with a physical magnitude.
  double Label(std::size_t line_no, std::size_t column, const char* what, double max_abs) {
    const double v = Cell(line_no, column, true, what);
    if (std::abs(v) > max_abs) {
      Fail(line_no, "column " + std::to_string(column + 1) + " (" + what + ") " + FormatNumber(v) +
                        " is outside -" + FormatNumber(max_abs) + ".." + FormatNumber(max_abs));
    }
    return v;
  }

  void AddRow(std::size_t line_no, Dataset& data) {
    Frame f;
    f.t_s = Cell(line_no, 0, false, "time");
    if (!data.t_s.empty() && !(f.t_s > data.t_s.back())) {
      Fail(line_no, "time " + FormatNumber(f.t_s) + " s is not after " + FormatNumber(data.t_s.back()) +
                        " s on line " + std::to_string(previous_line_) + "; time must be strictly increasing");
    }
    for (std::size_t k = 0; k < kChannels; ++k) f.wavelength_nm[k] = Cell(line_no, 1 + k, true, "wavelength");
    const double force = columns_ >= 18 ? Label(line_no, 17, "force", 1e4) : kNaN;
    const double y = columns_ == 20 ? Label(line_no, 18, "y_mm", 1e4) : kNaN;
    const double r = columns_ == 20 ? Label(line_no, 19, "r_deg", 1e4) : kNaN;
    f.force_n = static_cast<float>(force);
    f.y_mm = static_cast<float>(y);
    f.r_deg = static_cast<float>(r);
    f.true_force_n = std::numeric_limits<float>::quiet_NaN();
    f.serial = data.size();
    f.flags = 0;
    f.indentation = -1;
    data.Append(f);
    previous_line_ = line_no;
  }

  static double MedianStep(const std::vector<double>& t) {
    std::vector<double> dt(t.size() - 1);
    for (std::size_t i = 1; i < t.size(); ++i) dt[i - 1] = t[i] - t[i - 1];
    const std::size_t mid = dt.size() / 2;
    std::nth_element(dt.begin(), dt.begin() + static_cast<std::ptrdiff_t>(mid), dt.end());
    double median = dt[mid];
    if (dt.size() % 2 == 0) {
      const double lower = *std::max_element(dt.begin(), dt.begin() + static_cast<std::ptrdiff_t>(mid));
      median = 0.5 * (lower + median);
    }
    return median;
  }

  // Each run of consecutive rows with finite y_mm and r_deg is one indentation, numbered from 0.
  static void AssignIndentations(Dataset& data) {
    std::int32_t next = 0;
    bool in_run = false;
    for (std::size_t i = 0; i < data.size(); ++i) {
      const bool inside = std::isfinite(data.y_mm[i]) && std::isfinite(data.r_deg[i]);
      if (inside && !in_run) ++next;
      in_run = inside;
      data.indentation[i] = inside ? next - 1 : -1;
    }
  }

  const std::string& path_;
  const CsvImportOptions& options_;
  std::array<std::string_view, kMaxColumns> cells_{};
  std::size_t columns_ = 0;
  std::size_t first_data_line_ = 0;
  std::size_t previous_line_ = 0;
};

}  // namespace

Dataset ImportCsv(const std::string& csv_path, const CsvImportOptions& options) {
  return CsvImporter(csv_path, options).Run();
}

}  // namespace ruffini::dataset
