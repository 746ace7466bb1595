"""Tabular one-step games: N levels, each with an observation id and a reward per action.

The paper's game (ReMiDi §6.2) has six levels and two actions (A, B). In the ``distinct``
setting every level has its own observation; in ``shared`` the pairs (θ1, θ2), (θ3, θ4),
(θ5, θ6) share one observation each, so the agent cannot tell the levels of a pair apart and
has to pick one distribution over actions for both.

A :class:`TabularGame` is plain NumPy data; the learners turn it into JAX arrays. Regret here
is always *expected* regret, computed exactly from the policy's action probabilities.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from remidi.errors import one_of

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


@dataclass(frozen=True)
class TabularGame:
    """A one-step game.

    Attributes:
        actions: action names, length A.
        level_names: level names, length L.
        observation_names: observation names, length O.
        level_obs: int[L], the observation index of each level.
        rewards: f64[L, A], reward of each action on each level.
    """

    actions: tuple[str, ...]
    level_names: tuple[str, ...]
    observation_names: tuple[str, ...]
    level_obs: np.ndarray
    rewards: np.ndarray

    @property
    def num_levels(self) -> int:
        return len(self.level_names)

    @property
    def num_observations(self) -> int:
        return len(self.observation_names)

    @property
    def num_actions(self) -> int:
        return len(self.actions)

    def obs_level_matrix(self) -> np.ndarray:
        """f64[O, L]: 1 where level l shows observation o."""
        m = np.zeros((self.num_observations, self.num_levels))
        m[self.level_obs, np.arange(self.num_levels)] = 1.0
        return m

    def action_regret(self) -> np.ndarray:
        """f64[L, A]: regret of playing action a on level l, ``max_b r(l, b) − r(l, a)``."""
        return self.rewards.max(axis=1, keepdims=True) - self.rewards


def paper_game(setting: str) -> TabularGame:
    """The six-level game of the paper, observations named as in the paper (h1…)."""
    if setting == "distinct":
        level_obs = np.arange(6)
        obs_names = tuple(f"h{i}" for i in range(1, 7))
    elif setting == "shared":
        level_obs = np.array([0, 0, 1, 1, 2, 2])
        obs_names = ("h1", "h3", "h5")
    else:
        raise one_of("setting", setting, SETTINGS)
    return TabularGame(
        actions=("A", "B"),
        level_names=PAPER_LEVEL_NAMES,
        observation_names=obs_names,
        level_obs=level_obs,
        rewards=PAPER_REWARDS.copy(),
    )
