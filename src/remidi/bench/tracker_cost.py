"""The exact tracker's cost per environment step against ``remidi.tracker_budget``, on a cheap
environment (the maze) and an expensive one (Brax hopper).

ReMiDi's candidate tracker steps ``remidi.tracker_budget`` (K) frozen levels beside every rollout
env at every step, filled or not, so a rollout steps the environment K + 1 times per env step;
the reference tracker (K = 0) steps every frozen level. These workloads time the part of an update
that the tracker multiplies: every update here evaluates fresh levels (``buffer.replay_prob`` 0:
a rollout, its scores and the buffer's insertion, no PPO), PLR⊥ without a tracker and ReMiDi in
its last buffer with its frozen buffers full, so ``tracker_*_over_plr`` (the ratios, taken in one
invocation) is the tracker's multiple of a rollout's cost. How much of a whole update that is
depends on the rest of the update (PPO on the agent's network): ``maze-remidi`` over ``maze-plr``
and ``brax-plr`` say it for training updates.

* ``tracker-maze-plr``, ``tracker-maze-remidi-{0,8,64}``: the maze paper preset's shapes (32 envs ×
  256 steps, the conv + LSTM agent), three frozen buffers of 256 levels (768 frozen levels; K = 0:
  the reference tracker steps all 768).
* ``tracker-brax-plr``, ``tracker-brax-remidi-{8,64}``: ``brax-hopper``'s paper agent on 16 envs ×
  100 steps, one frozen buffer of 64 levels (every type A level shares its first observation: each
  env follows min(K, 64) of them).
"""

from __future__ import annotations

import dataclasses

from remidi.bench.registry import register
from remidi.bench.workloads import _maze_config, _train_workload

BUDGETS = (0, 8, 64)


def _fresh_only(cfg):
    """Every update evaluates fresh levels: a rollout, scores and an insertion, no PPO."""
    return dataclasses.replace(cfg, buffer=dataclasses.replace(cfg.buffer, replay_prob=0.0))


def _maze(algo: str, budget: int | None = None):
    from remidi.envs.maze import maze_task

    cfg = _fresh_only(_maze_config(algo, budget))
    active = cfg.remidi.num_buffers - 1 if algo == "remidi" else 0
    return _train_workload(maze_task("tmaze"), cfg, algo, active=active, updates_per_call=1 if budget == 0 else 2)


def _brax(algo: str, budget: int | None = None):
    from remidi.experiments.brax import paper_config, task_factory

    cfg = paper_config()
    cfg = dataclasses.replace(cfg, num_envs=16, ppo=dataclasses.replace(cfg.ppo, minibatches=2),
                              brax=dataclasses.replace(cfg.brax, reference_return=250.0))  # any value: timing only
    if algo == "remidi":
        cfg = dataclasses.replace(cfg, remidi=dataclasses.replace(
            cfg.remidi, num_buffers=2, buffer_capacity=64, steps_per_buffer=10**9, count="updates",
            tracker_budget=budget))
    cfg = _fresh_only(cfg)
    return _train_workload(task_factory("hopper")(cfg), cfg, algo, active=1 if algo == "remidi" else 0,
                           updates_per_call=1)


register("tracker-maze-plr", "PLR⊥'s fresh-level update on the maze (rollout, scores, insertion; no PPO)")(
    lambda: _maze("plr"))
register("tracker-brax-plr", "PLR⊥'s fresh-level update on brax-hopper, 16 envs × 100 steps (no PPO)")(
    lambda: _brax("plr"))
for _k in BUDGETS:
    register(f"tracker-maze-remidi-{_k}", f"tracker-maze-plr for ReMiDi in its last buffer, 768 frozen levels, "
                                          f"remidi.tracker_budget={_k}" + (" (the reference tracker)" if not _k else ""))(
        lambda k=_k: _maze("remidi", k))
for _k in BUDGETS[1:]:
    register(f"tracker-brax-remidi-{_k}", f"tracker-brax-plr for ReMiDi in its last buffer, 64 frozen levels, "
                                          f"remidi.tracker_budget={_k}")(lambda k=_k: _brax("remidi", k))

# (numerator, denominator, ratio name): env steps per second of the denominator over the numerator's
RATIOS = tuple((f"tracker-{domain}-remidi-{k}", f"tracker-{domain}-plr", f"tracker_{domain}_remidi_{k}_over_plr")
               for domain, budgets in (("maze", BUDGETS), ("brax", BUDGETS[1:])) for k in budgets)
