#!/usr/bin/python3
"""The Ruffini safety contract from Python: subscribe to the aggregator's WatchSafety, print every change
of state and every decision, and halt on anything but a live stream of clean CLEAR states.

The rules are the C++ client's (services/controller/safety_client.h, docs/controller.md); Monitor below is
its SafetyMonitor, tested on its own. The robot may move only after three CLEAR states in a row of one
aggregator run, each within the watchdog (30 ms) of the state before, on a live stream, since the last
halt of any kind. It halts (and the count starts again) on:
  STOP, FAULT or any other value (UNKNOWN_STATE); a state for another robot, an empty name included
  (WRONG_ROBOT, the state is refused and counted); a CLEAR whose stop_epoch is not the epoch of the state
  before it in the same run (MISSED_STOP: a STOP and its reset happened in states this subscriber skipped);
  a CLEAR from a new aggregator run (NEW_RUN: aggregator_run_id or aggregator_start_t_ns changed);
  silence longer than the watchdog (NO_HEARTBEAT); the stream ending (STREAM_ENDED) or not opening
  (CONNECT_FAILED).
Before those rules every state passes the safety layer's checks (docs/safety-channel.md), as in the C++
client: the CRC-32 over its safety fields (safety_crc32, the canonical layout of patches/channel/src/crc.cpp),
the robot (addressing), the aggregator run of the stream (insertion), the sequence (a repeat, an older seq, or
an older seq of the same run on a new stream, is discarded; a gap is counted and tolerated) and freshness
(the age against the offset between the aggregator's steady clock, sender_steady_ns, and this host's, learned
per stream: older than --freshness-budget-ms is discarded, LATE). A discarded state halts (LINK_ERROR,
WRONG_ROBOT or LATE) and is no heartbeat. Two such errors within --link-error-window-s latch: no state is used
until the operator acknowledges with SIGUSR1 (`kill -USR1 PID`, an "ACK LINK_ERRORS" line).
A real controller would command its robot where this prints HALT and CLEAR.

The channel sends HTTP/2 keepalive pings every 1 s (a dead peer is found in about 2 s); a stream silent for
0.5 s is cancelled and the channel made again, so the next call dials a new connection.

Needs Debian's python3-grpcio and python3-protobuf, and the stubs the build generates from
proto/ruffini/v1/ (protoc with /usr/bin/grpc_python_plugin, into build/<preset>/services/controller/python):

  /usr/bin/python3 services/controller/python/watch_safety.py --aggregator 127.0.0.1:50051 --robot cobot \\
      --stubs build/release/services/controller/python --insecure

Exit codes: 0 after --duration-s or on Ctrl-C, 1 when the stubs or grpc cannot be imported, 2 usage.
"""
import argparse
import collections
import os
import queue
import signal
import struct
import sys
import threading
import time
import zlib

CLEAR, STOP, FAULT = 1, 2, 3  # SafetyState.State values (aggregator.proto)
LINK_REASONS = {"NO_HEARTBEAT", "STREAM_ENDED", "CONNECT_FAILED"}
STATE_REASONS = {"STOP", "FAULT", "UNKNOWN_STATE", "MISSED_STOP", "NEW_RUN"}


def safety_crc32(s):
    """The CRC-32 over a SafetyState's safety fields (everything but safety_crc32 and cause.message), in the
    canonical layout of patches/channel/src/crc.cpp (docs/safety-channel.md): integers little-endian at their
    proto width, enums 4 bytes, floats and doubles their IEEE 754 bytes, strings a 4-byte length then UTF-8.
    CRC-32/IEEE 802.3, which is zlib's."""
    def u64(v): return struct.pack("<Q", v & 0xFFFFFFFFFFFFFFFF)
    def i64(v): return struct.pack("<q", v)
    def i32(v): return struct.pack("<i", v)
    def f32(v): return struct.pack("<f", v)
    def f64(v): return struct.pack("<d", v)
    def text(v):
        b = v.encode()
        return struct.pack("<I", len(b)) + b
    k = s.cause
    data = b"".join((
        i32(s.state), u64(s.stop_epoch), u64(s.seq), i64(s.changed_t_ns), i64(s.published_t_ns),
        i64(s.aggregator_start_t_ns), u64(s.aggregator_run_id), text(s.robot_name), i64(s.sender_steady_ns),
        i32(k.kind), text(k.patch_id), text(k.body_region), text(k.link), f32(k.force_n), f32(k.threshold_n),
        f64(k.p_bc_m.x), f64(k.p_bc_m.y), f64(k.p_bc_m.z), i32(k.patch_fault), i64(k.t_ns)))
    return zlib.crc32(data)


