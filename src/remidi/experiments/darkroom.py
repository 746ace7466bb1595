"""The dark room experiment (beyond the paper): ``remidi run darkroom``.

A 5×5 grid, 12 border goals (:mod:`remidi.envs.darkroom`): lit levels show the goal, dark ones do
not (a guess, 1/12: irreducible regret). Only 108 lit levels, like a user's small level space:
ReMiDi's first buffer holds many learnable levels, its second rejects and masks them.
``buffer_solve_rate/b<k>`` shows what the agent keeps of a frozen buffer (docs/retention.md).

Budgets: one capacity for every buffer, duplicate check on, the switch at half the run."""

from __future__ import annotations

from remidi.engine.config import BufferConfig, ReMiDiConfig, UEDConfig
from remidi.engine.core.ppo import PPOConfig
from remidi.envs.darkroom import darkroom_task
from remidi.experiments.ued import UEDSpec, make_ued_experiment

SIZE, NUM_GOALS = 5, 12
CAPACITY = 64  # PLR⊥'s buffer and each ReMiDi buffer


def base_config() -> UEDConfig:
    """600 updates of 32 envs × 16 steps (episodes ≤ 15), a 64-unit MLP, perfect regret, rank
    prioritisation over 64 levels with duplicate check; ReMiDi 2 buffers of 64 switching at half the
    run (3 seeds: about 6 min for PLR⊥, 8 for ReMiDi on a loaded 2-core CPU)."""
    return UEDConfig(
        num_updates=600, num_envs=32, num_steps=16, score="perfect_regret", network="mlp", hidden_size=64,
        eval_every=50, eval_attempts=5, checkpoint_every=300,
        ppo=PPOConfig(gamma=0.99, gae_lambda=0.95, clip_eps=0.2, clip_value=True, vf_coef=0.5, ent_coef=0.01,
                      epochs=4, minibatches=1, lr=2e-3, anneal_lr=True, adam_eps=1e-5, max_grad_norm=0.5),
        buffer=BufferConfig(capacity=CAPACITY, prioritization="rank", temperature=0.3, staleness_coef=0.3,
                            replay_prob=0.8, min_fill=0.5, duplicate_check=True),
        remidi=ReMiDiConfig(num_buffers=2, buffer_capacity=CAPACITY, steps_per_buffer=300, count="updates"),
    )


PRESETS = {
    "cpu": {},
    # a few minutes on a 2-core CPU: the switch at update 100
    "smoke": {"num_updates": 200, "checkpoint_every": 100, "remidi.steps_per_buffer": 100},
}

SUMMARY_METRICS = ("solve_rate/lit", "solve_rate/dark", "regret/lit/mean", "buffer_solve_rate/b0",
                   "buffer_solve_rate/b1", "replay_fraction/dark", "buffer_fraction/dark", "buffer_fraction/dark/b1")
PLOT_PANELS = (("solve_rate/lit", "solve rate, lit levels"),
               ("solve_rate/dark", "solve rate, dark levels",
                {"references": [(1 / NUM_GOALS, f"chance (1/{NUM_GOALS})")]}),
               ("buffer_solve_rate/b0", "solve rate on buffer 1's levels", {"optional": True}),
               ("buffer_solve_rate/b1", "solve rate on buffer 2's levels", {"optional": True}),
               ("replay_fraction/dark", "share of dark levels among replayed"),
               ("buffer_fraction/dark", "share of dark levels in the active buffer"))

EXPERIMENTS = [
    make_ued_experiment(UEDSpec(
        name="darkroom", description="beyond the paper: 5×5 grid, 12 border goals, half the levels hide the goal "
                                     "(irreducible regret); a small level space",
        task_factory=lambda cfg: darkroom_task(SIZE, NUM_GOALS), config_factory=base_config, presets=PRESETS,
        preset_seeds={"cpu": 3, "smoke": 2}, summary_metrics=SUMMARY_METRICS, plot_panels_spec=PLOT_PANELS,
        builds_levels=False, task_gives=("optimal_return", "solved"), cheap_step=True)),
]
