"""SFL's adversary (Rutherford et al., 2024, "No Regrets"): Sampling For Learnability, and ReMiDi over it.

Every ``sfl.refresh_every`` updates (and before the first) the buffer is refreshed
(:meth:`LearnabilityBuffers.refresh`): ``sfl.batch_size × sfl.num_batches`` fresh levels are
played ``sfl.rollout_steps`` steps by the current policy (no gradient), scored by learnability
p·(1 − p), and the K best kept (:func:`select_top`). Each update trains on N envs, the last
round(``sfl.sampled_envs_ratio`` · N) drawn uniformly from the buffer, the rest fresh
(``Proposal.replay`` is bool[N]).

With ``buffer_sequence`` (``remidi-sfl``) the adversary is a sequence of ``remidi.num_buffers``
SFL buffers of ``remidi.buffer_capacity`` levels each, the active one refreshed every
``sfl.refresh_every`` updates *on it* (a new buffer is filled at its first update) and switched
after ``remidi.steps_per_buffer`` updates; the frozen buffers' levels go to the tracker
(:meth:`LearnabilityBuffers.frozen`). The refresh's candidate rollouts run with the tracker
beside them, against the same frozen levels as the update's rollout: a candidate whose rollout
the frozen levels explain at every step (a complete overlap, as the train step's ``overlap``)
scores −inf and is never kept. The learner's loss is masked where a frozen level explains the
prefix (the train step's ``traj.indist``), on buffer and fresh envs alike.

Deliberate departures from the published code: a level with no finished episode is never kept
(the original's NaN solve rate sorts highest); learnability ties go to the higher solve rate
(Kinetix's ``+ 0.001 · p``, applied lexicographically), then to the earlier candidate."""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp

from remidi.engine import learner as lrn
from remidi.engine.adversaries import level_buffer as buf
from remidi.engine.adversaries import scores as sc
from remidi.engine.adversaries.base import Adversary, AdversaryState, Proposal
from remidi.engine.adversaries.plr import buffer_contents, sequence_advance
from remidi.engine.config import BufferConfig, num_buffers
from remidi.engine.learner import nonfinite, nonfinite_names
from remidi.engine.core.seeds import cond_per_seed

#: the name of the refresh's rollouts in their non-finite flags (``nonfinite/reward/candidates``)
CANDIDATES = "candidates"


def select_top(scores: jax.Array, solve_rates: jax.Array, k: int) -> tuple[jax.Array, jax.Array]:
    """``(indices i32[k], valid bool[k])``, best first: the ``k`` highest ``scores`` f32[M].

    Ties to higher ``solve_rates`` f32[M], then lower index. ``valid`` is False where the score is
    −inf (no finished episode, or explained by a frozen level)."""
    order = jnp.lexsort((-solve_rates, -scores))  # primary: score descending; stable: index ascending
    top = order[:k]
    return top, jnp.isfinite(scores[top])


def learnability_of(setup, traj) -> tuple[jax.Array, jax.Array]:
    """``(learnability f32[B], solve rate f32[B])`` of rollouts ``traj`` [T, B]; −inf where no episode
    ended or frozen levels explain every step."""
    solved = setup.task.solved
    score = sc.learnability(traj.reward, traj.done, solved, flags=traj.solved)
    p, _ = sc.solve_rate(traj.reward, traj.done, solved, traj.solved)
    return jnp.where(jnp.all(traj.indist, axis=0), -jnp.inf, score), p


def per_level(mask: jax.Array, x: jax.Array) -> jax.Array:
    """``mask`` bool[K] shaped to broadcast over ``x`` [K, ...]."""
    return mask.reshape(mask.shape + (1,) * (x.ndim - 1))


def valid_mean(valid: jax.Array, x: jax.Array) -> jax.Array:
    """f32[]: the mean of ``x`` f32[K] over ``valid`` bool[K]; NaN where none is."""
    size = jnp.sum(valid)
    return jnp.where(size > 0, jnp.sum(jnp.where(valid, x, 0.0)) / jnp.maximum(size, 1), jnp.nan)


def mix_mask(num_envs: int, ratio: float) -> jax.Array:
    """bool[N]: the envs filled from the buffer, the last round(``ratio`` · N) (as the published code)."""
    return jnp.arange(num_envs) >= num_envs - round(ratio * num_envs)


