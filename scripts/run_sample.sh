#!/usr/bin/env bash
# README command (a): install what is missing, build, and run the main job on the bundled
# CT sample: volume in -> adaptive hierarchy + glTF/Draco iso-surfaces + report out.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$ROOT/scripts/install_deps.sh"
bash "$ROOT/scripts/build.sh" -DMLFE_BUILD_TESTS=OFF -DMLFE_BUILD_BENCH=OFF
OUT="$ROOT/out"
mkdir -p "$OUT"
"$ROOT/build/converters/cli/mlfe" convert "$ROOT/samples/ct_skull_64.nrrd" --iso 1.5,3.0 --simplify 0.2 \
  -o "$OUT/ct_skull.glb" --hierarchy "$OUT/ct_skull.mlfeh" --report "$OUT/ct_skull.report.json"
"$ROOT/build/converters/cli/mlfe" convert "$ROOT/samples/dem_jacksboro.nrrd" --rms 0.5% --z-scale 0.00001 \
  -o "$OUT/dem_jacksboro.glb" --report "$OUT/dem_jacksboro.report.json" --quiet
echo
echo "Outputs:"
ls -l "$OUT"/ct_skull.glb "$OUT"/ct_skull.mlfeh "$OUT"/ct_skull.report.json "$OUT"/dem_jacksboro.glb
