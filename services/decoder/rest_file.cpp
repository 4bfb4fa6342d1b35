#include "rest_file.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <unistd.h>

#include "ruffini/error.h"

namespace ruffini::decoder {

std::int64_t UnixNowS() {
  return std::chrono::duration_cast<std::chrono::seconds>(std::chrono::system_clock::now().time_since_epoch()).count();
}

RestFile ReadRestFile(const std::string& path, const std::string& patch, const patch::PatchSpec& spec) {
  const auto fail = [&](const std::string& why) { return InputError("rest file " + path + ": " + why); };
  std::ifstream in(path);
  if (!in) throw fail("cannot be read");
  std::string line, word;
  RestFile r;
  int version = 0;
  // Lines may end in CR LF (a file copied through another system).
  const auto getline = [&](std::string& l) {
    if (!std::getline(in, l)) return false;
    if (!l.empty() && l.back() == '\r') l.pop_back();
    return true;
  };
  if (!getline(line) || std::sscanf(line.c_str(), "ruffini-rest %d", &version) != 1 || version != 1) {
    throw fail("not a ruffini rest file of version 1 (first line '" + line.substr(0, 40) + "')");
  }
  if (!getline(line) || line.rfind("patch ", 0) != 0) throw fail("second line is not 'patch NAME'");
  r.patch = line.substr(6);
  if (r.patch != patch) throw fail("written for patch '" + r.patch + "', not '" + patch + "'");
  long long unix_s = 0;
  if (!getline(line) || std::sscanf(line.c_str(), "unix_s %lld", &unix_s) != 1) {
    throw fail("third line is not 'unix_s SECONDS'");
  }
  r.unix_s = unix_s;
  if (r.unix_s > UnixNowS() + 86400) throw fail("written in the future (unix_s " + std::to_string(r.unix_s) + ")");
  if (!getline(line)) throw fail("no wavelength_nm line");
  std::istringstream values(line);
  values >> word;
  if (word != "wavelength_nm") throw fail("fourth line is not 'wavelength_nm' and 16 values");
  int present = 0;
  for (std::size_t i = 0; i < kGratings; ++i) {
    if (!(values >> word)) throw fail("fewer than 16 wavelengths");
    double v = 0.0;
    try {
      std::size_t used = 0;
      v = std::stod(word, &used);
      if (used != word.size()) throw std::invalid_argument(word);
    } catch (const std::exception&) {
      throw fail("wavelength " + std::to_string(i + 1) + " '" + word + "' is not a number");
    }
    if (std::isnan(v)) {
      r.wavelength_nm[i] = v;
      continue;
    }
    const double c = spec.gratings[i].wavelength_nm, half = spec.fibre.band_half_width_nm;
    if (!(std::abs(v - c) <= half)) {
      throw fail("wavelength " + std::to_string(i + 1) + " " + word + " nm lies outside grating " + std::to_string(i + 1) +
                 "'s band");
    }
    r.wavelength_nm[i] = v;
    ++present;
  }
  if (values >> word) throw fail("more than 16 wavelengths");
  if (present < 9) throw fail("only " + std::to_string(present) + " of 16 wavelengths present");
  return r;
}

void WriteRestFile(const std::string& path, const std::string& patch, const Wavelengths& wavelength_nm) {
  const std::string tmp = path + ".tmp";
  std::string text = "ruffini-rest 1\npatch " + patch + "\nunix_s " + std::to_string(UnixNowS()) + "\nwavelength_nm";
  char buf[32];
  for (double v : wavelength_nm) {
    std::snprintf(buf, sizeof buf, " %.7f", v);
    text += std::isnan(v) ? std::string(" nan") : std::string(buf);
  }
  text += "\n";
  {
    // fsync before the rename: after a power loss the file is the old rest or the new one, not an empty one.
    std::FILE* f = std::fopen(tmp.c_str(), "w");
    if (f == nullptr) throw InputError("rest file " + tmp + ": cannot be written");
    const bool ok = std::fwrite(text.data(), 1, text.size(), f) == text.size() && std::fflush(f) == 0 && ::fsync(::fileno(f)) == 0;
    std::fclose(f);
    if (!ok) throw InputError("rest file " + tmp + ": write failed");
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) throw InputError("rest file " + path + ": cannot replace it (" + ec.message() + ")");
}

}  // namespace ruffini::decoder
