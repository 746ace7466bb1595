"""The adversary's protocol: where an update's levels come from, and what becomes of them once
scored; and DR's adversary, the protocol's default behaviour.

The train step (:mod:`remidi.engine.train`) asks the algorithm's adversary
(:attr:`~remidi.engine.algorithms.Algorithm.adversary`), never its flags:

* :meth:`Adversary.init`: its state (``Runner.adversary``; :class:`AdversaryState` or a subclass);
* :meth:`Adversary.propose`: the N levels of this update, from the fresh levels the step drew (a
  :class:`Proposal`: where they come from, whether the learner trains on them);
* :meth:`Adversary.frozen`: what the rollout's tracker compares against, a sequence's earlier
  adversaries' levels (None: nothing frozen, no tracker runs);
* :meth:`Adversary.update`: after scoring (an :class:`Outcome`): the buffer's new scores or
  insertions (a level a frozen level explains completely is never inserted);
* :meth:`Adversary.advance`: after the learner, the end of the update: a sequence's switch (its
  tracker and the policy frozen with the active adversary), ACCEL's memory of the last replay, a
  fresh generator;
* :meth:`Adversary.metrics`: what its buffers hold (tag shares, size).

Implementations, each the one before plus what it adds: :class:`RandomLevels` (DR, here);
:class:`~remidi.engine.adversaries.plr.LevelBuffers` (the PLR family and ReMiDi's sequence of
buffers); :class:`~remidi.engine.adversaries.accel.EditingBuffers` (ACCEL);
:class:`~remidi.engine.adversaries.sfl.LearnabilityBuffers` (SFL and ReMiDi over SFL); and
:class:`~remidi.engine.adversaries.paired.LevelGenerator` (PAIRED) and
:class:`~remidi.engine.adversaries.paired.GeneratorSequence` (ReMiDi over PAIRED), built on this
base directly.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
from flax import struct

from remidi.engine.adversaries import level_buffer as buf
from remidi.engine.config import buffer_config, num_buffers
from remidi.errors import ConfigError


@struct.dataclass
class AdversaryState:
    """What every adversary carries: ``buffers`` (K stacked level buffers, leaves [K, capacity,
    ...]: the PLR family's, a generator sequence's reservoirs (:func:`empty_buffers`); for DR, which
    keeps no level, one buffer without a slot, leaves [1, 0, ...], :func:`no_buffers`),
    ``active`` (i32[], the index of the buffer being filled and replayed) and ``count`` (i32[],
    updates, or replays, spent on the active one)."""

    buffers: buf.BufferState
    active: jax.Array
    count: jax.Array


@struct.dataclass
class Proposal:
    """The levels of one update and where they came from.

    levels: leaves [N, ...]; replay: bool[], replayed from the active buffer (else fresh from the
    generator, or edited), or bool[N], per env, for an adversary that mixes both in one update
    (SFL: :mod:`~remidi.engine.adversaries.sfl`; the train step's stages broadcast it, and such an
    adversary counts its own updates in :meth:`Adversary.advance`); train: bool[], the learner trains on this update's rollout; buffer: the
    active buffer as sampled (its replay counters advanced; as it was for an adversary without
    replay); slots: i32[N], the replayed levels' slots in it (None without replay); edit: bool[],
    the levels are edits of the last replay's (None for an adversary that does not edit);
    rehearse: bool[], the levels come from a frozen buffer (``remidi.rehearsal``, see
    :func:`~remidi.engine.adversaries.plr.rehearse_frozen`): trained on at every step, given to
    no buffer (None without rehearsal); nonfinite: the step metrics
    (:func:`~remidi.engine.learner.nonfinite`) of the rollouts the adversary ran to propose
    (SFL's candidates, PAIRED's generator; None without).
    """

    replay: jax.Array
    levels: object
    buffer: buf.BufferState
    slots: jax.Array | None
    train: jax.Array
    edit: jax.Array | None = None
    generated: object = None  # PAIRED: the generator's episode that built the levels
    rehearse: jax.Array | None = None
    nonfinite: dict | None = None


@struct.dataclass
class Outcome:
    """What the rollout of a proposal says of each of its N levels, for the adversary.

    collection: the rollout and its returns (:class:`~remidi.engine.learner.Collection`; its
    ``best_return`` is MaxMC's record, −inf where no episode ended); scores: f32[N], the levels'
    scores; overlap: bool[N], a new level whose rollout a frozen level explains at every step
    (never inserted)."""

    collection: object
    scores: jax.Array
    overlap: jax.Array


@dataclass(frozen=True)
class Adversary:
    """The protocol, with DR's behaviour: N fresh levels from the task's generator every update,
    all trained on, nothing kept.

    ``trains_on_fresh``: the learner trains on rollouts of fresh levels too (DR, PLR without the
    robust ⊥); False: only on replays (an adversary that replays)."""

    trains_on_fresh: bool = True

    def __post_init__(self):
        # an adversary that never replays (DR, a learned generator) trains the agent on fresh levels or never
        if not self.trains_on_fresh and not self.replays:
            raise ConfigError(f"adversary: {type(self).__name__} without trains_on_fresh would never train the agent "
                             "(it has no replay); allowed: trains_on_fresh=True")

    #: it keeps level buffers and replays from them (the PLR family)
    replays = False

    def init(self, setup, example_level, example_obs, rng) -> AdversaryState:
        """The initial state: buffers without a slot (:func:`no_buffers`: DR keeps no level; an
        adversary that keeps levels replaces them with :func:`empty_buffers`), the first one
        active; ``rng`` (the runner's key, which an adversary that needs one folds, never splits)."""
        zero = jnp.zeros((), jnp.int32)
        return AdversaryState(buffers=no_buffers(setup, example_level), active=zero, count=zero)

    def propose(self, setup, runner, fresh, k_branch, k_levels, k_sample) -> Proposal:
        """The N levels of this update: here the ``fresh`` ones (leaves [N, ...], the task
        generator's, drawn by the step with ``k_levels``)."""
        state = runner.adversary
        replay = jnp.asarray(False)
        return Proposal(replay=replay, levels=fresh, buffer=buf.select_buffer(state.buffers, state.active),
                        slots=None, train=replay | self.trains_on_fresh)

    def frozen(self, setup, runner, proposal: Proposal | None = None):
        """The rollout's :class:`~remidi.engine.trackers.base.Frozen` view (None: nothing is frozen
        and no tracker runs beside the environments)."""
        return None

    def active_levels(self, setup, runner):
        """``(levels [C, ...], valid bool[C])``: the active buffer's levels (a simulated tracker
        calibrates against them at the switch)."""
        active = buf.select_buffer(runner.adversary.buffers, runner.adversary.active)
        return active.levels, active.valid

    def own_levels(self, proposal: Proposal) -> jax.Array:
        """bool[]: this update's rollout shows the active adversary's own levels: a replay of the
        active buffer (its fresh levels are the task generator's, not the adversary's)."""
        return proposal.replay

    def best_return(self, proposal: Proposal, best_return):
        """f32[N]: MaxMC's record, the best return ever seen on each level: this rollout's
        (``best_return``: the best return of an episode that ended in it, −inf where none did)."""
        return best_return

    def update(self, setup, runner, proposal: Proposal, outcome: Outcome, rng):
        """After scoring: ``(state, inserted bool[N], step metrics)``; nothing is kept. ``rng``
        for an adversary that learns."""
        return runner.adversary, jnp.zeros((setup.cfg.num_envs,), bool), {}

    def advance(self, setup, runner, proposal: Proposal, outcome: Outcome):
        """The end of the update (``runner``: after :meth:`update` and the learner's training):
        ``(runner, step metrics)``. Counts the update on the active buffer (a replay with
        ``remidi.count=replays``)."""
        state = runner.adversary
        count = state.count + (proposal.replay.astype(jnp.int32) if setup.cfg.remidi.count == "replays" else 1)
        return runner.replace(adversary=state.replace(count=count)), {}

    def metrics(self, setup, runner) -> dict:
        """What the adversary's buffers hold: nothing without buffers."""
        return {}


@dataclass(frozen=True)
class RandomLevels(Adversary):
    """DR's adversary: the protocol's default, fresh random levels every update."""


def empty_buffers(setup, example_level) -> buf.BufferState:
    """K empty level buffers (leaves [K, capacity, ...]) of levels like ``example_level``, with
    MaxMC's ``max_return`` record: ``remidi.num_buffers`` of ``remidi.buffer_capacity`` for a
    sequence, else one of ``buffer.capacity`` (:func:`~remidi.engine.config.buffer_config`)."""
    one = buf.init_buffer(buffer_config(setup.cfg, setup.algo), example_level, extra_names=("max_return",))
    return buf.stack_buffers([one] * num_buffers(setup.cfg, setup.algo))


def no_buffers(setup, example_level) -> buf.BufferState:
    """:func:`empty_buffers` without a slot (leaves [K, 0, ...], :func:`~remidi.engine.adversaries.
    level_buffer.without_slots`): the state of an adversary that keeps no level (DR), with the
    fields of every adversary's and nothing stored (a checkpoint of DR held ``buffer.capacity``
    empty levels it never read)."""
    one = buf.init_buffer(buffer_config(setup.cfg, setup.algo), example_level, extra_names=("max_return",))
    return buf.stack_buffers([buf.without_slots(one)] * num_buffers(setup.cfg, setup.algo))


def tag_counts(setup, levels, weight) -> dict[str, jax.Array]:
    """Σ weight over the levels [N] that carry each tag."""
    tags = jax.vmap(setup.task.level_tags)(levels)
    return {name: jnp.sum(jnp.where(t, weight, 0.0)) for name, t in tags.items()}
