"""Rolling a policy out on a batch of levels, optionally with a distinguishability tracker beside
the environments.

One rollout = ``num_steps`` steps on N environments that all start a fresh episode on their
level; an environment whose episode ends restarts the same level (:class:`AutoReplay`). A tracker
(:mod:`remidi.engine.trackers`) comes in ``frozen.tracker`` and wraps the environments' reset and
step; the rollout only asks it which prefixes are explained.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import jax
import jax.numpy as jnp
from flax import struct

from remidi.engine.core.distributions import CATEGORICAL
from remidi.envs.interface import AutoReplay, UnderspecifiedEnv


@struct.dataclass
class Trajectory:
    """A rollout; every field has leading dims [T, N]."""

    obs: Any  # observation pytree, leaves [T, N, ...]
    reset: jax.Array  # bool: step t is the first of an episode
    action: jax.Array  # i32 (Discrete), i32[T, N, k] (MultiDiscrete: one per component) or f32[T, N, A] (Box)
    log_prob: jax.Array  # f32
    value: jax.Array  # f32
    reward: jax.Array  # f32
    done: jax.Array  # bool: the episode ended at step t
    indist: jax.Array  # bool: the prefix up to obs[t] is indistinguishable from a frozen level
    overflow: jax.Array  # i32: frozen levels sharing the episode's first observation that the
    #                      candidate tracker had no slot for (0 for the reference tracker)
    solved: Any = None  # bool: the step's info flag of solving (Stepping.solved_info); None without one


@dataclass(frozen=True)
class Stepping:
    """The environments a rollout steps: ``raw`` (the env), ``params`` (its parameters),
    ``deterministic_reset`` (its reset ignores its key, so a restart restores the episode's first
    state instead of resetting: :class:`AutoReplay`) and ``tracker_env`` (where a tracker plays
    the frozen levels: they are training levels, so a larger evaluation environment passes the
    training one; default ``raw``), ``solved_info`` (the info key a task's ``solved`` names,
    whose value at each step the trajectory records as ``solved``; None: none). ``auto``: ``raw``
    restarting each env's level when its episode ends."""

    raw: UnderspecifiedEnv
    params: Any
    deterministic_reset: bool = False
    tracker_env: UnderspecifiedEnv | None = None
    solved_info: str | None = None

    def __post_init__(self):
        if self.tracker_env is None:
            object.__setattr__(self, "tracker_env", self.raw)
        object.__setattr__(self, "auto", AutoReplay(self.raw, self.deterministic_reset, self.solved_info))


@dataclass(frozen=True)
class Policy:
    """The policy a rollout acts with: ``apply({"params": params}, carry, obs[1, N, ...], reset
    bool[1, N]) -> carry, (logits [1, N, P], value [1, N])`` (a flax module's ``apply``), its
    ``params`` and its initial recurrent state ``carry`` (leaves [N, ...])."""

    apply: Callable
    params: Any
    carry: Any


def rollout(rng, envs: Stepping, policy: Policy, levels, num_steps: int, frozen=None, dist=CATEGORICAL):
    """Roll out ``policy`` on ``levels`` (leaves [N, ...]) of ``envs`` for ``num_steps`` steps.

    With ``frozen`` (:class:`~remidi.engine.trackers.base.Frozen`), its tracker
    (``frozen.tracker``) wraps the environments' reset and step and judges at every step whether
    the prefix so far is indistinguishable from a frozen level. With ``frozen.params`` the actions
    come from :func:`combine` (ReMiDi's Combine); ``log_prob`` and ``value`` are always the current
    policy's (PPO trains only on the steps it acted on, ``~indist``). Without ``frozen``,
    ``indist`` is all False. ``dist`` (:mod:`remidi.engine.core.distributions`) reads the policy
    output ``logits`` and samples the actions. Returns ``(trajectory, last_value f32[N])``.
    """
    env, apply_fn, params, init_carry = envs.auto, policy.apply, policy.params, policy.carry
    num_envs = jax.tree.leaves(levels)[0].shape[0]
    rng, rng_reset = jax.random.split(rng)
    reset_keys = jax.random.split(rng_reset, num_envs)
    tracker = frozen.tracker if frozen is not None else None
    if tracker is None:
        obs, state = jax.vmap(env.reset_to_level, in_axes=(0, 0, None))(reset_keys, levels, envs.params)
        tstate = None
    else:
        obs, state, tstate = tracker.reset(envs, frozen, reset_keys, levels)
    combining = frozen is not None and frozen.params is not None

    def step(carry, key):
        state, obs, reset, (hidden, frozen_hidden), tstate = carry
        k_act, k_env = jax.random.split(key)
        indist = tracker.indistinguishable(tstate) if tracker is not None else jnp.zeros((num_envs,), bool)
        if frozen is not None and frozen.rehearse is not None:  # a rehearsal: no step explained
            indist = indist & ~frozen.rehearse
        obs_in = jax.tree.map(lambda x: x[None], obs)
        hidden, (logits, value) = apply_fn({"params": params}, hidden, obs_in, reset[None])
        logits, value = logits[0], value[0]
        acting = logits
        if combining:
            frozen_hidden, acting = combine(frozen, tstate, apply_fn, frozen_hidden, obs_in, reset, logits)
        action = dist.sample(k_act, acting)
        log_prob = dist.log_prob(logits, action)
        env_keys = jax.random.split(k_env, num_envs)
        if tracker is None:
            next_obs, state, reward, done, _ = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
                env_keys, state, action, envs.params)
        else:
            next_obs, state, reward, done, tstate = tracker.step(envs, frozen, env_keys, state, tstate, action)
        overflow = tracker.overflow(tstate) if tracker is not None else jnp.zeros((num_envs,), jnp.int32)
        record = Trajectory(obs=obs, reset=reset, action=action, log_prob=log_prob, value=value,
                            reward=reward.astype(jnp.float32), done=done, indist=indist, overflow=overflow,
                            solved=state.solved)
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


