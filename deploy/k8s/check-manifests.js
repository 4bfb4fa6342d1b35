// Checks rendered Kubernetes manifests (kubectl kustomize output) for Ruffini. Run by deploy/k8s/check.sh.
//   node check-manifests.js --rendered FILE --help-dir DIR --repo DIR --overlay NAME
// 1. Schema: every object is validated against the Kubernetes schemas of npm kubernetes-models (which checks
//    types, required fields and formats, but not unknown field names).
// 2. The executables: each container's command is /usr/local/bin/<exe> where <exe> is a Ruffini executable the
//    Containerfile installs; its image is ruffini/ruffini (what deploy/container/build.sh tags); every --flag
//    in its args appears in `<exe> --help` (DIR/<exe>.help), unless deploy/k8s/pending-flags.txt lists it (a
//    flag the manifests need and the executable lacks; listed ones that the executable now accepts fail, so
//    the list stays honest); every $(VAR) is defined in env; every configMapKeyRef names a rendered ConfigMap
//    with that key.
// 3. Ports: the port of each HOST:PORT flag the container listens on is a containerPort; every probe's port is
//    one of the container's ports; the exec probe's port is the --metrics port; Service targetPorts exist on
//    the selected pods; NetworkPolicy ports exist on the selected pods; the decoder's aggregator address is the
//    aggregator Service's gRPC port.
// 4. The robot: the scene exists in config/ (the image's /etc/ruffini/config); one decoder per scene patch,
//    each patch once, each interrogator channel once per interrogator.
// 5. Hardening: runAsNonRoot with the image's uid, readOnlyRootFilesystem, allowPrivilegeEscalation false,
//    capabilities drop ALL, seccomp RuntimeDefault, cpu and memory requests and limits, TLS from a Secret
//    mounted read-only at /etc/ruffini/tls, and no --insecure anywhere.
"use strict";
const fs = require("fs");
const path = require("path");
const YAML = require("yaml");

const args = {};
for (let i = 2; i < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, "")] = process.argv[i + 1];
const problems = [];
const notes = new Set();
const fail = (where, msg) => problems.push(`${where}: ${msg}`);

const docs = YAML.parseAllDocuments(fs.readFileSync(args.rendered, "utf8"))
  .map((d) => d.toJSON())
  .filter((o) => o);
if (docs.length === 0) fail(args.rendered, "no objects rendered");

// 1. Schemas.
function modelFor(o) {
  const [group, version] = o.apiVersion.includes("/") ? o.apiVersion.split("/") : ["", o.apiVersion];
  const mod = group ? `kubernetes-models/${group}/${version}/${o.kind}` : `kubernetes-models/${version}/${o.kind}`;
  return require(mod)[o.kind];
}
const byKind = {};
for (const o of docs) {
  const id = `${o.kind}/${o.metadata && o.metadata.name}`;
  let Model;
  try {
    Model = modelFor(o);
  } catch (e) {
    fail(id, `no schema for ${o.apiVersion} ${o.kind}`);
    continue;
  }
  try {
    new Model(o).validate();
  } catch (e) {
    fail(id, `schema: ${e.message}`);
  }
  (byKind[o.kind] = byKind[o.kind] || []).push(o);
}
const all = (k) => byKind[k] || [];

// What the image holds: executables, scripts and the uid (from the Containerfile).
const containerfile = fs.readFileSync(path.join(args.repo, "deploy/container/Containerfile"), "utf8");
const uidMatch = containerfile.match(/^ARG RUFFINI_UID=(\d+)/m);
const imageUid = uidMatch ? Number(uidMatch[1]) : null;
if (imageUid === null) fail("deploy/container/Containerfile", "no 'ARG RUFFINI_UID=' line");
const pending = fs
  .readFileSync(path.join(args.repo, "deploy/k8s/pending-flags.txt"), "utf8")
  .split("\n")
  .filter((l) => l.trim() && !l.startsWith("#"))
  .map((l) => l.trim().split(/\s+/));
