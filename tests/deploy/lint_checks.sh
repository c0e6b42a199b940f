#!/usr/bin/env bash
# Syntax and schema checks of deploy/ that need only Debian packages:
#   yaml      yamllint on every YAML file of deploy/ and tests/deploy/
#   compose   docker-compose's own schema check of deploy/compose.yaml (every profile)
#   grafana   the dashboard's JSON, its panels, and that every rpsr_ metric the dashboard and the
#             alerts query is one rpsrd exports (server/service_metrics.cc)
#   kustomize `kubectl kustomize deploy` renders every manifest plus the Envoy ConfigMap
#   tests/deploy/lint_checks.sh yaml|compose|grafana|kustomize
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
cd "$root"
need() {
  command -v "$1" >/dev/null && return 0
  echo "SKIP: $1 not installed ($2)"
  exit 77
}
fail() { echo "FAIL: $*" >&2; exit 1; }

case "${1:-}" in
  yaml)
    need yamllint "Debian package yamllint; deploy/setup.sh installs it"
    mapfile -t files < <(find deploy tests/deploy -name '*.yaml' -o -name '*.yml' | sort)
    [ ${#files[@]} -ge 12 ] || fail "found only ${#files[@]} YAML files"
    yamllint -f parsable -s -c tests/deploy/yamllint.yml "${files[@]}"
    echo "yamllint: ${#files[@]} files clean"
    ;;
  compose)
    need docker-compose "Debian package docker-compose; deploy/setup.sh installs it"
    docker-compose -f deploy/compose.yaml --profile affinity config -q
    services=$(docker-compose -f deploy/compose.yaml --profile affinity config --services | sort | tr '\n' ' ')
    [ "$services" = "envoy grafana prometheus rpsrd " ] || fail "compose services are '$services'"
    # Prometheus scrapes rpsrd by its compose name on the port rpsrd's command listens on.
    port=$(docker-compose -f deploy/compose.yaml config | sed -n 's/.*--metrics_address=0.0.0.0:\([0-9]*\).*/\1/p')
    grep -q "targets: \[\"rpsrd:$port\"\]" deploy/prometheus/prometheus.yml ||
      fail "prometheus.yml does not scrape rpsrd:$port"
    # rpsrd's command line: every flag is one rpsrd defines.
    defined=$(grep -oE 'ABSL_FLAG\([^,]+, *[a-z_0-9]+' server/rpsrd_main.cc | sed -E 's/.*, *//' | sort -u)
    flags=$(awk '/^  [a-z]+:$/ {s = ($1 == "rpsrd:")} s' deploy/compose.yaml | grep -oE -- '- --[a-z_0-9]+' | sed 's/- --//' | sort -u)
    [ "$(wc -w <<<"$flags")" -ge 3 ] || fail "found no flags in compose's rpsrd command"
    for flag in $flags; do
      grep -qx "$flag" <<<"$defined" || fail "compose passes rpsrd --$flag, which rpsrd does not define"
    done
    # Envoy (profile affinity) resolves the replicas by the name the rpsrd service is aliased to.
    envoy_host=$(sed -n 's/.*socket_address: {address: \([a-z-]*\), port_value: 50051}.*/\1/p' deploy/envoy/envoy.yaml)
    docker-compose -f deploy/compose.yaml config | grep -A3 'aliases:' | grep -q -- "- $envoy_host\$" ||
      fail "compose's rpsrd has no network alias '$envoy_host' (Envoy's cluster address)"
    echo "compose: valid; services $services"
    ;;
  grafana)
    need jq "Debian package jq"
    dash=deploy/grafana/dashboards/rpsr.json
    jq -e . "$dash" >/dev/null || fail "$dash is not JSON"
    jq -e '.uid and .title and (.panels | length > 10)' "$dash" >/dev/null || fail "$dash lacks uid, title or panels"
    [ "$(jq '[.panels[].id] | length' "$dash")" = "$(jq '[.panels[].id] | unique | length' "$dash")" ] ||
      fail "panel ids repeat"
    jq -e '[.panels[] | select(.type != "row") | .targets[]? | .expr] | all(length > 0)' "$dash" >/dev/null ||
      fail "a panel target has no expr"
    jq -e '[.panels[] | select(.type != "row") | .datasource.uid] | all(. == "${datasource}")' "$dash" >/dev/null ||
      fail "a panel does not use the \${datasource} variable"
    uid=$(sed -n 's/^ *uid: *//p' deploy/grafana/provisioning/datasources/prometheus.yml)
    jq -e --arg uid "$uid" '.templating.list[] | select(.name == "datasource") | .current.value == $uid' "$dash" >/dev/null ||
      fail "the dashboard's default data source is not the provisioned uid $uid"
    exprs=$(jq -r '.panels[] | .targets[]? | .expr' "$dash")
    # What the issue asks the dashboard to show.
    for needle in 'rpsr_requests_total' 'rpsr_request_duration_seconds_bucket' 'rpsr_queue_wait_seconds_bucket' \
                  'rpsr_batch_size_bucket' 'rpsr_cache_hits_total' 'rpsr_cache_misses_total' 'rpsr_cache_bytes' \
                  'rpsr_sessions' 'sum by (code)'; do
      grep -qF "$needle" <<<"$exprs" || fail "no dashboard panel queries $needle"
    done
    # Every metric queried exists in rpsrd (histograms' _bucket/_sum/_count are its series).
    defined=$(grep -o '"rpsr_[a-z_]*"' server/service_metrics.cc | tr -d '"' | sort -u)
    [ "$(wc -l <<<"$defined")" -ge 10 ] || fail "found only $(wc -l <<<"$defined") metrics in server/service_metrics.cc"
    used=$( { echo "$exprs"; grep -h 'expr' -A3 deploy/prometheus/alerts.yml; } |
            grep -o 'rpsr_[a-z_]*' | sed -E 's/_(bucket|sum|count)$//' | sort -u)
    missing=$(comm -23 <(echo "$used") <(echo "$defined"))
    [ -z "$missing" ] || fail "queried but not exported by rpsrd: $(echo $missing)"
    echo "grafana: $(jq '.panels | length' "$dash") panels; $(wc -l <<<"$used") rpsr metrics queried, all exported"
    ;;
  kustomize)
    need kubectl "kubectl (its built-in kustomize renders deploy/kustomization.yaml offline)"
    out=$(kubectl kustomize deploy)
    kinds=$(grep '^kind:' <<<"$out" | sort | uniq -c | awk '{print $3 "=" $1}' | tr '\n' ' ')
    [ "$kinds" = "ConfigMap=2 Deployment=2 HorizontalPodAutoscaler=1 PodDisruptionBudget=2 Service=2 " ] ||
      fail "kustomize rendered $kinds"
    grep -q 'name: rpsr-envoy$' <<<"$out" || fail "no rpsr-envoy ConfigMap generated"
    grep -q 'lb_policy: RING_HASH' <<<"$out" || fail "the generated ConfigMap lacks envoy.yaml"
    echo "kustomize: $kinds"
    ;;
  *) echo "usage: $0 yaml|compose|grafana|kustomize" >&2; exit 2 ;;
esac
