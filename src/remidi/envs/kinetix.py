"""Kinetix (Matthews et al., ICLR 2025) as a UED domain: 2-D physics tasks on Kinetix's own levels.

Needs the optional extra (``pip install -e ".[kinetix]"``; it caps JAX at 0.9.0, so it lives in
its own environment); this module imports Kinetix at its top. A level is Kinetix's ``EnvState``;
sizes ``s``, ``m``, ``l`` differ in how many shapes, joints and thrusters it holds. The task:

* ``sample_level``: Kinetix's random level behind its no-op filter (``filter_ratio`` candidates
  played ``filter_steps`` no-op steps, one the no-op solved drawn with weight 0.001), as
  Kinetix's PLR, ACCEL and SFL do;
* :class:`KinetixUED`: Kinetix's step without auto-reset; +1 when green touches blue, −1 for red
  (either ends the episode), plus the dense shaping whose episode sum is kept within
  ±:data:`SHAPING_BOUND` (Kinetix's is unbounded), so the return alone says whether the goal was
  reached (``solved``: return > 0.5); 256 steps;
* ``eval_sets``: Kinetix's hand-made held-out levels of the training size and every smaller one
  (``s_h0_weak_thrust``), cached as arrays (:mod:`remidi.envs.kinetix_levels`);
* ``mutate_level``: Kinetix's own mutator (``make_mutate_env``);
* ``level_tags``: ``has_motor``, ``has_thruster``, ``has_red`` and free-shape-count buckets;
* ``deterministic_reset``: the level is the start state and the physics is deterministic.

Observation and action components: :mod:`remidi.envs.kinetix_obs`."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct
from kinetix.environment import (ActionType, EnvParams, ObservationType, UEDParams, make_kinetix_env,
                                 make_mutate_env, static_env_params_from_size)
from kinetix.environment.ued.distributions import create_vmapped_filtered_distribution
from kinetix.environment.ued.ued import make_reset_fn_sample_kinetix_level

from remidi.envs.interface import UEDTask, UnderspecifiedEnv
from remidi.envs.kinetix_levels import held_out_sets
from remidi.envs.kinetix_names import SIZES
from remidi.envs.kinetix_obs import ACTIONS, OBSERVATIONS, Observation
from remidi.errors import one_of, require

MAX_STEPS = 256  # Kinetix's EnvParams.max_timesteps
SHAPING_BOUND = 0.45  # |the episode's shaping sum| ≤ this < 0.5: solved ⇔ return > 0.5
ROLE_RED = 3  # Kinetix's shape roles: 0 plain, 1 green, 2 blue, 3 red
NUM_STATIC = 4  # polygon slots 0–3: the floor and the walls and ceiling (StaticEnvParams default)


@struct.dataclass
class KinetixState:
    env_state: Any  # Kinetix's EnvState
    shaping: jax.Array  # f32[]: the dense shaping paid so far in this episode, within ±SHAPING_BOUND


class KinetixUED(UnderspecifiedEnv):
    """Kinetix's env (``auto_reset=False``, its own shaping off) with the dense shaping at
    ``dense_reward_scale`` added here, bounded per episode, and the observation ``observation.adapt``
    makes."""

    def __init__(self, kinetix_env, params, observation: Observation, dense_reward_scale: float):
        self.kinetix_env = kinetix_env
        self.params = params
        self.observation = observation
        self.dense_reward_scale = float(dense_reward_scale)

    def _key(self):
        return (self.kinetix_env, self.observation.kinetix_type, self.dense_reward_scale)

    def __hash__(self):
        return hash(self._key())

    def __eq__(self, other):
        return isinstance(other, KinetixUED) and self._key() == other._key()

    @property
    def default_params(self):
        return self.params

    def action_space(self, params):
        return self.kinetix_env.action_space(params)

    def reset_env_to_level(self, rng, level, params):
        obs, state = self.kinetix_env.reset(rng, params, override_reset_state=level)
        return self.observation.adapt(obs), KinetixState(env_state=state, shaping=jnp.zeros((), jnp.float32))

    def step_env(self, rng, state: KinetixState, action, params):
        before = state.env_state.last_distance  # -1 on an episode's first step: no shaping (as Kinetix)
        obs, env_state, reward, done, info = self.kinetix_env.step(rng, state.env_state, action, params)
        delta = jnp.nan_to_num(-(info["distance"] - before) * self.dense_reward_scale, nan=0.0, posinf=0.0,
                               neginf=0.0)
        delta = jnp.where(before == -1, 0.0, delta)
        shaping = jnp.clip(state.shaping + delta, -SHAPING_BOUND, SHAPING_BOUND)
        reward = jnp.asarray(reward, jnp.float32) + (shaping - state.shaping)
        next_state = KinetixState(env_state=env_state, shaping=jnp.where(done, 0.0, shaping))
        return self.observation.adapt(obs), next_state, reward, jnp.asarray(done, bool), {}


def shape_buckets(capacity: int) -> list[tuple[int, int]]:
    """The ``(low, high)`` free-shape counts of the ``shapes_*`` tags for a size of ``capacity`` free
    shapes (a level has at least two)."""
    if capacity <= 3:
        return [(n, n) for n in range(2, capacity + 1)]
    return [(lo, min(hi, capacity)) for lo, hi in ((2, 3), (4, 6), (7, 12)) if lo <= capacity]


def level_tags(level, capacity: int) -> dict[str, jax.Array]:
    """``{tag: bool[]}`` of a level (module docstring); ``capacity``: free shape slots."""
    free = jnp.sum(level.polygon.active[NUM_STATIC:]) + jnp.sum(level.circle.active)
    red = jnp.any((level.polygon_shape_roles == ROLE_RED) & level.polygon.active) | jnp.any(
        (level.circle_shape_roles == ROLE_RED) & level.circle.active)
    tags = {"has_motor": jnp.any(level.joint.active & level.joint.motor_on),
            "has_thruster": jnp.any(level.thruster.active), "has_red": red}
    for lo, hi in shape_buckets(capacity):
        tags[f"shapes_{lo}" if lo == hi else f"shapes_{lo}-{hi}"] = (free >= lo) & (free <= hi)
    return tags


def filtered_sampler(sample_one, env_params, static, ued_params, filter_env, ratio: int, steps: int):
    """``rng -> level``: Kinetix's no-op filter over ``ratio`` candidates of ``sample_one``, each played
    ``steps`` no-op steps (``filter_env``: multi-discrete, all-zero is the no-op); ``steps`` 0: raw."""
    if steps == 0:
        return sample_one

    def sample_level(rng):
        levels, _ = create_vmapped_filtered_distribution(rng, sample_one, env_params, static, ued_params, 1,
                                                         filter_env, True, ratio, "", steps)
        return jax.tree.map(lambda x: x[0], levels)

    return sample_level


def kinetix_task(size: str = "s", observation: str = "symbolic_flat", actions: str = "discrete",
                 dense_reward_scale: float = 0.2, filter_steps: int = 64, filter_ratio: int = 2,
                 held_out: bool = True) -> UEDTask:
    """The Kinetix task of ``size`` (module docstring).

    ``observation``, ``actions``: components (:mod:`remidi.envs.kinetix_obs`); ``dense_reward_scale``
    (Kinetix's configs: 0.2); ``filter_steps`` (0: none) and ``filter_ratio`` (Kinetix: 64, 2);
    ``held_out``: load the held-out sets (seconds to minutes the first time). ConfigError for a value
    out of range."""
    if size not in SIZES:
        raise one_of("kinetix.size", size, SIZES)
    if observation not in OBSERVATIONS:
        raise one_of("kinetix.observation", observation, OBSERVATIONS)
    if actions not in ACTIONS:
        raise one_of("kinetix.actions", actions, ACTIONS)
    require(dense_reward_scale >= 0, "kinetix.dense_reward_scale", "a number ≥ 0", dense_reward_scale)
    require(isinstance(filter_steps, int) and filter_steps >= 0, "kinetix.filter_steps", "an integer ≥ 0",
            filter_steps)
    require(isinstance(filter_ratio, int) and filter_ratio >= 1, "kinetix.filter_ratio", "an integer ≥ 1",
            filter_ratio)
    static = static_env_params_from_size(size)
    kinetix_params = EnvParams().replace(dense_reward_scale=float(dense_reward_scale), max_timesteps=MAX_STEPS)
    ued_params = UEDParams()  # one instance: it compares by identity, and Kinetix's sampler jits on it
    obs_kind, action_kind = OBSERVATIONS[observation], ACTIONS[actions]
    kinetix_env = make_kinetix_env(ActionType[action_kind.kinetix_type], ObservationType[obs_kind.kinetix_type],
                                   None, kinetix_params, static, auto_reset=False)
    env = KinetixUED(kinetix_env, kinetix_params.replace(dense_reward_scale=0.0), obs_kind, dense_reward_scale)
    sample_one = make_reset_fn_sample_kinetix_level(kinetix_params, static, ued_params,
                                                    physics_engine=kinetix_env.physics_engine)
    filter_env = make_kinetix_env(ActionType.MULTI_DISCRETE, ObservationType.SYMBOLIC_FLAT, None, kinetix_params,
                                  static, auto_reset=True)
    mutate = make_mutate_env(static, kinetix_params, ued_params)
    capacity = static.num_polygons - NUM_STATIC + static.num_circles
    return UEDTask(
        env=env,
        params=env.params,
        sample_level=filtered_sampler(sample_one, kinetix_params, static, ued_params, filter_env, filter_ratio,
                                      filter_steps),
        action_space=action_kind.declare(kinetix_env.action_space(kinetix_params)),
        max_episode_steps=MAX_STEPS,
        eval_sets=held_out_sets(size, static) if held_out else {},
        level_tags=lambda level: level_tags(level, capacity),
        solved=lambda ret: ret > 0.5,
        mutate_level=lambda rng, level, num_edits: mutate(rng, level, num_edits),
        deterministic_reset=True,
    )
