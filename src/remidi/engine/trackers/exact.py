"""The exact distinguishability tracker ("parallel step") of ReMiDi: the default tracker.

While the agent acts on its own level, the tracker steps the agent's *same actions* on frozen
levels in lock-step and remembers, per frozen level, whether it has produced exactly the agent's
observations (and episode ends) so far. Environments are deterministic given the level, so the
agent's current trajectory prefix is *indistinguishable* from the earlier adversaries iff ONE
frozen level produced the entire prefix: ``any(match)``, with each ``match`` AND-ed every step
(mode ``"prefix"``, the definition).

Two trackers compute that, over *slots* (each slot follows one frozen level, ``index``):

* the **reference** tracker (:func:`tracker_reset`, :func:`tracker_step`) has one slot per
  frozen level and steps all F of them beside every rollout env at every step, restarting all
  of them at each episode start. Exact for any environment; its cost grows with F.
* the **candidate** tracker (:meth:`CandidateTracker.start`, :meth:`CandidateTracker.step`) needs a
  deterministic reset (``reset_to_level`` ignores its key, as in every UED environment whose
  level fixes the start). It computes the frozen levels' first observations once per rollout;
  a rollout env (whose restarts replay the same level, so every episode starts alike) keeps as
  slots only the first ``budget`` frozen levels whose first observation equals its own, and
  steps those while they match (:meth:`CandidateTracker.step`: only the live slots, in a batch sized
  to them). Its per-step cost is at most ``budget`` environment steps per env, whatever F, and
  none where no frozen level shares the env's first observation. A frozen level
  that diverged never matches again within the episode, so this equals the reference whenever
  no more than ``budget`` frozen levels share the env's first observation; ``overflow`` counts
  those that did not fit (then a prefix might be judged distinguishable although a dropped
  level would still match it).

Mode ``"per_step"`` reproduces the authors' looser rule, one boolean AND-ed with "some frozen
level matches *this* step" — a prefix can pass that test although no single frozen level
produced it. It needs every frozen level stepped: the reference tracker only.

The functions act on ONE rollout environment. The rollout uses them through the tracker
components (:class:`ExactTracker`, :class:`CandidateTracker`; :func:`make_tracker` picks one),
which vmap them over its N envs (the protocol: :mod:`remidi.engine.trackers.base`): ``start`` at
the rollout's first step, ``indistinguishable`` (bool[N]: the prefix so far could have come from a
frozen level) before each action, ``observe`` after each environment step. They keep no state
across updates: the frozen levels are the adversary's.
Shapes: F = number of frozen levels (padding entries have ``valid[f] = False``), S = slots.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from remidi.engine.core.seeds import SEED_BATCH
from remidi.engine.trackers.base import Tracker
from remidi.envs.interface import tree_equal, tree_select

MODES = ("prefix", "per_step")


@struct.dataclass
class TrackerState:
    index: jax.Array  # i32[S]: the frozen level each slot follows (−1: empty slot)
    env_states: Any  # the slots' environment states, leaves [S, ...]
    match: jax.Array  # bool[S]: the slot's frozen level produced this whole prefix
    every_step: jax.Array  # bool[]: every step so far was matched by SOME frozen level (per_step)
    start_states: Any = None  # candidate tracker: the slots' first states (leaves [S, ...]) ...
    start_match: Any = None  # ... and matches (bool[S]), restored when the agent's episode restarts
    overflow: Any = None  # candidate tracker: i32[], frozen levels matching the first observation that did not fit
    restarted: Any = None  # candidate tracker, stepped with the envs (CandidateTracker.step): bool[], the env restarted
    #                        at the last step, so its slots are at their first states (env_states not restored)


def _compare(obs_f, obs) -> jax.Array:
    """bool[F]: frozen observation f equals the agent's observation (the exact trackers' rule;
    another tracker passes its own as ``compare``, e.g. :mod:`~remidi.engine.trackers.tolerance`)."""
    return jax.vmap(tree_equal, in_axes=(0, None))(obs_f, obs)


# ---------------------------------------------------------------------- the reference tracker
def tracker_reset(env, params, rng, frozen_levels, valid, agent_obs, compare=_compare) -> TrackerState:
    """Start a new episode on every frozen level and compare first observations.

    ``rng`` must be the key the agent's own reset used, so that environments whose reset
    draws randomness stay in lock-step.
    """
    obs_f, states = jax.vmap(env.reset_to_level, in_axes=(None, 0, None))(rng, frozen_levels, params)
    match = valid & compare(obs_f, agent_obs)
    return TrackerState(index=jnp.arange(valid.shape[0]), env_states=states, match=match,
                        every_step=jnp.any(match))


def tracker_step(env, params, rng, state: TrackerState, frozen, action, agent_obs, agent_done,
                 compare=_compare) -> TrackerState:
    """Advance after the agent took ``action`` and saw ``agent_obs`` (``agent_done``: its episode
    ended); ``frozen``: the frozen levels (``levels`` leaves [F, ...], ``valid`` bool[F]).

    ``rng`` is the key given to the agent's :class:`~remidi.envs.interface.AutoReplay` step
    (split the same way). When the agent's episode ended, ``agent_obs`` is the first
    observation of its next episode and the tracker restarts every frozen level.
    """
    rng_step, rng_reset = jax.random.split(rng)
    obs_f, states, _, done_f, _ = jax.vmap(env.step, in_axes=(None, 0, None, None))(
        rng_step, state.env_states, action, params)
    same = compare(obs_f, agent_obs) & (done_f == agent_done)
    stepped = state.replace(env_states=states, match=state.match & same,
                            every_step=state.every_step & jnp.any(frozen.valid & same))
    restarted = tracker_reset(env, params, rng_reset, frozen.levels, frozen.valid, agent_obs, compare)
    return tree_select(agent_done, restarted, stepped)


# ---------------------------------------------------------------------- the candidate tracker
def frozen_starts(env, params, frozen_levels):
    """``(first observations, first states)`` of the F frozen levels (leaves [F, ...]); once per
    rollout, for the candidate tracker (a deterministic reset: any key gives the same start)."""
    return jax.vmap(env.reset_to_level, in_axes=(None, 0, None))(jax.random.PRNGKey(0), frozen_levels, params)


def candidates_step(env, params, rng, state: TrackerState, action, agent_obs, agent_done,
                    compare=_compare) -> TrackerState:
    """Advance the slots as :func:`tracker_step` does (same keys); a restart restores the slots'
    first states, since the env's restart replays the same level from the same start."""
    rng_step, _ = jax.random.split(rng)
    obs_s, states, _, done_s, _ = jax.vmap(env.step, in_axes=(None, 0, None, None))(
        rng_step, state.env_states, action, params)
    same = compare(obs_s, agent_obs) & (done_s == agent_done)
    advanced = state.replace(env_states=states, match=state.match & same)
    restarted = state.replace(env_states=state.start_states, match=state.start_match)
    return tree_select(agent_done, restarted, advanced)


