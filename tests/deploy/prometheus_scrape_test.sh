#!/usr/bin/env bash
# A real Prometheus (Debian's, deploy/prometheus/prometheus.yml with its alert rules) on
# 127.0.0.1 scraping a real rpsrd started with deploy/k8s/configmap.yaml's flags; its HTTP API must show the target up, rpsr metrics with the
# model loaded, the request counters of a few real calls by method and code, and the alert rules
# loaded and healthy. Free ports, a temporary folder, both
# processes ended at exit.
#   tests/deploy/prometheus_scrape_test.sh RPSRD_BINARY
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
rpsrd=${1:-}
if [ -z "$rpsrd" ] || [ ! -x "$rpsrd" ]; then
  echo "SKIP: rpsrd is not built ('${rpsrd}')"
  exit 77
fi
if ! command -v prometheus >/dev/null; then
  echo "SKIP: prometheus not installed (Debian package prometheus; deploy/setup.sh installs it)"
  exit 77
fi
for tool in curl jq python3; do
  command -v "$tool" >/dev/null || { echo "SKIP: $tool not installed"; exit 77; }
done
if ! /usr/bin/python3 -c 'import grpc' 2>/dev/null; then
  echo "SKIP: python3-grpcio not installed (Debian package; deploy/setup.sh installs it)"
  exit 77
fi

work=$(mktemp -d)
pids=()
cleanup() {
  for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
  for pid in "${pids[@]}"; do wait "$pid" 2>/dev/null || true; done
  rm -rf "$work"
}
trap cleanup EXIT
fail() {
  echo "FAIL: $*" >&2
  echo "--- rpsrd log (tail)" >&2; tail -20 "$work/rpsrd.log" >&2 || true
  echo "--- prometheus log (tail)" >&2; tail -20 "$work/prometheus.log" >&2 || true
  exit 1
}
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
grpc_port=$(free_port)
metrics_port=$(free_port)
prom_port=$(free_port)

# rpsrd runs with the Kubernetes ConfigMap's flag file (every flag and value must parse), its
# addresses moved to free loopback ports (later flags win).
awk '/rpsrd.flags: \|/ {f = 1; next} f && /^    / {sub(/^    /, ""); print; next} f {exit}' \
  "$root/deploy/k8s/configmap.yaml" >"$work/rpsrd.flags"
[ "$(grep -c '^--' "$work/rpsrd.flags")" -ge 10 ] || fail "could not read the flags of deploy/k8s/configmap.yaml"
OMP_WAIT_POLICY=PASSIVE "$rpsrd" --flagfile="$work/rpsrd.flags" --address="127.0.0.1:$grpc_port" \
  --metrics_address="127.0.0.1:$metrics_port" --log_requests=false >"$work/rpsrd.log" 2>&1 &
pids+=($!)

# The shipped config, pointed at this rpsrd and this Prometheus, scraping every second.
mkdir -p "$work/config"
cp "$root/deploy/prometheus/alerts.yml" "$work/config/"
sed -e "s/\"rpsrd:9464\"/\"127.0.0.1:$metrics_port\"/" -e "s/\"localhost:9090\"/\"127.0.0.1:$prom_port\"/" \
    -e 's/scrape_interval: 15s/scrape_interval: 1s/' -e 's/evaluation_interval: 15s/evaluation_interval: 1s/' \
    "$root/deploy/prometheus/prometheus.yml" >"$work/config/prometheus.yml"
grep -q "127.0.0.1:$metrics_port" "$work/config/prometheus.yml" || fail "could not point prometheus.yml at rpsrd"
prometheus --config.file="$work/config/prometheus.yml" --storage.tsdb.path="$work/data" \
  --web.listen-address="127.0.0.1:$prom_port" >"$work/prometheus.log" 2>&1 &
pids+=($!)

api=http://127.0.0.1:$prom_port/api/v1
query() { curl -sf --get --data-urlencode "query=$1" "$api/query"; }
# Up to 90 s: rpsrd loads the model (a few seconds), Prometheus starts and scrapes every second.
deadline=$((SECONDS + 90))
until [ "$(query 'rpsr_model_loaded{job="rpsrd"}' 2>/dev/null | jq -r '.data.result[0].value[1] // empty')" = 1 ]; do
  [ $SECONDS -lt $deadline ] || fail "Prometheus never saw rpsr_model_loaded == 1"
  for pid in "${pids[@]}"; do kill -0 "$pid" 2>/dev/null || fail "a process exited early"; done
  sleep 1
done
echo "rpsr_model_loaded = 1 after $SECONDS s"

