#!/usr/bin/env bash
# Installs the Debian 12 packages that only the benchmarks in bench/ need:
#   python3-vtk9       VTK flying edges / marching cubes / quadric decimation (bench/py/iso_bench.py)
#   python3-numpy      arrays for the distance measurements (pulled in by vtk, listed for clarity)
#   python3-scipy      KD-tree for the surface distances (bench/py/iso_bench.py)
#   libopenvdb-tools   vdb_tool / vdb_print / vdb_render (OpenVDB comparison)
#   xvfb               X server for VTK's volume mappers, which need a render window (bench/py/render_bench.py)
#   libzfp-dev         optional: ZFP compressed-array comparison (skipped if unavailable)
#   python3-zfpy       ZFP fixed-accuracy rate-distortion beside the hierarchy file (bench/py/hierarchy_file_bench.py)
#   zstd               zstd -19 of the raw input (bench/py/hierarchy_file_bench.py, file_bench.py)
#   libcharls-dev      CharLS JPEG-LS, the lossless/near-lossless peer of bench/py/file_bench.py
#                      (scripts/build_bench_peers.sh builds bench/cpp/peers/jpegls_slices.cpp on it)
#   libjxl-tools       cjxl/djxl, JPEG XL lossless in bench/py/file_bench.py
# and from npm: gltfpack 1.3 (bench/py/convert_bench.py's meshoptimizer 1.x peer).
# Idempotent: checks every package with dpkg-query and runs apt-get update/install only when
# something is missing. Build dependencies of mlfe itself: scripts/install_deps.sh.
set -euo pipefail

REQUIRED=(python3-vtk9 python3-numpy python3-scipy libopenvdb-tools xvfb python3-zfpy zstd libcharls-dev libjxl-tools)
OPTIONAL=(libzfp-dev)

is_installed() {
  dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"
}

missing=()
for p in "${REQUIRED[@]}"; do is_installed "$p" || missing+=("$p"); done
missing_opt=()
for p in "${OPTIONAL[@]}"; do is_installed "$p" || missing_opt+=("$p"); done

# gltfpack 1.3 (npm; meshoptimizer 1.x's simplifier), the asset peer of bench/py/convert_bench.py.
if ! command -v gltfpack >/dev/null 2>&1; then
  if command -v npm >/dev/null 2>&1; then
    echo "mlfe bench: installing gltfpack@1.3 from npm" >&2
    npm install -g --no-audit --no-fund --silent gltfpack@1.3 >/dev/null 2>&1 \
      || echo "mlfe bench: warning: npm install gltfpack failed; convert_bench skips it" >&2
  else
    echo "mlfe bench: warning: no npm (scripts/install_deps.sh installs it); convert_bench skips gltfpack" >&2
  fi
fi

if [ "${#missing[@]}" -eq 0 ] && [ "${#missing_opt[@]}" -eq 0 ]; then
  echo "mlfe bench: all benchmark dependencies are installed" >&2
  exit 0
fi

SUDO=""
if [ "$(id -u)" != "0" ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive

echo "mlfe bench: installing ${missing[*]} ${missing_opt[*]}" >&2
$SUDO apt-get update -qq

if [ "${#missing[@]}" -gt 0 ]; then
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
for p in "${missing_opt[@]}"; do
  if ! $SUDO apt-get install -y -qq --no-install-recommends "$p" >/dev/null 2>&1; then
    echo "mlfe bench: warning: optional package $p could not be installed; skipping it" >&2
  fi
done

for p in "${REQUIRED[@]}"; do
  is_installed "$p" || { echo "mlfe bench: error: $p is still missing" >&2; exit 1; }
done
echo "mlfe bench: benchmark dependencies installed" >&2
