"""The budgets an import-path task's run gives each algorithm (:func:`budget_defaults`), so that
PLR⊥, minimax return, ACCEL, ReMiDi and SFL are compared at one level budget, and the line a
run says of each (:func:`budget_line`). The rule is docs/extending.md's ("Defaults")."""

from __future__ import annotations

import math
from typing import Any

from remidi.engine.adversaries.accel import EditingBuffers
from remidi.engine.adversaries.base import RandomLevels
from remidi.engine.adversaries.paired import GeneratorSequence, LevelGenerator
from remidi.engine.adversaries.plr import LevelBuffers
from remidi.engine.adversaries.sfl import LearnabilityBuffers
from remidi.engine.algorithms import get_algorithm
from remidi.engine.config import UEDConfig
from remidi.envs.interface import UEDTask
from remidi.experiments.overrides import apply_overrides

FRESH_PER_SLOT = 16  # an import-path task's buffers hold a sixteenth of the fresh levels PLR⊥ evaluates (buffer_capacity) ...
MIN_CAPACITY, MAX_CAPACITY = 64, 4000  # ... at least 64, at most 4,000 (the paper's maze buffer and JaxUED's)
SFL_CANDIDATES = 4  # SFL keeps the most learnable quarter of its candidates (budget_defaults)
SFL_EPISODES = 4  # ... each played this many episodes of the task's bound
SFL_BATCH_ROLLOUTS = 8  # ... in batches of as many steps as this many training rollouts
# the keys budget_defaults derives from the run's size (not scaled in proportion to num_updates)
BUDGET_KEYS = ("buffer.capacity", "remidi.buffer_capacity", "buffer.duplicate_check", "remidi.steps_per_buffer",
               "sfl.buffer_size", "sfl.rollout_steps", "sfl.batch_size", "sfl.num_batches", "sfl.refresh_every")
MAX_ROLLOUT = 256  # an import-path task's rollouts last its episode bound, at most this (the paper's maze: 256)


def buffer_capacity(config: UEDConfig) -> int:
    """C, the one buffer capacity of an import-path task's run (every buffer and SFL's kept levels):
    a sixteenth of the fresh levels PLR⊥ sees, ``num_updates × num_envs × (1 − buffer.replay_prob)``,
    rounded up and clamped to [:data:`MIN_CAPACITY`, :data:`MAX_CAPACITY`]. Replay then stays
    selective while each level is replayed about 16·p/(1 − p) times (64 at p = 0.8), enough for its
    score to follow the agent."""
    fresh = config.num_updates * config.num_envs * (1.0 - config.buffer.replay_prob)
    return int(min(max(math.ceil(fresh / FRESH_PER_SLOT), MIN_CAPACITY), MAX_CAPACITY))


