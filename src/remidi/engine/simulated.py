"""The simulated belief model (issue #31, ``remidi.tracker=simulated``; wired into a run by
:mod:`remidi.engine.adversary`).

The exact tracker asks whether one frozen level produced exactly the agent's observations; with
randomness in what the agent sees (a noisy TV, a noise code) no level ever does. The learned
adversary-level model (:mod:`remidi.engine.belief`) generalises over levels and cannot say "one
of *these* levels". This model keeps the exact tracker's level-conditioning and learns only the
noise:

    P(h | θ) = Π_t Π_e q(o_e,t | d_t, ô¹_e,t, ô²_e,t),     P(h | Λ) = mean over θ ∈ Λ of P(h | θ)

where ô¹, ô² are the frozen level θ stepped in lock-step with the agent's actions under two fresh
draws of its randomness (``UEDTask.reseed_level``; a task without one is deterministic given the
level, and both copies are θ itself), ``d_t`` says whether the two simulated observations agree
entirely, and ``q`` (:func:`log_q`) is a table per entry e learnt by counting (agent, copy, copy)
triples of the same level played three times with the same actions (:func:`count_triples`). One
more entry (the last, K = 2) is the episode's end: whether the step before ended it.

In a deterministic environment every triple agrees, ``q`` learns the identity and the mixture *is*
the exact tracker; where the randomness is, the rows with ``d = 0`` learn its distribution, so a
fresh draw of the same situation costs what noise costs. Judged alone (a threshold on the
mixture) or as a ratio over a model of the generator's trajectories (needed on a noisy TV, where
uniform noise makes any view as likely as any other). Measured on constructed adversaries:
``docs/belief_probe_simulated.py``, ``docs/belief-tracker-plan.md``.

Shapes: E entries of the observation coding plus the end entry (E + 1), K categories, F frozen
levels, S candidate slots per env (each with two simulated copies).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import jax
import jax.numpy as jnp
from flax import struct

from remidi.engine.belief import (BeliefModel, ObsCoding, calibrate_monotone, earlier_references, fit_reference,
                                  freeze_reference, frozen_logliks, frozen_step, init_reference, length_bucket,
                                  num_length_buckets, prefix_lengths)
from remidi.engine.seeds import cond_per_seed
from remidi.envs.interface import tree_equal

SMOOTHING = 0.1  # the noise table's Dirichlet prior per cell (log_q)


# ---------------------------------------------------------------------------- the noise table
def init_counts(coding: ObsCoding) -> jax.Array:
    """f32[E + 1, 2, K, K, K]: no triple counted yet (``[e, d, ô¹, ô², o]``)."""
    k = max(coding.num_categories, 2)
    return jnp.zeros((coding.num_entries + 1, 2, k, k, k), jnp.float32)


def agree(sim1, sim2) -> jax.Array:
    """i32[...]: 1 where the two simulated copies' coded observations ``sim1``, ``sim2``
    i32[..., E + 1] agree on every entry."""
    return jnp.all(sim1 == sim2, axis=-1).astype(jnp.int32)


def count_triples(counts, agent, sim1, sim2, mask=None) -> jax.Array:
    """``counts`` with the triples ``(agent, sim1, sim2)`` (i32[..., E + 1] each, the same level
    played with the same actions, the copies under fresh randomness) added where ``mask``
    bool[...] (all if None)."""
    d = agree(sim1, sim2)
    e = jnp.broadcast_to(jnp.arange(agent.shape[-1]), agent.shape)
    weight = jnp.ones(agent.shape[:-1]) if mask is None else mask.astype(jnp.float32)
    weight = jnp.broadcast_to(weight[..., None], agent.shape)
    dd = jnp.broadcast_to(d[..., None], agent.shape)
    return counts.at[e, dd, sim1, sim2, agent].add(weight)


def log_q(counts, smoothing: float = 0.1) -> jax.Array:
    """f32[E + 1, 2, K, K, K]: log q(o | d, ô¹, ô²) per entry, the counts' frequencies with
    ``smoothing`` added to every cell (a symmetric Dirichlet prior: an unseen row is uniform)."""
    k = counts.shape[-1]
    return jnp.log((counts + smoothing) / (jnp.sum(counts, axis=-1, keepdims=True) + smoothing * k))


def step_logq(logq, agent, sim1, sim2) -> jax.Array:
    """f32[...]: log q of the agent's coded observation ``agent`` i32[..., E + 1] given the two
    simulated copies' ``sim1``, ``sim2`` (broadcast against it), summed over the entries."""
    agent, sim1, sim2 = jnp.broadcast_arrays(agent, sim1, sim2)
    d = jnp.broadcast_to(agree(sim1, sim2)[..., None], agent.shape)
    e = jnp.broadcast_to(jnp.arange(agent.shape[-1]), agent.shape)
    return jnp.sum(logq[e, d, sim1, sim2, agent], axis=-1)


