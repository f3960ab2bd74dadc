#!/usr/bin/env bash
# README command (b): install what is missing, check the formatting, build, and run every test:
#   1. Release build, all GoogleTest suites and the Python module's tests through ctest (unit,
#      format round trips, CLI, golden files, Khronos glTF validator verdicts);
#   2. the core tests again under AddressSanitizer + UBSan (Debug);
#   3. a consumer project that does find_package(mlfe), links mlfe::core and mlfe::pipeline and
#      converts the CT sample to a .glb the Khronos validator accepts, renders and compares images;
#   4. `pip install --no-build-isolation .` into a temporary venv, then a tiny conversion;
#   5. bounded libFuzzer runs of every parser (MLFE_FUZZ_SECONDS each, default 30).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
JOBS="${MLFE_JOBS:-$(nproc)}"
bash "$ROOT/scripts/install_deps.sh"

echo "== clang-format (.clang-format; Debian 12's clang-format 14)"
find "$ROOT"/{core,formats,converters,include,tests,fuzz,bench,python} \( -name '*.cpp' -o -name '*.h' \) -print0 |
  xargs -0 clang-format --dry-run -Werror

echo "== no function over 150 lines in core/, formats/, converters/"
python3 "$ROOT/scripts/check_function_length.py" "$ROOT"

echo "== layering: includes go down or sideways (docs/architecture.md)"
python3 "$ROOT/scripts/check_layering.py" "$ROOT"

echo "== release build and tests"
bash "$ROOT/scripts/build.sh" -DMLFE_BUILD_TESTS=ON -DMLFE_BUILD_BENCH=ON
(cd "$ROOT/build" && ctest -j "$JOBS" --output-on-failure --timeout 600) | tee "$ROOT/build/ctest.log"
TOTAL="$(sed -n 's/.*tests passed, 0 tests failed out of \([0-9]*\).*/\1/p' "$ROOT/build/ctest.log" | tail -1)"

echo "== core tests under ASan + UBSan"
cmake -S "$ROOT" -B "$ROOT/build-asan" -G Ninja -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG="-g -O1" -DMLFE_SANITIZE=ON \
  -DMLFE_BUILD_FORMATS=OFF -DMLFE_BUILD_BENCH=OFF >/dev/null
cmake --build "$ROOT/build-asan" -j "$JOBS" --target mlfe_core_tests
# The rate test runs big uniform meshes; it is covered by the release run.
"$ROOT/build-asan/tests/mlfe_core_tests" --gtest_filter='-*ConvergesWithRateTwo*:*SphereIsAccurate*:*ThresholdLoop*'

echo "== find_package(mlfe) consumer"
PREFIX="$ROOT/build/install-test"
rm -rf "$PREFIX" "$ROOT/build/consumer"
cmake --install "$ROOT/build" --prefix "$PREFIX" >/dev/null
cmake -S "$ROOT/tests/consumer" -B "$ROOT/build/consumer" -DCMAKE_PREFIX_PATH="$PREFIX" >/dev/null
cmake --build "$ROOT/build/consumer" -j "$JOBS"
"$ROOT/build/consumer/mlfe_consumer" "$ROOT/samples/ct_skull_64.nrrd" "$ROOT/build/consumer/ct_skull.glb"
node "$ROOT/tools/validate_gltf.js" "$ROOT/build/consumer/ct_skull.glb" >/dev/null
echo "consumer: ct_skull.glb accepted by the glTF validator"
# The installed Python module loads (its RPATH finds the installed libmlfe_formats) and reads
# OpenVDB through the module installed beside that library.
PYSITE="$(sed -n 's/^MLFE_PYTHON_INSTALL_DIR:STRING=//p' "$ROOT/build/CMakeCache.txt")"
if [ -n "$PYSITE" ]; then
  PYTHONPATH="$PREFIX/$PYSITE" /usr/bin/python3 -c "import mlfe, sys; g = mlfe.info(sys.argv[1])['grids']; \
print('installed python module: mlfe', mlfe.__version__, 'reads', g[0])" "$ROOT/tests/data/small_sphere.vdb"
fi

echo "== pip install . into a temporary venv"
# README's command: setuptools (pyproject.toml) runs the project's CMake, the package lands in
# the venv with its libmlfe_formats.
VENV_DIR="$(mktemp -d)"
/usr/bin/python3 -m venv --system-site-packages "$VENV_DIR/venv"
# The tests' build folder is reused (MLFE_PIP_BUILD_DIR): only the extension relinks, where a
# fresh build-pip/ would compile the libraries again (minutes on 2 cores without ccache).
MLFE_PIP_BUILD_DIR="$ROOT/build" CMAKE_BUILD_PARALLEL_LEVEL="$JOBS" \
  "$VENV_DIR/venv/bin/pip" install --quiet --no-build-isolation "$ROOT"
(cd "$VENV_DIR" && "$VENV_DIR/venv/bin/python" - "$VENV_DIR" "$ROOT/tests/data/small_sphere.vdb" <<'PY'
import os, sys
import numpy as np
import mlfe, mlfe.batch
assert mlfe.__file__.startswith(sys.argv[1]), mlfe.__file__  # the venv's copy, not a build tree
d = np.linalg.norm(np.mgrid[0:12, 0:12, 0:12].T - 5.5, axis=-1).astype(np.float32)
out = os.path.join(sys.argv[1], "sphere.ply")
s = mlfe.convert(d, out, iso=4, affine=np.diag([0.5, 0.5, 0.5, 1]))
assert s["triangles"] > 0 and os.path.getsize(out) == s["bytes"], s
assert mlfe.info(sys.argv[2])["format"] == "vdb"  # the OpenVDB module came along
print("pip-installed mlfe", mlfe.__version__, "converts:", s["triangles"], "triangles; reads .vdb")
PY
)
rm -rf "$VENV_DIR"
# Back to the tests' configuration (the venv's interpreter is gone, the bundle was pip's).
cmake -S "$ROOT" -B "$ROOT/build" -DMLFE_PYTHON_EXECUTABLE=/usr/bin/python3 -DMLFE_PYTHON_BUNDLE=OFF \
  -UMLFE_PYTHON_INSTALL_DIR >/dev/null

echo "== bounded fuzzing"
bash "$ROOT/fuzz/run_fuzzers.sh" "${MLFE_FUZZ_SECONDS:-30}"

echo "== all test stages passed"
echo "ctest: ${TOTAL:-0} passed, 0 failed"
