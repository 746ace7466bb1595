"""Rolling a policy out on a batch of levels, optionally tracking distinguishability.

One rollout = ``num_steps`` steps on N environments that all start a fresh episode on their
level; an environment whose episode ends restarts the same level (:class:`AutoReplay`).
"""

from __future__ import annotations

from typing import Any, Callable

import jax
import jax.numpy as jnp
from flax import struct

from remidi.engine import tracker as trk
from remidi.engine.distributions import CATEGORICAL
from remidi.envs.interface import AutoReplay, UnderspecifiedEnv


@struct.dataclass
class Trajectory:
    """A rollout; every field has leading dims [T, N]."""

    obs: Any  # observation pytree, leaves [T, N, ...]
    reset: jax.Array  # bool: step t is the first of an episode
    action: jax.Array  # i32, or f32[T, N, A] for continuous actions
    log_prob: jax.Array  # f32
    value: jax.Array  # f32
    reward: jax.Array  # f32
    done: jax.Array  # bool: the episode ended at step t
    indist: jax.Array  # bool: the prefix up to obs[t] is indistinguishable from a frozen level
    overflow: jax.Array  # i32: frozen levels sharing the episode's first observation that the
    #                      candidate tracker had no slot for (0 for the reference tracker)


@struct.dataclass
class Frozen:
    """The frozen buffers' levels as one batch: ``levels`` leaves [F, ...], ``valid`` bool[F],
    buffer-major (F = B·C for B frozen buffers of capacity C). With ``params`` (leaves [B, ...]:
    the policy frozen with each buffer, ReMiDi's ``Combine``), a step whose prefix one of those
    buffers' levels produced is acted on by the policy of the earliest such buffer.

    ``tracker`` (static): the component that judges distinguishability
    (:mod:`remidi.engine.tracker`: the reference tracker stepping every frozen level, or the
    candidate tracker with ``budget`` slots per env, whose environment's reset ignores its key;
    or :class:`~remidi.engine.belief.BeliefTracker`, which reads the frozen adversaries' learned
    models from ``belief``, a :class:`~remidi.engine.belief.FrozenBeliefs`)."""

    levels: Any
    valid: jax.Array
    params: Any = None
    belief: Any = None
    tracker: trk.ExactTracker = struct.field(pytree_node=False, default=trk.ExactTracker())


def rollout(rng, env: UnderspecifiedEnv, env_params, apply_fn: Callable, params, init_carry, levels,
            num_steps: int, frozen: Frozen | None = None, tracker_env: UnderspecifiedEnv | None = None,
            dist=CATEGORICAL, deterministic_reset: bool = False):
    """Roll out the policy on ``levels`` (leaves [N, ...]) of ``env`` for ``num_steps`` steps.

    With ``frozen``, its tracker (``frozen.tracker``) judges at every step whether the prefix so
    far is indistinguishable from a frozen level; it plays the frozen levels in ``tracker_env``
    (default ``env``; they are training levels, so a larger evaluation environment passes the
    training one). With ``frozen.params`` the actions come from :func:`combine` (ReMiDi's
    Combine); ``log_prob`` and ``value`` are always the current policy's (PPO trains only on the
    steps it acted on, ``~indist``). Without ``frozen``, ``indist`` is all False.

    ``apply_fn({"params": params}, carry, obs[1, N, ...], reset bool[1, N]) -> carry,
    (logits [1, N, P], value [1, N])`` (a flax module's ``apply``); ``dist``
    (:mod:`remidi.engine.distributions`) reads the policy output ``logits`` and samples the
    actions. ``deterministic_reset``: the environment's reset ignores its key, so a restart
    restores the episode's first state instead of resetting (:class:`AutoReplay`). Returns
    ``(trajectory, last_value f32[N])``.
    """
    tracker_env = tracker_env if tracker_env is not None else env
    raw_env, env = env, AutoReplay(env, deterministic_reset)
    num_envs = jax.tree.leaves(levels)[0].shape[0]
    rng, rng_reset = jax.random.split(rng)
    reset_keys = jax.random.split(rng_reset, num_envs)
    tracker = frozen.tracker if frozen is not None else None
    # the candidate tracker's slots and the envs share one reset and one environment step per
    # rollout step (each further copy of the environment's reset or step in the program costs
    # compile time: seconds for Brax); the reset ignores its keys
    shared = isinstance(tracker, trk.CandidateTracker) and deterministic_reset and tracker_env is raw_env
    starts = None
    if shared:
        both = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), levels, frozen.levels)
        frozen_keys = jnp.broadcast_to(reset_keys[:1], (frozen.valid.shape[0],) + reset_keys.shape[1:])
        keys = jnp.concatenate([reset_keys, frozen_keys])
        obs_all, states_all = jax.vmap(raw_env.reset_to_level, in_axes=(0, 0, None))(keys, both, env_params)
        obs, raw_state = jax.tree.map(lambda x: x[:num_envs], (obs_all, states_all))
        state = jax.vmap(env.start_state)(obs, raw_state, levels)
        starts = jax.tree.map(lambda x: x[num_envs:], (obs_all, states_all))
    else:
        obs, state = jax.vmap(env.reset_to_level, in_axes=(0, 0, None))(reset_keys, levels, env_params)
    tstate = tracker.start(tracker_env, env_params, frozen, reset_keys, obs, starts) if tracker is not None else None
    combining = frozen is not None and frozen.params is not None

    def step(carry, key):
        state, obs, reset, (hidden, frozen_hidden), tstate = carry
        k_act, k_env = jax.random.split(key)
        indist = tracker.explained(tstate) if tracker is not None else jnp.zeros((num_envs,), bool)
        obs_in = jax.tree.map(lambda x: x[None], obs)
        hidden, (logits, value) = apply_fn({"params": params}, hidden, obs_in, reset[None])
        logits, value = logits[0], value[0]
        acting = logits
        if combining:
            frozen_hidden, acting = combine(frozen, tstate, apply_fn, frozen_hidden, obs_in, reset, logits)
        action = dist.sample(k_act, acting)
        log_prob = dist.log_prob(logits, action)
        env_keys = jax.random.split(k_env, num_envs)
        if shared:
            next_obs, state, reward, done, tstate = step_with_slots(raw_env, env, env_params, env_keys, state, tstate,
                                                                    action, tracker)
        else:
            next_obs, state, reward, done, _ = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
                env_keys, state, action, env_params)
            if tracker is not None:
                tstate = tracker.advance(tracker_env, env_params, frozen, env_keys, tstate, action, next_obs, done)
        overflow = tracker.overflow(tstate) if tracker is not None else jnp.zeros((num_envs,), jnp.int32)
        record = Trajectory(obs=obs, reset=reset, action=action, log_prob=log_prob, value=value,
                            reward=reward.astype(jnp.float32), done=done, indist=indist, overflow=overflow)
        return (state, next_obs, done, (hidden, frozen_hidden), tstate), record

    first = jnp.ones((num_envs,), bool)
    frozen_carry = None
    if combining:
        copies = jax.tree.leaves(frozen.params)[0].shape[0]
        frozen_carry = jax.tree.map(lambda x: jnp.broadcast_to(x, (copies,) + x.shape), init_carry)
    carry = (state, obs, first, (init_carry, frozen_carry), tstate)
    (state, obs, reset, (hidden, _), _), traj = jax.lax.scan(step, carry, jax.random.split(rng, num_steps))
    _, (_, last_value) = apply_fn({"params": params}, hidden, jax.tree.map(lambda x: x[None], obs), reset[None])
    return traj, last_value[0]


