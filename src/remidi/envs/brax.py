"""Brax robotics: ant, halfcheetah, hopper, walker2d with two kinds of level (:class:`BraxLevel`).

- **type A**: a per-action-dimension multiplier ``theta f32[A]``: the simulator gets
  ``theta * action`` of the unbounded Gaussian policy, unclipped before the multiplication, so
  the agent can still reach full torque for ``theta < 1`` (the paper's argument that every type
  A level has the same optimum). Brax's reward, so its control cost is on ``theta · a`` (our
  choice: the paper does not say); the simulator clips ``theta · a`` to ``[-1, 1]``. Ends on
  Brax's termination or at ``t + 1 >= 100``. Observation: Brax's, then the flag ``[1, 0]``.
- **type B**: a one-step guessing game: reward ``+10000`` if ``(action[-1] > 0) == sign``, else
  ``-10000``. Every type B level shows the same observation (ReMiDi's tracker compares exactly):
  joint positions ``-1``, other entries ``0``, then the flag ``[0, 1]``.

The level's ``seed u32[2]`` (threefry key data) draws Brax's reset noise; the reset ignores its
key (``UEDTask.deterministic_reset``). A type B level still carries a valid, never-stepped Brax
state, so the type A branch that ``vmap`` computes never runs physics on garbage.

Backend: ``mjx`` with Brax's fast MJX-ant solver options (Newton, 1 iteration, 4 line-search
iterations, no Euler damping) for every morphology: about ``generalized``'s accuracy, faster on a
CPU, and meant for accelerators (measurements: ``docs/performance.md``, "Brax backends").

Caveat: the same levels and actions in a batch of another size differ in the last bits (up to
~2e-6 with ``mjx``, ~5e-4 ``positional``), so a type A level replayed in another batch layout may
be judged distinguishable; the rollout steps envs and tracker slots in one batch, where they
agreed bit for bit (``tests/test_brax_env.py``). Type B levels are unaffected.

Brax is imported lazily (~1.5 s), its "Failed to import warp" notice kept off stdout."""

from __future__ import annotations

import contextlib
import functools
import io
import warnings
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from remidi.envs.builder import LevelBuilder
from remidi.envs.interface import UEDTask, UnderspecifiedEnv, tree_select
from remidi.errors import one_of

MORPHOLOGIES = ("ant", "halfcheetah", "hopper", "walker2d")
BACKENDS = ("generalized", "positional", "spring", "mjx")
DEFAULT_BACKEND = "mjx"

EPISODE_LENGTH = 100
TYPE_B_REWARD = 10000.0

# leading observation entries that are positions: q minus the root x (and y for ant) Brax drops
# (ant 15 − 2, halfcheetah 9 − 1, hopper 6 − 1, walker2d 9 − 1; checked against sys.q_size() in the tests)
NUM_POSITIONS = {"ant": 13, "halfcheetah": 8, "hopper": 5, "walker2d": 8}
# The q entries Brax drops from the observation (checked in the tests).
NUM_EXCLUDED_POSITIONS = {"ant": 2, "halfcheetah": 1, "hopper": 1, "walker2d": 1}

FLAG_A = (1.0, 0.0)
FLAG_B = (0.0, 1.0)


@struct.dataclass
class BraxLevel:
    theta: jax.Array  # f32[A] per-action-dimension multiplier (type A); ones for type B
    type_b: jax.Array  # bool[]
    sign: jax.Array  # bool[] (type B: True means a positive last action dimension wins)
    seed: jax.Array  # u32[2] threefry key data for Brax's reset noise


@struct.dataclass
class BraxEnvState:
    brax_state: Any  # brax.envs.base.State (a valid reset state for type B levels)
    level: BraxLevel
    time: jax.Array  # i32[] steps taken in this episode


@struct.dataclass
class BraxParams:
    max_steps_in_episode: int = EPISODE_LENGTH


def _check(morphology: str, backend: str) -> None:
    if morphology not in MORPHOLOGIES:
        raise one_of("morphology", morphology, MORPHOLOGIES)
    if backend not in BACKENDS:
        raise one_of("backend", backend, BACKENDS)


def make_brax_env(morphology: str, backend: str):
    """The underlying Brax env (default options; for ``mjx`` the fast MJX-ant solver options)."""
    _check(morphology, backend)
    with contextlib.redirect_stdout(io.StringIO()):  # lazy: slow to import; keep its warp notice off stdout
        import brax.envs

    import mujoco

    # MuJoCo's warnings go to Python's (not MUJOCO_LOG.TXT in the user's folder), but for the
    # 'settotalmass' notice about Brax's own files, which users cannot act on
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda msg: None if "settotalmass" in msg else warnings.warn(f"MuJoCo: {msg}"))
    try:
        with warnings.catch_warnings():  # Brax's notice that its own pipelines are unmaintained (mjx is what we use)
            warnings.filterwarnings("ignore", message="Brax System, piplines and environments")
            env = brax.envs.get_environment(morphology, backend=backend)
    finally:
        mujoco.set_mju_user_warning(previous)
    if backend == "mjx":
        # Brax's own MJX settings for ant, for every morphology (see the module docstring).
        env.sys = env.sys.tree_replace({
            "opt.solver": mujoco.mjtSolver.mjSOL_NEWTON,
            "opt.iterations": 1,
            "opt.ls_iterations": 4,
            "opt.disableflags": mujoco.mjtDisableBit.mjDSBL_EULERDAMP,
        })
    return env


