"""Level scores for prioritised replay, from one rollout per level.

Every function maps rollout arrays with leading dims [T, N] to one score per level, f32[N].
Higher = replayed more.

* ``perfect_regret``: optimal return − the agent's mean episodic return (exact regret when
  the environment knows its optimal return).
* ``pvl`` (positive value loss): mean over steps of max(GAE advantage, 0).
* ``maxmc``: mean over steps of (highest return ever achieved on the level − V(s_t)).
* ``neg_return``: −mean episodic return (minimax return).

Episodic returns use the episodes that *ended* inside the rollout; an env whose episode never
ended is credited with the reward collected so far (its partial return).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

SCORES = ("perfect_regret", "pvl", "maxmc", "neg_return")


def episode_returns(reward: jax.Array, done: jax.Array):
    """Mean and max return of the episodes that ended, per env.

    ``reward`` f32[T, N], ``done`` bool[T, N] → ``(mean f32[N], max f32[N], count i32[N])``;
    with no finished episode, mean = max = the partial return and count = 0.
    """

    def step(carry, x):
        running, total, best, count = carry
        r, d = x
        running = running + r
        total = total + jnp.where(d, running, 0.0)
        best = jnp.where(d, jnp.maximum(best, running), best)
        count = count + d
        return (jnp.where(d, 0.0, running), total, best, count), None

    zeros = jnp.zeros(reward.shape[1])
    init = (zeros, zeros, jnp.full(reward.shape[1], -jnp.inf), jnp.zeros(reward.shape[1], jnp.int32))
    (running, total, best, count), _ = jax.lax.scan(step, init, (reward, done))
    mean = jnp.where(count > 0, total / jnp.maximum(count, 1), running)
    best = jnp.where(count > 0, best, running)
    return mean, best, count


def perfect_regret(mean_return: jax.Array, optimal_return: jax.Array) -> jax.Array:
    return optimal_return - mean_return


def positive_value_loss(advantages: jax.Array) -> jax.Array:
    return jnp.mean(jnp.maximum(advantages, 0.0), axis=0)


def max_mc(values: jax.Array, max_return: jax.Array) -> jax.Array:
    """``values`` f32[T, N], ``max_return`` f32[N] (highest return ever seen on the level)."""
    return jnp.mean(max_return[None, :] - values, axis=0)


def negative_return(mean_return: jax.Array) -> jax.Array:
    return -mean_return


def score_levels(name: str, *, mean_return, values, advantages, max_return, optimal_return=None) -> jax.Array:
    """Dispatch on the score's name (static)."""
    if name == "perfect_regret":
        return perfect_regret(mean_return, optimal_return)
    if name == "pvl":
        return positive_value_loss(advantages)
    if name == "maxmc":
        return max_mc(values, max_return)
    if name == "neg_return":
        return negative_return(mean_return)
    raise ValueError(f"score must be one of {SCORES}, got {name!r}")
