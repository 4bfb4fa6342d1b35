#!/usr/bin/python3
"""The Python example (services/controller/python/watch_safety.py) keeps the C++ client's rules: its Monitor
on its own with an injected clock, then the whole script against a scripted grpcio aggregator
(scripted_aggregator.py) in this process. Prints "python example checks passed" when every check held.

  python_example_test.py STUBS_DIR REPO_DIR WORK_DIR
"""
import os
import re
import signal
import subprocess
import sys
import threading
import time

stubs, repo, work = sys.argv[1], sys.argv[2], sys.argv[3]
sys.path.insert(0, stubs)
sys.path.insert(0, os.path.join(repo, "services/controller/python"))
sys.path.insert(0, os.path.join(repo, "tests/controller"))
import grpc  # noqa: E402
from ruffini.v1 import aggregator_pb2 as pb, aggregator_pb2_grpc as pb_grpc  # noqa: E402
import scripted_aggregator  # noqa: E402
import watch_safety  # noqa: E402

failures = []


def check(ok, what):
    print(("ok   " if ok else "FAIL ") + what, flush=True)
    if not ok:
        failures.append(what)


# --- The Monitor alone (deterministic) ---------------------------------------------------------------------

# The CRC's canonical layout: the C++ test vector (tests/channel/crc_test.cpp, computed by crc_oracle.py).
sys.path.insert(0, os.path.join(repo, "tests/channel"))
import crc_oracle  # noqa: E402

vector = pb.SafetyState(state=2, stop_epoch=3, seq=42, changed_t_ns=100, published_t_ns=200, aggregator_start_t_ns=50,
                        aggregator_run_id=0x1122334455667788, robot_name="cobot", sender_steady_ns=123456789)
vector.cause.kind, vector.cause.patch_id, vector.cause.body_region = 1, "forearm_a", "forearm"
vector.cause.link, vector.cause.force_n, vector.cause.threshold_n = "forearm_link", 3.0, 1.5
vector.cause.p_bc_m.x, vector.cause.p_bc_m.y, vector.cause.p_bc_m.z, vector.cause.t_ns = 0.1, -0.2, 0.3, 99
vector.cause.message = "free text is not covered"
crc = watch_safety.safety_crc32(vector)
check(crc == crc_oracle.EXPECTED["state"], f"crc: the SafetyState test vector 0x{crc:08X} (C++: 0x{crc_oracle.EXPECTED['state']:08X})")


class Feed:
    """The aggregator's side: states of one run with seq counting up, stamped with the sender's clock (the
    test's clock: offset 0) and sealed."""

    def __init__(self, m, run=1):
        self.m, self.run, self.seq = m, run, 0

    def state(self, kind=1, epoch=1, robot="cobot", run=None, seq=None, sent=None, t=0.0):
        self.seq = self.seq + 1 if seq is None else seq
        run = self.run if run is None else run
        s = pb.SafetyState(state=kind, stop_epoch=epoch, seq=self.seq, aggregator_run_id=run,
                           aggregator_start_t_ns=run, robot_name=robot,
                           sender_steady_ns=int(round((t if sent is None else sent) * 1e9)))
        s.safety_crc32 = watch_safety.safety_crc32(s)
        return s

    def __call__(self, t, **kw):
        return self.m.on_state(self.state(t=t, **kw), t)


def fresh(**kw):
    m = watch_safety.Monitor("cobot", 0.030, now=0.0, **kw)
    m.on_stream_opened(0.0)
    return m, Feed(m)


def clear_up(feed, t, epoch=1):
    for _ in range(10):
        t += 0.010
        e = feed(t, epoch=epoch)
        if e and e[0] == "CLEAR":
            return t
    check(False, "never cleared")
    return t


m, feed = fresh()
t = clear_up(feed, 0.0)
check(not m.halted, "monitor: three CLEARs release")
e = feed(t + 0.010, epoch=2)
check(e is not None and e[1] == "MISSED_STOP", f"monitor: a CLEAR under a new epoch is a missed stop ({e and e[:2]})")

