"""Dark reach: a point in the unit square reaches a goal that "lit" levels show and "dark" ones
hide, seen through noisy float observations.

The agent moves on a ``grid × grid`` lattice (spacing 0.1 for 11) with four actions (off the
square: stays). A level: start, goal in ``[0.05, 0.95]²``, lit?, noise seed. Reaching within
``radius`` pays ``1 − 0.9·(t+1)/T`` and ends the episode; else 0 after T = ``max_steps``.

Observation ``f32[4]``: position plus Gaussian noise of deviation ``noise`` (from the level's
seed and the step: :func:`~remidi.envs.noisy.noise_words`, so deterministic given the level),
then the goal (lit) or zeros (dark). No float repeats, so the exact tracker matches nothing;
dark levels with one start play alike up to the noise (irreducible regret), which a tolerance
tracker wider than the noise (:mod:`remidi.engine.trackers.tolerance`) sees as a complete
overlap. ``darkreach_task(lit_prob=1, random_start=True)``: every level lit, starts vary."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from remidi.envs.interface import UEDTask, UnderspecifiedEnv
from remidi.envs.noisy import draw_seed, noise_words

MOVES = np.array([[0, 1], [1, 0], [0, -1], [-1, 0]], np.int32)  # up, right, down, left as (dx, dy)
GOAL_LOW, GOAL_HIGH = 0.05, 0.95  # the goal's range on each axis


@struct.dataclass
class DarkreachLevel:
    start: jax.Array  # i32[2]: the start lattice point (x, y), in [0, grid)
    goal: jax.Array  # f32[2]: the goal's position in [0.05, 0.95]²
    lit: jax.Array  # bool[]: the observation shows the goal
    seed: jax.Array  # u32[]: the observation noise's seed


@struct.dataclass
class DarkreachState:
    level: DarkreachLevel
    cell: jax.Array  # i32[2]: the agent's lattice point
    t: jax.Array  # i32[]: steps taken in this episode


@struct.dataclass
class DarkreachParams:
    max_steps: int = struct.field(pytree_node=False, default=20)
    noise: float = struct.field(pytree_node=False, default=0.01)  # the position's noise deviation
    radius: float = struct.field(pytree_node=False, default=0.075)  # the goal is reached within it


def gaussian_noise(seed, step) -> jax.Array:
    """f32[2]: two standard normals (Box–Muller over four noise words) of ``seed`` at ``step``."""
    words = noise_words(seed, step, 4)
    u = (words >> 8).astype(jnp.float32) * jnp.float32(2.0 ** -24)  # [0, 1)
    r = jnp.sqrt(-2.0 * jnp.log(1.0 - u[:2]))  # 1 − u in (0, 1]
    return r * jnp.cos(2.0 * jnp.pi * u[2:])


class Darkreach(UnderspecifiedEnv):
    def __init__(self, grid: int = 11):
        if grid < 3:
            raise ValueError(f"grid: must be ≥ 3, got {grid}")
        self.grid = grid
        self.spacing = 1.0 / (grid - 1)
        # every lattice point (x, y), for the optimal return's shortest path
        self.cells = np.stack(np.meshgrid(np.arange(grid), np.arange(grid), indexing="ij"), -1).reshape(-1, 2)

    def __hash__(self):
        return hash((type(self), self.grid))

    def __eq__(self, other):
        return type(other) is type(self) and other.grid == self.grid

    @property
    def default_params(self) -> DarkreachParams:
        return DarkreachParams()

    def action_space(self, params):
        from gymnax.environments import spaces

        return spaces.Discrete(4)

    def position(self, cell) -> jax.Array:
        """f32[..., 2]: a lattice point's position in the unit square."""
        return cell.astype(jnp.float32) * jnp.float32(self.spacing)

    def observation(self, state: DarkreachState, params: DarkreachParams) -> jax.Array:
        """f32[4]: noisy position, then the goal (lit) or zeros (dark)."""
        noisy = self.position(state.cell) + params.noise * gaussian_noise(state.level.seed, state.t)
        shown = jnp.where(state.level.lit, state.level.goal, 0.0).astype(jnp.float32)
        return jnp.concatenate([noisy, shown])

    def reset_env_to_level(self, rng, level: DarkreachLevel, params):
        state = DarkreachState(level=level, cell=jnp.asarray(level.start, jnp.int32), t=jnp.zeros((), jnp.int32))
        return self.observation(state, params), state

    def step_env(self, rng, state: DarkreachState, action, params: DarkreachParams):
        cell = jnp.clip(state.cell + jnp.asarray(MOVES)[action], 0, self.grid - 1).astype(jnp.int32)
        reached = jnp.linalg.norm(self.position(cell) - state.level.goal) <= params.radius
        done = reached | (state.t + 1 >= params.max_steps)
        reward = jnp.where(reached, 1.0 - 0.9 * (state.t + 1) / params.max_steps, 0.0).astype(jnp.float32)
        new = state.replace(cell=cell, t=state.t + 1)
        return self.observation(new, params), new, reward, done, {}

    def distance(self, level: DarkreachLevel, params: DarkreachParams) -> jax.Array:
        """i32[]: the fewest moves from the start to a lattice point within ``radius`` of the goal
        (Manhattan distance on the lattice; a move off the square never shortens a path)."""
        cells = jnp.asarray(self.cells)
        near = jnp.linalg.norm(self.position(cells) - level.goal, axis=-1) <= params.radius
        moves = jnp.sum(jnp.abs(cells - level.start), axis=-1)
        return jnp.min(jnp.where(near, moves, 4 * self.grid)).astype(jnp.int32)

    def optimal_return(self, level: DarkreachLevel, params: DarkreachParams) -> jax.Array:
        """f32[]: the shortest path's ``1 − 0.9·d/T``."""
        return 1.0 - 0.9 * self.distance(level, params).astype(jnp.float32) / params.max_steps

    def optimal_discounted_return(self, level: DarkreachLevel, gamma: float, params: DarkreachParams) -> jax.Array:
        """f32[]: the shortest path's reward arrives at step index d − 1: ``γ^(d−1)·(1 − 0.9·d/T)``."""
        d = self.distance(level, params).astype(jnp.float32)
        return jnp.power(jnp.float32(gamma), d - 1.0) * self.optimal_return(level, params)

    def sample_level(self, rng, params: DarkreachParams, lit_prob: float = 0.5,
                     random_start: bool = False) -> DarkreachLevel:
        """A level: the start at the centre (or, ``random_start``, any lattice point), the goal
        uniform in ``[0.05, 0.95]²`` farther than ``2·radius`` from the start (the first of 8
        draws that is; the last draw if none), lit with ``lit_prob``, a fresh noise seed."""
        k_start, k_goal, k_lit, k_seed = jax.random.split(rng, 4)
        centre = jnp.full((2,), self.grid // 2, jnp.int32)
        start = jax.random.randint(k_start, (2,), 0, self.grid) if random_start else centre
        goals = jax.random.uniform(k_goal, (8, 2), minval=GOAL_LOW, maxval=GOAL_HIGH)
        far = jnp.linalg.norm(goals - self.position(start), axis=-1) > 2 * params.radius
        goal = goals[jnp.where(jnp.any(far), jnp.argmax(far), 7)]
        return DarkreachLevel(start=start.astype(jnp.int32), goal=goal, lit=jax.random.uniform(k_lit) < lit_prob,
                              seed=draw_seed(k_seed))

    def mutate_level(self, rng, level: DarkreachLevel, num_edits: int) -> DarkreachLevel:
        """ACCEL's editor: the goal moved by ``num_edits`` steps of ±0.05 per axis (kept in its
        range); start, lighting and noise seed stay."""
        steps = jnp.where(jax.random.bernoulli(rng, 0.5, (num_edits, 2)), 0.05, -0.05)
        return level.replace(goal=jnp.clip(level.goal + jnp.sum(steps, axis=0), GOAL_LOW, GOAL_HIGH))


def eval_levels(env: Darkreach, params: DarkreachParams, lit: bool, random_start: bool, count: int = 64,
                key: int = 12345) -> DarkreachLevel:
    """``count`` levels of one lighting (leading dim ``count``), drawn once from a fixed key: the
    lit and dark sets share goals, starts and seeds."""
    sample = jax.jit(jax.vmap(lambda k: env.sample_level(k, params, 1.0, random_start)))  # one program
    levels = sample(jax.random.split(jax.random.PRNGKey(key), count))
    return levels.replace(lit=jnp.full((count,), lit))


@functools.lru_cache(maxsize=None)
def darkreach_task(lit_prob: float = 0.5, random_start: bool = False, noise: float = 0.01, max_steps: int = 20,
                   grid: int = 11) -> UEDTask:
    """Dark reach as a UED task (evaluation sets ``lit`` and, where ``lit_prob < 1``, ``dark``: 64
    levels each; tag ``dark``). Cached: the same arguments give the same (immutable) task."""
    env = Darkreach(grid)
    params = DarkreachParams(max_steps=max_steps, noise=float(noise))
    eval_sets = {"lit": eval_levels(env, params, True, random_start)}
    if lit_prob < 1:
        eval_sets["dark"] = eval_levels(env, params, False, random_start)
    return UEDTask(
        env=env,
        params=params,
        sample_level=lambda rng: env.sample_level(rng, params, lit_prob, random_start),
        num_actions=4,
        max_episode_steps=max_steps,
        optimal_return=lambda level: env.optimal_return(level, params),
        optimal_discounted_return=lambda level, gamma: env.optimal_discounted_return(level, gamma, params),
        eval_sets=eval_sets,
        level_tags=lambda level: {"dark": ~level.lit},
        mutate_level=env.mutate_level,
        reseed_level=lambda rng, level: level.replace(seed=draw_seed(rng)),
        deterministic_reset=True,
    )
