#!/usr/bin/env bash
# Runs deploy/Dockerfile's steps on this machine, without Docker (no Docker engine here):
#   1. the build stage's RUN steps, read from the Dockerfile and run in order from the repository
#      root (deploy/setup.sh --deps-only, the build through deploy/setup.sh, the staging), with
#      the build folder and the stage folder moved to local ones;
#   2. the runtime stage, as far as it goes without an image: its package list resolves in
#      Debian's archive (apt-get install --simulate), the entry point and the health check's
#      program are staged;
#   3. the staged rpsrd started as the image's non-root user (uid 10001) on free loopback ports,
#      the image's HEALTHCHECK command run against it until it reports SERVING, and SIGTERM
#      ending it cleanly.
#
#   deploy/dockerfile_steps.sh [--build-dir DIR] [--stage-dir DIR] [--no-compile] [--no-deps]
#     --build-dir   build folder (default: build-docker/ in the repository)
#     --no-compile  skip the compiling RUN step: DIR already holds rpsrd and rpsr (the test suite)
#     --no-deps     skip the dependency step (it needs root)
# Exit status 0: all passed; 1: a step failed; 77: --no-compile and rpsrd is not built.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
dockerfile=$here/deploy/Dockerfile
build_dir=$here/build-docker
stage_dir=
compile=1
deps=1
while [ $# -gt 0 ]; do
  case "$1" in
    --build-dir) build_dir=$2; shift 2 ;;
    --stage-dir) stage_dir=$2; shift 2 ;;
    --no-compile) compile=0; shift ;;
    --no-deps) deps=0; shift ;;
    -h|--help) sed -n '2,20p' "$0"; exit 0 ;;
    *) echo "dockerfile_steps.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
build_dir=$(mkdir -p "$build_dir" && cd "$build_dir" && pwd)
work=$(mktemp -d)
server_pid=
cleanup() {
  if [ -n "$server_pid" ] && kill -0 "$server_pid" 2>/dev/null; then kill -KILL "$server_pid"; fi
  rm -rf "$work"
}
trap cleanup EXIT
[ -n "$stage_dir" ] || stage_dir=$work/stage
fail() { echo "dockerfile_steps.sh: FAIL: $*" >&2; exit 1; }
step() { echo "dockerfile_steps.sh: $*"; }

if [ "$compile" -eq 0 ] && { [ ! -x "$build_dir/server/rpsrd" ] || [ ! -x "$build_dir/client/cli/rpsr" ]; }; then
  echo "dockerfile_steps.sh: SKIP: $build_dir has no built rpsrd and rpsr (build them first)"
  exit 77
fi

