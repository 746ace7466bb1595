"""The distinguishability tracker ("parallel step") of ReMiDi.

While the agent acts on its own level, the tracker steps the agent's *same actions* on every
level of the frozen buffers, in lock-step, and remembers per frozen level whether it has
produced exactly the agent's observations (and episode ends) so far. Environments are
deterministic given the level, so the agent's current trajectory prefix is *indistinguishable*
from the earlier adversaries iff ONE frozen level produced the entire prefix:
``any_f(match[f])`` with ``match[f]`` AND-ed every step (mode ``"prefix"``, the definition).

Mode ``"per_step"`` reproduces the authors' looser rule, one boolean AND-ed with "some frozen
level matches *this* step" — a prefix can pass that test although no single frozen level
produced it. Both are kept so the difference can be measured and tested.

All functions act on ONE rollout environment; the rollout vmaps them over its N envs.
Shapes: F = number of frozen levels (padding entries have ``valid[f] = False``).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from remidi.envs.interface import tree_equal, tree_select

MODES = ("prefix", "per_step")


@struct.dataclass
class TrackerState:
    env_states: Any  # frozen envs' states, leaves [F, ...]
    match: jax.Array  # bool[F]: frozen level f produced this whole prefix
    every_step: jax.Array  # bool[]: every step so far was matched by SOME frozen level


def _compare(obs_f, obs) -> jax.Array:
    """bool[F]: frozen observation f equals the agent's observation."""
    return jax.vmap(tree_equal, in_axes=(0, None))(obs_f, obs)


def tracker_reset(env, params, rng, frozen_levels, valid, agent_obs) -> TrackerState:
    """Start a new episode on every frozen level and compare first observations.

    ``rng`` must be the key the agent's own reset used, so that environments whose reset
    draws randomness stay in lock-step.
    """
    obs_f, states = jax.vmap(env.reset_to_level, in_axes=(None, 0, None))(rng, frozen_levels, params)
    match = valid & _compare(obs_f, agent_obs)
    return TrackerState(env_states=states, match=match, every_step=jnp.any(match))


def tracker_step(env, params, rng, state: TrackerState, frozen_levels, valid, action, agent_obs, agent_done) -> TrackerState:
    """Advance after the agent took ``action`` and saw ``agent_obs`` (``agent_done``: its episode ended).

    ``rng`` is the key given to the agent's :class:`~remidi.envs.interface.AutoReplay` step
    (split the same way). When the agent's episode ended, ``agent_obs`` is the first
    observation of its next episode and the tracker restarts every frozen level.
    """
    rng_step, rng_reset = jax.random.split(rng)
    obs_f, states, _, done_f, _ = jax.vmap(env.step, in_axes=(None, 0, None, None))(
        rng_step, state.env_states, action, params)
    same = _compare(obs_f, agent_obs) & (done_f == agent_done)
    stepped = TrackerState(env_states=states, match=state.match & same,
                           every_step=state.every_step & jnp.any(valid & same))
    restarted = tracker_reset(env, params, rng_reset, frozen_levels, valid, agent_obs)
    return tree_select(agent_done, restarted, stepped)


def indistinguishable(state: TrackerState, mode: str = "prefix") -> jax.Array:
    """bool[]: the current prefix could have come from a frozen level."""
    if mode == "prefix":
        return jnp.any(state.match)
    if mode == "per_step":
        return state.every_step
    raise ValueError(f"tracker mode must be one of {MODES}, got {mode!r}")
