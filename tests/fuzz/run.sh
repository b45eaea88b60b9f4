#!/usr/bin/env bash
# Builds the libFuzzer targets in a separate clang build (-DEXID_FUZZ=ON) and runs them.
#   tests/fuzz/run.sh build FUZZ_BUILD_DIR [TARGETS]  configure (once) and build (default: all)
#   tests/fuzz/run.sh run FUZZ_BUILD_DIR TARGET SECS  run TARGET for SECS seconds on its corpus
# The seed corpus tests/fuzz/corpus/TARGET is read, never written: new inputs go to
# FUZZ_BUILD_DIR/corpus/TARGET, findings to FUZZ_BUILD_DIR/artifacts/ (the exit status is
# non-zero when libFuzzer finds a crash, a sanitizer error, a leak, a timeout or an OOM).
# The build dir's `ctest -L fuzz` runs every target for EXID_FUZZ_SECONDS (set at configure time).
# Environment: EXID_FUZZ_JOBS (build jobs, default 1), CXX_FUZZ (default clang++-14 or clang++),
# EXID_FUZZ_SECONDS (default 60, read when the build is configured).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
cmd=${1:?usage: run.sh build|run FUZZ_BUILD_DIR [TARGET SECS]}
build=${2:?FUZZ_BUILD_DIR}
case "$cmd" in
  build)
    cxx=${CXX_FUZZ:-$(command -v clang++-14 || command -v clang++)}
    cc=${cxx/clang++/clang}
    if [ ! -f "$build/CMakeCache.txt" ]; then
      cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER="$cxx" \
        -DCMAKE_C_COMPILER="$cc" -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only" -DEXID_FUZZ=ON \
        -DEXID_BUILD_TESTS=OFF -DEXID_BUILD_BENCHMARKS=OFF \
        -DEXID_FUZZ_SECONDS="${EXID_FUZZ_SECONDS:-60}" >/dev/null
    fi
    shift 2
    cmake --build "$build" -j "${EXID_FUZZ_JOBS:-1}" --target "${@:-exid_fuzz_all}"
    ;;
  run)
    target=${3:?TARGET}
    secs=${4:?SECS}
    mkdir -p "$build/corpus/$target" "$build/artifacts"
    # Leaks are reported at exit of the whole process only (plugins stay loaded on purpose).
    export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=0}
    export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
    exec "$build/bin/$target" -max_total_time="$secs" -timeout=10 -rss_limit_mb=2048 \
      -max_len=8192 -print_final_stats=1 -artifact_prefix="$build/artifacts/$target-" \
      "$build/corpus/$target" "$here/corpus/$target"
    ;;
  *) echo "run.sh: unknown command '$cmd' (build | run)" >&2; exit 2 ;;
esac
