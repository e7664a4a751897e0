#!/bin/sh
# Builds vnr with sanitizers and runs the test suite under them (docs/reliability.md, "Sanitizers").
#   sh scripts/sanitize.sh            AddressSanitizer + UBSan in build-asan/ over the loader, limit,
#                                     fault, format and API tests (CI_TESTS below; what CI runs)
#   sh scripts/sanitize.sh address-full   the same over the whole suite minus the training-heavy tests
#   sh scripts/sanitize.sh thread     ThreadSanitizer in build-tsan/ (clang, LLVM's libomp + Archer) over
#                                     the threaded trainer, training sessions, out-of-core reader pool,
#                                     viewer engine and server (TSAN_TESTS below; CI runs it after address)
#   sh scripts/sanitize.sh thread-full    the same with the slow tests CI leaves out (TSAN_SLOW)
# Any report fails the run: UBSan aborts (-fno-sanitize-recover); ASan, LeakSanitizer and TSan exit non-zero.
set -eu
cd "$(dirname "$0")/.."
MODE=${1:-address}
BUILD=${VNR_SANITIZE_BUILD:-build-asan}
case $MODE in thread*) BUILD=${VNR_SANITIZE_BUILD:-build-tsan} ;; esac
JOBS=$(nproc)
LAUNCHER=""
command -v ccache >/dev/null 2>&1 && LAUNCHER="-DCMAKE_CXX_COMPILER_LAUNCHER=ccache"
# MPI off: LeakSanitizer reports Open MPI's own start-up allocations in every MPI process (not ours);
# the MPI layer's tests run in the normal suite.
COMMON="-G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DVNR_CUDA=OFF -DVNR_BUILD_BENCH=OFF -DVNR_PYTHON=OFF
        -DVNR_PARAVIEW=OFF -DVNR_MPI=OFF $LAUNCHER"

# The tests of every loader, parser, limit and fault, the model format, the API objects and the threaded
# trainer's session: what fits CI's 20 minutes after the main suite (docs/reliability.md, Sanitizers).
CI_TESTS="test_fuzz_regressions test_limits test_faults test_model_file test_param_codec test_volume test_volume_values
          test_volume_writer test_transfer_function test_render_io test_image_io test_api_objects test_api_arrays
          test_core test_metrics test_training_session test_file_evaluation"
# Left out of `address-full` (each trains for seconds even in the optimised build, 3-10x that under ASan;
# the same code paths run in the tests that are kept): the out-of-core and series training curves, the
# precision sweeps, the kernel-vs-reference sweeps, and the browser test (Chromium, not our code);
# and one timing assertion (a thread slowed by 300 us claims fewer chunks), which ASan's own slowdown voids.
SLOW='OutOfCore\.|OutOfCoreCli\.|Series\.|SeriesCli\.|Cli\.TrainingPrecision|Cli\.InferencePrecision|MlpKernels\.|PointEval\.|OnlineLoop\.|Strategies\.|StreamEval\.|browser_viewer|CpuTrainer\.SharedTailChunks'
# The threaded code (docs/reliability.md, Sanitizers), the tests of these executables: the CPU trainer
# (parallel_threads, for_each_claimed, gradient sums; test_network), training sessions stopped and paused
# from other threads, the out-of-core reader pool, the viewer engine thread, the server's network,
# broadcaster and worker threads (and `vnr view` under SIGTERM), and the OpenMP loops of the parameter
# codec, metrics, renderer and residuals, the brick cache's decoding thread and its copy's atomic reads
# (what the GPU's copy records, on the host); tsan_openmp_canary checks
# the checker.
TSAN_TESTS="tsan_openmp_canary test_network test_training_session test_out_of_core test_viewer_engine
            test_view_server test_param_codec test_metrics test_render test_residuals test_brick_cache
            test_brick_cache_copy test_brick_cache_refresh"
# Their test suites (a name filter, so executables left from another run of this folder are not run).
TSAN_FILTER='^(TsanCanary|Mlp|Loss|Adam|CpuTrainer|Sampler|TargetRatio|TrainingSession|OutOfCore|Mmap|OutOfCoreCli|'\
'ViewerEngine|ViewAccess|ViewServerTest|ViewPng|ViewCli|ParamCodec|ResidualBlock|CompactMacrocells|Metrics|Dda|'\
'MacroCells|RayMarch|PathTrace|Strategies|CpuRenderer|Residuals|BrickCache|BrickCacheCopy|ChangingModel)\.'
# Left out for CI's 20 minutes (28-40 s each under TSan; their threads run in the tests kept): the
# out-of-core loss curve (the reader pool trains in OutOfCoreCli.*), two image comparisons of the viewer
# engine against the renderer (the engine renders in the other ViewerEngine tests), the strategy sweep.
TSAN_SLOW='^(OutOfCore\.LossCurveMatchesInCoreWithinTolerance|ViewerEngine\.TruthViewEqualsTheRenderer|'\
'ViewerEngine\.SceneInputUsesItsCameraAndTf|Strategies\..*)$'
export ASAN_OPTIONS=detect_leaks=1:halt_on_error=1 UBSAN_OPTIONS=print_stacktrace=1

