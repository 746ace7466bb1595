"""The simulated tracker (``remidi.tracker=simulated``): frozen levels simulated under fresh
randomness, judged with a learnt noise model.

With randomness in what the agent sees no frozen level reproduces its observations exactly, and
the belief model cannot say "one of *these* levels". This keeps the exact tracker's
level-conditioning and learns only the noise:

    P(h | θ) = Π_t Π_e q(o_e,t | d_t, ô¹_e,t, ô²_e,t),     P(h | Λ) = mean over θ ∈ Λ of P(h | θ)

ô¹, ô²: θ stepped with the agent's actions under two fresh draws of its randomness
(``UEDTask.reseed_level``; none: both are θ); ``d_t``: the two copies agree entirely; ``q``: the
table of :mod:`remidi.engine.trackers.noise`. A last entry (K = 2) is the episode's end. In a
deterministic env ``q`` learns the identity and this *is* the exact tracker. Judged alone or as
a ratio over a model of the generator's trajectories (needed on a noisy TV).

:class:`SimulatedTracker`: the rollout's component; :class:`Simulated`: the run's tracker, keeping
the table, reference and calibration record (:class:`SimMemory`). Shapes: E + 1 entries, K
categories, F frozen levels, S slots per env (two copies each)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import jax
import jax.numpy as jnp
from flax import struct

from remidi.engine.core.seeds import cond_per_seed
from remidi.engine.trackers.audit import audit_against_exact, threshold_metrics
from remidi.engine.trackers.base import Frozen, Tracker, fresh_levels
from remidi.engine.trackers.belief_model import (BeliefModel, ObsCoding, earlier_references, fit_reference,
                                                 freeze_reference, frozen_logliks, frozen_step, init_reference,
                                                 LearnedSettings, prefix_lengths)
from remidi.engine.trackers.calibration import calibrate_monotone, length_bucket, num_length_buckets
from remidi.engine.trackers.noise import (SMOOTHING, candidates, count_rollout, init_counts, log_q, mixture,
                                          recorded_codes, step_logq, with_end)
from remidi.envs.interface import tree_equal


# ---------------------------------------------------------------------------- the tracker
@struct.dataclass
class FrozenSims:
    """What the tracker reads from ``Frozen.belief``.

    ``logq`` (the table's :func:`log_q`), ``threshold`` f32[B, L], ``valid`` bool[B] (frozen),
    ``ref`` (leaves [B, ...], the ratio's denominator; None: mixture alone), ``key`` (the copies'
    randomness in this rollout)."""

    logq: jax.Array
    threshold: jax.Array
    valid: jax.Array
    key: jax.Array
    ref: Any = None


@struct.dataclass
class SimState:
    """One env's tracker state (leaves [N, ...] in the component).

    ``index`` i32[S] (−1 empty), the slots' copies' states (leaves [S, 2, ...]) and first states,
    ``total`` f32[S] (log P(prefix | level)) and ``start_total``, ``count`` i32[], the reference's
    state f32[B, H] and total f32[B], ``last`` i32[E + 1] (its input), ``match`` bool[B]."""

    index: jax.Array
    copies: Any
    start_copies: Any
    total: jax.Array
    start_total: jax.Array
    count: jax.Array
    match: jax.Array
    last: jax.Array
    ref_hidden: Any = None
    ref_total: Any = None


@dataclass(frozen=True)
class SimulatedTracker(Tracker):
    """The simulated model as a rollout component over N envs (``frozen.belief``: :class:`FrozenSims`).

    ``budget`` slots per env, each one frozen level in two copies; ``reseed`` (static, or None)
    draws a copy's randomness; ``ref_model``: the reference's GRU. The reset must ignore its key."""

    coding: ObsCoding
    ref_model: BeliefModel
    num_buffers: int
    budget: int = 64
    reseed: Callable | None = None

    def __hash__(self):
        return hash((self.coding, self.ref_model, self.num_buffers, self.budget, id(self.reseed)))

    def __eq__(self, other):
        return (isinstance(other, SimulatedTracker) and (self.coding, self.ref_model, self.num_buffers, self.budget)
                == (other.coding, other.ref_model, other.num_buffers, other.budget) and self.reseed is other.reseed)

    # -- scoring
    def scores(self, frozen, state: SimState) -> jax.Array:
        """f32[N, B]: per-step score of each env's prefix under each frozen buffer (mixture minus reference)."""
        capacity = frozen.valid.shape[0] // self.num_buffers
        mix = jax.vmap(mixture, in_axes=(0, 0, None, None, None))(state.total, state.index, frozen.valid,
                                                                   self.num_buffers, capacity)  # [N, B]
        score = mix if state.ref_total is None else mix - state.ref_total
        return score / jnp.maximum(state.count, 1)[:, None]

    def _judge(self, frozen, state: SimState) -> jax.Array:
        """bool[N, B]: each frozen buffer's score reaches its threshold for the prefix's length."""
        sims = frozen.belief
        tau = sims.threshold[:, length_bucket(state.count, sims.threshold.shape[1])].T  # [N, B]
        return sims.valid[None, :] & (self.scores(frozen, state) >= tau)

    def _copies(self, frozen):
        """The frozen levels' two copies (leaves [F, ...] each), freshly reseeded."""
        if self.reseed is None:
            return frozen.levels, frozen.levels
        f = frozen.valid.shape[0]
        k1, k2 = jax.random.split(frozen.belief.key)
        return (jax.vmap(self.reseed)(jax.random.split(k1, f), frozen.levels),
                jax.vmap(self.reseed)(jax.random.split(k2, f), frozen.levels))

    # -- the component's methods
    def start_coded(self, env, params, frozen, agent) -> SimState:
        """The state at the envs' first coded observations ``agent`` i32[N, E + 1]."""
        n = agent.shape[0]
        key0 = jax.random.PRNGKey(0)  # the reset ignores it
        firsts = [jax.vmap(env.reset_to_level, in_axes=(None, 0, None))(key0, lv, params) for lv in self._copies(frozen)]
        c1, c2 = (with_end(self.coding, obs, jnp.zeros(frozen.valid.shape, bool)) for obs, _ in firsts)
        index, total = jax.vmap(candidates, in_axes=(None, 0, None, None, None, None))(
            frozen.belief.logq, agent, c1, c2, frozen.valid, self.budget)  # [N, S]
        gather = lambda states: jax.tree.map(lambda x: x[jnp.maximum(index, 0)], states)  # noqa: E731
        copies = jax.tree.map(lambda a, b: jnp.stack([a, b], axis=2), gather(firsts[0][1]), gather(firsts[1][1]))
        count = jnp.ones((n,), jnp.int32)
        ref_hidden = ref_total = None
        if frozen.belief.ref is not None:
            ref_hidden = self.ref_model.initial_hidden((n, self.num_buffers))
            ref_total = frozen_logliks(self.ref_model, frozen.belief.ref, ref_hidden, agent[:, :-1])
        state = SimState(index=index, copies=copies, start_copies=copies, total=total, start_total=total,
                         count=count, match=jnp.zeros((n, self.num_buffers), bool), last=agent,
                         ref_hidden=ref_hidden, ref_total=ref_total)
        return state.replace(match=self._judge(frozen, state))

    def start(self, env, params, frozen, reset_keys, obs, starts=None) -> SimState:
        return self.start_coded(env, params, frozen, with_end(self.coding, obs, jnp.zeros(reset_keys.shape[:1], bool)))

    def indistinguishable(self, state: SimState) -> jax.Array:
        return jnp.any(state.match, axis=-1)

    def observe_coded(self, env, params, frozen, env_keys, state: SimState, action, agent, done) -> SimState:
        """After ``action`` [N] with ``env_keys`` [N], seeing ``agent`` i32[N, E + 1]; slots restart where ``done``."""
        step_keys = jax.vmap(lambda k: jax.random.split(k)[0])(env_keys)
        step = jax.vmap(jax.vmap(jax.vmap(env.step, in_axes=(None, 0, None, None)),  # the two copies
                                 in_axes=(None, 0, None, None)),  # the slots
                        in_axes=(0, 0, 0, None))  # the envs
        obs, copies, _, ended, _ = step(step_keys, state.copies, action, params)
        codes = with_end(self.coding, obs, ended)  # [N, S, 2, E + 1]
        lq = step_logq(frozen.belief.logq, agent[:, None], codes[:, :, 0], codes[:, :, 1])  # [N, S]
        total = jnp.where(state.index >= 0, state.total + lq, -jnp.inf)
        restart = done[:, None]
        total = jnp.where(restart, state.start_total, total)
        copies = jax.tree.map(lambda s, c: jnp.where(restart.reshape(restart.shape + (1,) * (c.ndim - 2)), s, c),
                              state.start_copies, copies)
        count = jnp.where(done, 0, state.count) + 1
        ref_hidden = ref_total = None
        if frozen.belief.ref is not None:
            ref_hidden, ref_total = frozen_step(self.ref_model, frozen.belief.ref, state.ref_hidden, state.ref_total,
                                                state.last[:, :-1], action, agent[:, :-1], done)
        state = state.replace(copies=copies, total=total, count=count, last=agent, ref_hidden=ref_hidden,
                              ref_total=ref_total)
        fresh = self._judge(frozen, state)
        return state.replace(match=jnp.where(done[:, None], fresh, state.match & fresh))

    def observe(self, env, params, frozen, env_keys, state: SimState, action, next_obs, done) -> SimState:
        # the agent's own end entry is 0: an ended episode restarts (as the exact tracker does)
        agent = with_end(self.coding, next_obs, jnp.zeros(done.shape, bool))
        return self.observe_coded(env, params, frozen, env_keys, state, action, agent, done)

    def overflow(self, state: SimState) -> jax.Array:
        return jnp.zeros(state.count.shape, jnp.int32)


def score_recorded(tracker: SimulatedTracker, env, params, frozen, codes, actions, resets, key) -> jax.Array:
    """f32[T, N, B]: :meth:`SimulatedTracker.scores` of a recorded rollout against ``frozen``, as in a rollout.

    ``codes`` i32[T, N, E + 1] (:func:`recorded_codes`), ``actions`` [T, N], ``resets`` bool[T, N]."""
    agent = codes.at[:, :, -1].set(0)  # an ended episode restarts: the agent's own end entry is 0
    state = tracker.start_coded(env, params, frozen, agent[0])
    first = tracker.scores(frozen, state)
    n = actions.shape[1]

    def body(state, inp):
        act, obs, restart, k = inp
        state = tracker.observe_coded(env, params, frozen, jax.random.split(k, n), state, act, obs, restart)
        return state, tracker.scores(frozen, state)

    keys = jax.random.split(key, actions.shape[0] - 1)
    _, later = jax.lax.scan(body, state, (actions[:-1], agent[1:], resets[1:], keys))
    return jnp.concatenate([first[None], later])


# ---------------------------------------------------------------------------- in a run
@struct.dataclass
class SimMemory:
    """A simulated run's ``Runner.tracker``.

    ``counts``: the noise table, learnt from every rollout (the noise is the env's, not an
    adversary's); ``ref``/``ref_opt``: the reference (None without ``remidi.belief_reference``),
    copied into ``ref_frozen`` [K, ...] at each freeze; ``threshold`` f32[K, L] (+inf until
    calibrated); the active buffer's last R replays (``codes`` i8[R, T, N, E + 1], ``actions``,
    ``resets``, ``levels`` [R, N, ...]; ``written`` i32[]), scored at the freeze to calibrate."""

    counts: jax.Array
    threshold: jax.Array
    codes: jax.Array
    actions: jax.Array
    resets: jax.Array
    levels: Any
    written: jax.Array
    ref: Any = None
    ref_opt: Any = None
    ref_frozen: Any = None


def simulation_key(runner, purpose: int) -> jax.Array:
    """This update's key for ``purpose`` (19: frozen copies, 23: counted replays, 29: calibration).

    From the seed's own key; the train step uses ``fold_in(rng, 0..5)``, so ``purpose`` must be ≥ 6."""
    return jax.random.fold_in(runner.rng, purpose)


@dataclass(frozen=True)
class Simulated(Tracker):
    """The run's simulated tracker (``remidi.tracker=simulated``).

    ``model``: coding and the reference's GRU; ``budget``: ``remidi.tracker_budget``; ``capacity``:
    ``remidi.buffer_capacity``; ``reseed``: ``UEDTask.reseed_level`` or None; settings as the belief
    tracker's. The reset must ignore its key."""

    model: BeliefModel
    budget: int = 64
    capacity: int = 32
    reseed: Callable | None = None
    settings: LearnedSettings = LearnedSettings()

    learns = True

    def _settings(self):
        return (self.model, self.budget, self.capacity, self.settings)

    def __hash__(self):
        return hash(self._settings() + (id(self.reseed),))

    def __eq__(self, other):
        return isinstance(other, Simulated) and self._settings() == other._settings() and self.reseed is other.reseed

    @property
    def optimizer(self):
        return self.settings.optimizer

    def component(self, num_buffers: int) -> SimulatedTracker:
        """The rollout's component over ``num_buffers`` frozen buffers."""
        return SimulatedTracker(self.model.coding, self.model, num_buffers,
                                budget=min(self.budget, num_buffers * self.capacity), reseed=self.reseed)

    def init(self, setup, rng) -> SimMemory:
        """A fresh memory: empty table and record, +inf thresholds, and a fresh reference if ``reference``."""
        cfg, coding = setup.cfg, self.model.coding
        rng = jax.random.fold_in(rng, 31)
        level = jax.eval_shape(setup.task.sample_level, jax.random.PRNGKey(0))
        num_buffers, batch = cfg.remidi.num_buffers, (self.settings.calibration, cfg.num_steps, cfg.num_envs)
        ref, ref_opt, ref_frozen = init_reference(self.model, self.optimizer, num_buffers, rng) \
            if self.settings.reference else (None,) * 3
        buckets = num_length_buckets(min(cfg.num_steps, setup.task.max_episode_steps or cfg.num_steps))
        threshold = jnp.full((num_buffers, buckets), jnp.inf, jnp.float32)  # strongly typed, as a checkpoint restores it
        return SimMemory(counts=init_counts(coding), threshold=threshold,
                         codes=jnp.zeros(batch + (coding.num_entries + 1,), jnp.int8),
                         actions=jnp.zeros(batch + self.model.action_shape, jnp.int32), resets=jnp.ones(batch, bool),
                         levels=jax.tree.map(lambda x: jnp.zeros(batch[:1] + (cfg.num_envs,) + x.shape, x.dtype), level),
                         written=jnp.zeros((), jnp.int32), ref=ref, ref_opt=ref_opt, ref_frozen=ref_frozen)

    def frozen(self, setup, runner, proposal=None) -> Frozen | None:
        """The earlier buffers' levels, simulated with the learnt noise (the copies' key: 19)."""
        view = super().frozen(setup, runner, proposal)
        if view is None:
            return None
        k = setup.cfg.remidi.num_buffers - 1  # the last buffer is never frozen
        return view.replace(tracker=self.component(k), belief=frozen_sims(runner.tracker, runner.adversary.active,
                                                                          SMOOTHING, simulation_key(runner, 19)))

    def learn(self, setup, runner, proposal, traj):
        """The table counts the rollout's triples (every rollout); the active adversary's own rollouts are
        recorded for calibration; the reference learns from fresh levels."""
        memory, levels, task = runner.tracker, proposal.levels, setup.task
        coding, own = self.model.coding, setup.algo.adversary.own_levels(proposal)
        counts = count_rollout(memory.counts, task.env, task.params, coding, task.reseed_level, levels, traj,
                               simulation_key(runner, 23))
        rows = memory.codes.shape[0]
        row = jnp.where(own, memory.written % rows, rows)  # rows: out of bounds, dropped
        memory = memory.replace(
            counts=counts,
            codes=memory.codes.at[row].set(recorded_codes(coding, traj.obs, traj.reset).astype(jnp.int8), mode="drop"),
            actions=memory.actions.at[row].set(traj.action, mode="drop"),
            resets=memory.resets.at[row].set(traj.reset, mode="drop"),
            levels=jax.tree.map(lambda all_, x: all_.at[row].set(x, mode="drop"), memory.levels, levels),
            written=memory.written + own.astype(jnp.int32))
        if memory.ref is not None:
            memory = fit_reference(self.model, self.optimizer, memory, traj, self.settings.epochs, fresh_levels(proposal))
        return memory, {}

    def freeze(self, setup, runner, switch):
        """At a switch: calibrate the active buffer's threshold on its recorded replays, freeze the
        reference, empty the record.

        Each replay is scored against the buffer as fresh prefixes will be; replays of levels the buffer
        has since dropped are left out; +inf without a recorded replay."""
        task, active = setup.task, runner.adversary.active
        buffer_levels, buffer_valid = setup.algo.adversary.active_levels(setup, runner)
        tracker, key = self.component(1), simulation_key(runner, 29)

        def switched(m: SimMemory) -> SimMemory:
            rows = m.codes.shape[0]
            frozen = _one_buffer(buffer_levels, buffer_valid, m, key,
                                 None if m.ref is None else jax.tree.map(lambda x: x[None], m.ref))
            scores = jax.lax.map(lambda x: score_recorded(tracker, task.env, task.params, frozen, x[0].astype(jnp.int32),
                                                          x[1], x[2], jax.random.fold_in(key, 1))[..., 0],
                                 (m.codes, m.actions, m.resets))  # [R, T, N]
            lengths = jax.vmap(prefix_lengths)(m.resets)
            # an env's replayed level counts only if the buffer still holds it (PLR replaces levels)
            held = jax.vmap(jax.vmap(lambda lv: jnp.any(buffer_valid & jax.vmap(tree_equal, in_axes=(0, None))(
                buffer_levels, lv))))(m.levels)  # [R, N]
            valid = (jnp.arange(rows) < m.written)[:, None, None] & held[:, None, :]
            valid = jnp.broadcast_to(valid, scores.shape)
            tau = calibrate_monotone(jnp.maximum(scores, -1e9), lengths, self.settings.false_rate,
                                     m.threshold.shape[1], valid, margin=self.settings.margin, spread=self.settings.spread)
            tau = jnp.where(jnp.any(valid), tau, jnp.inf)
            return m.replace(threshold=m.threshold.at[active].set(tau), written=jnp.zeros((), jnp.int32),
                             ref_frozen=freeze_reference(m, active))

        return cond_per_seed(switch, switched, lambda m: m, runner.tracker)

    def metrics(self, setup, runner) -> dict:
        """The thresholds (:func:`~remidi.engine.trackers.audit.threshold_metrics`)."""
        return threshold_metrics(runner.tracker.threshold, runner.adversary.active)

    def audit(self, setup, runner, rng) -> dict:
        return audit_against_exact(self, setup, runner, rng)


def _one_buffer(levels, valid, memory: SimMemory, key, ref):
    return Frozen(levels=levels, valid=valid,
                  belief=FrozenSims(logq=log_q(memory.counts, SMOOTHING),
                                    threshold=jnp.zeros((1, memory.threshold.shape[1])),
                                    valid=jnp.ones((1,), bool), key=key, ref=ref))


def frozen_sims(memory: SimMemory, active, smoothing: float, key) -> FrozenSims:
    """What the rollout's tracker reads: the buffers before ``active`` (B = K − 1)."""
    k = memory.threshold.shape[0]
    return FrozenSims(logq=log_q(memory.counts, smoothing), threshold=memory.threshold[:-1],
                      valid=jnp.arange(k - 1) < active, key=key, ref=earlier_references(memory))
