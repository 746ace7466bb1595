"""An independent reference for the solver tests: zero-sum matrix games over explicit policies.

Rows are (deterministic) policies, columns levels, entries regret. Written directly with
``linprog`` and no code from ``remidi.solvers``.
"""

import numpy as np
from scipy.optimize import linprog


def matrix_game_value(regret: np.ndarray) -> float:
    """min over mixtures mu [P] of max over columns of mu @ regret."""
    n_pol, n_lev = regret.shape
    result = linprog(np.r_[np.zeros(n_pol), 1.0],
                     A_ub=np.hstack([regret.T, -np.ones((n_lev, 1))]), b_ub=np.zeros(n_lev),
                     A_eq=np.r_[np.ones(n_pol), 0.0][None], b_eq=[1.0],
                     bounds=[(0, None)] * n_pol + [(None, None)], method="highs")
    assert result.status == 0
    return result.fun


def maximal_support(regret: np.ndarray, value: float) -> set[int]:
    """Columns with positive probability in some equilibrium adversary of the matrix game."""
    n_pol, n_lev = regret.shape
    slack = 1e-9 * max(np.abs(regret).max(), 1e-12)
    support = set()
    for k in range(n_lev):
        cost = np.zeros(n_lev)
        cost[k] = -1.0
        result = linprog(cost, A_ub=-regret, b_ub=-(value - slack) * np.ones(n_pol),
                         A_eq=np.ones((1, n_lev)), b_eq=[1.0], bounds=[(0, None)] * n_lev,
                         method="highs")
        if result.status == 0 and -result.fun > 1e-6:
            support.add(k)
    return support
