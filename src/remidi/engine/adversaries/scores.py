"""Level scores for prioritised replay: one rollout's arrays [T, N] -> f32[N], higher = replayed more.

* ``perfect_regret``: optimal return − the agent's mean episodic return. Discounted by default
  (``UEDConfig.discounted_regret``), as the paper's U_θ(π) = E[Σ_t γ^t r_t]: the optimum is the
  task's ``optimal_discounted_return`` (mazes: γ^(n−1) for a goal reached with the n-th action,
  so a shortest path has regret exactly 0).
* ``pvl``: per finished episode, the mean over its steps of max(GAE advantage, 0); then the
  mean over finished episodes.
* ``maxmc``: per finished episode, the mean over its steps of (best return ever achieved on the
  level − V(s_t)); then the mean over finished episodes.
* ``neg_return``: −mean episodic return.
* ``learnability`` (SFL): p·(1 − p), p the share of the episodes that ended in the rollout and
  were solved (:func:`episode_solved`).

PVL and MaxMC match the reference implementations (minimax, jaxued) wherever an episode ends:
the steps of an unfinished trailing episode are left out.

A rollout **without any finished episode** (an episode longer than the rollout, e.g. Craftax) is
scored from its truncated episode, bootstrapped by the critic, so such levels are still ranked
(the references score them ``-inf``, and a buffer of them never grows past one level):

* PVL: the mean over all steps of max(A_t, 0) (GAE already bootstraps from V(s_T));
* MaxMC: the mean over the steps of (best − V(s_t)), best = max(the level's record, V(s_0) + A_0);
  that estimate ranks this rollout only, the record keeps finished episodes alone.

``learnability`` needs finished episodes: without one it scores ``-inf`` (never inserted; a
replayed level ranks last until rescored). Episodic returns use the episodes that ended; an env
with none is credited with its partial return."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import jax
import jax.numpy as jnp
from flax import struct

from remidi.errors import ConfigError, check_name


def episode_returns(reward: jax.Array, done: jax.Array, gamma: float = 1.0, *, time_average: bool = False):
    """Mean and max return of the episodes that ended, per env.

    ``reward`` f32[T, N], ``done`` bool[T, N] -> ``(mean f32[N], max f32[N], count i32[N])``.
    ``gamma`` (static) < 1 discounts from each episode's first step; ``time_average`` (static) takes
    each episode's per-step mean instead of its return. With no finished episode, mean = max = the
    partial return (0 for no step) and count = 0."""

    def step(carry, inp):  # running: the current episode's total so far, steps: its length
        running, steps, total, best, count = carry
        xt, d = inp
        weight = 1.0 if gamma == 1.0 else jnp.power(jnp.float32(gamma), steps.astype(jnp.float32))
        running, steps = running + weight * xt, steps + 1
        value = running / steps if time_average else running
        total = total + jnp.where(d, value, 0.0)
        best = jnp.where(d, jnp.maximum(best, value), best)
        count = count + d
        return (jnp.where(d, 0.0, running), jnp.where(d, 0, steps), total, best, count), None

    n = reward.shape[1]
    zeros, izeros = jnp.zeros(n), jnp.zeros(n, jnp.int32)
    init = (zeros, izeros, zeros, jnp.full(n, -jnp.inf), izeros)
    (running, steps, total, best, count), _ = jax.lax.scan(step, init, (reward, done))
    partial = running / jnp.maximum(steps, 1) if time_average else running
    mean = jnp.where(count > 0, total / jnp.maximum(count, 1), partial)
    best = jnp.where(count > 0, best, partial)
    return mean, best, count


def episode_mean(x: jax.Array, done: jax.Array, incomplete_value: float | jax.Array = -jnp.inf) -> jax.Array:
    """f32[N]: mean over finished episodes of their per-step mean of ``x`` f32[T, N];
    ``incomplete_value`` (a number or f32[N]) where no episode finished."""
    mean, _, count = episode_returns(x, done, time_average=True)
    return jnp.where(count > 0, mean, incomplete_value)


def info_key(solved) -> str | None:
    """The info key a task's ``solved`` names; None for a function of the return (or no criterion)."""
    return solved if isinstance(solved, str) else None


def episode_solved(solved, returns: jax.Array, flags: jax.Array | None = None) -> jax.Array:
    """bool of ``returns``' shape: which episodes the task's ``solved`` calls solved.

    For a function, ``solved(returns)``; for an info key, ``flags`` (that key at each episode's last
    step, ``Trajectory.solved``), required then."""
    if info_key(solved) is None:
        return solved(returns)
    if flags is None:
        raise ValueError(f"solved names the info key {solved!r}: the episodes' flags are needed (Trajectory.solved)")
    return flags


