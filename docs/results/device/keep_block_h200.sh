#!/bin/bash
# The keep-skills block (issue #31, commit ab55b8c) on a lent GPU, side by side; SIGTERM at DEADLINE s,
# SIGKILL at HARD s; every run folder comes back as a split tar under $OUT.
T0=$(date +%s); DEADLINE=${DEADLINE:-470}; HARD=${HARD:-545}; PY=${PY:-python3}; R=${R:-/tmp/runs}; OUT=${OUT:-/tmp/out}
el() { echo $(( $(date +%s) - T0 )); }
if [ -z "${LOCALTEST:-}" ]; then
  $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
  export PYTHONPATH=/tmp/site:$PWD/.gpu/ab55b8c/src
  export XLA_PYTHON_CLIENT_PREALLOCATE=false
  git config --global --add safe.directory '*'
  nvidia-smi -L; git --version
else
  export PYTHONPATH=$PWD/.gpu/ab55b8c/src
fi
$PY -c "import jax, jaxued, remidi.experiments.maze, remidi.files as f; print(jax.devices(), f.code_version())" || exit 1
mkdir -p $R/blindfold $R/tmaze $OUT
cp -r .gpu/runs/blindfold/remidi-combine-s0 $R/blindfold/
$PY -m remidi run --resume $R/blindfold/remidi-combine-s0 --quiet > $R/blindfold/remidi-combine-s0.log 2>&1 &
run() { local name=$1 exp=$2; shift 2
  $PY -m remidi run $exp --algo remidi --preset cpu --seed 0 --seeds 5 --out $R/$exp/$name --quiet "$@" > $R/$exp/$name.log 2>&1 & }
for e in blindfold tmaze; do
  run remidi-masked-s0 $e --set remidi.policy=masked
  [ $e = tmaze ] && run remidi-combine-s0 $e --set remidi.policy=combine
  run remidi-rehearsal0.1-s0 $e --set remidi.rehearsal=0.1
  run remidi-rehearsal0.3-s0 $e --set remidi.rehearsal=0.3
done
progress() { echo "== $(el) s"; for d in $R/*/*/; do
  u=$($PY -c "import numpy as np; print(int(np.load('$d/checkpoint.npz')['leaf:.update'].max()))" 2>/dev/null); echo "$d ${u:-none} $(ls $d | tr '\n' ' ')"; done; }
n=0; while [ -n "$(jobs -rp)" ] && [ $(el) -lt $DEADLINE ]; do sleep 15; n=$((n+1)); [ $((n % 6)) -eq 0 ] && progress; done
echo "== SIGTERM at $(el) s"; kill -TERM $(jobs -rp) 2>/dev/null
while [ -n "$(jobs -rp)" ] && [ $(el) -lt $HARD ]; do sleep 2; done
echo "== SIGKILL at $(el) s: $(jobs -rp | wc -l) left"; kill -KILL $(jobs -rp) 2>/dev/null; wait
progress
for f in $R/*/*.log; do echo "--- $f"; tail -n 4 $f; done
tar -C $R -cf - . | split -b 15m - $OUT/runs.tar.part-
ls -la $OUT; echo "== done at $(el) s"
