"""The PLR family's adversary (:class:`LevelBuffers`): PLR⊥, minimax return, ReMiDi's buffer sequence.

With probability ``buffer.replay_prob``, once the active buffer can replay, an update replays N
levels sampled from it (by score rank or top-k, mixed with staleness:
:mod:`remidi.engine.adversaries.level_buffer`); otherwise it plays N fresh levels, scored and
inserted by score. With ``buffer_sequence`` (ReMiDi) the adversary is a sequence of
``remidi.num_buffers`` buffers: after ``remidi.steps_per_buffer`` updates the active one is frozen
and the next takes over (the last stays); the frozen ones' levels go to the tracker
(:meth:`~remidi.engine.trackers.base.Tracker.frozen`), a fresh level a frozen one explains at every step (a
complete overlap) is never inserted, and with ``remidi.rehearsal`` an update may instead rehearse
a frozen buffer's levels (:func:`rehearse_frozen`).
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp

from remidi.engine.adversaries import level_buffer as buf
from remidi.engine.adversaries.base import Adversary, AdversaryState, Outcome, Proposal, empty_buffers, tag_counts


@dataclass(frozen=True)
class LevelBuffers(Adversary):
    """The PLR family's adversary (module docstring). State: :class:`~remidi.engine.adversaries.base.AdversaryState`."""

    trains_on_fresh: bool = False
    buffer_sequence: bool = False

    replays = True

    def init(self, setup, example_level, example_obs, rng) -> AdversaryState:
        """K empty buffers (:func:`~remidi.engine.adversaries.base.empty_buffers`), the first active."""
        return super().init(setup, example_level, example_obs, rng).replace(buffers=empty_buffers(setup, example_level))

    def propose(self, setup, runner, fresh, k_branch, k_levels, k_sample) -> Proposal:
        """A replay of N levels from the active buffer (``k_branch``: whether; ``k_sample``: which) or the
        N ``fresh`` ones; a sequence may rehearse a frozen buffer instead."""
        state, bcfg = runner.adversary, setup.buffer
        active = buf.select_buffer(state.buffers, state.active)
        replay = buf.can_replay(active, bcfg) & (jax.random.uniform(k_branch) < bcfg.replay_prob)
        sampled, slots, replayed = buf.sample_replay(active, bcfg, k_sample, setup.cfg.num_envs)
        levels = jax.tree.map(lambda r, f: jnp.where(replay, r, f), replayed, fresh)
        proposal = Proposal(replay=replay, levels=levels, buffer=sampled, slots=slots,
                            train=replay | self.trains_on_fresh)
        if self.buffer_sequence and setup.cfg.remidi.rehearsal > 0:
            proposal = rehearse_frozen(setup, state, proposal, jax.random.fold_in(k_branch, 1))
        return proposal

    def best_return(self, proposal: Proposal, best_return):
        """For a replayed level, the buffer's record too."""
        record = proposal.buffer.extras["max_return"][proposal.slots]
        return jnp.where(proposal.replay, jnp.maximum(best_return, record), best_return)

    def update(self, setup, runner, proposal: Proposal, outcome: Outcome, rng):
        """Replayed levels are rescored; fresh ones are inserted by score unless a frozen level explains
        them completely; a rehearsal changes no buffer."""
        state, n, bcfg = runner.adversary, setup.cfg.num_envs, setup.buffer
        record = {"max_return": outcome.collection.best_return}

        def rescore(_):
            return buf.update_scores(proposal.buffer, proposal.slots, outcome.scores, record), jnp.zeros((n,), bool)

        def insert(_):
            active = buf.select_buffer(state.buffers, state.active)
            new_buf, ins, _ = buf.insert_batch(active, bcfg, proposal.levels,
                                               jnp.where(outcome.overlap, -jnp.inf, outcome.scores), record)
            return new_buf, ins

        if proposal.rehearse is None:
            new_buf, inserted = jax.lax.cond(proposal.replay, rescore, insert, None)
        else:
            def keep(_):
                return buf.select_buffer(state.buffers, state.active), jnp.zeros((n,), bool)

            branch = jnp.where(proposal.rehearse, 2, proposal.replay.astype(jnp.int32))
            new_buf, inserted = jax.lax.switch(branch, (insert, rescore, keep), None)
        return state.replace(buffers=buf.replace_buffer(state.buffers, state.active, new_buf)), inserted, {}

    def advance(self, setup, runner, proposal: Proposal, outcome: Outcome):
        """Count the update (only replays with ``remidi.count=replays``); a sequence may switch."""
        state = runner.adversary
        state = state.replace(count=state.count + (proposal.replay.astype(jnp.int32)
                                                   if setup.cfg.remidi.count == "replays" else 1))
        if not self.buffer_sequence:
            return runner.replace(adversary=state), {}
        return sequence_advance(setup, runner, state, proposal, outcome)

    def metrics(self, setup, runner) -> dict:
        return buffer_contents(setup, runner.adversary)


