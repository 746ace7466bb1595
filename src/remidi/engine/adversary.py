"""Adversaries: where an update's levels come from, and what becomes of them once scored.

The train step (:mod:`remidi.engine.train`) asks the algorithm's adversary
(:attr:`~remidi.engine.algorithms.Algorithm.adversary`), never its flags:

* :meth:`RandomLevels.propose`: the N levels of this update (a :class:`Proposal`: where they come
  from, whether the learner trains on them);
* :meth:`RandomLevels.frozen`: the earlier adversaries' levels, for the distinguishability tracker
  (None: nothing is frozen);
* :meth:`RandomLevels.own_levels`: whether this update's rollout played the active adversary's
  own levels, what its learned belief model (``remidi.tracker=belief``) learns from;
* :meth:`RandomLevels.update`: after scoring: the buffer's new scores or insertions (a level a
  frozen level explains completely is never inserted), and the best-return record of MaxMC;
* :meth:`RandomLevels.advance`: after the learner: a buffer sequence's switch (freeze the active
  buffer, and under ``remidi.policy=combine`` the policy trained on it), ACCEL's memory of the last
  replay;
* :meth:`RandomLevels.metrics`: what its buffers hold (tag shares, size).

Implementations, each the one before plus what it adds:

* :class:`RandomLevels`: DR, fresh levels from the task's generator every update;
* :class:`LevelBuffers`: the PLR family: a buffer of scored levels replayed with probability
  ``buffer.replay_prob``; with ``buffer_sequence`` (ReMiDi) a sequence of ``remidi.num_buffers``
  buffers switched after ``remidi.steps_per_buffer``, the earlier ones frozen; with
  ``remidi.rehearsal`` an update may instead rehearse a frozen buffer's levels
  (:func:`rehearse_frozen`);
* :class:`EditingBuffers`: ACCEL: the update after a replay edits the replayed levels instead.

Their state lives in named :class:`~remidi.engine.train.Runner` fields (``buffers``, ``active``,
``count``, ``frozen_params``, ``edit_next``, ``last_replayed``), so checkpoints keep their paths.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
from flax import struct

from remidi.engine import belief as bl
from remidi.engine import buffer as buf
from remidi.engine import simulated as sm
from remidi.engine.config import buffer_config
from remidi.engine.rollout import Frozen
from remidi.engine.tracker import make_tracker
from remidi.errors import ConfigError


@struct.dataclass
class Proposal:
    """The levels of one update and where they came from.

    levels: leaves [N, ...]; replay: bool[], replayed from the active buffer (else fresh from the
    generator, or edited); train: bool[], the learner trains on this update's rollout; buffer: the
    active buffer as sampled (its replay counters advanced; as it was for an adversary without
    replay); slots: i32[N], the replayed levels' slots in it (None without replay); edit: bool[],
    the levels are edits of the last replay's (None for an adversary that does not edit);
    rehearse: bool[], the levels come from a frozen buffer (``remidi.rehearsal``, see
    :func:`rehearse_frozen`): trained on at every step, given to no buffer (None without rehearsal).
    """

    replay: jax.Array
    levels: object
    buffer: buf.BufferState
    slots: jax.Array | None
    train: jax.Array
    edit: jax.Array | None = None
    generated: object = None  # PAIRED: the generator's episode that built the levels
    rehearse: jax.Array | None = None

    def explained(self, indist: jax.Array) -> jax.Array:
        """bool[T, N]: the steps the learner and the buffer treat as explained by a frozen level:
        the tracker's ``indist``, none on a rehearsal (its levels are frozen levels, so the tracker
        explains every step; rehearsal trains on them exactly to keep that behaviour)."""
        return indist if self.rehearse is None else indist & ~self.rehearse


@dataclass(frozen=True)
class RandomLevels:
    """DR's adversary: N fresh levels from the task's generator every update, all trained on.

    ``trains_on_fresh`` (every implementation): the learner trains on rollouts of fresh levels
    too (DR, and PLR without the robust ⊥); False: only on replays."""

    trains_on_fresh: bool = True

    def __post_init__(self):
        # an adversary that never replays (DR, a learned generator) trains the agent on fresh levels or never
        if not self.trains_on_fresh and not isinstance(self, LevelBuffers):
            raise ConfigError(f"adversary: {type(self).__name__} without trains_on_fresh would never train the agent "
                              "(it has no replay); allowed: trains_on_fresh=True")

    def propose(self, setup, runner, k_branch, k_levels, k_sample) -> Proposal:
        new = self._fresh(setup, k_levels)
        replay = jnp.asarray(False)
        return Proposal(replay=replay, levels=new, buffer=buf.select_buffer(runner.buffers, runner.active),
                        slots=None, train=replay | self.trains_on_fresh)

    def _fresh(self, setup, k_levels):
        """N fresh levels from the task's generator."""
        return jax.vmap(setup.task.sample_level)(jax.random.split(k_levels, setup.cfg.num_envs))

    def frozen(self, setup, runner) -> Frozen | None:
        return None

    def own_levels(self, proposal: Proposal) -> jax.Array:
        """bool[]: this update's rollout shows the active adversary's own levels, what its belief
        model learns from (``remidi.tracker=belief``): a replay of the active buffer (its fresh
        levels are the task generator's, not the adversary's)."""
        return proposal.replay

    def best_return(self, proposal: Proposal, best_return):
        """f32[N]: MaxMC's record, the best return ever seen on each level: this rollout's
        (``best_return``: the best return of an episode that ended in it, −inf where none did)."""
        return best_return

    def update(self, setup, runner, proposal: Proposal, scores, overlap, best_return, mean_return, rng):
        """After scoring: ``(changed Runner fields, inserted bool[N], step metrics)``; nothing is
        kept. ``best_return``: :meth:`best_return`'s record (−inf where no episode ended);
        ``mean_return`` f32[N]: the agent's mean episodic return on each level (the partial return
        where no episode ended); ``rng`` for an adversary that learns."""
        return {}, jnp.zeros((setup.cfg.num_envs,), bool), {}

    def advance(self, setup, runner, proposal: Proposal, params) -> dict:
        """The Runner fields the adversary changes after the learner: ``active``, ``count``,
        ``frozen_params``, ``edit_next``, ``last_replayed``. Counts the update on the active buffer
        (a replay with ``remidi.count=replays``); with one buffer nothing switches."""
        cfg = setup.cfg
        count = runner.count + (proposal.replay.astype(jnp.int32) if cfg.remidi.count == "replays" else 1)
        return {"active": runner.active, "count": count, "frozen_params": runner.frozen_params,
                "edit_next": runner.edit_next, "last_replayed": runner.last_replayed}

    def memory(self, setup, example_level, example_obs, rng) -> dict:
        """Initial values of the Runner fields only this adversary uses (ACCEL's, PAIRED's);
        ``rng``: the runner's key, which an adversary that needs one folds (never splits)."""
        return {}

    def metrics(self, setup, runner) -> dict:
        """What the adversary's buffers hold: nothing without buffers."""
        return {}


