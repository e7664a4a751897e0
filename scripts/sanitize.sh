#!/bin/sh
# Builds vnr with sanitizers and runs the test suite under them (docs/reliability.md, "Sanitizers").
#   sh scripts/sanitize.sh            AddressSanitizer + UBSan in build-asan/ over the loader, limit,
#                                     fault, format and API tests (CI_TESTS below; what CI runs)
#   sh scripts/sanitize.sh address-full   the same over the whole suite minus the training-heavy tests
# Any report fails the run: UBSan aborts (-fno-sanitize-recover), ASan and LeakSanitizer exit non-zero.
set -eu
cd "$(dirname "$0")/.."
MODE=${1:-address}
BUILD=${VNR_SANITIZE_BUILD:-build-asan}
JOBS=$(nproc)
LAUNCHER=""
command -v ccache >/dev/null 2>&1 && LAUNCHER="-DCMAKE_CXX_COMPILER_LAUNCHER=ccache"
# MPI off: LeakSanitizer reports Open MPI's own start-up allocations in every MPI process (not ours);
# the MPI layer's tests run in the normal suite.
COMMON="-G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DVNR_CUDA=OFF -DVNR_BUILD_BENCH=OFF -DVNR_PYTHON=OFF
        -DVNR_PARAVIEW=OFF -DVNR_MPI=OFF $LAUNCHER"

# The tests of every loader, parser, limit and fault, the model format, the API objects and the threaded
# trainer's session: what fits CI's 20 minutes after the main suite (docs/reliability.md, Sanitizers).
CI_TESTS="test_fuzz_regressions test_limits test_faults test_model_file test_volume test_volume_values
          test_volume_writer test_transfer_function test_render_io test_image_io test_api_objects test_api_arrays
          test_core test_metrics test_training_session test_file_evaluation"
# Left out of `address-full` (each trains for seconds even in the optimised build, 3-10x that under ASan;
# the same code paths run in the tests that are kept): the out-of-core and series training curves, the
# precision sweeps, the kernel-vs-reference sweeps, and the browser test (Chromium, not our code);
# and one timing assertion (a thread slowed by 300 us claims fewer chunks), which ASan's own slowdown voids.
SLOW='OutOfCore\.|OutOfCoreCli\.|Series\.|SeriesCli\.|Cli\.TrainingPrecision|Cli\.InferencePrecision|MlpKernels\.|PointEval\.|OnlineLoop\.|Strategies\.|StreamEval\.|browser_viewer|CpuTrainer\.SharedTailChunks'
export ASAN_OPTIONS=detect_leaks=1:halt_on_error=1 UBSAN_OPTIONS=print_stacktrace=1

if [ "$MODE" = address ] || [ "$MODE" = address-full ]; then
  VIEW=OFF TARGETS=$CI_TESTS
  [ "$MODE" = address-full ] && VIEW=ON TARGETS=all
  # -O1: the sanitizers' checks, not the optimiser, dominate the run, and it builds faster than -O2.
  # shellcheck disable=SC2086
  cmake -S . -B "$BUILD" $COMMON -DVNR_VIEW=$VIEW -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" \
    -DVNR_SANITIZE=address,undefined >/dev/null
  # shellcheck disable=SC2086
  cmake --build "$BUILD" -j "$JOBS" --target $TARGETS
  # Executables not built (address mode) appear to ctest as *_NOT_BUILT: not failures of this run.
  # install_and_consume builds an unsanitized program against the install: nothing for ASan to check.
  ctest --test-dir "$BUILD" --output-on-failure -j "$JOBS" -E "$SLOW|_NOT_BUILT|^install_and_consume$"
else
  echo "usage: sh scripts/sanitize.sh [address|address-full]" >&2
  exit 2
fi
