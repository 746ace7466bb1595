"""A gymnax environment as a UED task: CartPole whose gravity, pole mass, pole length and start
seed are the level (:mod:`remidi.envs.gymnax`). From the repository root:

    PYTHONPATH=. remidi run examples.gymnax_cartpole:make_task --algo plr,accel --set score=pvl \\
        --set num_steps=500 --set num_updates=200 --out runs/cartpole

(``python -m remidi run ...`` finds ``examples`` from the current directory without PYTHONPATH.)
CartPole has no known optimal return, so choose a score without one (``pvl``, ``maxmc``,
``neg_return``, ``learnability``); the default ``perfect_regret`` is refused. Reported: the
return (and solve rate: the pole up for all 500 steps) on each point of the held-out grid
(``return/gravity=9.8_length=0.5`` ...), and which half of each range the adversary replays
(``replay_fraction/gravity_high`` ...). ``remidi run cartpole`` is the built-in version, with
presets and the grid mean.
"""

from remidi.envs.gymnax import gymnax_task


def make_task():
    return gymnax_task(
        "CartPole-v1",
        level={"gravity": (5.0, 15.0), "masspole": (0.05, 0.5), "length": (0.25, 1.0)},  # uniform ranges
        seed_in_level=True,  # the start state's seed is part of the level
        eval_grid={"gravity": (5.0, 9.8, 15.0), "length": (0.25, 0.5, 1.0)},  # held out: 9 points × 4 seeds
        solved_at=500.0,  # solved: the pole stays up for the whole episode
    )
