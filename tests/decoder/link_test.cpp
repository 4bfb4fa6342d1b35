// link::Monitor, the decode thread's logic, on an injected clock with a scripted pipeline: every rule of
// monitor.h (heartbeats, faults and their priority, contacts, no NaN out), no threads, no ports.
#include <gtest/gtest.h>

#include <cctype>
#include <cmath>
#include <deque>
#include <limits>
#include <vector>

#include "ruffini/decode/model_io.h"
#include "ruffini/error.h"
#include "ruffini/link/monitor.h"
#include "ruffini/link/to_proto.h"
#include "ruffini/twin/scene.h"

namespace {

using namespace ruffini;
using link::FaultCode;
using link::Message;
using link::Now;

constexpr std::int64_t kMs = 1'000'000;

// Returns scripted outputs (valid, no contact by default); the baseline can be made to track.
class ScriptedPipeline final : public link::FramePipeline {
 public:
  std::deque<decode::PipelineOutput> script;
  decode::PipelineOutput fallback = Valid(0.0f, false);
  decode::BaselineTracker tracker;
  decode::PipelineCounters c;
  bool uncertainty = true;

  static decode::PipelineOutput Valid(float force, bool contact, float y = 0, float r = 0) {
    decode::PipelineOutput o;
    o.valid = true;
    o.reason = decode::Reason::kOk;
    o.force_n = force;
    o.in_contact = contact;
    o.located = contact;
    o.y_mm = contact ? y : std::numeric_limits<float>::quiet_NaN();
    o.r_deg = contact ? r : std::numeric_limits<float>::quiet_NaN();
    o.force_sd_n = 0.05f;
    o.cov_yy_mm2 = o.cov_yr_mm2 = o.cov_rr_mm2 = contact ? 4.0f : std::numeric_limits<float>::quiet_NaN();
    return o;
  }
  static decode::PipelineOutput Invalid(decode::Reason r) {
    decode::PipelineOutput o;
    o.valid = false;
    o.reason = r;
    o.y_mm = o.r_deg = o.force_sd_n = std::numeric_limits<float>::quiet_NaN();
    return o;
  }
  void Track() {
    Wavelengths w{};
    for (std::size_t i = 0; i < kGratings; ++i) w[i] = 1530.0 + 3.0 * static_cast<double>(i);
    tracker.Seed(w);
  }
  void Retare(const Wavelengths& baseline_nm) noexcept override { tracker.Seed(baseline_nm); }
  decode::PipelineOutput Process(const Wavelengths&, std::uint32_t) noexcept override {
    ++c.frames;
    decode::PipelineOutput o = fallback;
    if (!script.empty()) {
      o = script.front();
      script.pop_front();
    }
    if (o.valid) ++c.valid;
    else ++c.invalid[static_cast<std::size_t>(o.reason)];
    if (o.valid && o.in_contact) ++c.onsets;  // not exact; the monitor only copies it
    return o;
  }
  const decode::BaselineTracker& baseline() const noexcept override { return tracker; }
  const decode::PipelineCounters& counters() const noexcept override { return c; }
  bool calibrated_uncertainty() const noexcept override { return uncertainty; }
  int breaks = 0;
  void OnStreamBreak() noexcept override { ++breaks; }
};

struct VectorSink final : link::MessageSink {
  std::vector<Message> got;
  void Push(const Message& m) noexcept override { got.push_back(m); }
  std::vector<Message> Of(Message::Kind k) const {
    std::vector<Message> out;
    for (const auto& m : got) {
      if (m.kind == k) out.push_back(m);
    }
    return out;
  }
  std::vector<FaultCode> Faults() const {
    std::vector<FaultCode> out;
    for (const auto& m : Of(Message::Kind::kFault)) out.push_back(m.fault.code);
    return out;
  }
};

Now At(std::int64_t ns) { return {ns, 1'700'000'000'000'000'000 + ns}; }

class MonitorTest : public ::testing::Test {
 protected:
  MonitorTest() { pipe.Track(); }
  link::MonitorConfig Config() {
    link::MonitorConfig c;
    c.sample_rate_hz = 1000.0;
    c.silence_deadline_ns = 3 * kMs;  // explicit: the rules below are written for 3 ms
    return c;
  }
  // Connects at t and feeds n frames 1 ms apart from serial s0; returns the time after the last one.
  std::int64_t Feed(link::Monitor& m, std::int64_t t, int n, std::uint64_t s0 = 1) {
    for (int i = 0; i < n; ++i) {
      link::FrameIn f;
      f.serial = s0 + static_cast<std::uint64_t>(i);
      f.t_ns = 5'000 + t;
      m.OnFrame(f, At(t), sink);
      t += kMs;
    }
    return t;
  }
  ScriptedPipeline pipe;
  VectorSink sink;
};

TEST_F(MonitorTest, DefaultsComeFromTheRate) {
  link::MonitorConfig d;
  d.sample_rate_hz = 1000.0;
  const auto c = link::Resolved(d);
  EXPECT_EQ(c.silence_deadline_ns, 15 * kMs);  // 3 frame periods (3 ms at 1 kHz), at least 15 ms
  link::MonitorConfig slow;
  slow.sample_rate_hz = 100.0;
  EXPECT_EQ(link::Resolved(slow).silence_deadline_ns, 30 * kMs);
  EXPECT_EQ(c.reject_fault_frames, 20);
  EXPECT_EQ(link::Resolved(slow).reject_fault_frames, 3);
  link::MonitorConfig bad;
  bad.sample_rate_hz = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(link::Resolved(bad), InputError);
  bad.sample_rate_hz = 1000.0;
  bad.heartbeat_period_ns = 0;
  EXPECT_THROW(link::Resolved(bad), InputError);
}

TEST_F(MonitorTest, StartsDisconnectedAndUnhealthyThenHeartbeatsEveryPeriod) {
  link::Monitor m(pipe, Config(), At(0));
  m.Tick(At(0), sink);
  ASSERT_EQ(sink.Faults(), std::vector<FaultCode>{FaultCode::kInterrogatorDisconnected});
  ASSERT_EQ(sink.Of(Message::Kind::kHeartbeat).size(), 1u);
  EXPECT_FALSE(sink.Of(Message::Kind::kHeartbeat)[0].health.healthy);
  // No frames: silent, still heartbeats every 10 ms (and nothing in between).
  for (std::int64_t t = 0; t <= 100 * kMs; t += kMs / 2) m.Tick(At(t), sink);
  EXPECT_EQ(sink.Of(Message::Kind::kHeartbeat).size(), 11u);
  m.OnConnected(At(100 * kMs), sink);
  const std::int64_t t = Feed(m, 100 * kMs, 50);
  m.Tick(At(t), sink);
  const auto hb = sink.Of(Message::Kind::kHeartbeat);
  EXPECT_TRUE(hb.back().health.healthy);
  EXPECT_EQ(hb.back().health.active_fault, FaultCode::kNone);
  EXPECT_EQ(hb.back().health.frames, 50u);
  EXPECT_EQ(hb.back().serial, 50u);
  EXPECT_LE(m.NextDeadlineMono(), t + 3 * kMs + 1);
}

TEST_F(MonitorTest, SilencePastTheDeadlineIsAFaultAndNotBefore) {
  link::Monitor m(pipe, Config(), At(0));
  m.OnConnected(At(0), sink);
  const std::int64_t last = Feed(m, 0, 10) - kMs;  // the last frame's time
  sink.got.clear();
  m.Tick(At(last + 3 * kMs), sink);  // exactly at the deadline: not yet
  EXPECT_TRUE(sink.Faults().empty());
  EXPECT_EQ(m.NextDeadlineMono(), last + 3 * kMs + 1);
  m.Tick(At(last + 3 * kMs + 1), sink);
  ASSERT_EQ(sink.Faults(), std::vector<FaultCode>{FaultCode::kInterrogatorSilent});
  // Reported once, not again on each tick; frames resuming clear it (healthy heartbeats).
  m.Tick(At(last + 20 * kMs), sink);
  EXPECT_EQ(sink.Faults().size(), 1u);
  EXPECT_FALSE(m.health().healthy);
  Feed(m, last + 30 * kMs, 3, 11);
  EXPECT_TRUE(m.health().healthy);
  EXPECT_EQ(m.health().serial_gaps, 0u);
}

TEST_F(MonitorTest, ConnectedWithoutAnyFrameIsSilentAfterTheDeadline) {
  link::Monitor m(pipe, Config(), At(0));
  m.OnConnected(At(5 * kMs), sink);
  sink.got.clear();
  m.Tick(At(8 * kMs), sink);
  EXPECT_TRUE(sink.Faults().empty());
  m.Tick(At(8 * kMs + 1), sink);
  EXPECT_EQ(sink.Faults(), std::vector<FaultCode>{FaultCode::kInterrogatorSilent});
}

TEST_F(MonitorTest, DisconnectIsAFaultAtOnce) {
  link::Monitor m(pipe, Config(), At(0));
  m.OnConnected(At(0), sink);
  const std::int64_t t = Feed(m, 0, 5);
  sink.got.clear();
  m.OnDisconnected(At(t), sink);
  EXPECT_EQ(sink.Faults(), std::vector<FaultCode>{FaultCode::kInterrogatorDisconnected});
  EXPECT_FALSE(m.health().healthy);
}

TEST_F(MonitorTest, PersistentRejectionsAreAFaultNamingTheReason) {
  link::Monitor m(pipe, Config(), At(0));
  m.OnConnected(At(0), sink);
  std::int64_t t = Feed(m, 0, 5);
  sink.got.clear();
  // 19 rejected frames in a row: counted, no fault; the 20th: fault.
  for (int i = 0; i < 19; ++i) pipe.script.push_back(ScriptedPipeline::Invalid(decode::Reason::kOutOfBand));
  t = Feed(m, t, 19, 6);
  EXPECT_TRUE(sink.Faults().empty());
  EXPECT_TRUE(m.health().healthy);
  m.OnStreamRejected(ingest::Reason::kNonFinite, At(t), sink);
  ASSERT_EQ(sink.Faults(), std::vector<FaultCode>{FaultCode::kFramesRejected});
  EXPECT_EQ(sink.Of(Message::Kind::kFault)[0].fault.reason, 40u);  // FRAME_REJECT_REASON_NON_FINITE_PEAK
  EXPECT_EQ(m.health().stream_rejected[static_cast<std::size_t>(ingest::Reason::kNonFinite)], 1u);
  // One valid frame ends the run.
  Feed(m, t + kMs, 1, 26);
  EXPECT_TRUE(m.health().healthy);
  // Capturing frames are not rejections.
  for (int i = 0; i < 40; ++i) pipe.script.push_back(ScriptedPipeline::Invalid(decode::Reason::kCapturing));
  sink.got.clear();
  Feed(m, t + 2 * kMs, 40, 27);
  EXPECT_TRUE(sink.Faults().empty());
}

TEST_F(MonitorTest, ContactsCarryOnsetAndReleaseAndNeverNaN) {
  link::Monitor m(pipe, Config(), At(0));
  m.OnConnected(At(0), sink);
  std::int64_t t = Feed(m, 0, 3);
  sink.got.clear();
  pipe.script = {ScriptedPipeline::Valid(0.3f, true, 40, 70),
                 ScriptedPipeline::Invalid(decode::Reason::kOutOfBand),  // no message, contact not ended
                 ScriptedPipeline::Valid(0.5f, true, 41, 71), ScriptedPipeline::Valid(0.02f, false),
                 ScriptedPipeline::Valid(0.0f, false)};
  t = Feed(m, t, 5, 4);
  const auto contacts = sink.Of(Message::Kind::kContact);
  ASSERT_EQ(contacts.size(), 3u);
  EXPECT_TRUE(contacts[0].contact.onset);
  EXPECT_FALSE(contacts[0].contact.released);
  EXPECT_EQ(contacts[0].serial, 4u);
  EXPECT_FALSE(contacts[1].contact.onset);
  EXPECT_FLOAT_EQ(contacts[1].contact.y_mm, 41.0f);
  EXPECT_TRUE(contacts[2].contact.released);
  EXPECT_FALSE(contacts[2].contact.located);
  for (const auto& c : contacts) {
    for (float v : {c.contact.force_n, c.contact.force_sd_n, c.contact.y_mm, c.contact.r_deg, c.contact.cov_yy_mm2,
                    c.contact.cov_yr_mm2, c.contact.cov_rr_mm2, c.contact.confidence, c.contact.common_mode_pm}) {
      EXPECT_TRUE(std::isfinite(v));
    }
    EXPECT_TRUE(c.critical() == (c.contact.onset || c.contact.released));
  }
  // Without calibrated uncertainty, the uncertainty fields are 0 and say so.
  pipe.uncertainty = false;
  pipe.script = {ScriptedPipeline::Valid(0.3f, true, 40, 70)};
  sink.got.clear();
  Feed(m, t, 1, 9);
  const auto c = sink.Of(Message::Kind::kContact).at(0).contact;
  EXPECT_FALSE(c.uncertainty);
  EXPECT_EQ(c.force_sd_n, 0.0f);
  EXPECT_EQ(c.cov_yy_mm2, 0.0f);
}

// The frame that closes the gate reads below the gate's off level, often a little below 0 (noise about an
// unloaded patch, down to -0.1 N on a field cover): it is sent as a release of 0 N, never as a negative force the
// aggregator would take for a broken decoder (a STOP). A contact frame's force is sent as read.
TEST_F(MonitorTest, AReleaseIsSentClampedAtZero) {
  link::Monitor m(pipe, Config(), At(0));
  m.OnConnected(At(0), sink);
  std::int64_t t = Feed(m, 0, 3);
  sink.got.clear();
  pipe.script = {ScriptedPipeline::Valid(0.3f, true, 40, 70), ScriptedPipeline::Valid(-0.08f, false),
                 ScriptedPipeline::Valid(0.2f, true, 40, 70), ScriptedPipeline::Valid(0.01f, false)};
  Feed(m, t, 4, 4);
  const auto contacts = sink.Of(Message::Kind::kContact);
  ASSERT_EQ(contacts.size(), 4u);
  EXPECT_FLOAT_EQ(contacts[0].contact.force_n, 0.3f);
  EXPECT_TRUE(contacts[1].contact.released);
  EXPECT_EQ(contacts[1].contact.force_n, 0.0f);
  EXPECT_FLOAT_EQ(contacts[3].contact.force_n, 0.01f);
}

TEST_F(MonitorTest, SerialGapsAreCounted) {
  link::Monitor m(pipe, Config(), At(0));
  m.OnConnected(At(0), sink);
  std::int64_t t = Feed(m, 0, 3, 1);   // 1, 2, 3
  t = Feed(m, t, 2, 7);                // 7, 8: 3 lost
  Feed(m, t, 1, 10);                   // 1 lost
  EXPECT_EQ(m.health().serial_gaps, 2u);
  EXPECT_EQ(m.health().frames_lost, 4u);
  // Each break tells the pipeline (the two-touch cache starts afresh): the connect and the two gaps.
  EXPECT_EQ(pipe.breaks, 3);
}

TEST_F(MonitorTest, FaultPriorityAndOverloadHold) {
  link::Monitor m(pipe, Config(), At(0));
  m.OnConnected(At(0), sink);
  std::int64_t t = Feed(m, 0, 3);
  sink.got.clear();
  m.OnFramesDropped(5, At(t), sink);
  EXPECT_EQ(sink.Faults(), std::vector<FaultCode>{FaultCode::kOverloaded});
  EXPECT_EQ(m.health().frames_dropped, 5u);
  t = Feed(m, t, 100, 4);  // still within the 1 s hold
  EXPECT_EQ(m.health().active_fault, FaultCode::kOverloaded);
  // Disconnect outranks the overload.
  m.OnDisconnected(At(t), sink);
  EXPECT_EQ(sink.Faults().back(), FaultCode::kInterrogatorDisconnected);
  m.OnConnected(At(t + 1'100 * kMs), sink);
  Feed(m, t + 1'100 * kMs, 2, 200);
  EXPECT_EQ(m.health().active_fault, FaultCode::kNone);
}

TEST_F(MonitorTest, ShutdownIsTheLastWord) {
  link::Monitor m(pipe, Config(), At(0));
  m.OnConnected(At(0), sink);
  const std::int64_t t = Feed(m, 0, 3);
  sink.got.clear();
  m.Shutdown(At(t), sink);
  ASSERT_EQ(sink.got.size(), 1u);
  EXPECT_EQ(sink.got[0].fault.code, FaultCode::kShuttingDown);
  EXPECT_FALSE(m.health().healthy);
}

TEST_F(MonitorTest, BaselineNeverCapturedIsAFault) {
  ScriptedPipeline capturing;  // its tracker never leaves capturing
  capturing.fallback = ScriptedPipeline::Invalid(decode::Reason::kCapturing);
  auto c = Config();
  c.capture_deadline_s = 0.05;
  link::Monitor m(capturing, c, At(0));
  m.OnConnected(At(0), sink);
  for (int i = 0; i < 60; ++i) {
    link::FrameIn f;
    f.serial = static_cast<std::uint64_t>(i + 1);
    m.OnFrame(f, At(i * kMs), sink);
  }
  EXPECT_EQ(sink.Faults().back(), FaultCode::kBaselineInvalid);
  EXPECT_EQ(m.health().baseline, link::BaselineState::kCapturing);
}

// Issue 17: the pipeline's faint flag rides on the contact as information, located or not, the force as
// decoded; an unflagged frame is not faint.
TEST_F(MonitorTest, TheFaintFlagIsCarriedAndTheForceStands) {
  link::Monitor m(pipe, Config(), At(0));
  m.OnConnected(At(0), sink);
  std::int64_t t = Feed(m, 0, 3);
  sink.got.clear();
  decode::PipelineOutput faint = ScriptedPipeline::Valid(0.8f, true, 40, 70);
  faint.faint = true;
  decode::PipelineOutput force_only = ScriptedPipeline::Valid(1.7f, true);
  force_only.located = false;
  force_only.y_mm = force_only.r_deg = std::numeric_limits<float>::quiet_NaN();
  force_only.faint = true;
  pipe.script = {faint, force_only, ScriptedPipeline::Valid(0.9f, true, 41, 71)};
  Feed(m, t, 3, 4);
  const auto contacts = sink.Of(Message::Kind::kContact);
  ASSERT_EQ(contacts.size(), 3u);
  EXPECT_TRUE(contacts[0].contact.faint);
  EXPECT_FLOAT_EQ(contacts[0].contact.force_n, 0.8f);
  EXPECT_TRUE(contacts[0].contact.located);
  EXPECT_TRUE(contacts[1].contact.faint);
  EXPECT_FALSE(contacts[1].contact.located);
  EXPECT_FLOAT_EQ(contacts[1].contact.force_n, 1.7f);
  EXPECT_FALSE(contacts[2].contact.faint);
  v1::PatchMessage out;
  link::ToProto(contacts[1], "forearm", 5, out);
  ASSERT_TRUE(out.has_contact());
  EXPECT_TRUE(out.contact().faint());
  EXPECT_FLOAT_EQ(out.contact().force_n(), 1.7f);
  link::ToProto(contacts[2], "forearm", 6, out);
  EXPECT_FALSE(out.contact().faint());
}

TEST_F(MonitorTest, ProtoConversionKeepsEveryField) {
  link::Monitor m(pipe, Config(), At(0));
  m.OnConnected(At(0), sink);
  pipe.script = {ScriptedPipeline::Invalid(decode::Reason::kOutOfRange), ScriptedPipeline::Valid(1.5f, true, 50, 60)};
  Feed(m, 0, 2);
  m.OnStreamRejected(ingest::Reason::kWrongPeakCount, At(3 * kMs), sink);
  m.Tick(At(20 * kMs), sink);
  v1::PatchMessage out;
  const Message contact = sink.Of(Message::Kind::kContact).at(0);
  link::ToProto(contact, "forearm", 7, out);
  EXPECT_EQ(out.patch_id(), "forearm");
  EXPECT_EQ(out.seq(), 7u);
  EXPECT_EQ(out.interrogator_serial(), 2u);
  ASSERT_TRUE(out.has_contact());
  EXPECT_FLOAT_EQ(out.contact().y_mm(), 50.0f);
  EXPECT_TRUE(out.contact().onset());
  EXPECT_TRUE(out.contact().uncertainty_calibrated());
  link::ToProto(sink.Of(Message::Kind::kHeartbeat).back(), "forearm", 8, out);
  ASSERT_TRUE(out.has_heartbeat());
  EXPECT_EQ(out.heartbeat().frames(), 2u);
  EXPECT_EQ(out.heartbeat().baseline_state(), v1::BASELINE_STATE_TRACKING);
  std::map<int, std::uint64_t> rejected;
  for (const auto& r : out.heartbeat().rejected()) rejected[r.reason()] = r.frames();
  EXPECT_EQ(rejected[v1::FRAME_REJECT_REASON_OUT_OF_RANGE], 1u);
  EXPECT_EQ(rejected[v1::FRAME_REJECT_REASON_WRONG_PEAK_COUNT], 1u);
  EXPECT_EQ(rejected.size(), 2u);
}

// Re-tare requests (docs/safety.md "Re-tare"): answered with the request's id; without a map refused no_map;
// a second while one runs busy (the first goes on); a disconnect ends it interrupted; the health is untouched.
TEST_F(MonitorTest, RetareRequestsAreAnsweredWithTheirIdAndOutcome) {
  auto retares = [&] { return sink.Of(Message::Kind::kRetare); };
  {
    link::Monitor m(pipe, Config(), At(0));
    m.OnConnected(At(0), sink);
    Feed(m, 0, 5);
    m.RequestRetare(7, At(6 * kMs), sink);  // never enabled: no map
    ASSERT_EQ(retares().size(), 1u);
    EXPECT_EQ(retares()[0].retare.request_id, 7u);
    EXPECT_EQ(retares()[0].retare.outcome, decode::RetareOutcome::kNoMap);
    EXPECT_TRUE(retares()[0].critical());
  }
  sink.got.clear();
  const v1::DecoderModel model = decode::LoadModel(RUFFINI_SOURCE_DIR "/config/models/cobot-forearm_a.rmodel");
  ASSERT_TRUE(model.has_response());
  link::Monitor m(pipe, Config(), At(0));
  decode::RetareConfig rc;
  rc.min_force_n = 0.75;
  m.EnableRetare(&model.response(), rc);
  m.OnConnected(At(0), sink);
  std::int64_t t = Feed(m, 0, 5);
  const bool healthy = m.health().healthy;
  m.RequestRetare(1, At(t), sink);
  m.RequestRetare(2, At(t), sink);
  ASSERT_EQ(retares().size(), 1u);
  EXPECT_EQ(retares()[0].retare.request_id, 2u);
  EXPECT_EQ(retares()[0].retare.outcome, decode::RetareOutcome::kBusy);
  t = Feed(m, t, 10, 6);
  EXPECT_EQ(m.health().healthy, healthy);
  m.OnDisconnected(At(t), sink);
  ASSERT_EQ(retares().size(), 2u);
  EXPECT_EQ(retares()[1].retare.request_id, 1u);
  EXPECT_EQ(retares()[1].retare.outcome, decode::RetareOutcome::kInterrupted);
  EXPECT_FLOAT_EQ(retares()[1].retare.min_force_n, 0.75f);
  EXPECT_EQ(m.retares()[static_cast<std::size_t>(decode::RetareOutcome::kBusy)], 1u);
  EXPECT_EQ(m.retares()[static_cast<std::size_t>(decode::RetareOutcome::kInterrupted)], 1u);
  // On the wire: the proto's outcome numbers are decode's + 1.
  v1::PatchMessage out;
  link::ToProto(retares()[1], "forearm", 9, out);
  ASSERT_TRUE(out.has_retare_result());
  EXPECT_EQ(out.retare_result().request_id(), 1u);
  EXPECT_EQ(out.retare_result().outcome(), v1::RETARE_OUTCOME_INTERRUPTED);
  for (std::size_t i = 0; i < decode::kRetareOutcomeCount; ++i) {
    std::string name(decode::RetareOutcomeName(static_cast<decode::RetareOutcome>(i)));
    for (char& ch : name) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
    EXPECT_EQ(v1::RetareOutcome_Name(static_cast<v1::RetareOutcome>(i + 1)), "RETARE_OUTCOME_" + name);
  }
}

TEST(RejectCodes, MatchTheProtoEnum) {
  for (std::size_t i = 1; i < decode::kReasonCount; ++i) {
    const auto code = link::RejectCode(static_cast<decode::Reason>(i));
    ASSERT_TRUE(v1::FrameRejectReason_IsValid(static_cast<int>(code)));
    // The proto's name ends with the pipeline's reason name in upper case.
    std::string upper(decode::ReasonName(static_cast<decode::Reason>(i)));
    for (auto& ch : upper) ch = static_cast<char>(std::toupper(ch));
    EXPECT_TRUE(v1::FrameRejectReason_Name(static_cast<v1::FrameRejectReason>(code)).ends_with(upper)) << upper;
  }
  for (std::size_t i = 1; i < ingest::kReasonCount; ++i) {
    const auto r = static_cast<ingest::Reason>(i);
    const auto code = link::RejectCode(r);
    EXPECT_TRUE(v1::FrameRejectReason_IsValid(static_cast<int>(code)));
    EXPECT_GE(code, 32u);
  }
  for (std::size_t i = 0; i < link::kFaultCodeCount; ++i) {
    EXPECT_TRUE(v1::PatchFaultCode_IsValid(static_cast<int>(i)));
  }
}

TEST(DecoderChoice, NamesTheOfferedConfigurations) {
  const auto model = decode::LoadModel(std::string(RUFFINI_SOURCE_DIR) + "/config/models/forearm.rmodel");
  EXPECT_EQ(link::ParseDecoderChoice("paper-float", model).grid, -1);
  EXPECT_TRUE(link::ParseDecoderChoice("paper-double", model).use_double);
  const auto sg = link::ParseDecoderChoice(model.location(0).grid().name() + "-float", model);
  EXPECT_EQ(sg.grid, 0);
  try {
    link::ParseDecoderChoice("nope-float", model);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("paper-double"), std::string::npos) << e.what();
  }
  EXPECT_THROW(link::ParseDecoderChoice("paper", model), InputError);
  EXPECT_THROW(link::ParseDecoderChoice("inversion-float", model), InputError);
  // Every choice builds a pipeline for the shipped model.
  const auto scene = twin::LoadScene(std::string(RUFFINI_SOURCE_DIR) + "/config/scenes/forearm.yaml");
  decode::PipelineConfig pc;
  pc.baseline = decode::BaselineFor(model, 1000.0);
  for (const char* name : {"paper-float", "paper-double"}) {
    EXPECT_NE(link::MakePipeline(model, scene.Patch().spec, pc, link::ParseDecoderChoice(name, model)), nullptr);
  }
}

}  // namespace
