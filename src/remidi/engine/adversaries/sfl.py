"""SFL's adversary (Rutherford et al., 2024, "No Regrets: Investigating and Improving Regret
Approximations for Curriculum Discovery"): Sampling For Learnability, and ReMiDi over it.

Every ``sfl.refresh_every`` updates (and before the first), the adversary refreshes its buffer
(:meth:`LearnabilityBuffers.refresh`): it draws ``sfl.batch_size × sfl.num_batches`` fresh
levels from the task's generator, rolls the *current* policy out on each for
``sfl.rollout_steps`` steps (several episodes; :func:`remidi.engine.learner.play`, no gradient),
scores each by its learnability p·(1 − p), p its solve rate over the episodes that ended
(:func:`~remidi.engine.adversaries.scores.solve_rate`, the task's ``solved``), and keeps the K
highest (:func:`select_top`). Every update then trains on N envs of which
round(``sfl.sampled_envs_ratio`` · N) are drawn uniformly, with replacement, from the buffer (as
the published code draws them, ``jax.random.randint`` over the kept levels) and the rest are
fresh levels; the learner trains on all of them (:class:`~remidi.engine.adversaries.base.Proposal`'s
``replay`` is per env: bool[N]).

With ``buffer_sequence`` (``remidi-sfl``) the adversary is a sequence of ``remidi.num_buffers``
SFL buffers of ``remidi.buffer_capacity`` levels each, the active one refreshed every
``sfl.refresh_every`` updates *on it* (a new buffer is filled at its first update) and switched
after ``remidi.steps_per_buffer`` updates; the frozen buffers' levels go to the tracker
(:meth:`LearnabilityBuffers.frozen`). The refresh's candidate rollouts run with the tracker
beside them, against the same frozen levels as the update's rollout: a candidate whose rollout
the frozen levels explain at every step (a complete overlap, as the train step's ``overlap``)
scores −inf and is never kept. The learner's loss is masked where a frozen level explains the
prefix (the train step's ``traj.indist``), on buffer and fresh envs alike.

Departures from the published code, each on purpose: a level none of whose episodes ended inside
the rollout is never kept (the published code gives it a NaN solve rate, which its sort ranks
highest); ties in learnability go to the higher solve rate (Kinetix's ``+ 0.001 · p``, taken
lexicographically so it never outranks a real difference), then to the earlier candidate.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp

from remidi.engine import learner as lrn
from remidi.engine.adversaries import level_buffer as buf
from remidi.engine.adversaries import scores as sc
from remidi.engine.adversaries.base import Adversary, AdversaryState, Proposal
from remidi.engine.adversaries.plr import buffer_contents, sequence_advance, sequence_frozen
from remidi.engine.config import BufferConfig, num_buffers
from remidi.engine.learner import nonfinite, nonfinite_names
from remidi.engine.core.seeds import cond_per_seed

#: the name of the refresh's rollouts in their non-finite flags (``nonfinite/reward/candidates``)
CANDIDATES = "candidates"


def select_top(scores: jax.Array, solve_rates: jax.Array, k: int) -> tuple[jax.Array, jax.Array]:
    """SFL's selection: the ``k`` candidates with the highest learnability ``scores`` f32[M]
    (−inf: no finished episode, or explained by a frozen level), ties to the higher
    ``solve_rates`` f32[M], then to the lower index. Returns ``(indices i32[k], valid bool[k])``,
    best first; ``valid`` is False where the chosen score is −inf (fewer than ``k`` candidates
    can be kept)."""
    order = jnp.lexsort((-solve_rates, -scores))  # primary: score descending; stable: index ascending
    top = order[:k]
    return top, jnp.isfinite(scores[top])


def learnability_of(setup, traj) -> tuple[jax.Array, jax.Array]:
    """Each candidate's ``(learnability f32[B], solve rate f32[B])`` from its rollout ``traj``
    [T, B]: −inf where no episode ended or where the frozen levels explain every step."""
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
    """bool[N]: the envs an update fills from the buffer, the last round(``ratio`` · N) (the
    published code puts the fresh levels first)."""
    return jnp.arange(num_envs) >= num_envs - round(ratio * num_envs)


@dataclass(frozen=True)
class LearnabilityBuffers(Adversary):
    """SFL's adversary (module docstring). State:
    :class:`~remidi.engine.adversaries.base.AdversaryState` (``count``: updates on the active
    buffer, which times the refreshes; each buffer's ``scores`` its levels' learnability and its
    ``solve_rate`` extra their solve rate at the refresh that kept them)."""

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
        """Refresh the active buffer if due (``k_branch``), then N levels: round(ratio · N) drawn
        uniformly from its valid levels (``k_sample``), the rest ``fresh``; all fresh
        while it holds none."""
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
        frozen = self.frozen(setup, runner, None)

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

    def frozen(self, setup, runner, proposal: Proposal | None = None):
        """A sequence's tracker view of its earlier buffers; None for one buffer."""
        return sequence_frozen(setup, runner, proposal) if self.buffer_sequence else None

    def update(self, setup, runner, proposal: Proposal, outcome, rng):
        """The refreshed buffer (the proposal's) becomes the active one; nothing else is kept.
        Reports the learnability and solve rate of its levels (``sfl/buffer_learnability``,
        ``sfl/buffer_solve_rate``; NaN while empty)."""
        state, active = runner.adversary, proposal.buffer
        metrics = {"sfl/buffer_learnability": valid_mean(active.valid, active.scores),
                   "sfl/buffer_solve_rate": valid_mean(active.valid, active.extras["solve_rate"])}
        state = state.replace(buffers=buf.replace_buffer(state.buffers, state.active, active))
        return state, jnp.zeros((setup.cfg.num_envs,), bool), metrics

    def advance(self, setup, runner, proposal: Proposal, outcome):
        """Every update counts on the active buffer (whatever ``remidi.count``: each trains on
        it); a sequence moves on after ``remidi.steps_per_buffer``, its next buffer refreshed at
        its first update (count 0)."""
        state = runner.adversary.replace(count=runner.adversary.count + 1)
        if not self.buffer_sequence:
            return runner.replace(adversary=state), {}
        return sequence_advance(setup, runner, state, proposal, outcome)

    def metrics(self, setup, runner) -> dict:
        return buffer_contents(setup, runner.adversary)
