#!/usr/bin/env bash
# The wheel (pyproject.toml, python/build_backend/exid_build.py) as a researcher installs it:
# built by pip from the source tree (from BUILD_DIR, an existing build tree: EXID_BUILD_DIR),
# installed into a fresh virtual environment of PYTHON (--system-site-packages: numpy and
# pandas from Debian), then, from a folder outside the source tree with nothing else on
# PYTHONPATH, the package's pytest tests and the notebooks run against it. The module must load
# the wheel's libexid_core and plugins alone. Usage: wheel.sh SOURCE_DIR BUILD_DIR PYTHON
set -euo pipefail
src=$(cd "$1" && pwd)
build=$(cd "$2" && pwd)
python=$3
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"
# The command docs/python.md gives, with the wheel kept (pip wheel) to check its contents.
EXID_BUILD_DIR="$build" "$python" -m pip wheel --no-build-isolation --no-index --no-deps \
  -q -w "$work/dist" "$src"
wheel=$(ls "$work"/dist/exid-*.whl)
echo "wheel.sh: $(basename "$wheel") ($(du -k "$wheel" | cut -f1) kB)"
"$python" -m venv --system-site-packages "$work/venv"
"$work/venv/bin/python" -m pip install -q --no-index --no-deps "$wheel"
unset PYTHONPATH EXID_PLUGIN_PATH EXID_DATA_DIR
export MPLBACKEND=Agg PYTHONDONTWRITEBYTECODE=1 PYDEVD_DISABLE_FILE_VALIDATION=1
"$work/venv/bin/python" - "$work/venv" <<'PY'
import os
import sys

import exid

venv = os.path.realpath(sys.argv[1])
inside = lambda p: os.path.realpath(p).startswith(venv + os.sep)  # noqa: E731
assert inside(exid.__file__), exid.__file__
libs = sorted({p["library"] for p in exid.plugins()})
assert libs and all(inside(lib) for lib in libs), f"plugins from outside the wheel: {libs}"
assert all(inside(d) for d in exid.plugin_search_paths()), exid.plugin_search_paths()
maps = open("/proc/self/maps").read()
cores = {line.split()[-1] for line in maps.splitlines() if "libexid_core" in line}
assert cores and all(inside(c) for c in cores), cores
assert inside(exid.data_path("examples/real/tx40_wls.yaml"))
print(f"wheel.sh: exid {exid.__version__} with {len(libs)} plugin libraries from {venv}")
PY
# The tests, run from here (outside the source tree): they read the source tree's test inputs
# (EXID_SOURCE_DIR) but import the wheel's exid.
EXID_SOURCE_DIR="$src" "$work/venv/bin/python" -m pytest -q -p no:cacheprovider \
  --rootdir "$work" --basetemp "$work/pytest" "$src/tests/python"
for nb in "$src"/examples/notebooks/*.ipynb; do
  "$work/venv/bin/python" "$src/tests/python/run_notebook.py" "$nb" "$work/notebooks"
done
