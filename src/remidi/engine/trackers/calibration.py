"""Calibrating a learned tracker's thresholds: the score of a prefix below which a frozen model
calls it distinguishable, per prefix-length bucket, from held-out prefixes of the model's own
adversary (``remidi.belief_false_rate``: the share of them it may call distinguishable), and at
most their median minus ``remidi.belief_spread`` robust standard deviations (:func:`spread_fence`).

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


def _median(x, valid) -> jax.Array:
    """f32[]: the lower median of the valid entries of ``x`` (f32[n], ``valid`` bool[n]); +inf with none."""
    return jnp.sort(jnp.where(valid, x, jnp.inf))[jnp.maximum(jnp.sum(valid) - 1, 0) // 2]


def spread_fence(scores, valid, spread: float) -> jax.Array:
    """f32[]: the median of the valid held-out ``scores`` (f32[R, ...]: R rows, each one rollout
    scored by one version of the model; ``valid`` bool[R, ...]) minus ``spread`` robust standard
    deviations: 1.4826 × the median over rows of each row's median absolute deviation from its
    own median (the spread of one model version's scores: the record holds up to
    ``remidi.belief_calibration`` versions, and a model still learning drifts from row to row,
    which is no spread of the adversary's trajectories). +inf (no fence) with no valid score.

    Why the threshold needs it: the held-out scores are those of the adversary's own few levels,
    replayed again and again, so their lower quantile says little about the tail of the
    adversary's *kind* of trajectory, which the next adversary searches (``lever-noisy``: each
    hidden level's noise code; the next buffer's PLR⊥ ranking keeps any hidden level the frozen
    model scores below τ, as its regret beats every visible level's). Where the scores are one
    mode the fence extrapolates that tail in units of its own spread; where the adversary's
    support holds a lower-scoring minority larger than the false rate (a generator that still
    builds some visible levels, a buffer's few ordinary mazes) the quantile already lies below
    the fence and stays; where most scores are equal (a deterministic task) the spread is 0 and
    the fence is the median, above the quantile."""
    rows = scores.shape[0]
    flat, ok = jnp.reshape(scores, (rows, -1)), jnp.reshape(valid, (rows, -1))
    row_mad = jax.vmap(lambda x, v: _median(jnp.abs(x - _median(x, v)), v))(flat, ok)  # [R]; +inf for an empty row
    fence = _median(flat.ravel(), ok.ravel()) - spread * 1.4826 * _median(row_mad, jnp.any(ok, axis=1))
    return jnp.where(jnp.any(ok), fence, jnp.inf)


def calibrate_by_length(scores, lengths, false_rate: float, num_buckets: int, valid=None,
                        slack: float = 1e-3, spread: float = 0.0) -> jax.Array:
    """f32[L]: :func:`calibrate` separately for the prefixes of each length bucket
    (:func:`length_bucket` of ``lengths`` i32[...], as ``scores``). A prefix's score is a mean
    over its steps, so short prefixes (the first observation alone) spread far wider than long
    ones, and one threshold over all lengths would be set by the short ones and let long prefixes
    of other adversaries through. A bucket with too few held-out prefixes for its quantile (fewer
    than ⌈1/false_rate⌉, one for a rate of 0) takes the threshold of the bucket below it (the
    first bucket: the threshold of all lengths together). ``spread`` > 0: each threshold is at
    most its prefixes' :func:`spread_fence` (then ``scores`` are [R, ...], rows first)."""
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
    """f32[T, N]: the running minimum of ``z`` f32[T, N] over each episode's prefix so far
    (``lengths`` i32[T, N], :func:`prefix_lengths`: 1 starts an episode)."""
    return episode_running(jnp.minimum, z, lengths == 1)


def calibrate_monotone(scores, lengths, false_rate: float, num_buckets: int, valid=None,
                       margin: float = 1e-3, spread: float = 0.0) -> jax.Array:
    """f32[L]: thresholds per prefix-length bucket for the *monotone* judgement the tracker makes
    (a prefix is explained when it and every shorter prefix of its episode reach their
    thresholds: a prefix an adversary cannot produce has no extension it can produce). Per bucket
    :func:`calibrate_by_length`; then all are lowered together until at most ``false_rate`` of
    the held-out prefixes have a shorter prefix below its threshold (the ``false_rate`` quantile
    of ``min over the episode so far of (score − τ)``), and by ``margin`` nats per step.
    ``spread`` > 0: each bucket's threshold is first at most its :func:`spread_fence`
    (``remidi.belief_spread``). ``scores``, ``lengths``, ``valid``: [R, T, N] (rows of T steps of N
    envs, time-major)."""
    tau = calibrate_by_length(scores, lengths, false_rate, num_buckets, valid, spread=spread)
    z = scores - tau[length_bucket(lengths, num_buckets)]
    low = jax.vmap(episode_minimum)(z, lengths)  # [R, T, N]
    shift = calibrate(low, false_rate, valid, slack=0.0)
    shift = jnp.where(jnp.isfinite(shift), jnp.minimum(shift, 0.0), 0.0)
    return tau + shift - margin
