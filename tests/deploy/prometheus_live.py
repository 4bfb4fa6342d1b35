#!/usr/bin/python3
"""Prometheus and Grafana against the real topology on loopback (standard library only).

  prometheus_live.py --static REPO
      The Grafana provisioning and dashboard: valid JSON, unique panel ids, every panel and target on the
      provisioned datasource uid, every query non-empty.
  prometheus_live.py REPO BIN_DIR WORK_DIR
      Starts `ruffini demo` (sim, one decoder per patch, aggregator, controller), a real `prometheus` on a free
      loopback port scraping them every second through file_sd (deploy/prometheus/demo-targets.py keeps the
      targets current) with deploy/prometheus/rules/ruffini.yml loaded, and checks through the HTTP API:
      every target up; `promtool check metrics` on a live scrape of every service; contact rates per patch;
      a STOP after the hard touch; the frame-to-STOP histogram; the alert rules loaded and healthy; every
      dashboard query runs, and each metric name it uses has series (deploy/grafana/pending-metrics.txt lists
      the names known to be missing). Every process is stopped by pid. Exit 77 when prometheus is missing.
"""
import importlib.util
import json
import math
import os
import pathlib
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.parse
import urllib.request

SKIP = 77
DS_UID = "ruffini-prometheus"
failures = []


def check(ok, what, quiet=False):
    if not ok or not quiet:
        print(("ok    " if ok else "FAIL  ") + what, flush=True)
    if not ok:
        failures.append(what)
    return ok


def dashboard_queries(repo):
    """[(panel title, expr)] of every dashboard, after the static checks."""
    out = []
    prov = (repo / "deploy/grafana/provisioning/datasources/ruffini.yml").read_text()
    check(re.search(rf"^\s+uid: {DS_UID}$", prov, re.MULTILINE) is not None, f"datasource provisioned with uid {DS_UID}")
    for f in sorted((repo / "deploy/grafana/dashboards").glob("*.json")):
        d = json.loads(f.read_text())
        ids = [p["id"] for p in d["panels"]]
        check(len(ids) == len(set(ids)), f"{f.name}: unique panel ids")
        for p in d["panels"]:
            if p["type"] == "row":
                continue
            ds_ok = p.get("datasource", {}).get("uid") == DS_UID and all(
                t.get("datasource", {}).get("uid") == DS_UID for t in p["targets"])
            check(ds_ok and p["targets"], f"{f.name}: '{p['title']}' queries datasource {DS_UID}", quiet=True)
            for t in p["targets"]:
                check(bool(t.get("expr", "").strip()), f"{f.name}: '{p['title']}' {t['refId']} has a query", quiet=True)
                out.append((p["title"], t["expr"]))
        check(True, f"{f.name}: {len(ids)} panels on datasource {DS_UID}")
    return out


KEYWORDS = {"by", "without", "on", "ignoring", "group_left", "group_right", "bool", "and", "or", "unless",
            "offset", "inf", "nan", "atan2"}


def metric_names(expr):
    """Metric names a PromQL expression selects (strings, matchers, ranges, grouping and functions removed)."""
    e = re.sub(r'"(?:[^"\\]|\\.)*"', "", expr)
    e = re.sub(r"\{[^}]*\}", "", e)
    e = re.sub(r"\[[^\]]*\]", "", e)
    e = re.sub(r"\b(by|without|on|ignoring|group_left|group_right)\s*\([^)]*\)", "", e)
    names = set()
    for m in re.finditer(r"(?<![A-Za-z0-9_:.])[A-Za-z_:][A-Za-z0-9_:]*", e):  # not a duration such as 5m
        rest = e[m.end():].lstrip()
        if rest.startswith("(") or m.group(0).lower() in KEYWORDS:
            continue
        names.add(m.group(0))
    return names


