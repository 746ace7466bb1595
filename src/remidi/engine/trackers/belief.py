"""The belief tracker (``remidi.tracker=belief``): a learned model P(h | Λᵢ) per adversary judges
whether a prefix could have come from an earlier adversary, for envs whose observations are
random given the level (the paper's appendix).

Each adversary's model (:mod:`remidi.engine.trackers.belief_model`) learns from rollouts of its
own levels and is frozen with it; its thresholds are calibrated at the freeze on held-out prefix
scores of its last ``remidi.belief_calibration`` rollouts. A prefix is explained when some valid
frozen model scores it, and every shorter prefix, at or above its length's threshold.

Shapes: T steps, N envs, E entries, H hidden units, B frozen models, K adversaries, R recorded
rollouts, L length buckets."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from remidi.engine.core.seeds import cond_per_seed
from remidi.engine.trackers.audit import audit_against_exact, threshold_metrics
from remidi.engine.trackers.base import Frozen, Tracker, fresh_levels
from remidi.engine.trackers.belief_model import (BeliefModel, coded_logliks, earlier_references, fit_reference,
                                                 fit_steps, freeze_reference, frozen_logliks, frozen_step,
                                                 LearnedSettings, init_reference, prefix_lengths, prefix_scores,
                                                 step_logliks)
from remidi.engine.trackers.calibration import calibrate_monotone, length_bucket, num_length_buckets


# ---------------------------------------------------------------------------- the tracker
@struct.dataclass
class FrozenBeliefs:
    """The frozen adversaries' models: ``params`` leaves [B, ...], ``threshold`` f32[B, L] (per length
    bucket) or f32[B], ``valid`` bool[B] (frozen)."""

    params: Any
    threshold: jax.Array
    valid: jax.Array
    ref: Any = None  # remidi.belief_reference: the generator's reference model frozen with each, leaves [B, ...]


@struct.dataclass
class BeliefState:
    """One env's tracker state (leaves [N, ...] in the component) over B frozen models."""

    hidden: jax.Array  # f32[B, H]: each model's state before the current observation
    total: jax.Array  # f32[B]: the episode's summed log-likelihood so far under each model
    count: jax.Array  # i32[]: the episode's steps so far
    last: jax.Array  # i32[E]: the current observation's categories (the next step's input)
    match: jax.Array  # bool[B]: model b explains the prefix (it and every shorter one reach their thresholds)
    ref_hidden: Any = None  # f32[B, H]: with a reference, its frozen copies' states ...
    ref_total: Any = None  # f32[B]: ... and summed log-likelihoods (the score is the difference)


