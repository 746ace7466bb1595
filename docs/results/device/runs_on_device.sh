#!/bin/bash
# The queue of ../runs.sh on a lent GPU: JOBS copies of runs.sh side by side (each takes the next
# run no other copy holds, as the CPU lanes do), SIGTERM to every run at DEADLINE s (each
# finishes the block under way, checkpoints it and stops: Python sees the signal only when XLA's
# call returns, so HARD − DEADLINE should exceed one block), SIGKILL at HARD s, and the run folders back under
# $OUT: each run xz-compressed on its own, as many whole runs as fit in BACK MiB (default 60; a call
# brings back at most 8 files of 16 MiB, 64 MiB in all) in one tar split into 15 MiB parts. The runs
# that do not fit are named (they stay on the device while it is warm: fetch them with a second call
# from $W/pack). A gzipped tar of all four 5-seed maze runs of 2026-11-26 came to 80 MB and its last
# part was left out: hence one archive per run and the size check.
#
#   on the device, from the checkout root:  [ONLY="EXP/NAME ..."] bash docs/results/device/runs_on_device.sh [JOBS]
#
# ONLY limits runs.sh's queue to the runs named (those not carried along start from update 0: name
# only runs the CPU has not started, or carry them).
#
# It expects, carried along (README): `.whl` (the wheels the image lacks), `.gpu/<commit>` (a
# depth-1 clone of each commit whose runs are still to train: runs.sh trains from
# $W/frozen-<commit>, linked to it, so no git history is needed) and, optionally, `.gpu/runs.txz`
# (run folders to resume, as `tar -C RUNS_DIR -cf - EXP/NAME ... | xz -T0 -6 > .gpu/runs.txz` packs
# them: a 5-seed cpu-preset simulated-model checkpoint, 95 MB, packs to 22 MB; `.gpu/runs.tgz` is
# read too). Unpack what comes back with
#   cat runs.tar.part-* | tar -C PACK -xf - && for f in PACK/*.txz; do tar -C RUNS_DIR -xJf "$f"; done
#
# Test the orchestration on the CPU without training (a stand-in python that sleeps until SIGTERM):
#   STANDIN=1 DEADLINE=20 HARD=30 OUT=/tmp/out W=/tmp/w bash docs/results/device/runs_on_device.sh 3
T0=$(date +%s); el() { echo $(( $(date +%s) - T0 )); }
JOBS=${1:-8}; DEADLINE=${DEADLINE:-400}; HARD=${HARD:-575}; W=${W:-/tmp/w}; R=$W/runs; OUT=${OUT:?OUT: where the parts go}
PY=${PY:-python3}; NP=${NP:-python3}  # NP: a python with numpy, to read checkpoints
rm -rf "$W"; mkdir -p "$R" "$OUT"
if [ -n "${STANDIN:-}" ]; then  # a python that logs its arguments and waits for SIGTERM
  printf '#!/bin/bash\necho "$(date +%%T) $*" >> %s/standin.log\ntrap "exit 0" TERM\nwhile :; do sleep 1; done\n' "$W" > "$W/python"
  chmod +x "$W/python"; PY=$W/python
else
  $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$W/site" .whl/*.whl || exit 1
  export RUNS_PYTHONPATH=$W/site XLA_PYTHON_CLIENT_PREALLOCATE=false
  git config --global --add safe.directory '*'; nvidia-smi -L
fi
for c in .gpu/*/; do c=${c%/}; [ -d "$c/src/remidi" ] && ln -s "$PWD/$c" "$W/frozen-${c#.gpu/}" && echo "clone ${c#.gpu/}"; done
[ -f .gpu/runs.tgz ] && tar -C "$R" -xzf .gpu/runs.tgz
[ -f .gpu/runs.txz ] && tar -C "$R" -xJf .gpu/runs.txz
updates() {  # the last checkpointed update of every run folder
  for d in "$R"/*/*/; do [ -f "$d/checkpoint.npz" ] || continue
    echo "${d#$R/} $($NP -c "import numpy as np; print(int(np.load('$d/checkpoint.npz')['leaf:.update'].max()))" 2>/dev/null)"; done; }
updates > "$W/updates-before.txt"
for j in $(seq "$JOBS"); do PYTHON=$PY bash docs/results/runs.sh "$R" > "$W/job$j.log" 2>&1 & sleep 2; done
echo "$JOBS jobs at $(el) s"
while [ -n "$(jobs -rp)" ] && [ "$(el)" -lt "$DEADLINE" ]; do sleep 5; done
# stop the queues first (or each would start its next run), then their runs: SIGTERM, each checkpoints
queues=$(jobs -rp); runs=$(for q in $queues; do pgrep -P "$q"; done)
kill -KILL $queues 2>/dev/null; wait 2>/dev/null
kill -TERM $runs 2>/dev/null; echo "SIGTERM to $(echo $runs | wc -w) runs at $(el) s"
alive() { for p in $runs; do kill -0 "$p" 2>/dev/null && return 0; done; return 1; }
while alive && [ "$(el)" -lt "$HARD" ]; do sleep 2; done
kill -KILL $runs 2>/dev/null; echo "stopped at $(el) s"
updates > "$W/updates-after.txt"; join -a 2 -e - -o 0,1.2,2.2 "$W/updates-before.txt" "$W/updates-after.txt"  # run, before, after
cp "$W"/job*.log "$W"/updates-*.txt "$R/" 2>/dev/null
# one xz archive per run (its folder and log), then as many whole runs as fit in BACK MiB, by folder name
P=$W/pack; mkdir -p "$P"; cap=$(( ${BACK:-60} * 1024 * 1024 )); used=0; taken=()
tar -C "$R" -cJf "$P/logs.txz" $(cd "$R" && ls job*.log updates-*.txt 2>/dev/null); taken+=(logs.txz)
for d in "$R"/*/*/; do run=${d#$R/}; run=${run%/}; f=${run/\//+}.txz
  tar -C "$R" -cf - "$run" $(cd "$R" && ls "$run.log" 2>/dev/null) | xz -T0 -6 > "$P/$f"
  size=$(stat -c %s "$P/$f")
  if [ $(( used + size )) -le "$cap" ]; then used=$(( used + size )); taken+=("$f")
  else echo "LEFT ON THE DEVICE ($(( size / 1048576 )) MiB, over BACK): $P/$f"; fi
done
tar -C "$P" -cf - "${taken[@]}" | split -b 15m - "$OUT/runs.tar.part-"
ls -la "$OUT"; echo "back: ${taken[*]}"; echo "done at $(el) s"
