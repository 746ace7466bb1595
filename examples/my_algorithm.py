"""Algorithms of your own made of existing components, registered without editing the library.

    python examples/my_algorithm.py OUT_DIR [--updates 20]

``remidi.register_algorithm(name, adversary, score=..., description=...)`` names a combination
of the engine's adversaries (``remidi.engine.adversaries.base``: ``RandomLevels``, ``LevelBuffers``,
``EditingBuffers``; ``remidi.engine.adversaries.paired``: ``LevelGenerator``, ``GeneratorSequence``) and
optionally the score it always ranks levels by. Every UED experiment then accepts it: ``remidi
run lever --algo plr-classic``, ``remidi list`` shows it, ``remidi.run_ued`` takes its name.
Two here:

* ``plr-classic``: prioritized level replay as first published (Jiang et al., 2021): PLR⊥'s
  buffer, but the agent learns from its rollouts on fresh levels too, not only from replays
  (``LevelBuffers(trains_on_fresh=True)``);
* ``remidi-maxmc``: ReMiDi's sequence of buffers ranked by MaxMC whatever the config's
  ``score`` (``LevelBuffers(buffer_sequence=True)``, ``score="maxmc"``), a ReMiDi for tasks
  without a known optimal return.

A new *kind* of adversary is a class with the adversary's methods (docs/extending.md); it is
registered the same way. The command line in a shell of its own finds these algorithms when it
imports this module first (``REMIDI_PLUGINS``, or an entry point of the group ``remidi.plugins``):

    REMIDI_PLUGINS=my_algorithm PYTHONPATH=examples remidi run lever --algo plr,plr-classic
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import remidi
from remidi.engine.adversaries.plr import LevelBuffers

# at import: the command line imports the module named by REMIDI_PLUGINS before it reads its arguments
remidi.register_algorithm("plr-classic", LevelBuffers(trains_on_fresh=True),
                          description="PLR as first published: PLR⊥'s buffer, trains on fresh levels too")
remidi.register_algorithm("remidi-maxmc", LevelBuffers(buffer_sequence=True), score="maxmc",
                          description="ReMiDi ranking levels by MaxMC (no optimal return needed)")

TINY = {"num_envs": 8, "num_steps": 4, "eval_every": 10, "checkpoint_every": 10, "eval_attempts": 2,
        "ppo.epochs": 1, "buffer.capacity": 16, "buffer.topk_k": 8, "buffer.min_fill": 0.25,
        "remidi.buffer_capacity": 8, "remidi.steps_per_buffer": 8}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, help="output folder (must not hold a run)")
    parser.add_argument("--updates", type=int, default=20, help="train steps per algorithm (default 20)")
    args = parser.parse_args(argv)

    from remidi.cli import main as remidi_main

    sets = [f"{key}={value}" for key, value in {"num_updates": args.updates, **TINY}.items()]
    return remidi_main(["run", "lever", "--algo", "plr-classic,remidi-maxmc", "--seeds", "1", "--quiet",
                        "--out", str(args.out), *(item for key in sets for item in ("--set", key))])


if __name__ == "__main__":
    sys.exit(main())