@dataclass(frozen=True)
class BeliefTracker(Tracker):
    """Judges distinguishability by the frozen belief models in ``frozen.belief``; frozen levels are not stepped.

    Model b explains env n's prefix when the mean per-step log-likelihood under b of it and every
    shorter prefix of the episode reaches b's threshold for its length (monotone, as realisability
    is). Settings: the ``remidi.belief_*`` keys (:class:`LearnedSettings`)."""

    model: BeliefModel
    settings: LearnedSettings = LearnedSettings()

    learns = True

    @property
    def optimizer(self):
        return self.settings.optimizer

    # -- per update
    def init(self, setup, rng) -> BeliefMemory:
        """Fresh models for the ``remidi.num_buffers`` adversaries (from ``fold_in(rng, 31)``)."""
        cfg = setup.cfg
        return init_memory(self.model, self.optimizer, cfg.remidi.num_buffers, self.settings.calibration,
                           (cfg.num_steps, cfg.num_envs), jax.random.fold_in(rng, 31),
                           max_length=setup.task.max_episode_steps, reference=self.settings.reference)

    def frozen(self, setup, runner, proposal=None) -> Frozen | None:
        """The earlier adversaries' learned models judge (their levels kept for the audit)."""
        view = super().frozen(setup, runner, proposal)
        if view is None:
            return None
        return view.replace(belief=frozen_beliefs(runner.tracker, runner.adversary.active))

    def learn(self, setup, runner, proposal, traj):
        """The active adversary's model learns from a rollout of its own levels."""
        memory, loss = learn(self.model, self.optimizer, runner.tracker, runner.adversary.active, traj,
                             setup.algo.adversary.own_levels(proposal), self.settings.epochs, fresh=fresh_levels(proposal))
        return memory, {"belief/loss": loss}

    def freeze(self, setup, runner, switch):
        """At a switch the active model is frozen and calibrated."""
        return freeze(self.optimizer, runner.tracker, runner.adversary.active, switch, self.settings.false_rate,
                      self.settings.margin, self.model, self.settings.spread)

    def metrics(self, setup, runner) -> dict:
        """:func:`~remidi.engine.trackers.audit.threshold_metrics`, ``belief/heldout_score`` and
        ``belief/uniform_score`` (a model that knows nothing: scores near it explain almost anything),
        nats per step."""
        return {**threshold_metrics(runner.tracker.threshold, runner.adversary.active),
                "belief/heldout_score": heldout_score(runner.tracker),
                "belief/uniform_score": jnp.float32(uniform_score(self.model))}

    def audit(self, setup, runner, rng) -> dict:
        return audit_against_exact(self, setup, runner, rng)

    # -- per rollout step

    def _judge(self, frozen, total, count, ref_total=None) -> jax.Array:
        """bool[N, B]: the env's prefix score reaches each valid frozen model's threshold (with a
        reference: the log-likelihood ratio over it)."""
        b = frozen.belief
        score = (total if ref_total is None else total - ref_total) / jnp.maximum(count, 1)[:, None]
        if b.threshold.ndim == 1:
            tau = b.threshold[None, :]
        else:  # each env's threshold for its prefix's length: [N, B]
            tau = b.threshold[:, length_bucket(count, b.threshold.shape[1])].T
        return b.valid[None, :] & (score >= tau)

    def start(self, env, params, frozen, reset_keys, obs, starts=None) -> BeliefState:
        """The state at the envs' first observations ``obs`` (leaves [N, ...])."""
        n = reset_keys.shape[0]
        cats = self.model.coding.encode(obs)  # [N, E]
        hidden = self.model.initial_hidden((n, frozen.belief.threshold.shape[0]))
        total, count = frozen_logliks(self.model, frozen.belief.params, hidden, cats), jnp.ones((n,), jnp.int32)
        ref_hidden = ref_total = None
        if frozen.belief.ref is not None:
            ref_hidden, ref_total = hidden, frozen_logliks(self.model, frozen.belief.ref, hidden, cats)
        return BeliefState(hidden=hidden, total=total, count=count, last=cats,
                           match=self._judge(frozen, total, count, ref_total), ref_hidden=ref_hidden,
                           ref_total=ref_total)

    def indistinguishable(self, state: BeliefState) -> jax.Array:
        """bool[N]: some frozen model explains each env's prefix."""
        return jnp.any(state.match, axis=-1)

    def observe(self, env, params, frozen, env_keys, state: BeliefState, action, next_obs, done) -> BeliefState:
        """After ``action`` i32[N]; ``next_obs`` is the next episode's first where ``done`` bool[N]."""
        cats = self.model.coding.encode(next_obs)  # [N, E]
        hidden, total = frozen_step(self.model, frozen.belief.params, state.hidden, state.total, state.last, action,
                                    cats, done)
        ref_hidden = ref_total = None
        if frozen.belief.ref is not None:
            ref_hidden, ref_total = frozen_step(self.model, frozen.belief.ref, state.ref_hidden, state.ref_total,
                                                state.last, action, cats, done)
        count = jnp.where(done, 0, state.count) + 1
        fresh = self._judge(frozen, total, count, ref_total)
        return BeliefState(hidden=hidden, total=total, count=count, last=cats,
                           match=jnp.where(done[:, None], fresh, state.match & fresh), ref_hidden=ref_hidden,
                           ref_total=ref_total)

    def overflow(self, state: BeliefState) -> jax.Array:
        return jnp.zeros(state.count.shape, jnp.int32)