@dataclass(frozen=True)
class LevelBuffers(RandomLevels):
    """The PLR family's adversary: with probability ``buffer.replay_prob``, once the active buffer
    can replay, N levels sampled from it (by score rank or top-k, mixed with staleness); else N
    fresh levels, scored and inserted by score. ``buffer_sequence`` (ReMiDi): a sequence of
    ``remidi.num_buffers`` buffers; after ``remidi.steps_per_buffer`` the active one is frozen and
    the next takes over (the last stays); the frozen ones' levels go to the tracker, and a fresh
    level a frozen one explains at every step (``overlap``) is never inserted."""

    trains_on_fresh: bool = False
    buffer_sequence: bool = False

    def propose(self, setup, runner, k_branch, k_levels, k_sample) -> Proposal:
        bcfg = buffer_config(setup.cfg, setup.algo)
        active = buf.select_buffer(runner.buffers, runner.active)
        replay = buf.can_replay(active, bcfg) & (jax.random.uniform(k_branch) < bcfg.replay_prob)
        new = self._fresh(setup, k_levels)
        sampled, slots, replayed = buf.sample_replay(active, bcfg, k_sample, setup.cfg.num_envs)
        levels = jax.tree.map(lambda r, f: jnp.where(replay, r, f), replayed, new)
        proposal = Proposal(replay=replay, levels=levels, buffer=sampled, slots=slots,
                            train=replay | self.trains_on_fresh)
        if self.buffer_sequence and setup.cfg.remidi.rehearsal > 0:
            proposal = rehearse_frozen(setup, runner, proposal, jax.random.fold_in(k_branch, 1))
        return proposal

    def frozen(self, setup, runner) -> Frozen | None:
        """A sequence's earlier buffers (:func:`earlier_buffers`); nothing for a single buffer."""
        return earlier_buffers(setup, runner) if self.buffer_sequence else None

    def best_return(self, proposal: Proposal, best_return):
        """For a replayed level, the buffer's record too."""
        record = proposal.buffer.extras["max_return"][proposal.slots]
        return jnp.where(proposal.replay, jnp.maximum(best_return, record), best_return)

    def update(self, setup, runner, proposal: Proposal, scores, overlap, best_return, mean_return, rng):
        """Replayed levels get their new ``scores`` [N]; fresh levels are inserted into the active
        buffer by score, never one whose rollout overlaps a frozen level completely (``overlap``
        bool[N]: scored −inf); a rehearsal changes no buffer."""
        n = setup.cfg.num_envs
        bcfg = buffer_config(setup.cfg, setup.algo)

        def rescore(_):
            return (buf.update_scores(proposal.buffer, proposal.slots, scores, {"max_return": best_return}),
                    jnp.zeros((n,), bool))

        def insert(_):
            active = buf.select_buffer(runner.buffers, runner.active)
            new_buf, ins, _ = buf.insert_batch(active, bcfg, proposal.levels, jnp.where(overlap, -jnp.inf, scores),
                                               {"max_return": best_return})
            return new_buf, ins

        if proposal.rehearse is None:
            new_buf, inserted = jax.lax.cond(proposal.replay, rescore, insert, None)
        else:
            def keep(_):
                return buf.select_buffer(runner.buffers, runner.active), jnp.zeros((n,), bool)

            branch = jnp.where(proposal.rehearse, 2, proposal.replay.astype(jnp.int32))
            new_buf, inserted = jax.lax.switch(branch, (insert, rescore, keep), None)
        return {"buffers": buf.replace_buffer(runner.buffers, runner.active, new_buf)}, inserted, {}

    def advance(self, setup, runner, proposal: Proposal, params) -> dict:
        """After ``remidi.steps_per_buffer`` counted updates on the active buffer of a sequence:
        freeze it (and, under ``remidi.policy=combine``, keep ``params`` as its policy) and move to
        the next, staying on the last."""
        out = super().advance(setup, runner, proposal, params)
        count = out["count"]
        switch = switches(setup, runner, count) if self.buffer_sequence else jnp.asarray(False)
        frozen_params = runner.frozen_params
        if frozen_params is not None:  # Combine: the policy trained on the buffer being frozen is kept
            frozen_params = jax.tree.map(
                lambda f, p: f.at[runner.active].set(jnp.where(switch, p, f[runner.active]), mode="drop"),
                frozen_params, params)
        return {**out, "active": jnp.where(switch, runner.active + 1, runner.active),
                "count": jnp.where(switch, 0, count), "frozen_params": frozen_params}

    def metrics(self, setup, runner) -> dict:
        return {**buffer_contents(setup, runner), **belief_contents(setup, runner)}