m, feed = fresh()
t = clear_up(feed, 0.0)
e = m.on_tick(t + 0.031)
check(e is not None and e[1] == "NO_HEARTBEAT", "monitor: 31 ms of silence halts")
released = False
for i in range(6):  # CLEARs one second apart, the watchdog ticking in between
    t += 1.0
    e = feed(t)
    released |= e is not None and e[0] == "CLEAR"
    m.on_tick(t + 0.031)
check(not released and m.halted, "monitor: after a watchdog halt, CLEARs a second apart never release")
t += 1.0
events = [feed(t + k * 0.010) for k in range(4)]
check(events[2] is None and events[3] is not None and events[3][0] == "CLEAR",
      "monitor: then three within the watchdog after the late one release")

m, feed = fresh()
t = clear_up(feed, 0.0)
e = feed(t + 0.010, run=2)
check(e is not None and e[1] == "LINK_ERROR" and m.link_errors["insertion"] == 1,
      f"monitor: another run's state within a stream is an insertion ({e and e[:2]})")
m.on_stream_ended("UNAVAILABLE", t + 0.011)
m.on_stream_opened(t + 0.012)
feed2 = Feed(m, run=2)
e = feed2(t + 0.020)
check(e is not None and e[1] == "NEW_RUN", f"monitor: a CLEAR of a new run on a new stream halts NEW_RUN ({e and e[:2]})")
e2, e3, e4 = feed2(t + 0.030), feed2(t + 0.040), feed2(t + 0.050)
check(e2 is None and e3 is None and e4 is not None and e4[0] == "CLEAR",
      "monitor: released by three clean states of the new run after the halt")

m, feed = fresh()
t = 0.0
released = False
for robot in ["other", ""] * 10:
    t += 0.010
    e = feed(t, robot=robot)
    released |= e is not None and e[0] == "CLEAR"
check(not released and m.reason == "WRONG_ROBOT" and m.counts["refused"] == 20 and m.link_errors["addressing"] == 20,
      f"monitor: states for another robot (or none) are refused and counted ({m.reason}, {m.counts['refused']})")
try:
    watch_safety.Monitor("", 0.030)
    check(False, "monitor: an empty robot name is refused")
except ValueError:
    check(True, "monitor: an empty robot name is refused")

# The safety layer, one error at a time (each once: below the error-rate limit), then the latch.
m, feed = fresh()
t = clear_up(feed, 0.0)
bad = feed.state(t=t + 0.010)
bad.state = 2  # flipped after sealing: it reads STOP, but the CRC says otherwise
e = m.on_state(bad, t + 0.010)
check(e is not None and e[1] == "LINK_ERROR" and "corruption" in e[2] and m.link_errors["corruption"] == 1,
      f"monitor: a corrupted state is discarded and halts LINK_ERROR ({e and e[1:3]})")
t = clear_up(feed, t + 0.010)
check(not m.halted and not m.link_latched, "monitor: one error does not latch: three clean states release")

m, feed = fresh()
t = clear_up(feed, 0.0)
e = feed(t + 0.010, seq=feed.seq)
check(e is not None and e[1] == "LINK_ERROR" and m.link_errors["repetition"] == 1, f"monitor: a repeated seq ({e and e[1:3]})")

m, feed = fresh()
t = clear_up(feed, 0.0)
e = feed(t + 0.010, seq=feed.seq - 1)
check(e is not None and e[1] == "LINK_ERROR" and m.link_errors["incorrect_sequence"] == 1,
      f"monitor: an older seq ({e and e[1:3]})")

m, feed = fresh()
t = clear_up(feed, 0.0)
e = feed(t + 0.010, seq=feed.seq + 5)
check(e is None and not m.halted and m.link_errors["loss"] == 1, "monitor: a gap in seq is counted and tolerated")

m, feed = fresh()
t = clear_up(feed, 0.0)
e = feed(t + 0.010, sent=t + 0.010 - 0.021)  # it took 21 ms longer than the fastest state: past the 20 ms budget
check(e is not None and e[1] == "LATE" and m.link_errors["delay"] == 1, f"monitor: a state 21 ms old halts LATE ({e and e[1:3]})")
e = feed(t + 0.020, sent=t + 0.020 - 0.019)
check(e is None and m.link_errors["delay"] == 1, "monitor: one 19 ms old is used")
m2, feed2 = fresh(freshness_budget_s=0.050)
t2 = clear_up(feed2, 0.0)
check(feed2(t2 + 0.010, sent=t2 + 0.010 - 0.021) is None, "monitor: --freshness-budget-ms sets the budget")

