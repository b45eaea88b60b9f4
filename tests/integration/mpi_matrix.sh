#!/usr/bin/env bash
# mpirun -np 2 exid matrix gives the same results as the single-process run.
set -euo pipefail
exid=$1
src=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cat > "$work/m.yaml" <<'YAML'
name: mpi
study:
  robot: {type: planar2r}
  model: {type: differential, params: {rotor_inertia: false, coulomb: false, viscous: false}}
  experiment: {type: simulate, params: {duration_s: 2, drive_terms: false, noise_tau_Nm: 0.01}}
  estimator: {type: batch_ls}
axes:
  estimator: [{type: batch_ls}, {type: wls}, {type: rls}]
  seed: [1, 2]
YAML
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_mpi_warn_on_fork=0
export OMPI_MCA_rmaps_base_oversubscribe=1 OMPI_MCA_btl=self,vader OMPI_MCA_plm=isolated 2>/dev/null || true
"$exid" -q matrix "$work/m.yaml" --out "$work/single"
mpirun --oversubscribe -np 2 "$exid" -q matrix "$work/m.yaml" --out "$work/mpi"
test -f "$work/mpi/results.sqlite"
test -f "$work/mpi/shard-0-of-2.sqlite"
test -f "$work/mpi/shard-1-of-2.sqlite"
a=$("$exid" matrix table "$work/single" --rows estimator,seed --metric param_rel_err)
b=$("$exid" matrix table "$work/mpi" --rows estimator,seed --metric param_rel_err)
echo "$b"
if [ "$a" != "${b//$work\/mpi/$work\/single}" ]; then
  echo "single-process and MPI tables differ:"; echo "$a"; exit 1
fi
test "$(grep -c '^| ' <<<"$b")" = 7   # the header and the 6 cells
echo "mpi matrix: OK"