def rehearse_frozen(setup, state, proposal: Proposal, rng) -> Proposal:
    """``remidi.rehearsal``: with that probability, once an earlier buffer of the sequence holds
    levels, ``proposal`` gives way to a rehearsal: N levels drawn uniformly (with replacement) from
    the valid levels of one of the non-empty earlier buffers, chosen uniformly. A rehearsal trains
    on every step (:attr:`~remidi.engine.trackers.base.Frozen.rehearse`), is no replay of the active buffer (``replay``
    False: nothing is rescored, inserted or sampled, and ``remidi.count=replays`` does not count
    it), and reads the frozen buffers without changing them (no clock tick, no ``last_seen``).

    The buffer is chosen uniformly among non-empty frozen ones, its levels uniformly with
    replacement. A rehearsal trains on every step, is no replay (nothing rescored, inserted or
    counted) and leaves the frozen buffers unchanged. Uniform, not by score: frozen scores are stale,
    and rehearsal should keep behaviour on the whole earlier support."""
    n = setup.cfg.num_envs
    k_draw, k_buffer, k_slots = jax.random.split(rng, 3)
    valid = state.buffers.valid  # bool[K, C]
    k, capacity = valid.shape
    eligible = (jnp.arange(k) < state.active) & jnp.any(valid, axis=1)  # frozen and not empty
    rehearse = jnp.any(eligible) & (jax.random.uniform(k_draw) < setup.cfg.remidi.rehearsal)
    which = jax.random.choice(k_buffer, k, p=jnp.where(jnp.any(eligible), eligible / jnp.maximum(jnp.sum(eligible), 1),
                                                         1.0 / k))
    chosen = valid[which]
    slots = jax.random.choice(k_slots, capacity, (n,), replace=True,
                              p=jnp.where(jnp.any(chosen), chosen / jnp.maximum(jnp.sum(chosen), 1), 1.0 / capacity))
    frozen = buf.get_levels(buf.select_buffer(state.buffers, which), slots)
    levels = jax.tree.map(lambda f, o: jnp.where(rehearse, f, o), frozen, proposal.levels)
    return proposal.replace(levels=levels, replay=proposal.replay & ~rehearse, train=proposal.train | rehearse,
                            rehearse=rehearse)


def sequence_advance(setup, runner, state, proposal: Proposal, outcome: Outcome):
    """The end of a sequence's update, given its adversary ``state`` after counting: a tracker
    with a state (a learned model) learns from the rollout; after ``remidi.steps_per_buffer``
    counted updates (and unless the active adversary is the last) the active one is frozen and
    the next takes over, and with it Combine's policy (``remidi.policy``) and the tracker's model
    freeze. Returns ``(runner, the tracker's step metrics)``."""
    switch = (state.count >= setup.cfg.remidi.steps_per_buffer) & (state.active + 1 < state.buffers.valid.shape[0])
    metrics = {}
    if runner.tracker is not None:  # the exact trackers keep nothing across updates
        tracker, metrics = setup.tracker.learn(setup, runner, proposal, outcome.collection.traj)
        runner = runner.replace(tracker=setup.tracker.freeze(setup, runner.replace(tracker=tracker), switch))
    if runner.learner.frozen_params is not None:  # remidi.policy=combine
        learner, active = runner.learner, runner.adversary.active  # keep the policy trained on the frozen one
        frozen_params = jax.tree.map(lambda f, p: f.at[active].set(jnp.where(switch, p, f[active]), mode="drop"),
                                     learner.frozen_params, learner.train_state.params)
        runner = runner.replace(learner=learner.replace(frozen_params=frozen_params))
    state = state.replace(active=jnp.where(switch, state.active + 1, state.active),
                          count=jnp.where(switch, 0, state.count))
    return runner.replace(adversary=state), metrics


def buffer_contents(setup, state) -> dict:
    """``buffer_fraction/<tag>/b<k>`` and ``buffer_fraction/<tag>`` (active) tag shares, ``buffer_size``."""
    out = {}
    valid = state.buffers.valid  # bool[K, C]
    sizes = jnp.maximum(jnp.sum(valid, axis=1), 1)  # [K]
    counts = jax.vmap(lambda levels, v: tag_counts(setup, levels, v.astype(jnp.float32)))(state.buffers.levels, valid)
    for name, c in counts.items():  # c: f32[K]
        fractions = c / sizes
        for b in range(valid.shape[0]):
            out[f"buffer_fraction/{name}/b{b}"] = fractions[b]
        out[f"buffer_fraction/{name}"] = fractions[state.active]
    out["buffer_size"] = jnp.sum(valid[state.active]).astype(jnp.float32)
    return out
