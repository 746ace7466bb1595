"""gymnax's classic-control environments as UED domains: ``remidi run cartpole|acrobot|pendulum``.

Beyond the paper (SPEC §6): a level is physical parameters, each uniform in a range, and the start
seed (:mod:`remidi.envs.gymnax`). Evaluation on a held-out grid over two parameters:
``return/<point>`` (mean over 4 start seeds × ``eval_attempts``), ``return/mean``, and likewise
``solve_rate/<point>``, ``solve_rate/mean`` (CartPole: the pole stays up all episode; Acrobot:
return ≥ −100; Pendulum: return ≥ −200).

No optimal return, so the presets score by positive value loss (``pvl``). ``paper`` is the full run
(10 seeds; no paper setting exists); ``smoke`` takes minutes on a 2-core CPU, episodes capped at
200 steps (``gymnax.max_steps``)."""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass, field
from functools import cache

import numpy as np

from remidi.engine.config import BufferConfig
from remidi.engine.config import ReMiDiConfig, UEDConfig
from remidi.engine.core.ppo import PPOConfig
from remidi.envs.gymnax import gymnax_task, point_name
from remidi.errors import require
from remidi.experiments.ued import UEDSpec, make_ued_experiment


@dataclass(frozen=True)
class GymnaxLevelsConfig:
    max_steps: int = field(default=0, metadata={
        "help": "episode limit (gymnax's max_steps_in_episode; 0: gymnax's own, 500 for CartPole and Acrobot, "
                "200 for Pendulum)"})


@dataclass(frozen=True)
class GymnaxUEDConfig(UEDConfig):
    """A UED run on a gymnax domain: the engine's :class:`UEDConfig` plus the episode limit."""

    gymnax: GymnaxLevelsConfig = field(default_factory=GymnaxLevelsConfig)


@dataclass(frozen=True)
class Domain:
    """A built-in gymnax domain: the environment, level ranges, held-out grid and what counts as
    solved: ``solved_at`` at gymnax's episode limit (None: the whole episode survived); with
    ``solved_scales`` the threshold scales with the limit (a cost per step), otherwise −1 per step
    until the goal. A failed episode never counts as solved."""

    name: str
    env_name: str
    level: dict
    grid: dict
    solved_at: float | None
    reward_scale: float = 1.0
    solved_scales: bool = False
    description: str = ""


DOMAINS = {d.name: d for d in (
    Domain("cartpole", "CartPole-v1",
           level={"gravity": (5.0, 15.0), "masspole": (0.05, 0.5), "length": (0.25, 1.0)},
           grid={"gravity": (5.0, 9.8, 15.0), "length": (0.25, 0.5, 1.0)}, solved_at=None,
           description="gymnax CartPole: gravity, pole mass, pole length and start seed as the level"),
    Domain("acrobot", "Acrobot-v1",
           level={"link_length_1": (0.5, 1.5), "link_mass_1": (0.5, 1.5), "link_mass_2": (0.5, 1.5)},
           grid={"link_length_1": (0.75, 1.0, 1.25), "link_mass_2": (0.75, 1.0, 1.25)}, solved_at=-100.0,
           description="gymnax Acrobot: first link's length, both links' masses and start seed as the level"),
    Domain("pendulum", "Pendulum-v1",
           level={"g": (5.0, 15.0), "m": (0.5, 1.5), "l": (0.5, 1.5)},
           grid={"g": (5.0, 10.0, 15.0), "l": (0.75, 1.0, 1.25)}, solved_at=-200.0, solved_scales=True,
           reward_scale=0.1,
           description="gymnax Pendulum (continuous torque): gravity, mass, length and start seed as the level"),
)}


def paper_config() -> GymnaxUEDConfig:
    """The full run: 500 updates of PPO on 32 envs × 512 steps (longer than an episode, so
    every level's PVL is scored), 4 epochs of 4 minibatches, γ 0.99, λ 0.95, lr 3e-4, entropy
    0.01 (PureJaxRL's classic-control PPO), a 64-unit MLP; PLR⊥ rank prioritisation over 256
    levels, replay 0.8; ReMiDi 2 buffers of 128, the first for 250 updates."""
    return GymnaxUEDConfig(
        num_updates=500, num_envs=32, num_steps=512, score="pvl", network="mlp", hidden_size=64,
        eval_every=25, eval_attempts=2, checkpoint_every=50,
        ppo=PPOConfig(gamma=0.99, gae_lambda=0.95, clip_eps=0.2, clip_value=True, vf_coef=0.5, ent_coef=0.01,
                      epochs=4, minibatches=4, lr=3e-4, anneal_lr=True, adam_eps=1e-5, max_grad_norm=0.5),
        buffer=BufferConfig(capacity=256, prioritization="rank", temperature=1.0, staleness_coef=0.3,
                            replay_prob=0.8, min_fill=0.5, duplicate_check=True),
        remidi=ReMiDiConfig(num_buffers=2, buffer_capacity=128, steps_per_buffer=250),
    )