# ---------------------------------------------------------------------------- in a run
@struct.dataclass
class BeliefMemory:
    """A belief run's ``Runner.tracker``: one model per adversary, trained while active, then frozen.

    ``params`` leaves [K, ...]; ``opt_state``: the active model's (restarted at each switch);
    ``threshold`` f32[K, L] (+inf until calibrated); ``scores`` f32[R, T, N], ``lengths``
    i32[R, T, N]: prefix scores of the active adversary's last R own rollouts, each under the model
    before it fit that rollout (held out); ``written`` i32[]: rows recorded since the switch (next:
    ``written mod R``); ``fits`` i32[]: rollouts learnt from since the switch. The first rollout is
    not recorded: the untrained model scores near uniform and would let every prefix through."""

    params: Any
    opt_state: Any
    threshold: jax.Array
    scores: jax.Array
    lengths: jax.Array
    written: jax.Array
    fits: jax.Array
    # remidi.belief_reference: a model of the task generator's trajectories (the rollouts of fresh
    # levels), ``ref`` (learning all run, ``ref_opt`` its optimiser state), copied into
    # ``ref_frozen`` [K, ...] when adversary k is frozen; scores are then log-likelihood ratios
    ref: Any = None
    ref_opt: Any = None
    ref_frozen: Any = None
    # ... and the recorded rollouts themselves (coded observations i8[R, T, N, E], actions i32[R, T, N(, k)],
    # resets bool[R, T, N]), so that at the freeze the reference's part of each recorded ratio is
    # computed by the frozen reference, the one that will judge (``scores`` then holds the model's part)
    codes: Any = None
    actions: Any = None
    resets: Any = None


def init_memory(model: BeliefModel, optimizer, num_buffers: int, rows: int, batch: tuple[int, int], rng,
                max_length: int | None = None, reference: bool = False) -> BeliefMemory:
    """Fresh models for ``num_buffers`` adversaries and an empty record of ``rows`` × ``batch`` (T, N).

    Prefix lengths of at most ``min(T, max_length)`` set the number of length buckets."""
    num_steps = batch[0]
    params = jax.vmap(model.init)(jax.random.split(rng, num_buffers))
    first = jax.tree.map(lambda x: x[0], params)
    ref = ref_opt = ref_frozen = codes = actions = resets = None
    if reference:
        ref, ref_opt, ref_frozen = init_reference(model, optimizer, num_buffers, rng)
        codes = jnp.zeros((rows,) + batch + (model.coding.num_entries,), jnp.int8)
        actions = jnp.zeros((rows,) + batch + model.action_shape, jnp.int32)
        resets = jnp.ones((rows,) + batch, bool)
    return BeliefMemory(ref=ref, ref_opt=ref_opt, ref_frozen=ref_frozen, codes=codes, actions=actions, resets=resets,
                        params=params, opt_state=optimizer.init(first),
                        threshold=jnp.full((num_buffers, num_length_buckets(min(num_steps, max_length or num_steps))),
                                           jnp.inf, jnp.float32),  # strongly typed, as a checkpoint restores it
                        scores=jnp.zeros((rows,) + batch), lengths=jnp.ones((rows,) + batch, jnp.int32),
                        written=jnp.zeros((), jnp.int32), fits=jnp.zeros((), jnp.int32))


def frozen_beliefs(memory: BeliefMemory, active) -> FrozenBeliefs:
    """The models of the buffers before ``active`` (B = K − 1: the last is never frozen)."""
    k = memory.threshold.shape[0]
    return FrozenBeliefs(params=jax.tree.map(lambda x: x[:-1], memory.params), threshold=memory.threshold[:-1],
                         valid=jnp.arange(k - 1) < active, ref=earlier_references(memory))


