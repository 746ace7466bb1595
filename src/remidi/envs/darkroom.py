"""Dark room: a small grid whose goal is shown on "lit" levels and hidden on "dark" ones.

``size × size`` grid; ``num_goals`` candidate goals on the border (no corners); the agent starts
inside. A level: (start, goal index, lit?). Actions up, right, down, left (off the grid: stays).
Entering a candidate ends the episode: the true goal pays ``1 − 0.9·(t+1)/T`` (T =
``max_steps``), others 0; 0 after T steps.

Observation ``f32[size² + num_goals + 1]``: the agent's cell one-hot, then the goal one-hot at
``1 + goal`` (lit) or at 0 (dark). Dark levels with one start play identically whatever the
goal (solve rate ``1/num_goals`` at best: irreducible regret); lit levels are learnable and few
(``(size−2)² · num_goals``), so a frozen ReMiDi buffer may hold most of them
(docs/retention.md). Reset and step ignore their keys."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from remidi.envs.interface import UEDTask, UnderspecifiedEnv

MOVES = np.array([[-1, 0], [0, 1], [1, 0], [0, -1]], np.int32)  # up, right, down, left as (row, col)


@struct.dataclass
class DarkroomLevel:
    start: jax.Array  # i32[]: the start cell, row · size + col (an interior cell)
    goal: jax.Array  # i32[]: index into the task's candidate goal cells
    lit: jax.Array  # bool[]: the observation shows the goal


@struct.dataclass
class DarkroomState:
    level: DarkroomLevel
    pos: jax.Array  # i32[]: the agent's cell
    t: jax.Array  # i32[]: steps taken in this episode


@struct.dataclass
class DarkroomParams:
    max_steps: int = struct.field(pytree_node=False, default=15)


def goal_cells(size: int, num_goals: int) -> np.ndarray:
    """i32[num_goals]: the candidate cells, evenly spaced along the border's non-corner cells
    (clockwise from the top-left)."""
    border = ([(0, c) for c in range(1, size - 1)] + [(r, size - 1) for r in range(1, size - 1)]
              + [(size - 1, c) for c in range(size - 2, 0, -1)] + [(r, 0) for r in range(size - 2, 0, -1)])
    if not 1 <= num_goals <= len(border):
        raise ValueError(f"num_goals: must be in [1, {len(border)}] for a {size}×{size} grid, got {num_goals}")
    picks = np.floor(np.arange(num_goals) * len(border) / num_goals).astype(int)
    return np.array([border[i][0] * size + border[i][1] for i in picks], np.int32)


def interior_cells(size: int) -> np.ndarray:
    """i32[(size−2)²]: the start cells."""
    return np.array([r * size + c for r in range(1, size - 1) for c in range(1, size - 1)], np.int32)


class Darkroom(UnderspecifiedEnv):
    def __init__(self, size: int = 5, num_goals: int = 12):
        if size < 3:
            raise ValueError(f"size: must be ≥ 3, got {size}")
        self.size, self.num_goals = size, num_goals
        self.goals = goal_cells(size, num_goals)
        self.starts = interior_cells(size)

    @property
    def default_params(self) -> DarkroomParams:
        return DarkroomParams()

    def action_space(self, params):
        from gymnax.environments import spaces

        return spaces.Discrete(4)

    def observation(self, state: DarkroomState) -> jax.Array:
        """f32[size² + num_goals + 1]."""
        shown = jnp.where(state.level.lit, state.level.goal + 1, 0)
        return jnp.concatenate([jax.nn.one_hot(state.pos, self.size * self.size),
                                jax.nn.one_hot(shown, self.num_goals + 1)])

    def reset_env_to_level(self, rng, level: DarkroomLevel, params):
        state = DarkroomState(level=level, pos=level.start, t=jnp.zeros((), jnp.int32))
        return self.observation(state), state

    def step_env(self, rng, state: DarkroomState, action, params: DarkroomParams):
        move = jnp.asarray(MOVES)[action]
        row = jnp.clip(state.pos // self.size + move[0], 0, self.size - 1)
        col = jnp.clip(state.pos % self.size + move[1], 0, self.size - 1)
        pos = (row * self.size + col).astype(jnp.int32)
        goals = jnp.asarray(self.goals)
        at_goal = pos == goals[state.level.goal]
        ends = jnp.any(pos == goals) | (state.t + 1 >= params.max_steps)
        reward = jnp.where(at_goal, 1.0 - 0.9 * (state.t + 1) / params.max_steps, 0.0)
        new = state.replace(pos=pos, t=state.t + 1)
        return self.observation(new), new, reward.astype(jnp.float32), ends, {}

    def distance(self, level: DarkroomLevel) -> jax.Array:
        """i32[]: moves from the start to the goal (Manhattan: the path can stay inside until its
        last move, since goals are non-corner border cells)."""
        goal = jnp.asarray(self.goals)[level.goal]
        return (jnp.abs(level.start // self.size - goal // self.size)
                + jnp.abs(level.start % self.size - goal % self.size))

    def optimal_return(self, level: DarkroomLevel, params: DarkroomParams) -> jax.Array:
        """f32[]: the goal reached by the shortest path, ``1 − 0.9·d/T``."""
        return 1.0 - 0.9 * self.distance(level).astype(jnp.float32) / params.max_steps

    def optimal_discounted_return(self, level: DarkroomLevel, gamma: float, params: DarkroomParams) -> jax.Array:
        """f32[]: the shortest path's reward arrives at step index d − 1: ``γ^(d−1)·(1 − 0.9·d/T)``."""
        d = self.distance(level).astype(jnp.float32)
        return jnp.power(jnp.float32(gamma), d - 1.0) * self.optimal_return(level, params)

    def sample_level(self, rng, lit_prob: float = 0.5) -> DarkroomLevel:
        k1, k2, k3 = jax.random.split(rng, 3)
        return DarkroomLevel(start=jax.random.choice(k1, jnp.asarray(self.starts)),
                             goal=jax.random.randint(k2, (), 0, self.num_goals),
                             lit=jax.random.uniform(k3) < lit_prob)

    def mutate_level(self, rng, level: DarkroomLevel, num_edits: int) -> DarkroomLevel:
        """ACCEL's editor: each of ``num_edits`` edits moves the goal to a neighbouring candidate
        (wrapping around the border); lit stays lit, dark dark, the start stays."""
        steps = jnp.sum(jnp.where(jax.random.bernoulli(rng, 0.5, (num_edits,)), 1, -1))
        return level.replace(goal=((level.goal + steps) % self.num_goals).astype(level.goal.dtype))

    def all_levels(self, lit: bool) -> DarkroomLevel:
        """Every level with the given lighting, batched: leading dim (size−2)² · num_goals
        (start-major)."""
        starts = np.repeat(self.starts, self.num_goals)
        goals = np.tile(np.arange(self.num_goals, dtype=np.int32), len(self.starts))
        return DarkroomLevel(start=jnp.asarray(starts), goal=jnp.asarray(goals),
                             lit=jnp.full((len(starts),), lit))


@functools.lru_cache(maxsize=None)
def darkroom_task(size: int = 5, num_goals: int = 12, lit_prob: float = 0.5, max_steps: int | None = None) -> UEDTask:
    """The dark room as a UED task (``max_steps`` default ``3 · size``). Cached: the same
    arguments give the same (immutable) task, so runs in one process reuse compiled programs."""
    env = Darkroom(size, num_goals)
    params = DarkroomParams(max_steps=3 * size if max_steps is None else max_steps)
    return UEDTask(
        env=env,
        params=params,
        sample_level=lambda rng: env.sample_level(rng, lit_prob),
        num_actions=4,
        max_episode_steps=params.max_steps,
        optimal_return=lambda level: env.optimal_return(level, params),
        optimal_discounted_return=lambda level, gamma: env.optimal_discounted_return(level, gamma, params),
        eval_sets={"lit": env.all_levels(True), "dark": env.all_levels(False)},
        level_tags=lambda level: {"dark": ~level.lit},
        mutate_level=env.mutate_level,
        deterministic_reset=True,
    )
