"""Any gymnax environment as a UED task: some ``EnvParams`` fields (and optionally the start seed)
are the level.

    from remidi.envs.gymnax import gymnax_task

    task = gymnax_task("CartPole-v1",
                       level={"gravity": (5.0, 15.0), "masspole": (0.05, 0.5), "length": (0.25, 1.0)},
                       eval_grid={"gravity": (5.0, 9.8, 15.0), "length": (0.25, 0.5, 1.0)})

A level is ``{field: f32[]}`` plus ``"seed": u32[2]`` (``reset_env``'s key) with
``seed_in_level``. :class:`GymnaxUED` calls gymnax's ``reset_env``/``step_env`` with the level's
fields written in and derived fields recomputed (:data:`DERIVED`); episodes end where gymnax
ends them. The task offers: uniform ``sample_level``; ``<field>_high`` tags plus ``tags``;
ACCEL edits of ±``edit_size`` of a field's range; one ``eval_sets`` entry per ``eval_grid``
point (``eval_seeds`` levels differing only in seed); no optimal return (``perfect_regret``
refused), ``learnability`` with ``solved_at``.

With the seed in the level an episode is a function of level and actions wherever ``step_env``
ignores its key (CartPole, Pendulum, Acrobot without torque noise), as ReMiDi's tracker assumes."""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from remidi.envs.actions import from_env_space
from remidi.envs.interface import UEDTask, UnderspecifiedEnv
from remidi.errors import ConfigError

SEED = "seed"  # the level's key for the start seed (u32[2])

# params fields gymnax computes once from others (a level changing the others must recompute them)
DERIVED: dict[str, Callable[[Any], Any]] = {
    "CartPole-v1": lambda p: p.replace(total_mass=p.masscart + p.masspole, polemass_length=p.masspole * p.length),
}


@struct.dataclass
class GymnaxState:
    env_state: Any  # gymnax's own state
    level: dict  # {field: f32[]} (+ "seed": u32[2])


class GymnaxUED(UnderspecifiedEnv):
    """A gymnax env whose level sets some of its params.

    ``fields``: the level's params fields; ``base``: the ``EnvParams`` written into (the engine's
    ``params``); ``derive``: ``params -> params`` recomputing derived fields, or None."""

    def __init__(self, env, base, fields: Sequence[str], seed_in_level: bool, derive=None):
        self.gymnax_env = env
        self.base = base
        self.fields = tuple(fields)
        self.seed_in_level = seed_in_level
        self.derive = derive

    @property
    def default_params(self):
        return self.base

    def action_space(self, params):
        return self.gymnax_env.action_space(params)

    def params_for(self, level: dict, params):
        """gymnax's ``EnvParams``: ``params`` with the level's fields written in (and derived)."""
        out = params.replace(**{name: level[name] for name in self.fields})
        return self.derive(out) if self.derive is not None else out

    def reset_env_to_level(self, rng, level: dict, params):
        key = jax.random.wrap_key_data(level[SEED], impl="threefry2x32") if self.seed_in_level else rng
        obs, state = self.gymnax_env.reset_env(key, self.params_for(level, params))
        return obs, GymnaxState(env_state=state, level=level)

    def step_env(self, rng, state: GymnaxState, action, params):
        p = self.params_for(state.level, params)
        obs, env_state, reward, terminated, _info = self.gymnax_env.step_env(rng, state.env_state, action, p)
        done = jnp.logical_or(terminated, self.gymnax_env.is_truncated(env_state, p))
        return obs, state.replace(env_state=env_state), jnp.asarray(reward, jnp.float32), done, {}


def point_name(point: Mapping[str, float]) -> str:
    """A grid point's evaluation-set name: ``gravity=9.8_length=0.5``."""
    return "_".join(f"{n}={v:g}" for n, v in point.items())


