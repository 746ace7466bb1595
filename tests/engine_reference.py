"""The engine's results on the lever game's and the T-maze's tiny configs, for every algorithm:
what ``tests/test_engine_reference.py`` and ``tests/test_engine_reference_maze.py`` compare the
engine against, within a float32 tolerance. A refactor must reproduce them; that is how it proves
it changed no result.

``python tests/engine_reference.py [CASE ...]`` rewrites those cases (all without arguments) in
``tests/data/engine_reference.json``. Do that only for a change that is *meant* to change
training results, and say so in its commit. Write them as the suite computes them: without
XLA's optimisations (the script sets that) and with the suite's XLA flags in ``XLA_FLAGS``
(``tests/conftest.py``'s ``FAST_XLA_FLAGS``: older fusion emitters, LLVM level 1 and, on
x86-64, ``--xla_cpu_max_isa=AVX2``).

``plr``, ``minimax-return``, ``accel`` and ``remidi-accel`` play an 8-lever game
(:data:`LEVER8`), the other lever cases the 64-lever :data:`TASK`. On 64 levers those four drifted
beyond the tolerance between CPUs (values written on an AVX2 machine, read on an AVX-512 one with
the same flags, 2026-11-29) and between ``--xla_cpu_max_isa`` settings on one machine: their
replayed batches are at times one outcome throughout (every pull of a few replayed levels
fails), so the advantages are nearly constant and normalising them by their standard deviation
turns rounding into the update's direction (a floor of 1e-2 under that deviation removed the
drift; so did 8 levers, where a batch of 32 pulls is rarely one outcome). On 8 levers the same
cases agree to the tolerance with ``--xla_cpu_max_isa`` at AVX2, at SSE4_2 and uncapped, as every
other case does on 64 levers, and c32046b's code (the results page's) computes the stored values
on them: every metric it logged and every runner leaf within the tolerance. (The learner keeps the
field's normalisation, ``std + 1e-8``, as JaxUED's and minimax's PPO do.)
"""

import dataclasses
import json
import sys
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from test_ued_engine import TASK, TINY  # noqa: E402

from remidi.engine.run import driver  # noqa: E402
from remidi.envs.lever import lever_task  # noqa: E402
from remidi.envs.maze import maze_task  # noqa: E402
from remidi.experiments.maze import paper_config as maze_paper_config  # noqa: E402

R = dataclasses.replace
PATH = Path(__file__).parent / "data" / "engine_reference.json"
SEEDS = [0, 1]
#: the tmaze experiment's paper config cut to a few updates of a tiny agent: every algorithm's
#: path through the maze (T-maze optimum, 250-step episodes, the LSTM, the tracker on mazes)
MAZE = maze_task("tmaze")
_M = maze_paper_config()
MAZE_TINY = R(_M, num_updates=6, num_envs=4, num_steps=24, eval_every=6, eval_attempts=1, checkpoint_every=6,
              lstm_size=8, ppo=R(_M.ppo, epochs=1),
              buffer=R(_M.buffer, capacity=8, min_fill=0.25),
              remidi=R(_M.remidi, num_buffers=2, buffer_capacity=4, steps_per_buffer=2))
#: SFL's refresh at the lever TINY config's size: 32 candidates × 4 steps, 8 kept, every 10 updates
SFL_TINY = R(TINY, sfl=R(TINY.sfl, batch_size=16, num_batches=2, rollout_steps=4, buffer_size=8, refresh_every=10))
#: the lever game for the cases whose 64-lever batches are at times one outcome (module docstring)
LEVER8 = lever_task(8)
#: name: (task, algorithm, config)
CASES = {
    "dr": (TASK, "dr", TINY),
    "plr": (LEVER8, "plr", TINY),
    "minimax-return": (LEVER8, "minimax-return", TINY),
    "remidi": (TASK, "remidi", TINY),
    "remidi-combine": (TASK, "remidi", R(TINY, remidi=R(TINY.remidi, policy="combine"))),
    "accel": (LEVER8, "accel", TINY),
    "remidi-accel": (LEVER8, "remidi-accel", TINY),
    "sfl": (TASK, "sfl", SFL_TINY),
    "remidi-sfl": (TASK, "remidi-sfl", SFL_TINY),
    **{f"tmaze-{algo}": (MAZE, algo, MAZE_TINY)
       for algo in ("dr", "plr", "minimax-return", "remidi", "accel", "remidi-accel")},
    "tmaze-remidi-combine": (MAZE, "remidi", R(MAZE_TINY, remidi=R(MAZE_TINY.remidi, policy="combine"))),
}


def fingerprint(task, algo: str, cfg) -> dict:
    """Every logged metric [S, T], and per runner leaf its sum and sum of squares (float64),
    compiled without XLA's optimisations (as most of the suite: ``tests/conftest.py``)."""
    if not jax.config.read("jax_disable_most_optimizations"):  # run as a script (the suite sets it)
        jax.clear_caches()
        jax.config.update("jax_disable_most_optimizations", True)
    result = driver.train_seeds(task, cfg, algo, SEEDS, progress=False)
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
