#!/usr/bin/env bash
# Install, build and run the whole test suite (ctest). Extra arguments go to ctest
# (e.g. -L unit, -LE slow); EXID_CMAKE_ARGS (whitespace-separated) go to cmake (e.g.
# "-DEXID_SANITIZE=ON"). Afterwards the CI matrix's tables are printed when it ran.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${EXID_BUILD_DIR:-$root/build}
# shellcheck disable=SC2086
bash "$root/scripts/build.sh" -DEXID_BUILD_TESTS=ON ${EXID_CMAKE_ARGS:-}
cd "$build"
status=0
ctest --output-on-failure -j "${EXID_JOBS:-$(nproc)}" --timeout 900 "$@" || status=$?
if [ -f "$build/ci_matrix/results.sqlite" ]; then
  echo
  echo "== CI matrix (examples/matrix/ci.yaml) =="
  for metric in param_rel_err cond_W wall_s; do
    "$build/bin/exid" matrix table "$build/ci_matrix" --rows robot,model --cols estimator --metric "$metric" || true
    echo
  done
fi
if [ -f "$build/ci_excitation/results.sqlite" ]; then
  echo "== CI excitation matrix (examples/matrix/ci_excitation.yaml) =="
  "$build/bin/exid" matrix table "$build/ci_excitation" --rows robot,excitation.criterion --cols optimizer \
    --metric excitation.cond_W_final || true
  echo
fi
exit $status