def learn(model: BeliefModel, optimizer, memory: BeliefMemory, active, traj, trained,
          epochs: int = 1, fresh=None) -> tuple[BeliefMemory, jax.Array]:
    """The active adversary's model learns from a rollout of its levels (``trained`` bool[]: the
    rollout played the adversary's own levels, a replay of its buffer or a generator's levels;
    otherwise nothing changes): record the rollout's prefix scores under the model before the
    update (held out; not for the model's first rollout since the switch, whose scores are the
    untrained model's), then ``epochs`` :func:`fit_step` on all
    its steps. ``traj``: a :class:`~remidi.engine.learner.Trajectory` (leaves [T, N, ...]). Returns
    ``(memory, loss f32[]: the first epoch's, NaN when not trained)``.

    ``trained``: the rollout played the adversary's own levels. First the rollout's held-out scores
    are recorded (not for the first fit since the switch), then ``epochs`` fit steps; loss is the
    first epoch's, NaN when not trained. With a reference the rollout is recorded too, and the
    reference learns from the generator's ``fresh`` (bool[]) levels."""

    def fit(m: BeliefMemory):
        params = jax.tree.map(lambda x: x[active], m.params)
        ll = step_logliks(model, params, traj.obs, traj.action, traj.reset)
        scores = prefix_scores(ll, traj.reset)  # [T, N]
        rows = m.scores.shape[0]

        params, opt_state, losses = fit_steps(model, optimizer, params, m.opt_state, traj.obs, traj.action,
                                              traj.reset, epochs)
        loss = losses[0]
        record = m.fits > 0
        row = jnp.where(record, m.written % rows, rows)  # rows: out of bounds, dropped
        lengths = prefix_lengths(traj.reset)
        if m.ref is not None:
            m = m.replace(codes=m.codes.at[row].set(model.coding.encode(traj.obs).astype(jnp.int8), mode="drop"),
                          actions=m.actions.at[row].set(traj.action, mode="drop"),
                          resets=m.resets.at[row].set(traj.reset, mode="drop"))
        return m.replace(params=jax.tree.map(lambda all_, p: all_.at[active].set(p), m.params, params),
                         opt_state=opt_state, scores=m.scores.at[row].set(scores, mode="drop"),
                         lengths=m.lengths.at[row].set(lengths, mode="drop"),
                         written=m.written + record.astype(jnp.int32), fits=m.fits + 1), loss

    memory, loss = cond_per_seed(trained, fit, lambda m: (m, jnp.float32(jnp.nan)), memory)
    if memory.ref is None:
        return memory, loss

    return fit_reference(model, optimizer, memory, traj, epochs, fresh), loss


def heldout_score(memory: BeliefMemory) -> jax.Array:
    """f32[]: mean recorded held-out score of the active model (its own log-likelihood, the threshold's
    units); NaN until one is recorded."""
    rows = memory.scores.shape[0]
    recorded = (jnp.arange(rows) < memory.written)[:, None, None]
    per_row = memory.scores[0].size
    total = jnp.sum(jnp.where(recorded, memory.scores, 0.0))
    return total / jnp.where(memory.written > 0, jnp.minimum(memory.written, rows) * per_row, jnp.nan)


def uniform_score(model: BeliefModel) -> float:
    """Per-step log-likelihood of a model uniform over every entry's categories (first step, as
    ``belief/threshold``): held-out scores near it mean the threshold lets nearly everything through."""
    c = model.coding
    return -sum(size * math.log(k) for size, k in zip(c.sizes, c.categories))


def freeze(optimizer, memory: BeliefMemory, active, switch, false_rate: float, margin: float = 1e-3,
           model: BeliefModel | None = None, spread: float = 0.0) -> BeliefMemory:
    """At a switch (``switch`` bool[]): calibrate the active model's thresholds, empty the record,
    restart the optimiser.

    Thresholds: :func:`calibrate_monotone` (each at most its ``spread`` fence) lowered by ``margin``
    nats; +inf (explaining nothing) if nothing was recorded. With a reference (``model`` needed) the
    recorded scores become ratios over the frozen reference, computed now."""

    def switched(m: BeliefMemory) -> BeliefMemory:
        rows, k = m.scores.shape[0], m.threshold.shape[0]
        valid = jnp.broadcast_to((jnp.arange(rows) < m.written)[:, None, None], m.scores.shape)
        scores = m.scores
        if m.ref is not None:
            ref_ll = jax.vmap(lambda c, a, r: coded_logliks(model, m.ref, c, a, r))(m.codes, m.actions, m.resets)
            scores = scores - jax.vmap(prefix_scores)(ref_ll, m.resets)
        tau = calibrate_monotone(scores, m.lengths, false_rate, m.threshold.shape[1], valid, margin=margin,
                                 spread=spread)
        tau = jnp.where(m.written > 0, tau, jnp.inf)
        nxt = jax.tree.map(lambda x: x[jnp.minimum(active + 1, k - 1)], m.params)
        return m.replace(threshold=m.threshold.at[active].set(tau), opt_state=optimizer.init(nxt),
                         written=jnp.zeros((), jnp.int32), fits=jnp.zeros((), jnp.int32),
                         ref_frozen=freeze_reference(m, active))

    return cond_per_seed(switch, switched, lambda m: m, memory)
