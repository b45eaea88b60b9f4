#!/usr/bin/env bash
# Installs exid from the build tree into a temporary prefix (or uses an installed exid: PREFIX
# given as third argument, e.g. /usr after `apt-get install ./exid_*.deb`), builds
# examples/out_of_tree_plugin against it with find_package(exid), loads both plugins with the
# installed exid and runs a study with the out-of-tree estimator (built on the installed
# estimator helpers): noise-free data give the true parameters.
set -euo pipefail
src=$1
build=$2
prefix=${3:-}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
if [ -z "$prefix" ]; then
  cmake --install "$build" --prefix "$work/prefix" >/dev/null
  prefix="$work/prefix"
fi
exid="$prefix/bin/exid"
cmake -S "$src/examples/out_of_tree_plugin" -B "$work/plugin" -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_PREFIX_PATH="$prefix" >/dev/null
cmake --build "$work/plugin" -j 2 >/dev/null
lib=$(find "$work/plugin" -name 'libexid_plugin_a_optimal.so' | head -n 1)
test -n "$lib"
dir=$(dirname "$lib")
out=$("$exid" --plugin-path "$dir" plugins info a_optimal)
echo "$out"
grep -q "criterion 'a_optimal' version 1.0" <<<"$out"
grep -q "weight" <<<"$out"
# global options also after the subcommand
"$exid" plugins info huber_ls --plugin-path "$dir" | grep -q "estimator 'huber_ls' version 1.0"
# The installed exid finds its own installed plugins without any path.
"$exid" plugins criterion | grep -q "cond"
# The out-of-tree estimator in a study: noise-free simulated data, exact recovery.
cat >"$work/study.yaml" <<'YAML'
name: huber_out_of_tree
robot: {type: planar2r}
model: {type: differential, params: {rotor_inertia: false, coulomb: false, viscous: false}}
experiment: {type: simulate, params: {duration_s: 4, drive_terms: false}}
estimator: {type: huber_ls}
YAML
"$exid" -q --plugin-path "$dir" run "$work/study.yaml" --out "$work/out" >/dev/null
grep -q '"status": "ok"' "$work/out/summary.json"
err=$(sed -n 's/.*"param_rel_err": \([-0-9.e+]*\).*/\1/p' "$work/out/summary.json" | head -n 1)
test -n "$err"
awk -v e="$err" 'BEGIN { exit !(e < 1e-8) }' || { echo "huber_ls: param_rel_err $err" >&2; exit 1; }
echo "out-of-tree criterion and estimator: OK (huber_ls param_rel_err $err)"
