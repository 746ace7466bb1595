#!/usr/bin/env bash
# The runs behind docs/results.md, one after another, each block at the commit its claims name.
#
#   bash docs/results/runs.sh [RUNS_DIR]      # default /work/runs; rerun it to continue
#
# Each block trains from a worktree of its commit (so that work on the checkout does not change
# what the runs execute), then `remidi evaluate --attempts 30` scores each run's final
# checkpoint. Rerunning the script skips finished runs (and those whose data are already
# committed under docs/results/data/ or references/, so a fresh machine starts where the page
# stands) and resumes an interrupted one from its last checkpoint (`remidi run --resume`), on a
# fresh machine from the archive docs/results/carry.sh committed under docs/results/inflight/
# (a machine of this project keeps nothing outside the checkout between sessions: carry the
# unfinished runs before one ends). When a run has finished, copy its small outputs into the
# page's data and regenerate the page (which deletes its archive):
#
#   python -m tools.results.page --collect RUNS_DIR/<experiment>/<run>    # from the repository root
#
# (a committed run trained again, under RUNS_DIR/repeats/: --collect-repeat instead of --collect).
#
# On a CPU, two lanes (one process per core, XLA on one thread) train 1.36× faster in total than
# one process on both cores (`remidi bench maze-plr --lanes 2`, docs/performance.md). Each lane
# takes the next run that no other lane holds (a `flock` on RUNS_DIR/EXPERIMENT/NAME.lock, released
# when its process ends), so lanes stay busy until the list is done.
#
#   for l in 0 1; do LANES=2 LANE=$l nohup bash docs/results/runs.sh RUNS_DIR > lane$l.log 2>&1 & done
#
# The runs train with --quiet; `remidi status RUNS_DIR/*/*/` says where each stands (its last
# checkpoint, each part's device and rate, the time left, stalled seeds).
#
# ONLY="EXPERIMENT/NAME ..." limits the queue to those runs; RUNS_PYTHONPATH is appended to each
# commit's PYTHONPATH (device/runs_on_device.sh uses both on a lent GPU).
set -u
HERE=$(cd "$(dirname "$0")/../.." && pwd)
R=${1:-/work/runs}
PY=${PYTHON:-python}
LANES=${LANES:-1}; LANE=${LANE:-0}
# JAX's persistent compilation cache beside the runs: a resume compiles the run's block again, which
# took 7.6 min on a CPU lane for a simulated-model maze run (cpu preset), and with the cache only once
export JAX_COMPILATION_CACHE_DIR=${JAX_COMPILATION_CACHE_DIR:-$R/.jax-cache}
if [ "$LANES" -gt 1 ]; then  # pin this lane to its core, XLA on one thread
  export XLA_FLAGS="${XLA_FLAGS:-} --xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
  PY="taskset -c $LANE $PY"
