"""The environment interface: ``jaxued``'s ``UnderspecifiedEnv``, plus what UED needs around it.

An environment is any ``jaxued.environments.UnderspecifiedEnv``: ``obs, state =
env.reset_to_level(rng, level, params)``, ``obs, state, reward, done, info = env.step(rng, state,
action, params)``; levels are pytrees and the environment never resets itself
(:class:`AutoReplay` restarts the *same* level). A :class:`UEDTask` bundles it with its level
generator and what the engine uses beside."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import jax
import jax.numpy as jnp
from flax import struct

from remidi.envs.actions import ActionSpace, Box, Discrete, as_action_space


def _jaxued_interface():
    """``jaxued.environments.underspecified_env``, loaded without running ``jaxued.environments``'
    ``__init__``.

    Why: that imports jaxued's maze, gymnax's every env and seaborn, seconds of start-up for every
    process. Registered under its own name, so jaxued's classes stay the same objects."""
    import importlib.util
    import sys

    name = "jaxued.environments.underspecified_env"
    if name in sys.modules:
        return sys.modules[name]
    package = importlib.util.find_spec("jaxued")
    if package is None or not package.submodule_search_locations:
        raise ImportError("remidi needs the jaxued package (pip install jaxued)")
    path = Path(next(iter(package.submodule_search_locations))) / "environments" / "underspecified_env.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


_JAXUED = _jaxued_interface()
EnvParams, UnderspecifiedEnv = _JAXUED.EnvParams, _JAXUED.UnderspecifiedEnv

__all__ = ["UnderspecifiedEnv", "EnvParams", "AutoReplay", "AutoReplayState", "UEDTask", "tree_equal",
           "one_step_discounted", "info_flag"]


@struct.dataclass
class AutoReplayState:
    env_state: Any
    level: Any
    start: Any = None  # (first observation, first state) when the reset is deterministic
    solved: Any = None  # bool[]: the last step's info flag of solving (AutoReplay's solved_info); else None


class AutoReplay(UnderspecifiedEnv):
    """Restart the same level when an episode ends.

    On a terminal step the observation and state are the fresh episode's; ``done`` is True and the
    reward is the terminal one. ``deterministic_reset`` (the reset ignores its key): the first
    observation and state are kept and restored, so the step's program holds no reset (for Brax, a
    kinematics pass per step and seconds of compilation). ``solved_info`` (the info key of a task's
    ``solved``): ``state.solved`` keeps that key's last-step value (:func:`info_flag`), which
    outlives the terminal step's info."""

    def __init__(self, env: UnderspecifiedEnv, deterministic_reset: bool = False, solved_info: str | None = None):
        self._env = env
        self._deterministic_reset = deterministic_reset
        self._solved_info = solved_info

    @property
    def default_params(self):
        return self._env.default_params

    def action_space(self, params):
        return self._env.action_space(params)

    def reset_env_to_level(self, rng, level, params):
        obs, state = self._env.reset_to_level(rng, level, params)
        return obs, self.start_state(obs, state, level)

    def start_state(self, obs, state, level) -> AutoReplayState:
        """The wrapper's state at an episode's start, from the wrapped reset's ``obs`` and ``state``."""
        start = (obs, state) if self._deterministic_reset else None
        solved = jnp.asarray(False) if self._solved_info is not None else None
        return AutoReplayState(env_state=state, level=level, start=start, solved=solved)

    def step_env(self, rng, state: AutoReplayState, action, params):
        rng_step, rng_reset = jax.random.split(rng)
        stepped = self._env.step(rng_step, state.env_state, action, params)
        return self.restart_where_done(state, stepped, params, rng_reset)

    def restart_where_done(self, state: AutoReplayState, stepped, params, rng_reset=None):
        """The second half of :meth:`step_env`: restart the level where the wrapped ``stepped = (obs,
        env_state, reward, done, info)`` ended; ``rng_reset`` is unused with ``deterministic_reset``."""
        obs, env_state, reward, done, info = stepped
        if self._deterministic_reset:
            obs_re, env_state_re = state.start
        else:
            obs_re, env_state_re = self._env.reset_to_level(rng_reset, state.level, params)
        obs = tree_select(done, obs_re, obs)
        env_state = tree_select(done, env_state_re, env_state)
        state = state.replace(env_state=env_state)
        if self._solved_info is not None:
            state = state.replace(solved=info_flag(info, self._solved_info))
        return obs, state, reward, done, info


def info_flag(info, key: str) -> jax.Array:
    """bool[]: ``info[key]`` as a flag: truthy, every entry for an array (e.g. one flag per agent)."""
    return jnp.all(jnp.asarray(info[key]).astype(bool))


def tree_select(pred, on_true, on_false):
    """Leafwise ``where(pred, on_true, on_false)`` for a scalar ``pred``."""
    return jax.tree.map(lambda a, b: jnp.where(pred, a, b), on_true, on_false)


def tree_equal(a, b) -> jax.Array:
    """bool[]: every leaf of ``a`` equals the corresponding leaf of ``b`` everywhere."""
    leaves = jax.tree.leaves(jax.tree.map(lambda x, y: jnp.all(x == y), a, b))
    return jnp.all(jnp.stack(leaves)) if leaves else jnp.asarray(True)


