"""The exact distinguishability tracker, ReMiDi's default.

The tracker steps the agent's *same actions* on frozen levels in lock-step and records, per frozen
level, whether it has produced exactly the agent's observations and episode ends so far. Envs are
deterministic given the level, so the prefix is *indistinguishable* from the earlier adversaries
iff ONE frozen level produced all of it: ``any(match)``, each ``match`` AND-ed every step (mode
``"prefix"``, the definition). Mode ``"per_step"`` is the authors' looser rule: "some frozen level
matches *this* step", AND-ed; a prefix can pass it that no single level produced.

Two trackers, over *slots* (each follows one frozen level, ``index``):

* **reference** (:func:`tracker_reset`, :func:`tracker_step`): one slot per frozen level, all F
  stepped beside every env. Exact for any env, cost grows with F; the only one for ``per_step``.
* **candidate** (:class:`CandidateTracker`): needs a reset that ignores its key. Each env keeps as
  slots the first ``budget`` frozen levels whose first observation equals its own and steps only
  those still matching. A diverged level never matches again in the episode, so this equals the
  reference unless more than ``budget`` levels share the first observation; ``overflow`` counts
  those dropped (a prefix only they explain is then judged distinguishable).

The functions act on ONE env; :class:`ExactTracker` and :class:`CandidateTracker` vmap them over
N. No state across updates. Shapes: F frozen levels (padding has ``valid[f] = False``), S slots."""

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
    """bool[F]: frozen observation f equals the agent's (other trackers pass their own ``compare``)."""
    return jax.vmap(tree_equal, in_axes=(0, None))(obs_f, obs)


# ---------------------------------------------------------------------- the reference tracker
def tracker_reset(env, params, rng, frozen_levels, valid, agent_obs, compare=_compare) -> TrackerState:
    """Start an episode on every frozen level and compare first observations.

    ``rng`` must be the agent's own reset key, so envs whose reset draws randomness stay in lock-step."""
    obs_f, states = jax.vmap(env.reset_to_level, in_axes=(None, 0, None))(rng, frozen_levels, params)
    match = valid & compare(obs_f, agent_obs)
    return TrackerState(index=jnp.arange(valid.shape[0]), env_states=states, match=match,
                        every_step=jnp.any(match))


def tracker_step(env, params, rng, state: TrackerState, frozen, action, agent_obs, agent_done,
                 compare=_compare) -> TrackerState:
    """Advance after the agent took ``action``, saw ``agent_obs`` and ``agent_done``.

    ``frozen``: ``levels`` leaves [F, ...], ``valid`` bool[F]. ``rng``: the key of the agent's
    :class:`~remidi.envs.interface.AutoReplay` step (split the same way). When the episode ended,
    ``agent_obs`` is the next episode's first observation and every frozen level restarts."""
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
    """``(first observations, first states)`` of the F frozen levels (a deterministic reset: any key)."""
    return jax.vmap(env.reset_to_level, in_axes=(None, 0, None))(jax.random.PRNGKey(0), frozen_levels, params)


def candidates_step(env, params, rng, state: TrackerState, action, agent_obs, agent_done,
                    compare=_compare) -> TrackerState:
    """:func:`tracker_step` for the slots; a restart restores their first states (same level, same start)."""
    rng_step, _ = jax.random.split(rng)
    obs_s, states, _, done_s, _ = jax.vmap(env.step, in_axes=(None, 0, None, None))(
        rng_step, state.env_states, action, params)
    same = compare(obs_s, agent_obs) & (done_s == agent_done)
    advanced = state.replace(env_states=states, match=state.match & same)
    restarted = state.replace(env_states=state.start_states, match=state.start_match)
    return tree_select(agent_done, restarted, advanced)


