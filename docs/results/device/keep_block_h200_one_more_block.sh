#!/bin/bash
# One more block of each keep-block run on the GPU: resume each, and as soon as a run has written
# its next checkpoint, stop it and put its folder in $OUT (so whatever finishes comes back).
T0=$(date +%s); el() { echo $(( $(date +%s) - T0 )); }
R=/tmp/runs; PY=python3
$PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH=/tmp/site:$PWD/.gpu/ab55b8c/src XLA_PYTHON_CLIENT_PREALLOCATE=false
git config --global --add safe.directory '*'
rm -rf $R; mkdir -p $R; cp -r .gpu/runs/* $R/
declare -A PID STAMP
for d in $R/*/*/; do d=${d%/}; k=$(basename $(dirname $d))__$(basename $d)
  STAMP[$k]=$(stat -c %Y.%i $d/checkpoint.npz)
  $PY -m remidi run --resume $d --quiet > $d.gpu2.log 2>&1 & PID[$k]=$!; done
echo "started ${#PID[@]} at $(el) s"
while [ ${#PID[@]} -gt 0 ]; do sleep 2
  for k in "${!PID[@]}"; do d=$R/${k%%__*}/${k#*__}
    if [ "$(stat -c %Y.%i $d/checkpoint.npz)" != "${STAMP[$k]}" ] || ! kill -0 ${PID[$k]} 2>/dev/null; then
      sleep 1; kill -KILL ${PID[$k]} 2>/dev/null; wait ${PID[$k]} 2>/dev/null
      tar -C $R -cf $OUT/$k.tar ${k%%__*}/${k#*__} ${k%%__*}/${k#*__}.gpu2.log; unset "PID[$k]"; echo "shipped $k at $(el) s"; fi
  done; done
echo "done at $(el) s"