@dataclass(frozen=True)
class EditingBuffers(LevelBuffers):
    """ACCEL's adversary: :class:`LevelBuffers` whose update after a replay edits the levels it
    replayed (``accel.num_edits`` edits each by the task's mutator) and offers the edits to the
    buffer like fresh levels, without training on them; with ``accel.easy_start``, fresh levels
    come from the task's easy generator. With a buffer sequence, edits a frozen level explains are
    rejected like fresh levels."""

    def _fresh(self, setup, k_levels):
        generate = setup.task.easy_level if setup.cfg.accel.easy_start else setup.task.sample_level
        return jax.vmap(generate)(jax.random.split(k_levels, setup.cfg.num_envs))

    def propose(self, setup, runner, k_branch, k_levels, k_sample) -> Proposal:
        base = super().propose(setup, runner, k_branch, k_levels, k_sample)  # replayed or fresh levels
        edit = runner.edit_next
        replay = base.replay & ~edit
        edited = edit_levels(setup, runner.last_replayed, jax.random.fold_in(k_levels, 1))
        levels = jax.tree.map(lambda e, chosen: jnp.where(edit, e, chosen), edited, base.levels)
        train = replay | self.trains_on_fresh
        rehearse = base.rehearse
        if rehearse is not None:  # an edit update never rehearses (the edits of the last replay come first)
            rehearse = rehearse & ~edit
            train = train | rehearse
        return Proposal(replay=replay, levels=levels, buffer=base.buffer, slots=base.slots, train=train, edit=edit,
                        rehearse=rehearse)

    def advance(self, setup, runner, proposal: Proposal, params) -> dict:
        """After a replay the next update edits its levels."""
        out = super().advance(setup, runner, proposal, params)
        last = jax.tree.map(lambda c, o: jnp.where(proposal.replay, c, o), proposal.levels, runner.last_replayed)
        return {**out, "edit_next": proposal.replay, "last_replayed": last}

    def memory(self, setup, example_level, example_obs, rng) -> dict:
        return {"edit_next": jnp.asarray(False),
                "last_replayed": jax.tree.map(lambda x: jnp.stack([x] * setup.cfg.num_envs), example_level)}


