#!/usr/bin/env bash
# The installed Python package: `cmake --install` of the build into a temporary prefix, then
# `import exid` from outside both trees with only PYTHONPATH set. The module must load the
# installed libexid_core (its RPATH) and the installed plugins (beside that core), none of the
# build tree's, and find the examples and data installed under <prefix>/share/exid (data_path).
# Usage: installed.sh BUILD_DIR PYTHON
set -euo pipefail
build=$1
python=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cmake --install "$build" --prefix "$work/prefix" >/dev/null
init=$(find "$work/prefix" -path '*/dist-packages/exid/__init__.py' | head -n 1)
test -n "$init" || { echo "installed.sh: no exid package under $work/prefix" >&2; exit 1; }
cd "$work"
env -u EXID_PLUGIN_PATH PYTHONPATH="$(dirname "$(dirname "$init")")" "$python" - "$work/prefix" <<'PY'
import os
import sys

import exid

prefix = os.path.realpath(sys.argv[1])
assert os.path.realpath(exid.__file__).startswith(prefix), exid.__file__
r = exid.Robot("panda")
print(r.base_parameters[:3])
libs = sorted({p["library"] for p in exid.plugins()})
outside = [lib for lib in libs if not os.path.realpath(lib).startswith(prefix)]
assert libs and not outside, f"plugins loaded from outside the prefix: {outside}"
maps = open("/proc/self/maps").read()
cores = {line.split()[-1] for line in maps.splitlines() if "libexid_core" in line}
assert cores and all(os.path.realpath(c).startswith(prefix) for c in cores), cores
study = os.path.realpath(exid.data_path("examples/real/tx40_wls.yaml"))
assert study.startswith(prefix + "/share/exid/"), study
assert os.path.isfile(exid.data_path("data/staubli_tx40/urdf/tx40_mdh_modified.urdf"))
assert os.path.isfile(exid.data_path("robots/tx40/tx40_exid.xml"))
print(f"installed package: {len(libs)} plugin libraries and libexid_core from {prefix}")
PY