def solve_rate(reward: jax.Array, done: jax.Array, solved, flags: jax.Array | None = None
               ) -> tuple[jax.Array, jax.Array]:
    """``(f32[N], i32[N])``: the solved share (0 if none) and count of the episodes that ended.

    ``solved``: ``f32[N] -> bool[N]`` of the return, or an info key read from ``flags`` bool[T, N]."""

    def step(carry, inp):
        running, wins, count = carry
        rt, d, f = inp
        running = running + rt
        wins = wins + (d & episode_solved(solved, running, f))
        return (jnp.where(d, 0.0, running), wins, count + d), None

    n = reward.shape[1]
    izeros = jnp.zeros(n, jnp.int32)
    (_, wins, count), _ = jax.lax.scan(step, (jnp.zeros(n), izeros, izeros), (reward, done, flags))
    return wins / jnp.maximum(count, 1), count


def learnability(reward: jax.Array, done: jax.Array, solved, incomplete_value: float = -jnp.inf,
                 flags: jax.Array | None = None) -> jax.Array:
    """f32[N]: p·(1 − p), p = :func:`solve_rate`; ``incomplete_value`` where no episode finished."""
    p, count = solve_rate(reward, done, solved, flags)
    return jnp.where(count > 0, p * (1.0 - p), incomplete_value)


def perfect_regret(mean_return: jax.Array, optimal_return: jax.Array) -> jax.Array:
    """Optimal − mean return, both discounted or both undiscounted."""
    return optimal_return - mean_return


def positive_value_loss(advantages: jax.Array, done: jax.Array) -> jax.Array:
    """f32[N]: PVL of ``advantages`` f32[T, N] (GAE) and ``done`` bool[T, N] (module docstring)."""
    positive = jnp.maximum(advantages, 0.0)
    return episode_mean(positive, done, incomplete_value=jnp.mean(positive, axis=0))


def max_mc(values: jax.Array, max_return: jax.Array, done: jax.Array, advantages: jax.Array) -> jax.Array:
    """f32[N]: MaxMC (module docstring).

    ``values``, ``advantages`` f32[T, N]; ``max_return`` f32[N] (best return of an episode that
    ended on the level, −inf if none); ``done`` bool[T, N]."""
    best = jnp.maximum(max_return, values[0] + advantages[0])
    return episode_mean(max_return[None, :] - values, done, incomplete_value=jnp.mean(best[None, :] - values, axis=0))


def negative_return(mean_return: jax.Array) -> jax.Array:
    return -mean_return


@struct.dataclass
class ScoreInputs:
    """What a score may read of one rollout of N levels, T steps, in reward units.

    ``mean_return`` f32[N] (finished episodes; discounted under ``discounted_regret``), ``values``,
    ``advantages``, ``reward`` f32[T, N], ``done`` bool[T, N], ``max_return`` f32[N] (MaxMC's record,
    −inf where none), ``optimal_return`` f32[N] (only for ``needs_optimum``), ``solved`` (static) and
    ``solved_flags`` bool[T, N] (None for a function of the return) for ``needs_solved``."""

    mean_return: jax.Array
    values: jax.Array
    advantages: jax.Array
    max_return: jax.Array
    done: jax.Array
    reward: jax.Array
    optimal_return: jax.Array | None = None
    solved: Callable | str | None = struct.field(pytree_node=False, default=None)
    solved_flags: jax.Array | None = None


@dataclass(frozen=True)
class Score:
    """A level score ``fn(ScoreInputs) -> f32[N]`` and what it needs (checked before the run).

    needs_optimum: the task's optimal return (discounted too under ``discounted_regret``).
    needs_solved: the task's solve criterion (``UEDTask.solved``).
    needs_finished_episodes: reads episodes that end inside a rollout; warned when ``num_steps`` <
        the episode limit.
    unfinished: ends the warning "levels whose episode does not end ...".
    help: one line for ``remidi list``."""

    name: str
    fn: Callable[[ScoreInputs], jax.Array]
    needs_optimum: bool = False
    needs_solved: bool = False
    needs_finished_episodes: bool = False
    unfinished: str = "score -inf and are never inserted"
    help: str = ""


PARTIAL = "are scored by the reward collected so far as if the episode had ended"  # the episodic-return scores
#: pvl, maxmc: a rollout without a finished episode is scored from its truncated episode (module docstring)
BOOTSTRAPPED = "are scored by their steps' advantages and values, bootstrapped by the critic at the rollout's end"


