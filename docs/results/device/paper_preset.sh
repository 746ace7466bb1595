#!/usr/bin/env bash
# One call on a lent GPU (the `device` tool's `run`, 10 minutes at most): first `remidi bench BENCH`
# with the seeds vmapped as the runs train them, then the PRESET (default `paper`) of experiment
# EXP for each of ALGOS, SEEDS seeds each, side by side on the one GPU, until DEADLINE seconds after
# the start; then SIGTERM (each run finishes its block under way, checkpoints and exits 143), and
# the runs' histories, configs and logs come back as $OUT/EXP-PRESET.tgz; their checkpoints come
# back too, xz-compressed, as many as fit beside it (a call brings back at most 8 files, 64 MiB in
# all) in $OUT/checkpoints.tar.part-* (15 MiB parts), in the order CKPT_ORDER (default ALGOS).
# The defaults are the scale study's paper point: T-maze PLR⊥ and ReMiDi, 10 seeds each.
#
#   device run: SRC=.gpu/<commit>/src bash docs/results/device/paper_preset.sh
#     (carry: .whl, the wheels the image lacks, and .gpu/<commit>, a depth-1 clone of the commit to
#     train, so that config.json records it: README.md beside this says how)
#   Brax (carry .whl-brax too): EXP=brax-ant ALGOS="plr minimax-return remidi" BENCH=brax-plr \
#     WHEELS=".whl .whl-brax" CHECKPOINT_EVERY=10 SRC=... bash docs/results/device/paper_preset.sh
#
#   Brax references at the paper's agent and envs (one DR seed, SETS: `--set` pairs of a fresh run):
#     EXP=brax-ant ALGOS=dr PRESET=reference SEEDS=1 BENCH= WHEELS=".whl .whl-brax" CHECKPOINT_EVERY=50 \
#     SETS="num_envs=256 hidden_size=0 lstm_size=0 ppo.minibatches=32" SRC=... bash docs/results/device/paper_preset.sh
#
# A run folder left in RUNS (default /tmp/gpu-runs) on a still-warm machine is resumed by a second call.
# The runs checkpoint every CHECKPOINT_EVERY updates (default 250, the maze paper preset's
# eval_every; it must be a multiple of the preset's eval_every), so a block cut off by the call's
# end loses at most that many updates; everything else is the preset.
set -u
T0=$(date +%s)
DEADLINE=${DEADLINE:-470}          # seconds after start at which the runs are asked to stop
HARD=${HARD:-560}                  # seconds after start at which whatever is still running is killed
PRESET=${PRESET:-paper}
SEEDS=${SEEDS:-10}
EXP=${EXP:-tmaze}
ALGOS=${ALGOS:-plr remidi}
CKPT_ORDER=${CKPT_ORDER:-$ALGOS}
CHECKPOINT_EVERY=${CHECKPOINT_EVERY:-250}
SETS=${SETS:-}                       # more KEY=VALUE overrides of a fresh run, e.g. "num_envs=256"
BENCH=${BENCH-maze-plr maze-remidi}  # BENCH= : no bench
WHEELS=${WHEELS:-.whl}               # folders of wheels to install (the image lacks them)
RUNS=${RUNS:-/tmp/gpu-runs}
OUT=${OUT:-/tmp/out}; mkdir -p "$OUT" "$RUNS/$EXP"
wheels=$(for w in $WHEELS; do ls "$w"/*.whl 2> /dev/null; done)
if [ -n "$wheels" ]; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site $wheels || exit 1
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

n=$(echo $ALGOS | wc -w)
export XLA_PYTHON_CLIENT_MEM_FRACTION=$(python3 -c "print(round(0.9 / $n, 2))")  # n processes on one GPU
pids=()
for algo in $ALGOS; do
  out=$RUNS/$EXP/$algo-$PRESET-s0
  if [ -f "$out/config.json" ]; then
    python3 -m remidi run --resume "$out" --quiet > "$OUT/$algo.log" 2>&1 &
  else
    python3 -m remidi run "$EXP" --algo "$algo" --preset "$PRESET" --seeds "$SEEDS" --out "$out" --quiet \
      --set checkpoint_every="$CHECKPOINT_EVERY" $(for kv in $SETS; do echo --set "$kv"; done) > "$OUT/$algo.log" 2>&1 &
  fi
  pids+=($!)
done
while [ "$(elapsed)" -lt "$DEADLINE" ] && kill -0 "${pids[@]}" 2> /dev/null; do sleep 5; done
echo "SIGTERM at $(elapsed) s"; kill -TERM "${pids[@]}" 2> /dev/null
while [ "$(elapsed)" -lt "$HARD" ] && kill -0 "${pids[@]}" 2> /dev/null; do sleep 2; done
kill -KILL "${pids[@]}" 2> /dev/null; wait
echo "stopped at $(elapsed) s"; for algo in $ALGOS; do tail -n 3 "$OUT/$algo.log"; done
python3 -m remidi status "$RUNS/$EXP"/*/ > "$OUT/status.txt" 2>&1; cat "$OUT/status.txt"
mv "$OUT"/*.log "$OUT"/status.txt "$RUNS/$EXP/" 2> /dev/null
tar czf "$OUT/$EXP-$PRESET.tgz" --exclude checkpoint.npz -C "$RUNS" "$EXP"
# the checkpoints (about 52 MB each for 10 seeds), xz-compressed, as many as fit in what is left
# of the 64 MiB a call brings back
left=$(( 63 * 1024 * 1024 - $(stat -c %s "$OUT/$EXP-$PRESET.tgz") - $(stat -c %s "$OUT/bench.json" 2> /dev/null || echo 0) ))
P=/tmp/pack; rm -rf "$P"; mkdir -p "$P"; taken=(); Z="xz -T0 -6"; command -v xz > /dev/null || Z="gzip -6"
for algo in $CKPT_ORDER; do f=$RUNS/$EXP/$algo-$PRESET-s0/checkpoint.npz; [ -f "$f" ] || continue
  z=$algo-$PRESET-s0.checkpoint.npz.${Z%% *}; $Z -c "$f" > "$P/$z"; size=$(stat -c %s "$P/$z")
  if [ "$size" -le "$left" ]; then left=$(( left - size )); taken+=("$z")
  else echo "checkpoint left on the device ($(( size / 1048576 )) MiB compressed): $f"; fi
done
[ ${#taken[@]} -gt 0 ] && tar -C "$P" -cf - "${taken[@]}" | split -b 15m - "$OUT/checkpoints.tar.part-"
ls -la "$OUT"; echo "checkpoints back: ${taken[*]:-none}; done at $(elapsed) s"
