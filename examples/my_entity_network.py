"""A network of your own for entity observations, registered without editing the library: ``set_max``.

    REMIDI_PLUGINS=my_entity_network PYTHONPATH=examples remidi run kinetix-s --set network=set_max \\
        --set kinetix.observation=entity --set kinetix.actions=multi_discrete

``set_max`` is a deep set (Zaheer et al. 2017) with max pooling per entity type: each group of an
entity observation (remidi's convention, docs/extending.md, *Entity observations*, which Kinetix's
``kinetix.observation=entity`` follows) has its own two-layer MLP over its rows; a padded row
(mask False) is dropped by the max, so neither its features nor the order of the rows reach the
output; the per-group maxima and the ``globals`` vector, concatenated, feed the engine's policy
and value heads (``ActorCriticHeads``). It differs from the library's ``entity`` network (attention,
one mean over all entities) on purpose: it is what a user writes in a page, not a copy.

The interface every network has is the docstring of ``remidi.engine.core.networks``:
``__call__(carry, obs, reset)`` over a whole rollout (leaves ``[T, N, ...]``), returning
``(carry, (logits, value))``; ``num_actions`` is the number of policy logits, which for Kinetix's
multi-discrete actions is the sum of the choices (3 + 3 + 3 + 3 + 2 + 2 = 16), so the network
needs nothing to know about the action space. ``reads`` and ``check_observation`` say what it
reads, so that ``--set network=set_max`` on a task whose observation is one vector stops before
training, in one line.
"""

from __future__ import annotations

from collections.abc import Mapping

import flax.linen as nn
import jax.numpy as jnp
import numpy as np

import remidi
from remidi.engine.core.networks import ActorCriticHeads


class SetMaxActorCritic(nn.Module):
    """Per group: rows -> Dense(width) -> relu -> Dense(width) -> max over valid rows (zeros if none);
    groups (sorted by name) and globals concatenated -> heads. Feed-forward: the carry is a dummy
    ``f32[N]``."""

    reads = "entities {group: {features f32[n, F], mask bool[n]}}, optionally globals f32[G]"

    num_actions: int
    width: int = 64
    head_hidden: int = 64
    continuous: bool = False

    @nn.nowrap
    def initialize_carry(self, batch_size: int):
        return jnp.zeros((batch_size,), jnp.float32)

    @nn.nowrap
    def check_observation(self, obs) -> str | None:
        """Why ``obs`` (one observation, unbatched) is not an entity observation; None if it is."""
        if not isinstance(obs, Mapping) or not isinstance(obs.get("entities"), Mapping):
            return "not a dict with entities (a dict of groups)"
        for name, group in obs["entities"].items():
            if not (isinstance(group, Mapping) and {"features", "mask"} <= set(group)):
                return f"its group {name} has no features and mask"
            if len(group["features"].shape) != 2:
                return f"its group {name}'s features are not [n, F]"
        return None

    @nn.compact
    def __call__(self, carry, obs, reset):
        init = nn.initializers.orthogonal(np.sqrt(2.0))
        pooled = []
        for name in sorted(obs["entities"]):
            mask = obs["entities"][name]["mask"]  # [T, N, n]
            rows = jnp.where(mask[..., None], obs["entities"][name]["features"].astype(jnp.float32), 0.0)  # [T, N, n, F]
            x = nn.relu(nn.Dense(self.width, kernel_init=init, name=f"{name}_0")(rows))  # [T, N, n, width]
            x = nn.Dense(self.width, kernel_init=init, name=f"{name}_1")(x)
            top = jnp.max(jnp.where(mask[..., None], x, -jnp.inf), axis=-2)  # [T, N, width]
            pooled.append(jnp.where(jnp.isfinite(top), top, 0.0))  # a group with no valid row: zeros
        if "globals" in obs:
            pooled.append(obs["globals"].astype(jnp.float32))
        features = jnp.concatenate(pooled, axis=-1)
        return carry, ActorCriticHeads(self.num_actions, self.head_hidden, "tanh", self.continuous,
                                       name="heads")(features)


# at import: the command line imports the module named by REMIDI_PLUGINS before it reads its arguments
remidi.register_network("set_max", SetMaxActorCritic,
                        description="a deep set, max over each entity type (examples/my_entity_network.py)")
