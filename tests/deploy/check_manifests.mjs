// Offline checks of the Kubernetes manifests (deploy/k8s/*.yaml) and their agreement with the
// rest of deploy/ and with rpsrd itself:
//  1. schema: every document validated by kubernetes-models (the Kubernetes OpenAPI schemas as
//     ajv validators: types, required fields, enums, formats such as quantities), plus a strict
//     pass that rejects fields the schema does not know (typos, wrong indentation), read from the
//     package's TypeScript interfaces;
//  2. consistency: selectors match pod labels, Services' target ports exist, the HPA and PDB
//     point at the Deployment, probes use gRPC on the gRPC port, every flag in the ConfigMap is
//     one rpsrd defines, the cache budget agrees with the memory limit and the alert, the drain
//     fits the grace period, Envoy's ring hash reaches the headless Service and its port.
//
//   node tests/deploy/check_manifests.mjs REPO_ROOT   (modules from NODE_PATH's kubernetes-models)
import fs from "node:fs";
import path from "node:path";
import { createRequire } from "node:module";

const root = path.resolve(process.argv[2] ?? ".");
const require = createRequire(path.resolve(process.env.RPSR_NODE_MODULES ?? root, "x.js"));
const YAML = require("yaml");
const modelsDir = path.dirname(require.resolve("kubernetes-models/package.json"));

let failures = 0;
const fail = (msg) => { failures++; console.error(`FAIL: ${msg}`); };
const check = (cond, msg) => { if (!cond) fail(msg); };

// ---- Loading -------------------------------------------------------------------------------
const k8sDir = path.join(root, "deploy/k8s");
const docs = [];
for (const file of fs.readdirSync(k8sDir).filter((f) => f.endsWith(".yaml")).sort()) {
  for (const doc of YAML.parseAllDocuments(fs.readFileSync(path.join(k8sDir, file), "utf8"))) {
    if (doc.errors.length) { fail(`${file}: ${doc.errors[0].message}`); continue; }
    const obj = doc.toJS();
    if (obj) docs.push({ file, obj });
  }
}
check(docs.length >= 8, `expected at least 8 manifests in deploy/k8s, found ${docs.length}`);
const where = (d) => `${d.file}: ${d.obj.kind}/${d.obj.metadata?.name}`;

// ---- 1. Schema -----------------------------------------------------------------------------
// apiVersion "apps/v1" -> kubernetes-models/apps/v1/<Kind>; "v1" -> kubernetes-models/v1/<Kind>.
function modelFile(apiVersion, kind) {
  return path.join(modelsDir, ...apiVersion.split("/"), `${kind}`);
}

// The strict pass: the fields of each interface, from the .d.ts files.
const interfaces = new Map(); // "<file>#<name>" -> {fields: Map(name -> type)}
function parseDts(file) {
  const text = fs.readFileSync(file, "utf8");
  const imports = new Map();
  for (const m of text.matchAll(/import \{ ([^}]+) \} from "([^"]+)"/g)) {
    for (const name of m[1].split(",").map((s) => s.trim())) imports.set(name, m[2]);
  }
  const aliases = new Map();
  for (const m of text.matchAll(/export \{ ([^}]+) \}/g)) {
    for (const pair of m[1].split(",")) {
      const [local, alias] = pair.split(" as ").map((s) => s.trim());
      if (alias) aliases.set(alias, local);
    }
  }
  const bodies = new Map();
  for (const m of text.matchAll(/export interface (\w+)(?: extends [\w, ]+)? \{\n([\s\S]*?)\n\}/g)) {
    const fields = new Map();
    const body = m[2].replace(/\/\*\*[\s\S]*?\*\//g, "")
                     .replace(/\{\s*\[key: string\]: ([^;]+);\s*\}/g, "Map<$1>");
    for (const f of body.matchAll(/^\s*"([^"]+)"\??: (.+);$/gm)) fields.set(f[1], f[2]);
    bodies.set(m[1], fields);
  }
  return { file, imports, aliases, bodies };
}
const parsed = new Map();
function dts(file) {
  if (!parsed.has(file)) parsed.set(file, parseDts(file));
  return parsed.get(file);
}
function resolveModule(fromFile, spec) {
  const base = spec.startsWith(".")
    ? path.resolve(path.dirname(fromFile), spec)
    : path.join(path.dirname(path.dirname(modelsDir)), spec.startsWith("@") ? "" : "", spec)
        .replace(`${path.sep}node_modules${path.sep}node_modules`, `${path.sep}node_modules`);
  for (const candidate of [`${base}.d.ts`, path.join(base, "index.d.ts")]) {
    if (fs.existsSync(candidate)) return candidate;
  }
  const viaRequire = path.join(path.dirname(require.resolve(`${spec.split("/").slice(0, spec.startsWith("@") ? 2 : 1).join("/")}/package.json`)),
                               spec.split("/").slice(spec.startsWith("@") ? 2 : 1).join("/"));
  for (const candidate of [`${viaRequire}.d.ts`, path.join(viaRequire, "index.d.ts")]) {
    if (fs.existsSync(candidate)) return candidate;
  }
  return null;
}
// The fields of the interface `name` as seen from `file`; null when it is not a known interface.
function fieldsOf(file, name) {
  const d = dts(file);
  const local = d.aliases.get(name) ?? name;
  if (d.bodies.has(local)) return d.bodies.get(local);
  if (d.imports.has(name)) {
    const target = resolveModule(file, d.imports.get(name));
    if (target) return fieldsOf(target, name);
  }
  return null;
}
let strictlyChecked = 0;
function strict(file, typeName, value, at, label) {
  const fields = fieldsOf(file, typeName);
  if (!fields) return;  // a scalar, IntOrString, Quantity, ...: ajv checked it
  if (value === null || typeof value !== "object" || Array.isArray(value)) return;
  strictlyChecked++;
  const d = dts(file);
  const local = d.aliases.get(typeName) ?? typeName;
  const home = d.bodies.has(local) ? file : resolveModule(file, d.imports.get(typeName));
  for (const [key, sub] of Object.entries(value)) {
    if (!fields.has(key)) { fail(`${label}: unknown field ${at}.${key}`); continue; }
    let type = fields.get(key).replace(/ \| null$/, "");
    const array = type.match(/^Array<(\w+)>$/);
    const map = type.match(/^Map<(\w+)>$/);
    if (array && Array.isArray(sub)) sub.forEach((e, i) => strict(home, array[1], e, `${at}.${key}[${i}]`, label));
    else if (map && sub && typeof sub === "object") for (const [k, v] of Object.entries(sub)) strict(home, map[1], v, `${at}.${key}.${k}`, label);
    else if (/^\w+$/.test(type)) strict(home, type, sub, `${at}.${key}`, label);
  }
}