m, feed = fresh()
t = clear_up(feed, 0.0)
newest = feed.seq
m.on_stream_ended("UNAVAILABLE", t + 0.001)
m.on_stream_opened(t + 0.002)
e = feed(t + 0.010, seq=newest - 3)
check(e is not None and e[1] == "LINK_ERROR" and m.link_errors["incorrect_sequence"] == 1,
      "monitor: an older state of the same run on a new stream (a replay) is an incorrect sequence")

m, feed = fresh()
t = clear_up(feed, 0.0)
for k in range(2):
    bad = feed.state(t=t + 0.010)
    bad.stop_epoch = 9  # after sealing: corrupted
    m.on_state(bad, t + 0.010)
    t += 0.010
check(m.link_latched and m.halted, "monitor: two errors within the window latch")
released = False
for k in range(20):
    t += 0.010
    e = feed(t)
    released |= e is not None and e[0] == "CLEAR"
check(not released and m.reason == "LINK_ERROR", "monitor: latched, clean states are not used")
m.on_stream_ended("CANCELLED", t + 0.001)
m.on_stream_opened(t + 0.002)
t += 0.002
for k in range(5):
    t += 0.010
    e = feed(t)
    released |= e is not None and e[0] == "CLEAR"
check(not released and m.link_latched, "monitor: a new stream does not forget the latch")
check(m.acknowledge_link_errors() and not m.acknowledge_link_errors(), "monitor: acknowledged once (then nothing held)")
# The first state used after the acknowledgement ends a silence of 40 ms (nothing was used while latched):
# not clean; the three after it release.
events = [feed(t + k * 0.010) for k in range(1, 5)]
check(events[:3] == [None] * 3 and events[3] is not None and events[3][0] == "CLEAR",
      f"monitor: after the acknowledgement three clean states release ({[e and e[:2] for e in events]})")

# --- The script against a scripted aggregator -------------------------------------------------------------

os.makedirs(work, exist_ok=True)


def parse(text):
    lines = []
    for line in text.splitlines():
        mt = re.match(r"t=([0-9.]+) s (.*)", line)
        if mt:
            lines.append((float(mt.group(1)), mt.group(2)))
    return lines


def run_scenario(name, seconds, operator=None):
    """Runs watch_safety.py against the scenario for `seconds`; operator(proc, out_path), if given, runs
    meanwhile (it may signal the process). Returns the decision lines [(t, text)] and the whole stdout."""
    out_path = os.path.join(work, name + ".out")
    with open(os.path.join(work, name + ".log"), "w") as log, open(out_path, "w") as out:
        server, port = scripted_aggregator.serve(pb, pb_grpc, grpc, "watch-" + name, log)
        try:
            # Watchdog and freshness budget at 100 ms: a loaded 2-core machine schedules a Python server late.
            proc = subprocess.Popen([sys.executable, os.path.join(repo, "services/controller/python/watch_safety.py"),
                                     "--aggregator", f"127.0.0.1:{port}", "--robot", "cobot", "--stubs", stubs,
                                     "--insecure", "--timeout-ms", "100", "--freshness-budget-ms", "100",
                                     "--duration-s", str(seconds)], stdout=out, stderr=subprocess.STDOUT, text=True)
            try:
                if operator is not None:
                    operator(proc, out_path)
                code = proc.wait(timeout=seconds + 30)
            finally:
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
        finally:
            server.stop(0.5).wait()
    with open(out_path) as f:
        text = f.read()
    check(code == 0, f"{name}: exit 0 ({code})")
    return parse(text), text


