"""One benchmark in this process: ``python -m remidi.bench NAME REPEATS`` (what
:func:`remidi.bench.runner.run_benchmarks` starts for each)."""

import json
import os
import sys

from remidi.bench import BENCHMARKS  # noqa: F401  (every benchmark registered)
from remidi.bench.registry import CORE_ENV
from remidi.bench.runner import run_one

if os.environ.get(CORE_ENV):
    os.sched_setaffinity(0, {int(os.environ[CORE_ENV])})
print(json.dumps(run_one(sys.argv[1], int(sys.argv[2]))))