for (const d of docs) {
  const { apiVersion, kind } = d.obj;
  const file = modelFile(apiVersion ?? "", kind ?? "");
  if (!fs.existsSync(`${file}.js`)) { fail(`${where(d)}: unknown apiVersion/kind ${apiVersion} ${kind}`); continue; }
  const Model = require(file)[kind];
  try {
    new Model(d.obj).validate();
  } catch (e) {
    fail(`${where(d)}: ${e.message}`);
  }
  strict(`${file}.d.ts`, `I${kind}`, d.obj, "", where(d));
}
check(strictlyChecked > 50, `the strict pass looked at only ${strictlyChecked} objects: is the .d.ts parsing broken?`);

// ---- 2. Consistency ------------------------------------------------------------------------
const find = (kind, name) => docs.map((d) => d.obj).find((o) => o.kind === kind && o.metadata?.name === name);
const matches = (selector, labels) =>
  Object.entries(selector ?? {}).every(([k, v]) => labels?.[k] === v) && Object.keys(selector ?? {}).length > 0;
const deployments = docs.map((d) => d.obj).filter((o) => o.kind === "Deployment");

for (const dep of deployments) {
  const labels = dep.spec.template.metadata.labels;
  check(matches(dep.spec.selector.matchLabels, labels), `Deployment/${dep.metadata.name}: selector does not match its pod labels`);
  for (const c of dep.spec.template.spec.containers) {
    check(c.resources?.requests?.cpu && c.resources?.requests?.memory, `Deployment/${dep.metadata.name}: container ${c.name} lacks cpu and memory requests`);
    check(c.resources?.limits?.memory, `Deployment/${dep.metadata.name}: container ${c.name} has no memory limit`);
  }
  for (const v of dep.spec.template.spec.volumes ?? []) {
    if (v.configMap) check(find("ConfigMap", v.configMap.name) || v.configMap.name === "rpsr-envoy",
                           `Deployment/${dep.metadata.name}: volume ${v.name} names no ConfigMap ${v.configMap.name}`);
  }
}
for (const svc of docs.map((d) => d.obj).filter((o) => o.kind === "Service")) {
  const dep = deployments.find((x) => matches(svc.spec.selector, x.spec.template.metadata.labels));
  if (!dep) { fail(`Service/${svc.metadata.name}: its selector matches no Deployment's pods`); continue; }
  const portNames = dep.spec.template.spec.containers.flatMap((c) => (c.ports ?? []).map((p) => p.name));
  for (const p of svc.spec.ports) {
    check(typeof p.targetPort !== "string" || portNames.includes(p.targetPort),
          `Service/${svc.metadata.name}: targetPort ${p.targetPort} is no port of Deployment/${dep.metadata.name}`);
  }
}
for (const pdb of docs.map((d) => d.obj).filter((o) => o.kind === "PodDisruptionBudget")) {
  check(deployments.some((x) => matches(pdb.spec.selector.matchLabels, x.spec.template.metadata.labels)),
        `PodDisruptionBudget/${pdb.metadata.name}: selects no Deployment's pods`);
}

