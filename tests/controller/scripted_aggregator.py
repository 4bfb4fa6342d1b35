#!/usr/bin/python3
"""A scripted Ruffini aggregator in Python (grpcio) for the client tests: WatchSafety plays a scenario of
SafetyStates with their gaps; GetStatus and ResetStop play an operator-reset scenario. Every call is
logged (one line each) to --log. Every state carries the safety layer as the real aggregator sends it
(docs/safety-channel.md): seq counting per run across streams, sender_steady_ns from this process's
monotonic clock, and safety_crc32 (watch_safety.safety_crc32, pinned to the C++ test vector by
python_example_test.py); a scenario may corrupt a state after sealing it, or stamp it older than it is.
Used in-process by python_example_test.py and as a process by tests/cli/reset_test.sh:

  scripted_aggregator.py --stubs DIR --mode reset-accepted --ports-file F --log L

writes "grpc PORT" to F once it listens and serves until SIGTERM.
"""
import argparse
import collections
import os
import signal
import sys
import threading
import time
from concurrent import futures

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "../../services/controller/python"))
from watch_safety import safety_crc32  # noqa: E402

RUN_A, RUN_B = 0x1F2E3D4C5B6A7988, 0x7777000011112222


def clear(epoch=1, run=RUN_A, robot="cobot", gap_s=0.010, corrupt=False, age_s=0.0):
    """A CLEAR sent gap_s after the state before it; corrupt: a field flipped after the CRC (the state reads
    STOP); age_s: stamped this much older than it is (sender_steady_ns), as if it had waited in a queue."""
    return dict(state=1, epoch=epoch, run=run, robot=robot, gap_s=gap_s, corrupt=corrupt, age_s=age_s)


# Watch scenarios: one list of states per WatchSafety call (the last list serves every later call), each
# state sent gap_s after the one before; the last state of a list keeps repeating every 10 ms until the
# subscriber leaves, unless the list ends with END (the stream ends there).
END = "end"
WATCH = {
    # A CLEAR under a new epoch (its STOP and reset skipped) while moving: MISSED_STOP, then three clean states.
    "missed_stop": [[clear()] * 40 + [clear(epoch=2)] * 40],
    # Moving, then 300 ms of silence (NO_HEARTBEAT), then CLEARs 300 ms apart (never three within the
    # watchdog: no release), then CLEARs 10 ms apart (release).
    "streak": [[clear()] * 40 + [clear(gap_s=0.3)] * 5 + [clear()] * 40],
    # A new run's CLEAR on the next stream (the old run's stream ended) while moving: NEW_RUN, then three clean
    # states of the new run. Within one stream another run's state would be an insertion.
    "new_run": [[clear()] * 40 + [END], [clear(run=RUN_B)] * 40],
    # Another robot, then no robot name at all: WRONG_ROBOT, never a release.
    "wrong_robot": [[clear(robot="other-cell")] * 40 + [clear(robot="")] * 40],
    # One corrupted state while moving: LINK_ERROR, then three clean states release (one error does not latch).
    "corrupt": [[clear()] * 40 + [clear(corrupt=True)] + [clear()] * 40],
    # One state 500 ms older than the others while moving: LATE, then three clean states release.
    "stale": [[clear()] * 40 + [clear(age_s=0.5)] + [clear()] * 40],
    # Two corrupted states within the window: latched; clean states (on this stream and the next ones) are not
    # used until the operator acknowledges.
    "latch": [[clear()] * 40 + [clear(corrupt=True)] + [clear()] * 10 + [clear(corrupt=True)] + [clear()] * 40,
              [clear()] * 40],
}


