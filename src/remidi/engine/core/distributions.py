"""The policy's action distribution, one per kind of action space, behind one small interface.

A network's policy output ``out`` (``f32[..., P]``) parameterises the distribution:

- :class:`Categorical` (``Discrete(A)``): ``out`` holds ``P = A`` logits; actions are ``i32[...]``
  in ``[0, A)``.
- :class:`MultiCategorical` (``MultiDiscrete(nvec)``): ``out`` holds ``P = Σ nvec`` logits, the
  components' in order; actions are ``i32[..., k]``, one independent choice per component.
- :class:`DiagGaussian` (``Box(A)``): ``out`` holds ``P = 2A`` entries, the mean then the log
  standard deviation of a diagonal Gaussian; actions are ``f32[..., A]`` (unbounded: the
  environment clips).

The rollout samples, PPO scores log-probabilities and entropies through the same functions
whichever the task's action space (:func:`for_task`, chosen once at set-up: ``Setup.dist``), so
there is one code path. The three distributions live beside the networks' policy heads
(:mod:`remidi.engine.core.networks.base`), whose output they read; this module chooses one.
``network_actions`` is what :func:`remidi.engine.core.networks.make_network` takes as
``num_actions`` for it (the discrete head's logits, or the Gaussian's dimensions).
An evaluation that acts with the policy's most likely action (``remidi evaluate --action mode``:
the Gaussian's mean, the categorical's arg-max, each component's arg-max) plays the same rollout
with :class:`Greedy`.
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
    """The distribution of ``task``'s policy, from its action space (``task.actions``; for an
    object without one, ``num_actions`` and ``continuous``, the shorthand). A bool
    (``continuous``, the earlier form) gives the size-free :data:`GAUSSIAN` or :data:`CATEGORICAL`."""
    if isinstance(task, bool):
        return GAUSSIAN if task else CATEGORICAL
    space = getattr(task, "actions", None)
    if space is None:  # an object with the shorthand's fields only (num_actions, continuous)
        space = Box(task.num_actions) if task.continuous else Discrete(task.num_actions)
    return for_space(space)


@dataclass(frozen=True)
class Greedy:
    """``base``'s most likely action every time (its ``mode``), scored as ``base`` scores it: the
    deterministic policy an evaluation reports beside the sampled one."""

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