class StateLink:
    """The safety layer's receiver for one WatchSafety stream (ruffini::channel::StateLinkCheck): receive()
    returns (error, use, age_ns), error None or one of "corruption", "addressing", "insertion", "repetition",
    "incorrect_sequence", "loss" (tolerated: use is True), "delay"."""

    def __init__(self, robot, budget_ns, max_drift_ppm=200.0):
        self.robot, self.budget_ns, self.max_drift_ppm = robot, budget_ns, max_drift_ppm
        self.run_id = 0  # learned from the stream's first good state
        self.last_seq = 0
        self.offset_ns = None  # this host's steady clock minus the aggregator's: the fastest state, with creep
        self.last_arrival_ns = 0

    def age(self, sent_ns, arrival_ns):
        """How much longer this state took than the fastest one of the stream (the first has age 0); the
        learned offset may creep up by max_drift_ppm of the time elapsed (two steady clocks' rates differ)."""
        offset = arrival_ns - sent_ns
        if self.offset_ns is None:
            self.offset_ns, self.last_arrival_ns = offset, arrival_ns
            return 0
        creep = int(max(0, arrival_ns - self.last_arrival_ns) * self.max_drift_ppm * 1e-6)
        self.last_arrival_ns = max(self.last_arrival_ns, arrival_ns)
        self.offset_ns = min(self.offset_ns + creep, offset)
        return offset - self.offset_ns

    def receive(self, s, arrival_ns):
        if safety_crc32(s) != s.safety_crc32:
            return "corruption", False, 0
        if s.robot_name != self.robot:
            return "addressing", False, 0
        if s.aggregator_run_id == 0:
            return "insertion", False, 0
        if self.run_id == 0:
            self.run_id = s.aggregator_run_id
        elif s.aggregator_run_id != self.run_id:
            return "insertion", False, 0
        error = None
        if self.last_seq == 0 and s.seq != 0:  # a subscriber joins the shared counter anywhere
            self.last_seq = s.seq
        elif s.seq == 0 or s.seq < self.last_seq:
            return "incorrect_sequence", False, 0
        elif s.seq == self.last_seq:
            return "repetition", False, 0
        else:
            if s.seq > self.last_seq + 1:
                error = "loss"  # tolerable: states are latest-value, the watchdog bounds the silence
            self.last_seq = s.seq
        age = self.age(s.sender_steady_ns, arrival_ns)
        if age > self.budget_ns:
            return "delay", False, age
        return error, True, age


