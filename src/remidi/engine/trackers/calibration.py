"""Calibrating a learned tracker's thresholds: per prefix-length bucket, the score below which a
frozen model calls a prefix distinguishable, set on held-out prefixes of its own adversary so
that at most ``remidi.belief_false_rate`` of them fall below, and at most their median minus
``remidi.belief_spread`` robust deviations (:func:`spread_fence`).

Shapes: R recorded rollouts, T steps, N envs, L length buckets."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from remidi.engine.trackers.belief_model import episode_running


def num_length_buckets(max_length: int) -> int:
    """Buckets for prefixes of at most ``max_length`` steps: lengths 1, 2–3, 4–7, ... (powers of two)."""
    return max(1, int(max_length).bit_length())


def length_bucket(length, num_buckets: int) -> jax.Array:
    """i32[...]: ⌊log₂ length⌋ of each prefix length ≥ 1, capped at the last bucket."""
    lg = jnp.floor(jnp.log2(jnp.maximum(length, 1).astype(jnp.float32))).astype(jnp.int32)
    return jnp.minimum(lg, num_buckets - 1)


def calibrate(scores, false_rate: float, valid=None, slack: float = 1e-3) -> jax.Array:
    """f32[]: threshold τ with at most ``false_rate`` of ``scores`` (where ``valid``) strictly below.

    The (⌊false_rate·n⌋ + 1)-th smallest score minus ``slack`` nats (step-by-step scores differ from
    the batch's by rounding). A prefix is explained when its score ≥ τ; no valid score: τ = +inf."""
    scores = jnp.ravel(scores)
    valid = jnp.ones(scores.shape, bool) if valid is None else jnp.ravel(valid)
    n = jnp.sum(valid)
    ordered = jnp.sort(jnp.where(valid, scores, jnp.inf))
    k = jnp.floor(false_rate * n).astype(jnp.int32)
    tau = ordered[jnp.minimum(k, scores.shape[0] - 1)] - slack
    return jnp.where(n > 0, tau, jnp.inf)


def _median(x, valid) -> jax.Array:
    """f32[]: lower median of ``x`` f32[n] where ``valid``; +inf with none."""
    return jnp.sort(jnp.where(valid, x, jnp.inf))[jnp.maximum(jnp.sum(valid) - 1, 0) // 2]


def spread_fence(scores, valid, spread: float) -> jax.Array:
    """f32[]: median of the valid ``scores`` f32[R, ...] minus ``spread`` robust standard deviations.

    The deviation is 1.4826 × the median over rows (model versions) of each row's MAD, so a model's
    drift between versions is not counted as spread. +inf with no valid score. Why: the held-out
    scores come from the adversary's few replayed levels, so their low quantile says little about
    the tail of its *kind* of trajectory, which the next adversary searches; the fence extrapolates
    that tail. A real low-scoring minority keeps the lower quantile; equal scores give the median."""
    rows = scores.shape[0]
    flat, ok = jnp.reshape(scores, (rows, -1)), jnp.reshape(valid, (rows, -1))
    row_mad = jax.vmap(lambda x, v: _median(jnp.abs(x - _median(x, v)), v))(flat, ok)  # [R]; +inf for an empty row
    fence = _median(flat.ravel(), ok.ravel()) - spread * 1.4826 * _median(row_mad, jnp.any(ok, axis=1))
    return jnp.where(jnp.any(ok), fence, jnp.inf)


def calibrate_by_length(scores, lengths, false_rate: float, num_buckets: int, valid=None,
                        slack: float = 1e-3, spread: float = 0.0) -> jax.Array:
    """f32[L]: :func:`calibrate` per length bucket of ``lengths`` (shaped like ``scores``).

    Why: a prefix's score is a per-step mean, so short prefixes spread far wider; one threshold would
    let long prefixes of other adversaries through. A bucket with fewer than ⌈1/false_rate⌉ prefixes
    inherits the bucket below's (the first: the pooled threshold). ``spread`` > 0: each is at most
    its :func:`spread_fence` (``scores`` [R, ...])."""
    shape = jnp.shape(scores)
    scores, lengths = jnp.ravel(scores), jnp.ravel(lengths)
    valid = jnp.ones(scores.shape, bool) if valid is None else jnp.ravel(valid)

    def threshold(mine):
        tau = calibrate(scores, false_rate, mine, slack)
        if spread > 0:
            tau = jnp.minimum(tau, spread_fence(scores.reshape(shape), mine.reshape(shape), spread) - slack)
        return tau

    pooled = threshold(valid)
    bucket = length_bucket(lengths, num_buckets)
    needed = math.ceil(1.0 / false_rate) if false_rate > 0 else 1

    def one(b):
        mine = valid & (bucket == b)
        return threshold(mine), jnp.sum(mine) >= needed

    taus, enough = jax.vmap(one)(jnp.arange(num_buckets))

    def inherit(previous, x):
        tau, ok = x
        tau = jnp.where(ok, tau, previous)
        return tau, tau

    return jax.lax.scan(inherit, pooled, (taus, enough))[1]


def episode_minimum(z, lengths) -> jax.Array:
    """f32[T, N]: running minimum of ``z`` over each episode so far (``lengths`` == 1 starts one)."""
    return episode_running(jnp.minimum, z, lengths == 1)


def calibrate_monotone(scores, lengths, false_rate: float, num_buckets: int, valid=None,
                       margin: float = 1e-3, spread: float = 0.0) -> jax.Array:
    """f32[L]: bucket thresholds for the *monotone* judgement (a prefix is explained when it and every
    shorter prefix of its episode reach their thresholds).

    :func:`calibrate_by_length`, then all lowered together until at most ``false_rate`` of held-out
    prefixes have a shorter prefix below threshold, then by ``margin`` nats. ``scores``, ``lengths``,
    ``valid``: [R, T, N]."""
    tau = calibrate_by_length(scores, lengths, false_rate, num_buckets, valid, spread=spread)
    z = scores - tau[length_bucket(lengths, num_buckets)]
    low = jax.vmap(episode_minimum)(z, lengths)  # [R, T, N]
    shift = calibrate(low, false_rate, valid, slack=0.0)
    shift = jnp.where(jnp.isfinite(shift), jnp.minimum(shift, 0.0), 0.0)
    return tau + shift - margin
