"""Kinetix (Matthews et al., ICLR 2025) as a UED domain: 2-D physics tasks on Kinetix's own levels.

Needs the optional extra (``pip install -e ".[kinetix]"``: ``kinetix-env``, which caps JAX at
0.9.0; the core stays on the newest JAX, so the extra lives in an environment of its own). This
module imports Kinetix at its top: import it only where a Kinetix task is built.

A level is Kinetix's ``EnvState`` (shapes, joints, thrusters, their roles), as Kinetix's own
environment resets to it; sizes ``s``, ``m`` and ``l`` (Kinetix's ``static_env_params_from_size``)
differ in how many polygons, circles, joints and thrusters a level holds. What the task offers:

* ``sample_level``: Kinetix's random level (``sample_kinetix_level``) behind Kinetix's own filter
  of levels that doing nothing already solves (``create_vmapped_filtered_distribution``, one
  level per call: ``filter_ratio`` candidates, each played by the no-op action for
  ``filter_steps`` steps, one drawn with weight 0.001 for a candidate the no-op solved and 1
  otherwise), as Kinetix's PLR, ACCEL and SFL do;
* the environment (:class:`KinetixUED`): Kinetix's step (``frame_skip`` physics substeps) without
  its auto-reset; reward +1 when a green shape touches a blue one, −1 when it touches a red one
  (either ends the episode), plus Kinetix's dense shaping, −``dense_reward_scale`` × the change
  in the green–blue distance, whose sum over the episode is kept within ±:data:`SHAPING_BOUND`
  (Kinetix's is unbounded): so the return alone says whether the goal was reached (``solved``:
  return > 0.5), as the engine's solve rates and learnability score read it; episodes end after
  256 steps;
* ``eval_sets``: Kinetix's hand-made held-out levels (the lists of its ``configs/eval``), each
  level a set ``<size>_<name>`` (``s_h0_weak_thrust``): those of the training size and of every
  smaller one (padded to the training size by Kinetix's ``expand_env_state``), loaded from
  Kinetix's JSON files once and cached as arrays (:mod:`remidi.envs.kinetix_levels`);
* ``mutate_level`` (ACCEL): Kinetix's own mutator (``make_mutate_env``: add, move, resize,
  rotate a shape, swap roles, add or remove a thruster, toggle a fixture);
* ``level_tags``: ``has_motor`` (an active joint with its motor on), ``has_thruster``,
  ``has_red`` (a red shape, floor included, to avoid) and the number of free shapes in buckets
  (``shapes_2-3``, ``shapes_4-6``, ``shapes_7-12``; one tag per count where the size allows
  three or fewer: ``shapes_2``, ``shapes_3``);
* ``deterministic_reset``: the level is the start state and the physics is deterministic, so
  ReMiDi's exact candidate tracker applies.

Observations and actions are components (:mod:`remidi.envs.kinetix_obs`): ``symbolic_flat`` or
``entity`` observations, ``discrete`` actions.
"""

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
    """Kinetix's environment (``kinetix_env``: a ``KinetixEnv`` built with ``auto_reset=False``,
    played on params whose ``dense_reward_scale`` is 0) with Kinetix's dense shaping at
    ``dense_reward_scale`` added here, its episode sum bounded (the module's docstring), and the
    observation ``observation.adapt`` makes of Kinetix's."""

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
    """The ``(low, high)`` counts of free shapes each ``shapes_*`` tag covers, for a size holding at
    most ``capacity`` free shapes (a level has at least two: the green and the blue one)."""
    if capacity <= 3:
        return [(n, n) for n in range(2, capacity + 1)]
    return [(lo, min(hi, capacity)) for lo, hi in ((2, 3), (4, 6), (7, 12)) if lo <= capacity]


def level_tags(level, capacity: int) -> dict[str, jax.Array]:
    """``{tag: bool[]}`` of a level (the module's docstring); ``capacity``: free shape slots."""
    free = jnp.sum(level.polygon.active[NUM_STATIC:]) + jnp.sum(level.circle.active)
    red = jnp.any((level.polygon_shape_roles == ROLE_RED) & level.polygon.active) | jnp.any(
        (level.circle_shape_roles == ROLE_RED) & level.circle.active)
    tags = {"has_motor": jnp.any(level.joint.active & level.joint.motor_on),
            "has_thruster": jnp.any(level.thruster.active), "has_red": red}
    for lo, hi in shape_buckets(capacity):
        tags[f"shapes_{lo}" if lo == hi else f"shapes_{lo}-{hi}"] = (free >= lo) & (free <= hi)
    return tags


def filtered_sampler(sample_one, env_params, static, ued_params, filter_env, ratio: int, steps: int):
    """``rng -> level``: Kinetix's no-op filter (``create_vmapped_filtered_distribution``) drawing
    one level of ``ratio`` candidates from ``sample_one``, each played ``steps`` steps by the no-op
    (``filter_env``: multi-discrete actions, whose all-zero action is the no-op); ``steps`` 0: the
    raw sampler."""
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
    """The Kinetix task of ``size`` (the module's docstring): ``observation`` and ``actions``
    components (:mod:`remidi.envs.kinetix_obs`), Kinetix's dense shaping ``dense_reward_scale``
    (its configs: 0.2), the no-op filter's ``filter_steps`` (0: none) and ``filter_ratio``
    (Kinetix's ``level_filter_n_steps`` 64, ``level_filter_sample_ratio`` 2); ``held_out``: the
    held-out levels as evaluation sets (loading them costs seconds to minutes the first time).
    ConfigError (one line, naming the field) for a value out of range."""
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
