"""Kinetix (Matthews et al., ICLR 2025): ``remidi run kinetix-s|kinetix-m|kinetix-l``.

Beyond the paper: 2-D physics tasks (make green touch blue, avoid red) on Kinetix's random levels
(behind its no-op filter) at one of its three sizes, evaluated on its hand-made held-out levels of
that size and smaller (:mod:`remidi.envs.kinetix`): ``solve_rate/<size>_<level>``, the mean per
size ``solve_rate/<size>``, and ``solve_rate/mean``.

Needs ``pip install -e ".[kinetix]"`` (``kinetix-env`` caps JAX at 0.9.0: use an environment of its
own); Kinetix is imported only when a task is built, so ``remidi list`` works without it.

Presets: ``paper`` (10 seeds) and ``gpu`` (3 seeds) are Kinetix's own PLR configuration
(``configs/plr.yaml``: 2048 envs × 256 steps, 2048 updates ≈ 2^30 steps, PPO 8 epochs × 32
minibatches, γ 0.995, λ 0.9, lr 5e-5, entropy 0.01, gradient norm 1.0; MaxMC over a rank-prioritised
buffer of 4000, replay 0.5, staleness 0.3; ACCEL 5 edits), with ReMiDi's 2 buffers, the first for a
quarter of the run. ``cpu`` and ``smoke`` are smaller, each deviation with its reason.

Every preset reads the ``symbolic_flat`` observation with the ``mlp`` network and plays the
``discrete`` actions (11; :mod:`remidi.envs.kinetix_obs`). Kinetix's own agent reads
``symbolic_entity`` (``kinetix.observation=entity``) with multi-discrete actions; the presets move
there once the engine has such a network."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from remidi.engine.config import AccelConfig, BufferConfig, ReMiDiConfig, SFLConfig, UEDConfig
from remidi.engine.core.ppo import PPOConfig
from remidi.errors import missing_extra
from remidi.envs.kinetix_names import HELD_OUT, SIZES, eval_set_names
from remidi.experiments.ued import UEDSpec, make_ued_experiment

TAGS = ("has_motor", "has_thruster", "has_red")


@dataclass(frozen=True)
class KinetixLevelsConfig:
    observation: str = field(default="symbolic_flat", metadata={
        "help": "what the agent observes: symbolic_flat (Kinetix's flat vector) or entity (its entities, remidi's "
                "entity convention)"})
    actions: str = field(default="discrete", metadata={
        "help": "Kinetix's action type: discrete (11 choices: a motor and direction, a thruster, or nothing) or "
                "multi_discrete (Kinetix's default: one choice per motor and per thruster)"})
    dense_reward_scale: float = field(default=0.2, metadata={
        "help": "Kinetix's dense shaping per unit of green–blue distance closed (its configs: 0.2; the episode's "
                "shaping sum is kept within ±0.45)"})
    filter_steps: int = field(default=64, metadata={
        "help": "steps of the no-op policy by which a sampled level is judged already solved (Kinetix's "
                "level_filter_n_steps; 0: no filter)"})
    filter_ratio: int = field(default=2, metadata={
        "help": "candidates drawn per sampled level by the no-op filter (Kinetix's level_filter_sample_ratio)"})


@dataclass(frozen=True)
class KinetixUEDConfig(UEDConfig):
    """A UED run on Kinetix: the engine's :class:`UEDConfig` plus the level generator's."""

    kinetix: KinetixLevelsConfig = field(default_factory=KinetixLevelsConfig)


def gpu_config() -> KinetixUEDConfig:
    """Kinetix's PLR configuration (the module's docstring) on remidi's engine: 2048 updates of PPO
    on 2048 envs × 256 steps, a 128-unit MLP (Kinetix's flat agent: a 128-unit embedding and five
    128-unit tanh layers; ours has two)."""
    return KinetixUEDConfig(
        num_updates=2048, num_envs=2048, num_steps=256, score="maxmc", network="mlp", hidden_size=128,
        eval_every=64, eval_attempts=20, checkpoint_every=256,
        ppo=PPOConfig(gamma=0.995, gae_lambda=0.9, clip_eps=0.2, clip_value=True, vf_coef=0.5, ent_coef=0.01,
                      epochs=8, minibatches=32, lr=5e-5, anneal_lr=False, adam_eps=1e-5, max_grad_norm=1.0),
        buffer=BufferConfig(capacity=4000, prioritization="rank", temperature=1.0, staleness_coef=0.3,
                            replay_prob=0.5, min_fill=0.5, duplicate_check=False),
        # one tracker slot: two Kinetix levels rarely share a first observation (positions are drawn at
        # random), and each slot steps the physics once more per env and step (tracker_overflow counts misses)
        remidi=ReMiDiConfig(num_buffers=2, buffer_capacity=4000, steps_per_buffer=512, tracker_budget=1),
        accel=AccelConfig(num_edits=5),
        # Kinetix's SFL (configs/ued/sfl.yaml): 3 batches of 4096 candidates played 512 steps, the 1024
        # most learnable kept, refreshed every 128 updates, half of each update's envs from the buffer
        sfl=SFLConfig(batch_size=4096, num_batches=3, rollout_steps=512, buffer_size=1024, refresh_every=128,
                      sampled_envs_ratio=0.5),
    )


# smoke: the machinery end to end (a few updates of 8 envs, each playing a whole episode's 256 steps
# per rollout, as Kinetix's PLR does: MaxMC scores only levels whose episode ended); its cost is
# compiling Kinetix's sampler, filter and physics into the train step, minutes on a 2-core CPU
SMOKE = {
    "num_updates": 6, "num_envs": 8, "eval_every": 3, "eval_attempts": 1, "checkpoint_every": 3,
    "hidden_size": 64, "ppo.epochs": 1, "ppo.minibatches": 1, "ppo.lr": 3e-4, "buffer.capacity": 16,
    "buffer.min_fill": 0.25, "remidi.buffer_capacity": 16, "remidi.steps_per_buffer": 3,
    "sfl.batch_size": 16, "sfl.num_batches": 1, "sfl.rollout_steps": 512, "sfl.buffer_size": 8, "sfl.refresh_every": 3,
}
CPU_REASONS = {
    "num_updates": "Kinetix's 2048 updates of 2048 envs × 256 steps are ≈ 2^30 environment steps, months on a "
                   "2-core CPU; 200 updates of 32 envs × 256 steps fit hours per seed and algorithm",
    "num_envs": "32 envs instead of 2048: Kinetix's physics steps about 2000 envs per second on a 2-core CPU",
    "eval_every": "a point every 20 updates: 10 points over the run",
    "eval_attempts": "5 attempts per held-out level instead of 20: evaluation plays 256 steps per attempt",
    "checkpoint_every": "at every other evaluation",
    "ppo.minibatches": "4 minibatches of 8 envs (Kinetix's 32 minibatches would hold one env each)",
    "ppo.epochs": "4 epochs instead of 8: half the gradient cost of an update",
    "ppo.lr": "3e-4 instead of 5e-5: the smaller batch learns within 200 updates",
    "buffer.capacity": "256 levels instead of 4000, in proportion to the fewer levels seen",
    "remidi.buffer_capacity": "256 levels, as buffer.capacity",
    "remidi.steps_per_buffer": "the gpu preset's proportion: the first buffer spans a quarter of the run",
    "sfl.batch_size": "Kinetix's SFL refresh (4096 × 3 candidates played 512 steps) is 6.3 M physics steps, "
                      "770 of this preset's updates; 256 candidates per refresh",
    "sfl.num_batches": "one batch of 256 candidates (Kinetix: 3 of 4096)",
    "sfl.buffer_size": "the 64 most learnable of 256 candidates kept (Kinetix: 1024 of 12,288)",
    "sfl.refresh_every": "every 50 updates (4 refreshes in 200; Kinetix: 128 of 2048): a refresh's 131 k physics "
                         "steps against 50 updates' 410 k",
}
CPU = {"num_updates": 200, "num_envs": 32, "eval_every": 20, "eval_attempts": 5,
       "checkpoint_every": 40, "ppo.minibatches": 4, "ppo.epochs": 4, "ppo.lr": 3e-4, "buffer.capacity": 256,
       "remidi.buffer_capacity": 256, "remidi.steps_per_buffer": 50, "sfl.batch_size": 256, "sfl.num_batches": 1,
       "sfl.buffer_size": 64, "sfl.refresh_every": 50}
PRESETS = {"paper": {}, "gpu": {}, "cpu": CPU, "smoke": SMOKE}


def make_derive(size: str):
    sizes = SIZES[:SIZES.index(size) + 1]

    def derive(history: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """``solve_rate/<size>`` (the mean over that size's held-out levels) and ``solve_rate/mean``
        (over all of them), f[S, T]."""
        out = {}
        for s in sizes:
            rates = [history[f"solve_rate/{s}_{n}"] for n in HELD_OUT[s] if f"solve_rate/{s}_{n}" in history]
            if rates:
                out[f"solve_rate/{s}"] = np.mean(rates, axis=0)
        rates = [history[f"solve_rate/{n}"] for n in eval_set_names(size) if f"solve_rate/{n}" in history]
        if rates:
            out["solve_rate/mean"] = np.mean(rates, axis=0)
        return out

    return derive


def task_factory(size: str):
    def factory(cfg: KinetixUEDConfig):
        try:
            from remidi.envs.kinetix import kinetix_task  # Kinetix itself: the optional extra
        except ModuleNotFoundError as err:
            raise missing_extra(err, f"kinetix-{size}", "kinetix", " in a virtual environment of its own (kinetix-env "
                                "caps JAX at 0.9; README, Installation)") from None

        k = cfg.kinetix
        return kinetix_task(size, k.observation, k.actions, k.dense_reward_scale, k.filter_steps, k.filter_ratio)

    return factory


def _experiment(size: str):
    sizes = SIZES[:SIZES.index(size) + 1]
    return make_ued_experiment(UEDSpec(
        name=f"kinetix-{size}",
        description=f"beyond the paper: Kinetix 2-D physics tasks, size {size}, held-out levels of sizes "
                    f"{', '.join(sizes)} (needs the kinetix extra, jax ≤ 0.9)",
        task_factory=task_factory(size),
        config_factory=gpu_config,
        presets=PRESETS,
        preset_seeds={"paper": 10, "gpu": 3, "cpu": 2, "smoke": 1},
        task_gives=("solved",),  # a return above 0.5; no optimal return
        summary_metrics=("solve_rate/mean", *(f"solve_rate/{s}" for s in sizes),
                         *(f"replay_fraction/{t}" for t in TAGS)),
        plot_panels_spec=(("solve_rate/mean", "mean solve rate, held-out levels"),
                          *((f"solve_rate/{s}", f"solve rate, held-out levels of size {s}") for s in sizes[:-1]),
                          *((f"replay_fraction/{t}", f"share of levels with {t[4:]} among replayed levels")
                            for t in TAGS)),
        derive=make_derive(size),
        bar_chart=("final solve rate per held-out size", tuple(f"solve_rate/{s}" for s in sizes)),
        preset_reasons={"cpu": CPU_REASONS},
        builds_levels=False,  # no level-building MDP: no PAIRED
        notes=("needs the kinetix extra (pip install -e \".[kinetix]\", kinetix-env: jax ≤ 0.9) in an "
               "environment of its own",),
    ))


EXPERIMENTS = [_experiment(size) for size in SIZES]
