"""Tabular UED (paper §6.2): the paper's one-step game (:mod:`~remidi.tabular.games`) and the
exact-expectation learners MMR-UED and ReMiDi (:mod:`~remidi.tabular.learner`).

The game type is the exact solver's :class:`~remidi.solvers.onestep.OneStepGame`, so a game
trained on here is solved exactly by ``remidi.solvers.onestep.solve_blp`` with no conversion.
"""
