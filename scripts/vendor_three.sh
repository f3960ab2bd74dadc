#!/usr/bin/env bash
# Re-makes third_party/three/ (the preview page's viewer, `mlfe convert --preview`) from npm at
# the pinned versions below. The result is checked in, so building mlfe needs neither npm nor
# the network; run this only to move to another three.js version (then rebuild and run the
# preview test in Chromium).
#
# What it writes:
#   three_viewer.js    three.js's WebGLRenderer, GLTFLoader, DRACOLoader and OrbitControls
#                      (and the few classes the page uses) bundled by esbuild into one minified
#                      classic script that defines the global MLFE3: a page opened from disk
#                      (file://) cannot import ES modules from relative paths, and one bundle
#                      keeps only what the page uses (tree-shaken: ~0.6 MB instead of 1.5 MB).
#   draco_wasm_wrapper.js, draco_decoder.wasm
#                      the Draco decoder as three ships it (examples/jsm/libs/draco/gltf/),
#                      unchanged; the page hands them to DRACOLoader through THREE.Cache.
#   LICENSE.three, LICENSE.draco, VERSIONS
set -euo pipefail

THREE_VERSION=0.187.0
ESBUILD_VERSION=0.28.2

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
OUT="$ROOT/third_party/three"
WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT

cd "$WORK"
npm init -y >/dev/null
npm install --no-audit --no-fund --silent "three@$THREE_VERSION" "esbuild@$ESBUILD_VERSION"
cat > entry.js <<'JS'
export {
  AmbientLight, Box3, Cache, Color, DirectionalLight, PerspectiveCamera, Scene, Vector3, WebGLRenderer,
} from 'three';
export { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
export { DRACOLoader } from 'three/addons/loaders/DRACOLoader.js';
export { OrbitControls } from 'three/addons/controls/OrbitControls.js';
JS
# DRACOLoader computes its default decoder URLs from import.meta.url, which a classic script
# lacks; the page's base URL keeps that line valid (the page gives the decoder itself).
npx esbuild entry.js --bundle --minify --format=iife --global-name=MLFE3 --legal-comments=none \
  --define:import.meta.url=document.baseURI --target=es2020 --outfile=three_viewer.js --log-level=warning

mkdir -p "$OUT"
cp three_viewer.js "$OUT/"
cp node_modules/three/examples/jsm/libs/draco/gltf/draco_wasm_wrapper.js \
   node_modules/three/examples/jsm/libs/draco/gltf/draco_decoder.wasm "$OUT/"
cp node_modules/three/LICENSE "$OUT/LICENSE.three"
# three's package ships Draco's decoder (Apache-2.0) without the licence text; Debian has it.
cp /usr/share/common-licenses/Apache-2.0 "$OUT/LICENSE.draco"
printf 'three %s (npm), bundled by esbuild %s; Draco decoder as shipped in three %s (examples/jsm/libs/draco/gltf)\n' \
  "$THREE_VERSION" "$ESBUILD_VERSION" "$THREE_VERSION" > "$OUT/VERSIONS"
echo "third_party/three: three $THREE_VERSION"
