"""The dark reach experiments (beyond the paper): ``remidi run darkreach`` and ``darkreach-lit``.

A point in the unit square reaches a goal (:mod:`remidi.envs.darkreach`), seen through float
observations with N(0, 0.01) noise from the level's seed: lit levels show the goal, dark ones hide
it (irreducible regret). No float repeats, so the exact tracker matches nothing; these experiments
judge with the tolerance tracker (``remidi.tracker_tolerance=0.05``: five noise deviations, half
the lattice spacing), under which dark levels with one start are one level (rejected later) and
lit levels with goals over 0.05 apart are not. ``--set remidi.tracker=prefix`` compares the exact one.

``darkreach-lit``: every level lit and distinct, so ReMiDi should reject none and be PLR⊥.

Budgets: one capacity (64) for every buffer, no duplicate check (continuous goals), the switch at
half the run."""

from __future__ import annotations

from remidi.engine.config import BufferConfig, ReMiDiConfig, UEDConfig
from remidi.engine.core.ppo import PPOConfig
from remidi.envs.darkreach import darkreach_task
from remidi.experiments.ued import UEDSpec, make_ued_experiment

CAPACITY = 64  # PLR⊥'s buffer and each ReMiDi buffer
TOLERANCE = 0.05  # 5 σ of the position noise (0.01); half the lattice spacing (0.1)
NUM_UPDATES = 1000


def base_config() -> UEDConfig:
    """32 envs × 20 steps (episodes ≤ 20), a 64-unit MLP, perfect regret, rank prioritisation over
    64 levels; ReMiDi 2 buffers of 64 switching at half the run, tolerance tracker."""
    return UEDConfig(
        num_updates=NUM_UPDATES, num_envs=32, num_steps=20, score="perfect_regret", network="mlp", hidden_size=64,
        eval_every=50, eval_attempts=4, checkpoint_every=250,
        ppo=PPOConfig(gamma=0.99, gae_lambda=0.95, clip_eps=0.2, clip_value=True, vf_coef=0.5, ent_coef=0.01,
                      epochs=4, minibatches=1, lr=1e-3, anneal_lr=True, adam_eps=1e-5, max_grad_norm=0.5),
        buffer=BufferConfig(capacity=CAPACITY, prioritization="rank", temperature=0.3, staleness_coef=0.3,
                            replay_prob=0.8, min_fill=0.5, duplicate_check=False),
        remidi=ReMiDiConfig(num_buffers=2, buffer_capacity=CAPACITY, steps_per_buffer=NUM_UPDATES // 2,
                            count="updates", tracker="tolerance", tracker_tolerance=TOLERANCE),
    )


PRESETS = {
    # a few minutes per algorithm for 5 vmapped seeds on one CPU core
    "cpu": {},
    # seconds: the switch at update 30
    "smoke": {"num_updates": 60, "eval_every": 20, "checkpoint_every": 60, "remidi.steps_per_buffer": 30},
}

SUMMARY_METRICS = ("solve_rate/lit", "solve_rate/dark", "regret/lit/mean", "regret/dark/mean", "rejected",
                   "trained_fraction_masked", "replay_fraction/dark", "buffer_fraction/dark")
LIT_METRICS = ("solve_rate/lit", "regret/lit/mean", "rejected", "trained_fraction_masked")
PLOT_PANELS = (("solve_rate/lit", "solve rate, lit levels"),
               ("solve_rate/dark", "solve rate, dark levels", {"optional": True}),
               ("regret/lit/mean", "mean regret over lit levels", {"ylim": (0.0, None)}),
               ("rejected", "fresh levels rejected per block", {"optional": True}),
               ("replay_fraction/dark", "share of dark levels among replayed", {"optional": True}),
               ("buffer_fraction/dark", "share of dark levels in the active buffer", {"optional": True}))


def _experiment(name: str, description: str, task_factory, summary_metrics):
    return make_ued_experiment(UEDSpec(
        name=name, description=description, task_factory=task_factory, config_factory=base_config,
        presets=PRESETS, preset_seeds={"cpu": 5, "smoke": 2}, summary_metrics=summary_metrics,
        plot_panels_spec=PLOT_PANELS, task_gives=("optimal_return", "solved"),
        cheap_step=True))  # a lattice move and a hash: cheaper than the agent's network


EXPERIMENTS = [
    _experiment("darkreach", "beyond the paper: a point reaches a goal in the unit square through noisy float "
                             "observations; half the levels hide the goal (irreducible regret); the tolerance tracker",
                lambda cfg: darkreach_task(), SUMMARY_METRICS),
    _experiment("darkreach-lit", "beyond the paper: dark reach with every level lit and the start anywhere, so every "
                                 "level differs (the tolerance tracker should reject none)",
                lambda cfg: darkreach_task(lit_prob=1.0, random_start=True), LIT_METRICS),
]