def budget_defaults(task: UEDTask, config: UEDConfig, overrides: dict[str, Any]) -> UEDConfig:
    """``config`` with the :data:`BUDGET_KEYS` that ``overrides`` leave alone derived from its other
    keys, so they follow ``--set num_updates=N`` (and ``num_envs``, ``buffer.replay_prob``, ...):

    * one capacity C (:func:`buffer_capacity`, or a hand-set ``buffer.capacity`` /
      ``remidi.buffer_capacity``) for ``buffer.capacity``, ``remidi.buffer_capacity`` and
      ``sfl.buffer_size``;
    * ``buffer.duplicate_check`` true: a repeated level updates its entry instead of copying;
    * ``remidi.steps_per_buffer`` = ⌈num_updates / remidi.num_buffers⌉;
    * SFL keeps the C most learnable of 4·C candidates (published: 1,000 of 25,000), each played
      ``sfl.rollout_steps`` = 4 task episodes (≤ 4 × :data:`MAX_ROLLOUT`), in batches of about 8
      training rollouts' steps (``sfl.batch_size`` = ⌈8 · num_envs · num_steps / rollout_steps⌉, ≤ 4·C;
      ``sfl.num_batches`` = ⌈4·C / batch_size⌉), refreshed every ``eval_every`` updates."""
    given = set(overrides)
    if "buffer.capacity" in given:
        capacity = config.buffer.capacity
    elif "remidi.buffer_capacity" in given:
        capacity = config.remidi.buffer_capacity
    else:
        capacity = buffer_capacity(config)
    kept = config.sfl.buffer_size if "sfl.buffer_size" in given else capacity
    rollout = config.sfl.rollout_steps if "sfl.rollout_steps" in given else \
        SFL_EPISODES * min(task.max_episode_steps, MAX_ROLLOUT)
    candidates = SFL_CANDIDATES * kept
    batch = config.sfl.batch_size if "sfl.batch_size" in given else \
        min(candidates, max(1, math.ceil(SFL_BATCH_ROLLOUTS * config.num_envs * config.num_steps / rollout)))
    derived = {
        "buffer.capacity": capacity, "remidi.buffer_capacity": capacity, "buffer.duplicate_check": True,
        "remidi.steps_per_buffer": max(1, math.ceil(config.num_updates / max(1, config.remidi.num_buffers))),
        "sfl.buffer_size": kept, "sfl.rollout_steps": rollout, "sfl.batch_size": batch,
        "sfl.num_batches": max(1, math.ceil(candidates / batch)), "sfl.refresh_every": max(1, config.eval_every),
    }
    return apply_overrides(config, {k: v for k, v in derived.items() if k not in given}, source="task budgets")


def budget_line(config: UEDConfig, algo_name: str) -> str | None:
    """The line a fresh run says of ``algo_name``'s budget under ``config`` (buffers, ReMiDi's
    switches, SFL's refresh, replay probability, score); None for an unknown adversary."""
    algo = get_algorithm(algo_name)
    adversary, b, r, s = algo.adversary, config.buffer, config.remidi, config.sfl
    score = f"score {algo.score_name(config.score)}"
    many = r.num_buffers if algo.buffer_sequence else 1
    size = r.buffer_capacity if algo.buffer_sequence else None
    switch = (f", switch every {r.steps_per_buffer:,} {'updates' if r.count == 'updates' else 'replays'}"
              if algo.buffer_sequence and many > 1 else "")
    if isinstance(adversary, LearnabilityBuffers):
        kept = size if size is not None else s.buffer_size
        buffers = f"{many} buffers of {kept:,}{switch}" if algo.buffer_sequence else f"1 buffer of {kept:,} levels"
        return (f"{algo.name}: {buffers}, the most learnable of {s.batch_size * s.num_batches:,} candidates "
                f"({s.num_batches:,} batches of {s.batch_size:,}, {s.rollout_steps:,} steps each) every "
                f"{s.refresh_every:,} updates; {s.sampled_envs_ratio:g} of each update's levels from it")
    if isinstance(adversary, LevelBuffers):
        duplicates = "duplicates update their entry" if b.duplicate_check else "no duplicate check"
        buffers = (f"{many} buffers of {size:,} ({duplicates}){switch}" if algo.buffer_sequence else
                   f"1 buffer of {b.capacity:,} levels ({duplicates})")
        edits = f", {config.accel.num_edits} edits per edited level" if isinstance(adversary, EditingBuffers) else ""
        return f"{algo.name}: {buffers}, replay {b.replay_prob:g}{edits}, {score}"
    if isinstance(adversary, RandomLevels):
        return f"{algo.name}: no buffer, {config.num_envs} fresh levels every update"
    if isinstance(adversary, (LevelGenerator, GeneratorSequence)):
        more = f"{r.num_buffers} generators, switch every {r.steps_per_buffer:,} updates, " \
            if isinstance(adversary, GeneratorSequence) else ""
        return f"{algo.name}: {more}a learned generator ({config.paired.generator_network}), estimator " \
               f"{config.paired.estimator}"
    return None