def _seed_key(seed: jax.Array) -> jax.Array:
    return jax.random.wrap_key_data(jnp.asarray(seed, jnp.uint32), impl="threefry2x32")


def seed_data(i) -> jax.Array:
    """u32[2]: the key data of ``PRNGKey(i)`` (threefry), whatever JAX's default PRNG."""
    return jax.random.key_data(jax.random.key(i, impl="threefry2x32"))


class BraxUED(UnderspecifiedEnv):
    """A Brax morphology as an underspecified environment (module docstring)."""

    def __init__(self, morphology: str = "hopper", backend: str = DEFAULT_BACKEND):
        _check(morphology, backend)
        self.morphology = morphology
        self.backend = backend
        self.brax_env = make_brax_env(morphology, backend)
        self.num_actions = int(self.brax_env.action_size)
        reset_shape = jax.eval_shape(self.brax_env.reset, jax.random.PRNGKey(0))
        self.brax_obs_size = int(reset_shape.obs.shape[-1])
        self.obs_size = self.brax_obs_size + 2
        self.num_positions = NUM_POSITIONS[morphology]
        obs_b = np.zeros(self.obs_size, np.float32)
        obs_b[: self.num_positions] = -1.0
        obs_b[-2:] = FLAG_B
        self._obs_b = obs_b

    @property
    def default_params(self) -> BraxParams:
        return BraxParams()

    def action_space(self, params):
        from gymnax.environments import spaces

        return spaces.Box(-1.0, 1.0, (self.num_actions,), jnp.float32)

    def type_b_observation(self) -> jax.Array:
        """f32[obs_size]: the observation of every type B level."""
        return jnp.asarray(self._obs_b)

    def _observe(self, level: BraxLevel, brax_obs: jax.Array) -> jax.Array:
        obs_a = jnp.concatenate([brax_obs.astype(jnp.float32), jnp.asarray(FLAG_A, jnp.float32)])
        return jnp.where(level.type_b, self.type_b_observation(), obs_a)

    def reset_env_to_level(self, rng, level: BraxLevel, params):
        del rng  # deterministic given the level
        brax_state = self.brax_env.reset(_seed_key(level.seed))
        state = BraxEnvState(brax_state=brax_state, level=level, time=jnp.asarray(0, jnp.int32))
        return self._observe(level, brax_state.obs), state

    def step_env(self, rng, state: BraxEnvState, action, params):
        level = state.level
        action = jnp.asarray(action, jnp.float32)
        # type A: the multiplier acts on the agent's action before the simulator, whose own control
        # limits then apply. (Brax's step updates ``state.metrics`` in place: give it a copy.)
        current = state.brax_state.replace(metrics=dict(state.brax_state.metrics))
        stepped = self.brax_env.step(current, level.theta * action)
        time = state.time + 1
        done_a = (stepped.done > 0.5) | (time >= params.max_steps_in_episode)
        # type B: one step, the sign of the last action dimension against the hidden sign.
        reward_b = jnp.where((action[-1] > 0) == level.sign, TYPE_B_REWARD, -TYPE_B_REWARD)
        # A type B level keeps its (valid, never stepped) reset state.
        brax_state = tree_select(level.type_b, state.brax_state, stepped)
        reward = jnp.where(level.type_b, reward_b, stepped.reward).astype(jnp.float32)
        done = level.type_b | done_a
        obs = self._observe(level, stepped.obs)
        return obs, BraxEnvState(brax_state=brax_state, level=level, time=time), reward, done, {}

    def sample_level(self, rng, theta_low: float = 0.5, theta_high: float = 1.5,
                     type_b_prob: float = 0.5) -> BraxLevel:
        """theta ~ U[theta_low, theta_high]^A, type B with prob ``type_b_prob``, sign a fair coin.

        Unused fields are canonical (theta = 1 for type B, sign = False for type A), so levels that play
        identically are equal."""
        k_theta, k_b, k_sign, k_seed = jax.random.split(rng, 4)
        type_b = jax.random.bernoulli(k_b, type_b_prob)
        theta = jax.random.uniform(k_theta, (self.num_actions,), jnp.float32, theta_low, theta_high)
        theta = jnp.where(type_b, jnp.ones_like(theta), theta)
        sign = jax.random.bernoulli(k_sign, 0.5) & type_b
        seed = jax.random.bits(k_seed, (2,), jnp.uint32)
        return BraxLevel(theta=theta, type_b=type_b, sign=sign, seed=seed)

    def mutate_level(self, rng, level: BraxLevel, num_edits: int, theta_low: float = 0.5,
                     theta_high: float = 1.5) -> BraxLevel:
        """ACCEL's editor: each edit moves one random θ by N(0, (0.1 (high − low))²), clipped; a type B
        level stays type B, each edit flipping its sign with probability 1/2."""
        def edit(lv: BraxLevel, key):
            k_dim, k_step, k_sign = jax.random.split(key, 3)
            dim = jax.random.randint(k_dim, (), 0, self.num_actions)
            step = 0.1 * (theta_high - theta_low) * jax.random.normal(k_step)
            theta = lv.theta.at[dim].set(jnp.clip(lv.theta[dim] + step, theta_low, theta_high))
            sign = lv.sign ^ jax.random.bernoulli(k_sign)
            return lv.replace(theta=jnp.where(lv.type_b, lv.theta, theta), sign=jnp.where(lv.type_b, sign, lv.sign)), None

        return jax.lax.scan(edit, level, jax.random.split(rng, num_edits))[0]

    def undisturbed_levels(self, n: int) -> BraxLevel:
        """``n`` type A levels with theta = 1 and seeds ``PRNGKey(i)``, ``i < n`` (batched)."""
        return BraxLevel(theta=jnp.ones((n, self.num_actions), jnp.float32),
                         type_b=jnp.zeros((n,), bool), sign=jnp.zeros((n,), bool),
                         seed=jax.vmap(seed_data)(jnp.arange(n)))


