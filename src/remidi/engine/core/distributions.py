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
whichever the task's action space (:func:`for_task`, chosen once at set-up), so there is one code
path. ``network_actions`` is what :func:`remidi.engine.core.networks.make_network` takes as
``num_actions`` for it (the discrete head's logits, or the Gaussian's dimensions).
An evaluation that acts with the policy's most likely action (``remidi evaluate --action mode``:
the Gaussian's mean, the categorical's arg-max, each component's arg-max) plays the same rollout
with :class:`Greedy`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp

from remidi.envs.actions import SUPPORTED, Box, Discrete, MultiDiscrete
from remidi.errors import ConfigError, one_of

_LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True)
class Categorical:
    """Softmax over ``out`` (logits ``f32[..., A]``). ``n``: ``A``, the network's logits (None: a
    distribution that only samples and scores, reading ``A`` from ``out``)."""

    n: int | None = None
    continuous = False

    @property
    def network_actions(self) -> int:
        return self.n

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
    """Independent Gaussians per action dimension: ``out = [mean f32[..., A], log_std f32[..., A]]``.
    ``dims``: ``A`` (None: read from ``out``)."""

    dims: int | None = None
    continuous = True

    @property
    def network_actions(self) -> int:
        return self.dims

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


@dataclass(frozen=True)
class MultiCategorical:
    """Independent categoricals, one per component: component ``i`` has ``nvec[i]`` choices and
    its logits are the next ``nvec[i]`` entries of ``out`` (``f32[..., Σ nvec]``); an action is
    ``i32[..., k]``. Its log-probability and entropy are the components' sums."""

    nvec: tuple[int, ...]
    continuous = False

    @property
    def network_actions(self) -> int:
        return sum(self.nvec)

    def split(self, out: jax.Array) -> list[jax.Array]:
        """The components' logits, ``f32[..., nvec[i]]`` each."""
        starts = [sum(self.nvec[:i]) for i in range(len(self.nvec))]
        return [out[..., s:s + n] for s, n in zip(starts, self.nvec)]

    def sample(self, key: jax.Array, out: jax.Array) -> jax.Array:
        """i32[..., k]: each component drawn with its own key."""
        keys = jax.random.split(key, len(self.nvec))
        return jnp.stack([jax.random.categorical(k, logits) for k, logits in zip(keys, self.split(out))], axis=-1)

    def log_prob(self, out: jax.Array, action: jax.Array) -> jax.Array:
        """f32[...]: Σ_i log π_i(action[..., i])."""
        return sum(Categorical.log_prob(logits, action[..., i]) for i, logits in enumerate(self.split(out)))

    def entropy(self, out: jax.Array) -> jax.Array:
        """f32[...]: Σ_i H(π_i)."""
        return sum(Categorical.entropy(logits) for logits in self.split(out))

    def mode(self, out: jax.Array) -> jax.Array:
        """i32[..., k]: each component's most likely choice."""
        return jnp.stack([jnp.argmax(logits, axis=-1) for logits in self.split(out)], axis=-1)


#: size-free distributions: they sample and score any number of actions (the rollout's and PPO's
#: defaults); :func:`for_task` gives the sized one a network is built for
CATEGORICAL = Categorical()
GAUSSIAN = DiagGaussian()


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
