"""The policy's action distribution, one per kind of action space, behind one interface.

A network's policy output ``out`` (``f32[..., P]``) parameterises it:

- :class:`Categorical` (``Discrete(A)``): ``P = A`` logits; actions ``i32[...]`` in ``[0, A)``.
- :class:`MultiCategorical` (``MultiDiscrete(nvec)``): ``P = Σ nvec`` logits, the components' in
  order; actions ``i32[..., k]``, one independent choice per component.
- :class:`DiagGaussian` (``Box(A)``): ``P = 2A`` entries, the mean then the log standard deviation;
  actions ``f32[..., A]`` (unbounded: the environment clips).

The rollout and PPO call the same functions whatever the action space (:func:`for_task`, chosen
once at set-up), so there is one code path. The distributions live beside the policy heads
(:mod:`remidi.engine.core.networks.base`); ``network_actions`` is the ``num_actions`` a network is
made with. :class:`Greedy` acts with the most likely action (``remidi evaluate --action mode``).
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp

from remidi.engine.core.networks.base import (CATEGORICAL, GAUSSIAN, Categorical, DiagGaussian,  # noqa: F401
                                              MultiCategorical)
from remidi.envs.actions import SUPPORTED, Box, Discrete, MultiDiscrete
from remidi.errors import ConfigError, one_of


def for_space(space):
    """The distribution of a policy over ``space`` (:mod:`remidi.envs.actions`)."""
    if isinstance(space, Discrete):
        return Categorical(space.n)
    if isinstance(space, Box):
        return DiagGaussian(space.dims)
    if isinstance(space, MultiDiscrete):
        return MultiCategorical(space.nvec)
    raise ConfigError(f"task.action_space: a {type(space).__name__} has no policy distribution; allowed: "
                      f"{', '.join(SUPPORTED)}")


def for_task(task):
    """The distribution of ``task``'s policy, from ``task.actions`` (without it: ``num_actions`` and
    ``continuous``). A bool (``continuous``) gives the size-free :data:`GAUSSIAN` or :data:`CATEGORICAL`."""
    if isinstance(task, bool):
        return GAUSSIAN if task else CATEGORICAL
    space = getattr(task, "actions", None)
    if space is None:  # an object with the shorthand's fields only (num_actions, continuous)
        space = Box(task.num_actions) if task.continuous else Discrete(task.num_actions)
    return for_space(space)


@dataclass(frozen=True)
class Greedy:
    """``base``'s most likely action every time (its ``mode``), scored as ``base`` scores it."""

    base: object

    @property
    def continuous(self) -> bool:
        return self.base.continuous

    def sample(self, key: jax.Array, out: jax.Array) -> jax.Array:
        del key  # nothing is drawn
        return self.base.mode(out)

    def log_prob(self, out: jax.Array, action: jax.Array) -> jax.Array:
        return self.base.log_prob(out, action)

    def entropy(self, out: jax.Array) -> jax.Array:
        return self.base.entropy(out)

    def mode(self, out: jax.Array) -> jax.Array:
        return self.base.mode(out)

    def probs(self, out: jax.Array) -> jax.Array:
        """f32[..., A]: one-hot on the arg-max (a categorical base)."""
        return jax.nn.one_hot(self.base.mode(out), out.shape[-1], dtype=out.dtype)


#: how an evaluation chooses the agent's actions: drawn from the policy, or its most likely one
ACTIONS = ("sample", "mode")


def acting(dist, action: str):
    """The distribution an evaluation acts with: ``dist`` itself (``"sample"``) or
    :class:`Greedy` over it (``"mode"``). ConfigError naming ``--action`` otherwise."""
    if action not in ACTIONS:
        raise one_of("--action", action, ACTIONS)
    return Greedy(dist) if action == "mode" else dist
