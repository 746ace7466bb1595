"""The environment interface: ``jaxued``'s ``UnderspecifiedEnv``, plus what UED needs around it.

An environment is a ``jaxued.environments.UnderspecifiedEnv`` (bring your own: any subclass
works): ``obs, state = env.reset_to_level(rng, level, params)`` and ``obs, state, reward,
done, info = env.step(rng, state, action, params)``, levels are pytrees, and the environment
never resets by itself. :class:`AutoReplay` restarts the *same* level when an episode ends.

A :class:`UEDTask` bundles an environment with the level generator and the extras the engine
uses: the optimal return of a level (for the perfect-regret score), named evaluation level
sets, and boolean level tags to report (e.g. which levels hide the answer).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import jax
import jax.numpy as jnp
from flax import struct

from remidi.envs.actions import ActionSpace, Box, Discrete, as_action_space


def _jaxued_interface():
    """``jaxued.environments.underspecified_env``, the module of the interface we share with
    jaxued, without running ``jaxued.environments``' ``__init__`` until something else needs it:
    that imports jaxued's maze, which imports gymnax's every environment and seaborn, seconds of
    start-up for every process (the CLI's included) that never touches a maze. The module is
    registered under its own name, so a later import of the package finds it there and jaxued's
    classes stay the same objects (``tests/test_interface_import.py``)."""
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

    On a terminal step the returned observation and state are those of the fresh episode on the
    same level; ``done`` is still True for that step, and the reward is the terminal reward.

    With ``deterministic_reset`` (the wrapped ``reset_to_level`` ignores its key, as
    ``UEDTask.deterministic_reset`` promises) the first observation and state are kept from the
    reset and restored on restart, instead of resetting again at every step: the same result,
    without a reset in the step's program (for Brax, a forward-kinematics pass per step and
    several seconds of compilation).

    With ``solved_info`` (the info key a task's ``solved`` names) the state keeps that key's value
    at the last step as ``state.solved`` (:func:`info_flag`), which a restart leaves as it was:
    the rollout records it (``Trajectory.solved``) where the terminal step's info is gone.
    """

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
        """The wrapper's state at the start of an episode whose first observation and state the
        wrapped environment's reset returned."""
        start = (obs, state) if self._deterministic_reset else None
        solved = jnp.asarray(False) if self._solved_info is not None else None
        return AutoReplayState(env_state=state, level=level, start=start, solved=solved)

    def step_env(self, rng, state: AutoReplayState, action, params):
        rng_step, rng_reset = jax.random.split(rng)
        stepped = self._env.step(rng_step, state.env_state, action, params)
        return self.restart_where_done(state, stepped, params, rng_reset)

    def restart_where_done(self, state: AutoReplayState, stepped, params, rng_reset=None):
        """The second half of :meth:`step_env`: given the wrapped environment's ``stepped =
        (obs, env_state, reward, done, info)`` (from ``state.env_state``, with the first half of
        ``split(rng)``), restart the level where the episode ended. ``rng_reset`` (the second
        half) is unused with ``deterministic_reset``."""
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
    """bool[]: the step's ``info[key]`` read as a flag: truthy (nonzero), and for an array (e.g.
    one flag per agent) every entry truthy."""
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
    """Everything the UED engine needs to know about a domain.

    Compared and hashed by identity, so that compiled train steps are reused for the same task.

    Attributes:
        env: the (non-resetting) environment.
        params: its ``EnvParams``.
        sample_level: ``rng -> level``, the random level generator (domain randomisation).
        action_space: the actions (:mod:`remidi.envs.actions`): ``Discrete(n)`` (``i32[]``),
            ``MultiDiscrete(nvec)`` (``i32[k]``, one choice per component) or ``Box(dims)``
            (``f32[dims]``, unbounded: the environment clips); or the environment's own space
            (gymnax's, Kinetix's, JaxMARL's, gymnasium's), converted to one of those
            (:func:`~remidi.envs.actions.from_env_space`). Or the shorthand:
        num_actions: ``Discrete(num_actions)``, or with ``continuous`` ``Box(num_actions)``. Given
            beside ``action_space``, the two must agree (``Discrete``/``Box`` only). Read the
            space as :attr:`actions` (set for either declaration).
        max_episode_steps: an upper bound on an episode's length (evaluation rolls this long).
        optimal_return: ``level -> f32[]`` best achievable (undiscounted) return, or None if
            unknown (then the perfect-regret score is unavailable).
        optimal_discounted_return: ``(level, gamma) -> f32[]``, the best achievable discounted
            return E[Σ_t γ^t r_t] (t counted from the episode's first step, ``gamma`` a static
            float): the optimum of the paper's utility, which the default perfect-regret score
            uses (``UEDConfig.discounted_regret``). For a one-step task it is ``optimal_return``
            (:func:`one_step_discounted`).
        eval_sets: name → level batch (leading dim = number of levels) to report solve rates on.
        eval_envs: name → the environment that plays that evaluation set, where it is not ``env``
            (e.g. a held-out maze larger than the training grid); same ``params``.
        level_tags: ``level -> dict[str, bool[]]``, properties reported as replay/buffer
            fractions (e.g. ``{"hidden": ...}``).
        solved: when an episode counts as solved (``solve_rate/<set>``, the learnability score,
            SFL): a function of its return, ``f32[N] -> bool[N]`` (default: return > 0); or the
            name of a key of the step's info dict (``env.step``'s fifth output) whose value at the
            episode's last step says so (truthy; an array, e.g. one flag per agent, when all its
            entries are: :func:`info_flag`), for an environment that reports success itself where
            the return does not tell (JaxNav's goal flag); the return then does not enter. None for a
            task without a notion of solving (no ``solve_rate`` metric, no learnability score).
        expected_return: for a one-step task with ``Discrete(n)`` actions, ``(level, probs f32[n]) -> f32[]``, the
            exact expected return of a policy with those action probabilities; makes the
            evaluation's regret exact (instead of sampled) and adds the policy's entropy.
        mutate_level: ``(rng, level, num_edits: int) -> level``, ACCEL's level editor: at most
            ``num_edits`` small changes (e.g. a wall added or removed), returning a valid level of
            the same shapes; None for a task without one (ACCEL cannot run on it).
        easy_level: ``rng -> level``, the generator of ACCEL's "easy start" (e.g. mazes without
            walls, ``accel.easy_start``); None for a task without one.
        level_builder: the task's level-building MDP (:class:`remidi.envs.builder.LevelBuilder`),
            the environment a learned level generator (PAIRED) acts in; None for a task without
            one (the generator algorithms cannot run on it).
        reseed_level: ``(rng, level) -> level``, the level with its own randomness drawn afresh
            (a level that carries its environment's random seed, so that the environment is
            deterministic given the level: :mod:`remidi.envs.noisy`); with the ``reseed`` config
            key every rollout plays its levels so, as the stochastic environment would. None:
            the task has no such randomness.
        deterministic_reset: ``env.reset_to_level`` ignores its key (the level fixes the start,
            as in every environment of this package). Lets ReMiDi use the candidate tracker,
            whose cost per step does not grow with the number of frozen levels; leave False for
            an environment that draws its start at random (the reference tracker then runs).
        continuous: with ``num_actions``, the actions are ``Box(num_actions)``.
        actions: (derived, not a constructor argument) the action space either declaration gives.
    """

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
    """``UEDTask.optimal_discounted_return`` of a task whose episodes last one step: its reward
    comes at t = 0, undiscounted (γ^0 = 1), so the discounted optimum is the optimum."""
    return lambda level, gamma: optimal_return(level)