def simulation_key(runner, purpose: int) -> jax.Array:
    """The simulated tracker's key for one of its uses in this update (19: the rollout's frozen
    copies, 23: the counted replays, 29: the calibration): from the seed's own key, so each seed
    draws its own noise. ``runner.rng``'s children in the train step are ``fold_in(rng, 0..5)``
    (``split`` with JAX's partitionable threefry), so ``purpose`` must not be below 6."""
    return jax.random.fold_in(runner.rng, purpose)


def earlier_buffers(setup, runner) -> Frozen | None:
    """The levels of every buffer of a sequence before the active one, as one batch of
    F = (K−1)·capacity with the tracker of the config (None with fewer than two buffers)."""
    if setup.cfg.remidi.num_buffers < 2:
        return None
    earlier = jax.tree.map(lambda x: x[:-1], runner.buffers)  # the last buffer is never frozen
    k = earlier.valid.shape[0]
    valid = earlier.valid & (jnp.arange(k) < runner.active)[:, None]
    flat = jax.tree.map(lambda x: x.reshape((-1,) + x.shape[2:]), earlier.levels)
    if uses_simulated(setup):  # remidi.tracker=simulated: the earlier buffers' levels, simulated with learnt noise
        return Frozen(levels=flat, valid=valid.reshape(-1), params=runner.frozen_params,
                      tracker=simulated_tracker(setup, k),
                      belief=sm.frozen_sims(runner.belief, runner.active, sm.SMOOTHING,
                                            simulation_key(runner, 19)))
    if runner.belief is not None:  # remidi.tracker=belief: the earlier buffers' learned models judge
        return Frozen(levels=flat, valid=valid.reshape(-1), params=runner.frozen_params,
                      tracker=bl.BeliefTracker(belief_model(setup)),
                      belief=bl.frozen_beliefs(runner.belief, runner.active))
    return Frozen(levels=flat, valid=valid.reshape(-1), params=runner.frozen_params,
                  tracker=make_tracker(setup.cfg.remidi.tracker, tracker_budget(setup)))


def rehearse_frozen(setup, runner, proposal: Proposal, rng) -> Proposal:
    """``remidi.rehearsal``: with that probability, once an earlier buffer of the sequence holds
    levels, ``proposal`` gives way to a rehearsal: N levels drawn uniformly (with replacement) from
    the valid levels of one of the non-empty earlier buffers, chosen uniformly. A rehearsal trains
    on every step (:meth:`Proposal.explained`), is no replay of the active buffer (``replay``
    False: nothing is rescored, inserted or sampled, and ``remidi.count=replays`` does not count
    it), and reads the frozen buffers without changing them (no clock tick, no ``last_seen``).

    Uniform, not by the frozen buffer's replay distribution: its scores stopped being updated when
    it was frozen, and rehearsal is meant to keep the behaviour on the whole of an earlier
    adversary's support, not on the levels that had the most regret then."""
    n = setup.cfg.num_envs
    k_draw, k_buffer, k_slots = jax.random.split(rng, 3)
    valid = runner.buffers.valid  # bool[K, C]
    k, capacity = valid.shape
    eligible = (jnp.arange(k) < runner.active) & jnp.any(valid, axis=1)  # frozen and not empty
    rehearse = jnp.any(eligible) & (jax.random.uniform(k_draw) < setup.cfg.remidi.rehearsal)
    which = jax.random.choice(k_buffer, k, p=jnp.where(jnp.any(eligible), eligible / jnp.maximum(jnp.sum(eligible), 1),
                                                         1.0 / k))
    chosen = valid[which]
    slots = jax.random.choice(k_slots, capacity, (n,), replace=True,
                              p=jnp.where(jnp.any(chosen), chosen / jnp.maximum(jnp.sum(chosen), 1), 1.0 / capacity))
    frozen = buf.get_levels(buf.select_buffer(runner.buffers, which), slots)
    levels = jax.tree.map(lambda f, o: jnp.where(rehearse, f, o), frozen, proposal.levels)
    return proposal.replace(levels=levels, replay=proposal.replay & ~rehearse, train=proposal.train | rehearse,
                            rehearse=rehearse)