def with_end(coding: ObsCoding, obs, ended) -> jax.Array:
    """i32[..., E + 1]: ``obs`` coded, and the end entry (``ended`` bool[...]: the step before
    this observation ended an episode)."""
    return jnp.concatenate([coding.encode(obs), jnp.asarray(ended, jnp.int32)[..., None]], axis=-1)


# ---------------------------------------------------------------------------- simulating a level
def replay_level(env, params, coding: ObsCoding, level, actions, resets, key) -> jax.Array:
    """i32[T, E + 1]: ``level`` played with the recorded ``actions`` i32[T] and restarted where the
    recorded episode restarted (``resets`` bool[T]: step t starts an episode; the environment's
    reset must ignore its key, as the candidate tracker's), coded with the end entry (the
    simulated step before ended its episode). ``key``: the environment steps' randomness."""
    obs0, state0 = env.reset_to_level(key, level, params)

    def body(carry, inp):
        state, k = carry
        action, restart = inp
        k, ks = jax.random.split(k)
        obs, nstate, _, done, _ = env.step(ks, state, action, params)
        obs = jax.tree.map(lambda a, b: jnp.where(restart, a, b), obs0, obs)
        state = jax.tree.map(lambda a, b: jnp.where(restart, a, b), state0, nstate)
        return (state, k), with_end(coding, obs, done)  # the end entry: this copy's own end

    # step t's observation follows action t − 1 (or the agent's restart at t)
    _, later = jax.lax.scan(body, (state0, key), (actions[:-1], resets[1:]))
    return jnp.concatenate([with_end(coding, obs0, False)[None], later])


def recorded_codes(coding: ObsCoding, obs, resets) -> jax.Array:
    """i32[T, N, E + 1]: a rollout's observations ``obs`` (leaves [T, N, ...]) coded with the end
    entry (an episode restart at t means the step before ended it)."""
    ended = resets.at[0].set(False)
    return with_end(coding, obs, ended)


def count_rollout(counts, env, params, coding: ObsCoding, reseed, levels, obs, actions, resets, key) -> jax.Array:
    """``counts`` with a rollout's triples: each env's level (``levels`` leaves [N, ...]) replayed
    twice with the rollout's ``actions`` i32[T, N] and ``resets`` bool[T, N], each copy's
    randomness drawn afresh (``reseed(key, level) -> level``, or None: the level as it is),
    beside the agent's observations ``obs`` (leaves [T, N, ...])."""
    n = actions.shape[1]

    def copies(level, acts, rs, k):
        k1, k2, k3 = jax.random.split(k, 3)
        l1, l2 = (level, level) if reseed is None else (reseed(k1, level), reseed(k2, level))
        return (replay_level(env, params, coding, l1, acts, rs, k3),
                replay_level(env, params, coding, l2, acts, rs, k3))

    s1, s2 = jax.vmap(copies, in_axes=(0, 1, 1, 0), out_axes=1)(levels, actions, resets, jax.random.split(key, n))
    return count_triples(counts, recorded_codes(coding, obs, resets), s1, s2)


