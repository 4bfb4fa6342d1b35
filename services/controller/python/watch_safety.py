#!/usr/bin/python3
"""The Ruffini safety contract from Python: subscribe to the aggregator's WatchSafety, print every change
of state, and halt on silence.

The rules (docs/contracts.md, docs/controller.md): the robot may move only while the newest state is CLEAR,
it arrived less than 30 ms ago on a live stream, and the stream is open. STOP, FAULT, any other value, a
state older than 30 ms, the stream ending or failing to open: halt. A real controller would command its
robot where this prints HALT and CLEAR.

Needs Debian's python3-grpcio and python3-protobuf, and the stubs the build generates from
proto/ruffini/v1/ (protoc with /usr/bin/grpc_python_plugin, into build/<preset>/services/controller/python):

  /usr/bin/python3 services/controller/python/watch_safety.py --aggregator 127.0.0.1:50051 \
      --stubs build/release/services/controller/python

Exit codes: 0 after --duration-s or on Ctrl-C, 1 when the stubs or grpc cannot be imported, 2 usage.
"""
import argparse
import os
import collections
import signal
import sys
import threading
import time


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--aggregator", required=True, help="the aggregator's gRPC address, HOST:PORT")
    parser.add_argument("--stubs", default="", help="folder holding the generated ruffini/v1/*_pb2*.py")
    parser.add_argument("--duration-s", type=float, default=0.0, help="stop after this long (0: until Ctrl-C)")
    parser.add_argument("--timeout-ms", type=float, default=30.0, help="halt when no state came for this long")
    parser.add_argument("--subscriber", default="watch_safety.py", help="the name given to the aggregator")
    tls = parser.add_mutually_exclusive_group(required=True)
    tls.add_argument("--tls-dir", help="mutual TLS: ca.crt and this client's controller.crt / controller.key "
                     "(deploy/tls/make-dev-ca.sh), as the C++ services read them")
    tls.add_argument("--insecure", action="store_true", help="plaintext (an --insecure aggregator)")
    args = parser.parse_args()

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
    timeout_s = args.timeout_ms / 1000.0
    t0 = time.monotonic()
    lock = threading.Lock()
    shared = {"last_arrival": None, "halted": True, "reason": "not started", "stream_open": False}
    counts = collections.Counter()
    gaps = {"max_s": 0.0}
    done = threading.Event()

    def say(text):
        print(f"t={time.monotonic() - t0:.3f} s {text}", flush=True)

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

    def halt(reason):  # with the lock held
        if not shared["halted"] or shared["reason"] != reason:
            say(f"HALT {reason}")
        shared["halted"], shared["reason"] = True, reason

    # Reconnect quickly: gRPC's default backoff is 1 s growing to 120 s.
    options = [("grpc.initial_reconnect_backoff_ms", 100), ("grpc.min_reconnect_backoff_ms", 100),
               ("grpc.max_reconnect_backoff_ms", 1000)]
    if args.insecure:
        print("--insecure: PLAINTEXT gRPC, no TLS and no identity", file=sys.stderr, flush=True)
        channel = grpc.insecure_channel(args.aggregator, options=options)
    else:
        def read(name):
            with open(os.path.join(args.tls_dir, name), "rb") as f:
                return f.read()
        own = "controller" if os.path.exists(os.path.join(args.tls_dir, "controller.crt")) else "tls"
        creds = grpc.ssl_channel_credentials(root_certificates=read("ca.crt"), private_key=read(own + ".key"),
                                             certificate_chain=read(own + ".crt"))
        channel = grpc.secure_channel(args.aggregator, creds, options=options)
    stub = aggregator_pb2_grpc.AggregatorStub(channel)
    calls = []

    def reader():
        pause = 0.1
        while not done.is_set():
            call = stub.WatchSafety(aggregator_pb2.WatchSafetyRequest(subscriber=args.subscriber))
            calls.append(call)
            with lock:
                shared["stream_open"], shared["last_arrival"] = True, time.monotonic()
            previous, streak, got_any = None, 0, False
            try:
                for s in call:
                    now = time.monotonic()
                    with lock:
                        if got_any:
                            gaps["max_s"] = max(gaps["max_s"], now - shared["last_arrival"])
                        got_any = True
                        shared["last_arrival"] = now
                        counts[s.state] += 1
                        key = (s.state, s.stop_epoch, s.aggregator_start_t_ns)
                        if key != previous:
                            say(describe(s))
                            previous = key
                        if s.state == State.STATE_CLEAR:
                            streak += 1
                            if shared["halted"] and streak >= 3:  # three CLEARs in a row on a live stream
                                shared["halted"] = False
                                say("CLEAR: may move")
                        else:
                            streak = 0
                            halt(describe(s))
            except grpc.RpcError as e:
                if done.is_set():
                    break
                with lock:
                    halt(("stream ended: " if got_any else "no stream: ") + e.code().name)
            with lock:
                shared["stream_open"] = False
                if not done.is_set():
                    halt("stream ended")
            pause = 0.1 if got_any else min(pause * 2, 1.0)
            done.wait(pause)

    def watchdog():
        while not done.wait(0.001):
            with lock:
                if shared["stream_open"] and shared["last_arrival"] is not None:
                    silence = time.monotonic() - shared["last_arrival"]
                    if silence > timeout_s and not (shared["halted"] and shared["reason"].startswith("no heartbeat")):
                        halt(f"no heartbeat for {silence * 1000:.1f} ms")

    signal.signal(signal.SIGINT, lambda *_: done.set())
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    threads = [threading.Thread(target=reader, daemon=True), threading.Thread(target=watchdog, daemon=True)]
    for t in threads:
        t.start()
    deadline = t0 + args.duration_s if args.duration_s > 0 else None
    while not done.is_set():
        if deadline is not None and time.monotonic() >= deadline:
            done.set()
            break
        done.wait(0.05)
    for call in calls:
        call.cancel()
    for t in threads:
        t.join(timeout=2)
    channel.close()
    by_state = ", ".join(f"{State.State.Name(k).replace('STATE_', '')} {v}" for k, v in sorted(counts.items()))
    print(f"received {sum(counts.values())} states ({by_state or 'none'}), longest gap "
          f"{gaps['max_s'] * 1000:.1f} ms, halted at exit: {shared['halted']}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