# ---------------------------------------------------------------------- reading a tracker
def buffer_match(state: TrackerState, num_buffers: int, capacity: int) -> jax.Array:
    """bool[B]: some level of frozen buffer b produced the whole prefix (frozen levels are
    buffer-major: level f belongs to buffer f // capacity)."""
    owner = jnp.where(state.match, state.index // capacity, -1)  # [S]
    return jnp.any(owner[None, :] == jnp.arange(num_buffers)[:, None], axis=1)


# ---------------------------------------------------------------------- the components
@dataclass(frozen=True)
class ExactTracker(Tracker):
    """The reference tracker over N rollout envs: every frozen level stepped beside each env.
    ``mode``: ``"prefix"`` (the definition) or ``"per_step"`` (the authors' rule). Its methods
    take the rollout's ``frozen`` (:class:`~remidi.engine.trackers.base.Frozen`) and act on leaves
    [N, ...]."""

    mode: str = "prefix"

    def __post_init__(self):
        if self.mode not in MODES:
            raise ValueError(f"tracker mode must be one of {MODES}, got {self.mode!r}")

    def compare(self, obs_f, obs) -> jax.Array:
        """bool[F]: frozen observation f (leaves [F, ...]) is the agent's ``obs`` (exact equality;
        :mod:`~remidi.engine.trackers.tolerance` overrides it)."""
        same = jnp.ones(jax.tree.leaves(obs_f)[0].shape[:1], bool)
        for frozen_leaf, leaf in zip(jax.tree.leaves(obs_f), jax.tree.leaves(obs)):
            same = same & jnp.all((frozen_leaf == leaf).reshape(frozen_leaf.shape[0], -1), axis=1)
        return same

    def start(self, env, params, frozen, reset_keys, obs, starts=None) -> TrackerState:
        """The state at the envs' first observations ``obs`` (reset with ``reset_keys`` [N])."""
        reset = functools.partial(tracker_reset, compare=self.compare)
        return jax.vmap(reset, in_axes=(None, None, 0, None, None, 0))(
            env, params, reset_keys, frozen.levels, frozen.valid, obs)

    def indistinguishable(self, state: TrackerState) -> jax.Array:
        """bool[N]: each env's prefix so far could have come from a frozen level (``prefix``: one
        frozen level produced all of it; ``per_step``: some frozen level matched every step)."""
        return state.every_step if self.mode == "per_step" else jnp.any(state.match, axis=-1)

    def observe(self, env, params, frozen, env_keys, state: TrackerState, action, next_obs, done) -> TrackerState:
        """After the envs took ``action`` with ``env_keys`` [N] and saw ``next_obs``, ``done``."""
        return jax.vmap(functools.partial(tracker_step, compare=self.compare),
                        in_axes=(None, None, 0, 0, None, 0, 0, 0))(
            env, params, env_keys, state, frozen, action, next_obs, done)

    def overflow(self, state: TrackerState) -> jax.Array:
        """i32[N]: frozen levels the tracker could not follow (none: it follows all)."""
        return jnp.zeros(state.match.shape[:1], jnp.int32)

    def buffer_match(self, state: TrackerState, num_buffers: int, capacity: int) -> jax.Array:
        """bool[N, B]: some level of frozen buffer b produced env n's whole prefix (Combine)."""
        return jax.vmap(buffer_match, in_axes=(0, None, None))(state, num_buffers, capacity)

    def at_first_observation(self) -> ExactTracker:
        """The reference tracker of this mode (every frozen level stepped)."""
        return ExactTracker(mode=self.mode)


@dataclass(frozen=True)
class CandidateTracker(ExactTracker):
    """The candidate tracker over N rollout envs: ``budget`` slots per env, the frozen levels
    sharing the env's first observation (mode ``prefix`` only; the environment's reset must
    ignore its key). ``starts``: the frozen levels' first observations and states
    (:func:`frozen_starts`), computed once per rollout."""

    budget: int = 64

    def __post_init__(self):
        if self.mode != "prefix" or self.budget < 1:
            raise ValueError("the candidate tracker computes the prefix mode only, with budget ≥ 1")

    def reset(self, envs, frozen, reset_keys, levels):
        """The envs' reset and the frozen levels' in one batch where they share it (the reset
        ignores its keys and the frozen levels play in the envs' own environment: each further
        copy of the reset or step in the program costs compile time, seconds for Brax)."""
        if not (envs.deterministic_reset and envs.tracker_env is envs.raw):
            return super().reset(envs, frozen, reset_keys, levels)
        num_envs = reset_keys.shape[0]
        both = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), levels, frozen.levels)
        frozen_keys = jnp.broadcast_to(reset_keys[:1], (frozen.valid.shape[0],) + reset_keys.shape[1:])
        keys = jnp.concatenate([reset_keys, frozen_keys])
        obs_all, states_all = jax.vmap(envs.raw.reset_to_level, in_axes=(0, 0, None))(keys, both, envs.params)
        obs, raw_state = jax.tree.map(lambda x: x[:num_envs], (obs_all, states_all))
        state = envs.start(obs, raw_state, levels)
        starts = jax.tree.map(lambda x: x[num_envs:], (obs_all, states_all))
        return obs, state, self.start(envs.tracker_env, envs.params, frozen, reset_keys, obs, starts)

    def start(self, env, params, frozen, reset_keys, obs, starts=None) -> TrackerState:
        """Each env's slots: the first ``budget`` valid frozen levels (in index order: earlier
        buffers first) whose first observation equals the env's (``obs``, leaves [N, ...])."""
        first_obs, first_states = frozen_starts(env, params, frozen.levels) if starts is None else starts
        matches = frozen.valid & jax.vmap(self.compare, in_axes=(None, 0))(first_obs, obs)  # bool[N, F]
        index = jax.vmap(lambda m: jnp.nonzero(m, size=self.budget, fill_value=-1)[0])(matches)  # i32[N, S]
        match = index >= 0
        states = jax.tree.map(lambda x: x[jnp.maximum(index, 0)], first_states)
        overflow = jnp.maximum(jnp.sum(matches, axis=1) - self.budget, 0).astype(jnp.int32)
        return TrackerState(index=index, env_states=states, match=match, every_step=jnp.any(match, axis=1),
                            start_states=states, start_match=match, overflow=overflow,
                            restarted=jnp.zeros(index.shape[:1], bool))

    def step(self, envs, frozen, env_keys, state, tstate, action):
        """One step of the N envs and of their live slots together, as one batch [N + M]: each
        slot takes its env's action and the key its env's own step takes (the first half of
        ``split(env_key)``, as in :meth:`~remidi.envs.interface.AutoReplay.step_env`), so the
        results are theirs. Only live slots (``match``: their frozen level produced the whole
        prefix) are stepped; a slot that diverged is read again only after its env restarts. M is
        the smallest size of :func:`slot_ladder` that holds the live slots of every seed of the
        program (``lax.switch``: where nothing matches the step costs the envs' alone)."""
        if not (envs.deterministic_reset and envs.tracker_env is envs.raw):
            return super().step(envs, frozen, env_keys, state, tstate, action)
        num_envs, slots = tstate.match.shape
        sizes = slot_ladder(num_envs, slots)
        live = jnp.sum(tstate.match)
        try:  # the most live slots over the seeds this program runs together: one branch for all of them
            live = jax.lax.pmax(live, SEED_BATCH)
        except NameError:  # no seed batch bound here
            pass
        rung = jnp.sum(live > jnp.asarray(sizes))  # the first size ≥ the count
        step_keys = jax.vmap(lambda k: jax.random.split(k)[0])(env_keys)
        branches = [functools.partial(_step_live, envs, self, size) for size in sizes]
        return jax.lax.switch(rung, branches, step_keys, state, tstate, action)

    def observe(self, env, params, frozen, env_keys, state: TrackerState, action, next_obs, done) -> TrackerState:
        return jax.vmap(functools.partial(candidates_step, compare=self.compare), in_axes=(None, None, 0, 0, 0, 0, 0))(
            env, params, env_keys, state, action, next_obs, done)

    def overflow(self, state: TrackerState) -> jax.Array:
        return state.overflow