@dataclass(frozen=True, eq=False)
class UEDTask:
    """Everything the UED engine needs to know about a domain (compared and hashed by identity, so
    compiled steps are reused per task).

    Attributes:
        env: the (non-resetting) environment.
    params: its ``EnvParams``.
        sample_level: ``rng -> level``, the random level generator.
        action_space: ``Discrete(n)`` (``i32[]``), ``MultiDiscrete(nvec)`` (``i32[k]``) or
            ``Box(dims)`` (``f32[dims]``, unbounded: the env clips), or the env's own space
            (gymnax, Kinetix, JaxMARL, gymnasium; :func:`~remidi.envs.actions.from_env_space`).
        num_actions: shorthand: ``Discrete(num_actions)``, or ``Box`` with ``continuous``; must agree
            with ``action_space`` if both are given. Read either as :attr:`actions`.
        max_episode_steps: an upper bound on an episode's length (evaluation rolls this long).
        optimal_return: ``level -> f32[]``, best undiscounted return; None: no perfect regret.
        optimal_discounted_return: ``(level, gamma) -> f32[]``, best E[Σ_t γ^t r_t] from the
            episode's first step (``gamma`` static), used by default perfect regret
            (``UEDConfig.discounted_regret``); one-step tasks: :func:`one_step_discounted`.
        eval_sets: name → level batch (leading dim: levels) to report on.
        eval_envs: name → the env that plays that set where it is not ``env`` (same ``params``).
        level_tags: ``level -> dict[str, bool[]]``, reported as replay/buffer fractions.
        solved: when an episode counts as solved (solve rates, learnability, SFL): ``f32[N] ->
            bool[N]`` of the return (default: return > 0), or an info key whose value at the
            episode's last step says so (:func:`info_flag`; the return then does not enter); None:
            no notion of solving.
        expected_return: one-step ``Discrete(n)`` tasks: ``(level, probs f32[n]) -> f32[]``, the
            exact expected return; makes evaluation's regret exact and adds the policy's entropy.
        mutate_level: ``(rng, level, num_edits) -> level``, ACCEL's editor (at most ``num_edits``
            small changes, same shapes); None: no ACCEL.
        easy_level: ``rng -> level``, ACCEL's easy start (``accel.easy_start``); None: none.
        level_builder: the level-building MDP (:class:`remidi.envs.builder.LevelBuilder`) a learned
            generator acts in; None: no PAIRED.
        reseed_level: ``(rng, level) -> level`` with the level's own randomness redrawn
            (:mod:`remidi.envs.noisy`); the ``reseed`` key applies it every rollout. None: none.
        deterministic_reset: ``reset_to_level`` ignores its key; lets ReMiDi use the candidate
            tracker, whose cost does not grow with the frozen levels. False for random starts.
        continuous: with ``num_actions``, the actions are ``Box(num_actions)``.
        actions: (derived) the action space either declaration gives."""

    env: UnderspecifiedEnv
    params: Any
    sample_level: Callable[[jax.Array], Any]
    num_actions: int | None = None
    max_episode_steps: int = None  # required: a missing one is a TypeError, as for sample_level
    optimal_return: Callable[[Any], jax.Array] | None = None
    optimal_discounted_return: Callable[[Any, float], jax.Array] | None = None
    eval_sets: dict[str, Any] = field(default_factory=dict)
    eval_envs: dict[str, UnderspecifiedEnv] = field(default_factory=dict)
    level_tags: Callable[[Any], dict[str, jax.Array]] = lambda level: {}
    solved: Callable[[jax.Array], jax.Array] | str | None = lambda ret: ret > 0
    expected_return: Callable[[Any, jax.Array], jax.Array] | None = None
    mutate_level: Callable[[jax.Array, Any, int], Any] | None = None
    easy_level: Callable[[jax.Array], Any] | None = None
    level_builder: Any = None
    deterministic_reset: bool = False
    continuous: bool = False
    reseed_level: Callable[[jax.Array, Any], Any] | None = None
    action_space: ActionSpace | None = None
    actions: ActionSpace = field(init=False, repr=False)

    def __post_init__(self):
        if self.max_episode_steps is None:
            raise TypeError("UEDTask.__init__() missing required argument: 'max_episode_steps'")
        if self.action_space is None and self.num_actions is None:
            raise TypeError("UEDTask.__init__() needs the actions: action_space= (remidi.envs.actions) or "
                            "num_actions=")
        declared = as_action_space(self.action_space)  # an environment's own space: ours from here on
        object.__setattr__(self, "action_space", declared)
        if declared is None:
            declared = Box(self.num_actions) if self.continuous else Discrete(self.num_actions)
        object.__setattr__(self, "actions", declared)  # checked by validate_task


def one_step_discounted(optimal_return: Callable[[Any], jax.Array]) -> Callable[[Any, float], jax.Array]:
    """``UEDTask.optimal_discounted_return`` of a one-step task: the reward comes at t = 0 (γ^0 = 1)."""
    return lambda level, gamma: optimal_return(level)