def wait_for_line(out_path, prefix, after=-1.0, timeout_s=10.0):
    """Polls the output file until a decision line starting with prefix after time `after` appears."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with open(out_path) as f:
            t = first(parse(f.read()), prefix, after)
        if t is not None:
            return t
        time.sleep(0.02)
    return None


def first(lines, prefix, after=-1.0):
    for t, text in lines:
        if t > after and text.startswith(prefix):
            return t
    return None


lines, _ = run_scenario("missed_stop", 2.0)
moved = first(lines, "CLEAR: may move")
missed = first(lines, "HALT MISSED_STOP", moved if moved is not None else -1)
check(moved is not None and missed is not None, "script: a CLEAR under a new epoch while moving halts MISSED_STOP")
check(missed is not None and first(lines, "CLEAR: may move", missed) is not None,
      "script: ... and three clean states of the new epoch release")

lines, _ = run_scenario("streak", 3.0)
moved = first(lines, "CLEAR: may move")
silent = first(lines, "HALT NO_HEARTBEAT", moved if moved is not None else -1)
check(moved is not None and silent is not None, "script: silence after moving halts NO_HEARTBEAT")
if silent is not None:
    # The spread CLEARs (300 ms apart) come for 1.5 s after the 300 ms silence: no release among them.
    early = [t for t, text in lines if text == "CLEAR: may move" and silent < t < silent + 1.2]
    check(not early, f"script: CLEARs 300 ms apart after the halt never release (released at {early})")
    check(first(lines, "CLEAR: may move", silent + 1.2) is not None, "script: CLEARs 10 ms apart release again")

lines, _ = run_scenario("new_run", 2.5)
moved = first(lines, "CLEAR: may move")
new_run = first(lines, "HALT NEW_RUN", moved if moved is not None else -1)
check(moved is not None and new_run is not None, "script: a CLEAR of a new aggregator run halts NEW_RUN")
check(new_run is not None and first(lines, "CLEAR: may move", new_run) is not None,
      "script: ... and three clean states of the new run release")

lines, _ = run_scenario("wrong_robot", 1.5)
check(first(lines, "HALT WRONG_ROBOT: a state for robot 'other-cell'") is not None, "script: another robot halts WRONG_ROBOT")
check(first(lines, "CLEAR: may move") is None, "script: states for another robot (or none) never release")

lines, _ = run_scenario("corrupt", 2.0)
moved = first(lines, "CLEAR: may move")
bad = first(lines, "HALT LINK_ERROR: the safety layer discarded a state: corruption", moved if moved is not None else -1)
check(moved is not None and bad is not None, "script: a corrupted state while moving halts LINK_ERROR (corruption)")
check(bad is not None and first(lines, "CLEAR: may move", bad) is not None,
      "script: ... and three clean states release (one error does not latch)")

lines, _ = run_scenario("stale", 2.0)
moved = first(lines, "CLEAR: may move")
late = first(lines, "HALT LATE: a state", moved if moved is not None else -1)
check(moved is not None and late is not None, "script: a state 500 ms older than the others halts LATE")
check(late is not None and first(lines, "CLEAR: may move", late) is not None, "script: ... and three clean states release")


def acknowledge_after_latch(proc, out_path):
    latched = wait_for_line(out_path, "HALT LINK_ERROR")
    latched = latched if latched is None else wait_for_line(out_path, "HALT LINK_ERROR", latched)  # the second error
    check(latched is not None, "script: the second corruption latches")
    if latched is None:
        return
    # Latched: clean states keep coming (on this stream, then on new ones) for 0.8 s and none releases.
    time.sleep(0.8)
    with open(out_path) as f:
        check(first(parse(f.read()), "CLEAR: may move", latched) is None, "script: latched, nothing releases")
    proc.send_signal(signal.SIGUSR1)


lines, text = run_scenario("latch", 4.0, acknowledge_after_latch)
check("[latched: acknowledge with SIGUSR1]" in text, "script: the latched halt says how to acknowledge it")
acked = first(lines, "ACK LINK_ERRORS: the operator acknowledged the error-rate latch")
check(acked is not None, "script: SIGUSR1 acknowledges the latch (an ACK line)")
check(acked is not None and first(lines, "CLEAR: may move", acked) is not None,
      "script: ... and then three clean states release")
check(re.search(r"link errors: corruption 2(, loss [0-9]+)?; error-rate latch not held, acknowledged 1", text) is not None,
      "script: the summary counts the errors (each corruption leaves a gap: a loss) and the acknowledgement")
check("STOP epoch" not in text, "script: the corrupted states' content (a STOP) is never printed as a state")

if failures:
    print(f"{len(failures)} checks failed")
    sys.exit(1)
print("python example checks passed")
