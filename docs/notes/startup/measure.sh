#!/bin/bash
# measure.sh SRC OUT PY TASKDIR -- RUNARGS...   : fresh run (SIGTERM after its first checkpoint), resume, evaluate, evaluate again
# env: EVALARGS, WARMRUN=1 (a second fresh run of the whole config, for the bit-identical check)
SRC=$1; OUT=$2; PY=$3; TASKDIR=$4; shift 5
export PYTHONPATH=$SRC${TASKDIR:+:$TASKDIR}
cd ${TASKDIR:-/tmp}
rm -rf $OUT; mkdir -p $OUT
P="$PY /tmp/startup-prof/prof.py"
echo "== fresh (SIGTERM after first checkpoint) $(date -u +%T)" >> $OUT/log
$P run "$@" --out $OUT/run --quiet > $OUT/fresh.log 2>&1 &
pid=$!
while kill -0 $pid 2>/dev/null && [ ! -f $OUT/run/checkpoint.npz ]; do sleep 2; done
kill -TERM $pid 2>/dev/null; wait $pid; echo "rc $?" >> $OUT/log
[ -n "$FRESHONLY" ] && exit 0
echo "== resume $(date -u +%T)" >> $OUT/log
$P run --resume $OUT/run --quiet > $OUT/resume.log 2>&1; echo "rc $?" >> $OUT/log
echo "== evaluate $(date -u +%T)" >> $OUT/log
$P evaluate $OUT/run $EVALARGS > $OUT/evaluate.log 2>&1; echo "rc $?" >> $OUT/log
cp $OUT/run/evaluate.json $OUT/evaluate1.json 2>/dev/null
echo "== evaluate again $(date -u +%T)" >> $OUT/log
$P evaluate $OUT/run $EVALARGS > $OUT/evaluate2.log 2>&1; echo "rc $?" >> $OUT/log
if [ -n "$WARMRUN" ]; then
  echo "== fresh again, whole $(date -u +%T)" >> $OUT/log
  $P run "$@" --out $OUT/run2 --quiet > $OUT/fresh2.log 2>&1; echo "rc $?" >> $OUT/log
fi
echo "== done $(date -u +%T)" >> $OUT/log
