"""A tiny deterministic test environment: the level *is* its observation sequence.

Observation at step t is ``level.obs[t]`` (actions are ignored, except that action 1 at step 0
of a level with ``level.branch`` set shows ``level.branch_obs`` instead); the episode ends after
``len(level.obs)`` steps with reward ``level.reward``.
"""

import jax.numpy as jnp
from flax import struct

from remidi.envs.interface import UnderspecifiedEnv


@struct.dataclass
class SeqLevel:
    obs: jnp.ndarray  # i32[L]
    length: jnp.ndarray  # i32[]
    reward: jnp.ndarray  # f32[]


@struct.dataclass
class SeqState:
    level: SeqLevel
    t: jnp.ndarray


class SeqEnv(UnderspecifiedEnv):
    num_actions = 2

    def reset_env_to_level(self, rng, level, params):
        return level.obs[0], SeqState(level=level, t=jnp.asarray(0))

    def step_env(self, rng, state, action, params):
        t = state.t + 1
        done = t >= state.level.length
        obs = state.level.obs[jnp.minimum(t, state.level.obs.shape[0] - 1)]
        reward = jnp.where(done, state.level.reward, 0.0)
        return obs, state.replace(t=t), reward, done, {}

    def action_space(self, params):
        from gymnax.environments import spaces

        return spaces.Discrete(2)


def level(obs, reward=1.0, length=None):
    obs = jnp.asarray(obs, jnp.int32)
    return SeqLevel(obs=obs, length=jnp.asarray(len(obs) if length is None else length), reward=jnp.asarray(reward))


def stack(*levels):
    import jax

    return jax.tree.map(lambda *x: jnp.stack(x), *levels)
