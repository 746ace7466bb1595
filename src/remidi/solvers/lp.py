"""Regret games over a sequence-form policy polytope, solved with HiGHS linear programs.

Both game kinds reduce to the same data:

* a :class:`Polytope` of realisation plans ``x`` [S] over the agent's sequences (``x[0] = 1`` for
  the empty sequence; for every information set ``I`` the mass of its action sequences equals the
  mass of its parent sequence). A one-step game is the special case where every observation is an
  information set whose parent is the empty sequence, so ``x`` is the stacked policy rows.
* a payoff matrix ``C`` [L, S]: the return on level ``l`` is linear, ``U_l(x) = C[l] @ x``.
* a reach matrix ``reach`` [L, I]: the chance probability of arriving at information set ``I`` on
  level ``l`` if the agent plays towards it; ``I`` is *realisable* on ``l`` under ``x`` iff
  ``reach[l, I] * x[parent(I)] > 0``.

Regret is ``R_l(x) = U*_l - C[l] @ x`` with ``U*_l`` the best return on level ``l`` alone.

**Equilibrium adversary.** Each round reports the *maximal-support* equilibrium adversary: the
levels that receive positive probability in *some* equilibrium adversary. For every level not yet
seen positive, an LP maximises that level's probability over the set of equilibrium adversaries
(the adversary's LP with its value constrained to within ``_VALUE_SLACK`` of its optimum); the
reported adversary is the average of these solutions (still an equilibrium, since the set is
convex), restricted to the levels whose maximum exceeded ``tol``. A plain LP dual would be a
vertex and could miss levels (e.g. with two duplicate levels it names only one). A level outside
every equilibrium can reach at most ``slack / gap`` probability, where ``gap`` is how much
adversary value a unit of its mass costs and ``slack`` is ``_VALUE_SLACK`` plus HiGHS's feasibility
tolerance (1e-10), so with the default ``tol = 1e-7`` it would be misclassified when ``gap`` is
below about 1e-3 (normalised units; seen on a 100-level random game with a gap of 3e-5, and
whenever the value itself is that far below the payoff scale). Two tests keep such levels out:
a level must be a *candidate* (its regret under the round's plan within ``_CANDIDATE_GAP``, and
within ``CHECK_RTOL`` of the value, of the value), and a support level whose largest probability
is below ``_PRUNE_MASS`` is dropped if some optimal plan lowers its regret by more than
``_CANDIDATE_GAP`` (:func:`_in_no_equilibrium`). What remains is a tie within the LPs'
resolution. The one-step solver (:mod:`remidi.solvers.onestep`) compares its observation
games' values directly and has no such limit across observations.

**Uniqueness.** A round's optimal plan need not be unique, and the behaviour it freezes decides
what later rounds can achieve: with one observation and levels paying (1, 0, 0), (0, 1, 1) and
(0, 0, 0.2) for three actions, round 1 (value 0.5 on the first two levels) fixes P(a1) = 0.5 but
leaves any split of the other 0.5 between a2 and a3 optimal, and the third level's final regret is
0.2 − 0.2·P(a3), anywhere in [0.1, 0.2]. So a BLP policy is not unique in general; the solver
returns the one HiGHS finds. Each round therefore checks whether the policy it freezes is unique
(:func:`frozen_plan_is_unique`): for every sequence below an information set it freezes, two LPs
minimise and maximise that sequence's mass over the round's *optimal face* (the plans whose
regret on every available level is within ``_FACE_SLACK`` of the round's value); the frozen policy
is unique iff every minimum and maximum agree within ``_UNIQUE_TOL``.

**Scaling.** Payoffs are divided by their largest magnitude before solving, so the tolerances
above are relative to that *payoff scale*. A per-level shift of rewards leaves every regret
unchanged, a global factor scales them all, and nothing else is free: a level whose regrets are
many orders of magnitude below the scale is invisible to the LP (HiGHS treats matrix entries
below 1e-9 as zero). The callers scale each LP on its own (one per observation in a one-step
game) and centre each level's rewards first (:mod:`remidi.solvers.sequence_form`).

**Checking.** Every answer is checked before it is returned (:func:`remidi.solvers.checks.check_rounds`,
:func:`~remidi.solvers.checks.check_final`), from numbers computed directly from the rewards with no LP: the regrets
of the round's policy, the least expected regret any allowed policy achieves against the
round's adversary (its *guarantee*), and the same for an optimal vertex adversary (the
*bound*, a lower bound on the round's value). All are sums of non-negative *regret gaps*
(:func:`~remidi.solvers.polytope.regret_gaps`), so their rounding is relative to themselves, not to the payoff scale,
and a bound is never negative. For a round of value ``v`` and ``T(v) = CHECK_RTOL * |v|`` plus
``_ROUNDING`` of the largest regret of the level that attains it (the rounding of a value
computed by subtracting returns): the value is the policy's worst regret and exceeds the bound
by at most ``T(v)``, so every stated value is certified to ``CHECK_RTOL``, relatively, however
far its LP's payoff scale ``s`` is above it; when the rewards' range hides the regrets that decide a round
from its LP (below about 1e-9 of the scale, or 1e-16 in float64 itself), this check is what
fails. The adversary's support must have regret within ``CHECK_RTOL * |v|`` (plus rounding) of
the value, and its guarantee, which the LPs' value slack and feasibility tolerances loosen,
within ``T_eq(v) = CHECK_RTOL * |v| + _EQUILIBRIUM_TOL * s``. A BLP round's value is at most the
previous one's, and the final policy's regret on each round's support is that round's value
(within ``T_eq``: the later LPs pin the frozen behaviour to their feasibility tolerance). A failed
check, a HiGHS failure or an overflow raises :class:`SolverError`, naming the check and the
range of the levels' regrets.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.optimize import linprog

from remidi.errors import RemidiError
from remidi.solvers.polytope import Polytope, RawRound, best_response_values, regret_of_plan

#: HiGHS options: feasibility tolerances well below ``tol``, so LP noise never looks like support.
_HIGHS_OPTIONS = {"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10}
#: Slack (normalised payoff units) by which an equilibrium adversary may miss the game value.
_VALUE_SLACK = 1e-11
#: A level whose regret under an optimal plan is this far below the value is in no support (or
#: ``CHECK_RTOL`` of the value, plus rounding, if that is less: see :func:`solve_regret_game`).
_CANDIDATE_GAP = 1e-9
#: Plans whose regret exceeds a round's value by at most this (normalised units) are optimal.
_FACE_SLACK = 1e-9
#: Optimal plans differing by more than this on a frozen sequence make the frozen policy non-unique.
_UNIQUE_TOL = 1e-6
#: A level outside every equilibrium takes at most (value slack + HiGHS feasibility tolerance) /
#: gap probability in the adversary LPs, so one with less than this may be there only by a gap
#: of ``_CANDIDATE_GAP`` or more, which the optimal face shows (:func:`_in_no_equilibrium`).
_PRUNE_MASS = (_VALUE_SLACK + 1e-10) / _CANDIDATE_GAP
#: Relative accuracy to which every stated value is checked (the report prints 6 digits).
CHECK_RTOL = 1e-6
#: Rounding, relative to a level's largest regret, of its regret computed by subtracting returns.
_ROUNDING = 1e-15
#: Slack (normalised payoff units) of the checks on an adversary, which the LPs' value slack and
#: feasibility tolerances loosen.
_EQUILIBRIUM_TOL = 1e-9


class SolverError(RemidiError):
    """The exact solver cannot vouch for an answer: HiGHS failed, a check of the answer failed, or
    the rewards' range is beyond what float64 LPs resolve. One line; ``remidi solve`` exits 2."""