// rpsrd itself.
const rpsrd = find("Deployment", "rpsrd");
const hpa = find("HorizontalPodAutoscaler", "rpsrd");
const flagsMap = find("ConfigMap", "rpsrd-flags");
if (!rpsrd || !hpa || !flagsMap || !find("PodDisruptionBudget", "rpsrd")) {
  fail("deploy/k8s needs Deployment, HorizontalPodAutoscaler, PodDisruptionBudget rpsrd and ConfigMap rpsrd-flags");
} else {
  check(hpa.spec.scaleTargetRef.kind === "Deployment" && hpa.spec.scaleTargetRef.name === "rpsrd", "the HPA does not scale Deployment/rpsrd");
  check(hpa.spec.minReplicas >= 2, "the HPA allows fewer than 2 replicas (a PDB with maxUnavailable 1 would then block drains)");
  const c = rpsrd.spec.template.spec.containers.find((x) => x.name === "rpsrd");
  const grpcPort = c.ports.find((p) => p.name === "grpc")?.containerPort;
  const metricsPort = c.ports.find((p) => p.name === "metrics")?.containerPort;
  for (const probe of ["startupProbe", "readinessProbe", "livenessProbe"]) {
    check(c[probe]?.grpc?.port === grpcPort, `rpsrd's ${probe} is not a gRPC health probe on the grpc port ${grpcPort}`);
  }
  check(c.args.includes("--flagfile=/etc/rpsr/rpsrd.flags"), "rpsrd does not read the ConfigMap's flag file");
  check((c.volumeMounts ?? []).some((m) => m.mountPath === "/etc/rpsr"), "the flag file is not mounted at /etc/rpsr");
  check(rpsrd.spec.template.spec.securityContext?.runAsNonRoot === true &&
        rpsrd.spec.template.spec.securityContext?.runAsUser === 10001, "rpsrd must run as the image's uid 10001");
  // Flags: each must be one of rpsrd's, and the addresses' ports the container's.
  const defined = new Set([...fs.readFileSync(path.join(root, "server/rpsrd_main.cc"), "utf8")
                             .matchAll(/ABSL_FLAG\(\s*[\w:<>]+\s*,\s*(\w+)/g)].map((m) => m[1]));
  check(defined.size > 10, `found only ${defined.size} flags in server/rpsrd_main.cc`);
  const flags = new Map();
  // Abseil's flag files: one --flag=value a line; lines starting with '#' are comments.
  for (const line of flagsMap.data["rpsrd.flags"].split("\n").map((l) => l.trim()).filter((l) => l && !l.startsWith("#"))) {
    const m = line.match(/^--(\w+)=(.*)$/);
    if (!m) { fail(`rpsrd.flags: '${line}' is not --flag=value`); continue; }
    check(defined.has(m[1]), `rpsrd.flags: --${m[1]} is not a flag of rpsrd (server/rpsrd_main.cc)`);
    flags.set(m[1], m[2]);
  }
  check(flags.get("address")?.endsWith(`:${grpcPort}`), `--address ${flags.get("address")} is not the container's grpc port ${grpcPort}`);
  check(flags.get("metrics_address")?.endsWith(`:${metricsPort}`), `--metrics_address is not the container's metrics port ${metricsPort}`);
  // Memory: the cache budget plus ~1 GiB of runtime below the limit; the alert at 90% of it.
  const bytes = (q) => { const m = String(q).match(/^(\d+)(Ki|Mi|Gi)?$/); return m ? Number(m[1]) * { Ki: 1024, Mi: 1024 ** 2, Gi: 1024 ** 3 }[m[2] ?? ""] || Number(m[1]) : NaN; };
  const budget = Number(flags.get("cache_memory_bytes"));
  check(budget > 0, "rpsrd.flags sets no --cache_memory_bytes");
  // Worst case: a full cache, every open upload at its largest (12 bytes a point until the tree is
  // built), and ~0.5 GiB of LibTorch, the model and buffers.
  const inFlight = Number(flags.get("max_open_streams")) * Number(flags.get("max_points_per_cloud")) * 12;
  check(inFlight > 0, "rpsrd.flags must set --max_open_streams and --max_points_per_cloud (uploads in flight hold their points)");
  // The prepared targets kept beside the cache (rpsrd's --prepared_target_bytes; unless set, its
  // default: BatchingOptions::prepared_target_bytes in server/rpsr_server.h, 160 MiB).
  const prepared = Number(flags.get("prepared_target_bytes") ?? 160 * 2 ** 20);
  check(prepared >= 0, "rpsrd.flags: --prepared_target_bytes must be a number of bytes");
  check(budget + inFlight + prepared + 2 ** 29 <= bytes(c.resources.limits.memory),
        `the memory limit ${c.resources.limits.memory} is below the cache budget (${budget}) + uploads in flight (${inFlight}) + prepared targets (${prepared}) + 0.5 GiB`);
  check(budget <= bytes(c.resources.requests.memory), `the memory request ${c.resources.requests.memory} is below the cache budget ${budget}`);
  const alerts = YAML.parse(fs.readFileSync(path.join(root, "deploy/prometheus/alerts.yml"), "utf8"));
  const cacheAlert = alerts.groups.flatMap((g) => g.rules).find((r) => r.alert === "RpsrCacheMemoryHigh");
  const threshold = cacheAlert?.expr.match(/rpsr_cache_bytes > 0\.9 \* (\d+)/);
  check(threshold && Number(threshold[1]) === budget, `RpsrCacheMemoryHigh's budget (${threshold?.[1]}) is not --cache_memory_bytes (${budget})`);
  // Drain: preStop + --drain_notice + --shutdown_grace within the pod's grace period.
  const seconds = (d) => { const m = String(d ?? "0s").match(/^(\d+)s$/); return m ? Number(m[1]) : NaN; };
  const preStop = Number(c.lifecycle?.preStop?.exec?.command?.[1] ?? 0);
  const drain = preStop + seconds(flags.get("drain_notice")) + seconds(flags.get("shutdown_grace"));
  check(drain < rpsrd.spec.template.spec.terminationGracePeriodSeconds,
        `preStop + --drain_notice + --shutdown_grace (${drain} s) does not fit terminationGracePeriodSeconds: a drain would be killed`);
  // Envoy's ring hash reaches the headless Service on the grpc port.
  const envoy = YAML.parse(fs.readFileSync(path.join(root, "deploy/envoy/envoy.yaml"), "utf8"));
  const cluster = envoy.static_resources.clusters.find((x) => x.name === "rpsrd");
  check(cluster?.lb_policy === "RING_HASH", "Envoy's rpsrd cluster is not RING_HASH");
  check(cluster?.health_checks?.some((h) => "grpc_health_check" in h), "Envoy does not health-check rpsrd through grpc.health.v1");
  const endpoint = cluster?.load_assignment.endpoints[0].lb_endpoints[0].endpoint.address.socket_address;
  const headless = find("Service", endpoint?.address);
  check(headless?.spec.clusterIP === "None", `Envoy resolves ${endpoint?.address}, which is no headless Service`);
  check(headless?.spec.ports.some((p) => p.port === endpoint.port_value && p.targetPort === "grpc"),
        `Envoy's port ${endpoint?.port_value} is not the headless Service's grpc port`);
  const routes = envoy.static_resources.listeners[0].filter_chains[0].filters[0].typed_config.route_config.virtual_hosts[0].routes;
  const hashed = routes.find((r) => r.match.prefix === "/");
  check(hashed?.route.hash_policy?.[0]?.header?.header_name === "x-rpsr-affinity" && hashed.route.hash_policy[0].terminal === true,
        "Envoy's catch-all route does not hash the x-rpsr-affinity header first");
  check(hashed?.route.hash_policy?.some((h) => h.connection_properties?.source_ip === true),
        "Envoy's catch-all route has no client-address fallback");
  const listenerPort = envoy.static_resources.listeners[0].address.socket_address.port_value;
  const envoyDep = find("Deployment", "rpsr-envoy");
  check(envoyDep?.spec.template.spec.containers[0].ports.some((p) => p.name === "grpc" && p.containerPort === listenerPort),
        `the Envoy Deployment does not expose Envoy's listener port ${listenerPort} as grpc`);
  // Prometheus in the cluster scrapes the headless Service on the metrics port.
  const prom = YAML.parse(fs.readFileSync(path.join(root, "deploy/prometheus/prometheus-k8s.yml"), "utf8"));
  const sd = prom.scrape_configs.find((s) => s.job_name === "rpsrd")?.dns_sd_configs?.[0];
  check(sd?.names?.includes(headless?.metadata.name) && sd?.port === metricsPort,
        "prometheus-k8s.yml does not scrape the headless Service on the metrics port");
}

if (failures) {
  console.error(`check_manifests: ${failures} problem(s)`);
  process.exit(1);
}
console.log(`check_manifests: ${docs.length} manifests valid (schema + ${strictlyChecked} objects checked strictly) and consistent`);
