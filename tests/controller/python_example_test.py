#!/usr/bin/python3
"""The Python example (services/controller/python/watch_safety.py) keeps the C++ client's rules: its Monitor
on its own with an injected clock, then the whole script against a scripted grpcio aggregator
(scripted_aggregator.py) in this process. Prints "python example checks passed" when every check held.

  python_example_test.py STUBS_DIR REPO_DIR WORK_DIR
"""
import os
import re
import subprocess
import sys
import threading

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

def state(kind=1, epoch=1, seq=0, run=1, robot="cobot"):
    return pb.SafetyState(state=kind, stop_epoch=epoch, seq=seq, aggregator_run_id=run, aggregator_start_t_ns=run,
                          robot_name=robot)


def clear_up(m, t, epoch=1, run=1):
    for _ in range(10):
        t += 0.010
        e = m.on_state(state(epoch=epoch, run=run), t)
        if e and e[0] == "CLEAR":
            return t
    check(False, "never cleared")
    return t


m = watch_safety.Monitor("cobot", 0.030, now=0.0)
m.on_stream_opened(0.0)
t = clear_up(m, 0.0)
check(not m.halted, "monitor: three CLEARs release")
e = m.on_state(state(epoch=2), t + 0.010)
check(e is not None and e[1] == "MISSED_STOP", f"monitor: a CLEAR under a new epoch is a missed stop ({e and e[:2]})")

m = watch_safety.Monitor("cobot", 0.030, now=0.0)
m.on_stream_opened(0.0)
t = clear_up(m, 0.0)
e = m.on_tick(t + 0.031)
check(e is not None and e[1] == "NO_HEARTBEAT", "monitor: 31 ms of silence halts")
released = False
for i in range(6):  # CLEARs one second apart, the watchdog ticking in between
    t += 1.0
    e = m.on_state(state(), t)
    released |= e is not None and e[0] == "CLEAR"
    m.on_tick(t + 0.031)
check(not released and m.halted, "monitor: after a watchdog halt, CLEARs a second apart never release")
t += 1.0
events = [m.on_state(state(), t + k * 0.010) for k in range(4)]
check(events[2] is None and events[3] is not None and events[3][0] == "CLEAR",
      "monitor: then three within the watchdog after the late one release")

m = watch_safety.Monitor("cobot", 0.030, now=0.0)
m.on_stream_opened(0.0)
t = clear_up(m, 0.0)
e = m.on_state(state(run=2), t + 0.010)
check(e is not None and e[1] == "NEW_RUN", "monitor: a CLEAR of a new run halts")
e2 = m.on_state(state(run=2), t + 0.020)
e3 = m.on_state(state(run=2), t + 0.030)
e4 = m.on_state(state(run=2), t + 0.040)
check(e2 is None and e3 is None and e4 is not None and e4[0] == "CLEAR",
      "monitor: released by three clean states of the new run after the halt")

m = watch_safety.Monitor("cobot", 0.030, now=0.0)
m.on_stream_opened(0.0)
t = 0.0
released = False
for robot in ["other", ""] * 10:
    t += 0.010
    e = m.on_state(state(robot=robot), t)
    released |= e is not None and e[0] == "CLEAR"
check(not released and m.reason == "WRONG_ROBOT" and m.counts["refused"] == 20,
      f"monitor: states for another robot (or none) are refused and counted ({m.reason}, {m.counts['refused']})")
try:
    watch_safety.Monitor("", 0.030)
    check(False, "monitor: an empty robot name is refused")
except ValueError:
    check(True, "monitor: an empty robot name is refused")

# --- The script against a scripted aggregator -------------------------------------------------------------

os.makedirs(work, exist_ok=True)


def run_scenario(name, seconds):
    with open(os.path.join(work, name + ".log"), "w") as log:
        server, port = scripted_aggregator.serve(pb, pb_grpc, grpc, "watch-" + name, log)
        try:
            out = subprocess.run([sys.executable, os.path.join(repo, "services/controller/python/watch_safety.py"),
                                  "--aggregator", f"127.0.0.1:{port}", "--robot", "cobot", "--stubs", stubs,
                                  "--insecure", "--timeout-ms", "100", "--duration-s", str(seconds)],
                                 capture_output=True, text=True, timeout=seconds + 30)
        finally:
            server.stop(0.5).wait()
    with open(os.path.join(work, name + ".out"), "w") as f:
        f.write(out.stdout + out.stderr)
    check(out.returncode == 0, f"{name}: exit 0 ({out.returncode})")
    lines = []
    for line in out.stdout.splitlines():
        mt = re.match(r"t=([0-9.]+) s (.*)", line)
        if mt:
            lines.append((float(mt.group(1)), mt.group(2)))
    return lines


def first(lines, prefix, after=-1.0):
    for t, text in lines:
        if t > after and text.startswith(prefix):
            return t
    return None


lines = run_scenario("missed_stop", 2.0)
moved = first(lines, "CLEAR: may move")
missed = first(lines, "HALT MISSED_STOP", moved if moved is not None else -1)
check(moved is not None and missed is not None, "script: a CLEAR under a new epoch while moving halts MISSED_STOP")
check(missed is not None and first(lines, "CLEAR: may move", missed) is not None,
      "script: ... and three clean states of the new epoch release")

lines = run_scenario("streak", 3.0)
moved = first(lines, "CLEAR: may move")
silent = first(lines, "HALT NO_HEARTBEAT", moved if moved is not None else -1)
check(moved is not None and silent is not None, "script: silence after moving halts NO_HEARTBEAT")
if silent is not None:
    # The spread CLEARs (300 ms apart) come for 1.5 s after the 300 ms silence: no release among them.
    early = [t for t, text in lines if text == "CLEAR: may move" and silent < t < silent + 1.2]
    check(not early, f"script: CLEARs 300 ms apart after the halt never release (released at {early})")
    check(first(lines, "CLEAR: may move", silent + 1.2) is not None, "script: CLEARs 10 ms apart release again")

lines = run_scenario("new_run", 2.0)
moved = first(lines, "CLEAR: may move")
new_run = first(lines, "HALT NEW_RUN", moved if moved is not None else -1)
check(moved is not None and new_run is not None, "script: a CLEAR of a new aggregator run halts NEW_RUN")
check(new_run is not None and first(lines, "CLEAR: may move", new_run) is not None,
      "script: ... and three clean states of the new run release")

lines = run_scenario("wrong_robot", 1.5)
check(first(lines, "HALT WRONG_ROBOT: a state for robot 'other-cell'") is not None, "script: another robot halts WRONG_ROBOT")
check(first(lines, "CLEAR: may move") is None, "script: states for another robot (or none) never release")

if failures:
    print(f"{len(failures)} checks failed")
    sys.exit(1)
print("python example checks passed")