def _check(result, what: str):
    """Return a linprog result, raising SolverError if HiGHS did not solve it."""
    if result.status != 0:
        message = " ".join(str(result.message).split())
        raise SolverError(f"exact solver: {what}: HiGHS failed ({message})")
    return result


def _min_max_regret(
    payoff: np.ndarray, optimal: np.ndarray, eq: tuple[np.ndarray, np.ndarray], active: np.ndarray
) -> np.ndarray:
    """A plan [S] minimising the maximum regret over the active levels.

    LP over (x [S], t): minimise t s.t. U*_l - C[l] @ x <= t for active l, E @ x = e, x >= 0.
    """
    n_seq = payoff.shape[1]
    cost = np.zeros(n_seq + 1)
    cost[-1] = 1.0
    a_ub = np.hstack([-payoff[active], -np.ones((int(active.sum()), 1))])
    a_eq = np.hstack([eq[0], np.zeros((eq[0].shape[0], 1))])
    bounds = [(0, None)] * n_seq + [(None, None)]
    result = _check(
        linprog(cost, A_ub=a_ub, b_ub=-optimal[active], A_eq=a_eq, b_eq=eq[1], bounds=bounds,
                method="highs", options=_HIGHS_OPTIONS),
        "minimax regret LP",
    )
    return np.clip(result.x[:n_seq], 0.0, None)