# The stages' instructions (one instruction a line, as the Dockerfile's header asks).
stage_lines() {  # stage_lines NAME: the lines of the stage "FROM ... AS NAME"
  awk -v name="$1" 'toupper($1) == "FROM" { s = (tolower($NF) == name); next } s' "$dockerfile"
}
mapfile -t build_runs < <(stage_lines build | sed -n 's/^RUN //p')
[ ${#build_runs[@]} -ge 3 ] || fail "expected at least 3 RUN steps in the build stage, found ${#build_runs[@]}"
grep -q '^COPY \. \.' <(stage_lines build) || fail "the build stage does not copy the sources"

# The build stage's ENV, then the local folders instead of the image's.
while read -r assignment; do
  export "${assignment?}"
done < <(stage_lines build | sed -n 's/^ENV //p' | tr ' ' '\n' | grep '=')
export RPSR_BUILD_DIR=$build_dir RPSR_STAGE_DIR=$stage_dir RPSR_BUILD_JOBS=${RPSR_LOCAL_JOBS:-2}

# 1. The build stage's RUN steps.
cd "$here"
ran_setup=0
for run in "${build_runs[@]}"; do
  if [[ "$run" == *"deploy/setup.sh --deps-only"* ]]; then
    if [ "$deps" -eq 0 ]; then step "skipped (--no-deps): $run"; continue; fi
    if [ "$(id -u)" -ne 0 ] && ! sudo -n true 2>/dev/null; then
      step "skipped (needs root or sudo): $run"
      continue
    fi
  elif [[ "$run" == *"deploy/setup.sh"* ]]; then
    ran_setup=1
    if [ "$compile" -eq 0 ]; then step "skipped (--no-compile): $run"; continue; fi
  fi
  step "RUN $run"
  bash -euo pipefail -c "$run" || fail "build-stage step failed: $run"
done
[ "$ran_setup" -eq 1 ] || fail "the build stage never builds through deploy/setup.sh"

# 2. The runtime stage.
runtime=$(stage_lines runtime)
packages=$stage_dir/usr/local/share/rpsr/runtime-packages.txt
[ -s "$packages" ] || fail "the staging wrote no $packages"
grep -q 'runtime-packages.txt' <<<"$runtime" || fail "the runtime stage does not install runtime-packages.txt"
step "runtime packages: $(tr '\n' ' ' <"$packages")"
# shellcheck disable=SC2046
apt-get install --simulate --no-install-recommends $(cat "$packages") >"$work/apt.log" 2>&1 ||
  { cat "$work/apt.log" >&2; fail "the runtime packages do not resolve in this machine's archive"; }
user_line=$(grep '^USER ' <<<"$runtime") || fail "the runtime stage sets no USER"
uid=${user_line#USER }
uid=${uid%%:*}
[ "$uid" != 0 ] && [ "$uid" != root ] || fail "the runtime stage runs as root"
grep -q "useradd .*--uid $uid" <<<"$runtime" || fail "no useradd creates uid $uid"
entrypoint=$(sed -n 's/^ENTRYPOINT \["\([^"]*\)".*/\1/p' <<<"$runtime")
health=$(sed -n 's/^HEALTHCHECK .*CMD \[\(.*\)\]$/\1/p' <<<"$runtime" | tr -d '"' | tr ',' ' ')
[ -n "$health" ] || fail "the runtime stage has no HEALTHCHECK CMD [...]"
read -r -a health_cmd <<<"$health"
for program in "$entrypoint" "${health_cmd[0]}"; do
  [ -x "$stage_dir/usr/local/bin/$program" ] || fail "$program is not staged in /usr/local/bin"
done
[ -n "$(ls "$stage_dir"/usr/local/share/rpsr/models/*/model.rpsrw 2>/dev/null)" ] ||
  fail "no model staged"

# 3. The staged server as the image's user, probed by the image's health check.
as_user=(setpriv --reuid="$uid" --regid="$uid" --clear-groups)
if [ "$(id -u)" -ne 0 ]; then as_user=(); fi
chmod -R a+rX "$stage_dir" "$work"
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
port=$(free_port)
metrics_port=$(free_port)
export PATH=$stage_dir/usr/local/bin:$PATH
step "starting the staged $entrypoint as uid $uid on 127.0.0.1:$port"
(cd "$work" && exec "${as_user[@]}" "$stage_dir/usr/local/bin/$entrypoint" \
   --address="127.0.0.1:$port" --metrics_address="127.0.0.1:$metrics_port" \
   >"$work/rpsrd.log" 2>&1) &
server_pid=$!
probe=("${health_cmd[@]//127.0.0.1:50051/127.0.0.1:$port}")
healthy=0
for _ in $(seq 1 120); do
  if "${as_user[@]}" "${probe[@]}" >"$work/probe.log" 2>&1; then healthy=1; break; fi
  kill -0 "$server_pid" 2>/dev/null || { cat "$work/rpsrd.log" >&2; fail "rpsrd exited at start"; }
  sleep 0.5
done
[ "$healthy" -eq 1 ] || { cat "$work/rpsrd.log" "$work/probe.log" >&2; fail "health check never passed: ${probe[*]}"; }
step "health check passed: ${probe[*]}"
kill -TERM "$server_pid"
status=0
for _ in $(seq 1 60); do kill -0 "$server_pid" 2>/dev/null || break; sleep 0.5; done
if kill -0 "$server_pid" 2>/dev/null; then fail "rpsrd still running 30 s after SIGTERM"; fi
wait "$server_pid" || status=$?
server_pid=
[ "$status" -eq 0 ] || { cat "$work/rpsrd.log" >&2; fail "rpsrd exited with $status after SIGTERM"; }
step "SIGTERM: rpsrd drained and exited 0"
echo "dockerfile_steps.sh: PASS"
