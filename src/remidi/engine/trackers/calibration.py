"""Calibrating a learned tracker's thresholds: the score of a prefix below which a frozen model
calls it distinguishable, per prefix-length bucket, from held-out prefixes of the model's own
adversary (``remidi.belief_false_rate``: the share of them it may call distinguishable).

Used at an adversary's freeze by the belief tracker (:mod:`remidi.engine.trackers.belief`) and
the simulated tracker (:mod:`remidi.engine.trackers.simulated`). Shapes: R recorded rollouts,
T steps, N envs, L length buckets.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from remidi.engine.trackers.belief_model import episode_running


def num_length_buckets(max_length: int) -> int:
    """How many prefix-length buckets prefixes of at most ``max_length`` steps fill: lengths
    1, 2–3, 4–7, 8–15, ... (powers of two)."""
    return max(1, int(max_length).bit_length())


def length_bucket(length, num_buckets: int) -> jax.Array:
    """i32[...]: the bucket of each prefix length ≥ 1 (⌊log₂ length⌋, the last bucket for longer ones)."""
    lg = jnp.floor(jnp.log2(jnp.maximum(length, 1).astype(jnp.float32))).astype(jnp.int32)
    return jnp.minimum(lg, num_buckets - 1)


def calibrate(scores, false_rate: float, valid=None, slack: float = 1e-3) -> jax.Array:
    """f32[]: the threshold τ at which at most a fraction ``false_rate`` of the held-out prefix
    ``scores`` (f32[...], of trajectories of the model's own adversary; ``valid`` bool[...] picks
    them) lie strictly below: the (⌊false_rate·n⌋ + 1)-th smallest score, lowered by ``slack`` nats
    (scores recomputed step by step differ from the batch's by rounding). A prefix is then
    *explained* when its score is ≥ τ. With no valid score τ = +inf: the model explains nothing."""
    scores = jnp.ravel(scores)
    valid = jnp.ones(scores.shape, bool) if valid is None else jnp.ravel(valid)
    n = jnp.sum(valid)
    ordered = jnp.sort(jnp.where(valid, scores, jnp.inf))
    k = jnp.floor(false_rate * n).astype(jnp.int32)
    tau = ordered[jnp.minimum(k, scores.shape[0] - 1)] - slack
    return jnp.where(n > 0, tau, jnp.inf)


def calibrate_by_length(scores, lengths, false_rate: float, num_buckets: int, valid=None,
                        slack: float = 1e-3) -> jax.Array:
    """f32[L]: :func:`calibrate` separately for the prefixes of each length bucket
    (:func:`length_bucket` of ``lengths`` i32[...], as ``scores``). A prefix's score is a mean
    over its steps, so short prefixes (the first observation alone) spread far wider than long
    ones, and one threshold over all lengths would be set by the short ones and let long prefixes
    of other adversaries through. A bucket with too few held-out prefixes for its quantile (fewer
    than ⌈1/false_rate⌉, one for a rate of 0) takes the threshold of the bucket below it (the
    first bucket: the threshold of all lengths together)."""
    scores, lengths = jnp.ravel(scores), jnp.ravel(lengths)
    valid = jnp.ones(scores.shape, bool) if valid is None else jnp.ravel(valid)
    pooled = calibrate(scores, false_rate, valid, slack)
    bucket = length_bucket(lengths, num_buckets)
    needed = math.ceil(1.0 / false_rate) if false_rate > 0 else 1

    def one(b):
        mine = valid & (bucket == b)
        return calibrate(scores, false_rate, mine, slack), jnp.sum(mine) >= needed

    taus, enough = jax.vmap(one)(jnp.arange(num_buckets))

    def inherit(previous, x):
        tau, ok = x
        tau = jnp.where(ok, tau, previous)
        return tau, tau

    return jax.lax.scan(inherit, pooled, (taus, enough))[1]


def episode_minimum(z, lengths) -> jax.Array:
    """f32[T, N]: the running minimum of ``z`` f32[T, N] over each episode's prefix so far
    (``lengths`` i32[T, N], :func:`prefix_lengths`: 1 starts an episode)."""
    return episode_running(jnp.minimum, z, lengths == 1)


def calibrate_monotone(scores, lengths, false_rate: float, num_buckets: int, valid=None,
                       margin: float = 1e-3) -> jax.Array:
    """f32[L]: thresholds per prefix-length bucket for the *monotone* judgement the tracker makes
    (a prefix is explained when it and every shorter prefix of its episode reach their
    thresholds: a prefix an adversary cannot produce has no extension it can produce). Per bucket
    :func:`calibrate_by_length`; then all are lowered together until at most ``false_rate`` of
    the held-out prefixes have a shorter prefix below its threshold (the ``false_rate`` quantile
    of ``min over the episode so far of (score − τ)``), and by ``margin`` nats per step.
    ``scores``, ``lengths``, ``valid``: [R, T, N] (rows of T steps of N envs, time-major)."""
    tau = calibrate_by_length(scores, lengths, false_rate, num_buckets, valid)
    z = scores - tau[length_bucket(lengths, num_buckets)]
    low = jax.vmap(episode_minimum)(z, lengths)  # [R, T, N]
    shift = calibrate(low, false_rate, valid, slack=0.0)
    shift = jnp.where(jnp.isfinite(shift), jnp.minimum(shift, 0.0), 0.0)
    return tau + shift - margin