@dataclass(frozen=True)
class LearnabilityBuffers(Adversary):
    """SFL's adversary (module docstring).

    State ``count``: updates on the active buffer (times the refreshes); buffer ``scores``:
    learnability, extra ``solve_rate``: solve rate at the refresh that kept them."""

    trains_on_fresh: bool = True
    buffer_sequence: bool = False

    def capacity(self, cfg) -> int:
        """K, the levels each buffer keeps: ``sfl.buffer_size``, a sequence's ``remidi.buffer_capacity``."""
        return cfg.remidi.buffer_capacity if self.buffer_sequence else cfg.sfl.buffer_size

    def init(self, setup, example_level, example_obs, rng) -> AdversaryState:
        one = buf.init_buffer(BufferConfig(capacity=self.capacity(setup.cfg)), example_level,
                              extra_names=("solve_rate",))
        zero = jnp.zeros((), jnp.int32)
        return AdversaryState(buffers=buf.stack_buffers([one] * num_buffers(setup.cfg, setup.algo)), active=zero,
                              count=zero)

    def propose(self, setup, runner, fresh, k_branch, k_levels, k_sample) -> Proposal:
        """Refresh the active buffer if due, then N levels: :func:`mix_mask` ones from it, the rest
        ``fresh`` (all fresh while it is empty)."""
        state, cfg = runner.adversary, setup.cfg
        active = buf.select_buffer(state.buffers, state.active)
        due = state.count % cfg.sfl.refresh_every == 0
        unrefreshed = {name: jnp.float32(0.0) for name in nonfinite_names(CANDIDATES)}
        active, flags = cond_per_seed(due, lambda b: self.refresh(setup, runner, k_branch, b),
                                      lambda b: (b, unrefreshed), active)
        n = cfg.num_envs
        weights = active.valid / jnp.maximum(jnp.sum(active.valid), 1)
        slots = jax.random.choice(k_sample, active.valid.shape[0], (n,), replace=True,
                                  p=jnp.where(jnp.any(active.valid), weights, 1.0 / active.valid.shape[0]))
        replay = mix_mask(n, cfg.sfl.sampled_envs_ratio) & jnp.any(active.valid)
        levels = jax.tree.map(lambda r, f: jnp.where(per_level(replay, r), r, f), buf.get_levels(active, slots),
                              fresh)
        return Proposal(replay=replay, levels=levels, buffer=active, slots=slots, train=jnp.asarray(True),
                        nonfinite=flags)

    def refresh(self, setup, runner, rng, old: buf.BufferState) -> tuple[buf.BufferState, dict]:
        """The active buffer refilled: ``sfl.batch_size × sfl.num_batches`` fresh candidates, each
        played ``sfl.rollout_steps`` steps by the current policy (one batch at a time, with the
        tracker against the frozen levels), the K most learnable kept (:func:`select_top`).
        Returns it with its rollouts' :func:`~remidi.engine.learner.nonfinite` flags."""
        s = setup.cfg.sfl
        frozen = setup.tracker.frozen(setup, runner) if setup.tracker is not None else None

        def one_batch(key):
            k_levels, k_roll = jax.random.split(key)
            levels = jax.vmap(setup.task.sample_level)(jax.random.split(k_levels, s.batch_size))
            traj, _ = lrn.play(setup, runner.learner, k_roll, levels, s.rollout_steps, frozen)
            score, p = learnability_of(setup, traj)
            return levels, score, p, nonfinite(traj, CANDIDATES)

        levels, scores, rates, flags = jax.lax.map(one_batch, jax.random.split(rng, s.num_batches))
        levels, scores, rates = jax.tree.map(lambda x: x.reshape((-1,) + x.shape[2:]), (levels, scores, rates))
        top, valid = select_top(scores, rates, old.valid.shape[0])  # over the M = num_batches · B candidates

        def kept(x):  # the chosen candidates' values; an empty slot's zeros where fewer can be kept
            return jnp.where(per_level(valid, x), x[top], jnp.zeros_like(x[top]))

        return old.replace(levels=jax.tree.map(kept, levels), scores=kept(scores), valid=valid,
                           extras={"solve_rate": kept(rates)}, last_seen=jnp.zeros_like(old.last_seen),
                           time=old.time + 1), jax.tree.map(jnp.max, flags)

    def update(self, setup, runner, proposal: Proposal, outcome, rng):
        """The refreshed buffer becomes the active one; reports ``sfl/buffer_learnability`` and
        ``sfl/buffer_solve_rate`` (NaN while empty)."""
        state, active = runner.adversary, proposal.buffer
        metrics = {"sfl/buffer_learnability": valid_mean(active.valid, active.scores),
                   "sfl/buffer_solve_rate": valid_mean(active.valid, active.extras["solve_rate"])}
        state = state.replace(buffers=buf.replace_buffer(state.buffers, state.active, active))
        return state, jnp.zeros((setup.cfg.num_envs,), bool), metrics

    def advance(self, setup, runner, proposal: Proposal, outcome):
        """Every update counts (whatever ``remidi.count``: each trains on the buffer); a sequence may
        switch, its next buffer refreshed at its first update."""
        state = runner.adversary.replace(count=runner.adversary.count + 1)
        if not self.buffer_sequence:
            return runner.replace(adversary=state), {}
        return sequence_advance(setup, runner, state, proposal, outcome)

    def metrics(self, setup, runner) -> dict:
        return buffer_contents(setup, runner.adversary)