# ---------------------------------------------------------------------------- scoring a prefix
def mixture(totals, index, valid, num_buffers: int, capacity: int) -> jax.Array:
    """f32[B]: log of the mean over each frozen buffer's valid levels of P(prefix | θ), from the
    candidate slots' log-likelihoods ``totals`` f32[S] (``index`` i32[S]: the frozen level each
    follows, −1 empty; levels buffer-major, ``valid`` bool[F]). Levels without a slot count as
    0 (they were not among the most likely at the first observation)."""
    owner = jnp.where(index >= 0, index // capacity, -1)
    mine = owner[None, :] == jnp.arange(num_buffers)[:, None]  # [B, S]
    total = jax.nn.logsumexp(jnp.where(mine, totals[None, :], -jnp.inf), axis=-1)
    n_valid = jnp.sum(valid.reshape(num_buffers, capacity), axis=-1)
    return jnp.where(n_valid > 0, total - jnp.log(jnp.maximum(n_valid, 1)), -jnp.inf)


def candidates(logq, first_agent, first1, first2, valid, budget: int):
    """The ``budget`` frozen levels whose two copies' first observations (``first1``, ``first2``
    i32[F, E + 1]) make the agent's ``first_agent`` i32[E + 1] most likely: ``(index i32[S], −1
    for a slot left empty (no valid level, or log q −inf), log q f32[S])``, highest first, ties in
    index order (earlier buffers first)."""
    lq = step_logq(logq, first_agent[None], first1, first2)  # [F]
    lq = jnp.where(valid, lq, -jnp.inf)
    top, index = jax.lax.top_k(lq, budget)
    index = jnp.where(jnp.isfinite(top), index, -1)
    return index.astype(jnp.int32), top


# ---------------------------------------------------------------------------- the tracker
@struct.dataclass
class FrozenSims:
    """What the simulated tracker reads from the rollout's ``Frozen.belief``: ``logq`` (:func:`log_q`
    of the run's table), ``threshold`` f32[B, L] (per prefix-length bucket), ``valid`` bool[B]
    (buffer b has been frozen), ``ref`` (leaves [B, ...]: the generator's GRU model frozen with
    each buffer, the ratio's denominator; None: judge by the mixture alone) and ``key`` (the
    randomness of the frozen levels' copies in this rollout)."""

    logq: jax.Array
    threshold: jax.Array
    valid: jax.Array
    key: jax.Array
    ref: Any = None


@struct.dataclass
class SimState:
    """The tracker state of one env (leaves [N, ...] in the component): ``index`` i32[S] (the
    frozen level each slot follows, −1 empty), the slots' two copies' environment states (leaves
    [S, 2, ...]) and their first states, ``total`` f32[S] (log P(prefix | the slot's level)) and
    ``start_total`` (its first observation's), ``count`` i32[] (the prefix's steps), the
    reference's GRU state f32[B, H], summed log-likelihood f32[B] and the last coded observation
    i32[E + 1] (its input), and ``match`` bool[B] (buffer b explains the prefix)."""

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
class SimulatedTracker:
    """The simulated belief model as a tracker component over N rollout envs (the rollout's
    ``frozen``: levels [F, ...] buffer-major with ``valid`` bool[F], and ``belief`` a
    :class:`FrozenSims`). ``budget`` candidate slots per env, each following one frozen level in
    two copies; ``reseed`` (static: ``UEDTask.reseed_level``, or None) draws a copy's randomness;
    ``ref_model`` the GRU of the ratio's reference. The environment's reset must ignore its key
    (the candidate tracker's condition): the copies' first states are computed once per rollout."""

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
        """f32[N, B]: each frozen buffer's score of each env's prefix, per step: the mixture's
        log-likelihood, minus the reference's with a reference, over the prefix's length."""
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
        """The frozen levels' two copies (leaves [F, ...] each), their randomness drawn afresh."""
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

    def explained(self, state: SimState) -> jax.Array:
        return jnp.any(state.match, axis=-1)

    def advance_coded(self, env, params, frozen, env_keys, state: SimState, action, agent, done) -> SimState:
        """After the envs took ``action`` [N] with ``env_keys`` [N] and saw the coded observation
        ``agent`` i32[N, E + 1] (the next episode's first where ``done`` bool[N]: the slots restart)."""
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

    def advance(self, env, params, frozen, env_keys, state: SimState, action, next_obs, done) -> SimState:
        # the agent's own end entry is 0: an ended episode restarts (as the exact tracker does)
        agent = with_end(self.coding, next_obs, jnp.zeros(done.shape, bool))
        return self.advance_coded(env, params, frozen, env_keys, state, action, agent, done)

    def overflow(self, state: SimState) -> jax.Array:
        return jnp.zeros(state.count.shape, jnp.int32)

    def buffer_match(self, state: SimState, num_buffers: int, capacity: int) -> jax.Array:
        return state.match[:, :num_buffers]



def score_recorded(tracker: SimulatedTracker, env, params, frozen, codes, actions, resets, key) -> jax.Array:
    """f32[T, N, B]: the tracker's per-step scores (:meth:`SimulatedTracker.scores`) of a recorded
    rollout (``codes`` i32[T, N, E + 1] of :func:`recorded_codes`, ``actions`` [T, N], ``resets``
    bool[T, N]) against ``frozen``: what calibration needs, the same computation as in a rollout."""
    agent = codes.at[:, :, -1].set(0)  # an ended episode restarts: the agent's own end entry is 0
    state = tracker.start_coded(env, params, frozen, agent[0])
    first = tracker.scores(frozen, state)
    n = actions.shape[1]

    def body(state, inp):
        act, obs, restart, k = inp
        state = tracker.advance_coded(env, params, frozen, jax.random.split(k, n), state, act, obs, restart)
        return state, tracker.scores(frozen, state)

    keys = jax.random.split(key, actions.shape[0] - 1)
    _, later = jax.lax.scan(body, state, (actions[:-1], agent[1:], resets[1:], keys))
    return jnp.concatenate([first[None], later])


# ---------------------------------------------------------------------------- in a run
@struct.dataclass
class SimMemory:
    """What a ReMiDi run with ``remidi.tracker=simulated`` carries (``Runner.belief``).

    ``counts`` (:func:`init_counts`): the noise table, learnt from every rollout (the noise is the
    environment's, not an adversary's); ``ref`` / ``ref_opt``: the generator's GRU model (the
    ratio's denominator, learning from rollouts of fresh levels; None without
    ``remidi.belief_reference``), copied into ``ref_frozen`` [K, ...] when buffer k is frozen;
    ``threshold`` f32[K, L] (+inf until calibrated); the active buffer's last R replays
    (``codes`` i8[R, T, N, E + 1], ``actions``, ``resets``, and the replayed ``levels`` leaves
    [R, N, ...]; ``written`` i32[] since the switch), scored against the buffer at its freeze to
    calibrate its threshold (the envs whose level the buffer has since dropped left out)."""

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


def init_memory(coding: ObsCoding, model: BeliefModel, optimizer, num_buffers: int, rows: int, num_steps: int,
                num_envs: int, rng, example_level, max_length: int | None = None, reference: bool = True) -> SimMemory:
    """A fresh memory: an empty table, ``rows`` replays of T = ``num_steps`` steps of ``num_envs``
    envs recorded (levels like ``example_level``), thresholds per length bucket (prefixes of at
    most ``min(T, max_length)`` steps), and with ``reference`` a fresh GRU reference."""
    batch = (rows, num_steps, num_envs)
    ref, ref_opt, ref_frozen = init_reference(model, optimizer, num_buffers, rng) if reference else (None,) * 3
    buckets = num_length_buckets(min(num_steps, max_length or num_steps))
    threshold = jnp.full((num_buffers, buckets), jnp.inf, jnp.float32)  # strongly typed, as a checkpoint restores it
    return SimMemory(counts=init_counts(coding), threshold=threshold,
                     codes=jnp.zeros(batch + (coding.num_entries + 1,), jnp.int8),
                     actions=jnp.zeros(batch, jnp.int32), resets=jnp.ones(batch, bool),
                     levels=jax.tree.map(lambda x: jnp.zeros((rows, num_envs) + x.shape, x.dtype), example_level),
                     written=jnp.zeros((), jnp.int32), ref=ref, ref_opt=ref_opt, ref_frozen=ref_frozen)


def learn(memory: SimMemory, env, params, coding: ObsCoding, reseed, model: BeliefModel, optimizer, levels, traj,
          own, fresh, epochs: int, key) -> SimMemory:
    """After a rollout (``traj`` leaves [T, N, ...]) of ``levels`` (leaves [N, ...]): the noise
    table counts its triples (every rollout); a replay of the active buffer (``own`` bool[]) is
    recorded for its calibration; the reference learns from rollouts of fresh levels (``fresh``)."""
    counts = count_rollout(memory.counts, env, params, coding, reseed, levels, traj.obs, traj.action, traj.reset, key)
    rows = memory.codes.shape[0]
    row = jnp.where(own, memory.written % rows, rows)  # rows: out of bounds, dropped
    memory = memory.replace(
        counts=counts,
        codes=memory.codes.at[row].set(recorded_codes(coding, traj.obs, traj.reset).astype(jnp.int8), mode="drop"),
        actions=memory.actions.at[row].set(traj.action, mode="drop"),
        resets=memory.resets.at[row].set(traj.reset, mode="drop"),
        levels=jax.tree.map(lambda all_, x: all_.at[row].set(x, mode="drop"), memory.levels, levels),
        written=memory.written + own.astype(jnp.int32))
    return memory if memory.ref is None else fit_reference(model, optimizer, memory, traj, epochs, fresh)


def freeze(tracker: SimulatedTracker, memory: SimMemory, env, params, buffer_levels, buffer_valid, active, switch,
           false_rate: float, margin: float, smoothing: float, key) -> SimMemory:
    """At a buffer switch (``switch`` bool[]): the active buffer's threshold is calibrated on its
    recorded replays, each scored against the buffer's levels (``buffer_levels`` leaves [C, ...],
    ``buffer_valid`` bool[C]) as the tracker will score fresh prefixes against it (with the
    reference frozen now; :func:`~remidi.engine.belief.calibrate_monotone`; +inf, explaining
    nothing, without a recorded replay); the reference is frozen with it and the record emptied.
    ``tracker``: the run's, for one buffer. Computed only at a switch."""

    def switched(m: SimMemory) -> SimMemory:
        rows = m.codes.shape[0]
        frozen = _one_buffer(buffer_levels, buffer_valid, m, smoothing, key,
                             None if m.ref is None else jax.tree.map(lambda x: x[None], m.ref))
        scores = jax.lax.map(lambda x: score_recorded(tracker, env, params, frozen, x[0].astype(jnp.int32), x[1], x[2],
                                                      jax.random.fold_in(key, 1))[..., 0],
                             (m.codes, m.actions, m.resets))  # [R, T, N]
        lengths = jax.vmap(prefix_lengths)(m.resets)
        # an env's replayed level counts only if the buffer still holds it (PLR replaces levels)
        held = jax.vmap(jax.vmap(lambda lv: jnp.any(buffer_valid & jax.vmap(tree_equal, in_axes=(0, None))(
            buffer_levels, lv))))(m.levels)  # [R, N]
        valid = (jnp.arange(rows) < m.written)[:, None, None] & held[:, None, :]
        valid = jnp.broadcast_to(valid, scores.shape)
        tau = calibrate_monotone(jnp.maximum(scores, -1e9), lengths, false_rate,
                                 m.threshold.shape[1], valid, margin=margin)
        tau = jnp.where(jnp.any(valid), tau, jnp.inf)
        return m.replace(threshold=m.threshold.at[active].set(tau), written=jnp.zeros((), jnp.int32),
                         ref_frozen=freeze_reference(m, active))

    return cond_per_seed(switch, switched, lambda m: m, memory)


def _one_buffer(levels, valid, memory: SimMemory, smoothing: float, key, ref):
    from remidi.engine.rollout import Frozen

    return Frozen(levels=levels, valid=valid,
                  belief=FrozenSims(logq=log_q(memory.counts, smoothing), threshold=jnp.zeros((1, memory.threshold.shape[1])),
                                    valid=jnp.ones((1,), bool), key=key, ref=ref))


def frozen_sims(memory: SimMemory, active, smoothing: float, key) -> FrozenSims:
    """What the rollout's tracker reads: the buffers before ``active`` (B = K − 1 entries)."""
    k = memory.threshold.shape[0]
    return FrozenSims(logq=log_q(memory.counts, smoothing), threshold=memory.threshold[:-1],
                      valid=jnp.arange(k - 1) < active, key=key, ref=earlier_references(memory))