# A few calls, so that the request counters carry method and code labels: GetServerInfo (OK) and
# CloseSession of an unknown session (NOT_FOUND), messages encoded by hand.
/usr/bin/python3 - "127.0.0.1:$grpc_port" <<'PY' || fail "the gRPC calls did not answer as expected"
import sys, grpc
with grpc.insecure_channel(sys.argv[1]) as channel:
    info = channel.unary_unary("/rpsr.v1.RegistrationService/GetServerInfo")
    for _ in range(3):
        assert len(info(b"", timeout=10)) > 0
    close = channel.unary_unary("/rpsr.v1.RegistrationService/CloseSession")
    try:
        close(b"\x0a\x0bno-such-one", timeout=10)  # CloseSessionRequest{session_id}
        sys.exit("CloseSession of an unknown session succeeded")
    except grpc.RpcError as error:
        assert error.code() == grpc.StatusCode.NOT_FOUND, error
PY
deadline=$((SECONDS + 30))
until [ "$(query 'sum(rpsr_requests_total{job="rpsrd",method="GetServerInfo",code="OK"})' | jq -r '.data.result[0].value[1] // empty')" = 3 ] &&
      [ "$(query 'sum(rpsr_requests_total{job="rpsrd",method="CloseSession",code="NOT_FOUND"})' | jq -r '.data.result[0].value[1] // empty')" = 1 ]; do
  [ $SECONDS -lt $deadline ] || fail "Prometheus never saw the 3 GetServerInfo OK and 1 CloseSession NOT_FOUND calls"
  sleep 1
done
n=$(query 'rpsr_request_duration_seconds_count{job="rpsrd",method="GetServerInfo"}' | jq -r '.data.result[0].value[1] // empty')
[ "$n" = 3 ] || fail "rpsr_request_duration_seconds_count for GetServerInfo is '$n', not 3"

targets=$(curl -sf "$api/targets")
[ "$(jq -r '.data.activeTargets[] | select(.labels.job == "rpsrd") | .health' <<<"$targets")" = up ] ||
  fail "the rpsrd target is not up: $(jq -c '.data.activeTargets' <<<"$targets")"
# Series rpsrd exports before any call: the cache, sessions, evictions by reason, histograms.
reasons=$(query 'rpsr_cache_evictions_total{job="rpsrd"}' | jq -r '[.data.result[].metric.reason] | sort | join(",")')
[ "$reasons" = "memory_budget,released,session_closed,session_expired" ] || fail "eviction reasons: '$reasons'"
for metric in rpsr_cache_bytes rpsr_sessions rpsr_cache_clouds rpsr_queue_depth rpsr_batch_size_count \
              rpsr_queue_wait_seconds_bucket rpsr_network_seconds_count; do
  n=$(query "$metric{job=\"rpsrd\"}" | jq '.data.result | length')
  [ "$n" -ge 1 ] || fail "Prometheus has no $metric from rpsrd"
done
# The alert rules load and evaluate against the live series.
rules=$(curl -sf "$api/rules")
alerts=$(jq '[.data.groups[].rules[] | select(.type == "alerting")] | length' <<<"$rules")
bad=$(jq -r '[.data.groups[].rules[] | select(.health != "ok" and .health != "unknown") | .name] | join(",")' <<<"$rules")
[ "$alerts" -ge 7 ] || fail "only $alerts alerting rules loaded"
[ -z "$bad" ] || fail "rules in error: $bad"
# Every query of the Grafana dashboard parses and evaluates (its variables substituted).
dash=$root/deploy/grafana/dashboards/rpsr.json
checked=0
while IFS= read -r expr; do
  expr=${expr//\$__rate_interval/1m}
  expr=${expr//\$instance/.*}
  expr=${expr//\$method/Register}
  answer=$(curl -s --get --data-urlencode "query=$expr" "$api/query")
  [ "$(jq -r .status <<<"$answer")" = success ] || fail "dashboard query fails: $expr: $(jq -r .error <<<"$answer")"
  checked=$((checked + 1))
done < <(jq -r '.panels[] | .targets[]? | .expr' "$dash")
[ "$checked" -ge 20 ] || fail "only $checked dashboard queries found"
echo "all $checked dashboard queries evaluate"
# A freshly started, idle rpsrd fires nothing but may be pending on nothing either.
firing=$(curl -sf "$api/alerts" | jq -r '[.data.alerts[] | select(.state == "firing") | .labels.alertname] | join(",")')
[ -z "$firing" ] || fail "alerts firing on an idle rpsrd: $firing"
echo "PASS: Prometheus scraped rpsrd ($alerts alert rules loaded, target up, rpsr series present)"
