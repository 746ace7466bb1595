"""The seed axis of a compiled program, and a branch that stays a branch over it.

:func:`remidi.engine.run.driver.over_seeds` runs a one-seed program over S seeds with ``jax.vmap``
(axis name :data:`SEED_BATCH`). ``vmap`` turns a ``lax.cond`` whose predicate is a per-seed value
into *both* branches and a select, so a branch taken at a few updates of a run (a buffer switch's
calibration, which replays every recorded rollout) costs every update of a multi-seed run.
:func:`cond_per_seed` keeps such a branch a branch: it runs when some seed takes it.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

SEED_BATCH = "seed_batch"  # the name of over_seeds' vmapped axis (the seeds one device runs together)


def any_seed(pred) -> jax.Array:
    """bool[]: ``pred`` bool[] (one seed's) holds for some seed of the batch this program runs
    (:data:`SEED_BATCH`: the same value for every seed), or ``pred`` itself where no seeds are
    batched (a one-seed program, a device's one seed under ``shard_map``). No communication
    between devices: the reduction is over the vmapped axis only."""
    try:
        return jax.lax.psum(jnp.asarray(pred, jnp.int32), SEED_BATCH) > 0
    except NameError:  # no seed batch bound here
        return jnp.asarray(pred)


def cond_per_seed(pred, true_fn, false_fn, operand):
    """``lax.cond(pred, true_fn, false_fn, operand)`` for each seed (``pred`` bool[]: the seed's),
    computed under the seed vmap as a branch that runs only when some seed's ``pred`` holds: then
    both functions run for every seed and each seed keeps the result of its own branch (what the
    vmapped ``lax.cond`` computes at every call). For a rarely taken ``true_fn`` and a cheap
    ``false_fn`` (the identity, typically)."""

    def some(x):
        return jax.tree.map(lambda t, f: jnp.where(pred, t, f), true_fn(x), false_fn(x))

    return jax.lax.cond(any_seed(pred), some, false_fn, operand)
