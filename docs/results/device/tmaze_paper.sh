#!/usr/bin/env bash
# One call on a lent GPU (the `device` tool's `run`, 10 minutes at most), for issue 48's scale
# study: first `remidi bench maze-plr maze-remidi` with the seeds vmapped as the runs train them,
# then the `paper` preset of T-maze PLR⊥ and ReMiDi, 10 seeds each, side by side on the one GPU,
# until DEADLINE seconds after the start; then SIGTERM (each run finishes its block under way,
# checkpoints and exits 143), and the runs' histories, configs and logs come back as
# $OUT/tmaze-paper.tgz; their checkpoints come back too, xz-compressed, as many as fit beside it
# (a call brings back at most 8 files, 64 MiB in all) in $OUT/checkpoints.tar.part-* (15 MiB parts).
#
#   device run: SRC=.gpu/<commit>/src bash docs/results/device/tmaze_paper.sh
#     (carry: .whl, the wheels the image lacks, and .gpu/<commit>, a depth-1 clone of the commit to
#     train, so that config.json records it: README.md beside this says how)
#
# A run folder left in RUNS (default /tmp/gpu-runs) on a still-warm machine is resumed by a second call.
# The runs checkpoint after every evaluation block (250 updates, the paper's eval_every), so a
# block cut off by the call's end loses at most one block; everything else is the paper preset.
set -u
T0=$(date +%s)
DEADLINE=${DEADLINE:-470}          # seconds after start at which the runs are asked to stop
HARD=${HARD:-560}                  # seconds after start at which whatever is still running is killed
PRESET=${PRESET:-paper}
SEEDS=${SEEDS:-10}
BENCH=${BENCH-maze-plr maze-remidi}  # BENCH= : no bench
RUNS=${RUNS:-/tmp/gpu-runs}
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT" "$RUNS/tmaze"
if [ -d .whl ] && ls .whl/*.whl > /dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
  export PYTHONPATH=/tmp/site
fi
SRC=${SRC:-$PWD/src}
export PYTHONPATH="$(cd "$SRC" && pwd)${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
git config --global --add safe.directory '*' 2> /dev/null
elapsed() { echo $(( $(date +%s) - T0 )); }
nvidia-smi -L 2>/dev/null
python3 -c "import jax, flax, optax, remidi.files as f; print('jax', jax.__version__, 'flax', flax.__version__, 'optax', optax.__version__, jax.devices(), f.code_version())" || exit 1

if [ -n "$BENCH" ]; then  # the GPU figure for docs/performance.md
  REMIDI_BENCH_SEEDS=$SEEDS timeout 170 python3 -m remidi bench $BENCH --seeds "$SEEDS" --repeats 2 --json \
    > "$OUT/bench.json" 2> "$OUT/bench.log"
  echo "bench exit $? at $(elapsed) s"; tail -n 4 "$OUT/bench.log"
fi

export XLA_PYTHON_CLIENT_MEM_FRACTION=0.45  # two processes on one GPU
pids=()
for algo in plr remidi; do
  out=$RUNS/tmaze/$algo-$PRESET-s0
  if [ -f "$out/config.json" ]; then
    python3 -m remidi run --resume "$out" --quiet > "$OUT/$algo.log" 2>&1 &
  else
    python3 -m remidi run tmaze --algo "$algo" --preset "$PRESET" --seeds "$SEEDS" --out "$out" --quiet \
      --set checkpoint_every=250 > "$OUT/$algo.log" 2>&1 &
  fi
  pids+=($!)
done
while [ "$(elapsed)" -lt "$DEADLINE" ] && kill -0 "${pids[@]}" 2> /dev/null; do sleep 5; done
echo "SIGTERM at $(elapsed) s"; kill -TERM "${pids[@]}" 2> /dev/null
while [ "$(elapsed)" -lt "$HARD" ] && kill -0 "${pids[@]}" 2> /dev/null; do sleep 2; done
kill -KILL "${pids[@]}" 2> /dev/null; wait
echo "stopped at $(elapsed) s"; tail -n 3 "$OUT"/plr.log "$OUT"/remidi.log
python3 -m remidi status "$RUNS"/tmaze/*/ > "$OUT/status.txt" 2>&1; cat "$OUT/status.txt"
mv "$OUT"/plr.log "$OUT"/remidi.log "$OUT"/bench.log "$OUT"/status.txt "$RUNS/tmaze/" 2> /dev/null
tar czf "$OUT/tmaze-$PRESET.tgz" --exclude checkpoint.npz -C "$RUNS" tmaze
# the checkpoints (about 52 MB each for 10 seeds), xz-compressed, as many as fit in what is left
# of the 64 MiB a call brings back
left=$(( 63 * 1024 * 1024 - $(stat -c %s "$OUT/tmaze-$PRESET.tgz") - $(stat -c %s "$OUT/bench.json" 2> /dev/null || echo 0) ))
P=/tmp/pack; rm -rf "$P"; mkdir -p "$P"; taken=(); Z="xz -T0 -6"; command -v xz > /dev/null || Z="gzip -6"
for algo in remidi plr; do f=$RUNS/tmaze/$algo-$PRESET-s0/checkpoint.npz; [ -f "$f" ] || continue
  z=$algo-$PRESET-s0.checkpoint.npz.${Z%% *}; $Z -c "$f" > "$P/$z"; size=$(stat -c %s "$P/$z")
  if [ "$size" -le "$left" ]; then left=$(( left - size )); taken+=("$z")
  else echo "checkpoint left on the device ($(( size / 1048576 )) MiB compressed): $f"; fi
done
[ ${#taken[@]} -gt 0 ] && tar -C "$P" -cf - "${taken[@]}" | split -b 15m - "$OUT/checkpoints.tar.part-"
ls -la "$OUT"; echo "checkpoints back: ${taken[*]:-none}; done at $(elapsed) s"
