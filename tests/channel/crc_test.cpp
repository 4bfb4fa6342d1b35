// The safety CRC: the catalogue check value, test vectors shared with crc_oracle.py (an independent Python
// implementation of the canonical layout), and that every safety field changes the CRC.
#include <array>
#include <cstring>

#include <gtest/gtest.h>

#include "ruffini/channel/crc.h"

namespace ruffini::channel {
namespace {

// The same numbers as crc_oracle.py's EXPECTED.
constexpr std::uint32_t kContactCrc = 0xE68ED30C;
constexpr std::uint32_t kHeartbeatCrc = 0x0A8F8F41;
constexpr std::uint32_t kStateCrc = 0x2A93C49F;

v1::PatchMessage ContactMessage() {
  v1::PatchMessage m;
  m.set_patch_id("forearm_a");
  m.set_seq(7);
  m.set_interrogator_serial(1234);
  m.set_t_ns(1700000000000000000);
  m.set_decoder_t_ns(1700000000000100000);
  m.set_sender_run_id(0x0123456789abcdefULL);
  m.set_sender_steady_ns(5000000000);
  m.set_aggregator_run_id(0xfedcba9876543210ULL);
  v1::PatchContact& c = *m.mutable_contact();
  c.set_force_n(2.5f);
  c.set_force_sd_n(0.125f);
  c.set_located(true);
  c.set_y_mm(75.5f);
  c.set_r_deg(42.25f);
  c.set_cov_yy_mm2(4.0f);
  c.set_cov_yr_mm2(0.5f);
  c.set_cov_rr_mm2(9.0f);
  c.set_confidence(0.75f);
  c.set_onset(true);
  c.set_released(false);
  c.set_common_mode_pm(-1.5f);
  c.set_missing_peaks(0);
  c.set_uncertainty_calibrated(true);
  c.set_over_range(true);
  c.set_force_lower_bound_n(2.5f);
  c.set_multiple(true);
  c.set_faint(true);
  return m;
}

v1::PatchMessage HeartbeatMessage() {
  v1::PatchMessage m;
  m.set_patch_id("p");
  m.set_seq(2);
  m.set_sender_run_id(1);
  m.set_sender_steady_ns(10);
  m.set_aggregator_run_id(2);
  v1::Heartbeat& h = *m.mutable_heartbeat();
  h.set_healthy(true);
  h.set_frames(100);
  h.set_valid_frames(99);
  v1::FrameRejectCount& r = *h.add_rejected();
  r.set_reason(v1::FRAME_REJECT_REASON_NO_SIGNAL);
  r.set_frames(1);
  h.set_baseline_state(v1::BASELINE_STATE_TRACKING);
  h.set_drift_pm(0.25f);
  return m;
}

v1::SafetyState State() {
  v1::SafetyState s;
  s.set_state(v1::SafetyState::STATE_STOP);
  s.set_stop_epoch(3);
  s.set_seq(42);
  s.set_changed_t_ns(100);
  s.set_published_t_ns(200);
  s.set_aggregator_start_t_ns(50);
  s.set_aggregator_run_id(0x1122334455667788ULL);
  s.set_robot_name("cobot");
  s.set_sender_steady_ns(123456789);
  v1::SafetyCause& k = *s.mutable_cause();
  k.set_kind(v1::SafetyCause::KIND_CONTACT);
  k.set_patch_id("forearm_a");
  k.set_body_region("forearm");
  k.set_link("forearm_link");
  k.set_force_n(3.0f);
  k.set_threshold_n(1.5f);
  k.mutable_p_bc_m()->set_x(0.1);
  k.mutable_p_bc_m()->set_y(-0.2);
  k.mutable_p_bc_m()->set_z(0.3);
  k.set_t_ns(99);
  k.set_message("free text is not covered");
  return s;
}

TEST(Crc32, CatalogueCheckValue) {
  const char* text = "123456789";
  std::array<std::byte, 9> bytes{};
  std::memcpy(bytes.data(), text, 9);
  EXPECT_EQ(Crc32(bytes), 0xCBF43926u);
  EXPECT_EQ(Crc32({}), 0u);
}

TEST(SafetyCrc, VectorsMatchTheIndependentOracle) {
  EXPECT_EQ(SafetyCrc(ContactMessage()), kContactCrc);
  EXPECT_EQ(SafetyCrc(HeartbeatMessage()), kHeartbeatCrc);
  EXPECT_EQ(SafetyCrc(State()), kStateCrc);
}

TEST(SafetyCrc, SealThenMatchAndTheCrcFieldItselfIsNotCovered) {
  v1::PatchMessage m = ContactMessage();
  EXPECT_FALSE(CrcMatches(m));
  Seal(m);
  EXPECT_EQ(m.safety_crc32(), kContactCrc);
  EXPECT_TRUE(CrcMatches(m));
  v1::SafetyState s = State();
  Seal(s);
  EXPECT_TRUE(CrcMatches(s));
  s.mutable_cause()->set_message("other text");
  EXPECT_TRUE(CrcMatches(s)) << "free text is outside the CRC";
}

// Each mutation of a safety field must change the CRC (a corrupted field is detected).
TEST(SafetyCrc, EverySafetyFieldOfAContactIsCovered) {
  const v1::PatchMessage base = ContactMessage();
  const std::uint32_t crc = SafetyCrc(base);
  using Mut = void (*)(v1::PatchMessage&);
  const Mut mutations[] = {
      [](v1::PatchMessage& m) { m.set_patch_id("forearm_b"); },
      [](v1::PatchMessage& m) { m.set_seq(8); },
      [](v1::PatchMessage& m) { m.set_interrogator_serial(1235); },
      [](v1::PatchMessage& m) { m.set_t_ns(m.t_ns() + 1); },
      [](v1::PatchMessage& m) { m.set_decoder_t_ns(m.decoder_t_ns() + 1); },
      [](v1::PatchMessage& m) { m.set_sender_run_id(m.sender_run_id() ^ 1); },
      [](v1::PatchMessage& m) { m.set_sender_steady_ns(m.sender_steady_ns() + 1); },
      [](v1::PatchMessage& m) { m.set_aggregator_run_id(m.aggregator_run_id() ^ 0x8000000000000000ULL); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_force_n(0.25f); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_force_sd_n(0.5f); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_located(false); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_y_mm(75.25f); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_r_deg(-42.25f); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_cov_yy_mm2(4.5f); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_cov_yr_mm2(0.0f); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_cov_rr_mm2(1.0f); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_confidence(0.5f); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_onset(false); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_released(true); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_common_mode_pm(0.0f); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_missing_peaks(1); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_uncertainty_calibrated(false); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_over_range(false); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_multiple(false); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_faint(false); },
      [](v1::PatchMessage& m) { m.mutable_contact()->set_force_lower_bound_n(5.0f); },
      [](v1::PatchMessage& m) { m.mutable_heartbeat()->set_healthy(true); },  // another body
  };
  for (std::size_t i = 0; i < std::size(mutations); ++i) {
    v1::PatchMessage m = base;
    mutations[i](m);
    EXPECT_NE(SafetyCrc(m), crc) << "mutation " << i;
  }
}

TEST(SafetyCrc, EverySafetyFieldOfAStateIsCovered) {
  const v1::SafetyState base = State();
  const std::uint32_t crc = SafetyCrc(base);
  using Mut = void (*)(v1::SafetyState&);
  const Mut mutations[] = {
      [](v1::SafetyState& s) { s.set_state(v1::SafetyState::STATE_CLEAR); },
      [](v1::SafetyState& s) { s.set_stop_epoch(4); },
      [](v1::SafetyState& s) { s.set_seq(43); },
      [](v1::SafetyState& s) { s.set_changed_t_ns(101); },
      [](v1::SafetyState& s) { s.set_published_t_ns(201); },
      [](v1::SafetyState& s) { s.set_aggregator_start_t_ns(51); },
      [](v1::SafetyState& s) { s.set_aggregator_run_id(1); },
      [](v1::SafetyState& s) { s.set_robot_name("cobot2"); },
      [](v1::SafetyState& s) { s.set_sender_steady_ns(123456788); },
      [](v1::SafetyState& s) { s.mutable_cause()->set_kind(v1::SafetyCause::KIND_PATCH_FAULT); },
      [](v1::SafetyState& s) { s.mutable_cause()->set_patch_id("forearm_b"); },
      [](v1::SafetyState& s) { s.mutable_cause()->set_body_region("upper_arm"); },
      [](v1::SafetyState& s) { s.mutable_cause()->set_link("upper_arm_link"); },
      [](v1::SafetyState& s) { s.mutable_cause()->set_force_n(3.5f); },
      [](v1::SafetyState& s) { s.mutable_cause()->set_threshold_n(2.0f); },
      [](v1::SafetyState& s) { s.mutable_cause()->mutable_p_bc_m()->set_x(0.2); },
      [](v1::SafetyState& s) { s.mutable_cause()->mutable_p_bc_m()->set_y(0.2); },
      [](v1::SafetyState& s) { s.mutable_cause()->mutable_p_bc_m()->set_z(-0.3); },
      [](v1::SafetyState& s) { s.mutable_cause()->set_patch_fault(v1::PATCH_FAULT_CODE_LATE); },
      [](v1::SafetyState& s) { s.mutable_cause()->set_t_ns(98); },
  };
  for (std::size_t i = 0; i < std::size(mutations); ++i) {
    v1::SafetyState s = base;
    mutations[i](s);
    EXPECT_NE(SafetyCrc(s), crc) << "mutation " << i;
  }
}

// A single flipped bit anywhere in the canonical fields is always caught (CRC-32 detects every 1-bit error).
TEST(SafetyCrc, EverySingleBitFlipOfTheForceIsDetected) {
  const v1::PatchMessage base = ContactMessage();
  std::uint32_t bits = 0;
  const float f = base.contact().force_n();
  std::memcpy(&bits, &f, 4);
  for (int i = 0; i < 32; ++i) {
    v1::PatchMessage m = base;
    const std::uint32_t flipped = bits ^ (1u << i);
    float g = 0;
    std::memcpy(&g, &flipped, 4);
    m.mutable_contact()->set_force_n(g);
    EXPECT_NE(SafetyCrc(m), SafetyCrc(base)) << "bit " << i;
  }
}

}  // namespace
}  // namespace ruffini::channel
