"""What evaluation reports of a learned tracker (:mod:`~remidi.engine.trackers.belief`,
:mod:`~remidi.engine.trackers.simulated`): its thresholds, and its judgement against the exact
tracker's on the same rollout."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from remidi.engine.learner import collect
from remidi.engine.trackers.exact import exact_budget, make_tracker


def threshold_metrics(threshold, active) -> dict:
    """``belief/threshold`` and ``belief/threshold/long``: the last frozen model's thresholds
    (``threshold`` f32[K, L], per adversary and prefix-length bucket) for one-step prefixes and
    for the longest bucket (which holds the longest bucket's with enough held-out prefixes,
    :func:`~remidi.engine.trackers.calibration.calibrate_by_length`), in nats per step; NaN before
    the first switch (``active`` i32[]: the active adversary)."""
    last = threshold[jnp.maximum(active - 1, 0)]  # f32[L]
    frozen = active > 0
    return {"belief/threshold": jnp.where(frozen, last[0], jnp.nan),
            "belief/threshold/long": jnp.where(frozen, last[-1], jnp.nan)}


def audit_against_exact(tracker, setup, runner, rng) -> dict[str, jax.Array]:
    """The learned ``tracker``'s judgement against the exact tracker's on the same rollout, one
    batch of ``num_envs`` fresh levels of the task's generator played by the current policy for
    ``num_steps`` steps (both rollouts take the same key and the trackers do not act, so their
    steps are the same): ``belief/explained`` and ``belief/exact_explained`` (the share of steps
    whose prefix each tracker calls indistinguishable from an earlier adversary's) and
    ``belief/agreement`` (the share of steps they judge alike); per level tag of the task the two
    shares over the levels of that kind and of the others (``belief/explained/<tag>``,
    ``belief/explained/not-<tag>``, ``belief/exact_explained/...``; NaN where the batch holds no
    such level); NaN while no buffer is frozen."""
    cfg = setup.cfg
    k_levels, k_roll = jax.random.split(rng)
    levels = jax.vmap(setup.task.sample_level)(jax.random.split(k_levels, cfg.num_envs))
    frozen = setup.algo.adversary.frozen(setup, runner).replace(params=None)  # the current policy acts in both
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