def _maximal_support_adversary(
    payoff: np.ndarray,
    optimal: np.ndarray,
    eq: tuple[np.ndarray, np.ndarray],
    active: np.ndarray,
    candidates: np.ndarray,
    tol: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Maximal-support equilibrium adversary [L], its support [L] bool (see module docstring) and
    the first LP's optimal vertex adversary [L].

    Only ``candidates`` [L] bool can be in the support: by complementary slackness a level in some
    equilibrium adversary's support has regret equal to the value under every optimal plan, and
    a level below it may still take up to ``slack / gap`` probability in the LPs' solutions.

    Adversary LP over (lambda [La], y [M]): the value of lambda is ``lambda @ U* + e @ y``
    subject to ``C_a.T @ lambda + E.T @ y <= 0`` (dual of the agent's best response),
    ``sum(lambda) = 1``, ``lambda >= 0``. A first LP maximises that value; the equilibria are
    then the points within ``_VALUE_SLACK`` of it, and each further LP maximises one level's
    probability among them.
    """
    levels = np.flatnonzero(active)
    n_act, (n_rows, n_seq) = len(levels), eq[0].shape
    value_row = np.concatenate([optimal[levels], eq[1]])
    a_ub = np.hstack([payoff[levels].T, eq[0].T])
    a_eq = np.concatenate([np.ones(n_act), np.zeros(n_rows)])[None, :]
    bounds = [(0, None)] * n_act + [(None, None)] * n_rows

    def solve(cost: np.ndarray, a_ub: np.ndarray, b_ub: np.ndarray) -> np.ndarray:
        result = _check(
            linprog(cost, A_ub=a_ub, b_ub=b_ub, A_eq=a_eq, b_eq=[1.0], bounds=bounds,
                    method="highs", options=_HIGHS_OPTIONS),
            "equilibrium adversary LP",
        )
        return result.x

    first = solve(-value_row, a_ub, np.zeros(n_seq))
    value = value_row @ first
    a_ub = np.vstack([a_ub, -value_row[None, :]])
    b_ub = np.concatenate([np.zeros(n_seq), [_VALUE_SLACK - value]])
    solutions = [np.clip(first[:n_act], 0.0, None)]
    for k in np.flatnonzero(candidates[levels]):
        if any(sol[k] > tol for sol in solutions):
            continue
        cost = np.zeros(n_act + n_rows)
        cost[k] = -1.0
        solutions.append(np.clip(solve(cost, a_ub, b_ub)[:n_act], 0.0, None))
    stacked = np.array(solutions)
    mass = stacked.max(axis=0)
    support = (mass > tol) & candidates[levels]
    for k in np.flatnonzero(support & (mass < _PRUNE_MASS)):
        if _in_no_equilibrium(payoff, optimal, eq, active, value, levels[k]):
            support[k] = False
    if not support.any():  # the value's own levels are candidates; only LP noise gets here
        support = stacked[0] == stacked[0].max()
    mean = np.where(support, stacked.mean(axis=0), 0.0)
    adversary, support_mask = np.zeros(len(active)), np.zeros(len(active), dtype=bool)
    certificate = np.zeros(len(active))
    adversary[levels] = mean / mean.sum()
    support_mask[levels] = support
    certificate[levels] = solutions[0] / solutions[0].sum()
    return adversary, support_mask, certificate


def _in_no_equilibrium(
    payoff: np.ndarray, optimal: np.ndarray, eq: tuple[np.ndarray, np.ndarray], active: np.ndarray,
    value: float, level: int,
) -> bool:
    """Whether some optimal plan gives ``level`` a regret more than ``_CANDIDATE_GAP`` below the
    value, which puts it outside every equilibrium adversary's support (strict complementarity).

    LP: minimise the level's regret over the plans whose regret on every active level is at most
    the value. (A slack there would let an equilibrium level's regret fall by the slack over its
    probability, which is more than ``_CANDIDATE_GAP`` when that is small.)
    """
    result = _check(
        linprog(-payoff[level], A_ub=-payoff[active], b_ub=value - optimal[active],
                A_eq=eq[0], b_eq=eq[1], bounds=(0, None), method="highs", options=_HIGHS_OPTIONS),
        "support LP",
    )
    return optimal[level] + result.fun < value - _CANDIDATE_GAP


def solve_regret_game(
    payoff: np.ndarray,
    optimal: np.ndarray,
    eq: tuple[np.ndarray, np.ndarray],
    active: np.ndarray,
    tol: float,
) -> RawRound:
    """Solve min over plans (E x = e, x >= 0) of max over active levels [L] bool of regret.

    ``payoff`` [L, S] and ``optimal`` [L] must already be normalised (magnitudes <= 1). Levels
    whose regret under the plan is below the value by more than ``_CANDIDATE_GAP``, or than
    ``CHECK_RTOL`` of the value (plus the level's rounding), are in no support.
    """
    plan = _min_max_regret(payoff, optimal, eq, active)
    regret = regret_of_plan(payoff, optimal, plan)
    value = float(regret[active].max())
    # relative to the value too: when it is far below the payoff scale, a level 1e-9 of the scale
    # below it is no tie (the rounding of each level's regret is relative to its own size)
    size = np.abs(payoff).max(axis=1) + np.abs(optimal)
    gap = np.minimum(_CANDIDATE_GAP, CHECK_RTOL * abs(value) + _ROUNDING * size)
    candidates = active & (regret >= value - gap)
    adversary, support, certificate = _maximal_support_adversary(payoff, optimal, eq, active, candidates, tol)
    return RawRound(value, adversary, support, plan, regret, certificate)


def frozen_plan_is_unique(
    payoff: np.ndarray,
    optimal: np.ndarray,
    eq: tuple[np.ndarray, np.ndarray],
    active: np.ndarray,
    value: float,
    sequences: np.ndarray,
) -> bool:
    """Whether every optimal plan of a regret game gives each of ``sequences`` [K] the same mass.

    The optimal face is ``{x : E @ x = e, x >= 0, U*_l - C[l] @ x <= value + _FACE_SLACK for the
    active l}`` (normalised payoffs, as in :func:`solve_regret_game`); each sequence's mass is
    minimised and maximised over it (see the module docstring).
    """
    a_ub = -payoff[active]
    b_ub = value + _FACE_SLACK - optimal[active]
    for seq in sequences:
        extremes = []
        for sign in (1.0, -1.0):
            cost = np.zeros(payoff.shape[1])
            cost[seq] = sign
            result = _check(
                linprog(cost, A_ub=a_ub, b_ub=b_ub, A_eq=eq[0], b_eq=eq[1], bounds=(0, None),
                        method="highs", options=_HIGHS_OPTIONS),
                "optimal face LP",
            )
            extremes.append(sign * result.fun)
        if extremes[1] - extremes[0] > _UNIQUE_TOL:
            return False
    return True


def realisable_infosets(
    poly: Polytope, reach: np.ndarray, plan: np.ndarray, levels: np.ndarray, tol: float
) -> np.ndarray:
    """Information sets [I] bool reached with positive probability under plan [S] on some level
    of ``levels`` [L] bool, given reach [L, I]."""
    chance = reach[levels].sum(axis=0) > 0
    played = plan[list(poly.parent)] > tol
    return chance & played


def fixing_equalities(
    poly: Polytope, plan: np.ndarray, fixed: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Rows [F, S] and rhs [F] pinning the behaviour of ``plan`` at the ``fixed`` [I] infosets.

    For each fixed information set and each action but the last (implied by the information-set
    constraint): ``x[(I, a)] - pi(a | I) * x[parent(I)] = 0``.
    """
    rows = []
    for info in np.flatnonzero(fixed):
        probs = poly.behaviour(plan, info)
        for seq, prob in zip(poly.children[info][:-1], probs[:-1]):
            row = np.zeros(poly.n_sequences)
            row[seq] += 1.0
            row[poly.parent[info]] -= prob
            rows.append(row)
    return np.array(rows).reshape(len(rows), poly.n_sequences), np.zeros(len(rows))


def normalise(payoff: np.ndarray, optimal: np.ndarray) -> float:
    """Scale [scalar] that maps the payoffs into [-1, 1] (1 if they are all zero)."""
    scale = max(float(np.abs(payoff).max(initial=0.0)), float(np.abs(optimal).max(initial=0.0)))
    return scale if scale > 0 else 1.0


def _rescaled(raw: RawRound, scale: float) -> RawRound:
    """A round with value and regret [L] multiplied back by ``scale``."""
    return replace(raw, value=raw.value * scale, regret=raw.regret * scale)


def solve_mmr_plan(poly: Polytope, payoff: np.ndarray, tol: float) -> RawRound:
    """Minimax regret over all levels: payoff [L, S] -> round (value, adversary, plan, regret)."""
    optimal = best_response_values(poly, payoff)
    scale = normalise(payoff, optimal)
    active = np.ones(payoff.shape[0], dtype=bool)
    raw = solve_regret_game(payoff / scale, optimal / scale, poly.equalities(), active, tol)
    return _rescaled(raw, scale)


def solve_blp_plans(
    poly: Polytope, payoff: np.ndarray, reach: np.ndarray, tol: float, progress=None, check=None
) -> list[RawRound]:
    """BLP by iterated refinement: the list of rounds, the last one holding the final plan.

    Round 1 is minimax regret over all levels. Round k+1 fixes the behaviour of round k's plan on
    every information set realisable on the union of the earlier supports, and lets the
    adversary choose only among levels outside those supports. Stops when every level is covered.
    Each round's ``unique`` tells whether the behaviour it fixes is the same in every optimal plan
    of its regret game (:func:`frozen_plan_is_unique`). ``check(rounds)``, if given, is called
    with the rounds so far after each round is solved (and may raise); then ``progress(value,
    support, covered, total)``, if given, with its value, its support's size, and how many of the
    ``total`` levels the supports cover so far.
    """
    optimal = best_response_values(poly, payoff)
    scale = normalise(payoff, optimal)
    payoff_n, optimal_n = payoff / scale, optimal / scale
    base = poly.equalities()
    eq = base
    covered = np.zeros(payoff.shape[0], dtype=bool)
    fixed = np.zeros(len(poly.parent), dtype=bool)
    rounds: list[RawRound] = []
    while not covered.all():
        active = ~covered
        raw = solve_regret_game(payoff_n, optimal_n, eq, active, tol)
        covered = covered | raw.support
        before, fixed = fixed, realisable_infosets(poly, reach, raw.plan, covered, tol)
        # only the information sets this round freezes: those frozen before are pinned by `eq` (and
        # so are their ancestors, realisable whenever they are), so their mass is the same in every plan
        frozen = np.array(sorted({seq for info in np.flatnonzero(fixed & ~before) for seq in poly.children[info]}),
                          dtype=int)
        unique = frozen_plan_is_unique(payoff_n, optimal_n, eq, active, raw.value, frozen)
        rounds.append(_rescaled(replace(raw, unique=unique, fixed=before if rounds else None), scale))
        if check is not None:
            check(rounds)
        if progress is not None:
            progress(rounds[-1].value, int(raw.support.sum()), int(covered.sum()), len(covered))
        rows, rhs = fixing_equalities(poly, raw.plan, fixed)
        eq = (np.vstack([base[0], rows]), np.concatenate([base[1], rhs]))
    return rounds
