"""The policy's action distribution, discrete or continuous, behind one small interface.

A network's policy output ``out`` (``f32[..., P]``) parameterises the distribution:

- :data:`CATEGORICAL`: ``out`` holds ``P = A`` logits; actions are ``i32[...]`` in ``[0, A)``.
- :data:`GAUSSIAN`: ``out`` holds ``P = 2A`` entries, the mean then the log standard deviation
  of a diagonal Gaussian; actions are ``f32[..., A]`` (unbounded: the environment clips).

The rollout samples, PPO scores log-probabilities and entropies through the same three
functions whichever the task's action space (:func:`for_task`), so there is one code path.
An evaluation that acts with the policy's most likely action (``remidi evaluate --action mode``:
the Gaussian's mean, the categorical's arg-max) plays the same rollout with :class:`Greedy`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp

from remidi.errors import one_of

_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class Categorical:
    """Softmax over ``out`` (logits ``f32[..., A]``)."""

    continuous = False

    @staticmethod
    def sample(key: jax.Array, out: jax.Array) -> jax.Array:
        """i32[...]: one action per batch entry."""
        return jax.random.categorical(key, out)

    @staticmethod
    def log_prob(out: jax.Array, action: jax.Array) -> jax.Array:
        """f32[...]: log π(action)."""
        log_pi = jax.nn.log_softmax(out)
        return jnp.take_along_axis(log_pi, action[..., None].astype(jnp.int32), axis=-1)[..., 0]

    @staticmethod
    def entropy(out: jax.Array) -> jax.Array:
        """f32[...]: −Σ π log π."""
        log_pi = jax.nn.log_softmax(out)
        return -jnp.sum(jnp.exp(log_pi) * log_pi, axis=-1)

    @staticmethod
    def mode(out: jax.Array) -> jax.Array:
        return jnp.argmax(out, axis=-1)

    @staticmethod
    def probs(out: jax.Array) -> jax.Array:
        """f32[..., A]: the probability of each action."""
        return jax.nn.softmax(out, axis=-1)


@dataclass(frozen=True)
class DiagGaussian:
    """Independent Gaussians per action dimension: ``out = [mean f32[..., A], log_std f32[..., A]]``."""

    continuous = True

    @staticmethod
    def split(out: jax.Array) -> tuple[jax.Array, jax.Array]:
        """``(mean, log_std)``, each ``f32[..., A]``."""
        a = out.shape[-1] // 2
        return out[..., :a], out[..., a:]

    @staticmethod
    def sample(key: jax.Array, out: jax.Array) -> jax.Array:
        """f32[..., A]: ``mean + std · ε``."""
        mean, log_std = DiagGaussian.split(out)
        return mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape, mean.dtype)

    @staticmethod
    def log_prob(out: jax.Array, action: jax.Array) -> jax.Array:
        """f32[...]: Σ_d log N(action_d; mean_d, std_d²)."""
        mean, log_std = DiagGaussian.split(out)
        z = (action - mean) * jnp.exp(-log_std)
        return jnp.sum(-0.5 * jnp.square(z) - log_std - 0.5 * _LOG_2PI, axis=-1)

    @staticmethod
    def entropy(out: jax.Array) -> jax.Array:
        """f32[...]: Σ_d (log std_d + ½ log(2πe))."""
        _, log_std = DiagGaussian.split(out)
        return jnp.sum(log_std + 0.5 * (_LOG_2PI + 1.0), axis=-1)

    @staticmethod
    def mode(out: jax.Array) -> jax.Array:
        return DiagGaussian.split(out)[0]


CATEGORICAL = Categorical()
GAUSSIAN = DiagGaussian()


def for_task(continuous: bool):
    """The distribution of a task's policy: :data:`GAUSSIAN` if its actions are continuous."""
    return GAUSSIAN if continuous else CATEGORICAL


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
