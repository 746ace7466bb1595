"""What evaluation reports of a learned tracker: its thresholds and its judgement against the exact tracker's."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from remidi.engine.learner import collect
from remidi.engine.trackers.exact import exact_budget, make_tracker


def threshold_metrics(threshold, active) -> dict:
    """``belief/threshold``, ``belief/threshold/long``: the last frozen model's thresholds (nats/step).

    ``threshold`` f32[K, L] (adversary, prefix-length bucket): the first and the last bucket; NaN
    before the first switch (``active`` i32[])."""
    last = threshold[jnp.maximum(active - 1, 0)]  # f32[L]
    frozen = active > 0
    return {"belief/threshold": jnp.where(frozen, last[0], jnp.nan),
            "belief/threshold/long": jnp.where(frozen, last[-1], jnp.nan)}


def audit_against_exact(tracker, setup, runner, rng) -> dict[str, jax.Array]:
    """The learned ``tracker`` against the exact one on one rollout of ``num_envs`` fresh levels.

    Both rollouts share the key and trackers do not act, so the steps are the same. Reports
    ``belief/explained``, ``belief/exact_explained`` (share of steps each calls indistinguishable),
    ``belief/agreement``, and per level tag ``belief/explained/<tag>``, ``.../not-<tag>`` (NaN where
    the batch has none); all NaN while nothing is frozen."""
    cfg = setup.cfg
    k_levels, k_roll = jax.random.split(rng)
    levels = jax.vmap(setup.task.sample_level)(jax.random.split(k_levels, cfg.num_envs))
    frozen = setup.tracker.frozen(setup, runner).replace(params=None)  # the current policy acts in both
    # the exact tracker a `prefix` run would use (candidate slots where the reset allows)
    budget = exact_budget(setup.task, cfg.remidi, "prefix")
    exact = frozen.replace(belief=None, tracker=make_tracker("prefix", budget))
    belief = collect(setup, runner.learner, k_roll, levels, frozen).traj.indist
    reference = collect(setup, runner.learner, k_roll, levels, exact).traj.indist
    nan = jnp.where(runner.adversary.active > 0, 0.0, jnp.nan)
    out = {"belief/explained": jnp.mean(belief.astype(jnp.float32)) + nan,
           "belief/exact_explained": jnp.mean(reference.astype(jnp.float32)) + nan,
           "belief/agreement": jnp.mean((belief == reference).astype(jnp.float32)) + nan}
    for tag, tagged in jax.vmap(setup.task.level_tags)(levels).items():  # bool[N]: the levels of one kind
        for kind, mask in ((tag, tagged), (f"not-{tag}", ~tagged)):
            steps = jnp.maximum(jnp.sum(mask) * belief.shape[0], 1)
            none = jnp.where(jnp.any(mask), 0.0, jnp.nan)
            out[f"belief/explained/{kind}"] = jnp.sum(belief & mask[None, :]) / steps + nan + none
            out[f"belief/exact_explained/{kind}"] = jnp.sum(reference & mask[None, :]) / steps + nan + none
    return out
