"""Brax robotics: ant, halfcheetah, hopper, walker2d with two kinds of level.

A level (:class:`BraxLevel`) is one of

- **type A**: a per-action-dimension multiplier ``theta f32[A]``. The agent's action (from an
  unbounded Gaussian policy) is multiplied by ``theta`` and handed to the simulator:
  ``brax_env.step(state, theta * action)``, as the paper does; nothing clips it before the
  multiplication, so for ``theta < 1`` the agent can still reach full torque by acting larger
  (the paper's argument that the optimum is the same on every type A level). The
  reward is Brax's own reward, so its control cost is computed on ``theta · a``: the
  disturbance acts on the motor and the cost is what the motor spends (a choice: the paper
  does not say, and its Brax code is not published); the simulator itself clips
  the control ``theta · a`` to the actuator range ``[-1, 1]`` (MuJoCo's ``ctrlrange``), so
  torque saturates there while the control cost keeps growing. The episode ends on
  Brax's own termination (unhealthy hopper/walker/ant; halfcheetah never terminates) or at the
  time limit (``t + 1 >= 100``). Observation: Brax's observation followed by the flag ``[1, 0]``.
- **type B**: a one-step guessing game. The first action ends the episode with reward
  ``+10000`` if the sign of the last action dimension matches the hidden ``sign``
  (``(action[-1] > 0) == sign``), else ``-10000``. The observation is the same for every type B
  level (whatever its seed, theta, sign: ReMiDi's tracker compares observations exactly): the
  joint-position entries of Brax's observation are ``-1``, every other entry ``0``, followed by
  the flag ``[0, 1]``.

The level's ``seed u32[2]`` (threefry key data, e.g. ``jax.random.PRNGKey(i)``) draws Brax's
reset noise: ``reset_env_to_level`` ignores its key, so an episode is a deterministic function
of the level and the actions (``UEDTask.deterministic_reset``). A type B level still carries a
valid Brax state (reset from its seed, never stepped), so the type A branch, which ``vmap``
computes for every level, never runs physics on garbage; the branches are merged with
``where``, which does not let a discarded branch's values through.

Backend: ``mjx`` (MuJoCo in JAX) with the fast solver options Brax sets for its MJX ant (Newton
solver, ``iterations=1``, ``ls_iterations=4``, Euler damping disabled), for every morphology: MuJoCo's
own dynamics at about ``generalized``'s accuracy, faster than ``generalized`` on a CPU, and the
backend meant for accelerators. The measurements behind the choice (throughput and compile time
of every backend, fidelity against MJX with the MJCF options, NaN checks) are in
``docs/performance.md``, "Brax backends".

``backend=`` overrides the default in :func:`brax_task`.

Bit-identity caveat (measured on this CPU, hopper, 20 steps, 4 levels): the *same* levels and
actions stepped in a batch of another size give observations that differ in the last bits, from
the first steps on: up to ~2e-6 with ``mjx`` (whose results can even depend on a level's position
inside a batch of the same size), ~2e-5 ``generalized``, ~6e-6 ``spring``, ~5e-4 ``positional``.
ReMiDi's tracker compares observations exactly, so a type A level replayed beside its frozen
copy in another batch layout may be judged distinguishable after a few steps. The rollout steps
each env and its tracker slots in one batch (``[N, 1 + S]``), so the copy differs only in its
position; at other positions of a batch of 4 the observations agreed bit for bit in
``tests/test_brax_env.py`` (this CPU, 20 steps). Type B levels (constant observation) and the
type A/B flag are unaffected.

Brax is imported lazily (``import brax`` takes ~1.5 s), so importing this module is cheap; its
harmless "Failed to import warp" notice is kept off stdout.
"""

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

# Number of leading observation entries that are (joint) positions, with Brax's default
# ``exclude_current_positions_from_observation=True``: the generalized coordinates ``q`` minus
# the excluded root x (and y for ant). ant: q = 7 (free joint) + 8 hinges = 15, minus x, y -> 13;
# halfcheetah: q = 3 root + 6 = 9, minus x -> 8; hopper: 3 root + 3 = 6, minus x -> 5;
# walker2d: 3 root + 6 = 9, minus x -> 8. (Checked against ``sys.q_size()`` in the tests.)
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
    """The underlying Brax environment: ``brax.envs.get_environment`` with default options, and
    for ``mjx`` the fast solver options of Brax's MJX ant (Newton, 1 iteration, 4 line-search
    iterations, no Euler damping)."""
    _check(morphology, backend)
    with contextlib.redirect_stdout(io.StringIO()):  # lazy: slow to import; keep its warp notice off stdout
        import brax.envs

    import mujoco

    # MuJoCo's warnings while Brax loads its model files would go to MUJOCO_LOG.TXT in the user's
    # working directory; route them to Python's warnings instead, except the deprecation notice
    # about Brax's own files ('settotalmass'), which users cannot act on
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
    """A Brax morphology as an underspecified environment (see the module docstring)."""

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
        """theta ~ U[theta_low, theta_high]^A, type B with prob ``type_b_prob``, sign a fair coin,
        seed from ``rng``. Unused fields are canonical (theta = 1 for type B, sign = False for
        type A), so levels that play identically with the same seed are equal."""
        k_theta, k_b, k_sign, k_seed = jax.random.split(rng, 4)
        type_b = jax.random.bernoulli(k_b, type_b_prob)
        theta = jax.random.uniform(k_theta, (self.num_actions,), jnp.float32, theta_low, theta_high)
        theta = jnp.where(type_b, jnp.ones_like(theta), theta)
        sign = jax.random.bernoulli(k_sign, 0.5) & type_b
        seed = jax.random.bits(k_seed, (2,), jnp.uint32)
        return BraxLevel(theta=theta, type_b=type_b, sign=sign, seed=seed)

    def mutate_level(self, rng, level: BraxLevel, num_edits: int, theta_low: float = 0.5,
                     theta_high: float = 1.5) -> BraxLevel:
        """ACCEL's Brax editor. A type A level: each of ``num_edits`` edits moves θ of one random
        action dimension by N(0, (0.1 (theta_high − theta_low))²), clipped to [theta_low,
        theta_high]. A type B level stays type B (θ stays canonical): each edit flips its sign
        with probability 1/2 (another guessing game, which plays identically until its one step)."""
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
    """The Brax domain's level-building MDP, θ discretised: the first action ``a`` picks the
    level's type from ``a mod 3`` (0: type A; 1: type B, positive sign wins; 2: type B, negative
    sign wins); then one action per action dimension picks its multiplier from
    ``bins`` evenly spaced values over ``[theta_low, theta_high]`` (ends included; action ``a <
    bins`` gives ``theta_low + a·(theta_high − theta_low)/(bins − 1)``, any other changes nothing:
    θ stays 1). A type B level's θ stays 1 (canonical, as the sampler's); the reset noise's seed
    comes from the episode's key. The sampler's θ are continuous, so a sampled type A level is
    built to within half a bin."""

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
    """A Brax morphology as a UED task. Cached: the same arguments give the same task.

    ``reference_return``: the return of a policy trained to convergence without disturbance (the
    optimal return of a type A level); without it the perfect-regret score is unavailable.
    ``reference_discounted_return``: that policy's discounted return Σ_t γ^t r_t (the optimum of
    the paper's utility, for the default discounted perfect regret; measured at the γ the
    reference was trained with, the experiments' ``ppo.gamma``).
    Raises ``ConfigError`` for an unknown morphology or backend.
    """
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
