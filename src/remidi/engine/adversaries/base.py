"""The adversary protocol (where an update's levels come from, what becomes of them) and DR's adversary.

The train step asks the algorithm's adversary, never its flags:

* :meth:`Adversary.init`: its state (``Runner.adversary``);
* :meth:`Adversary.propose`: this update's N levels (a :class:`Proposal`);
* :meth:`Adversary.update`: after scoring (an :class:`Outcome`): new scores or insertions;
* :meth:`Adversary.advance`: the end of the update (a sequence's switch, ACCEL's memory);
* :meth:`Adversary.metrics`: what its buffers hold.

Implementations: :class:`RandomLevels` (DR), :class:`~remidi.engine.adversaries.plr.LevelBuffers`
(PLR family), ACCEL's and SFL's built on it, and PAIRED's
:class:`~remidi.engine.adversaries.paired.LevelGenerator`."""

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
    """What every adversary carries.

    ``buffers``: K stacked level buffers, leaves [K, capacity, ...] (:func:`empty_buffers`; DR's
    have no slot, [1, 0, ...], :func:`no_buffers`); ``active`` i32[]: the buffer being filled and
    replayed; ``count`` i32[]: updates (or replays) spent on it."""

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
    """The protocol, with DR's behaviour: N fresh levels every update, all trained on, none kept.

    ``trains_on_fresh``: the learner trains on fresh levels too; False: only on replays."""

    trains_on_fresh: bool = True

    def __post_init__(self):
        # an adversary that never replays (DR, a learned generator) trains the agent on fresh levels or never
        if not self.trains_on_fresh and not self.replays:
            raise ConfigError(f"adversary: {type(self).__name__} without trains_on_fresh would never train the agent "
                             "(it has no replay); allowed: trains_on_fresh=True")

    #: it keeps level buffers and replays from them (the PLR family)
    replays = False

    def init(self, setup, example_level, example_obs, rng) -> AdversaryState:
        """The initial state: slotless buffers (an adversary that keeps levels uses :func:`empty_buffers`).

        ``rng``: the runner's key; an adversary that needs one folds it, never splits."""
        zero = jnp.zeros((), jnp.int32)
        return AdversaryState(buffers=no_buffers(setup, example_level), active=zero, count=zero)

    def propose(self, setup, runner, fresh, k_branch, k_levels, k_sample) -> Proposal:
        """This update's N levels: here the ``fresh`` ones (leaves [N, ...], drawn by the step with ``k_levels``)."""
        state = runner.adversary
        replay = jnp.asarray(False)
        return Proposal(replay=replay, levels=fresh, buffer=buf.select_buffer(state.buffers, state.active),
                        slots=None, train=replay | self.trains_on_fresh)

    def active_levels(self, setup, runner):
        """``(levels [C, ...], valid bool[C])``: the active buffer's (a simulated tracker calibrates on them)."""
        active = buf.select_buffer(runner.adversary.buffers, runner.adversary.active)
        return active.levels, active.valid

    def own_levels(self, proposal: Proposal) -> jax.Array:
        """bool[]: this rollout shows the active adversary's own levels (here: a replay)."""
        return proposal.replay

    def best_return(self, proposal: Proposal, best_return):
        """f32[N]: MaxMC's record per level; here this rollout's ``best_return`` (−inf where none ended)."""
        return best_return

    def update(self, setup, runner, proposal: Proposal, outcome: Outcome, rng):
        """``(state, inserted bool[N], step metrics)`` after scoring; here nothing is kept."""
        return runner.adversary, jnp.zeros((setup.cfg.num_envs,), bool), {}

    def advance(self, setup, runner, proposal: Proposal, outcome: Outcome):
        """``(runner, step metrics)`` at the end of the update: counts it on the active buffer.

        With ``remidi.count=replays`` only replays count."""
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
    """K empty buffers (leaves [K, capacity, ...]) with MaxMC's ``max_return`` extra.

    K, capacity: ``remidi.num_buffers``, ``remidi.buffer_capacity`` for a sequence, else 1,
    ``buffer.capacity`` (:func:`~remidi.engine.config.buffer_config`)."""
    one = buf.init_buffer(buffer_config(setup.cfg, setup.algo), example_level, extra_names=("max_return",))
    return buf.stack_buffers([one] * num_buffers(setup.cfg, setup.algo))


def no_buffers(setup, example_level) -> buf.BufferState:
    """:func:`empty_buffers` without slots (leaves [K, 0, ...]): an adversary that keeps no level (DR)."""
    one = buf.init_buffer(buffer_config(setup.cfg, setup.algo), example_level, extra_names=("max_return",))
    return buf.stack_buffers([buf.without_slots(one)] * num_buffers(setup.cfg, setup.algo))


def tag_counts(setup, levels, weight) -> dict[str, jax.Array]:
    """Σ weight over the levels [N] that carry each tag."""
    tags = jax.vmap(setup.task.level_tags)(levels)
    return {name: jnp.sum(jnp.where(t, weight, 0.0)) for name, t in tags.items()}