# ---------------------------------------------------------------------- reading a tracker
def buffer_match(state: TrackerState, num_buffers: int, capacity: int) -> jax.Array:
    """bool[B]: some level of frozen buffer b produced the whole prefix (level f is in buffer f // capacity)."""
    owner = jnp.where(state.match, state.index // capacity, -1)  # [S]
    return jnp.any(owner[None, :] == jnp.arange(num_buffers)[:, None], axis=1)


# ---------------------------------------------------------------------- the components
@dataclass(frozen=True)
class ExactTracker(Tracker):
    """The reference tracker over N envs; ``mode``: ``"prefix"`` or ``"per_step"``. Leaves [N, ...]."""

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
        """bool[N]: each env's prefix could have come from a frozen level (per ``mode``)."""
        return state.every_step if self.mode == "per_step" else jnp.any(state.match, axis=-1)

    def observe(self, env, params, frozen, env_keys, state: TrackerState, action, next_obs, done) -> TrackerState:
        """After the envs took ``action`` with ``env_keys`` [N] and saw ``next_obs``, ``done``."""
        return jax.vmap(functools.partial(tracker_step, compare=self.compare),
                        in_axes=(None, None, 0, 0, None, 0, 0, 0))(
            env, params, env_keys, state, frozen, action, next_obs, done)

    def overflow(self, state: TrackerState) -> jax.Array:
        """i32[N]: zeros (it follows every frozen level)."""
        return jnp.zeros(state.match.shape[:1], jnp.int32)

    def buffer_match(self, state: TrackerState, num_buffers: int, capacity: int) -> jax.Array:
        """bool[N, B]: some level of frozen buffer b produced env n's whole prefix (Combine)."""
        return jax.vmap(buffer_match, in_axes=(0, None, None))(state, num_buffers, capacity)

    def at_first_observation(self) -> ExactTracker:
        """The reference tracker of this mode."""
        return ExactTracker(mode=self.mode)


@dataclass(frozen=True)
class CandidateTracker(ExactTracker):
    """The candidate tracker over N envs: ``budget`` slots per env (``prefix`` only; key-free reset)."""

    budget: int = 64

    def __post_init__(self):
        if self.mode != "prefix" or self.budget < 1:
            raise ValueError("the candidate tracker computes the prefix mode only, with budget ≥ 1")

    def reset(self, envs, frozen, reset_keys, levels):
        """The envs' and the frozen levels' resets in one batch where possible.

        Why: each copy of reset or step in the program costs compile time (seconds for Brax)."""
        if not (envs.deterministic_reset and envs.tracker_env is envs.raw):
            return super().reset(envs, frozen, reset_keys, levels)
        num_envs = reset_keys.shape[0]
        both = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), levels, frozen.levels)
        frozen_keys = jnp.broadcast_to(reset_keys[:1], (frozen.valid.shape[0],) + reset_keys.shape[1:])
        keys = jnp.concatenate([reset_keys, frozen_keys])
        obs_all, states_all = jax.vmap(envs.raw.reset_to_level, in_axes=(0, 0, None))(keys, both, envs.params)
        obs, state = jax.tree.map(lambda x: x[:num_envs], (obs_all, states_all))
        starts = jax.tree.map(lambda x: x[num_envs:], (obs_all, states_all))
        return obs, state, self.start(envs.tracker_env, envs.params, frozen, reset_keys, obs, starts)

    def start(self, env, params, frozen, reset_keys, obs, starts=None) -> TrackerState:
        """Each env's slots: the first ``budget`` valid frozen levels (index order: earlier buffers first)
        whose first observation equals the env's."""
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
        """One step of the N envs and their live slots as one batch [N + M].

        Each slot takes its env's action and step key (the first half of ``split(env_key)``), so its
        results are the frozen level's. Only live slots (``match``) are stepped. M is the smallest
        :func:`slot_ladder` size holding every seed's live slots (``lax.switch``: with nothing live the
        step costs the envs' alone)."""
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
    """The exact tracker of ``mode``: candidate with ``budget`` > 0 slots per env, else reference."""
    return CandidateTracker(mode=mode, budget=budget) if budget > 0 else ExactTracker(mode=mode)


#: each batch size of :func:`slot_ladder` is at most this many times the next smaller one
LADDER_FACTOR = 8


def slot_ladder(num_envs: int, slots: int, factor: int = LADDER_FACTOR) -> tuple[int, ...]:
    """The batch sizes M :meth:`CandidateTracker.step` may use, ascending: 0, ``N·S`` and ``N·S``
    divided by ``factor`` repeatedly down to about ``N / factor``.

    Each size is one copy of the env's step (compile time); each gap wastes up to a factor of steps."""
    top = num_envs * slots
    floor = max(1, num_envs // factor)
    sizes, m = {0, top}, top
    while m > floor:
        m = max(floor, -(-m // factor))
        sizes.add(m)
    return tuple(sorted(sizes))


def _step_live(envs, tracker: CandidateTracker, size: int, step_keys, state, tstate, action):
    """:meth:`CandidateTracker.step` with a batch of ``size`` slots holding every live one.

    Live slots are picked in (env, slot) order (padding dropped), stepped beside the envs, compared
    and put back; a restarting env's slots restart from their first states next step. ``size`` 0:
    the envs alone."""
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
    """Candidate slots per env (0: reference tracker): ``remidi.tracker_budget``, at most the number of
    frozen levels, for ``prefix`` on a task whose reset ignores its key."""
    if mode != "prefix" or not task.deterministic_reset:
        return 0
    return min(r.tracker_budget, (r.num_buffers - 1) * r.buffer_capacity)
