"""A network of your own, registered without editing the library: ``ln_mlp``.

    python examples/my_network.py OUT_DIR [--updates 20]

``ln_mlp`` is an MLP whose hidden layers each normalise their pre-activations (LayerNorm, Ba et
al. 2016), a common remedy for the plasticity loss of long PPO runs, with the engine's policy and
value heads (``ActorCriticHeads``). It follows the interface every network has (the docstring of
``remidi.engine.core.networks``): a flax module whose ``__call__(carry, obs, reset)`` reads a
whole rollout (leaves ``[T, N, ...]``) and returns ``(carry, (logits, value))``, an
``initialize_carry(n)``, the fields ``num_actions`` and ``continuous``; its other fields, all with
defaults, are its options (``hidden`` is what ``--set hidden_size=W`` sets). It states what it
reads: ``reads`` (one line, shown by ``remidi list lever``) and ``check_observation``, which
refuses anything but one vector, so that ``--set network=ln_mlp`` on a maze (an image and a
direction) stops before training with one line naming what it reads.

This script registers it, then runs ``remidi run lever --algo plr --set network=ln_mlp`` with tiny
settings (seconds, most of it compiling). The command line in a shell of its own finds the
network when it imports this module first (``REMIDI_PLUGINS``, or an entry point of the group
``remidi.plugins``: docs/extending.md), also to resume such a run:

    REMIDI_PLUGINS=my_network PYTHONPATH=examples remidi run lever --set network=ln_mlp
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import flax.linen as nn
import jax.numpy as jnp
import numpy as np

import remidi
from remidi.engine.core.networks import ActorCriticHeads


class LayerNormMLP(nn.Module):
    """Flat observation -> ``hidden`` layers of Dense -> LayerNorm -> tanh -> policy and value
    heads (``head_hidden`` units). Feed-forward: the carry is a dummy ``f32[N]``."""

    reads = "one vector f32[D] (the observation is a single array)"

    num_actions: int
    hidden: tuple[int, ...] = (64, 64)
    head_hidden: int = 32
    continuous: bool = False

    @nn.nowrap
    def initialize_carry(self, batch_size: int):
        return jnp.zeros((batch_size,), jnp.float32)

    @nn.nowrap
    def check_observation(self, obs) -> str | None:
        """Why ``obs`` (one observation, unbatched) is not one vector; None if it is."""
        if not hasattr(obs, "shape") or len(obs.shape) != 1:
            return "not one vector"
        return None

    @nn.compact
    def __call__(self, carry, obs, reset):
        x = obs.astype(jnp.float32)  # [T, N, D]
        for i, width in enumerate(self.hidden):
            x = nn.Dense(width, kernel_init=nn.initializers.orthogonal(np.sqrt(2.0)), name=f"dense_{i}")(x)
            x = jnp.tanh(nn.LayerNorm(name=f"norm_{i}")(x))
        return carry, ActorCriticHeads(self.num_actions, self.head_hidden, "tanh", self.continuous, name="heads")(x)


# at import: the command line imports the module named by REMIDI_PLUGINS before it reads its arguments
remidi.register_network("ln_mlp", LayerNormMLP,
                        description="an MLP with LayerNorm before each tanh (examples/my_network.py)")

TINY = {"num_envs": 8, "num_steps": 4, "eval_every": 10, "checkpoint_every": 10, "eval_attempts": 2,
        "ppo.epochs": 1, "buffer.capacity": 16, "buffer.topk_k": 8, "buffer.min_fill": 0.25, "hidden_size": 32}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, help="output folder (must not hold a run)")
    parser.add_argument("--updates", type=int, default=20, help="train steps (default 20)")
    args = parser.parse_args(argv)

    from remidi.cli import main as remidi_main

    sets = [f"{key}={value}" for key, value in {"num_updates": args.updates, **TINY, "network": "ln_mlp"}.items()]
    code = remidi_main(["run", "lever", "--algo", "plr", "--seeds", "1", "--quiet", "--out", str(args.out),
                        *(item for key in sets for item in ("--set", key))])
    if code != 0:
        return code
    config = json.loads((args.out / "config.json").read_text())["config"]
    print(f"trained plr on the lever game with network={config['network']}: {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