@dataclasses.dataclass(frozen=True)
class LevelSpace:
    """The level's fields and their uniform ranges ``{field: (low, high)}``."""

    ranges: Mapping[str, tuple[float, float]]
    seed_in_level: bool = True

    def sample(self, rng) -> dict:
        """A random level: each field ~ U[low, high] (f32[]), a fresh seed (u32[2])."""
        k_fields, k_seed = jax.random.split(rng)
        keys = jax.random.split(k_fields, len(self.ranges))
        level = {name: jax.random.uniform(k, (), jnp.float32, lo, hi)
                 for k, (name, (lo, hi)) in zip(keys, self.ranges.items())}
        if self.seed_in_level:
            level[SEED] = jax.random.bits(k_seed, (2,), jnp.uint32)
        return level

    def mutate(self, rng, level: dict, num_edits: int, edit_size: float = 0.1) -> dict:
        """ACCEL's editor: each edit moves one random field by ±``edit_size``·(high − low), clipped; seed kept."""
        names = list(self.ranges)
        lows = jnp.asarray([self.ranges[n][0] for n in names], jnp.float32)  # [F]
        highs = jnp.asarray([self.ranges[n][1] for n in names], jnp.float32)
        k_field, k_sign = jax.random.split(rng)
        which = jax.random.randint(k_field, (num_edits,), 0, len(names))  # [E]
        sign = jnp.where(jax.random.bernoulli(k_sign, 0.5, (num_edits,)), 1.0, -1.0)
        moves = jnp.zeros(len(names)).at[which].add(sign) * edit_size * (highs - lows)  # [F]
        values = jnp.clip(jnp.stack([level[n] for n in names]) + moves, lows, highs)
        return {**level, **{n: values[i].astype(level[n].dtype) for i, n in enumerate(names)}}

    def tags(self, level: dict) -> dict[str, jax.Array]:
        """``{<field>_high: bool[]}``: the field is in its range's upper half (none for a one-point range)."""
        return {f"{n}_high": level[n] > (lo + hi) / 2 for n, (lo, hi) in self.ranges.items() if hi > lo}

    def grid(self, points: Mapping[str, Sequence[float]], defaults, seeds: int, rng) -> dict[str, dict]:
        """``{point name: levels}``: per grid point, ``seeds`` levels (leaves [seeds]; one without a seed in
        the level) with the same seeds at every point; fields outside ``points`` take ``defaults``."""
        count = seeds if self.seed_in_level else 1
        seed_data = jax.random.bits(rng, (count, 2), jnp.uint32)
        sets = {}
        for values in itertools.product(*points.values()):
            point = dict(zip(points, values))
            name = point_name(point)
            level = {n: jnp.full((count,), point.get(n, getattr(defaults, n)), jnp.float32) for n in self.ranges}
            if self.seed_in_level:
                level[SEED] = seed_data
            sets[name] = level
        return sets


