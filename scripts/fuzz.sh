#!/usr/bin/env bash
# Builds the libFuzzer targets (fuzz/, clang + ASan/UBSan, in build-fuzz/) and runs each for SECONDS
# (default 60) on a copy of its seed corpus, printing executions, coverage (edges) and crashes per target.
# Findings land in build-fuzz/findings/<target>/ (crash-*, timeout-*, leak-*); keep each as a regression
# input under tests/data/fuzz/<target>/ once fixed. VNR_FUZZ_TARGETS="a b" picks targets; VNR_FUZZ_NO_BUILD=1
# runs what is built.
set -euo pipefail
SECONDS_PER_TARGET=${1:-60}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=${VNR_FUZZ_BUILD:-$ROOT/build-fuzz}
TARGETS=(fuzz_sidecar fuzz_nrrd fuzz_nhdr fuzz_scene fuzz_tf fuzz_config fuzz_vnr_model fuzz_bson_model
         fuzz_vnr_decode fuzz_viewer_message)
if [[ -n "${VNR_FUZZ_TARGETS:-}" ]]; then read -r -a TARGETS <<< "$VNR_FUZZ_TARGETS"; fi

if ! command -v clang++ >/dev/null; then
  echo "scripts/fuzz.sh needs clang and libFuzzer: sudo sh scripts/setup.sh (Debian: clang libclang-rt-dev libomp-dev)" >&2
  exit 1
fi
# build.ninja, not CMakeCache.txt: a configure that failed half-way is redone.
if [[ ! -f "$BUILD/build.ninja" ]]; then
  mkdir -p "$BUILD"
  launcher=()
  command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  CC=clang CXX=clang++ cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g" -DVNR_FUZZ=ON \
    -DVNR_CUDA=OFF -DVNR_PYTHON=OFF -DVNR_PARAVIEW=OFF -DVNR_VIEW=OFF -DVNR_BUILD_TESTS=OFF \
    -DVNR_BUILD_BENCH=OFF "${launcher[@]}" >"$BUILD/configure.log" || { cat "$BUILD/configure.log" >&2; exit 1; }
fi
[[ -n "${VNR_FUZZ_NO_BUILD:-}" ]] || cmake --build "$BUILD" -j"${VNR_FUZZ_JOBS:-2}" --target "${TARGETS[@]}"

printf '%-22s %12s %8s %8s %8s\n' target executions edges corpus findings
for t in "${TARGETS[@]}"; do
  corpus="$BUILD/corpus/$t" findings="$BUILD/findings/$t"
  mkdir -p "$corpus" "$findings"
  cp -n "$ROOT/fuzz/corpus/$t"/* "$corpus/" 2>/dev/null || true
  log="$BUILD/findings/$t.log"
  # -fork keeps going after a finding, so one run reports every crash of the time budget.
  "$BUILD/fuzz/$t" "$corpus" -max_total_time="$SECONDS_PER_TARGET" -timeout=1 -rss_limit_mb=2048 \
    -artifact_prefix="$findings/" -print_final_stats=1 -fork=1 -ignore_crashes=1 -ignore_timeouts=1 \
    -ignore_ooms=1 >"$log" 2>&1 || true
  # fork mode's status lines carry the totals: "#N: cov: E ft: F corp: C exec/s: X oom/timeout/crash: A/B/C"
  # (|| true: a target that dies before its first status line must not end the script under pipefail)
  execs=$(grep -oE '^#[0-9]+' "$log" | tail -1 | tr -d '#' || true)
  edges=$(grep -oE 'cov: [0-9]+' "$log" | tail -1 | awk '{print $2}' || true)
  corp=$(grep -oE 'corp: [0-9]+' "$log" | tail -1 | awk '{print $2}' || true)
  crashes=$(find "$findings" -maxdepth 1 -type f \( -name 'crash-*' -o -name 'timeout-*' -o -name 'leak-*' \
            -o -name 'oom-*' \) | wc -l)
  printf '%-22s %12s %8s %8s %8s\n' "$t" "${execs:-?}" "${edges:-?}" "${corp:-?}" "$crashes"
done