class BraxBuilder(LevelBuilder):
    """The Brax level-building MDP, θ discretised.

    First action ``a mod 3``: 0 type A, 1 type B positive sign, 2 type B negative sign; then one
    action per dimension picks θ from ``bins`` even values over ``[theta_low, theta_high]`` (an
    action ≥ ``bins`` leaves θ = 1). Type B keeps θ = 1; the seed comes from the episode's key."""

    def __init__(self, num_dims: int, theta_low: float = 0.5, theta_high: float = 1.5, bins: int = 11):
        self.num_dims, self.low, self.high, self.bins = num_dims, theta_low, theta_high, bins
        self.num_steps = 1 + num_dims
        self.num_actions = max(3, bins)

    def empty(self, key) -> BraxLevel:
        return BraxLevel(theta=jnp.ones((self.num_dims,), jnp.float32), type_b=jnp.asarray(False),
                         sign=jnp.asarray(False), seed=jax.random.bits(key, (2,), jnp.uint32))

    def place(self, design: BraxLevel, t, action) -> BraxLevel:
        kind = design.replace(type_b=action % 3 != 0, sign=action % 3 == 1)
        value = self.low + action.astype(jnp.float32) * (self.high - self.low) / (self.bins - 1)
        dim = jnp.clip(t - 1, 0, self.num_dims - 1)
        theta = design.replace(theta=jnp.where((action < self.bins) & ~design.type_b,
                                               design.theta.at[dim].set(value), design.theta))
        return jax.tree.map(lambda a, b: jnp.where(t == 0, a, b), kind, theta)

    def show(self, design: BraxLevel) -> jax.Array:
        return jnp.concatenate([design.theta, jnp.stack([design.type_b, design.sign]).astype(jnp.float32)])

    def built(self, state) -> BraxLevel:
        return state.design


@functools.lru_cache(maxsize=None)
def brax_task(morphology: str, backend: str = DEFAULT_BACKEND, theta_low: float = 0.5,
              theta_high: float = 1.5, type_b_prob: float = 0.5, reference_return: float | None = None,
              num_eval_levels: int = 16, reference_discounted_return: float | None = None) -> UEDTask:
    """A Brax morphology as a UED task (cached per arguments); ConfigError for an unknown morphology
    or backend.

    ``reference_return``: the return of a policy trained without disturbance (a type A level's
    optimum; None: no perfect regret). ``reference_discounted_return``: its Σ_t γ^t r_t at the
    experiments' ``ppo.gamma``."""
    _check(morphology, backend)
    env = BraxUED(morphology, backend)
    optimal_return = optimal_discounted = None
    if reference_return is not None:
        ref = float(reference_return)
        optimal_return = lambda level: jnp.where(level.type_b, TYPE_B_REWARD, ref)  # noqa: E731
    if reference_discounted_return is not None:  # type B pays once, at t = 0: undiscounted
        dref = float(reference_discounted_return)
        optimal_discounted = lambda level, gamma: jnp.where(level.type_b, TYPE_B_REWARD, dref)  # noqa: E731
    return UEDTask(
        env=env,
        params=env.default_params,
        sample_level=lambda rng: env.sample_level(rng, theta_low, theta_high, type_b_prob),
        num_actions=env.num_actions,
        max_episode_steps=EPISODE_LENGTH,
        optimal_return=optimal_return,
        optimal_discounted_return=optimal_discounted,
        eval_sets={"undisturbed": env.undisturbed_levels(num_eval_levels)},
        level_tags=lambda level: {"type_b": level.type_b},
        solved=None,  # a return > 0 is no solve criterion for a walker: no solve_rate, no learnability
        mutate_level=lambda rng, level, edits: env.mutate_level(rng, level, edits, theta_low, theta_high),
        level_builder=BraxBuilder(env.num_actions, theta_low, theta_high),
        deterministic_reset=True,
        continuous=True,
    )
