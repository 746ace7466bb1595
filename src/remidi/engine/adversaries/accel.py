"""ACCEL's adversary (Parker-Holder et al., 2022): PLR⊥ whose update after a replay edits the
levels it replayed and offers the edits to the buffer like fresh levels."""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
from flax import struct

from remidi.engine.adversaries.base import AdversaryState, Proposal
from remidi.engine.adversaries.plr import LevelBuffers


@struct.dataclass
class EditingState(AdversaryState):
    """:class:`~remidi.engine.adversaries.base.AdversaryState` plus ACCEL's memory of the last replay.

    ``edit_next`` bool[]: the next update edits this one's replay; ``last_replayed``: its levels [N, ...]."""

    edit_next: jax.Array = None
    last_replayed: object = None


@dataclass(frozen=True)
class EditingBuffers(LevelBuffers):
    """ACCEL's adversary: after a replay, the next update edits the replayed levels.

    ``accel.num_edits`` mutator edits each; the edits are offered to the buffer like fresh levels,
    not trained on. ``accel.easy_start``: fresh levels from the task's easy generator."""

    def init(self, setup, example_level, example_obs, rng) -> EditingState:
        base = super().init(setup, example_level, example_obs, rng)
        return EditingState(buffers=base.buffers, active=base.active, count=base.count,
                            edit_next=jnp.asarray(False),
                            last_replayed=jax.tree.map(lambda x: jnp.stack([x] * setup.cfg.num_envs), example_level))

    def propose(self, setup, runner, fresh, k_branch, k_levels, k_sample) -> Proposal:
        if setup.cfg.accel.easy_start:  # fresh levels from the easy generator (the step's keys)
            fresh = jax.vmap(setup.task.easy_level)(jax.random.split(k_levels, setup.cfg.num_envs))
        base = super().propose(setup, runner, fresh, k_branch, k_levels, k_sample)  # replayed or fresh levels
        state = runner.adversary
        edit = state.edit_next
        replay = base.replay & ~edit
        edited = edit_levels(setup, state.last_replayed, jax.random.fold_in(k_levels, 1))
        levels = jax.tree.map(lambda e, chosen: jnp.where(edit, e, chosen), edited, base.levels)
        train = replay | self.trains_on_fresh
        rehearse = base.rehearse
        if rehearse is not None:  # an edit update never rehearses (the edits of the last replay come first)
            rehearse = rehearse & ~edit
            train = train | rehearse
        return Proposal(replay=replay, levels=levels, buffer=base.buffer, slots=base.slots, train=train, edit=edit,
                        rehearse=rehearse)

    def advance(self, setup, runner, proposal: Proposal, outcome):
        """After a replay the next update edits its levels."""
        runner, metrics = super().advance(setup, runner, proposal, outcome)
        state = runner.adversary
        last = jax.tree.map(lambda c, o: jnp.where(proposal.replay, c, o), proposal.levels, state.last_replayed)
        return runner.replace(adversary=state.replace(edit_next=proposal.replay, last_replayed=last)), metrics


def edit_levels(setup, levels, rng):
    """ACCEL's edits: ``accel.num_edits`` edits of each of ``levels`` [N] by the task's mutator."""
    n = jax.tree.leaves(levels)[0].shape[0]
    edits = setup.cfg.accel.num_edits
    return jax.vmap(lambda key, level: setup.task.mutate_level(key, level, edits))(jax.random.split(rng, n), levels)
