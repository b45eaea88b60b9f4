#!/usr/bin/env bash
# The main job: install, build (Release) and run the default study. Prints a short result
# table and where the full report is.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${EXID_BUILD_DIR:-$root/build}
bash "$root/scripts/build.sh" -DEXID_BUILD_TESTS=OFF -DEXID_BUILD_BENCHMARKS=OFF
study=${1:-$root/examples/default.yaml}
exec "$build/bin/exid" run "$study" --out "${EXID_OUT:-$root/out/default}"