fi
at() { AT=$1; }  # at COMMIT: the runs that follow train with that commit's code
SUB=  # "repeats/" while the runs that follow are committed runs trained again (RUNS_DIR/repeats/...)
checkout() {  # the code of commit $AT on PYTHONPATH (a worktree beside RUNS_DIR, made when a run first needs it)
  local frozen=$(dirname "$R")/frozen-$AT
  if [ ! -d "$frozen" ]; then git -C "$HERE" worktree add --detach "$frozen" "$AT" || [ -d "$frozen" ] || exit 1; fi
  export PYTHONPATH="$frozen/src${RUNS_PYTHONPATH:+:$RUNS_PYTHONPATH}"  # RUNS_PYTHONPATH: e.g. a device's wheels
}
collected() {  # collected EXPERIMENT NAME: the finished run's data are committed (a folder with its
  # config.json and a summary.json; a run collected while it trains has no summary.json there)
  local f; for f in $(grep -ls -- "/$SUB$1/$2\"" "$HERE"/docs/results/${SUB:-data/}"$1"/*/config.json); do
    [ -f "${f%/config.json}/summary.json" ] && return 0; done; return 1; }
run() {  # run NAME EXPERIMENT ALGO FIRST_SEED N_SEEDS PRESET [--set ...]: into RUNS_DIR/EXPERIMENT/NAME
  local name=$1 exp=$2 algo=$3 s=$4 n=$5 preset=$6; shift 6
  local out=$R/$SUB$exp/$name
  if [ -n "${ONLY:-}" ] && [[ " $ONLY " != *" $SUB$exp/$name "* ]]; then return; fi  # ONLY="EXP/NAME ...": just those
  if collected "$exp" "$name" ||
     { [ "$preset" = reference ] && [ -f "$HERE/docs/results/references/$exp.csv" ]; }; then  # collected already
    echo "committed: $SUB$exp/$name"; return; fi
  if [ -f "$out/evaluate.json" ]; then echo "done: $out"; return; fi
  mkdir -p "$R/$SUB$exp"; local lock; exec {lock}>"$out.lock"
  if ! flock -n "$lock"; then exec {lock}>&-; return 0; fi  # another lane is on it
  checkout
  local carried=$HERE/docs/results/inflight/$SUB$exp/$name.txz  # carried from an earlier machine (carry.sh)
  if [ ! -f "$out/checkpoint.npz" ] && [ -f "$carried" ]; then
    echo "$(date +%T) unpack $carried"; rm -rf "$out"; tar -C "$R" -xJf "$carried" || exit 1
  fi
  if [ -f "$out/summary.json" ]; then :
  elif [ -f "$out/config.json" ]; then
    echo "$(date +%T) resume $out"; $PY -m remidi run --resume "$out" --quiet >> "$out.log" 2>&1
  else
    echo "$(date +%T) start $out"
    $PY -m remidi run "$exp" --algo "$algo" --preset "$preset" --seed "$s" --seeds "$n" --out "$out" --quiet "$@" \
      > "$out.log" 2>&1
  fi
  echo "$(date +%T) exit $? $out"
  if [ -f "$out/summary.json" ] && [ ! -f "$out/evaluate.json" ] && [ "$preset" != reference ]; then
    $PY -m remidi evaluate "$out" --attempts 30 >> "$out.log" 2>&1; echo "$(date +%T) evaluated $? $out"
  fi
  exec {lock}>&-
}

evaluate_mode() {  # evaluate_mode EXPERIMENT NAME: a finished run's final checkpoint, acting with its most likely action
  local exp=$1 name=$2 out=$R/$SUB$1/$2
  if [ -n "${ONLY:-}" ] && [[ " $ONLY " != *" $SUB$exp/$name "* ]]; then return; fi
  if [ -f "$HERE/docs/results/${SUB:-data/}$exp/$name/evaluate-mode.json" ]; then echo "committed: $SUB$exp/$name (mode)"; return; fi
  if [ ! -f "$out/summary.json" ] || [ ! -f "$out/checkpoint.npz" ] || [ -f "$out/evaluate-mode.json" ]; then return; fi
  local lock; exec {lock}>"$out.lock"
  if ! flock -n "$lock"; then exec {lock}>&-; return 0; fi
  checkout
  $PY -m remidi evaluate "$out" --attempts 30 --action mode >> "$out.log" 2>&1; echo "$(date +%T) evaluated (mode) $? $out"
  exec {lock}>&-
}

# issue #28: the paper's claims, every run at one commit
at c32046b
for e in tabular-shared tabular-distinct; do  # both algorithms, the preset's 50 seeds, seconds each
  [ "$LANE" -ne 0 ] || [ -d "$HERE/docs/results/data/$e" ] || [ -f "$R/$e/all/remidi/summary.json" ] ||
    { checkout; $PY -m remidi run "$e" --preset paper --out "$R/$e/all" --quiet; }
done
for a in dr plr remidi minimax-return accel remidi-accel; do run "$a-s0" lever "$a" 0 10 paper; done
for s in 0 5; do run "plr-s$s" tmaze plr $s 5 cpu; run "remidi-s$s" tmaze remidi $s 5 cpu; done
for s in 0 5; do run "plr-s$s" blindfold plr $s 5 cpu; run "remidi-s$s" blindfold remidi $s 5 cpu; done
for s in 0 5; do run "minimax-return-s$s" tmaze minimax-return $s 5 cpu; done
for s in 0 5; do run "minimax-return-s$s" blindfold minimax-return $s 5 cpu; done
run dr-s0 tmaze dr 0 5 cpu
run dr-s0 blindfold dr 0 5 cpu
# Brax: the references of halfcheetah and ant trained to a plateau first (500 updates were still
# rising); their values then go into src/remidi/experiments/brax_reference.json, and the Brax runs
# (PLR⊥, minimax return, ReMiDi, 5 seeds, cpu preset) use the commit that holds them
run reference brax-halfcheetah dr 0 1 reference --set num_updates=2000
run reference brax-ant dr 0 1 reference --set num_updates=2000

# Brax (#28): PLR⊥, minimax return and ReMiDi, 5 seeds of the cpu preset, at the commit whose
# brax_reference.json holds the halfcheetah and ant references above (2000 updates)
at d071065
for m in ant halfcheetah hopper walker2d; do
  for a in plr minimax-return remidi; do run "$a-s0" "brax-$m" "$a" 0 5 cpu; done
done
# (the floors of the Brax and maze sections, policies that learn nothing, are no run: `python -m
# tools.results.floors` writes docs/results/references/floors.json in minutes)

# issue #29: PAIRED and ReMiDi over PAIRED on the lever game. Their claims were stated at 76e7226
# and first run there; both rerun at ab3ea79, where a generator's reservoir keeps a repeated
# level's highest key (at 76e7226 a repeat took its newest key, and the untrained generator's
# early levels crowded the frozen support: about a third of it visible levels, each then masked)
at ab3ea79
run paired-perfect-s0 lever paired 0 10 paper --set paired.estimator=perfect
run remidi-paired-perfect-s0 lever remidi-paired 0 10 paper --set paired.estimator=perfect
# PAIRED's own estimator, exploratory: at the commit that logs where its regret comes from (the
# antagonist's luck on hidden levels against the exact regret, per tag)
at 40ca202
run paired-paired-s0 lever paired 0 10 paper --set paired.estimator=paired

# issue #29: PAIRED and ReMiDi over PAIRED on the T-maze (cpu preset, perfect regret), at the commit
# that stated their claims (ReMiDi over PAIRED's runs here, remidi-paired-perfect-s0 and -s5, were
# superseded by the rerun at ab3ea79 below and are no longer run)
at 569c639
for s in 0 5; do run "paired-perfect-s$s" tmaze paired $s 5 cpu --set paired.estimator=perfect; done

# issue #31: the exact tracker on the noisy domains (PLR⊥ and ReMiDi), at the commit that stated
# their claims: lever-noisy at the lever's paper preset (10 seeds), blindfold-noisy at cpu (5 + 5)
at 6303b59
for a in plr remidi; do run "$a-s0" lever-noisy "$a" 0 10 paper; done
for s in 0 5; do for a in plr remidi; do run "$a-s$s" blindfold-noisy "$a" $s 5 cpu; done; done

# issue #31: the learned belief tracker (remidi.tracker=belief), at the commit that stated its
# claims: on the deterministic lever (defaults: agreement with the exact tracker) and on
# lever-noisy (defaults, and belief_margin 2), the lever's paper preset, 10 seeds
at 428dc27
run remidi-belief-s0 lever remidi 0 10 paper --set remidi.tracker=belief
run remidi-belief-margin2-s0 lever-noisy remidi 0 10 paper --set remidi.tracker=belief --set remidi.belief_margin=2
run remidi-belief-s0 lever-noisy remidi 0 10 paper --set remidi.tracker=belief

# issue #31: keeping earlier skills (the masked policy, combine, rehearsal 0.1 and 0.3), blindfold
# and T-maze, cpu preset, 5 seeds each, all at the commit that stated their claims. A lent H200 trained
# the eight runs side by side for nine minutes (blindfold combine from its update 600), then seven of
# them one block more (each config.json notes its updates per device); the CPU finishes them, the
# nearly finished ones first
at ab55b8c
run remidi-combine-s0 blindfold remidi 0 5 cpu --set remidi.policy=combine
for e in blindfold tmaze; do run remidi-masked-s0 $e remidi 0 5 cpu --set remidi.policy=masked; done
for e in blindfold tmaze; do
  run remidi-combine-s0 $e remidi 0 5 cpu --set remidi.policy=combine
  run remidi-rehearsal0.1-s0 $e remidi 0 5 cpu --set remidi.rehearsal=0.1
  run remidi-rehearsal0.3-s0 $e remidi 0 5 cpu --set remidi.rehearsal=0.3
done

# issue #31: the simulated belief model (remidi.tracker=simulated) and the learned belief tracker
# (remidi.tracker=belief) on the mazes, cpu preset, 5 seeds each. The simulated model's claims were
# stated at f199ddc, the belief tracker's at e113661. Their first runs (at aeff7a8, f199ddc with the
# seed-batch branch of 7369c07, and at b6e5399) were lost unfinished with the machine that trained
# them, aeff7a8 with it (a local branch); all four start again at cc0e7b3, the trackers after their
# reviews: the GRU model (the simulated model's reference, and the belief tracker's model) predicts
# episode ends (b96ae29), rare branches stay branches over seeds (7369c07, 8x faster per update
# at 5 seeds)
at cc0e7b3
for e in blindfold-noisy tmaze; do
  run remidi-simulated-s0 $e remidi 0 5 cpu --set remidi.tracker=simulated --set remidi.belief_reference=true \
    --set remidi.belief_false_rate=0 --set remidi.belief_margin=5
done
for e in blindfold-noisy tmaze; do run remidi-belief-s0 $e remidi 0 5 cpu --set remidi.tracker=belief; done

# issue #31: ReMiDi over PAIRED on lever-noisy (perfect regret), the exact tracker and the learned
# belief tracker (a model of each generator's trajectories), the lever's paper preset, 10 seeds,
# at the commit that stated their claims
at 3e5a339
run remidi-paired-perfect-s0 lever-noisy remidi-paired 0 10 paper --set paired.estimator=perfect
run remidi-paired-perfect-belief-s0 lever-noisy remidi-paired 0 10 paper --set paired.estimator=perfect --set remidi.tracker=belief

# ReMiDi over PAIRED on the T-maze again, at ab3ea79, where a generator's reservoir keeps a repeated
# level's highest key (the runs above, at 569c639, froze supports in which a T-maze made in every
# update had one uniform key, like a maze made once). Their data replaced remidi-paired-perfect-s0
# and -s5 on the page on 2026-11-29 (PAIRED's runs stay at 569c639: the reservoir is ReMiDi over
# PAIRED's alone)
at ab3ea79
for s in 0 5; do
  run "remidi-paired-perfect-keephigh-s$s" tmaze remidi-paired $s 5 cpu --set paired.estimator=perfect
done

# The scale study: the maze claims at the cpu4x preset (4× cpu's environment steps), 5 seeds of
# PLR⊥ and ReMiDi on both tasks, at the commit that stated its claims and its rule (the results
# page's scale section); minimax return after the Brax seeds, as lane time allows
at 8214e56
for e in tmaze blindfold; do for a in plr remidi; do run "$a-cpu4x-s0" $e $a 0 5 cpu4x; done; done

brax_seeds() {  # brax_seeds FIRST_SEED: PLR⊥, minimax return and ReMiDi on every morphology, 5 seeds
  # of the cpu preset at the commit of Table 1's seeds 0–4, then each final checkpoint evaluated
  # again acting with the policy's mean (remidi evaluate --action mode) at the commit that added it
  local m a
  at d071065
  for m in ant halfcheetah hopper walker2d; do
    for a in plr minimax-return remidi; do run "$a-s$1" "brax-$m" "$a" "$1" 5 cpu; done
  done
  at 5d44609
  for m in ant halfcheetah hopper walker2d; do
    for a in plr minimax-return remidi; do evaluate_mode "brax-$m" "$a-s$1"; done
  done
}

# Table 1 at the paper's 10 seeds: seeds 5–9 (their final checkpoints kept, so evaluated both ways)
brax_seeds 5

at 8214e56
run "minimax-return-cpu4x-s0" tmaze minimax-return 0 5 cpu4x
# the blindfold run was started (2026-12-02) from the checkout at ac5a71a, whose checkpoints name the
# learner's state (.learner.train_state); 8214e56 cannot read them. It resumed from update 1,200 at
# 590cb41 (the engine reference unchanged between them), and resumes there
at 590cb41
run "minimax-return-cpu4x-s0" blindfold minimax-return 0 5 cpu4x

# Table 1's seeds 0–4 were trained again at their commit (SUB=repeats/ brax_seeds 0: RUNS_DIR/repeats/,
# collected with --collect-repeat into docs/results/repeats), because their final checkpoints were
# not kept. No claim reads them: after ant's three, the nine on halfcheetah, hopper and walker2d
# were dropped unrun (2026-12-02), and the block no longer runs.

# Kinetix (beyond the paper): DR, PLR⊥, SFL and ReMiDi on kinetix-s, cpu preset, 5 seeds each, at a
# commit after the one that stated their claims (55016af) with the same Kinetix code and faster
# start-up. Kinetix needs its extra, which caps JAX at 0.9: KINETIX_PYTHON names the python of an
# environment that has it (e.g. .ci/.venv-kinetix/bin/python); without it the block is skipped
if [ -n "${KINETIX_PYTHON:-}" ]; then
  at 254fe8c
  CORE_PY=$PY; PY="${PY%"${PYTHON:-python}"}$KINETIX_PYTHON"
  for a in dr plr sfl remidi; do run "$a-s0" kinetix-s "$a" 0 5 cpu; done
  PY=$CORE_PY
else
  echo "skipped: the Kinetix runs (set KINETIX_PYTHON to a python with the kinetix extra)"
fi

# issue 63: the constructed domains (claims stated at 839fdd2, before these runs): the dark room
# and dark reach, cpu preset, 5 seeds each, at the commit that holds both domains' final code
at 2ab6db9
run plr-s0 darkroom plr 0 5 cpu
run remidi-s0 darkroom remidi 0 5 cpu
run plr-s0 darkreach plr 0 5 cpu
run remidi-tolerance-s0 darkreach remidi 0 5 cpu
run remidi-exact-s0 darkreach remidi 0 5 cpu --set remidi.tracker=prefix
run plr-s0 darkreach-lit plr 0 5 cpu
run remidi-tolerance-s0 darkreach-lit remidi 0 5 cpu
