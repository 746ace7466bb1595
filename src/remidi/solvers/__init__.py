"""Exact solvers for finite games: minimax regret (MMR) and Bayesian level-perfect MMR (BLP).

* :mod:`~remidi.solvers.onestep` -- one-step games (an observation and a reward per action per
  level): :class:`OneStepGame`, :func:`solve_mmr`, :func:`solve_blp`.
* :mod:`~remidi.solvers.sequence_form` -- multi-step games as trees per level, solved in sequence
  form: :class:`TreeGame`, MMR, BLP, the locally-MMR policy and policy evaluation.
* :mod:`~remidi.solvers.decision_rules` -- minimax, leximin and minimax regret on utility tables.
* :mod:`~remidi.solvers.gamefile` / :mod:`~remidi.solvers.report` -- game files and
  ``remidi solve``.
* :mod:`~remidi.solvers.lp` -- the shared HiGHS linear programs.

The solve functions live in their modules (``onestep.solve_blp``, ``sequence_form.solve_blp``).
"""

from remidi.solvers.gamefile import load_game, parse_game
from remidi.solvers.onestep import OneStepGame
from remidi.solvers.results import BLPResult, MMRResult, Round
from remidi.solvers.sequence_form import TreeGame

__all__ = [
    "BLPResult",
    "MMRResult",
    "OneStepGame",
    "Round",
    "TreeGame",
    "load_game",
    "parse_game",
]
