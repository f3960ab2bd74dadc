#!/bin/bash
# build_bench_peers.sh: the benchmark peers that Debian does not package, built outside the
# CMake project into build/bench-peers/ (bench/py/convert_bench.py looks for them there).
#
#   meshopt_update  bench/cpp/peers/meshopt_update.cpp over meshoptimizer 1.2's src/*.cpp
#                   (meshopt_simplifyWithUpdate, 1.0+; Debian's libmeshoptimizer is 0.18).
#   jpegls_slices   bench/cpp/peers/jpegls_slices.cpp over Debian's CharLS 2.x (libcharls-dev,
#                   scripts/install_bench_deps.sh): JPEG-LS per slice for bench/py/file_bench.py;
#                   skipped with a warning when CharLS is not installed.
#
# Source: zeux/meshoptimizer at the pinned tag v1.2 (commit 9d9890c73011d75920af614485296d1e03e95448),
# as the tarball GitHub serves at
#   https://codeload.github.com/zeux/meshoptimizer/tar.gz/refs/tags/v1.2
# kept as build/bench-peers/meshoptimizer-v1.2.tar.gz and downloaded with curl when absent. Both
# GitHub's tarball and `git archive --prefix=meshoptimizer-1.2/ v1.2` of a clone carry the
# commit id in their pax header; it is checked against the pin (git get-tar-commit-id), so a
# tarball made from a clone on a machine without access to GitHub is accepted as well.
#
# usage: scripts/build_bench_peers.sh [MESHOPTIMIZER_SOURCE_DIR | TARBALL]
#   A source directory (with src/meshoptimizer.h) is used as it is, unverified.
# Environment: CXX (default g++), OUT (default <repo>/build/bench-peers).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
OUT="${OUT:-$ROOT/build/bench-peers}"
CXX="${CXX:-g++}"
TAG=v1.2
COMMIT=9d9890c73011d75920af614485296d1e03e95448
URL="https://codeload.github.com/zeux/meshoptimizer/tar.gz/refs/tags/$TAG"
mkdir -p "$OUT"

src="${1:-$OUT/meshoptimizer-$TAG.tar.gz}"
if [ ! -d "$src" ]; then
  tarball="$src"
  if [ ! -f "$tarball" ]; then
    echo "downloading $URL"
    curl -fsSL -o "$tarball.part" "$URL" || {
      echo "error: cannot download $URL; give a tarball or source directory of zeux/meshoptimizer $TAG" >&2
      exit 1
    }
    mv "$tarball.part" "$tarball"
  fi
  got="$(gzip -dc "$tarball" | git get-tar-commit-id || true)"
  if [ "$got" != "$COMMIT" ]; then
    echo "error: $tarball is commit '${got:-unknown}', not meshoptimizer $TAG ($COMMIT)" >&2
    exit 1
  fi
  src="$OUT/meshoptimizer-$TAG"
  rm -rf "$src"
  mkdir -p "$src"
  tar -xzf "$tarball" -C "$src" --strip-components=1
fi
if ! grep -q meshopt_simplifyWithUpdate "$src/src/meshoptimizer.h"; then
  echo "error: $src/src/meshoptimizer.h has no meshopt_simplifyWithUpdate (meshoptimizer 1.0+ needed)" >&2
  exit 1
fi

echo "building $OUT/meshopt_update against $src"
"$CXX" -O2 -DNDEBUG -std=c++17 -I"$src/src" "$ROOT/bench/cpp/peers/meshopt_update.cpp" "$src"/src/*.cpp \
  -o "$OUT/meshopt_update"

# Smoke test: a flat 20 x 20 quad grid (800 triangles) must come down to at most 10 %.
ply="$OUT/smoke_grid.ply"
{
  printf 'ply\nformat ascii 1.0\nelement vertex 441\nproperty float x\nproperty float y\nproperty float z\n'
  printf 'element face 800\nproperty list uchar int vertex_indices\nend_header\n'
  for j in $(seq 0 20); do for i in $(seq 0 20); do echo "$i $j 0"; done; done
  for j in $(seq 0 19); do
    for i in $(seq 0 19); do
      v=$((j * 21 + i))
      echo "3 $v $((v + 1)) $((v + 22))"
      echo "3 $v $((v + 22)) $((v + 21))"
    done
  done
} >"$ply"
json="$("$OUT/meshopt_update" "$ply" 80 "$OUT/smoke_grid_out.ply")"
echo "$json"
tris="$(echo "$json" | sed -n 's/.*"triangles": \([0-9]*\).*/\1/p')"
if [ -z "$tris" ] || [ "$tris" -gt 80 ] || [ "$tris" -eq 0 ]; then
  echo "error: smoke test kept ${tris:-?} of 800 triangles (expected 1..80)" >&2
  exit 1
fi
rm -f "$ply" "$OUT/smoke_grid_out.ply"
echo "ok: $OUT/meshopt_update (meshoptimizer $TAG)"

if [ ! -f /usr/include/charls/charls.h ]; then
  echo "warning: no CharLS (libcharls-dev); bench/py/file_bench.py runs without its JPEG-LS rows" >&2
  exit 0
fi
echo "building $OUT/jpegls_slices against CharLS"
"$CXX" -O2 -DNDEBUG -std=c++17 "$ROOT/bench/cpp/peers/jpegls_slices.cpp" -lcharls -o "$OUT/jpegls_slices"

# Smoke test: a 64 x 48 x 3 ramp with noise, lossless bit for bit and NEAR 2 within 2.
raw="$OUT/smoke_ramp.raw"
python3 -c "import random,sys; random.seed(1); sys.stdout.buffer.write(bytes((x+y+z*7+random.randrange(9))%256 for z in range(3) for y in range(48) for x in range(64)))" >"$raw"
for near in 0 2; do
  "$OUT/jpegls_slices" encode "$raw" 64 48 3 8 "$near" "$raw.jlss" >/dev/null
  "$OUT/jpegls_slices" decode "$raw.jlss" "$raw.out" >/dev/null
  python3 -c "import sys; a=open(sys.argv[1],'rb').read(); b=open(sys.argv[2],'rb').read(); sys.exit(len(a)!=len(b) or max(abs(x-y) for x,y in zip(a,b))>int(sys.argv[3]))" \
    "$raw" "$raw.out" "$near" || { echo "error: jpegls_slices NEAR $near round trip out of bound" >&2; exit 1; }
done
rm -f "$raw" "$raw.jlss" "$raw.out"
echo "ok: $OUT/jpegls_slices (CharLS)"
