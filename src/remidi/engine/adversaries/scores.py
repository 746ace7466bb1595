"""Level scores for prioritised replay, from one rollout per level.

Every function maps rollout arrays with leading dims [T, N] to one score per level, f32[N].
Higher = replayed more.

* ``perfect_regret``: optimal return − the agent's mean episodic return (exact regret when
  the environment knows its optimal return). The paper's utility is discounted,
  U_θ(π) = E[Σ_t γ^t r_t] with t counted from the episode's first step, so by default both
  sides are discounted (``UEDConfig.discounted_regret``): the agent's episodes by γ^t, the
  optimum by the discount of the step its rewards come at (the task's
  ``optimal_discounted_return``; mazes: γ^(n−1) for a goal reached with the n-th action, so
  an agent following a shortest path has regret exactly 0).
* ``pvl`` (positive value loss): per finished episode, the mean over its steps of
  max(GAE advantage, 0); then the mean over the finished episodes.
* ``maxmc``: per finished episode, the mean over its steps of (highest return ever achieved on
  the level − V(s_t)); then the mean over the finished episodes.
* ``neg_return``: −mean episodic return (minimax return).
* ``learnability`` (Rutherford et al. 2024, "No Regrets", SFL): p·(1 − p), p the share of the
  level's episodes that ended inside the rollout and were solved (the task's ``solved``: on the
  episode's return, or its last step's info flag, :func:`episode_solved`); highest for levels
  the agent solves half of the time.

PVL and MaxMC follow Jiang et al. (2021), "Prioritized Level Replay", as its reference
implementations compute them (minimax's ``ued_scores.py``, and jaxued's ``positive_value_loss``
and ``max_mc`` derived from it) wherever an episode ends inside the rollout: an episode's score is
its per-step average, the level's score is the average over the episodes that *ended* inside the
rollout, and the steps of an unfinished trailing episode are left out (they would add the
critic's guess at the episode's end to scores of whole episodes; leaving them out keeps the
references' values).

A rollout **without any finished episode** (an episode longer than the rollout: Craftax's
10,000 steps against 64–256-step rollouts) is scored from its truncated episode, bootstrapped by
the critic, so that such levels are ranked instead of all scoring ``-inf`` (the references'
``incomplete_value``, under which a buffer of such levels never grows past one level):

* PVL: the mean over the rollout's steps of max(A_t, 0), A the GAE advantages, which already
  bootstrap from V(s_T) after the rollout's last step (``engine/core/ppo.py``'s ``compute_gae``);
* MaxMC: the mean over the steps of (best − V(s_t)), best the higher of the level's record (the
  best return of an episode that ended on it, −inf while none has) and the truncated episode's
  bootstrapped return V(s_0) + A_0 (GAE's target at its first step: the λ-return PPO fits the
  critic to). That estimate ranks this rollout only; the record keeps finished episodes alone.

``learnability`` still needs finished episodes (a solve rate counts outcomes): a rollout without
one scores ``-inf``, so a fresh level scored so is never inserted and a replayed one ranks last
until it is scored again (``num_steps`` ≥ the episode limit, or SFL's ``sfl.rollout_steps``,
scores every level; validation warns otherwise).

Episodic returns (``perfect_regret``, ``neg_return``) use the episodes that *ended* inside the
rollout; an env whose episode never ended is credited with the reward collected so far (its
partial return).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import jax
import jax.numpy as jnp
from flax import struct

from remidi.errors import ConfigError, check_name


def episode_returns(reward: jax.Array, done: jax.Array, gamma: float = 1.0, *, time_average: bool = False):
    """Mean and max return of the episodes that ended, per env (discounted, Σ_k γ^k r_k with k
    counted from each episode's first step, for ``gamma`` < 1; static). With ``time_average``
    (static) each episode's per-step mean of ``reward`` takes the place of its return (any
    per-step quantity: :func:`episode_mean`).

    ``reward`` f32[T, N], ``done`` bool[T, N] (the episode ended at step t) →
    ``(mean f32[N], max f32[N], count i32[N])``; with no finished episode, mean = max = the
    partial return (its per-step mean with ``time_average``; 0 for no step) and count = 0.
    """

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
    """f32[N]: the mean over finished episodes of each episode's per-step mean of ``x`` f32[T, N];
    ``incomplete_value`` (a number, or f32[N]) for an env with no finished episode (module docstring)."""
    mean, _, count = episode_returns(x, done, time_average=True)
    return jnp.where(count > 0, mean, incomplete_value)


def info_key(solved) -> str | None:
    """The info key a task's ``solved`` (``UEDTask.solved``) names, None for a function of the
    return (or no criterion)."""
    return solved if isinstance(solved, str) else None


def episode_solved(solved, returns: jax.Array, flags: jax.Array | None = None) -> jax.Array:
    """Which episodes the task's criterion ``solved`` (``UEDTask.solved``) calls solved, bool of
    ``returns``' shape: ``solved(returns)`` for a function of the episode's return; for the name
    of an info key, ``flags`` (bool, that key's value at each episode's last step: the rollout's
    ``Trajectory.solved``), which the return does not enter."""
    if info_key(solved) is None:
        return solved(returns)
    if flags is None:
        raise ValueError(f"solved names the info key {solved!r}: the episodes' flags are needed (Trajectory.solved)")
    return flags


def solve_rate(reward: jax.Array, done: jax.Array, solved, flags: jax.Array | None = None
               ) -> tuple[jax.Array, jax.Array]:
    """The share of the episodes that ended inside the rollout that ``solved`` (the task's
    criterion: a function ``f32[N] -> bool[N]`` of the return, or an info key, read from
    ``flags`` bool[T, N]: :func:`episode_solved`) calls solved, and their count:
    ``(f32[N] (0 if none), i32[N])``."""

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
    """f32[N]: p·(1 − p) with p = :func:`solve_rate` (``flags``: its info flags, for a ``solved``
    that names an info key); ``incomplete_value`` for an env with no finished episode (module
    docstring)."""
    p, count = solve_rate(reward, done, solved, flags)
    return jnp.where(count > 0, p * (1.0 - p), incomplete_value)


def perfect_regret(mean_return: jax.Array, optimal_return: jax.Array) -> jax.Array:
    """Both in the same units: discounted (the paper's U_θ) or undiscounted returns."""
    return optimal_return - mean_return


def positive_value_loss(advantages: jax.Array, done: jax.Array) -> jax.Array:
    """``advantages`` f32[T, N] (GAE, bootstrapped at the rollout's end), ``done`` bool[T, N]: the
    mean over finished episodes of their per-step mean of max(A, 0); where no episode ended, the
    mean over all T steps (module docstring)."""
    positive = jnp.maximum(advantages, 0.0)
    return episode_mean(positive, done, incomplete_value=jnp.mean(positive, axis=0))


def max_mc(values: jax.Array, max_return: jax.Array, done: jax.Array, advantages: jax.Array) -> jax.Array:
    """``values`` f32[T, N], ``max_return`` f32[N] (highest return of an episode that ended on the
    level, −inf if none has), ``done`` bool[T, N], ``advantages`` f32[T, N] (GAE): the mean over
    finished episodes of their per-step mean of (max_return − V(s_t)); where no episode ended, the
    mean over all T steps of (max(max_return, V(s_0) + A_0) − V(s_t)), V(s_0) + A_0 the truncated
    episode's bootstrapped return (module docstring)."""
    best = jnp.maximum(max_return, values[0] + advantages[0])
    return episode_mean(max_return[None, :] - values, done, incomplete_value=jnp.mean(best[None, :] - values, axis=0))


def negative_return(mean_return: jax.Array) -> jax.Array:
    return -mean_return


@struct.dataclass
class ScoreInputs:
    """What a score may read of one rollout of N levels (T steps), in the environment's reward
    units: ``mean_return`` f32[N] (the mean return of the finished episodes, discounted for
    perfect regret under ``discounted_regret``), ``values`` and ``advantages`` f32[T, N] (the
    critic's, GAE), ``max_return`` f32[N] (MaxMC's record: the best return of an episode that
    ended on the level, in this rollout or a replay before; −inf where none has), ``done``
    bool[T, N], ``reward`` f32[T, N], ``optimal_return`` f32[N] (the task's optimum, given only to
    a score that ``needs_optimum``); ``solved`` (the task's criterion, static: ``return -> bool``
    or an info key) and ``solved_flags`` (bool[T, N], that key's value at each step; None for a
    function of the return) for one that ``needs_solved``: read them with :func:`solve_rate`."""

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
    """A level score: ``fn(ScoreInputs) -> f32[N]`` (higher = replayed more) and what it needs,
    which the engine checks before a run (``engine/run/validation.py``) and provides in the step
    (``engine/learner.py``'s ``score_rollout``).

    needs_optimum: the task's optimal return (``UEDTask.optimal_return``; with
        ``discounted_regret``, ``optimal_discounted_return`` too).
    needs_solved: the task's solve criterion (``UEDTask.solved``).
    needs_finished_episodes: it reads the episodes that end inside a rollout, so a rollout shorter
        than an episode (``num_steps`` < the episode limit) scores some levels without one:
        warned before the run (``engine/run/validation.py``'s ``run_warnings``).
    unfinished: what becomes of a level whose episode does not end inside the rollout, completing
        the warning's "levels whose episode does not end ...".
    help: one line for ``remidi list``.
    """

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
    """The registered scores (:data:`SCORES`, in order) a task can rank levels by: those whose
    needs it meets, ``optimum``: it gives its optimal return (``UEDTask.optimal_return``),
    ``solved``: a solve criterion (``UEDTask.solved``)."""
    return [s.name for s in SCORES.values() if (optimum or not s.needs_optimum) and (solved or not s.needs_solved)]


def task_scores(task) -> list[str]:
    """:func:`scores_for` the UEDTask ``task``."""
    return scores_for(task.optimal_return is not None, task.solved is not None)


def register_score(name: str, fn: Callable[[ScoreInputs], jax.Array], *, needs_optimum: bool = False,
                   needs_solved: bool = False, needs_finished_episodes: bool = False, help: str = "",
                   unfinished: str = "are scored by whatever the score makes of a rollout in which no episode "
                                     "ended") -> Score:
    """Add a level score to :data:`SCORES`, so that ``score=NAME`` (``--set score=NAME``) ranks
    levels by it in every algorithm of the PLR family, and validation checks what it needs.

    ``fn(ScoreInputs) -> f32[N]``: one score per level of a rollout (higher = replayed more); it
    is traced (jit) inside the train step, so it must be written with ``jax.numpy``. The
    ``needs_*`` flags and ``unfinished`` (the short-rollout warning's words) are :class:`Score`'s. ``fn`` is tried once on a small abstract rollout (3
    steps × 2 levels, nothing is computed), so a function of the wrong shape is refused here,
    not in the middle of a run. Raises ConfigError (one line) for a name already taken or a
    malformed entry. Returns the registered :class:`Score`.
    """
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
    """f32[N]: the score ``name`` (static; one of :data:`SCORES`) of one rollout's ``inputs``."""
    if name not in SCORES:
        raise ValueError(f"score must be one of {tuple(SCORES)}, got {name!r}")
    return SCORES[name].fn(inputs)
