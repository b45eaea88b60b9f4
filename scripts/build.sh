#!/usr/bin/env bash
# Installs the dependencies (Debian 12 packages) and builds exid (Release) in build/.
# Usage: scripts/build.sh [extra cmake args...]   Environment: EXID_BUILD_DIR (default build),
# EXID_JOBS (default: number of cores).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${EXID_BUILD_DIR:-$root/build}
jobs=${EXID_JOBS:-$(nproc)}
bash "$root/scripts/install-deps.sh"
cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=Release "$@" >/dev/null
cmake --build "$build" -j "$jobs"
