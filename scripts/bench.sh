#!/usr/bin/env bash
# Install, build (Release, with benchmarks) and run the benchmarks; every figure the docs quote
# about speed comes from here, as a ratio to a baseline measured in the same run.
#   bash scripts/bench.sh            all: dynamics, estimators, excitation, studies, matrix
#   bash scripts/bench.sh studies    one of them (bench_<name>); extra arguments go to it,
#                                    e.g. --benchmark_filter=panda
# Run it on an otherwise idle machine: the seconds depend on the machine, the ratios much less.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${EXID_BUILD_DIR:-$root/build}
bash "$root/scripts/build.sh" -DEXID_BUILD_BENCHMARKS=ON >/dev/null
which=(dynamics estimators excitation studies matrix)
if [ $# -gt 0 ]; then
  which=("$1")
  shift
fi
for b in "${which[@]}"; do
  exe="$build/bin/bench_$b"
  [ -x "$exe" ] || { echo "bench.sh: no benchmark '$b' ($exe)" >&2; exit 2; }
  echo "== bench_$b =="
  "$exe" "$@"
  echo
done