#: the prefix of the step metrics that flag a rollout's non-finite rewards and observations
#: (:func:`nonfinite`); the driver stops the run on one and keeps them out of the history
NONFINITE = "nonfinite/"


def nonfinite_names(rollout_name: str | None = None) -> tuple[str, str]:
    """The keys of :func:`nonfinite`: ``nonfinite/reward`` and ``nonfinite/observation``, each
    ending in ``/<rollout_name>`` for a rollout other than the agent's."""
    tail = "" if rollout_name is None else f"/{rollout_name}"
    return f"{NONFINITE}reward{tail}", f"{NONFINITE}observation{tail}"


def nonfinite(traj: Trajectory, rollout_name: str | None = None) -> dict[str, jax.Array]:
    """f32[] 1.0 or 0.0 under :func:`nonfinite_names`: whether some reward, and some floating
    observation leaf (integer leaves cannot be), of ``traj`` is NaN or ±inf. Unchecked, a NaN is
    silent: PLR's scores drop it, so nothing enters the buffer and nothing trains."""
    floats = [jnp.all(jnp.isfinite(x)) for x in jax.tree.leaves(traj.obs) if jnp.issubdtype(x.dtype, jnp.inexact)]
    flags = (~jnp.all(jnp.isfinite(traj.reward)), ~jnp.all(jnp.stack(floats)) if floats else False)
    return {name: jnp.asarray(flag, jnp.float32) for name, flag in zip(nonfinite_names(rollout_name), flags)}


def combine(frozen, tstate, apply_fn: Callable, frozen_hidden, obs_in, reset, logits):
    """ReMiDi's ``Combine`` (Algorithm 1), the one place it is computed: each frozen buffer's
    policy (``frozen.params``, leaves [B, ...], each with its recurrent state ``frozen_hidden``
    [B, ...]) reads the observations ``obs_in`` [1, N, ...]; the earliest buffer one of whose
    levels produced env n's whole prefix, or whose learned model explains it
    (``frozen.tracker.buffer_match``), acts there, the current
    policy (``logits`` f32[N, P]) where none did. Returns ``(frozen_hidden, acting logits
    f32[N, P])``."""
    copies = jax.tree.leaves(frozen.params)[0].shape[0]
    capacity = frozen.valid.shape[0] // copies
    frozen_hidden, (frozen_logits, _) = jax.vmap(
        lambda p, h: apply_fn({"params": p}, h, obs_in, reset[None]))(frozen.params, frozen_hidden)
    matched = frozen.tracker.buffer_match(tstate, copies, capacity)
    return frozen_hidden, combined_logits(matched, frozen_logits[:, 0], logits)


def combined_logits(buffer_match: jax.Array, frozen_logits: jax.Array, logits: jax.Array) -> jax.Array:
    """ReMiDi's ``Combine``: f32[N, P], the policy output of the policy that acts on each env.

    ``buffer_match`` bool[N, B] (some level of frozen buffer b produced env n's whole prefix),
    ``frozen_logits`` f32[B, N, P] (each frozen buffer's policy), ``logits`` f32[N, P] (current).
    The earliest buffer with a matching level acts; the current policy where none matches.
    """
    earliest = jnp.argmax(buffer_match, axis=-1)  # first True (0 if none)
    chosen = jnp.take_along_axis(jnp.moveaxis(frozen_logits, 0, 1), earliest[:, None, None], axis=1)[:, 0]
    return jnp.where(buffer_match.any(axis=-1)[:, None], chosen, logits)