if [ "$MODE" = address ] || [ "$MODE" = address-full ]; then
  VIEW=OFF TARGETS=$CI_TESTS
  [ "$MODE" = address-full ] && VIEW=ON TARGETS=all
  # -O0: with ASan, -O1 spends most of the build inlining the SIMD kernels (nn/point_eval.cpp: 54 s at
  # -O1, 5 s at -O0); the CI set then builds in 4 minutes instead of 6 and its tests take 34 s, not 19.
  # Not a unity build: each file compiles on its own, which checks that it includes what it uses.
  # shellcheck disable=SC2086
  cmake -S . -B "$BUILD" $COMMON -DVNR_VIEW=$VIEW -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O0 -g1" \
    -DVNR_SANITIZE=address,undefined -DCMAKE_UNITY_BUILD=OFF >/dev/null
  # shellcheck disable=SC2086
  cmake --build "$BUILD" -j "$JOBS" --target $TARGETS
  # Executables not built (address mode) appear to ctest as *_NOT_BUILT: not failures of this run.
  # install_and_consume builds an unsanitized program against the install: nothing for ASan to check.
  ctest --test-dir "$BUILD" --output-on-failure -j "$JOBS" -E "$SLOW|_NOT_BUILT|^install_and_consume$"
elif [ "$MODE" = thread ] || [ "$MODE" = thread-full ]; then
  if [ "$MODE" = thread-full ]; then TSAN_SLOW='^$'; fi
  # GCC's libgomp is not TSan-instrumented: every OpenMP barrier would be reported. clang links LLVM's
  # libomp, and Archer (an OMPT tool of libomp) tells TSan what the OpenMP constructs synchronise, so
  # our parallel_for/parallel_threads code runs as in the release build, OpenMP and all.
  if ! command -v clang++ >/dev/null 2>&1; then
    echo "sanitize.sh thread needs clang and LLVM's libomp with Archer: sudo sh scripts/setup.sh" \
         "(Debian: clang libomp-dev)" >&2
    exit 1
  fi
  # shellcheck disable=SC2086
  CC=clang CXX=clang++ cmake -S . -B "$BUILD" $COMMON -DVNR_VIEW=ON -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1" \
    -DVNR_SANITIZE=thread >/dev/null
  # Archer comes with the libomp the build links (same LLVM version).
  OMP_LIB=$(sed -n 's/^OpenMP_omp_LIBRARY:FILEPATH=//p' "$BUILD/CMakeCache.txt")
  ARCHER=$(dirname "${OMP_LIB:-/nonexistent/x}")/libarcher.so
  if [ ! -f "$ARCHER" ]; then
    echo "sanitize.sh thread: no Archer next to the OpenMP runtime '$OMP_LIB' (Debian: libomp-dev)" >&2
    exit 1
  fi
  # shellcheck disable=SC2086
  cmake --build "$BUILD" -j "$JOBS" --target $TSAN_TESTS
  # ignore_noninstrumented_modules: libomp's own accesses are not ours (Archer's documented setting).
  # More OpenMP threads than cores, so even a two-core machine interleaves four.
  export OMP_TOOL_LIBRARIES="$ARCHER" OMP_NUM_THREADS="${OMP_NUM_THREADS:-4}" \
         TSAN_OPTIONS="ignore_noninstrumented_modules=1 second_deadlock_stack=1"
  # Archer announces itself when it is active; without it every parallel region is a false report.
  if ! ARCHER_OPTIONS=verbose=1 "$BUILD/test_network" --gtest_filter=CpuTrainer.RejectsBadBatch 2>&1 |
       grep -q "Archer detected OpenMP application with TSan"; then
    echo "sanitize.sh thread: Archer ($ARCHER) did not attach to libomp; see docs/reliability.md" >&2
    exit 1
  fi
  # No suppressions: nothing is reported. Not run: the browser test (Chromium is not our code; the
  # server tests drive the same server over 127.0.0.1), and TSAN_SLOW.
  ctest --test-dir "$BUILD" --output-on-failure -j "$JOBS" -R "$TSAN_FILTER" -E "$TSAN_SLOW"
else
  echo "usage: sh scripts/sanitize.sh [address|address-full|thread|thread-full]" >&2
  exit 2
fi
