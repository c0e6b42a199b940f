#!/usr/bin/env bash
# Installs every dependency of rpsr from Debian 12's archive and builds the project into build/.
#
#   deploy/setup.sh              # dependencies + Release build of everything
#   deploy/setup.sh --deps-only  # dependencies only
#   deploy/setup.sh --core-only  # build core/ alone (no gRPC, server or client)
#   deploy/setup.sh --with-peers # also Open3D and PCL for tests/bench/peers (~300 pkgs, 1.1 GB)
#
# Runs as root (or with sudo available). Idempotent: re-running only rebuilds what changed.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
deps_only=0
core_only=0
with_peers=0
for arg in "$@"; do
  case "$arg" in
    --deps-only) deps_only=1 ;;
    --core-only) core_only=1 ;;
    --with-peers) with_peers=1 ;;
    -h|--help) sed -n '2,9p' "$0"; exit 0 ;;
    *) echo "setup.sh: unknown argument '$arg' (see --help)" >&2; exit 2 ;;
  esac
done

sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then sudo_cmd=(sudo); fi

# Build tools, the service stack, the network runtime and the test tools. libopenblas0-openmp is
# explicit: libtorch only recommends a BLAS, and with reference BLAS its GEMMs run ~14x slower.
packages=(
  cmake ninja-build g++ pkg-config ccache git
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
  libtorch-dev libopenblas0-openmp
  libeigen3-dev libabsl-dev prometheus-cpp-dev libcivetweb-dev
  libgtest-dev libgmock-dev libbenchmark-dev libnanoflann-dev
  libhdf5-dev libpng-dev
  # clang + its sanitizer/libFuzzer runtime build the PLY and PCD fuzzers (tests/fuzz/);
  # clang-format checks the style in tests/run.sh.
  clang clang-format libclang-rt-14-dev
  # promtool (Debian's prometheus), docker-compose, yamllint and jq check deploy/ (tests/deploy/);
  # python3-grpcio runs the container image's health probe (deploy/docker/grpc_health_check.py).
  prometheus docker-compose yamllint jq curl python3-grpcio
)
if [ "$with_peers" -eq 1 ]; then packages+=(libopen3d-dev libpcl-dev); fi

start=$(date +%s)
export DEBIAN_FRONTEND=noninteractive
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup.sh: installing ${#missing[@]} packages: ${missing[*]}"
  "${sudo_cmd[@]}" apt-get update -qq
  "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" \
    libopenblas0-openmp >/dev/null
fi
echo "setup.sh: dependencies ready after $(( $(date +%s) - start )) s"
[ "$deps_only" -eq 1 ] && exit 0

cmake_args=(-G Ninja -DCMAKE_BUILD_TYPE=Release)
command -v ccache >/dev/null && cmake_args+=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
if [ "$core_only" -eq 1 ]; then cmake_args+=(-DRPSR_CORE_ONLY=ON); fi
# RPSR_CMAKE_ARGS adds configure options and RPSR_BUILD_TARGETS limits the build to some targets,
# e.g. the container image (deploy/Dockerfile): RPSR_BUILD_TARGETS="rpsrd rpsr".
read -r -a extra_cmake_args <<<"${RPSR_CMAKE_ARGS:-}"
cmake_args+=("${extra_cmake_args[@]}")
read -r -a build_targets <<<"${RPSR_BUILD_TARGETS:-}"
# RPSR_BUILD_DIR: another build folder than build/ (deploy/dockerfile_steps.sh uses one).
build_dir="${RPSR_BUILD_DIR:-$here/build}"
target_args=()
if [ ${#build_targets[@]} -gt 0 ]; then target_args=(--target "${build_targets[@]}"); fi
cmake -S "$here" -B "$build_dir" "${cmake_args[@]}"
# Two jobs on this 2-core machine: a LibTorch TU takes ~1.5 GB, so more jobs only thrash.
cmake --build "$build_dir" -j "${RPSR_BUILD_JOBS:-2}" "${target_args[@]}"
echo "setup.sh: done after $(( $(date +%s) - start )) s"
