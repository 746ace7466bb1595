"""The maze domain (paper §6.3): MiniGrid-style mazes, T-mazes, blindfolded mazes, held-out mazes.

:class:`MazeEnv` wraps ``jaxued``'s :class:`~jaxued.environments.Maze` and on an ordinary level
*is* it, step for step (``tests/test_maze_env.py``): a ``size × size`` grid (13 for training);
7 actions (``0`` left, ``1`` right, ``2`` forward, ``3..6`` nothing); an egocentric 5×5 view
(channels / 10) plus the direction; reward ``1 − 0.9·(t+1)/T`` on reaching the goal, ``T = 250``.

Level kinds (flags of :class:`MazeLevel`):

* **T-maze** (``tmaze``): the agent at a T's junction facing its top wall, the goal at the end of
  one arm drawn as an empty cell. The first move ends the episode: ``+1`` if it got closer to the
  goal, else ``−1``. Cells never visible from the junction are random walls, so T-mazes are
  distinct levels that play identically. Optimal return 1 (discounted ``γ``); any policy that
  cannot see the goal has regret ≥ 1 on one side.
* **Blind** (``blind``): an ordinary maze whose observations are all zeros.

Levels and generators: :mod:`remidi.envs.maze_levels`; exact optima:
:mod:`remidi.envs.maze_paths`; the generator's MDP: :mod:`remidi.envs.maze_builder`."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from flax import struct
from jaxued.environments.maze import Maze
from jaxued.environments.maze.env import EnvParams, Observation, make_maze_map

from remidi.envs.interface import UEDTask, UnderspecifiedEnv
from remidi.envs.maze_builder import MazeBuilder
from remidi.envs.maze_levels import (NUM_WALLS, VIEW, MazeLevel, corridor_levels, from_jaxued, held_out_sets,
                                     mutate_maze, prefab_level, random_maze, tmaze_level)
from remidi.envs.maze_names import HELD_OUT_NAMES, MAX_STEPS, PREFAB_NAMES, TRAIN_SIZE
from remidi.envs.maze_paths import cost_to_go, optimal_discounted_return, optimal_return, shortest_path_steps

__all__ = [
    "MazeLevel", "MazeState", "MazeEnv", "MAX_STEPS", "TRAIN_SIZE", "NUM_WALLS", "PREFAB_NAMES", "HELD_OUT_NAMES",
    "random_maze", "tmaze_level", "prefab_level", "corridor_levels", "held_out_sets", "cost_to_go", "shortest_path_steps",
    "optimal_return", "optimal_discounted_return", "maze_task", "from_jaxued", "mutate_maze",
]



@struct.dataclass
class MazeState:
    inner: object  # jaxued's EnvState (agent_pos, agent_dir, goal_pos, wall_map, maze_map, time, terminal)
    tmaze: jax.Array  # bool[]
    blind: jax.Array  # bool[]


class MazeEnv(UnderspecifiedEnv):
    """``jaxued``'s ``Maze`` (normalised observations) plus T-mazes and blindfolds; levels must be
    ``size × size``."""

    def __init__(self, size: int = TRAIN_SIZE, view: int = VIEW):
        self.size = size
        self.view = view
        self.maze = Maze(max_height=size, max_width=size, agent_view_size=view, normalize_obs=True)

    def __hash__(self):
        return hash((MazeEnv, self.size, self.view))

    def __eq__(self, other):
        return isinstance(other, MazeEnv) and (self.size, self.view) == (other.size, other.view)

    @property
    def default_params(self) -> EnvParams:
        return EnvParams(max_steps_in_episode=MAX_STEPS)

    def action_space(self, params):
        return self.maze.action_space(params)

    def _canonical(self, inner):
        # jaxued's state mixes Python scalars and u8/i32 directions; fix one type for scan carries
        return inner.replace(agent_pos=inner.agent_pos.astype(jnp.uint32), agent_dir=jnp.asarray(inner.agent_dir, jnp.uint8),
                             time=jnp.asarray(inner.time, jnp.int32), terminal=jnp.asarray(inner.terminal, bool))

    def _observe(self, state: MazeState) -> Observation:
        obs = self.maze.get_obs(state.inner)
        return Observation(image=jnp.where(state.blind, 0.0, obs.image),
                           agent_dir=jnp.where(state.blind, 0, obs.agent_dir).astype(jnp.uint8))

    def reset_env_to_level(self, rng, level: MazeLevel, params):
        inner = self.maze.init_state_from_level(level)
        # a T-maze's goal is drawn as an empty cell
        hidden = make_maze_map(level, self.view - 1, ignore_goal=True)
        inner = self._canonical(inner.replace(maze_map=jnp.where(level.tmaze, hidden, inner.maze_map)))
        state = MazeState(inner=inner, tmaze=level.tmaze, blind=level.blind)
        return self._observe(state), state

    def step_env(self, rng, state: MazeState, action, params):
        _, inner, reward, done, info = self.maze.step_env(rng, state.inner, action, params)
        inner = self._canonical(inner)
        old, new = state.inner.agent_pos.astype(jnp.int32), inner.agent_pos.astype(jnp.int32)
        goal = state.inner.goal_pos.astype(jnp.int32)
        moved = jnp.any(new != old)
        towards = jnp.sum(jnp.abs(new - goal)) < jnp.sum(jnp.abs(old - goal))
        reward = jnp.where(state.tmaze, jnp.where(moved, jnp.where(towards, 1.0, -1.0), 0.0), reward)
        done = jnp.where(state.tmaze, moved | done, done)
        state = state.replace(inner=inner.replace(terminal=done))
        return self._observe(state), state, reward.astype(jnp.float32), done, info


# -------------------------------------------------------------------------------------- tasks
KINDS = ("maze", "tmaze", "blindfold")


@functools.lru_cache(maxsize=None)
def maze_task(kind: str = "tmaze", prob: float = 0.5, num_walls: int = NUM_WALLS) -> UEDTask:
    """The maze domain as a UED task (cached per arguments, so compiled steps are reused).

    ``kind``: ``"tmaze"`` (a T-maze with probability ``prob``, tag ``tmaze``), ``"blindfold"`` (blind
    with probability ``prob``, tag ``blind``) or ``"maze"``. Evaluation sets: the ten held-out mazes."""
    if kind not in KINDS:
        raise ValueError(f"maze kind must be one of {KINDS}, got {kind!r}")
    env = MazeEnv(TRAIN_SIZE)

    def generator(walls: int):
        def sample_level(rng):
            k_kind, k_maze, k_t = jax.random.split(rng, 3)
            special = jax.random.bernoulli(k_kind, prob) if kind != "maze" else jnp.asarray(False)
            maze = random_maze(k_maze, TRAIN_SIZE, walls)
            if kind == "tmaze":
                t = tmaze_level(k_t, TRAIN_SIZE)
                return jax.tree.map(lambda a, b: jnp.where(special, a, b), t, maze)
            return maze.replace(blind=special)

        return sample_level

    tag = {"tmaze": "tmaze", "blindfold": "blind"}.get(kind)  # the level flag it reports
    sets = held_out_sets()
    envs = {size: (env if size == TRAIN_SIZE else MazeEnv(size)) for size, _ in sets.values()}
    return UEDTask(
        env=env,
        params=env.default_params,
        sample_level=generator(num_walls),
        num_actions=env.action_space(env.default_params).n,
        max_episode_steps=MAX_STEPS,
        optimal_return=optimal_return,
        optimal_discounted_return=optimal_discounted_return,
        eval_sets={name: levels for name, (_, levels) in sets.items()},
        eval_envs={name: envs[size] for name, (size, _) in sets.items() if size != TRAIN_SIZE},
        level_tags=(lambda level: {tag: getattr(level, tag)}) if tag else (lambda level: {}),
        mutate_level=mutate_maze,
        easy_level=generator(0),  # ACCEL's easy start: no walls (T-mazes and blind levels as generated)
        level_builder=MazeBuilder(kind, num_walls),
        deterministic_reset=True,
    )
