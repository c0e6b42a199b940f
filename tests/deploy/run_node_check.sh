#!/usr/bin/env bash
# Schema and consistency checks of deploy/k8s (check_manifests.mjs) with the npm package
# kubernetes-models (the Kubernetes OpenAPI schemas, offline once installed). Debian has no
# Kubernetes schema validator (no kubeconform or kubeval); npm is the other registry these
# machines reach. The packages install once into BUILD_DIR/deploy-node from package-lock.json.
#   tests/deploy/run_node_check.sh BUILD_DIR
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
root=$(cd "$here/../.." && pwd)
build_dir=${1:?usage: $0 BUILD_DIR}
mkdir -p "$build_dir"
prefix=$(cd "$build_dir" && pwd)/deploy-node
for tool in node npm; do
  if ! command -v "$tool" >/dev/null; then
    echo "SKIP: $tool not installed (Node.js runs the Kubernetes schema check)"
    exit 77
  fi
done
mkdir -p "$prefix"
if ! cmp -s "$here/package-lock.json" "$prefix/package-lock.json" || [ ! -d "$prefix/node_modules/kubernetes-models" ]; then
  cp "$here/package.json" "$here/package-lock.json" "$prefix/"
  if ! (cd "$prefix" && timeout 300 npm ci --no-audit --no-fund --loglevel=error >npm.log 2>&1); then
    tail -5 "$prefix/npm.log"
    rm -f "$prefix/package-lock.json"
    echo "SKIP: npm could not install kubernetes-models (registry unreachable?)"
    exit 77
  fi
fi
RPSR_NODE_MODULES=$prefix/node_modules exec node "$here/check_manifests.mjs" "$root"
