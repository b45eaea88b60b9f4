#!/usr/bin/env bash
# Installs exid from the build tree into a temporary prefix (or uses an installed exid: PREFIX
# given as third argument, e.g. /usr after `apt-get install ./exid_*.deb`), builds
# examples/out_of_tree_plugin against it with find_package(exid), loads its plugins with the
# installed exid and runs studies with them: the out-of-tree estimator (built on the installed
# estimator helpers) on noise-free data gives the true parameters; the templates (robot, model,
# trajectory, optimizer, experiment) are listed with their kind and version and used in studies
# whose results would be wrong if a template were broken (exact recovery, seeded noise, an
# excitation design within the limits, the exact gradients and Jacobian).
# Usage: out_of_tree_plugin.sh SRC BUILD [PREFIX]; CMAKE_BUILD_PARALLEL_LEVEL sets the build's
# jobs (default 2).
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
# The compiler exid was built with (a sanitized exid: its sanitizer runtime must be the plugin's).
cxx=()
if [ -f "$build/CMakeCache.txt" ]; then
  c=$(sed -n 's/^CMAKE_CXX_COMPILER:[A-Z]*=//p' "$build/CMakeCache.txt")
  if [ -n "$c" ]; then cxx=(-DCMAKE_CXX_COMPILER="$c"); fi
