"""Checking an exact solver's answer against the rewards, without an LP.

Both solvers (:mod:`remidi.solvers.onestep`, :mod:`remidi.solvers.sequence_form`) state their
rounds as :class:`Claims` (values, the bounds that certify them, adversaries, the policy's
regrets, all computed from the rewards in real units), and :func:`check_rounds` and
:func:`check_final` refuse, with a one-line :class:`~remidi.solvers.lp.SolverError`, any answer
they cannot vouch for: the tolerances and why they suffice are in :mod:`remidi.solvers.lp`'s
docstring (``CHECK_RTOL``, ``_ROUNDING``, ``_EQUILIBRIUM_TOL``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from remidi.solvers.lp import _EQUILIBRIUM_TOL, _ROUNDING, CHECK_RTOL, SolverError

def require_finite(names: tuple[str, ...], values: np.ndarray) -> None:
    """Raise SolverError naming the first level whose row of ``values`` [L, ...] (its rewards, or
    its payoffs) holds a number that is not finite."""
    bad = ~np.isfinite(values.reshape(len(names), -1)).all(axis=1)
    if bad.any():
        raise SolverError(f"exact solver: level {names[int(np.flatnonzero(bad)[0])]!r}: rewards must be finite")


@dataclass(frozen=True)
class Claims:
    """Rounds 0..R-1 of an answer and the numbers, computed directly from the rewards, that vouch
    for them (see the module docstring).

    value [R]: the stated values; bound [R]: the least expected regret, over the policies each
    round allows, against an optimal vertex adversary (a lower bound on the value); guarantee
    [R]: the same against the stated adversary; round_of [L] int: the round whose support holds
    each level (-1: covered before these rounds, R: not covered yet); adversary [L]: each level's
    probability in its round's adversary; regret [L] or [R, L]: the regret of the rounds' policy
    (or of each round's) on every level; scale [L]: the payoff scale of the LP that decided each
    level. Real units throughout.
    """

    value: np.ndarray
    bound: np.ndarray
    guarantee: np.ndarray
    round_of: np.ndarray
    adversary: np.ndarray
    regret: np.ndarray
    scale: np.ndarray


def _tolerance(value, scale, atol: float):
    """``CHECK_RTOL * |value| + atol * scale`` (elementwise)."""
    return CHECK_RTOL * np.abs(value) + atol * np.asarray(scale)


def _spread(spread: np.ndarray) -> str:
    """The range of the levels' largest regrets [L], for error messages."""
    positive = spread[spread > 0]
    if not positive.size:
        return "every level's regret is 0 whatever the policy"
    return f"the levels' largest regrets range from {positive.min():.3g} to {positive.max():.3g}"


def _refuse(round_no: int, why: str, spread: np.ndarray):
    raise SolverError(f"exact solver: cannot vouch for round {round_no}: {why} ({_spread(spread)})")


def _worst(claims: Claims) -> np.ndarray:
    """Per round [R], the level with the largest regret among those the round's adversary may
    pick (``round_of >= k``)."""
    n_rounds = len(claims.value)
    later = claims.round_of >= 0
    if claims.regret.ndim == 2:
        masked = np.where(claims.round_of[None, :] >= np.arange(n_rounds)[:, None], claims.regret, -np.inf)
        return masked.argmax(axis=1)
    # one policy for every round: the per-round maxima, then a running maximum from the last round
    levels = np.flatnonzero(later)
    order = levels[np.lexsort((claims.regret[levels], claims.round_of[levels]))]
    groups = claims.round_of[order]
    last = np.flatnonzero(np.r_[groups[1:] != groups[:-1], True])
    best_level = np.full(n_rounds + 1, -1)
    best_level[groups[last]] = order[last]
    best = np.where(best_level >= 0, claims.regret[np.maximum(best_level, 0)], -np.inf)
    best_rev = best[::-1]
    running = np.maximum.accumulate(best_rev)
    where = np.maximum.accumulate(np.where(best_rev >= running, np.arange(n_rounds + 1), 0))
    return best_level[::-1][where][::-1][:n_rounds]


def _first_off_level(off: np.ndarray, round_of: np.ndarray, n_rounds: int) -> np.ndarray:
    """Per round [R], the first level flagged in ``off`` [L] bool among its support (-1 if none)."""
    first = np.full(n_rounds + 1, len(off))
    np.minimum.at(first, round_of[off], np.flatnonzero(off))
    return np.where(first[:n_rounds] < len(off), first[:n_rounds], -1)


def check_rounds(claims: Claims, names: tuple[str, ...], spread: np.ndarray, first: int = 1,
                 previous: float | None = None) -> None:
    """Check every round of ``claims`` (see the module docstring); raise SolverError naming the
    first that fails. Rounds are numbered from ``first``; ``previous`` is the value of the round
    before them, if any. ``names`` [L] are the level names and ``spread`` [L] each level's
    largest regret over all policies (real units), for the message and as the size of each
    level's rounding.
    """
    value, n_rounds = claims.value, len(claims.value)
    regret = claims.regret if claims.regret.ndim == 2 else np.broadcast_to(claims.regret, (n_rounds, len(names)))
    top = _worst(claims)
    worst = regret[np.arange(n_rounds), top]
    # each covered level against its own round: regret, value, adversary
    covered = np.flatnonzero((claims.round_of >= 0) & (claims.round_of < n_rounds))
    rounds = claims.round_of[covered]
    own = regret[rounds, covered]
    off = np.zeros(len(names), dtype=bool)
    off[covered] = np.abs(own - value[rounds]) > _tolerance(value[rounds], spread[covered], _ROUNDING)
    culprit = _first_off_level(off, claims.round_of, n_rounds)
    members = np.bincount(rounds, minlength=n_rounds)
    mass = np.bincount(rounds, weights=claims.adversary[covered], minlength=n_rounds)
    loose = np.bincount(rounds, weights=claims.adversary[covered] * claims.scale[covered], minlength=n_rounds)
    before = np.r_[np.inf if previous is None else previous, value[:-1]]
    failures = [  # (failed [R] bool, what failed in round k)
        (~np.isfinite(value) | ~np.isfinite(worst) | ~np.isfinite(claims.bound) | ~np.isfinite(claims.guarantee),
         lambda k: "a regret overflows float64"),
        (np.abs(worst - value) > _tolerance(value, spread[top], _ROUNDING),
         lambda k: f"the value {value[k]:.9g} is not the policy's worst-case regret {worst[k]:.9g}"),
        (value - claims.bound > _tolerance(value, spread[top], _ROUNDING),
         lambda k: f"the value {value[k]:.9g} is not certified to {CHECK_RTOL:g}: the best adversary "
                   f"found guarantees only {claims.bound[k]:.9g}"),
        (members == 0, lambda k: "the adversary's support is empty"),
        (culprit >= 0,
         lambda k: f"the adversary is not a best response: level {names[culprit[k]]!r} in its support "
                   f"has regret {regret[k, culprit[k]]:.9g}, not the value {value[k]:.9g}"),
        (np.abs(mass - 1.0) > 1e-9, lambda k: "the adversary is not a distribution over its support"),
        (value - claims.guarantee > _tolerance(value, loose, _EQUILIBRIUM_TOL),
         lambda k: f"the adversary is not an equilibrium one: it guarantees only "
                   f"{claims.guarantee[k]:.9g}, not the value {value[k]:.9g}"),
        (value > before + _tolerance(before, spread[top], _ROUNDING),
         lambda k: f"its value {value[k]:.9g} exceeds the previous round's {before[k]:.9g}"),
    ]
    failed = [(int(np.flatnonzero(bad)[0]), i) for i, (bad, _) in enumerate(failures) if bad.any()]
    if failed:
        k, i = min(failed)
        _refuse(first + k, failures[i][1](k), spread)


def check_final(claims: Claims, regret: np.ndarray, names: tuple[str, ...], spread: np.ndarray) -> None:
    """Check that every level is covered and that the final policy's regret [L] on each round's
    support is that round's value (within ``T_eq``)."""
    n_rounds = len(claims.value)
    if not np.all(np.isfinite(regret)):
        l = int(np.flatnonzero(~np.isfinite(regret))[0])
        _refuse(n_rounds, f"the final regret of level {names[l]!r} overflows float64", spread)
    if ((claims.round_of < 0) | (claims.round_of >= n_rounds)).any():
        _refuse(n_rounds, "the rounds' supports do not cover every level", spread)
    target = claims.value[claims.round_of]
    off = np.abs(regret - target) > _tolerance(target, claims.scale, _EQUILIBRIUM_TOL)
    if off.any():
        l = int(np.flatnonzero(off)[0])
        _refuse(int(claims.round_of[l]) + 1, f"the final policy's regret {regret[l]:.9g} on level "
                f"{names[l]!r} is not the round's value {target[l]:.9g}", spread)
