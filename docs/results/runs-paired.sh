#!/usr/bin/env bash
# The runs behind docs/results.md's PAIRED section (issue #29), at the commit that has PAIRED,
# as docs/results/runs.sh does for issue #28's runs (same use: rerun to continue).
#
#   bash docs/results/runs-paired.sh [RUNS_DIR]
set -u
COMMIT=${COMMIT:?set COMMIT to the commit that added the claims}
HERE=$(cd "$(dirname "$0")/../.." && pwd)
R=${1:-/work/runs}
FROZEN=${FROZEN:-$(dirname "$R")/frozen-$COMMIT}
PY=${PYTHON:-python}
if [ ! -d "$FROZEN" ]; then git -C "$HERE" worktree add --detach "$FROZEN" "$COMMIT" || exit 1; fi
export PYTHONPATH="$FROZEN/src"
run() {  # run ALGO ESTIMATOR
  local out=$R/lever/$1-$2-s0
  if [ -f "$out/evaluate.json" ]; then echo "done: $out"; return; fi
  if [ -f "$out/summary.json" ]; then :
  elif [ -f "$out/config.json" ]; then
    $PY -m remidi run --resume "$out" --quiet >> "$out.log" 2>&1
  else
    mkdir -p "$R/lever"
    $PY -m remidi run lever --algo "$1" --preset paper --seeds 10 --set "paired.estimator=$2" --out "$out" --quiet \
      > "$out.log" 2>&1
  fi
  echo "$(date +%T) exit $? $out"
  [ -f "$out/summary.json" ] && [ ! -f "$out/evaluate.json" ] && $PY -m remidi evaluate "$out" --attempts 30 >> "$out.log" 2>&1
}
run paired perfect
run remidi-paired perfect
run paired paired