#: every score ``score=`` accepts, by name
SCORES: dict[str, Score] = {score.name: score for score in (
    Score("perfect_regret", lambda x: perfect_regret(x.mean_return, x.optimal_return), needs_optimum=True,
          needs_finished_episodes=True, unfinished=PARTIAL + " (a goal not yet reached looks like a failure)",
          help="optimal return − the agent's mean return"),
    Score("pvl", lambda x: positive_value_loss(x.advantages, x.done), unfinished=BOOTSTRAPPED,
          help="positive value loss: mean of max(GAE advantage, 0) over finished episodes (else the "
               "bootstrapped rollout)"),
    Score("maxmc", lambda x: max_mc(x.values, x.max_return, x.done, x.advantages), unfinished=BOOTSTRAPPED,
          help="best return seen on the level − V(s), over finished episodes (else the bootstrapped rollout)"),
    Score("neg_return", lambda x: negative_return(x.mean_return), needs_finished_episodes=True, unfinished=PARTIAL,
          help="−mean return (minimax return)"),
    Score("learnability", lambda x: learnability(x.reward, x.done, x.solved, flags=x.solved_flags),
          needs_solved=True, needs_finished_episodes=True,
          unfinished="score -inf and are never inserted (a solve rate needs episodes that end)",
          help="p(1 − p), p the level's solve rate in the rollout (SFL)"),
)}


BUILTIN_SCORES = tuple(SCORES)  # the scores of the library itself, in order


def scores_for(optimum: bool, solved: bool) -> list[str]:
    """The registered scores a task can rank by: ``optimum``/``solved``: it has an optimal return / a
    solve criterion."""
    return [s.name for s in SCORES.values() if (optimum or not s.needs_optimum) and (solved or not s.needs_solved)]


def task_scores(task) -> list[str]:
    """:func:`scores_for` the UEDTask ``task``."""
    return scores_for(task.optimal_return is not None, task.solved is not None)


def register_score(name: str, fn: Callable[[ScoreInputs], jax.Array], *, needs_optimum: bool = False,
                   needs_solved: bool = False, needs_finished_episodes: bool = False, help: str = "",
                   unfinished: str = "are scored by whatever the score makes of a rollout in which no episode "
                                     "ended") -> Score:
    """Add a score to :data:`SCORES`, usable as ``score=NAME`` by every PLR-family algorithm.

    ``fn(ScoreInputs) -> f32[N]`` is traced in the train step (write it in ``jax.numpy``); it is
    tried once on an abstract 3-step × 2-level rollout, so a wrong shape is refused here, not
    mid-run. Flags and ``unfinished`` are :class:`Score`'s. Raises ConfigError for a taken name or a
    malformed entry."""
    check_name("score", name)
    if name in SCORES:
        raise ConfigError(f"register_score: a score named {name!r} is already registered; "
                          f"taken: {', '.join(SCORES)}")
    if not callable(fn):
        raise ConfigError(f"register_score: {name}: fn must be a function of ScoreInputs, got {type(fn).__name__}")
    flags = {"needs_optimum": needs_optimum, "needs_solved": needs_solved,
             "needs_finished_episodes": needs_finished_episodes}
    for key, value in flags.items():
        if not isinstance(value, bool):
            raise ConfigError(f"register_score: {name}: {key} must be true or false, got {value!r}")
    for key, value in (("help", help), ("unfinished", unfinished)):
        if not isinstance(value, str):
            raise ConfigError(f"register_score: {name}: {key} must be a string, got {type(value).__name__}")
    score = Score(name, fn, help=help, unfinished=unfinished, **flags)
    steps, n = 3, 2
    inputs = ScoreInputs(mean_return=jnp.zeros(n), values=jnp.zeros((steps, n)), advantages=jnp.zeros((steps, n)),
                         max_return=jnp.zeros(n), done=jnp.zeros((steps, n), bool), reward=jnp.zeros((steps, n)),
                         optimal_return=jnp.zeros(n) if needs_optimum else None,
                         solved=(lambda r: r > 0) if needs_solved else None)
    try:
        out = jax.eval_shape(fn, inputs)
    except Exception as err:  # the user's function: its own error, one line
        first = (str(err).strip().splitlines() or [""])[0]
        raise ConfigError(f"register_score: {name}: fn failed on a rollout of {steps} steps × {n} levels: "
                          f"{type(err).__name__}{': ' + first if first else ''}") from None
    if not (hasattr(out, "shape") and tuple(out.shape) == (n,) and jnp.issubdtype(out.dtype, jnp.floating)):
        got = f"{getattr(out, 'dtype', type(out).__name__)}{list(getattr(out, 'shape', ()))}"
        raise ConfigError(f"register_score: {name}: fn must return one float score per level (f32[N]); on a "
                          f"rollout of {steps} steps × {n} levels it returned {got}")
    SCORES[name] = score
    return score


def score_levels(name: str, inputs: ScoreInputs) -> jax.Array:
    """f32[N]: the score ``name`` (static) of ``inputs``."""
    if name not in SCORES:
        raise ValueError(f"score must be one of {tuple(SCORES)}, got {name!r}")
    return SCORES[name].fn(inputs)
