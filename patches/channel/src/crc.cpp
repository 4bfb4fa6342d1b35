#include "ruffini/channel/crc.h"

#include <array>
#include <bit>
#include <string>

#include <boost/crc.hpp>

namespace ruffini::channel {
namespace {

// Feeds fields to Boost.CRC in the canonical layout (crc.h). No allocation: each field goes through a small
// stack buffer.
class Canonical {
 public:
  void U64(std::uint64_t v) noexcept { Le(v, 8); }
  void I64(std::int64_t v) noexcept { Le(static_cast<std::uint64_t>(v), 8); }
  void U32(std::uint32_t v) noexcept { Le(v, 4); }
  void I32(std::int32_t v) noexcept { Le(static_cast<std::uint32_t>(v), 4); }
  void Bool(bool v) noexcept { Le(v ? 1u : 0u, 1); }
  void F32(float v) noexcept { Le(std::bit_cast<std::uint32_t>(v), 4); }
  void F64(double v) noexcept { Le(std::bit_cast<std::uint64_t>(v), 8); }
  void Str(const std::string& s) noexcept {
    U32(static_cast<std::uint32_t>(s.size()));
    crc_.process_bytes(s.data(), s.size());
  }
  [[nodiscard]] std::uint32_t Value() const noexcept { return crc_.checksum(); }

