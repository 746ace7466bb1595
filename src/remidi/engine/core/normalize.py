"""Running observation normalisation (as in PureJaxRL's and Brax's continuous-control PPO).

The statistics live in the run state, so checkpoints and ``--resume`` keep them. A rollout
normalises with the statistics as they were when it started (PPO then trains on exactly what the
policy saw); they absorb the rollout's observations afterwards. The tracker compares *raw*
observations. Observations are flattened (every leaf after the batch axes, concatenated to
``f32[..., D]``: :func:`remidi.engine.core.networks.flatten_obs`), so a normalising agent must read
flat vector observations (the MLP networks do).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from remidi.engine.core.networks import flatten_obs

CLIP = 10.0  # normalised observations are clipped to [−CLIP, CLIP]
EPS = 1e-8


@struct.dataclass
class ObsStats:
    """Running mean and variance of D observation entries over ``count`` observations."""

    mean: jax.Array  # f32[D]
    var: jax.Array  # f32[D]
    count: jax.Array  # f32[]


def init_stats(dim: int) -> ObsStats:
    """No observation seen yet: mean 0, variance 1 (the identity normalisation), count 0."""
    return ObsStats(mean=jnp.zeros((dim,), jnp.float32), var=jnp.ones((dim,), jnp.float32),
                    count=jnp.zeros((), jnp.float32))


def update_stats(stats: ObsStats, x: jax.Array) -> ObsStats:
    """Merge a batch ``x`` (``f32[..., D]``) into the statistics (Chan et al.'s parallel update)."""
    x = x.reshape(-1, x.shape[-1]).astype(jnp.float32)
    n = jnp.asarray(x.shape[0], jnp.float32)
    batch_mean = jnp.mean(x, axis=0)
    batch_var = jnp.var(x, axis=0)
    total = stats.count + n
    delta = batch_mean - stats.mean
    mean = stats.mean + delta * n / total
    m2 = stats.var * stats.count + batch_var * n + jnp.square(delta) * stats.count * n / total
    return ObsStats(mean=mean, var=m2 / total, count=total)


def normalize(stats: ObsStats, x: jax.Array) -> jax.Array:
    """``clip((x − mean) / sqrt(var + 1e-8), ±10)`` for ``x`` ``f32[..., D]``."""
    return jnp.clip((x - stats.mean) / jnp.sqrt(stats.var + EPS), -CLIP, CLIP)
