"""The engine's results on the lever game's tiny config, for every algorithm: what
``tests/test_engine_reference.py`` compares the engine against.

``python tests/engine_reference.py`` rewrites ``tests/data/engine_reference.json``. Do that only
for a change that is *meant* to change training results, and say so in its commit; a refactor
must leave the file as it is. The engine that wrote today's values is the one of commit 8bb28df,
before the algorithm seam of issue #19, for dr, plr, minimax-return, remidi and remidi-combine
(and of the commit that added ACCEL for accel and remidi-accel): the file was written again,
unoptimised, when the suite stopped optimising (the engine unchanged, the test passing against
the optimised values before). The suite's XLA flags (``tests/conftest.py``: older fusion emitters)
came later and were not used to write it; the test passes within its float32 tolerance with them.
"""

import dataclasses
import json
import sys
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from test_ued_engine import TASK, TINY  # noqa: E402

from remidi.engine import driver  # noqa: E402

PATH = Path(__file__).parent / "data" / "engine_reference.json"
SEEDS = [0, 1]
#: name: (algorithm, config)
CASES = {
    "dr": ("dr", TINY),
    "plr": ("plr", TINY),
    "minimax-return": ("minimax-return", TINY),
    "remidi": ("remidi", TINY),
    "remidi-combine": ("remidi", dataclasses.replace(TINY, remidi=dataclasses.replace(TINY.remidi, policy="combine"))),
    "accel": ("accel", TINY),
    "remidi-accel": ("remidi-accel", TINY),
}


def fingerprint(algo: str, cfg) -> dict:
    """Every logged metric [S, T], and per runner leaf its sum and sum of squares (float64),
    compiled without XLA's optimisations (as most of the suite: ``tests/conftest.py``)."""
    if not jax.config.read("jax_disable_most_optimizations"):  # run as a script (the suite sets it)
        jax.clear_caches()
        jax.config.update("jax_disable_most_optimizations", True)
    result = driver.train_seeds(TASK, cfg, algo, SEEDS, progress=False)
    steps, history, per_step, runner = result.steps, result.history, result.per_step, result.runner
    leaves = {jax.tree_util.keystr(path): np.asarray(leaf, dtype=np.float64)
              for path, leaf in jax.tree_util.tree_leaves_with_path(runner)}
    return {
        "steps": [int(s) for s in steps],
        "history": {k: np.asarray(v, dtype=np.float64).tolist() for k, v in sorted(history.items())},
        "per_step": {k: np.asarray(v, dtype=np.float64).tolist() for k, v in sorted(per_step.items())},
        "runner": {k: [float(np.nansum(np.where(np.isfinite(v), v, 0))), float(np.nansum(np.where(np.isfinite(v), v, 0) ** 2))]
                   for k, v in sorted(leaves.items())},
    }


if __name__ == "__main__":  # python tests/engine_reference.py [CASE ...]: (re)write those cases only
    doc = json.loads(PATH.read_text()) if PATH.exists() else {}
    doc.update({name: fingerprint(*CASES[name]) for name in (sys.argv[1:] or CASES)})
    PATH.parent.mkdir(exist_ok=True)
    PATH.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {PATH}")
