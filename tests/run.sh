#!/usr/bin/env bash
# Builds rpsr if needed and runs the whole test suite through ctest.
#
#   tests/run.sh                 # everything
#   tests/run.sh -L unit         # extra arguments go to ctest (labels: unit, property, fuzz, e2e)
#
# Configures build/ the same way deploy/setup.sh does when it does not exist yet.
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$here"

# Style first: it is the cheapest check and the one most often broken.
if command -v clang-format >/dev/null; then
  mapfile -t sources < <(git ls-files '*.h' '*.cc' 2>/dev/null || true)
  if [ ${#sources[@]} -gt 0 ]; then
    if ! clang-format --dry-run --Werror "${sources[@]}" 2>/tmp/rpsr-format.log; then
      echo "tests/run.sh: clang-format finds unformatted files (run clang-format -i on them):" >&2
      grep -oE '^[^: ]+\.(h|cc):' /tmp/rpsr-format.log | sort -u >&2
      exit 1
    fi
  fi
else
  echo "tests/run.sh: clang-format not installed; style check skipped"
fi

if [ ! -f build/build.ninja ]; then
  cmake_args=(-G Ninja -DCMAKE_BUILD_TYPE=Release)
  command -v ccache >/dev/null && cmake_args+=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  cmake -S . -B build "${cmake_args[@]}"
fi
cmake --build build -j "${RPSR_BUILD_JOBS:-2}"

# OMP_WAIT_POLICY=PASSIVE: OpenMP spin-waiting collapses LibTorch when other threads are busy.
export OMP_WAIT_POLICY=PASSIVE
cd build
ctest --output-on-failure -j "${RPSR_TEST_JOBS:-2}" --timeout 600 "$@"
