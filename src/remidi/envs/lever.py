"""The lever game (paper §6.4): a one-step game where half of the levels hide the answer.

A level is (correct lever, visible?). The observation is a one-hot vector of size
``num_levers + 1``: index 0 means "answer hidden", index ``i > 0`` means "lever ``i − 1`` is
correct". Pulling the correct lever pays ``+1`` (visible) or ``+10`` (hidden), any other lever
``−1`` / ``−10``; the episode ends after one step. The optimal return of a level is ``+1`` or
``+10``, so hidden levels carry irreducible regret ``20·(1 − 1/num_levers)`` for any policy
that cannot see the answer.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from flax import struct

from remidi.envs.builder import LevelBuilder
from remidi.envs.interface import UEDTask, UnderspecifiedEnv, one_step_discounted


@struct.dataclass
class LeverLevel:
    correct: jax.Array  # i32[]
    visible: jax.Array  # bool[]


@struct.dataclass
class LeverState:
    level: LeverLevel
    done: jax.Array  # bool[]


@struct.dataclass
class LeverParams:
    hidden_multiplier: float = 10.0


class LeverGame(UnderspecifiedEnv):
    def __init__(self, num_levers: int = 64):
        self.num_levers = num_levers

    @property
    def default_params(self) -> LeverParams:
        return LeverParams()

    def action_space(self, params):
        from gymnax.environments import spaces

        return spaces.Discrete(self.num_levers)

    def observation(self, level: LeverLevel) -> jax.Array:
        """f32[num_levers + 1] one-hot."""
        index = jnp.where(level.visible, level.correct + 1, 0)
        return jax.nn.one_hot(index, self.num_levers + 1)

    def reset_env_to_level(self, rng, level: LeverLevel, params):
        return self.observation(level), LeverState(level=level, done=jnp.asarray(False))

    def step_env(self, rng, state: LeverState, action, params):
        scale = jnp.where(state.level.visible, 1.0, params.hidden_multiplier)
        reward = jnp.where(action == state.level.correct, 1.0, -1.0) * scale
        return self.observation(state.level), state.replace(done=jnp.asarray(True)), reward, jnp.asarray(True), {}

    def expected_return(self, level: LeverLevel, probs: jax.Array, params: LeverParams) -> jax.Array:
        """f32[]: the exact expected reward of pulling lever ``a`` with probability ``probs[a]``."""
        scale = jnp.where(level.visible, 1.0, params.hidden_multiplier)
        p_correct = probs[level.correct]
        return scale * (p_correct - (1.0 - p_correct))

    def sample_level(self, rng, visible_prob: float = 0.5) -> LeverLevel:
        k1, k2 = jax.random.split(rng)
        return LeverLevel(correct=jax.random.randint(k1, (), 0, self.num_levers),
                          visible=jax.random.uniform(k2) < visible_prob)

    def mutate_level(self, rng, level: LeverLevel, num_edits: int) -> LeverLevel:
        """ACCEL's lever editor: each of ``num_edits`` edits moves the correct lever to a neighbour
        (one up or down, wrapping around); a hidden level stays hidden, a visible one visible."""
        steps = jnp.sum(jnp.where(jax.random.bernoulli(rng, 0.5, (num_edits,)), 1, -1))
        return level.replace(correct=((level.correct + steps) % self.num_levers).astype(level.correct.dtype))

    def all_levels(self, visible: bool) -> LeverLevel:
        """Every level with the given visibility, batched: leading dim num_levers."""
        return LeverLevel(correct=jnp.arange(self.num_levers, dtype=jnp.int32),
                          visible=jnp.full((self.num_levers,), visible))


class LeverBuilder(LevelBuilder):
    """The lever game's level-building MDP: one action ``a`` in ``[0, 2·num_levers)``: lever
    ``a mod num_levers``, visible iff ``a < num_levers``; ``design`` is empty."""

    num_steps = 1

    def __init__(self, num_levers: int = 64):
        self.num_levers = num_levers
        self.num_actions = 2 * num_levers

    def empty(self, key) -> LeverLevel:
        return LeverLevel(correct=jnp.zeros((), jnp.int32), visible=jnp.asarray(True))

    def place(self, design: LeverLevel, t, action) -> LeverLevel:
        valid = (action >= 0) & (action < self.num_actions)
        built = LeverLevel(correct=(action % self.num_levers).astype(jnp.int32), visible=action < self.num_levers)
        return jax.tree.map(lambda new, old: jnp.where(valid, new, old), built, design)

    def show(self, design) -> jax.Array:
        return jnp.zeros((0,), jnp.float32)

    def built(self, state) -> LeverLevel:
        return state.design


@functools.lru_cache(maxsize=None)
def lever_task(num_levers: int = 64, visible_prob: float = 0.5, hidden_multiplier: float = 10.0) -> UEDTask:
    """The lever game as a UED task. Cached: the same arguments give the same (immutable) task,
    so runs in one process reuse its compiled train steps."""
    env = LeverGame(num_levers)
    params = LeverParams(hidden_multiplier=hidden_multiplier)
    optimal = lambda level: jnp.where(level.visible, 1.0, hidden_multiplier)  # noqa: E731
    return UEDTask(
        env=env,
        params=params,
        sample_level=lambda rng: env.sample_level(rng, visible_prob),
        num_actions=num_levers,
        max_episode_steps=1,
        optimal_return=optimal,
        optimal_discounted_return=one_step_discounted(optimal),
        eval_sets={"visible": env.all_levels(True), "hidden": env.all_levels(False)},
        level_tags=lambda level: {"hidden": ~level.visible},
        expected_return=lambda level, probs: env.expected_return(level, probs, params),
        mutate_level=env.mutate_level,
        level_builder=LeverBuilder(num_levers),
        deterministic_reset=True,
    )