fi
cmake -S "$src/examples/out_of_tree_plugin" -B "$work/plugin" -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_PREFIX_PATH="$prefix" "${cxx[@]}" >/dev/null
cmake --build "$work/plugin" --parallel "${CMAKE_BUILD_PARALLEL_LEVEL:-2}" >/dev/null
# The plugins' Eigen products block as exid's own (EIGEN_NO_CPUID from exid::dynamics' interface):
# their bits do not follow the CPU's cache sizes
grep -rq -- "-DEIGEN_NO_CPUID" "$work/plugin" --include=flags.make
lib=$(find "$work/plugin" -name 'libexid_plugin_a_optimal.so' | head -n 1)
test -n "$lib"
dir=$(dirname "$lib")
out=$("$exid" --plugin-path "$dir" plugins info a_optimal)
echo "$out"
grep -q "criterion 'a_optimal' version 1.0" <<<"$out"
grep -q "weight" <<<"$out"
# global options also after the subcommand
"$exid" plugins info huber_ls --plugin-path "$dir" | grep -q "estimator 'huber_ls' version 1.0"
# The installed exid finds its own installed plugins without any path, and never searches the
# build tree it came from (no path of the building machine is compiled in).
"$exid" plugins criterion | grep -q "cond"
paths=$(env -u EXID_PLUGIN_PATH "$exid" plugins paths)
test -n "$paths"
if [ -d "$build" ]; then
  b=$(cd "$build" && pwd -P)
  while IFS= read -r p; do
    rp=$(realpath -m "$p")
    case "$rp" in "$b"/*|"$b") echo "FAIL: the installed exid searches $p in the build tree $b" >&2; exit 1 ;; esac
  done <<<"$paths"
fi
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

# ---------------------------------------------------------------- an embedding program
# The same study run by a program through the facade (exid/exid.hpp), with the plugins of this
# build: status ok, verdict ok; a study file that is not there: exit 1, the file named.
emb=$(find "$work/plugin" -name embed_study -type f | head -n 1)
test -n "$emb"
out=$(LD_LIBRARY_PATH="$prefix/lib:$prefix/lib64:${LD_LIBRARY_PATH:-}" "$emb" "$work/study.yaml" "$work/embedded" "$dir")
grep -q "^status: ok" <<<"$out" || { echo "FAIL: embed_study: $out" >&2; exit 1; }
grep -q "^verdict: ok" <<<"$out" || { echo "FAIL: embed_study: $out" >&2; exit 1; }
test -f "$work/embedded/summary.json"
if emsg=$(LD_LIBRARY_PATH="$prefix/lib:$prefix/lib64:${LD_LIBRARY_PATH:-}" "$emb" "$work/none.yaml" "$work/none" "$dir" 2>&1); then
  echo "FAIL: embed_study ran a study file that is not there" >&2; exit 1
fi
grep -q "none.yaml" <<<"$emsg" || { echo "FAIL: embed_study: the missing file is not named: $emsg" >&2; exit 1; }
test ! -e "$work/none"
echo "embedding program: OK"

# ---------------------------------------------------------------- the templates
# Each template is listed with its kind, version and a declared parameter.
for entry in "robot template_robot tool_mass_kg" "model template_model joints" \
  "trajectory template_sine period_s" "optimizer template_random_search max_evaluations" \
  "experiment template_sine_sim noise_tau_Nm"; do
  read -r kind name param <<<"$entry"
  out=$("$exid" --plugin-path "$dir" plugins info "$name")
  grep -q "^$kind '$name' version 1.0" <<<"$out" ||
    { echo "FAIL: plugins info $name: no \"$kind '$name' version 1.0\" in: $out" >&2; exit 1; }
  grep -q "$param" <<<"$out" ||
    { echo "FAIL: plugins info $name: no parameter $param" >&2; exit 1; }
done
fail() { echo "FAIL: $*" >&2; exit 1; }
# value OUT SECTION KEY: the first "KEY": value (number or string) inside the top-level SECTION
# of OUT/summary.json (written with an indent of 2: top-level keys start 2 spaces in).
value() {
  sed -n "/^  \"$2\": {/,/^  }/p" "$1/summary.json" |
    sed -n "s/^ *\"$3\": \"\{0,1\}\([^\",]*\)\"\{0,1\},\{0,1\}$/\1/p" | head -n 1
}
num() {  # num OUT SECTION KEY: the value, which must be a number
  local v
  v=$(value "$@")
  [[ $v =~ ^-?[0-9.]+([eE][-+]?[0-9]+)?$ ]] || fail "$1: $2.$3 is not a number: '$v'"
  echo "$v"
}
# expect WHAT AWK_CONDITION: fails the test with WHAT when the condition is false.
expect() { awk "BEGIN { exit !($2) }" || fail "$1 ($2)"; }
run_study() {  # run_study NAME: $work/NAME.yaml -> $work/NAME, status ok
  "$exid" -q --plugin-path "$dir" run "$work/$1.yaml" --out "$work/$1" >/dev/null ||
    fail "study $1 failed (message above)"
  grep -q '"status": "ok"' "$work/$1/summary.json" || fail "study $1: status not ok"
}

# Robot + model + experiment: noise-free simulated data of the arm with ideal drives, the
# rigid-body model, batch least squares: the true parameters (the simulation says it is one).
cat >"$work/tpl_ident.yaml" <<'YAML'
name: template_identification
robot: {type: template_robot, params: {drives: false}}
model: {type: template_model}
experiment: {type: template_sine_sim}
estimator: {type: batch_ls}
YAML
run_study tpl_ident
e_ident=$(num "$work/tpl_ident" identification param_rel_err)
expect "template_model on template_sine_sim data: param_rel_err $e_ident < 1e-8" "$e_ident < 1e-8"
test "$(value "$work/tpl_ident" experiment generator)" = template_sine_sim ||
  fail "experiment.meta.generator is not template_sine_sim"
test "$(value "$work/tpl_ident" experiment simulated)" = true || fail "meta.simulated is not true"
nb_ident=$(num "$work/tpl_ident" model n_base)

# The arm with its drives and the in-tree model `differential` (rotor inertia, Coulomb and
# viscous columns): the simulation's drive terms must be the robot's own.
cat >"$work/tpl_drives.yaml" <<'YAML'
name: template_drives
robot: {type: template_robot}
model: {type: differential}
experiment: {type: template_sine_sim}
estimator: {type: batch_ls}
YAML
run_study tpl_drives
e_drives=$(num "$work/tpl_drives" identification param_rel_err)
nb_drives=$(num "$work/tpl_drives" model n_base)
expect "differential on template_sine_sim data with drives: param_rel_err $e_drives < 1e-8" \
  "$e_drives < 1e-8"
expect "drive columns identified: $nb_drives base parameters > $nb_ident" "$nb_drives > $nb_ident"

# Seeded noise: the residual standard deviation is the noise's, the error is not zero, and the
# same seed gives the same result.
noisy='{type: template_sine_sim, params: {noise_tau_Nm: 0.05, seed: 11}}'
for i in 1 2; do
  sed -e 's/name: template_identification/name: template_noise/' \
    -e "s/{type: template_sine_sim}/$noisy/" "$work/tpl_ident.yaml" >"$work/tpl_noise$i.yaml"
  run_study "tpl_noise$i"
done
e_n1=$(num "$work/tpl_noise1" identification param_rel_err)
e_n2=$(num "$work/tpl_noise2" identification param_rel_err)
sigma=$(num "$work/tpl_noise1" identification sigma)
expect "noise_tau_Nm 0.05: residual sigma $sigma within 10 %" "$sigma > 0.045 && $sigma < 0.055"
expect "noisy data: 1e-8 < param_rel_err $e_n1 < 0.5" "$e_n1 > 1e-8 && $e_n1 < 0.5"
test "$e_n1" = "$e_n2" || fail "seeded noise not reproducible: $e_n1 vs $e_n2"

# Excitation design (the arm with a tool): trajectory template_sine, criterion cond, optimizer
# template_random_search with an evaluation budget and a seed, torque limits; template_sine_sim
# along the designed trajectory gives the exact parameters again. Twice: the same seed gives the
# same design.
cat >"$work/tpl_excite1.yaml" <<'YAML'
name: template_excitation
seed: 3
robot: {type: template_robot, params: {drives: false, tool_mass_kg: 0.5}}
model: {type: template_model}
excitation:
  trajectory: {type: template_sine, params: {period_s: 10, sample_period_s: 0.1}}
  criterion: {type: cond}
  optimizer: {type: template_random_search, params: {max_evaluations: 40, seed: 7}}
  constraints: {torque_margin: 0.8}
experiment: {type: template_sine_sim}
estimator: {type: batch_ls}
YAML
cp "$work/tpl_excite1.yaml" "$work/tpl_excite2.yaml"
run_study tpl_excite1
run_study tpl_excite2
x="$work/tpl_excite1"
j0=$(num "$x" excitation criterion_initial)
j1=$(num "$x" excitation criterion_final)
viol=$(num "$x" excitation max_constraint_violation)
evals=$(num "$x" excitation evaluations)
stop=$(value "$x" excitation stop_reason)
e_x=$(num "$x" identification param_rel_err)
expect "template_random_search: criterion_final $j1 < criterion_initial $j0" "$j1 < $j0"
expect "template_random_search: max_constraint_violation $viol <= 1e-9" "$viol <= 1e-9"
expect "template_random_search: $evals evaluations for a budget of 40" "$evals == 40"
test "$stop" = max_evaluations || fail "template_random_search stopped by '$stop'"
test "$(num "$work/tpl_excite2" excitation criterion_final)" = "$j1" ||
  fail "template_random_search is not reproducible with its seed"
grep -q '"type": "the excitation trajectory' "$x/summary.json" ||
  fail "template_sine_sim did not follow the excitation trajectory"
expect "identification along the designed trajectory: param_rel_err $e_x < 1e-8" "$e_x < 1e-8"

# The exact derivatives: optimizer sundials compares its adjoint gradient (template_sine's
# evaluateAt / vjpAt, template_model's fullDesignVjp) with central differences; nlopt's SLSQP
# needs the gradient (vjp) and template_sine's constraint Jacobian.
cat >"$work/tpl_grad.yaml" <<'YAML'
name: template_gradient
robot: {type: template_robot, params: {drives: false}}
model: {type: template_model}
excitation:
  trajectory: {type: template_sine}
  criterion: {type: cond}
  optimizer: {type: sundials, params: {max_iterations: 0, check_gradient: true, rtol: 1.0e-10}}
YAML
run_study tpl_grad
gerr=$(num "$work/tpl_grad" excitation max_rel_error)
expect "adjoint gradient vs central differences: max_rel_error $gerr < 1e-4" "$gerr < 1e-4"
# Testing your derivatives (docs/plugins.md): the example's own test, check_derivatives, checks
# a_optimal's dJ/dM, template_sine's and template_model's derivatives with the installed
# exid/gradient_check.hpp, and that the check fails on a wrong dJ/dM.
dout=$(ctest --test-dir "$work/plugin" -V 2>&1) || fail "check_derivatives failed: $dout"
grep -q "derivatives: OK" <<<"$dout" || fail "check_derivatives: no 'derivatives: OK' in: $dout"
grep -q "criterion 'a_optimal_slip': dJ/dM: FAILED" <<<"$dout" ||
  fail "check_derivatives did not show the wrong derivative caught: $dout"
cat >"$work/tpl_slsqp.yaml" <<'YAML'
name: template_slsqp
robot: {type: template_robot, params: {drives: false}}
model: {type: template_model}
excitation:
  trajectory: {type: template_sine}
  criterion: {type: cond}
  optimizer: {type: nlopt, params: {algorithm: LD_SLSQP, max_evaluations: 60}}
YAML
run_study tpl_slsqp
s0=$(num "$work/tpl_slsqp" excitation criterion_initial)
s1=$(num "$work/tpl_slsqp" excitation criterion_final)
sv=$(num "$work/tpl_slsqp" excitation max_constraint_violation)
expect "SLSQP on template_sine: criterion_final $s1 < criterion_initial $s0 / 2" "$s1 < $s0 / 2"
expect "SLSQP on template_sine: max_constraint_violation $sv <= 1e-9" "$sv <= 1e-9"
echo "templates: OK (identification param_rel_err $e_ident, with drives $e_drives," \
  "noisy $e_n1 with sigma $sigma; excitation cond $j0 -> $j1 in $evals evaluations ($stop)," \
  "violation $viol, then param_rel_err $e_x; gradient rel. error $gerr; SLSQP $s0 -> $s1;" \
  "check_derivatives passed)"