# smoke: 200-step episodes and rollouts, 16 envs, 60 updates: the machinery end to end in
# minutes per algorithm on a 2-core CPU (CartPole's return on the grid rises within it)
SMOKE = {
    "gymnax.max_steps": 200, "num_steps": 200, "num_envs": 16, "num_updates": 60, "eval_every": 20,
    "checkpoint_every": 20, "ppo.minibatches": 2, "ppo.lr": 1e-3, "buffer.capacity": 64,
    "remidi.buffer_capacity": 32, "remidi.steps_per_buffer": 20,
}
PRESETS = {"paper": {}, "smoke": SMOKE}


@cache
def domain_task(name: str, max_steps: int = 0):
    """The domain's UED task (cached: one task per arguments, so runs share compiled programs);
    ``max_steps`` 0 keeps gymnax's episode limit."""
    import gymnax

    d = DOMAINS[name]
    params = {"max_steps_in_episode": max_steps} if max_steps else {}
    default = int(gymnax.make(d.env_name)[1].max_steps_in_episode)
    limit = max_steps or default
    if d.solved_at is None:  # the whole episode: the limit's number of steps of reward 1
        solved_at = float(limit)
    elif d.solved_scales:  # a cost per step: the threshold at gymnax's limit, per step
        solved_at = d.solved_at * limit / default
    else:  # −1 per step until the goal: up within -solved_at steps, or within a shorter episode
        solved_at = max(d.solved_at, -(limit - 1.0))
    return gymnax_task(d.env_name, d.level, params=params, eval_grid=d.grid, solved_at=solved_at)


def grid_points(name: str) -> tuple[str, ...]:
    """The names of the domain's held-out grid points (its evaluation sets), in the task's order."""
    grid = DOMAINS[name].grid
    return tuple(point_name(dict(zip(grid, values))) for values in itertools.product(*grid.values()))


def make_derive(points: tuple[str, ...]):
    def derive(history: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """``return/mean`` and ``solve_rate/mean``: the means over the grid points, f[S, T]."""
        return {f"{kind}/mean": np.mean([history[f"{kind}/{p}"] for p in points], axis=0)
                for kind in ("return", "solve_rate") if all(f"{kind}/{p}" in history for p in points)}

    return derive


def task_factory(name: str):
    def factory(cfg: GymnaxUEDConfig):
        require(isinstance(cfg.gymnax.max_steps, int) and cfg.gymnax.max_steps >= 0, "gymnax.max_steps",
                "an integer ≥ 0 (0: gymnax's own limit)", cfg.gymnax.max_steps)
        return domain_task(name, cfg.gymnax.max_steps)

    return factory


def _experiment(d: Domain):
    points = grid_points(d.name)
    tags = tuple(f"{n}_high" for n in d.level)
    return make_ued_experiment(UEDSpec(
        name=d.name,
        description=d.description + "; held-out grid of " + " × ".join(d.grid),
        task_factory=task_factory(d.name),
        config_factory=lambda: dataclasses.replace(paper_config(), reward_scale=d.reward_scale),
        presets=PRESETS,
        preset_seeds={"paper": 10, "smoke": 2},
        task_gives=("solved",),  # a return threshold; no optimal return
        cheap_step=True,  # classic control: a few arithmetic operations per step
        summary_metrics=("return/mean", "solve_rate/mean", *(f"return/{p}" for p in points),
                         *(f"replay_fraction/{t}" for t in tags)),
        plot_panels_spec=(("return/mean", "mean return over the held-out grid"),
                          ("solve_rate/mean", "mean solve rate over the held-out grid"),
                          *((f"replay_fraction/{t}", f"share of levels with {t[:-5]} in the upper half, replayed")
                            for t in tags)),
        derive=make_derive(points),
        bar_chart=("final return per held-out grid point", tuple(f"return/{p}" for p in points) + ("return/mean",)),
        builds_levels=False,  # gymnax tasks have no level-building MDP: no PAIRED
    ))


EXPERIMENTS = [_experiment(d) for d in DOMAINS.values()]
