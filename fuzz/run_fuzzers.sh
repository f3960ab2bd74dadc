#!/usr/bin/env bash
# Builds the libFuzzer targets of the volume readers with clang (ASan + UBSan) in
# build-fuzz/ and runs each for SECONDS (default 60), seeded from tests/data and, when present,
# ../shared/data. Exits non-zero when any target finds a crash, a sanitizer error, a leak or
# a timeout; the reproducer is left in build-fuzz/artifacts/<target>/.
#
#   fuzz/run_fuzzers.sh [SECONDS] [TARGET...]     e.g. fuzz/run_fuzzers.sh 60 nrrd nifti
set -euo pipefail

SECONDS_EACH="${1:-60}"
shift || true
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="${MLFE_FUZZ_BUILD_DIR:-$ROOT/build-fuzz}"
TARGETS=("$@")
# The user-facing parsers. fuzz_draco (Draco payloads, which mlfe only reads back from its own
# outputs) is built too and can be run by name: libdraco sizes buffers from counts in the data
# and asks for gigabytes on corrupt input, which ASan reports as a crash. fuzz_exr (the EXR
# reader of `mlfe compare`) likewise: OpenEXR allocates attribute values by the sizes in the
# header before reading them (up to 2 GB from a 700-byte file); read_image checks the top-level
# attribute list first, but OpenEXR's typed attributes (chlist) can run past their declared
# size, so a corrupt file can still make it ask. Outside ASan that is an allocation that fails
# or a read that fails, reported as bad input (exit 2).
if [ "${#TARGETS[@]}" -eq 0 ]; then TARGETS=(nrrd nifti vdb raw metaimage image vtu msh zarr hierarchy gltf label_table brick_parts); fi

command -v clang++ >/dev/null || { echo "run_fuzzers: clang++ not found (apt-get install clang libclang-rt-14-dev)" >&2; exit 1; }

# Everything that links into a fuzz target is instrumented alike (mixing instrumented and
# plain std::vector code gives false container-overflow reports).
SAN="-fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer"
CC=clang CXX=clang++ cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DMLFE_BUILD_FUZZ=ON -DMLFE_BUILD_TESTS=OFF -DMLFE_BUILD_BENCH=OFF \
  -DCMAKE_CXX_FLAGS="$SAN" -DCMAKE_EXE_LINKER_FLAGS="$SAN" -DCMAKE_SHARED_LINKER_FLAGS="$SAN" >/dev/null
ninja -C "$BUILD" -j"$(nproc)" $(printf 'fuzz_%s ' "${TARGETS[@]}") fuzz_draco fuzz_exr

SHARED="$ROOT/../shared/data"
seed_patterns() {
  case "$1" in
    nrrd) echo "*.nrrd *.nhdr" ;;
    nifti) echo "*.nii *.nii.gz *.hdr" ;;
    vdb) echo "*.vdb" ;;
    raw) echo "*.raw.json *.json" ;;
    metaimage) echo "*.mha *.mhd" ;;
    image) echo "*.pgm *.png" ;;
    vtu) echo "*.vtu" ;;
    msh) echo "*.msh" ;;
    zarr) echo "*.zarrfuzz" ;;
    hierarchy) echo "*.mlfeh" ;;
    draco) echo "*.drc" ;;
    gltf) echo "*.glb" ;;
    exr) echo "*.exr" ;;
    label_table) echo "*.txt *.ctbl *.json *.lut" ;;
    brick_parts) echo "*.mlfebrk" ;;
  esac
}

# A fixed mutation seed (MLFE_FUZZ_SEED, default 1) makes a CI run replay what was fuzzed
# before; set another seed (or 0 for a random one) to explore further.
# Huge allocations (e.g. a corrupt OpenVDB string length) fail like on a small machine
# instead of exhausting the fuzzer's RSS limit.
export ASAN_OPTIONS="allocator_may_return_null=1:max_allocation_size_mb=1024:detect_leaks=1"
export LSAN_OPTIONS="suppressions=$ROOT/fuzz/lsan_suppressions.txt:print_suppressions=0"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"

failed=()
for t in "${TARGETS[@]}"; do
  corpus="$BUILD/corpus/$t"
  artifacts="$BUILD/artifacts/$t/"
  mkdir -p "$corpus" "$artifacts"
  for dir in "$ROOT/samples" "$ROOT/tests/data" "$ROOT/tests/golden" "$ROOT/tests/data/fuzz_regressions" "$ROOT/tests/data/fuzz_regressions_draco" "$ROOT/tests/data/labels" "$SHARED"; do
    [ -d "$dir" ] || continue
    for pat in $(seed_patterns "$t"); do
      for f in "$dir"/$pat; do
        [ -f "$f" ] && cp -f "$f" "$corpus/seed_$(basename "$f")"
      done
    done
  done
  echo "== fuzz_$t: $(ls "$corpus" | wc -l) corpus files, ${SECONDS_EACH}s" >&2
  # -max_len keeps executions fast; large seeds are cut to their first 64 KiB, which still
  # holds every header.
  if ! (cd "$BUILD" && "$BUILD/fuzz/fuzz_$t" "$corpus" -max_total_time="$SECONDS_EACH" -max_len=65536 \
        -timeout=20 -rss_limit_mb=2560 -seed="${MLFE_FUZZ_SEED:-1}" -artifact_prefix="$artifacts" -print_final_stats=1 \
        >"$BUILD/fuzz_$t.log" 2>&1); then
    failed+=("$t")
    echo "!! fuzz_$t failed; see $BUILD/fuzz_$t.log and $artifacts" >&2
    grep -m5 -E "ERROR|SUMMARY|runtime error|deadly signal" "$BUILD/fuzz_$t.log" >&2 || true
  else
    grep -E "stat::number_of_executed_units|stat::peak_rss_mb" "$BUILD/fuzz_$t.log" | tr '\n' ' ' >&2
    echo >&2
  fi
done
if [ "${#failed[@]}" -gt 0 ]; then
  echo "run_fuzzers: failures in: ${failed[*]}" >&2
  exit 1
fi
echo "run_fuzzers: no crashes in ${TARGETS[*]} (${SECONDS_EACH}s each)" >&2