def _numbers(values, what: str, allowed: str, pair: bool = False) -> tuple[float, ...]:
    """``values`` (1-D real numbers; two for a ``pair``) as floats; ConfigError naming ``what``."""
    try:
        array = np.asarray(values)
        ok = (array.ndim == 1 and array.size >= 1 and (array.size == 2 or not pair)
              and (np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ConfigError(f"gymnax: {what} must be {allowed}, got {values!r}")
    return tuple(float(v) for v in array)


def gymnax_task(env_name: str, level: Mapping[str, tuple[float, float]], *, seed_in_level: bool = True,
                params: Mapping[str, Any] | None = None, eval_grid: Mapping[str, Sequence[float]] | None = None,
                eval_seeds: int = 4, tags: Mapping[str, Callable[[dict], jax.Array]] | None = None,
                edit_size: float = 0.1, solved_at: float | None = None, derive=None) -> UEDTask:
    """gymnax's ``env_name`` as a UED task whose level is ``level``'s params fields (``{field: (low, high)}``,
    float scalars drawn uniformly) and, with ``seed_in_level``, the start seed.

    ``params``: fixed params fields; ``eval_grid``: ``{field: values}`` (:meth:`LevelSpace.grid`);
    ``tags``: extra named predicates; ``edit_size``: ACCEL's step as a share of the range;
    ``solved_at``: return ≥ this is solved (None: no solve rate, no learnability); ``derive``:
    defaults to :data:`DERIVED`'s entry. ConfigError for an unknown env or field, or a bad range."""
    import gymnax

    try:
        env, base = gymnax.make(env_name)
    except ValueError as err:  # gymnax's own error for an unknown name
        raise ConfigError(f"gymnax: cannot make {env_name!r} ({err})") from None
    known = {f.name for f in dataclasses.fields(base)}
    for what, names in (("level", level), ("params", params or {}), ("eval_grid", eval_grid or {})):
        for name in names:
            if name not in known:
                raise ConfigError(f"gymnax: {what} field {name!r} is not a params field of {env_name}; "
                                  f"allowed: {', '.join(sorted(known))}")
    if not level:
        raise ConfigError(f"gymnax: give at least one params field of {env_name} as the level")
    if "max_steps_in_episode" in level:  # the engine reads the limit once (max_episode_steps), not per level
        raise ConfigError("gymnax: level field 'max_steps_in_episode' cannot vary by level: the episode limit is "
                          "one number of the task (params={'max_steps_in_episode': N})")
    level = {name: _numbers(bounds, f"level field {name}", "a (low, high) pair of numbers", pair=True)
             for name, bounds in level.items()}
    for name in level:
        given = getattr(base, name)
        if not jnp.issubdtype(jnp.asarray(given).dtype, jnp.floating) or jnp.ndim(given):  # drawn: a float scalar
            raise ConfigError(f"gymnax: level field {name} is {jnp.asarray(given).dtype}{list(jnp.shape(given))} in "
                              f"{env_name}'s params (default {given!r}), and a level draws each field as one float; "
                              f"allowed: a float scalar field (give {name} a fixed value in params)")
    eval_grid = {name: _numbers(values, f"eval_grid field {name}", "a non-empty list of numbers")
                 for name, values in (eval_grid or {}).items()}
    noise = {**dict(params or {}), **dict(level)}.get("torque_noise_max", getattr(base, "torque_noise_max", 0.0))
    if seed_in_level and (noise[1] if isinstance(noise, tuple) else noise) > 0:
        raise ConfigError("gymnax: torque_noise_max > 0 draws noise from the step's key, so the level (with its "
                          "seed) no longer decides the episode; keep it 0, or seed_in_level=False")
    for name, (lo, hi) in level.items():
        if not lo <= hi:
            raise ConfigError(f"gymnax: level field {name}: low must be ≤ high, got ({lo}, {hi})")
    for name in eval_grid or {}:
        if name not in level:
            raise ConfigError(f"gymnax: eval_grid field {name!r} is not a level field; allowed: {', '.join(level)}")
    base = base.replace(**dict(params or {}))
    space = LevelSpace(dict(level), seed_in_level)
    ued = GymnaxUED(env, base, list(level), seed_in_level, derive if derive is not None else DERIVED.get(env_name))
    actions = from_env_space(env.action_space(base))  # ConfigError naming the supported spaces for another
    extra = dict(tags or {})
    return UEDTask(
        env=ued,
        params=base,
        sample_level=space.sample,
        max_episode_steps=int(base.max_steps_in_episode),
        eval_sets=space.grid(eval_grid, base, eval_seeds, jax.random.PRNGKey(0)) if eval_grid else {},
        level_tags=lambda lv: {**space.tags(lv), **{name: jnp.asarray(f(lv)) for name, f in extra.items()}},
        solved=None if solved_at is None else (lambda ret: ret >= solved_at),
        mutate_level=lambda rng, lv, num_edits: space.mutate(rng, lv, num_edits, edit_size),
        deterministic_reset=seed_in_level,
        **actions.task_fields(),  # num_actions= (and continuous=) for Discrete and Box, else action_space=
    )
