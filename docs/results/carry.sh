#!/usr/bin/env bash
# Unfinished runs carried from one machine to the next through the repository. A machine of this
# project keeps nothing outside the checkout when its session ends, so before a session stops each
# unfinished run's folder is packed into docs/results/inflight/EXPERIMENT/NAME.txz and committed;
# runs.sh unpacks it into a RUNS_DIR that lacks the run and resumes the run from that checkpoint.
#
#   bash docs/results/carry.sh RUNS_DIR EXPERIMENT/NAME ...
#
# A run may be training while it is packed: checkpoint.npz is copied before the rest of the
# folder (the run writes checkpoint.history.npz first, so the copied history holds every block
# the copied checkpoint counts), and the copy is checked to load before it replaces the archive.
# `python -m tools.results.page --collect` deletes a run's archive when it collects the finished run.
set -eu
HERE=$(cd "$(dirname "$0")/../.." && pwd)
R=${1:?RUNS_DIR}; shift
PY=${PYTHON:-python}
for run in "$@"; do
  src=$R/$run; [ -f "$src/checkpoint.npz" ] || { echo "carry: $src has no checkpoint.npz" >&2; exit 1; }
  tmp=$(mktemp -d); mkdir -p "$tmp/$run"
  cp "$src/checkpoint.npz" "$tmp/$run/"  # first: see above
  for f in "$src"/*; do [ "$(basename "$f")" = checkpoint.npz ] || cp -r "$f" "$tmp/$run/"; done
  [ -f "$src.log" ] && cp "$src.log" "$tmp/$run.log"
  "$PY" - "$tmp/$run" <<'EOF'
import sys
from pathlib import Path
from remidi.engine.run.checkpoint import CHECKPOINT, HISTORY, load_history, read_meta
folder = Path(sys.argv[1])
meta = read_meta(folder / CHECKPOINT)
load_history(folder / HISTORY, meta)  # ConfigError when the pair disagrees
print(f"carry: {folder} at update {meta['done']}", file=sys.stderr)
EOF
  out=$HERE/docs/results/inflight/$run.txz; mkdir -p "$(dirname "$out")"
  (cd "$tmp" && ls -d "$run" "$run.log" 2>/dev/null | xargs tar -cf - | xz -T0 -6 > "$out.new") && mv "$out.new" "$out"
  rm -rf "$tmp"; echo "carry: $out ($(du -h "$out" | cut -f1))" >&2
done