const isPending = (exe, flag) => pending.some(([e, f]) => e === exe && f === flag);
const helpCache = {};
function help(exe) {
  if (!(exe in helpCache)) {
    const f = path.join(args["help-dir"], `${exe}.help`);
    helpCache[exe] = fs.existsSync(f) ? fs.readFileSync(f, "utf8") : null;
  }
  return helpCache[exe];
}
// A name in the Containerfile as a whole word ("ruffini-decode" is not "ruffini-decoder").
const installs = (name) => new RegExp(`(^|[^\\w-])${name.replace(/[-.]/g, "\\$&")}(?![\\w-])`, "m").test(containerfile);
const flagIn = (text, flag) => new RegExp(`(^|[\\s,\\[])${flag.replace(/-/g, "\\-")}(?![\\w-])`, "m").test(text);

const configMaps = Object.fromEntries(all("ConfigMap").map((c) => [c.metadata.name, c.data || {}]));
const services = all("Service");
const sceneRoot = "/etc/ruffini/config/";
const decoders = [];
const podsByLabels = []; // [labels, containers, deploymentName]

// 2, 3, 5. Deployments.
for (const d of all("Deployment")) {
  const id = `Deployment/${d.metadata.name}`;
  const pod = d.spec.template.spec;
  podsByLabels.push([d.spec.template.metadata.labels || {}, pod.containers, d.metadata.name]);
  const psc = pod.securityContext || {};
  if (psc.runAsNonRoot !== true) fail(id, "pod securityContext.runAsNonRoot is not true");
  if (psc.runAsUser !== imageUid) fail(id, `pod runAsUser ${psc.runAsUser} is not the image's uid ${imageUid}`);
  if (!psc.seccompProfile || psc.seccompProfile.type !== "RuntimeDefault") fail(id, "seccompProfile is not RuntimeDefault");
  if (pod.automountServiceAccountToken !== false) fail(id, "automountServiceAccountToken is not false");
  const volumes = Object.fromEntries((pod.volumes || []).map((v) => [v.name, v]));
  for (const c of pod.containers) {
    const cid = `${id} container ${c.name}`;
    const sc = c.securityContext || {};
    if (sc.readOnlyRootFilesystem !== true) fail(cid, "readOnlyRootFilesystem is not true");
    if (sc.allowPrivilegeEscalation !== false) fail(cid, "allowPrivilegeEscalation is not false");
    if (!sc.capabilities || !(sc.capabilities.drop || []).includes("ALL")) fail(cid, "capabilities do not drop ALL");
    for (const kind of ["requests", "limits"])
      for (const r of ["cpu", "memory"])
        if (!(c.resources && c.resources[kind] && c.resources[kind][r])) fail(cid, `no resources.${kind}.${r}`);

    const image = c.image || "";
    const imageName = image.replace(/:[^/:]+$/, "").replace(/^localhost\//, "");
    if (imageName !== "ruffini/ruffini") fail(cid, `image ${image} is not ruffini/ruffini (deploy/container/build.sh)`);

    const cmd = c.command || [];
    const exe = path.basename(cmd[0] || "");
    if (cmd.length !== 1 || !cmd[0].startsWith("/usr/local/bin/")) fail(cid, `command ${JSON.stringify(cmd)} is not one /usr/local/bin/ executable`);
    if (!exe || !installs(exe)) fail(cid, `${exe} is not installed by deploy/container/Containerfile`);
    const text = help(exe);
    if (text === null) {
      fail(cid, `${exe} --help was not captured (is ${exe} built?)`);
      continue;
    }
    const argv = c.args || [];
    const env = Object.fromEntries((c.env || []).map((e) => [e.name, e]));
    const flags = {};
    for (let i = 0; i < argv.length; i++) {
      const a = argv[i];
      for (const m of a.matchAll(/\$\(([A-Za-z_][A-Za-z0-9_]*)\)/g))
        if (!env[m[1]]) fail(cid, `args use $(${m[1]}), which env does not define`);
      if (!a.startsWith("--")) continue;
      const [flag, inline] = a.includes("=") ? [a.slice(0, a.indexOf("=")), a.slice(a.indexOf("=") + 1)] : [a, undefined];
      if (flag === "--insecure") fail(cid, "--insecure: plaintext is never deployed");
      const value = inline !== undefined ? inline : argv[i + 1] !== undefined && !argv[i + 1].startsWith("--") ? argv[i + 1] : undefined;
      flags[flag] = value;
      const accepted = flagIn(text, flag);
      if (isPending(exe, flag)) {
        if (accepted) fail(cid, `${flag} is in deploy/k8s/pending-flags.txt but ${exe} now accepts it: remove it from the list`);
        else notes.add(`${exe} ${flag}: PENDING (the manifests need it; ${exe} --help does not list it yet)`);
      } else if (!accepted) fail(cid, `${exe} does not accept ${flag} (not in its --help)`);
    }
    // Resolve env values (configMapKeyRef) to check the robot's settings.
    const resolved = {};
    for (const [name, e] of Object.entries(env)) {
      if (e.value !== undefined) resolved[name] = e.value;
      const ref = e.valueFrom && e.valueFrom.configMapKeyRef;
      if (ref) {
        if (!configMaps[ref.name]) fail(cid, `env ${name}: ConfigMap ${ref.name} is not rendered`);
        else if (!(ref.key in configMaps[ref.name])) fail(cid, `env ${name}: ConfigMap ${ref.name} has no key ${ref.key}`);
        else resolved[name] = configMaps[ref.name][ref.key];
      }
    }
    const val = (f) => (flags[f] || "").replace(/\$\(([A-Za-z_0-9]+)\)/g, (_, v) => (v in resolved ? resolved[v] : `$(${v})`));
    const ports = c.ports || [];
    const portOf = (p) => (typeof p === "number" ? ports.find((x) => x.containerPort === p) : ports.find((x) => x.name === p));
    for (const f of ["--listen", "--metrics", "--health-listen"]) {
      if (flags[f] === undefined) continue;
      const port = Number(val(f).split(":").pop());
      if (!ports.some((p) => p.containerPort === port)) fail(cid, `${f} ${val(f)}: port ${port} is not a containerPort`);
      if (val(f).startsWith("127.")) fail(cid, `${f} ${val(f)} binds loopback: unreachable from outside the pod`);
    }
    for (const pname of ["startupProbe", "livenessProbe", "readinessProbe"]) {
      const p = c[pname];
      if (!p) {
        if (pname !== "startupProbe") fail(cid, `no ${pname}`);
        continue;
      }
      const port = (p.grpc && p.grpc.port) || (p.tcpSocket && p.tcpSocket.port) || (p.httpGet && p.httpGet.port);
      if (port !== undefined && !portOf(port)) fail(cid, `${pname} port ${port} is not a container port`);
      if (p.exec) {
        const pc = p.exec.command || [];
        if (!pc[0] || !pc[0].startsWith("/usr/local/bin/") || !installs(path.basename(pc[0])))
          fail(cid, `${pname} runs ${pc[0]}, which deploy/container/Containerfile does not install`);
        const script = path.join(args.repo, "deploy/container", path.basename(pc[0] || ""));
        if (!fs.existsSync(script)) fail(cid, `${pname}: ${script} does not exist`);
        const metricsPort = flags["--metrics"] ? val("--metrics").split(":").pop() : null;
        if (!pc.slice(1).includes(metricsPort)) fail(cid, `${pname} ${JSON.stringify(pc)} does not check the --metrics port ${metricsPort}`);
      }
    }
    if (exe === "ruffini-aggregator" && !(c.readinessProbe && c.readinessProbe.grpc && c.livenessProbe && c.livenessProbe.grpc))
      fail(cid, "the aggregator's liveness and readiness are not grpc.health.v1 probes");
    // TLS from a Secret at /etc/ruffini/tls.
    if (val("--tls-dir") !== "/etc/ruffini/tls") fail(cid, "no --tls-dir /etc/ruffini/tls");
    const tlsMount = (c.volumeMounts || []).find((m) => m.mountPath === "/etc/ruffini/tls");
    if (!tlsMount || !tlsMount.readOnly) fail(cid, "no read-only volume mounted at /etc/ruffini/tls");
    else if (!(volumes[tlsMount.name] && volumes[tlsMount.name].secret)) fail(cid, "/etc/ruffini/tls is not a Secret volume");
    else notes.add(`${d.metadata.name}: needs Secret ${volumes[tlsMount.name].secret.secretName} (ca.crt, tls.crt, tls.key)`);
    // The scene.
    const scene = val("--scene");
    if (!scene.startsWith(sceneRoot)) fail(cid, `--scene ${scene} is not under ${sceneRoot} (baked into the image)`);
    const sceneFile = path.join(args.repo, "config", scene.slice(sceneRoot.length));
    let sceneDoc = null;
    if (!fs.existsSync(sceneFile)) fail(cid, `--scene ${scene}: ${sceneFile} does not exist`);
    else sceneDoc = YAML.parse(fs.readFileSync(sceneFile, "utf8"));
    if (exe === "ruffini-decoder")
      decoders.push({ id: cid, scene: sceneDoc, patch: val("--patch"), channel: val("--channel"),
        interrogator: val("--interrogator"), aggregator: val("--aggregator") });
  }
}

const selects = (sel, labels) => Object.entries(sel || {}).every(([k, v]) => labels[k] === v);

// 4. One decoder per patch of the scene; the aggregator address.
const aggregatorServices = services.filter((s) => (s.spec.ports || []).some((p) => p.name === "grpc"));
for (const dec of decoders) {
  const [host, port] = dec.aggregator.split(":");
  const svc = services.find((s) => s.metadata.name === host || `${s.metadata.name}.${s.metadata.namespace}.svc` === host);
  if (!svc) fail(dec.id, `--aggregator ${dec.aggregator}: no Service named ${host}`);
  else if (!(svc.spec.ports || []).some((p) => p.name === "grpc" && String(p.port) === port))
    fail(dec.id, `--aggregator ${dec.aggregator}: Service ${host} has no grpc port ${port}`);
}
if (decoders.length) {
  const scene = decoders[0].scene;
  const patches = scene && Array.isArray(scene.patches) ? scene.patches.map((p) => p.name) : [];
  const seen = {};
  for (const dec of decoders) {
    if (!patches.includes(dec.patch)) fail(dec.id, `--patch ${dec.patch} is not a patch of the scene (${patches.join(", ")})`);
    if (seen[dec.patch]) fail(dec.id, `patch ${dec.patch} has a second decoder (${seen[dec.patch]})`);
    seen[dec.patch] = dec.id;
    const key = `${dec.interrogator} channel ${dec.channel}`;
    const other = decoders.find((o) => o !== dec && `${o.interrogator} channel ${o.channel}` === key);
    if (other) fail(dec.id, `${key} is also read by ${other.id}`);
  }
  for (const p of patches) if (!seen[p]) fail(`overlay ${args.overlay}`, `the scene's patch ${p} has no decoder`);
  notes.add(`${decoders.length} decoders for ${patches.length} scene patches`);
}

// 3. Services and NetworkPolicies against the pods they select.
for (const s of services) {
  const id = `Service/${s.metadata.name}`;
  const pods = podsByLabels.filter(([labels]) => selects(s.spec.selector, labels));
  if (pods.length !== 1) fail(id, `selects ${pods.length} Deployments' pods, expected 1`);
  for (const p of s.spec.ports || [])
    for (const [, containers] of pods)
      if (!containers.some((c) => (c.ports || []).some((x) => x.name === p.targetPort || x.containerPort === p.targetPort)))
        fail(id, `targetPort ${p.targetPort} is not a port of the selected pods`);
}
for (const np of all("NetworkPolicy")) {
  const id = `NetworkPolicy/${np.metadata.name}`;
  const pods = podsByLabels.filter(([labels]) => selects(np.spec.podSelector.matchLabels, labels));
  if (pods.length === 0) fail(id, "selects no pod");
  for (const rule of np.spec.ingress || [])
    for (const p of rule.ports || [])
      for (const [, containers, name] of pods)
        if (!containers.some((c) => (c.ports || []).some((x) => x.containerPort === p.port || x.name === p.port)))
          fail(id, `ingress port ${p.port} is not a port of ${name}`);
  for (const rule of np.spec.egress || [])
    for (const to of rule.to || []) {
      if (!to.podSelector || to.namespaceSelector) continue;
      const targets = podsByLabels.filter(([labels]) => selects(to.podSelector.matchLabels, labels));
      if (targets.length === 0) fail(id, `egress to ${JSON.stringify(to.podSelector.matchLabels)} selects no pod`);
      for (const p of rule.ports || [])
        for (const [, containers, name] of targets)
          if (!containers.some((c) => (c.ports || []).some((x) => x.containerPort === p.port)))
            fail(id, `egress port ${p.port} is not a port of ${name}`);
    }
}

// The compose demo (deploy/container/compose.yaml) runs today's executables: every flag must be accepted now
// (no pending ones), each decoder's healthcheck must read its --metrics port, and Prometheus must scrape every
// service's --metrics port by its compose name.
if (args.compose) {
  const compose = YAML.parse(fs.readFileSync(args.compose, "utf8"), { merge: true });
  const metricsPorts = [];
  for (const [name, svc] of Object.entries(compose.services || {})) {
    const id = `compose service ${name}`;
    const cmd = svc.command || [];
    if (!String(cmd[0] || "").startsWith("/usr/local/bin/ruffini")) continue;
    const exe = path.basename(cmd[0]);
    if (!installs(exe)) fail(id, `${exe} is not installed by deploy/container/Containerfile`);
    if (!/^(localhost\/)?ruffini\/ruffini(:|$)/.test(svc.image || "")) fail(id, `image ${svc.image} is not ruffini/ruffini`);
    const text = help(exe);
    if (text === null) { fail(id, `${exe} --help was not captured`); continue; }
    let metrics = null;
    for (let i = 1; i < cmd.length; i++) {
      const a = String(cmd[i]);
      if (!a.startsWith("--")) continue;
      // The compose demo is a one-host development topology: plaintext is allowed there (and the services log it);
      // the Kubernetes manifests above may never carry --insecure.
      if (!flagIn(text, a)) fail(id, `${exe} does not accept ${a} (not in its --help)`);
      if (a === "--metrics") metrics = String(cmd[i + 1]).split(":").pop();
    }
    if (exe !== "ruffini-sim" && !cmd.map(String).some((a) => a === "--insecure" || a === "--tls-dir"))
      fail(id, `${exe} needs --tls-dir DIR or --insecure (it refuses to start without one)`);
    if (metrics) metricsPorts.push(`${name}:${metrics}`);
    const hc = svc.healthcheck && svc.healthcheck.test;
    if (exe === "ruffini-decoder" && !(hc && hc.includes("/usr/local/bin/ruffini-ready") && hc.includes(metrics)))
      fail(id, `healthcheck ${JSON.stringify(hc)} does not run ruffini-ready on the --metrics port ${metrics}`);
  }
  const promFile = path.join(path.dirname(args.compose), "prometheus-compose.yml");
  const prom = fs.existsSync(promFile) ? fs.readFileSync(promFile, "utf8") : "";
  for (const target of metricsPorts)
    if (!prom.includes(`"${target}"`)) fail(promFile, `does not scrape ${target}`);
  notes.add(`compose: ${metricsPorts.length} metrics endpoints scraped, every flag accepted today`);
}

const counts = Object.entries(byKind).map(([k, v]) => `${v.length} ${k}`).join(", ");
for (const n of notes) console.log(`  note: ${n}`);
if (problems.length) {
  for (const p of problems) console.log(`  FAIL ${p}`);
  console.log(`check-manifests ${args.overlay}: ${problems.length} problem(s) in ${docs.length} objects (${counts})`);
  process.exit(1);
}
console.log(`check-manifests ${args.overlay}: ${docs.length} objects valid and consistent (${counts})`);