def make_servicer(pb, pb_grpc, mode, log):
    lock = threading.Lock()
    st = {"epoch": 6, "state": 2, "resets": 0, "gets": 0, "calls": 0}  # STOP epoch 6 of RUN_A for the reset modes
    seqs = collections.defaultdict(int)  # per run, shared by its streams (as the aggregator's publication counter)

    def note(text):
        with lock:
            log.write(text + "\n")
            log.flush()

    def safety(state, epoch, run, robot, seq=0, corrupt=False, age_s=0.0):
        s = pb.SafetyState(state=state, stop_epoch=epoch, aggregator_run_id=run, aggregator_start_t_ns=run & 0x7FFFFFFF,
                           robot_name=robot, seq=seq, sender_steady_ns=time.monotonic_ns() - int(age_s * 1e9))
        if state != 1:
            s.cause.kind = pb.SafetyCause.KIND_CONTACT if state == 2 else pb.SafetyCause.KIND_PATCH_FAULT
            s.cause.patch_id = "forearm_a" if state == 2 else "upper_arm_a"
        s.safety_crc32 = safety_crc32(s)
        if corrupt:
            s.state = 2 if s.state == 1 else 1
        return s

    class Servicer(pb_grpc.AggregatorServicer):
        def WatchSafety(self, request, context):
            with lock:
                call = st["calls"]
                st["calls"] += 1
            note(f"WatchSafety {request.subscriber} (call {call + 1})")
            calls = WATCH[mode[len("watch-"):]] if mode.startswith("watch-") else [[clear()]]
            script = calls[min(call, len(calls) - 1)]

            def send(step):
                with lock:
                    seqs[step["run"]] += 1
                    seq = seqs[step["run"]]
                return safety(step["state"], step["epoch"], step["run"], step["robot"], seq, step["corrupt"],
                              step["age_s"])

            for i, step in enumerate(script):
                if step == END:
                    return
                if i > 0:
                    time.sleep(step["gap_s"])
                yield send(step)
            last = dict(script[-1], corrupt=False, age_s=0.0)
            while context.is_active():
                time.sleep(0.010)
                yield send(last)

        def GetStatus(self, request, context):
            with lock:
                st["gets"] += 1
                s = safety(st["state"], st["epoch"], RUN_A, "cobot")
            note(f"GetStatus -> state {s.state} epoch {s.stop_epoch}")
            return pb.AggregatorStatus(safety=s, aggregator_run_id=RUN_A, robot_name="cobot",
                                       aggregator_version="scripted")

        def ResetStop(self, request, context):
            R = pb.ResetRefusal
            with lock:
                st["resets"] += 1
                n = st["resets"]
                if request.aggregator_run_id != RUN_A:
                    reason, msg = R.RESET_REFUSAL_WRONG_RUN, f"run {request.aggregator_run_id:#x} is not this run"
                elif mode == "reset-new-cause" and n > 3:
                    st["state"], st["epoch"] = 3, 7  # a new cause latched: FAULT epoch 7
                    reason, msg = (None, "") if request.stop_epoch == 7 else (
                        R.RESET_REFUSAL_WRONG_EPOCH, f"stop_epoch {request.stop_epoch} is not the current 7")
                elif request.stop_epoch != st["epoch"]:
                    reason, msg = R.RESET_REFUSAL_WRONG_EPOCH, f"stop_epoch {request.stop_epoch} is not the current {st['epoch']}"
                elif mode == "reset-cause-present":
                    reason, msg = R.RESET_REFUSAL_CAUSE_PRESENT, "cause still present: contact forearm_a"
                elif mode in ("reset-accepted", "reset-new-cause") and n <= 3:
                    reason, msg = R.RESET_REFUSAL_NOT_HEALTHY_LONG_ENOUGH, "patch forearm_a healthy for 0.1 s of 0.5 s"
                else:
                    reason, msg = None, ""
                if reason is None:
                    st["state"] = 1
            note(f"ResetStop run {request.aggregator_run_id:#x} epoch {request.stop_epoch} -> "
                 f"{'accepted' if reason is None else R.Name(reason)}")
            if reason is None:
                return pb.ResetStopResponse(accepted=True, message=f"reset accepted: stop_epoch {request.stop_epoch} cleared")
            return pb.ResetStopResponse(accepted=False, reason=reason, message=msg)

    return Servicer()


def serve(pb, pb_grpc, grpc, mode, log):
    """Starts the server on 127.0.0.1:0; returns (server, port)."""
    server = grpc.server(futures.ThreadPoolExecutor(max_workers=8),
                         options=[("grpc.http2.min_ping_interval_without_data_ms", 100),
                                  ("grpc.keepalive_permit_without_calls", 1), ("grpc.http2.max_ping_strikes", 0)])
    pb_grpc.add_AggregatorServicer_to_server(make_servicer(pb, pb_grpc, mode, log), server)
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    return server, port


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--stubs", required=True)
    parser.add_argument("--mode", required=True)
    parser.add_argument("--ports-file", required=True)
    parser.add_argument("--log", required=True)
    args = parser.parse_args()
    sys.path.insert(0, args.stubs)
    import grpc
    from ruffini.v1 import aggregator_pb2 as pb, aggregator_pb2_grpc as pb_grpc
    with open(args.log, "w") as log:
        server, port = serve(pb, pb_grpc, grpc, args.mode, log)
        with open(args.ports_file + ".tmp", "w") as f:
            f.write(f"grpc {port}\n")
        import os
        os.replace(args.ports_file + ".tmp", args.ports_file)
        stop = threading.Event()
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
        signal.signal(signal.SIGINT, lambda *_: stop.set())
        while not stop.wait(0.1):
            pass
        server.stop(0.5).wait()
    return 0


if __name__ == "__main__":
    sys.exit(main())
