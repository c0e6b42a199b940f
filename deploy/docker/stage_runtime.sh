#!/usr/bin/env bash
# Stages what the runtime image holds, from a build folder, into DEST (deploy/Dockerfile's build
# stage runs it; deploy/dockerfile_steps.sh runs it here):
#   DEST/usr/local/bin/{rpsrd,rpsr,grpc_health_check}
#   DEST/usr/local/share/rpsr/models/<name>/   the shipped models (also embedded in the binaries)
#   DEST/usr/local/share/rpsr/runtime-packages.txt
#       the Debian packages that own the shared libraries the binaries link directly; the
#       runtime stage installs them (apt brings their own dependencies).
#
#   deploy/docker/stage_runtime.sh BUILD_DIR DEST
set -euo pipefail

if [ $# -ne 2 ]; then
  echo "usage: $0 BUILD_DIR DEST" >&2
  exit 2
fi
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
build=$(cd "$1" && pwd)
dest=$2

binaries=("$build/server/rpsrd" "$build/client/cli/rpsr")
for b in "${binaries[@]}"; do
  if [ ! -x "$b" ]; then
    echo "stage_runtime.sh: $b is missing: build the targets rpsrd and rpsr first" >&2
    exit 1
  fi
done

mkdir -p "$dest/usr/local/bin" "$dest/usr/local/share/rpsr/models"
for b in "${binaries[@]}"; do
  install -m 0755 "$b" "$dest/usr/local/bin/"
done
# The HEALTHCHECK's probe (grpc.health.v1 with python3-grpcio).
install -m 0755 "$here/deploy/docker/grpc_health_check.py" "$dest/usr/local/bin/grpc_health_check"
# Weights, confidence calibration and training record of each shipped model; not the
# optimizer's state or the training checkpoints.
for model in "$here"/core/models/*/; do
  name=$(basename "$model")
  mkdir -p "$dest/usr/local/share/rpsr/models/$name"
  for f in model.rpsrw confidence.txt TRAINING.md; do
    if [ -f "$model/$f" ]; then cp "$model/$f" "$dest/usr/local/share/rpsr/models/$name/"; fi
  done
done

# Where the loader finds each library (ldconfig's cache; ldd would load all ~330 of LibTorch's).
declare -A path_of=()
while read -r name flags _ path; do
  case "$flags" in *64*) [ -z "${path_of[$name]:-}" ] && path_of[$name]=$path ;; esac
done < <(ldconfig -p | tail -n +2)

# Each directly linked library, as the paths dpkg may have recorded for it: ldconfig gives /lib/...
# or /usr/lib/... (merged /usr) and alternatives' symlinks (libblas.so.3), so also the /usr twin
# and the resolved file.
declare -A candidates_of=()
for b in "${binaries[@]}"; do
  while read -r needed; do
    case "$needed" in ld-linux*) continue ;; esac  # the loader itself: libc6, in every image
    path=${path_of[$needed]:-}
    if [ -z "$path" ]; then
      echo "stage_runtime.sh: $b needs $needed, which the loader does not find" >&2
      exit 1
    fi
    real=$(readlink -f "$path")
    candidates_of[$needed]="$path /usr$path ${path#/usr} $real /usr$real ${real#/usr}"
  done < <(objdump -p "$b" | awk '$1 == "NEEDED" {print $2}')
done
# One pass over dpkg's file lists (dpkg -S per path takes ~1 s each here).
declare -A package_of=()
while read -r line; do  # /var/lib/dpkg/info/libfoo1:amd64.list:/usr/lib/.../libfoo.so.1
  pkg=$(basename "${line%%.list:*}")
  package_of[${line#*.list:}]=${pkg%%:*}
done < <(for n in "${!candidates_of[@]}"; do tr ' ' '\n' <<<"${candidates_of[$n]}"; done |
           sort -u | grep -HxF -f - /var/lib/dpkg/info/*.list || true)
packages=()
for needed in "${!candidates_of[@]}"; do
  pkg=
  for c in ${candidates_of[$needed]}; do
    if [ -n "${package_of[$c]:-}" ]; then pkg=${package_of[$c]}; break; fi
  done
  if [ -z "$pkg" ]; then
    echo "stage_runtime.sh: $needed belongs to no Debian package; the image would lack it" >&2
    exit 1
  fi
  packages+=("$pkg")
done
# libblas.so.3 resolves to whichever BLAS the alternatives chose; the image must get OpenBLAS
# (with the reference BLAS, LibTorch's GEMMs ran ~14x slower here).
packages+=(libopenblas0-openmp ca-certificates python3-grpcio)
printf '%s\n' "${packages[@]}" | sort -u >"$dest/usr/local/share/rpsr/runtime-packages.txt"
echo "stage_runtime.sh: staged $(ls "$dest/usr/local/bin" | wc -l) binaries," \
     "$(ls "$dest/usr/local/share/rpsr/models" | wc -l) model(s)," \
     "$(wc -l <"$dest/usr/local/share/rpsr/runtime-packages.txt") runtime packages into $dest"
