"""The paper's tabular one-step game (ReMiDi §6.2), as a :class:`~remidi.solvers.onestep.OneStepGame`.

The paper's game (ReMiDi §6.2) has six levels and two actions (A, B). In the ``distinct``
setting every level has its own observation; in ``shared`` the pairs (θ1, θ2), (θ3, θ4),
(θ5, θ6) share one observation each, so the agent cannot tell the levels of a pair apart and
has to pick one distribution over actions for both.

A game is the solver's :class:`~remidi.solvers.onestep.OneStepGame` (plain NumPy data: per
level an observation and a reward per action): the exact solvers and the tabular learners
(:mod:`remidi.tabular.learner`, which turns it into JAX arrays) read the same object. Regret here
is always *expected* regret, computed exactly from the policy's action probabilities.
"""

from __future__ import annotations

import numpy as np

from remidi.errors import one_of
from remidi.solvers.onestep import OneStepGame

PAPER_REWARDS = np.array(
    [
        [-0.1, +0.1],  # θ1
        [+0.7, -0.7],  # θ2
        [-0.7, +0.7],  # θ3
        [+0.1, -0.1],  # θ4
        [-1.0, +1.0],  # θ5
        [+1.0, -1.0],  # θ6
    ]
)
PAPER_LEVEL_NAMES = tuple(f"theta{i}" for i in range(1, 7))
SETTINGS = ("distinct", "shared")


def paper_game(setting: str) -> OneStepGame:
    """The six-level game of the paper, observations named as in the paper (h1…)."""
    if setting == "distinct":
        level_obs = np.arange(6)
        obs_names = tuple(f"h{i}" for i in range(1, 7))
    elif setting == "shared":
        level_obs = np.array([0, 0, 1, 1, 2, 2])
        obs_names = ("h1", "h3", "h5")
    else:
        raise one_of("setting", setting, SETTINGS)
    return OneStepGame(
        actions=("A", "B"),
        level_names=PAPER_LEVEL_NAMES,
        observations=tuple(obs_names[o] for o in level_obs),
        rewards=PAPER_REWARDS.copy(),
    )