def make_tracker(mode: str = "prefix", budget: int = 0) -> ExactTracker:
    """The tracker of ``remidi.tracker`` (``mode``) with ``budget`` slots per env: the candidate
    tracker for a budget > 0, else the reference tracker."""
    return CandidateTracker(mode=mode, budget=budget) if budget > 0 else ExactTracker(mode=mode)


#: each batch size of :func:`slot_ladder` is at most this many times the next smaller one
LADDER_FACTOR = 8


def slot_ladder(num_envs: int, slots: int, factor: int = LADDER_FACTOR) -> tuple[int, ...]:
    """The sizes M of the batch of live slots :meth:`CandidateTracker.step` may step, ascending: 0 (no
    slot live: the N envs alone), ``N·S`` (every slot) and between them ``N·S`` divided by
    ``factor`` again and again, down to about ``N / factor``. Each size is one copy of the
    environment's step in the program (compile time), each gap a factor of slots stepped in vain."""
    top = num_envs * slots
    floor = max(1, num_envs // factor)
    sizes, m = {0, top}, top
    while m > floor:
        m = max(floor, -(-m // factor))
        sizes.add(m)
    return tuple(sorted(sizes))


def _step_live(envs, tracker: CandidateTracker, size: int, step_keys, state, tstate, action):
    """:meth:`CandidateTracker.step` with a batch of ``size`` slots, which holds every live one:
    they are picked (in (env, slot) order, the rest of the batch filled with the last slot and
    dropped), stepped beside the envs, compared with their envs' next observations and episode
    ends, and put back; a restarting env's slots restart (``restarted``: from their first states
    at the next step). ``size`` 0: the envs alone."""
    num_envs, slots = tstate.match.shape
    pick = jnp.nonzero(tstate.match.reshape(-1), size=size, fill_value=num_envs * slots)[0]  # i32[M]
    owner = jnp.minimum(pick // slots, num_envs - 1)  # i32[M]: the env each picked slot follows
    fresh = tstate.restarted[owner]  # bool[M]: its env restarted at the last step
    flat = lambda x: x.reshape((num_envs * slots,) + x.shape[2:])  # noqa: E731  [N, S, ...] -> [N·S, ...]

    def picked(current, first):
        now, start = flat(current).at[pick].get(mode="clip"), flat(first).at[pick].get(mode="clip")
        return jnp.where(fresh.reshape(fresh.shape + (1,) * (now.ndim - 1)), start, now)

    slot_states = jax.tree.map(picked, tstate.env_states, tstate.start_states)
    batch = jax.tree.map(lambda e, s: jnp.concatenate([e, s]), state.env_state, slot_states)
    keys = jnp.concatenate([step_keys, step_keys[owner]])
    actions = jnp.concatenate([action, action[owner]])
    stepped = jax.vmap(envs.raw.step, in_axes=(0, 0, 0, None))(keys, batch, actions, envs.params)
    own = jax.tree.map(lambda x: x[:num_envs], stepped)
    next_obs, state, reward, done, _ = envs.restart_where_done(state, own, None)  # a deterministic reset
    if size == 0:
        match = jnp.where(done[:, None], tstate.start_match, False)
        return next_obs, state, reward, done, tstate.replace(match=match, restarted=done)
    obs_m, states_m, _, done_m, _ = jax.tree.map(lambda x: x[num_envs:], stepped)
    agent_obs = jax.tree.map(lambda x: x[owner], next_obs)
    same = jax.vmap(lambda o, a: tracker.compare(jax.tree.map(lambda x: x[None], o), a)[0])(obs_m, agent_obs)
    same = same & (done_m == done[owner])
    match = jnp.zeros((num_envs * slots,), bool).at[pick].set(same, mode="drop").reshape(num_envs, slots)
    env_states = jax.tree.map(lambda current, new: flat(current).at[pick].set(new, mode="drop").reshape(current.shape),
                              tstate.env_states, states_m)
    match = jnp.where(done[:, None], tstate.start_match, match)
    return next_obs, state, reward, done, tstate.replace(env_states=env_states, match=match, restarted=done)


def exact_budget(task, r, mode: str) -> int:
    """Slots per env of the candidate tracker, or 0 for the reference tracker, for the exact
    tracker of ``mode`` on ``task`` under ``r`` (the run's ``ReMiDiConfig``):
    ``remidi.tracker_budget``, at most the number of frozen levels, for the prefix mode on a task
    whose reset ignores its key."""
    if mode != "prefix" or not task.deterministic_reset:
        return 0
    return min(r.tracker_budget, (r.num_buffers - 1) * r.buffer_capacity)
