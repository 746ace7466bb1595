"""An independent reference for the solver tests: zero-sum matrix games over explicit policies.

Rows are (deterministic) policies, columns levels, entries regret. Written directly with
``linprog`` and no code from ``remidi.solvers``.
"""

import numpy as np
from scipy.optimize import linprog

#: Tight HiGHS tolerances: with the default 1e-7 feasibility tolerance, an adversary may lose up
#: to 1e-7 of value, which buys a level whose regret is ``gap`` below the value 1e-7 / gap of mass
#: -- above the 1e-6 support threshold whenever gap < 0.1.
_OPTIONS = {"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10}


def matrix_game_value(regret: np.ndarray) -> float:
    """min over mixtures mu [P] of max over columns of mu @ regret."""
    n_pol, n_lev = regret.shape
    result = linprog(np.r_[np.zeros(n_pol), 1.0],
                     A_ub=np.hstack([regret.T, -np.ones((n_lev, 1))]), b_ub=np.zeros(n_lev),
                     A_eq=np.r_[np.ones(n_pol), 0.0][None], b_eq=[1.0],
                     bounds=[(0, None)] * n_pol + [(None, None)], method="highs", options=_OPTIONS)
    assert result.status == 0
    return result.fun


def maximal_support(regret: np.ndarray, value: float) -> set[int]:
    """Columns with positive probability in some equilibrium adversary of the matrix game.

    A column ``gap`` below the value in every equilibrium gets at most ``slack / gap`` mass, so it
    is misclassified only if gap < 1e-6 (relative to the largest regret).
    """
    n_pol, n_lev = regret.shape
    slack = 1e-12 * max(np.abs(regret).max(), 1e-12)
    support = set()
    for k in range(n_lev):
        cost = np.zeros(n_lev)
        cost[k] = -1.0
        result = linprog(cost, A_ub=-regret, b_ub=-(value - slack) * np.ones(n_pol),
                         A_eq=np.ones((1, n_lev)), b_eq=[1.0], bounds=[(0, None)] * n_lev,
                         method="highs", options=_OPTIONS)
        if result.status == 0 and -result.fun > 1e-6:
            support.add(k)
    return support
