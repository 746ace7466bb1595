"""A level score of your own, registered without editing the library: ``abs_gae``.

    python examples/my_score.py OUT_DIR [--updates 20]

``abs_gae`` is the *L1 value loss* of Jiang et al. (2021), "Prioritized Level Replay" (their
"GAE magnitude"): per finished episode the mean over its steps of |GAE advantage|, then the
mean over the level's finished episodes. Unlike ``pvl`` (positive value loss) it counts the
critic's over-estimates as well as its under-estimates.

``remidi.register_score`` adds it to the scores ``score=`` accepts: every algorithm of the PLR
family (``plr``, ``remidi``, ``accel``, ...) then ranks the levels of its buffer by it, and the
run is validated like any other (a score that ``needs_optimum`` is refused on a task without an
optimal return, one that ``needs_finished_episodes`` is warned about on rollouts shorter than an
episode). The function is traced inside the compiled train step: write it with ``jax.numpy``.

This script registers the score, then runs ``remidi run lever --algo plr --set score=abs_gae``
with tiny settings (seconds, most of it compiling). The command line in a shell of its own finds
the score when it imports this module first (``REMIDI_PLUGINS``, or an entry point of the group
``remidi.plugins``: docs/extending.md):

    REMIDI_PLUGINS=my_score PYTHONPATH=examples remidi run lever --algo plr --set score=abs_gae
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import jax.numpy as jnp

import remidi
from remidi.engine.adversaries.scores import ScoreInputs, episode_mean


def abs_gae(x: ScoreInputs):
    """f32[N]: the mean over finished episodes of each episode's mean |GAE advantage|
    (``x.advantages`` f32[T, N]); −inf for a level with no finished episode, as ``pvl``."""
    return episode_mean(jnp.abs(x.advantages), x.done)


# at import: the command line imports the module named by REMIDI_PLUGINS before it reads its arguments
remidi.register_score("abs_gae", abs_gae, needs_finished_episodes=True,
                      help="L1 value loss: mean |GAE advantage| over finished episodes (PLR, Jiang et al. 2021)")

TINY = {"num_envs": 8, "num_steps": 4, "eval_every": 10, "checkpoint_every": 10, "eval_attempts": 2,
        "ppo.epochs": 1, "buffer.capacity": 16, "buffer.topk_k": 8, "buffer.min_fill": 0.25}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, help="output folder (must not hold a run)")
    parser.add_argument("--updates", type=int, default=20, help="train steps (default 20)")
    args = parser.parse_args(argv)

    from remidi.cli import main as remidi_main

    sets = [f"{key}={value}" for key, value in {"num_updates": args.updates, **TINY, "score": "abs_gae"}.items()]
    code = remidi_main(["run", "lever", "--algo", "plr", "--seeds", "1", "--quiet", "--out", str(args.out),
                        *(item for key in sets for item in ("--set", key))])
    if code != 0:
        return code
    config = json.loads((args.out / "config.json").read_text())["config"]
    print(f"trained plr on the lever game with score={config['score']}: {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
