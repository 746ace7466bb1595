#!/bin/bash
# the Kinetix run end to end (docs/performance.md, Start-up), cache off (as before the change) and on (a cold
# cache, then warm), side by side; measure.sh expects prof.py in /tmp/startup-prof (cp prof.py there first)
PY=/tmp/kinetix-venv/bin/python
ARGS="kinetix-s --algo remidi --preset smoke --seeds 1"
(REMIDI_JAX_CACHE=off bash /work/main/docs/notes/startup/measure.sh /work/main/src /tmp/kx-e2e/off $PY "" -- $ARGS) &
rm -rf /tmp/kx-e2e/cache
(REMIDI_JAX_CACHE=/tmp/kx-e2e/cache bash /work/main/docs/notes/startup/measure.sh /work/main/src /tmp/kx-e2e/on $PY "" -- $ARGS) &
wait