 private:
  void Le(std::uint64_t v, int bytes) noexcept {
    std::array<unsigned char, 8> b{};
    for (int i = 0; i < bytes; ++i) b[static_cast<std::size_t>(i)] = static_cast<unsigned char>(v >> (8 * i));
    crc_.process_bytes(b.data(), static_cast<std::size_t>(bytes));
  }
  boost::crc_32_type crc_;
};

void Hello(Canonical& c, const v1::PatchHello& h) noexcept {
  c.Str(h.patch_name());
  c.Str(h.patch_fingerprint());
  c.Str(h.model_name());
  c.Str(h.model_sha256());
  c.Str(h.model_patch_fingerprint());
  c.U32(h.model_format_version());
  c.F64(h.sample_rate_hz());
  const v1::DecoderConfig& d = h.decoder_config();
  c.Str(d.config_sha256());
  c.Str(d.scalar());
  c.U32(d.max_missing());
  c.F64(d.band_margin_nm());
  c.F64(d.z_limit());
  c.F64(d.contact_confirm_s());
  c.Bool(d.freeze_on_gate());
  c.Bool(d.common_mode_removed());
  c.U32(d.baseline_capture_frames());
  c.F64(d.baseline_drift_tau_s());
  c.F64(d.baseline_max_frozen_s());
  c.F32(d.gate_on_n());
  c.F32(d.gate_off_n());
  c.I64(h.heartbeat_period_ns());
  c.Str(h.decoder_version());
  c.Str(h.decoder_instance());
  c.U32(h.grating_count());
  // Added after the layout above was fixed (review 9: tests/channel/crc_descriptor_test.cpp found them outside
  // the CRC): the faint-refusal level and the sensitivity maps the aggregator's coverage check accepts the
  // patch on. A repeated field: its element count (4 bytes), then each element.
  c.F32(d.faint_refuse_below_n());
  c.U32(static_cast<std::uint32_t>(h.sensitivity_size()));
  for (const v1::SensitivityMap& m : h.sensitivity()) {
    c.F32(m.level_n());
    c.F32(m.reliability());
    c.U32(static_cast<std::uint32_t>(m.y_mm_size()));
    for (const double v : m.y_mm()) c.F64(v);
    c.U32(static_cast<std::uint32_t>(m.r_deg_size()));
    for (const double v : m.r_deg()) c.F64(v);
    c.U32(static_cast<std::uint32_t>(m.min_force_n_size()));
    for (const float v : m.min_force_n()) c.F32(v);
    c.U32(static_cast<std::uint32_t>(m.location_error_mm_size()));
    for (const float v : m.location_error_mm()) c.F32(v);
    c.U32(static_cast<std::uint32_t>(m.forces_n_size()));
    for (const float v : m.forces_n()) c.F32(v);
    c.U32(m.presses());
    c.F64(m.probe_radius_mm());
    c.Str(m.source());
    c.Str(m.measured_on());   // stop 31: what the map is bound to (docs/coverage.md)
    c.Str(m.model_sha256());
  }
}

void Contact(Canonical& c, const v1::PatchContact& k) noexcept {
  c.F32(k.force_n());
  c.F32(k.force_sd_n());
  c.Bool(k.located());
  c.F32(k.y_mm());
  c.F32(k.r_deg());
  c.F32(k.cov_yy_mm2());
  c.F32(k.cov_yr_mm2());
  c.F32(k.cov_rr_mm2());
  c.F32(k.confidence());
  c.Bool(k.onset());
  c.Bool(k.released());
  c.F32(k.common_mode_pm());
  c.U32(k.missing_peaks());
  c.Bool(k.uncertainty_calibrated());
  c.Bool(k.over_range());
  c.F32(k.force_lower_bound_n());
  c.Bool(k.multiple());
  c.Bool(k.faint());
}

void Beat(Canonical& c, const v1::Heartbeat& h) noexcept {
  c.Bool(h.healthy());
  c.I32(h.active_fault());
  c.U64(h.frames());
  c.U64(h.valid_frames());
  c.U64(h.serial_gaps());
  c.U64(h.frames_lost());
  c.U32(static_cast<std::uint32_t>(h.rejected_size()));
  for (const v1::FrameRejectCount& r : h.rejected()) {
    c.I32(r.reason());
    c.U64(r.frames());
  }
  c.U64(h.onsets());
  c.Bool(h.in_contact());
  c.I32(h.baseline_state());
  c.F32(h.drift_pm());
  c.F32(h.common_mode_pm());
  c.F32(h.baseline_frozen_s());
  c.U64(h.messages_dropped());
}

}  // namespace

std::uint32_t Crc32(std::span<const std::byte> bytes) noexcept {
  boost::crc_32_type crc;
  crc.process_bytes(bytes.data(), bytes.size());
  return crc.checksum();
}

std::uint32_t SafetyCrc(const v1::PatchMessage& m) noexcept {
  Canonical c;
  c.Str(m.patch_id());
  c.U64(m.seq());
  c.U64(m.interrogator_serial());
  c.I64(m.t_ns());
  c.I64(m.decoder_t_ns());
  c.U64(m.sender_run_id());
  c.I64(m.sender_steady_ns());
  c.U64(m.aggregator_run_id());
  c.U32(static_cast<std::uint32_t>(m.body_case()));
  switch (m.body_case()) {
    case v1::PatchMessage::kHello: Hello(c, m.hello()); break;
    case v1::PatchMessage::kContact: Contact(c, m.contact()); break;
    case v1::PatchMessage::kHeartbeat: Beat(c, m.heartbeat()); break;
    case v1::PatchMessage::kFault:
      c.I32(m.fault().code());
      c.I32(m.fault().reason());
      break;
    case v1::PatchMessage::kRetareResult: {
      const v1::RetareResult& r = m.retare_result();
      c.U64(r.request_id());
      c.I32(r.outcome());
      c.F32(r.force_n());
      c.F32(r.y_mm());
      c.F32(r.r_deg());
      c.F32(r.motion_pm());
      c.F32(r.min_force_n());
      break;
    }
    case v1::PatchMessage::BODY_NOT_SET: break;
  }
  return c.Value();
}

std::uint32_t SafetyCrc(const v1::SafetyState& s) noexcept {
  Canonical c;
  c.I32(s.state());
  c.U64(s.stop_epoch());
  c.U64(s.seq());
  c.I64(s.changed_t_ns());
  c.I64(s.published_t_ns());
  c.I64(s.aggregator_start_t_ns());
  c.U64(s.aggregator_run_id());
  c.Str(s.robot_name());
  c.I64(s.sender_steady_ns());
  const v1::SafetyCause& k = s.cause();
  c.I32(k.kind());
  c.Str(k.patch_id());
  c.Str(k.body_region());
  c.Str(k.link());
  c.F32(k.force_n());
  c.F32(k.threshold_n());
  c.F64(k.p_bc_m().x());
  c.F64(k.p_bc_m().y());
  c.F64(k.p_bc_m().z());
  c.I32(k.patch_fault());
  c.I64(k.t_ns());
  return c.Value();
}

void Seal(v1::PatchMessage& m) noexcept { m.set_safety_crc32(SafetyCrc(m)); }
void Seal(v1::SafetyState& s) noexcept { s.set_safety_crc32(SafetyCrc(s)); }
bool CrcMatches(const v1::PatchMessage& m) noexcept { return m.safety_crc32() == SafetyCrc(m); }
bool CrcMatches(const v1::SafetyState& s) noexcept { return s.safety_crc32() == SafetyCrc(s); }

}  // namespace ruffini::channel
