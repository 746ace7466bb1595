"""``buffer_solve_rate/b<k>``: the current policy's solve rate on each buffer of a buffer sequence,
to show what the agent keeps of a frozen buffer (docs/retention.md).

Up to :data:`MAX_LEVELS` valid levels per buffer (a uniform draw without replacement), played
as the evaluation sets are (``eval_attempts`` episodes, first episode judged by ``solved``). NaN
for a buffer with no valid level; nothing without a buffer sequence or ``solved``."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from remidi.engine.adversaries.scores import episode_solved

#: levels played per buffer at most (256 give the rate to about ±0.03; 4,000 would cost 40,000 episodes)
MAX_LEVELS = 256


def buffer_solve_rates(setup, runner, rng, level_episodes, action: str = "sample") -> dict[str, jax.Array]:
    """``{"buffer_solve_rate/b<k>": f32[]}`` for each of the K buffers.

    ``level_episodes``: :func:`remidi.engine.run.evaluation.level_episodes` (the combined policy
    under ``remidi.policy=combine``)."""
    task = setup.task
    if not setup.algo.buffer_sequence or task.solved is None:
        return {}
    buffers = runner.adversary.buffers
    valid = buffers.valid  # bool[K, C]
    k, capacity = valid.shape
    if capacity == 0:  # a generator sequence keeps no levels
        return {}
    m = min(capacity, MAX_LEVELS)
    k_pick, k_play = jax.random.split(rng)
    # valid slots first, in random order: the first m are a uniform draw without replacement
    _, slots = jax.lax.top_k(jnp.where(valid, jax.random.uniform(k_pick, (k, capacity)), -1.0), m)  # i32[K, m]
    picked = jnp.take_along_axis(valid, slots, axis=1)  # bool[K, m]
    levels = jax.tree.map(lambda x: jax.vmap(lambda xs, s: xs[s])(x, slots).reshape((k * m,) + x.shape[2:]),
                          buffers.levels)
    returns, _, flags = level_episodes(setup, runner, task.env, levels, setup.cfg.eval_attempts, k_play, action)
    solved = episode_solved(task.solved, returns, flags).astype(jnp.float32)  # [K·m, attempts]
    solved = jnp.mean(solved, axis=1).reshape(k, m)  # per level
    count = jnp.sum(picked, axis=1)
    rate = jnp.where(count > 0, jnp.sum(jnp.where(picked, solved, 0.0), axis=1) / jnp.maximum(count, 1), jnp.nan)
    return {f"buffer_solve_rate/b{b}": rate[b] for b in range(k)}
