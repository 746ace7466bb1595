"""PAIRED's pieces (Dennis et al., 2020): the regret estimate a learned level generator is paid,
and the generator's sparse reward.

PAIRED trains three policies: a *generator* that builds levels action by action in the task's
level-building MDP (:mod:`remidi.envs.builder`), a *protagonist* (the agent UED trains) and an
*antagonist* that estimates what is achievable on each generated level. After both agents play a
level, the generator receives a regret estimate on its episode's last step, and nothing before:

* ``paired``: the antagonist's best episodic return minus the protagonist's mean (the original);
* ``flexible``: the best return of either agent minus the mean of both agents' means (Jiang et
  al., 2021's "flexible PAIRED": neither agent is tied to a role);
* ``perfect``: the task's exact optimal return minus the protagonist's mean (the paper's
  "antagonist that is optimal on each level and does not learn"; needs ``UEDTask.optimal_return``).

Negative regret (the protagonist beats the antagonist's best) is passed on as it is, unless
``clip_negative`` asks for 0: clipping hides from the generator which levels the antagonist has
not learned yet. All functions are pure, shapes in their docstrings.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

ESTIMATORS = ("paired", "flexible", "perfect")


def regret_estimate(estimator: str, protagonist_mean, protagonist_best, antagonist_mean=None, antagonist_best=None,
                    optimal=None, clip_negative: bool = False) -> jax.Array:
    """f32[N]: the generator's regret estimate per level.

    ``protagonist_mean``, ``protagonist_best``: f32[N], the protagonist's mean and best episodic
    return on each level (``scores.episode_returns``); ``antagonist_mean``, ``antagonist_best``:
    the antagonist's (``paired``, ``flexible``); ``optimal``: f32[N], the task's optimal return
    (``perfect``). ``estimator`` and ``clip_negative`` are static."""
    if estimator == "paired":
        regret = antagonist_best - protagonist_mean
    elif estimator == "flexible":
        regret = jnp.maximum(antagonist_best, protagonist_best) - 0.5 * (antagonist_mean + protagonist_mean)
    elif estimator == "perfect":
        regret = optimal - protagonist_mean
    else:
        raise ValueError(f"regret estimator must be one of {ESTIMATORS}, got {estimator!r}")
    return jnp.maximum(regret, 0.0) if clip_negative else regret


def generator_rewards(regret: jax.Array, num_steps: int) -> tuple[jax.Array, jax.Array]:
    """The generator's episode as a reward signal: ``(rewards f32[T, N], dones bool[T, N])`` with
    T = ``num_steps`` (the level-building MDP's budget), the regret ``f32[N]`` on the last step and
    0 before, and the episode ending there, so GAE never bootstraps past the generator's episode
    (:func:`remidi.engine.ppo.compute_gae` gives ``reward − V`` at its last step whatever value
    follows)."""
    n = regret.shape[0]
    last = jnp.arange(num_steps)[:, None] == num_steps - 1
    rewards = jnp.where(last, regret[None, :], 0.0).astype(jnp.float32)
    return rewards, jnp.broadcast_to(last, (num_steps, n))
