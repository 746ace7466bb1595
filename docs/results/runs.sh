#!/usr/bin/env bash
# The runs behind docs/results.md (issue #28), one after another, at the one commit they all use.
#
#   bash docs/results/runs.sh [RUNS_DIR]      # default /work/runs; rerun it to continue
#
# Each run trains at commit $COMMIT from a worktree of its own (so that work on the checkout does
# not change what the runs execute), then `remidi evaluate --attempts 30` scores its final
# checkpoint. Rerunning the script skips finished runs and resumes an interrupted one from its
# last checkpoint (`remidi run --resume`). When a run has finished, copy its small outputs into
# the page's data and regenerate the page:
#
#   python -m remidi.experiments.results_page --collect RUNS_DIR/<experiment>/<algo>-s<seed>
set -u
COMMIT=c32046b
HERE=$(cd "$(dirname "$0")/../.." && pwd)
R=${1:-/work/runs}
FROZEN=${FROZEN:-$(dirname "$R")/frozen-$COMMIT}
PY=${PYTHON:-python}
if [ ! -d "$FROZEN" ]; then git -C "$HERE" worktree add --detach "$FROZEN" "$COMMIT" || exit 1; fi
export PYTHONPATH="$FROZEN/src"
run() {  # run EXPERIMENT ALGO FIRST_SEED N_SEEDS PRESET [extra --set ...]
  local exp=$1 algo=$2 s=$3 n=$4 preset=$5; shift 5
  local out=$R/$exp/$algo-s$s
  [ "$preset" = reference ] && out=$R/$exp/reference
  if [ -f "$out/evaluate.json" ]; then echo "done: $out"; return; fi
  if [ -f "$out/summary.json" ]; then :
  elif [ -f "$out/config.json" ]; then
    echo "$(date +%T) resume $out"; $PY -m remidi run --resume "$out" --quiet >> "$out.log" 2>&1
  else
    mkdir -p "$R/$exp"; echo "$(date +%T) start $out"
    $PY -m remidi run "$exp" --algo "$algo" --preset "$preset" --seed "$s" --seeds "$n" --out "$out" --quiet "$@" \
      > "$out.log" 2>&1
  fi
  echo "$(date +%T) exit $? $out"
  if [ -f "$out/summary.json" ] && [ ! -f "$out/evaluate.json" ] && [ "$preset" != reference ]; then
    $PY -m remidi evaluate "$out" --attempts 30 >> "$out.log" 2>&1; echo "$(date +%T) evaluated $? $out"
  fi
}
for e in tabular-shared tabular-distinct; do  # both algorithms, the preset's 50 seeds, seconds each
  [ -f "$R/$e/all/remidi/summary.json" ] || $PY -m remidi run "$e" --preset paper --out "$R/$e/all" --quiet
done
for a in dr plr remidi minimax-return accel remidi-accel; do run lever "$a" 0 10 paper; done
for s in 0 5; do run tmaze plr $s 5 cpu; run tmaze remidi $s 5 cpu; done
for s in 0 5; do run blindfold plr $s 5 cpu; run blindfold remidi $s 5 cpu; done
for s in 0 5; do run tmaze minimax-return $s 5 cpu; done
for s in 0 5; do run blindfold minimax-return $s 5 cpu; done
run tmaze dr 0 5 cpu
run blindfold dr 0 5 cpu
# Brax: the references of halfcheetah and ant trained to a plateau first (500 updates were still
# rising); their values then go into src/remidi/experiments/brax_reference.json, and the Brax runs
# (PLR⊥, minimax return, ReMiDi, 5 seeds, cpu preset) use the commit that holds them
run brax-halfcheetah dr 0 1 reference --set num_updates=2000
run brax-ant dr 0 1 reference --set num_updates=2000
