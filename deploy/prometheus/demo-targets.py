#!/usr/bin/python3
"""Writes Prometheus file_sd targets for a running `ruffini demo --out DEMO_OUT`.

The demo picks every port itself: the aggregator writes DEMO_OUT/logs/aggregator/ports ("metrics P"), each
decoder prints "ports: metrics P" on its stdout (DEMO_OUT/logs/decoder-PATCH/stdout). This writes
OUT/aggregator-demo.json and OUT/decoder-demo.json (default OUT: targets/ next to this script, which
prometheus.yml follows). --watch S rewrites them every S seconds until interrupted (the demo restarts a
decoder on a new port). Standard library only.

    deploy/prometheus/demo-targets.py demo-report --watch 1 &
    prometheus --config.file deploy/prometheus/prometheus.yml --storage.tsdb.path /tmp/ruffini-tsdb
"""
import argparse
import json
import os
import pathlib
import re
import sys
import time


def read_port(path, pattern):
    try:
        text = pathlib.Path(path).read_text()
    except OSError:
        return None
    m = re.search(pattern, text, re.MULTILINE)
    return int(m.group(1)) if m else None


def discover(demo_out, host="127.0.0.1"):
    """{"aggregator": [host:port], "decoder": {patch: host:port}} for what the demo has announced so far."""
    logs = pathlib.Path(demo_out) / "logs"
    found = {"aggregator": [], "decoder": {}}
    port = read_port(logs / "aggregator" / "ports", r"^metrics (\d+)$")
    if port:
        found["aggregator"].append(f"{host}:{port}")
    for d in sorted(logs.glob("decoder-*")):
        port = read_port(d / "stdout", r"^ports: metrics (\d+)$")
        if port:
            found["decoder"][d.name[len("decoder-"):]] = f"{host}:{port}"
    return found


def write_json(path, groups):
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(groups, indent=2) + "\n")
    os.replace(tmp, path)  # atomic: Prometheus never reads half a file


def write_targets(found, out_dir):
    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    # No `patch` label on the targets: the services label their series with it themselves.
    write_json(out_dir / "aggregator-demo.json", [{"targets": found["aggregator"], "labels": {"deployment": "demo"}}])
    write_json(out_dir / "decoder-demo.json",
               [{"targets": [t], "labels": {"deployment": "demo"}} for _, t in sorted(found["decoder"].items())])


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("demo_out", help="the demo's --out folder")
    p.add_argument("--out", default=str(pathlib.Path(__file__).resolve().parent / "targets"),
                   help="folder for the file_sd JSON files (default: %(default)s)")
    p.add_argument("--watch", type=float, default=0, help="rewrite every WATCH seconds until interrupted")
    a = p.parse_args()
    while True:
        found = discover(a.demo_out)
        write_targets(found, a.out)
        if not a.watch:
            print(f"aggregator {found['aggregator']}, decoders {found['decoder']} -> {a.out}")
            return 0 if found["aggregator"] else 1
        time.sleep(a.watch)


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        sys.exit(0)