def combine(frozen: Frozen, tstate, apply_fn: Callable, frozen_hidden, obs_in, reset, logits):
    """ReMiDi's ``Combine`` (Algorithm 1), the one place it is computed: each frozen buffer's
    policy (``frozen.params``, leaves [B, ...], each with its recurrent state ``frozen_hidden``
    [B, ...]) reads the observations ``obs_in`` [1, N, ...]; the earliest buffer one of whose
    levels produced env n's whole prefix, or whose learned model explains it (``remidi.tracker=belief``),
    (``frozen.tracker.buffer_match``) acts there, the current
    policy (``logits`` f32[N, P]) where none did. Returns ``(frozen_hidden, acting logits
    f32[N, P])``."""
    copies = jax.tree.leaves(frozen.params)[0].shape[0]
    capacity = frozen.valid.shape[0] // copies
    frozen_hidden, (frozen_logits, _) = jax.vmap(
        lambda p, h: apply_fn({"params": p}, h, obs_in, reset[None]))(frozen.params, frozen_hidden)
    matched = frozen.tracker.buffer_match(tstate, copies, capacity)
    return frozen_hidden, combined_logits(matched, frozen_logits[:, 0], logits)


def step_with_slots(raw_env, env: AutoReplay, env_params, env_keys, state, tstate, action,
                    tracker: trk.CandidateTracker):
    """One environment step of the N envs and of their candidate tracker slots together, as one
    batch [N, 1 + S]: each env's slots take its action and the key its own step takes (the first
    half of ``split(env_key)``, as in :meth:`AutoReplay.step_env` and
    :func:`~remidi.engine.tracker.candidates_step`), so the results are theirs. Returns
    ``(next_obs, state, reward, done, tstate)``, leaves [N, ...]."""
    step_keys = jax.vmap(lambda k: jax.random.split(k)[0])(env_keys)
    both = jax.tree.map(lambda e, s: jnp.concatenate([e[:, None], s], axis=1), state.env_state, tstate.env_states)
    slots = tstate.index.shape[1]
    actions = jnp.broadcast_to(action[:, None], (action.shape[0], 1 + slots) + action.shape[1:])
    stepped = jax.vmap(jax.vmap(raw_env.step, in_axes=(None, 0, 0, None)), in_axes=(0, 0, 0, None))(
        step_keys, both, actions, env_params)
    own = jax.tree.map(lambda x: x[:, 0], stepped)
    next_obs, state, reward, done, _ = jax.vmap(env.restart_where_done, in_axes=(0, 0, None))(state, own, env_params)
    tstate = tracker.advance_stepped(tstate, jax.tree.map(lambda x: x[:, 1:], stepped), next_obs, done)
    return next_obs, state, reward, done, tstate


def combined_logits(buffer_match: jax.Array, frozen_logits: jax.Array, logits: jax.Array) -> jax.Array:
    """ReMiDi's ``Combine``: f32[N, P], the policy output of the policy that acts on each env.

    ``buffer_match`` bool[N, B] (some level of frozen buffer b produced env n's whole prefix),
    ``frozen_logits`` f32[B, N, P] (each frozen buffer's policy), ``logits`` f32[N, P] (current).
    The earliest buffer with a matching level acts; the current policy where none matches.
    """
    earliest = jnp.argmax(buffer_match, axis=-1)  # first True (0 if none)
    chosen = jnp.take_along_axis(jnp.moveaxis(frozen_logits, 0, 1), earliest[:, None, None], axis=1)[:, 0]
    return jnp.where(buffer_match.any(axis=-1)[:, None], chosen, logits)