class Prom:
    def __init__(self, port):
        self.base = f"http://127.0.0.1:{port}"

    def get(self, path, **params):
        url = self.base + path + ("?" + urllib.parse.urlencode(params) if params else "")
        with urllib.request.urlopen(url, timeout=5) as r:
            return json.loads(r.read())

    def query(self, expr, at):
        """The result vector of an instant query at unix time `at`; raises on a query error."""
        try:
            r = self.get("/api/v1/query", query=expr, time=f"{at:.3f}")
        except urllib.error.HTTPError as e:
            raise RuntimeError(f"{expr}: {e.read().decode(errors='replace')}") from None
        if r["status"] != "success":
            raise RuntimeError(f"{expr}: {r}")
        return r["data"]["result"]

    def ready(self):
        try:
            with urllib.request.urlopen(self.base + "/-/ready", timeout=1) as r:
                return r.status == 200
        except OSError:
            return False


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def stop(proc, name, grace=5.0):
    """SIGTERM, then SIGKILL, by pid (the demo's own children are stopped by the demo; its process group is
    killed only if the demo itself does not end)."""
    if proc is None or proc.poll() is not None:
        return
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(grace)
    except subprocess.TimeoutExpired:
        print(f"{name} (pid {proc.pid}) ignored SIGTERM: SIGKILL", flush=True)
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # its own session: the group id is its pid
        except ProcessLookupError:
            pass
        proc.wait()