def uses_belief(setup) -> bool:
    """The run judges distinguishability by learned models (``remidi.tracker=belief`` or
    ``simulated``): a sequence of at least two buffers or generators."""
    r = setup.cfg.remidi
    return setup.algo.buffer_sequence and r.tracker in ("belief", "simulated") and r.num_buffers >= 2


def uses_simulated(setup) -> bool:
    """The run judges by the simulated belief model (``remidi.tracker=simulated``, engine/simulated.py)."""
    return uses_belief(setup) and setup.cfg.remidi.tracker == "simulated"


def simulated_tracker(setup, num_buffers: int) -> sm.SimulatedTracker:
    """The simulated tracker over ``num_buffers`` frozen buffers (the earlier buffers; one to calibrate)."""
    r = setup.cfg.remidi
    model = belief_model(setup)
    return sm.SimulatedTracker(model.coding, model, num_buffers,
                               budget=min(r.tracker_budget, num_buffers * r.buffer_capacity),
                               reseed=setup.task.reseed_level)


@functools.lru_cache(maxsize=None)
def _belief_model(task, hidden: int) -> bl.BeliefModel:
    from remidi.engine.train import example_observation

    obs = jax.eval_shape(lambda: example_observation(task)[0])
    return bl.BeliefModel(bl.coding_for(obs), num_actions=task.num_actions, hidden=hidden)


def belief_model(setup) -> bl.BeliefModel:
    """The belief model of the run's task (its observations' coding, its actions) and config."""
    return _belief_model(setup.task, setup.cfg.remidi.belief_hidden)


def belief_optimizer(setup):
    """The belief models' optimiser (``remidi.belief_lr``)."""
    return bl.make_optimizer(setup.cfg.remidi.belief_lr)


def belief_memory(setup, rng):
    """The initial :class:`~remidi.engine.belief.BeliefMemory` of a run that uses one (else None);
    ``rng``: the runner's key, folded."""
    if not uses_belief(setup):
        return None
    cfg = setup.cfg
    if uses_simulated(setup):
        model = belief_model(setup)
        level = jax.eval_shape(setup.task.sample_level, jax.random.PRNGKey(0))
        return sm.init_memory(model.coding, model, belief_optimizer(setup), cfg.remidi.num_buffers,
                              cfg.remidi.belief_calibration, cfg.num_steps, cfg.num_envs, jax.random.fold_in(rng, 31),
                              level, max_length=setup.task.max_episode_steps, reference=cfg.remidi.belief_reference)
    return bl.init_memory(belief_model(setup), belief_optimizer(setup), cfg.remidi.num_buffers,
                          cfg.remidi.belief_calibration, cfg.num_steps, cfg.num_envs, jax.random.fold_in(rng, 31),
                          max_length=setup.task.max_episode_steps, reference=cfg.remidi.belief_reference)


def belief_learns(setup, runner, proposal: Proposal, traj) -> tuple[dict, dict]:
    """The active adversary's model learns from a rollout of its own levels (the adversary's
    :meth:`~RandomLevels.own_levels`: a replay of the active buffer, every update of a generator;
    :func:`~remidi.engine.belief.learn`). Returns ``(changed Runner fields, step metrics)``:
    nothing without a belief tracker."""
    if runner.belief is None:
        return {}, {}
    fresh = ~proposal.replay  # the task generator's levels: no replay, no edit, no rehearsal
    for other in (proposal.edit, proposal.rehearse):
        fresh = fresh if other is None else fresh & ~other
    if uses_simulated(setup):
        model = belief_model(setup)
        memory = sm.learn(runner.belief, setup.task.env, setup.task.params, model.coding, setup.task.reseed_level, model,
                          belief_optimizer(setup), proposal.levels, traj, setup.algo.adversary.own_levels(proposal),
                          fresh, setup.cfg.remidi.belief_epochs, simulation_key(runner, 23))
        return {"belief": memory}, {}
    memory, loss = bl.learn(belief_model(setup), belief_optimizer(setup), runner.belief, runner.active, traj,
                            setup.algo.adversary.own_levels(proposal), setup.cfg.remidi.belief_epochs, fresh=fresh)
    return {"belief": memory}, {"belief/loss": loss}


