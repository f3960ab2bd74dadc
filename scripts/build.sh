#!/usr/bin/env bash
# Configures and builds mlfe (Release) into build/ (or $MLFE_BUILD_DIR).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="${MLFE_BUILD_DIR:-$ROOT/build}"
JOBS="${MLFE_JOBS:-$(nproc)}"
command -v ninja >/dev/null && GEN=(-G Ninja) || GEN=()
# The command line is always built (an earlier core-only configure of the same directory
# would otherwise stay cached); callers may still override it.
cmake -S "$ROOT" -B "$BUILD" "${GEN[@]}" -DCMAKE_BUILD_TYPE=Release -DMLFE_BUILD_FORMATS=ON "$@" >/dev/null
cmake --build "$BUILD" -j "$JOBS"
