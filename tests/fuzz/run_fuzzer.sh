#!/usr/bin/env bash
# Builds one libFuzzer target of tests/fuzz with clang (ASan + UBSan) and runs it for a bounded
# time on a copy of its seed corpus.
#
#   tests/fuzz/run_fuzzer.sh <ply|pcd> <output dir> [seconds, default 20]
#
# The output dir receives the binary, the working corpus (seeds + what the run found) and any
# crash-* / leak-* / timeout-* artifacts. Exit status: 0 when the run ends without a finding,
# the fuzzer's non-zero status when it finds one, 77 (ctest's skip) when clang++ or the libFuzzer
# runtime is not available. CLANGXX overrides the compiler.
set -euo pipefail

if [ $# -lt 2 ]; then
  echo "usage: $0 <ply|pcd> <output dir> [seconds]" >&2
  exit 2
fi
format=$1
out=$2
seconds=${3:-20}
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
root=$(cd "$here/../.." && pwd)

case "$format" in
  ply) sources=(core/io/ply.cc) ;;
  pcd) sources=(core/io/pcd.cc) ;;
  *) echo "$0: unknown fuzzer '$format' (ply, pcd)" >&2; exit 2 ;;
esac
sources+=(core/io/binary_scalars.cc core/io/text_tokens.cc core/io/file_bytes.cc
          core/cloud/point_cloud.cc "tests/fuzz/${format}_fuzzer.cc")

clangxx=${CLANGXX:-}
if [ -z "$clangxx" ]; then
  for candidate in clang++ clang++-19 clang++-18 clang++-17 clang++-16 clang++-15 clang++-14; do
    if command -v "$candidate" >/dev/null 2>&1; then clangxx=$candidate; break; fi
  done
fi
if [ -z "$clangxx" ]; then
  echo "$0: no clang++ found; skipping the $format fuzzer" >&2
  exit 77
fi

mkdir -p "$out"
# Is the libFuzzer runtime there? A trivial target must link.
probe="$out/libfuzzer_probe"
printf '%s\n' '#include <cstddef>' '#include <cstdint>' \
  'extern "C" int LLVMFuzzerTestOneInput(const uint8_t*, size_t) { return 0; }' >"$probe.cc"
if ! "$clangxx" -fsanitize=fuzzer "$probe.cc" -o "$probe" >"$probe.log" 2>&1; then
  echo "$0: $clangxx cannot link -fsanitize=fuzzer (no libFuzzer runtime); skipping" >&2
  exit 77
fi

if pkg-config --exists absl_status absl_statusor absl_strings 2>/dev/null; then
  read -r -a absl_libs <<<"$(pkg-config --libs absl_status absl_statusor absl_strings)"
else
  absl_libs=(-labsl_statusor -labsl_status -labsl_cord -labsl_cordz_info -labsl_cord_internal
             -labsl_cordz_functions -labsl_cordz_handle -labsl_exponential_biased
             -labsl_synchronization -labsl_graphcycles_internal -labsl_time -labsl_civil_time
             -labsl_time_zone -labsl_stacktrace -labsl_symbolize -labsl_debugging_internal
             -labsl_demangle_internal -labsl_malloc_internal -labsl_str_format_internal
             -labsl_strerror -labsl_bad_optional_access -labsl_bad_variant_access
             -labsl_strings -labsl_strings_internal -labsl_int128 -labsl_throw_delegate
             -labsl_base -labsl_spinlock_wait -labsl_raw_logging_internal -labsl_log_severity)
fi

binary="$out/${format}_fuzzer"
echo "$0: building $binary with $clangxx"
(cd "$root" && "$clangxx" -std=c++20 -O1 -g -fno-omit-frame-pointer \
  -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
  -I"$root" -I/usr/include/eigen3 "${sources[@]}" "${absl_libs[@]}" -o "$binary")

corpus="$out/corpus"
mkdir -p "$corpus"
cp -f "$here/corpus/$format/"* "$corpus/"

echo "$0: running $binary for ${seconds}s"
# -malloc_limit_mb: a single allocation over 512 MiB is reported as a finding, so a parser that
# trusts a declared size fails here even when the machine has the memory.
"$binary" "$corpus" -dict="$here/$format.dict" -max_total_time="$seconds" -timeout=10 \
  -rss_limit_mb=2048 -malloc_limit_mb=512 -max_len=65536 -print_final_stats=1 \
  -artifact_prefix="$out/"