def belief_freezes(setup, runner, switch) -> dict:
    """At a switch of a sequence (``switch`` bool[]: the adversary's ``advance`` moved ``active``
    on) the active adversary's model is frozen with it (:func:`~remidi.engine.belief.freeze`):
    the changed Runner field, nothing without a belief tracker. Called once, by the train step,
    for every adversary."""
    if runner.belief is None:
        return {}
    if uses_simulated(setup):
        active = buf.select_buffer(runner.buffers, runner.active)
        r = setup.cfg.remidi
        return {"belief": sm.freeze(simulated_tracker(setup, 1), runner.belief, setup.task.env, setup.task.params,
                                    active.levels, active.valid, runner.active, switch, r.belief_false_rate,
                                    r.belief_margin, sm.SMOOTHING, simulation_key(runner, 29))}
    return {"belief": bl.freeze(belief_optimizer(setup), runner.belief, runner.active, switch,
                                setup.cfg.remidi.belief_false_rate, setup.cfg.remidi.belief_margin, belief_model(setup))}


def belief_contents(setup, runner) -> dict:
    """``remidi.tracker=belief`` or ``simulated``: ``belief/threshold`` and ``belief/threshold/long`` (the last
    frozen model's thresholds for one-step prefixes and for the longest prefix-length bucket, which
    holds the longest bucket's with enough held-out prefixes, :func:`~remidi.engine.belief.calibrate_by_length`; NaN
    before the first switch), ``belief/heldout_score`` (the active model's mean held-out prefix
    score since the switch) and ``belief/uniform_score`` (a model that knows nothing: a frozen
    model whose scores sit near it explains almost anything; these two for ``belief`` only), all
    in nats per step."""
    if runner.belief is None:
        return {}
    memory = runner.belief
    last = memory.threshold[jnp.maximum(runner.active - 1, 0)]  # f32[L]
    frozen = runner.active > 0
    out = {"belief/threshold": jnp.where(frozen, last[0], jnp.nan),
           "belief/threshold/long": jnp.where(frozen, last[-1], jnp.nan)}
    if uses_simulated(setup):  # no model of the buffer's own: its scores are the mixture's
        return out
    return {**out, "belief/heldout_score": bl.heldout_score(memory),
            "belief/uniform_score": jnp.float32(bl.uniform_score(belief_model(setup)))}


def buffer_contents(setup, runner) -> dict:
    """Share of each tag among the valid levels of every buffer (``buffer_fraction/<tag>/b<k>``)
    and of the active one (``buffer_fraction/<tag>``); the active buffer's size."""
    out = {}
    valid = runner.buffers.valid  # bool[K, C]
    sizes = jnp.maximum(jnp.sum(valid, axis=1), 1)  # [K]
    counts = jax.vmap(lambda levels, v: tag_counts(setup, levels, v.astype(jnp.float32)))(runner.buffers.levels, valid)
    for name, c in counts.items():  # c: f32[K]
        fractions = c / sizes
        for b in range(valid.shape[0]):
            out[f"buffer_fraction/{name}/b{b}"] = fractions[b]
        out[f"buffer_fraction/{name}"] = fractions[runner.active]
    out["buffer_size"] = jnp.sum(valid[runner.active]).astype(jnp.float32)
    return out


def switches(setup, runner, count) -> jax.Array:
    """bool[]: a sequence moves to its next buffer (or generator): ``count`` (this update's count on
    the active one) reached ``remidi.steps_per_buffer`` and the active one is not the last."""
    k = runner.buffers.valid.shape[0]
    return (count >= setup.cfg.remidi.steps_per_buffer) & (runner.active + 1 < k)


def tracker_budget(setup, mode: str | None = None) -> int:
    """Slots per env of the candidate tracker, or 0 for the reference tracker (see ReMiDiConfig),
    for the exact tracker of ``mode`` (default: ``remidi.tracker``)."""
    r = setup.cfg.remidi
    if (mode or r.tracker) != "prefix" or not setup.task.deterministic_reset:
        return 0
    return min(r.tracker_budget, (r.num_buffers - 1) * r.buffer_capacity)


def tag_counts(setup, levels, weight) -> dict[str, jax.Array]:
    """Σ weight over the levels [N] that carry each tag."""
    tags = jax.vmap(setup.task.level_tags)(levels)
    return {name: jnp.sum(jnp.where(t, weight, 0.0)) for name, t in tags.items()}


def edit_levels(setup, levels, rng):
    """ACCEL's edits: ``accel.num_edits`` edits of each of ``levels`` [N] by the task's mutator."""
    n = jax.tree.leaves(levels)[0].shape[0]
    edits = setup.cfg.accel.num_edits
    return jax.vmap(lambda key, level: setup.task.mutate_level(key, level, edits))(jax.random.split(rng, n), levels)
