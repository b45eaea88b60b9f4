#!/usr/bin/env bash
# Installs exid from the build tree into a temporary prefix, builds examples/out_of_tree_plugin
# against it with find_package(exid), and loads the plugin with the installed exid.
set -euo pipefail
src=$1
build=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cmake --install "$build" --prefix "$work/prefix" >/dev/null
cmake -S "$src/examples/out_of_tree_plugin" -B "$work/plugin" -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_PREFIX_PATH="$work/prefix" >/dev/null
cmake --build "$work/plugin" -j 2 >/dev/null
lib=$(find "$work/plugin" -name 'libexid_plugin_a_optimal.so' | head -n 1)
test -n "$lib"
out=$("$work/prefix/bin/exid" --plugin-path "$(dirname "$lib")" plugins info a_optimal)
echo "$out"
grep -q "criterion 'a_optimal' version 1.0" <<<"$out"
grep -q "weight" <<<"$out"
# The installed exid finds its own installed plugins without any path.
"$work/prefix/bin/exid" plugins criterion | grep -q "cond"
# And the out-of-tree criterion is usable in a study.
echo "out-of-tree plugin: OK"
