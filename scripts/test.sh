#!/usr/bin/env bash
# Install, build and run the whole test suite (ctest). Extra arguments go to ctest
# (e.g. -L unit, -LE slow).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${EXID_BUILD_DIR:-$root/build}
bash "$root/scripts/build.sh" -DEXID_BUILD_TESTS=ON
cd "$build"
ctest --output-on-failure -j "${EXID_JOBS:-$(nproc)}" --timeout 900 "$@"
