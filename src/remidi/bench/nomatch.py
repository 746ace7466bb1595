"""A benchmark task on which ReMiDi's tracker finds nothing to match: the fogged maze.

The T-maze task's ordinary mazes (no T-mazes, no blindfolds), each level with a fog field of its
own (``fog f32[13, 13]``, uniform in [0, 1), drawn with the level). The fog diffuses:
``substeps`` steps of a 5-point stencil on the torus per environment step, the knob that makes a
step costlier than the maze's (128 by default: the step's cost grows with it, the maze's is one
``substeps = 0`` step). The observation is the maze's, every image entry offset by a tenth of the
fog density at the agent's cell, so every level's first observation differs from every other
level's (the fog is continuous): as on Craftax or JaxNav, no frozen level ever shares an env's
first observation, and ReMiDi masks nothing. Rewards, episode ends and optimal returns are the
maze's (the fog changes only what is seen).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from flax import struct
from jaxued.environments.maze.env import Observation

from remidi.envs.interface import UEDTask, UnderspecifiedEnv
from remidi.envs.maze import MAX_STEPS, NUM_WALLS, TRAIN_SIZE, MazeEnv, MazeLevel, random_maze
from remidi.envs.maze_paths import optimal_discounted_return, optimal_return

SUBSTEPS = 128  # diffusion steps of the fog per environment step: the step then costs several maze steps
RATE = 0.2  # the stencil's diffusion rate (stable below 0.25)


@struct.dataclass
class FogLevel:
    maze: MazeLevel
    fog: jax.Array  # f32[size, size], the fog density per cell at the episode's start


@struct.dataclass
class FogState:
    maze: object  # the maze's state (remidi.envs.maze.MazeState)
    fog: jax.Array  # f32[size, size]


def diffuse(fog: jax.Array, substeps: int) -> jax.Array:
    """``fog`` [size, size] after ``substeps`` stencil steps ``f + RATE · Δf`` on the torus."""

    def once(_, f):
        neighbours = jnp.roll(f, 1, 0) + jnp.roll(f, -1, 0) + jnp.roll(f, 1, 1) + jnp.roll(f, -1, 1)
        return f + RATE * (neighbours - 4.0 * f)

    return jax.lax.fori_loop(0, substeps, once, fog)


class FogMazeEnv(UnderspecifiedEnv):
    """The maze with a diffusing fog (the module's docstring)."""

    def __init__(self, substeps: int = SUBSTEPS):
        self.substeps = substeps
        self.maze = MazeEnv(TRAIN_SIZE)

    def __hash__(self):
        return hash((FogMazeEnv, self.substeps))

    def __eq__(self, other):
        return isinstance(other, FogMazeEnv) and self.substeps == other.substeps

    @property
    def default_params(self):
        return self.maze.default_params

    def action_space(self, params):
        return self.maze.action_space(params)

    def _observe(self, obs: Observation, state: FogState) -> Observation:
        x, y = state.maze.inner.agent_pos[0], state.maze.inner.agent_pos[1]
        return obs.replace(image=obs.image + 0.1 * state.fog[y, x])

    def reset_env_to_level(self, rng, level: FogLevel, params):
        obs, maze = self.maze.reset_env_to_level(rng, level.maze, params)
        state = FogState(maze=maze, fog=level.fog)
        return self._observe(obs, state), state

    def step_env(self, rng, state: FogState, action, params):
        obs, maze, reward, done, info = self.maze.step_env(rng, state.maze, action, params)
        state = FogState(maze=maze, fog=diffuse(state.fog, self.substeps))
        return self._observe(obs, state), state, reward, done, info


@functools.lru_cache(maxsize=None)
def fog_maze_task(substeps: int = SUBSTEPS) -> UEDTask:
    """The fogged maze as a UED task (cached: one task, one compiled program, per ``substeps``)."""
    env = FogMazeEnv(substeps)

    def sample_level(rng):
        k_maze, k_fog = jax.random.split(rng)
        return FogLevel(maze=random_maze(k_maze, TRAIN_SIZE, NUM_WALLS),
                        fog=jax.random.uniform(k_fog, (TRAIN_SIZE, TRAIN_SIZE)))

    return UEDTask(env=env, params=env.default_params, sample_level=sample_level,
                   num_actions=env.action_space(env.default_params).n, max_episode_steps=MAX_STEPS,
                   optimal_return=lambda level: optimal_return(level.maze),
                   optimal_discounted_return=lambda level, gamma: optimal_discounted_return(level.maze, gamma),
                   deterministic_reset=True)
