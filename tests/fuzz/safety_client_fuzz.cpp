// libFuzzer driver for the controller client's state handling (SafetyMonitor, services/controller). The bytes
// are a sequence of events, each an opcode byte and its arguments: a stream opening or ending, a watchdog
// tick, or a SafetyState (state value, including values outside the enum, epoch, run, robot name, seq), each
// after a time step of 0 to 63.75 ms (around the 30 ms watchdog). Beyond "no crash, no sanitizer report", the
// driver keeps its own count of clean states, from the contract rather than the code, and checks after every
// event:
//   - a clear decision comes only after at least three clean states since the last halt decision and the
//     last silence: a CLEAR for this robot, each within the watchdog of the accepted state before it (or of
//     the stream's start), on one stream, of the run and epoch of the accepted state before it;
//   - never "may move" right after a STOP, FAULT, unknown value, a state for another robot, or a CLEAR of a
//     new run or a new epoch;
//   - never "may move" while the open stream has been silent for longer than the watchdog after a tick;
//   - halted() and Stats().halted agree, and the counters add up.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "ruffini/channel/crc.h"
#include "safety_client.h"

namespace rc = ruffini::controller;
namespace v1 = ruffini::v1;
using namespace std::chrono_literals;

namespace {

void Check(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "property violated: %s\n", what);
    std::abort();
  }
}

struct Reader {
  const std::uint8_t* p;
  std::size_t n;
  std::uint8_t Next() {
    if (n == 0) return 0;
    --n;
    return *p++;
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Reader in{data, size};
  const auto timeout = std::chrono::nanoseconds(30ms);
  rc::SteadyClock::time_point t{std::chrono::seconds(1000)};
  rc::SafetyMonitor m({.robot_name = "cobot"}, t);

  int clean = 0;               // clean states since the last halt decision or silence (the contract's count)
  bool stream_open = false;
  rc::SteadyClock::time_point last_evidence = t;  // last accepted state on the stream, or its start
  bool have_prev = false;      // an accepted state of the current run and epoch was seen (for "same run, epoch")
  std::uint64_t prev_run = 0;
  std::int64_t prev_start = 0;
  std::uint64_t prev_epoch = 0;
  std::uint64_t seq = 0;
  std::uint64_t halts_told = 0, clears_told = 0;

  while (in.n > 0) {
    const std::uint8_t op = in.Next();
    t += std::chrono::microseconds(250) * in.Next();  // 0 .. 63.75 ms
    rc::SafetyMonitor::Action a;
    bool clean_state = false, bad_state = false;
    switch (op % 5) {
      case 0:
        a = m.OnStreamOpened(t);
        stream_open = true;
        last_evidence = t;
        clean = 0;
        break;
      case 1:
        a = m.OnStreamEnded("fuzz", t);
        stream_open = false;
        clean = 0;
        Check(m.halted(), "may move after the stream ended");
        break;
      case 2: {
        const bool silent = stream_open && t - last_evidence > timeout;
        a = m.OnTick(t);
        if (silent) {
          clean = 0;
          Check(m.halted(), "may move after a silence longer than the watchdog");
        }
        break;
      }
      default: {
        const std::uint8_t kind = in.Next(), epoch = in.Next(), who = in.Next(), step = in.Next();
        v1::SafetyState s;
        // Mostly the enum's values, sometimes anything (the wire allows any int32).
        const int value = kind < 200 ? kind % 4 : static_cast<int>(static_cast<std::int8_t>(kind)) * 37;
        s.GetReflection()->SetEnumValue(&s, s.GetDescriptor()->FindFieldByName("state"), value);
        s.set_stop_epoch(epoch % 4);
        const std::uint64_t run = who % 3;
        s.set_aggregator_run_id(0x1000 + run);
        s.set_aggregator_start_t_ns(static_cast<std::int64_t>(run) * 1000 + ((who & 0x80) ? 1 : 0));
        s.set_robot_name((who & 0x60) == 0x60 ? "other" : ((who & 0x60) == 0x40 ? "" : "cobot"));
        seq += step % 5;  // repeats, gaps
        s.set_seq(seq);
        if (!stream_open) {  // the monitor opens a stream for a driver that did not say so
          stream_open = true;
          last_evidence = t;
          clean = 0;
        }
        // The safety layer: sent now (fresh), sometimes a few ms to seconds old, sealed; sometimes corrupted.
        const std::uint8_t link = in.Next();
        const auto sent = t - std::chrono::milliseconds((link & 0x0F) == 0x0F ? 25 * (link >> 4) : 0);
        s.set_sender_steady_ns(std::chrono::duration_cast<std::chrono::nanoseconds>(sent.time_since_epoch()).count());
        ruffini::channel::Seal(s);
        if ((link & 0xF0) == 0xF0) s.set_safety_crc32(s.safety_crc32() ^ (1u << (link & 0x1F)));
        const bool ours = s.robot_name() == "cobot";
        const bool same = have_prev && s.aggregator_run_id() == prev_run &&
                          s.aggregator_start_t_ns() == prev_start && s.stop_epoch() == prev_epoch;
        const bool in_time = t - last_evidence <= timeout;
        const std::uint64_t discarded_before = m.Stats(t).discarded;
        a = m.OnState(s, t);
        const bool discarded = m.Stats(t).discarded > discarded_before;
        const bool clear = value == v1::SafetyState::STATE_CLEAR;
        if (!ours || discarded) {
          // Another robot's state, or one the safety layer discarded (corrupt, repeated, older, another run
          // within the stream, late): it halts and is never clean.
          bad_state = true;
        } else {
          // A CLEAR of another run, or another epoch of the same run, is a restart or a missed stop: it halts.
          if (!clear || (have_prev && !same)) bad_state = true;
          clean_state = clear && (!have_prev || same) && in_time;
          have_prev = true;
          prev_run = s.aggregator_run_id();
          prev_start = s.aggregator_start_t_ns();
          prev_epoch = s.stop_epoch();
          last_evidence = t;
        }
        if (bad_state) {
          clean = 0;
          Check(m.halted(), "may move after a STOP, FAULT, unknown state, another robot's state, or a CLEAR of a new run or epoch");
        } else if (clean_state) {
          ++clean;
        } else {
          clean = 0;  // a CLEAR that ends a silence: not within the watchdog of the state before
        }
        break;
      }
    }
    if (a.kind == rc::SafetyMonitor::Action::Kind::kHalt) {
      ++halts_told;
      clean = 0;
      Check(m.halted(), "a halt decision left the monitor moving");
    } else if (a.kind == rc::SafetyMonitor::Action::Kind::kClear) {
      ++clears_told;
      Check(clean >= 3, "released without three clean states after a halt");
      Check(!m.halted(), "a clear decision left the monitor halted");
    }
    const rc::SafetyStats st = m.Stats(t);
    Check(st.halted == m.halted(), "Stats().halted disagrees with halted()");
    Check(st.clears == clears_told, "clears counted differently from clear decisions");
    std::uint64_t halts = 0;
    for (auto h : st.halts) halts += h;
    Check(halts == halts_told, "halts counted differently from halt decisions");
    Check(st.discarded <= st.states, "more states discarded than received");
  }
  return 0;
}
