#include "ruffini/decode/model_io.h"

#include <cstdint>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include "ruffini/decode/sensitivity.h"
#include "ruffini/decode/touches.h"
#include "ruffini/error.h"

namespace ruffini::decode {
namespace {

constexpr char kMagic[8] = {'R', 'F', 'N', 'M', 'O', 'D', 'L', '1'};

std::uint32_t Fnv1a(const std::string& s) {
  std::uint32_t h = 2166136261u;
  for (unsigned char c : s) {
    h ^= c;
    h *= 16777619u;
  }
  return h;
}

std::size_t Count(const v1::Tensor& t) {
  std::size_t n = t.shape_size() ? 1 : 0;
  for (auto d : t.shape()) n *= d;
  return n;
}

void CheckTensor(const v1::Tensor& t, std::initializer_list<std::size_t> shape, const std::string& what) {
  std::string want, got;
  for (auto d : shape) {
    if (!want.empty()) want += 'x';
    want += std::to_string(d);
  }
  for (auto d : t.shape()) {
    if (!got.empty()) got += 'x';
    got += std::to_string(d);
  }
  if (static_cast<std::size_t>(t.shape_size()) != shape.size() || got != want) {
    throw InputError(what + " has shape [" + got + "], expected [" + want + "]");
  }
  if (Count(t) != static_cast<std::size_t>(t.values_size())) {
    throw InputError(what + " declares " + std::to_string(Count(t)) + " values but holds " + std::to_string(t.values_size()));
  }
  for (float v : t.values()) {
    if (!std::isfinite(v)) throw InputError(what + " contains a non-finite weight");
  }
}

void CheckNorm(const v1::Normalization& n, std::size_t size, const std::string& what) {
  if (static_cast<std::size_t>(n.mean_size()) != size || static_cast<std::size_t>(n.std_size()) != size) {
    throw InputError(what + " normalisation has " + std::to_string(n.mean_size()) + " means and " +
                     std::to_string(n.std_size()) + " stds, expected " + std::to_string(size));
  }
  for (int i = 0; i < n.std_size(); ++i) {
    if (!(n.std(i) > 0.0f) || !std::isfinite(n.mean(i))) {
      throw InputError(what + " normalisation entry " + std::to_string(i) + " has std " + std::to_string(n.std(i)) +
                       " (must be finite and > 0)");
    }
  }
}

// Checks a dense chain starting at `in` inputs; returns the final width.
std::size_t CheckDense(const google::protobuf::RepeatedPtrField<v1::DenseLayer>& layers, std::size_t in,
                       const std::string& what) {
  if (layers.empty()) throw InputError(what + " has no dense layers");
  for (int k = 0; k < layers.size(); ++k) {
    const auto& l = layers[k];
    const std::string name = what + " dense[" + std::to_string(k) + "]";
    if (l.weight().shape_size() != 2) throw InputError(name + " weight must be 2-D");
    const std::size_t out = l.weight().shape(0);
    CheckTensor(l.weight(), {out, in}, name + " weight");
    CheckTensor(l.bias(), {out}, name + " bias");
    in = out;
  }
  return in;
}

}  // namespace

void ValidateModel(const v1::DecoderModel& m, const std::string& where) {
  try {
    if (m.format_version() != kModelFormatVersion) {
      throw InputError("model format version " + std::to_string(m.format_version()) + ", this build reads version " +
                       std::to_string(kModelFormatVersion));
    }
    if (m.patch_name().empty() || m.patch_fingerprint().empty()) throw InputError("model names no patch");
    if (!(m.surface_radius_mm() > 0)) throw InputError("model has no surface_radius_mm");
    const auto& f = m.force();
    if (f.window() < 1 || f.window() > 256) throw InputError("force net window " + std::to_string(f.window()) + " outside 1..256");
    CheckNorm(f.input(), 16, "force net");
    std::size_t channels = f.window(), length = 16;
    if (f.conv().empty()) throw InputError("force net has no convolution layers");
    for (int k = 0; k < f.conv_size(); ++k) {
      const auto& c = f.conv(k);
      const std::string name = "force net conv[" + std::to_string(k) + "]";
      if (c.weight().shape_size() != 3) throw InputError(name + " weight must be 3-D");
      const std::size_t out = c.weight().shape(0), kernel = c.weight().shape(2);
      CheckTensor(c.weight(), {out, channels, kernel}, name + " weight");
      CheckTensor(c.bias(), {out}, name + " bias");
      if (c.pad_left() >= kernel) throw InputError(name + " pad_left must be below the kernel size");
      if (c.pool() < 1 || length % c.pool() != 0) throw InputError(name + " pool must divide the length " + std::to_string(length));
      channels = out;
      length /= c.pool();
    }
    if (CheckDense(f.dense(), channels * length, "force net") != 1) throw InputError("force net must end in 1 output");
    if (!std::isfinite(f.output_scale_n()) || f.output_scale_n() == 0.0f) throw InputError("force net output scale is 0");
    if (m.location().empty()) throw InputError("model has no location nets");
    for (int k = 0; k < m.location_size(); ++k) {
      const auto& l = m.location(k);
      const std::string name = "location net " + l.grid().name();
      if (l.grid().ny() < 1 || l.grid().nr() < 1 || !(l.grid().cell_y_mm() > 0) || !(l.grid().cell_r_deg() > 0)) {
        throw InputError(name + " has an empty grid");
      }
      CheckNorm(l.input(), 16, name);
      if (l.input_kind() != v1::LocationNet::RAW && l.input_kind() != v1::LocationNet::UNIT) {
        throw InputError(name + " has an unknown input kind " + std::to_string(static_cast<int>(l.input_kind())) +
                         " (a newer ruffini wrote it?)");
      }
      if (l.input_kind() == v1::LocationNet::UNIT && !(std::isfinite(l.unit_floor_pm()) && l.unit_floor_pm() > 0.0f)) {
        throw InputError(name + " has UNIT input with unit_floor_pm " + std::to_string(l.unit_floor_pm()) + " (must be > 0)");
      }
      const std::size_t classes = static_cast<std::size_t>(l.grid().ny()) * l.grid().nr();
      if (CheckDense(l.dense(), 16, name) != classes) {
        throw InputError(name + " outputs do not match its grid's " + std::to_string(classes) + " cells");
      }
    }
    if (!(m.gating().on_n() >= m.gating().off_n())) throw InputError("gating on_n must be >= off_n");
    if (m.has_input_range()) {
      const auto& r = m.input_range();
      if (static_cast<std::size_t>(r.min_shift_pm_size()) != kGratings || static_cast<std::size_t>(r.max_shift_pm_size()) != kGratings) {
        throw InputError("input_range has " + std::to_string(r.min_shift_pm_size()) + " minima and " +
                         std::to_string(r.max_shift_pm_size()) + " maxima, expected 16 each");
      }
      for (int i = 0; i < 16; ++i) {
        if (!(std::isfinite(r.min_shift_pm(i)) && std::isfinite(r.max_shift_pm(i)) && r.min_shift_pm(i) <= r.max_shift_pm(i))) {
          throw InputError("input_range grating " + std::to_string(i + 1) + " has min " + std::to_string(r.min_shift_pm(i)) +
                           " and max " + std::to_string(r.max_shift_pm(i)) + " (must be finite, min <= max)");
        }
      }
      if (!(std::isfinite(r.margin_pm()) && r.margin_pm() >= 0)) throw InputError("input_range margin_pm must be finite and >= 0");
    }
    if (m.preprocessing().thermal_ratio_size() != 0) {
      if (static_cast<std::size_t>(m.preprocessing().thermal_ratio_size()) != kGratings) {
        throw InputError("preprocessing thermal_ratio has " + std::to_string(m.preprocessing().thermal_ratio_size()) +
                         " entries, expected 16 (or none)");
      }
      for (float r : m.preprocessing().thermal_ratio()) {
        if (!(std::isfinite(r) && r > 0.5f && r < 2.0f)) {
          throw InputError("preprocessing thermal_ratio " + std::to_string(r) + " outside 0.5..2");
        }
      }
    }
    if (const float below = m.preprocessing().faint_refuse_below_n(); !(std::isfinite(below) && below >= 0.0f && below <= 10.0f)) {
      throw InputError("preprocessing faint_refuse_below_n " + std::to_string(below) + " N outside 0..10 (0: off)");
    }
    if (m.has_creep()) {
      const auto& c = m.creep();
      if (c.g_size() != c.tau_s_size() || c.g_size() > 4) {
        throw InputError("creep has " + std::to_string(c.g_size()) + " gains and " + std::to_string(c.tau_s_size()) +
                         " time constants (need equal counts, at most 4)");
      }
      for (int k = 0; k < c.g_size(); ++k) {
        if (!(std::isfinite(c.g(k)) && c.g(k) >= 0 && std::isfinite(c.tau_s(k)) && c.tau_s(k) > 0)) {
          throw InputError("creep term " + std::to_string(k) + " has g " + std::to_string(c.g(k)) + " and tau_s " +
                           std::to_string(c.tau_s(k)) + " (need g >= 0, tau_s > 0)");
        }
      }
    }
    if (m.has_uncertainty()) {
      const auto& u = m.uncertainty();
      const int n = u.force_knots_n_size();
      if (n < 1 || u.force_sd_n_size() != n || u.position_scale_size() != n) {
        throw InputError("uncertainty has " + std::to_string(n) + " knots, " + std::to_string(u.force_sd_n_size()) +
                         " force sds and " + std::to_string(u.position_scale_size()) + " position scales (need >= 1, all equal)");
      }
      for (int k = 0; k < n; ++k) {
        if (!std::isfinite(u.force_knots_n(k)) || (k > 0 && !(u.force_knots_n(k) > u.force_knots_n(k - 1)))) {
          throw InputError("uncertainty force_knots_n must be finite and ascending");
        }
        if (!(std::isfinite(u.force_sd_n(k)) && u.force_sd_n(k) > 0) || !(std::isfinite(u.position_scale(k)) && u.position_scale(k) > 0)) {
          throw InputError("uncertainty knot " + std::to_string(k) + " has force sd " + std::to_string(u.force_sd_n(k)) +
                           " and position scale " + std::to_string(u.position_scale(k)) + " (must be finite and > 0)");
        }
      }
      if (!(std::isfinite(u.position_floor_mm2()) && u.position_floor_mm2() >= 0)) {
        throw InputError("uncertainty position_floor_mm2 must be finite and >= 0");
      }
    }
    for (int k = 0; k < m.sensitivity_size(); ++k) {
      ValidateSensitivity(m.sensitivity(k), "sensitivity[" + std::to_string(k) + "]");
      if (k > 0 && !(m.sensitivity(k).level_n() > m.sensitivity(k - 1).level_n())) {
        throw InputError("sensitivity maps must be in ascending level_n, one per level");
      }
    }
    if (m.has_response()) (void)TouchCheck(m.response());  // throws what is wrong with it
  } catch (const InputError& e) {
    throw InputError(where + ": " + e.what());
  }
}

void CheckModelMatchesPatch(const v1::DecoderModel& m, const patch::PatchSpec& spec, const std::string& where) {
  if (m.patch_name() != spec.name || m.patch_fingerprint() != spec.Fingerprint()) {
    throw InputError(where + ": model was trained for patch '" + m.patch_name() + "' (spec fingerprint " +
                     m.patch_fingerprint() + "), but the patch is '" + spec.name + "' (fingerprint " + spec.Fingerprint() +
                     "); retrain with `ruffini train` for this patch");
  }
}

void SaveModel(const std::string& path, const v1::DecoderModel& m) {
  std::string payload;
  if (!m.SerializeToString(&payload)) throw InputError(path + ": cannot serialise the model");
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  const std::uint64_t size = payload.size();
  const std::uint32_t sum = Fnv1a(payload);
  unsigned char le[8];
  out.write(kMagic, 8);
  for (int i = 0; i < 8; ++i) le[i] = static_cast<unsigned char>(size >> (8 * i));
  out.write(reinterpret_cast<const char*>(le), 8);
  out.write(payload.data(), static_cast<std::streamsize>(payload.size()));
  for (int i = 0; i < 4; ++i) le[i] = static_cast<unsigned char>(sum >> (8 * i));
  out.write(reinterpret_cast<const char*>(le), 4);
  out.close();
  if (!out) throw InputError(path + ": cannot write the model file");
}

v1::DecoderModel LoadModel(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path + ": cannot open model file");
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string bytes = ss.str();
  if (bytes.size() < 20 || std::memcmp(bytes.data(), kMagic, 8) != 0) {
    throw InputError(path + ": not a ruffini model file (bad magic)");
  }
  std::uint64_t size = 0;
  for (int i = 0; i < 8; ++i) size |= static_cast<std::uint64_t>(static_cast<unsigned char>(bytes[8 + static_cast<std::size_t>(i)])) << (8 * i);
  if (bytes.size() != 16 + size + 4) {
    throw InputError(path + ": truncated or padded model file: " + std::to_string(bytes.size()) + " bytes, expected " +
                     std::to_string(16 + size + 4));
  }
  const std::string payload = bytes.substr(16, size);
  std::uint32_t sum = 0;
  for (int i = 0; i < 4; ++i) sum |= static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[16 + size + static_cast<std::size_t>(i)])) << (8 * i);
  if (sum != Fnv1a(payload)) throw InputError(path + ": model file is corrupted (checksum mismatch)");
  v1::DecoderModel m;
  if (!m.ParseFromString(payload)) throw InputError(path + ": model payload does not parse as ruffini.v1.DecoderModel");
  ValidateModel(m, path);
  return m;
}

}  // namespace ruffini::decode
