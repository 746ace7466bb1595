"""Level-building MDPs: the environment a learned level generator (PAIRED's adversary) acts in.

A :class:`LevelBuilder` is an ordinary ``UnderspecifiedEnv`` (as JaxUED's ``MazeEditor``): an
episode starts from an empty design (``reset_to_level`` ignores its level: pass ``None``), each
action places one part, and it ends after exactly :attr:`num_steps` actions, when :meth:`built`
reads the level off the state. An action invalid at its step changes nothing; the reward is
always 0 (PAIRED pays on the last step).

Observation: ``design`` (what the task shows of it), ``time`` (one-hot f32[num_steps]) and
``noise`` (f32[noise_dim], uniform on [0, 1) per reset, never zeroed, so a deterministic policy
can still make many levels)."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from remidi.envs.interface import UnderspecifiedEnv

NOISE_DIM = 50  # PAIRED's random_z_dim (DCD)


@struct.dataclass
class BuilderState:
    design: Any  # the task's design state (a pytree)
    time: jax.Array  # i32[]: design actions taken
    noise: jax.Array  # f32[noise_dim]
    key: jax.Array  # the episode's randomness (for parts of a level no action chooses)


class LevelBuilder(UnderspecifiedEnv):
    """The base of a level-building MDP: subclasses define :attr:`num_steps`, :attr:`num_actions`,
    :meth:`empty` (from the episode's key), :meth:`place` (one action at step ``t``), :meth:`show`
    and :meth:`built`."""

    num_steps: int
    num_actions: int
    noise_dim: int = NOISE_DIM

    @property
    def default_params(self):
        return None

    def action_space(self, params):
        from gymnax.environments import spaces

        return spaces.Discrete(self.num_actions)

    # the task's part -----------------------------------------------------------------------
    def empty(self, key) -> Any:
        raise NotImplementedError

    def place(self, design, t, action) -> Any:
        raise NotImplementedError

    def show(self, design) -> jax.Array:
        raise NotImplementedError

    def built(self, state: BuilderState):
        """The level of the finished design in ``state``."""
        raise NotImplementedError

    # the MDP ---------------------------------------------------------------------------------
    def observation(self, state: BuilderState) -> dict:
        return {"design": self.show(state.design), "time": jax.nn.one_hot(state.time, self.num_steps),
                "noise": state.noise}

    def reset_env_to_level(self, rng, level, params):
        """The empty design; ``rng`` itself is the episode's key (:attr:`BuilderState.key`, for
        parts of a level no action chooses), its noise is drawn with ``fold_in(rng, 1)``."""
        state = BuilderState(design=self.empty(rng), time=jnp.zeros((), jnp.int32),
                             noise=jax.random.uniform(jax.random.fold_in(rng, 1), (self.noise_dim,)), key=rng)
        return self.observation(state), state

    def step_env(self, rng, state: BuilderState, action, params):
        design = self.place(state.design, state.time, jnp.asarray(action, jnp.int32))
        state = state.replace(design=design, time=state.time + 1)
        done = state.time >= self.num_steps
        return self.observation(state), state, jnp.float32(0.0), done, {}

    def build(self, rng, actions):
        """The level built by the design ``actions`` i32[num_steps] from a reset with ``rng``."""
        _, state = self.reset_env_to_level(rng, None, None)
        state = jax.lax.fori_loop(0, self.num_steps, lambda t, s: self.step_env(rng, s, actions[t], None)[1], state)
        return self.built(state)