def live(repo, bin_dir, work):
    prometheus, promtool = shutil.which("prometheus"), shutil.which("promtool")
    if not prometheus or not promtool:
        print("prometheus/promtool not found (apt-get install prometheus): skipped")
        return SKIP
    queries = dashboard_queries(repo)
    pending = {l.strip() for l in (repo / "deploy/grafana/pending-metrics.txt").read_text().splitlines()
               if l.strip() and not l.startswith("#")}
    spec = importlib.util.spec_from_file_location("demo_targets", repo / "deploy/prometheus/demo-targets.py")
    demo_targets = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo_targets)

    shutil.rmtree(work, ignore_errors=True)
    (work / "targets").mkdir(parents=True)
    demo_out = work / "demo"
    config = work / "prometheus.yml"
    config.write_text(f"""# generated by {pathlib.Path(__file__).name}: the jobs of deploy/prometheus/prometheus.yml on the demo's ports
global:
  scrape_interval: 1s
  scrape_timeout: 900ms
  evaluation_interval: 1s
rule_files:
  - {repo / 'deploy/prometheus/rules/ruffini.yml'}
scrape_configs:
  - job_name: ruffini-aggregator
    file_sd_configs: [{{files: ["{work / 'targets'}/aggregator-*.json"], refresh_interval: 1s}}]
  - job_name: ruffini-decoder
    file_sd_configs: [{{files: ["{work / 'targets'}/decoder-*.json"], refresh_interval: 1s}}]
""")
    r = subprocess.run([promtool, "check", "config", str(config)], capture_output=True, text=True)
    check(r.returncode == 0, "promtool check config (generated config)" + ("" if r.returncode == 0 else ": " + r.stdout + r.stderr))

    demo = prom = None
    try:
        # Prometheus first (its start-up is the heaviest part), niced and on one core so that it does not
        # starve the demo's 1 kHz processes: a late wake-up there faults a healthy patch.
        env = dict(os.environ, GOMAXPROCS="1")
        api = None
        for attempt in range(3):  # a free port can be taken between the probe and prometheus' bind: retry
            port = free_port()
            prom_log = open(work / f"prometheus-{attempt}.log", "w")
            prom = subprocess.Popen(["nice", "-n", "10", prometheus, f"--config.file={config}",
                                     f"--storage.tsdb.path={work / 'tsdb'}", f"--web.listen-address=127.0.0.1:{port}",
                                     "--log.level=warn"],
                                    stdout=prom_log, stderr=subprocess.STDOUT, start_new_session=True, env=env)
            api = Prom(port)
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline and prom.poll() is None and not api.ready():
                time.sleep(0.2)
            if prom.poll() is None and api.ready():
                print(f"prometheus pid {prom.pid} on 127.0.0.1:{port}", flush=True)
                break
            stop(prom, "prometheus")
            prom = None
        if not check(prom is not None, "prometheus started"):
            return 1

        demo_log = open(work / "demo.log", "w")
        demo = subprocess.Popen([str(bin_dir / "ruffini"), "demo", "--out", str(demo_out)], cwd=repo,
                                stdout=demo_log, stderr=subprocess.STDOUT, start_new_session=True)
        print(f"ruffini demo pid {demo.pid}, out {demo_out}", flush=True)
        # While the demo runs: only keep the targets current (a restarted decoder gets a new port) and take one
        # copy of every service's /metrics; every query waits until it has ended (queries name their time).
        scrapes = {}
        deadline = time.monotonic() + 90
        while demo.poll() is None and time.monotonic() < deadline:
            found = demo_targets.discover(demo_out)
            demo_targets.write_targets(found, work / "targets")
            for name, target in [("aggregator", t) for t in found["aggregator"]] + sorted(found["decoder"].items()):
                if name not in scrapes:
                    try:
                        with urllib.request.urlopen(f"http://{target}/metrics", timeout=2) as resp:
                            scrapes[name] = (target, resp.read())
                    except OSError:
                        pass
            time.sleep(0.5)
        if demo.poll() is None:
            check(False, "ruffini demo ended within 90 s")
            return 1
        rc = demo.returncode
        check(rc in (0, 3), f"ruffini demo exited {rc} (0: every scripted event passed; 3: some did not)")
        events = [l.strip() for l in (work / "demo.log").read_text().splitlines() if re.match(r"\s+(PASS|FAIL)\s", l)]
        for e in events:
            print("      demo: " + e[:150])
        time.sleep(1.5)  # the last scrapes and rule evaluations

        for name, (target, text) in sorted(scrapes.items()):  # promtool check metrics on a live scrape of each
            r = subprocess.run([promtool, "check", "metrics"], input=text, capture_output=True)
            out = (r.stdout + r.stderr).decode(errors="replace").strip()
            check(r.returncode == 0, f"promtool check metrics {name} ({target})" + (": " + out if out else ""))
        check(len(scrapes) == 5, f"a live scrape of the aggregator and 4 decoders: {sorted(scrapes)}")

        t_end = time.time()
        ups = api.query(f'max_over_time(up{{job=~"ruffini-.*"}}[2m]) == 1', t_end)
        jobs = sorted(s["metric"]["job"] for s in ups)
        check(jobs.count("ruffini-aggregator") == 1 and jobs.count("ruffini-decoder") >= 4,
              f"targets scraped: {len(ups)} ({jobs.count('ruffini-decoder')} decoders; a restarted decoder is a new target)")

        # The moment of the first STOP, from a range query over the run; the instant checks look 2 s later,
        # while every process still ran (the demo kills a decoder ~3 s after the hard touch).
        r = api.get("/api/v1/query_range", query="ruffini_aggregator_stops_total > 0", start=t_end - 120, end=t_end,
                    step=0.5)["data"]["result"]
        t_stop = min((float(v[0]) for s in r for v in s["values"]), default=None)
        if not check(t_stop is not None, "a STOP after the hard touch (ruffini_aggregator_stops_total > 0)"):
            return 1
        t = t_stop + 2.0
        stops = api.query("ruffini_aggregator_stops_total", t)
        check(bool(stops) and float(stops[0]["value"][1]) >= 1, f"ruffini_aggregator_stops_total = {stops[0]['value'][1] if stops else None} 2 s after the first STOP")
        rates = api.query("sum by (patch, region) (rate(ruffini_aggregator_contacts_total[20s]))", t)
        patches = {f'{s["metric"]["patch"]} ({s["metric"]["region"]})': round(float(s["value"][1]), 3) for s in rates}
        check(len(patches) == 4, f"contact rate per patch at the aggregator (/s): {patches}")
        touched = api.query("sum by (patch) (increase(ruffini_aggregator_contacts_total[5s])) > 0", t)
        touched_patches = sorted(s["metric"]["patch"] for s in touched)
        check({"forearm_a", "forearm_b"} <= set(touched_patches), f"contacts around the hard touch on {touched_patches}")
        dec = api.query("sum by (patch) (rate(ruffini_decoder_contacts_total[20s]))", t)
        check(len(dec) == 4, "contact rate per patch at the decoders (/s): "
              + str({s["metric"]["patch"]: round(float(s["value"][1]), 3) for s in dec}))
        frames = api.query("sum by (patch) (rate(ruffini_decoder_frames_total[5s]))", t)
        fr = {s["metric"]["patch"]: round(float(s["value"][1])) for s in frames}
        check(len(fr) == 4 and all(v > 0 for v in fr.values()), f"frames per second per decoder: {fr}")
        count = api.query("ruffini_aggregator_frame_to_stop_seconds_count", t)
        check(bool(count) and float(count[0]["value"][1]) >= 1, "frame-to-STOP histogram has observations")
        p99 = api.query("histogram_quantile(0.99, sum by (le) (ruffini_aggregator_frame_to_stop_seconds_bucket))", t)
        v = float(p99[0]["value"][1]) if p99 else math.nan
        check(math.isfinite(v) and v > 0, f"frame-to-STOP p99 (every STOP so far, bucket bound) = {v * 1e3:.3f} ms")
        safety = api.query("ruffini_aggregator_safety_state == 1", t)
        check(bool(safety), f"safety_state 2 s after the STOP: {[s['metric']['state'] for s in safety]}")

        groups = api.get("/api/v1/rules")["data"]["groups"]
        rules = [r for g in groups for r in g["rules"]]
        bad = [r["name"] for r in rules if r.get("health") != "ok"]
        check(len(rules) == 8 and not bad, f"{len(rules)} alert rules loaded and evaluated, unhealthy: {bad}")
        firing = sorted({a["labels"]["alertname"] for a in api.get("/api/v1/alerts")["data"]["alerts"]})
        print(f"note  alerts pending or firing now (the demo ends on FAULT and its targets are gone): {firing}")

        names = set(api.get("/api/v1/label/__name__/values")["data"])
        for title in dict.fromkeys(title for title, _ in queries):
            used, errors = set(), []
            for _, expr in (q for q in queries if q[0] == title):
                qq = expr.replace("$__rate_interval", "10s").replace("$__range", "1m").replace("$__interval", "1s")
                try:
                    api.query(qq, t)
                except RuntimeError as e:
                    errors.append(str(e))
                used |= metric_names(qq)
            missing = sorted(used - names - pending)
            check(not errors and not missing, f"dashboard '{title}': {', '.join(sorted(used))}"
                  + (f": NO SERIES for {missing}" if missing else "") + (f": query errors {errors}" if errors else ""))
        now_exported = sorted(pending & names)
        check(not now_exported, "pending-metrics.txt names no exported metric"
              + (f" (now exported: {now_exported}; remove them from the list)" if now_exported else ""))
        for m in sorted(pending):
            print(f"note  {m}: not exported by any service yet (deploy/grafana/pending-metrics.txt)")
    finally:
        stop(prom, "prometheus")
        stop(demo, "ruffini demo", grace=15.0)
    print(("FAILED: " + "; ".join(failures)) if failures else "all checks passed", flush=True)
    return 1 if failures else 0


def main(argv):
    if len(argv) == 3 and argv[1] == "--static":
        dashboard_queries(pathlib.Path(argv[2]).resolve())
        print(("FAILED: " + "; ".join(failures)) if failures else "dashboard checks passed")
        return 1 if failures else 0
    if len(argv) != 4:
        print(__doc__, file=sys.stderr)
        return 2
    return live(pathlib.Path(argv[1]).resolve(), pathlib.Path(argv[2]).resolve(), pathlib.Path(argv[3]).resolve())


if __name__ == "__main__":
    sys.exit(main(sys.argv))
