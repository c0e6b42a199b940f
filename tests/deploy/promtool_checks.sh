#!/usr/bin/env bash
# promtool on deploy/prometheus: `config` checks both Prometheus configs (and the rule files they
# load), `rules` the alert rules, `test` runs the alerts' unit tests (alerts_test.yml).
#   tests/deploy/promtool_checks.sh config|rules|test
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
if ! command -v promtool >/dev/null; then
  echo "SKIP: promtool not installed (Debian package prometheus; deploy/setup.sh installs it)"
  exit 77
fi
cd "$root"
case "${1:-}" in
  config) promtool check config deploy/prometheus/prometheus.yml deploy/prometheus/prometheus-k8s.yml ;;
  rules) promtool check rules deploy/prometheus/alerts.yml ;;
  test) promtool test rules tests/deploy/alerts_test.yml ;;
  *) echo "usage: $0 config|rules|test" >&2; exit 2 ;;
esac
