#!/usr/bin/env bash
# Installs every build, test and tool dependency of mlfe from Debian 12 packages
# (and the Khronos glTF validator from npm). Idempotent: installs only what is missing.
set -euo pipefail

PKGS=(
  build-essential cmake ninja-build pkg-config git
  libeigen3-dev libtbb-dev
  libopenvdb-dev libboost-iostreams-dev
  libopenmesh-dev libdraco-dev draco libtinygltf-dev libmeshoptimizer-dev
  libopenexr-dev openexr
  libcli11-dev nlohmann-json3-dev libfmt-dev
  libnifti2-dev libteem-dev libzstd-dev zlib1g-dev libpng-dev libbz2-dev libexpat1-dev
  libblosc-dev         # OME-Zarr chunks (formats/zarr_reader.cpp)
  googletest libgtest-dev libbenchmark-dev
  python3 python3-dev pybind11-dev python3-pybind11 python3-numpy
  python3-setuptools python3-pip python3-venv  # pip install . (pyproject.toml: setuptools runs CMake)
  python3-distributed  # mlfe.batch (Dask)
  python3-nibabel      # tests/python/test_package.py: the nibabel affine round trip
  python3-zarr         # tests: OME-Zarr stores written by zarr-python
  clang libclang-rt-14-dev clang-format
  python3-vtk9  # tests/converters/export_command_test.cpp reads .vtu with VTK's XML reader
  chromium      # tests/python/test_preview.py opens the preview page (convert --preview) headless
)
# Node.js/npm only when the machine has none (a non-Debian node may already be there).
if ! command -v npm >/dev/null 2>&1; then PKGS+=(nodejs npm); fi

missing=()
for p in "${PKGS[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

SUDO=""
if [ "$(id -u)" != "0" ]; then SUDO="sudo"; fi

if [ "${#missing[@]}" -gt 0 ]; then
  echo "mlfe: installing missing Debian packages: ${missing[*]}" >&2
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# Khronos glTF validator (npm), installed into the project's tools/ folder so tests can find it.
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ ! -x "$ROOT/tools/node_modules/.bin/gltf_validator" ] && [ ! -f "$ROOT/tools/node_modules/gltf-validator/package.json" ]; then
  if command -v npm >/dev/null 2>&1; then
    echo "mlfe: installing gltf-validator from npm" >&2
    mkdir -p "$ROOT/tools"
    (cd "$ROOT/tools" && npm install --no-audit --no-fund --silent gltf-validator >/dev/null 2>&1) \
      || echo "mlfe: warning: npm install gltf-validator failed; validator tests will fail" >&2
  fi
fi