class Monitor:
    """The client's state machine, with no threads and no clock of its own (every call carries the time,
    in seconds on a monotonic clock). Each on_* returns None or a decision: ("HALT", reason, detail, state)
    or ("CLEAR", None, "", state)."""

    def __init__(self, robot, timeout_s=0.030, states_before_clear=3, now=0.0, freshness_budget_s=0.020,
                 error_limit=2, error_window_s=60.0):
        if not robot:
            raise ValueError("the robot's name is required")
        if not 1 <= error_limit <= 8 or not error_window_s > 0 or not freshness_budget_s > 0:
            raise ValueError("the error-rate limit must lie in 1..8, its window and the freshness budget above 0")
        self.robot, self.timeout_s, self.n_clear = robot, timeout_s, max(1, states_before_clear)
        self.budget_ns = int(freshness_budget_s * 1e9)
        self.error_limit, self.error_window_ns = error_limit, int(error_window_s * 1e9)
        self.error_times = collections.deque(maxlen=error_limit)  # the newest errors (error-rate rule)
        self.link_latched = False  # the error-rate limit was reached: no state is used until acknowledged
        self.halt_latched = False  # link_latched when the current halt was told (a new latch is told)
        self.acknowledgements = 0
        self.link_errors = collections.Counter()  # the safety layer's detections by error (loss included)
        self.link = StateLink(robot, self.budget_ns)
        self.seq_run = self.seq_last = 0  # the newest seq accepted from an aggregator run, on any stream
        self.halted, self.reason = True, "NOT_STARTED"
        self.halt_key = None  # (epoch, run) of the state behind the current halt
        self.stream_open = self.stream_has_state = False
        self.last_evidence = now  # the last accepted state on this stream, or the stream's start
        self.streak = 0
        self.run = self.epoch = None  # of the newest accepted state
        self.last_state = None
        self.discard_reasons = set()
        self.counts = collections.Counter()  # received states by value; "refused" for discarded ones

    @staticmethod
    def run_of(s):
        return (s.aggregator_run_id, s.aggregator_start_t_ns)

    def _halt(self, reason, detail, now, state=None):
        self.streak = 0  # every halt, told or not, ends the streak
        s = state if state is not None else self.last_state
        key = (s.stop_epoch, self.run_of(s)) if s is not None else None
        if (self.halted and reason == self.reason and self.link_latched == self.halt_latched
                and (reason not in STATE_REASONS or key == self.halt_key)):
            return None
        self.halted, self.reason, self.halt_key, self.halt_latched = True, reason, key, self.link_latched
        if self.link_latched:
            detail += " [latched: acknowledge with SIGUSR1]"
        return ("HALT", reason, detail, s)

    def check_state(self, s, arrival):
        """The safety layer's check of every received state (arrival in seconds on this host's monotonic
        clock), SafetyMonitor::CheckState in the C++ client: (True, None, "") or (False, halt_reason, detail)."""
        arrival_ns = int(round(arrival * 1e9))
        error, use, age = self.link.receive(s, arrival_ns)
        if use and s.aggregator_run_id == self.seq_run and s.seq < self.seq_last:
            # An older state of the same run on a new stream (a replay). The same seq is allowed: a new
            # subscription's first state repeats the one in force.
            error, use = "incorrect_sequence", False
        if error is not None:
            self.link_errors[error] += 1
        if error is not None and error != "loss":  # every error but a tolerated loss counts toward the latch
            self.error_times.append(arrival_ns)
            if len(self.error_times) == self.error_limit and arrival_ns - self.error_times[0] <= self.error_window_ns:
                self.link_latched = True
        if use and not self.link_latched:
            if s.aggregator_run_id != self.seq_run:
                self.seq_run, self.seq_last = s.aggregator_run_id, s.seq
            else:
                self.seq_last = max(self.seq_last, s.seq)
        if not use:
            if error == "addressing":
                return False, "WRONG_ROBOT", f"a state for robot '{s.robot_name}', not this controller's '{self.robot}'"
            if error == "delay":
                return False, "LATE", f"a state {age // 1000000} ms old (budget {self.budget_ns // 1000000} ms)"
            return False, "LINK_ERROR", f"the safety layer discarded a state: {error}"
        if self.link_latched:
            return False, "LINK_ERROR", "the error-rate limit was reached: no state is used until an operator acknowledges it"
        return True, None, ""

    def acknowledge_link_errors(self):
        """The operator's acknowledgement of the error-rate latch; True when one was held. The robot still
        needs three clean states."""
        was, self.link_latched = self.link_latched, False
        self.acknowledgements += was
        return was

    def on_stream_opened(self, now):
        self.stream_open, self.stream_has_state, self.last_evidence, self.streak = True, False, now, 0
        # A new stream learns the aggregator's clock offset anew; the latch and the run's newest seq are kept.
        self.link = StateLink(self.robot, self.budget_ns)

    def on_state(self, s, now):
        if not self.stream_open:
            self.on_stream_opened(now)
        self.counts[s.state] += 1
        ok, reason, detail = self.check_state(s, now)
        if not ok:
            self.counts["refused"] += 1
            self.discard_reasons.add(reason)
            return self._halt(reason, detail, now, s)
        run = self.run_of(s)
        new_run = self.run is not None and run != self.run
        gap = now - self.last_evidence
        late = gap > self.timeout_s  # a silence even if no watchdog tick saw it
        if late:
            self.streak = 0
        if self.run is None or new_run:
            self.epoch = None  # a restarted aggregator counts epochs from 1 again
        new_epoch = self.epoch is not None and s.stop_epoch != self.epoch
        self.run, self.epoch, self.last_state = run, s.stop_epoch, s
        self.stream_has_state, self.last_evidence = True, now
        event = self._on_accepted(s, new_run, new_epoch, late, now)
        if event is None and late:  # one decision per event: the state's, else the silence's
            return self._on_silence(gap, now)
        return event

    def _on_accepted(self, s, new_run, new_epoch, late, now):
        if s.state == CLEAR:
            if new_run:  # the streak starts after it: three clean states of the new run
                return self._halt("NEW_RUN", "CLEAR from a new aggregator run: clean states again", now)
            if new_epoch:
                return self._halt("MISSED_STOP", "CLEAR with a new stop_epoch: a stop and its reset were skipped", now)
            if not self.halted or late:  # a CLEAR that ends a silence is not clean: the streak starts after it
                return None
            self.streak += 1
            if self.streak < self.n_clear:
                return None
            self.halted, self.streak = False, 0
            return ("CLEAR", None, "", s)
        if s.state == STOP:
            return self._halt("STOP", "", now)
        if s.state == FAULT:
            return self._halt("FAULT", "", now)
        return self._halt("UNKNOWN_STATE", "treated as STOP", now)

    def on_stream_ended(self, detail, now):
        had_state = self.stream_has_state
        self.stream_open = self.stream_has_state = False
        if had_state:
            return self._halt("STREAM_ENDED", "stream ended: " + detail, now)
        return self._halt("CONNECT_FAILED", "no stream: " + detail, now)

    def silence(self, now):
        return now - self.last_evidence if self.stream_open else 0.0

    def on_tick(self, now):
        return self._on_silence(self.silence(now), now)

    def _on_silence(self, silence, now):
        if not self.stream_open or silence <= self.timeout_s:
            return None
        self.streak = 0  # the three-clean-states rule holds after this silence too
        if self.halted and (self.reason in LINK_REASONS or self.reason in self.discard_reasons):
            return None
        return self._halt("NO_HEARTBEAT", f"no state for {silence * 1000:.1f} ms "
                          f"(limit {self.timeout_s * 1000:.1f} ms)", now)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--aggregator", required=True, help="the aggregator's gRPC address, HOST:PORT")
    parser.add_argument("--robot", required=True, help="this robot's name, the scene's (e.g. cobot): states "
                        "for another robot (or naming none) are refused")
    parser.add_argument("--stubs", default="", help="folder holding the generated ruffini/v1/*_pb2*.py")
    parser.add_argument("--duration-s", type=float, default=0.0, help="stop after this long (0: until Ctrl-C)")
    parser.add_argument("--timeout-ms", type=float, default=30.0, help="halt when no state came for this long")
    parser.add_argument("--freshness-budget-ms", type=float, default=20.0,
                        help="discard (and halt LATE on) a state older than this (docs/safety-channel.md)")
    parser.add_argument("--link-error-limit", type=int, default=2, choices=range(1, 9), metavar="1..8",
                        help="safety-layer errors within the window that latch the halt until SIGUSR1")
    parser.add_argument("--link-error-window-s", type=float, default=60.0, help="the error-rate rule's window")
    parser.add_argument("--subscriber", default="watch_safety.py", help="the name given to the aggregator")
    tls = parser.add_mutually_exclusive_group(required=True)
    tls.add_argument("--tls-dir", help="mutual TLS: ca.crt and this client's controller.crt / controller.key "
                     "(deploy/tls/make-dev-ca.sh), as the C++ services read them")
    tls.add_argument("--insecure", action="store_true", help="plaintext (an --insecure aggregator)")
    args = parser.parse_args()
    if not args.robot:
        parser.error("--robot must name the robot")

    if args.stubs:
        sys.path.insert(0, args.stubs)
    try:
        import grpc
        from ruffini.v1 import aggregator_pb2, aggregator_pb2_grpc
    except ImportError as e:
        print(f"watch_safety.py: cannot import grpc or the Ruffini stubs ({e}); install python3-grpcio and "
              f"python3-protobuf, build the stubs, and pass --stubs", file=sys.stderr)
        return 1

    State = aggregator_pb2.SafetyState
    Kind = aggregator_pb2.SafetyCause.Kind
    t0 = time.monotonic()
    lock = threading.Lock()  # the monitor; never held while printing
    try:
        monitor = Monitor(args.robot, args.timeout_ms / 1000.0, now=t0, freshness_budget_s=args.freshness_budget_ms / 1000.0,
                          error_limit=args.link_error_limit, error_window_s=args.link_error_window_s)
    except ValueError as e:
        parser.error(str(e))
    lines = queue.Queue()  # printed by the main thread, in the order the decisions were made
    gaps = {"max_s": 0.0}
    done = threading.Event()
    cancel_after_s = 0.5
    current = {"call": None, "cancelled_for_silence": False}

    def describe(s):
        name = State.State.Name(s.state) if s.state in State.State.values() else f"UNKNOWN({s.state})"
        name = name.replace("STATE_", "")
        text = f"{name} epoch {s.stop_epoch}"
        if s.state != State.STATE_CLEAR and s.HasField("cause"):
            text += f" cause {Kind.Name(s.cause.kind)}"
            if s.cause.patch_id:
                text += f" {s.cause.patch_id}"
            if s.cause.kind == aggregator_pb2.SafetyCause.KIND_CONTACT:
                text += f" {s.cause.force_n:.2f} N"
        return text

    def tell(event, now):  # with the lock held: queue the decision's line
        if event is None:
            return
        kind, reason, detail, s = event
        if kind == "CLEAR":
            text = "CLEAR: may move"
        else:
            text = f"HALT {reason}: " + (describe(s) if reason in ("STOP", "FAULT", "UNKNOWN_STATE") and s is not None
                                         else detail)
        lines.put(f"t={now - t0:.3f} s {text}")

    # Reconnect quickly (gRPC's default backoff is 1 s growing to 120 s), keepalive pings every 1 s even
    # without calls or data, and a subchannel pool of its own so a new channel dials a new connection.
    options = [("grpc.initial_reconnect_backoff_ms", 100), ("grpc.min_reconnect_backoff_ms", 100),
               ("grpc.max_reconnect_backoff_ms", 1000), ("grpc.keepalive_time_ms", 1000),
               ("grpc.keepalive_timeout_ms", 1000), ("grpc.keepalive_permit_without_calls", 1),
               ("grpc.http2.max_pings_without_data", 0), ("grpc.use_local_subchannel_pool", 1)]
    if args.insecure:
        print("--insecure: PLAINTEXT gRPC, no TLS and no identity", file=sys.stderr, flush=True)

        def make_channel():
            return grpc.insecure_channel(args.aggregator, options=options)
    else:
        def read(name):
            with open(os.path.join(args.tls_dir, name), "rb") as f:
                return f.read()
        own = "controller" if os.path.exists(os.path.join(args.tls_dir, "controller.crt")) else "tls"
        creds = grpc.ssl_channel_credentials(root_certificates=read("ca.crt"), private_key=read(own + ".key"),
                                             certificate_chain=read(own + ".crt"))

        def make_channel():
            return grpc.secure_channel(args.aggregator, creds, options=options)

    def reader():
        pause, channel = 0.1, None
        remake = True
        while not done.is_set():
            if remake:
                if channel is not None:
                    channel.close()
                channel = make_channel()
                stub = aggregator_pb2_grpc.AggregatorStub(channel)
            call = stub.WatchSafety(aggregator_pb2.WatchSafetyRequest(subscriber=args.subscriber))
            with lock:
                current["call"], current["cancelled_for_silence"] = call, False
                monitor.on_stream_opened(time.monotonic())
            got_any, previous, code = False, None, "OK"
            try:
                for s in call:
                    now = time.monotonic()
                    with lock:
                        if got_any:
                            gaps["max_s"] = max(gaps["max_s"], now - monitor.last_evidence)
                        got_any = True
                        refused = monitor.counts["refused"]
                        event = monitor.on_state(s, now)
                        key = (s.state, s.stop_epoch, s.aggregator_run_id, s.aggregator_start_t_ns, s.robot_name)
                        if monitor.counts["refused"] == refused and key != previous:  # only states it accepted
                            lines.put(f"t={now - t0:.3f} s {describe(s)}")
                            previous = key
                        tell(event, now)
            except grpc.RpcError as e:
                code = e.code().name
            if done.is_set():
                break
            with lock:
                current["call"] = None
                now = time.monotonic()
                tell(monitor.on_stream_ended(code, now), now)
                remake = current["cancelled_for_silence"] or code == "UNAVAILABLE"
            pause = 0.1 if got_any else min(pause * 2, 1.0)
            done.wait(pause)
        if channel is not None:
            channel.close()

    def watchdog():
        while not done.wait(0.001):
            with lock:
                now = time.monotonic()
                tell(monitor.on_tick(now), now)
                call = current["call"]
                if call is not None and monitor.silence(now) > cancel_after_s and not current["cancelled_for_silence"]:
                    current["cancelled_for_silence"] = True
                    call.cancel()

    ack = threading.Event()  # SIGUSR1: the operator acknowledges the error-rate latch (handled below)

    def acknowledge():
        with lock:
            now = time.monotonic()
            if monitor.acknowledge_link_errors():
                text = ("ACK LINK_ERRORS: the operator acknowledged the error-rate latch (SIGUSR1); states are used "
                        "again, three clean CLEARs release")
            else:
                text = "ACK LINK_ERRORS: nothing to acknowledge (SIGUSR1; no error-rate latch held)"
            lines.put(f"t={now - t0:.3f} s {text}")

    signal.signal(signal.SIGINT, lambda *_: done.set())
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    signal.signal(signal.SIGUSR1, lambda *_: ack.set())
    threads = [threading.Thread(target=reader, daemon=True), threading.Thread(target=watchdog, daemon=True)]
    for t in threads:
        t.start()
    deadline = t0 + args.duration_s if args.duration_s > 0 else None

    def flush():
        while True:
            try:
                print(lines.get_nowait(), flush=True)
            except queue.Empty:
                return

    while not done.is_set():
        if deadline is not None and time.monotonic() >= deadline:
            done.set()
            break
        if ack.is_set():
            ack.clear()
            acknowledge()
        try:
            print(lines.get(timeout=0.05), flush=True)
        except queue.Empty:
            pass
    with lock:
        call = current["call"]
    if call is not None:
        call.cancel()
    for t in threads:
        t.join(timeout=2)
    flush()
    counts = monitor.counts
    by_state = ", ".join(f"{State.State.Name(k).replace('STATE_', '') if k in State.State.values() else k} {v}"
                         for k, v in sorted(((k, v) for k, v in counts.items() if k != "refused"), key=str))
    print(f"received {sum(v for k, v in counts.items() if k != 'refused')} states ({by_state or 'none'}), "
          f"refused {counts['refused']}, longest gap {gaps['max_s'] * 1000:.1f} ms, halted at exit: {monitor.halted}",
          flush=True)
    errors = ", ".join(f"{k} {v}" for k, v in sorted(monitor.link_errors.items())) or "none"
    print(f"link errors: {errors}; error-rate latch {'held' if monitor.link_latched else 'not held'}, "
          f"acknowledged {monitor.acknowledgements}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
