"""The one UED train step shared by every algorithm (:mod:`remidi.engine.algorithms`).

One update, top to bottom (:func:`train_step`), each stage a call to the adversary or the learner,
chosen at set-up (:func:`make_setup`); only a buffer sequence (ReMiDi) brings a tracker.

1. PROPOSE LEVELS: N fresh levels, the adversary's choice among them and its buffers (PLR: a replay
   with probability ``buffer.replay_prob``; ACCEL: edits after a replay; ``remidi.rehearsal``: a
   frozen buffer's levels; SFL: a mix), and whether the learner trains on them.
2. COLLECT TRAJECTORIES: one rollout (a sequence's tracker beside the envs), GAE, returns.
3. SCORE LEVELS: scores, MaxMC's record, and the new levels a frozen level explains at every step
   ("complete overlap": scored −inf, never inserted).
4. UPDATE ADVERSARY: replays rescored, new levels inserted by score (PAIRED: the antagonist plays,
   the generator is paid).
5. UPDATE NETWORK: masked PPO on the steps no frozen level explains, if the proposal is trained on.
6. ADVANCE ADVERSARY: the update counted; after ``remidi.steps_per_buffer`` a sequence freezes the
   active buffer with the policy and the tracker's model and moves to the next.
7. METRICS: the step's scalars; ``nonfinite/...`` flags a NaN or infinite reward or observation,
   which stops the run.

A pure function of :class:`Runner`, jit-ed and vmapped over seeds by the driver.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from typing import Any

from remidi.engine import learner as lrn
from remidi.engine.adversaries.base import AdversaryState, Outcome
from remidi.engine.adversaries.scores import info_key
from remidi.engine.algorithms import Algorithm, get_algorithm
from remidi.engine.config import UEDConfig
from remidi.engine.learner import nonfinite
from remidi.engine.setup import Setup, example_observation, network_for
from remidi.engine.trackers import tracker_for
from remidi.envs.interface import UEDTask


@struct.dataclass
class Runner:
    """What one seed's training carries from step to step: its key, the updates done, one state
    per component."""

    rng: jax.Array
    updates_done: jax.Array  # i32[], train steps done
    learner: lrn.LearnerState
    adversary: AdversaryState  # or the adversary's own subclass
    tracker: Any = None  # the tracker's state (None: the exact trackers keep none)


def make_setup(task: UEDTask, cfg: UEDConfig, algo: str | Algorithm) -> Setup:
    """The set-up of a run of ``algo`` (a name or an :class:`Algorithm`), its components chosen once."""
    algo = get_algorithm(algo)
    envs = lrn.Stepping(task.env, task.params, task.deterministic_reset, solved_info=info_key(task.solved))
    return Setup(task=task, cfg=cfg, algo=algo, net=network_for(cfg, task), tracker=tracker_for(task, cfg, algo),
                 envs=envs)


def init_runner(setup: Setup, rng) -> Runner:
    rng, k_net, k_level = jax.random.split(rng, 3)
    example_obs, example_level = example_observation(setup.task, k_level)
    return Runner(rng=rng, updates_done=jnp.zeros((), jnp.int32), learner=lrn.init_learner(setup, k_net, example_obs),
                  adversary=setup.algo.adversary.init(setup, example_level, example_obs, rng),
                  tracker=setup.tracker.init(setup, rng) if setup.tracker is not None else None)


def train_step(setup: Setup, runner: Runner):
    """One update. Returns ``(runner, metrics)``, metrics a dict of f32[] scalars."""
    adversary = setup.algo.adversary
    rng, k_branch, k_roll, k_levels, k_learn, k_sample = jax.random.split(runner.rng, 6)

    # PROPOSE LEVELS
    fresh = jax.vmap(setup.task.sample_level)(jax.random.split(k_levels, setup.cfg.num_envs))  # leaves [N, ...]
    proposal = adversary.propose(setup, runner, fresh, k_branch, k_levels, k_sample)

    # COLLECT TRAJECTORIES
    # a sequence's tracker beside the envs, against its frozen levels (no tracker: the envs alone)
    frozen = setup.tracker.frozen(setup, runner, proposal) if setup.tracker is not None else None
    collection = lrn.collect(setup, runner.learner, k_roll, proposal.levels, frozen)
    traj = collection.traj

    # SCORE LEVELS (MaxMC's record takes only ended episodes: with negative rewards a partial
    # return would beat every full one and stay in the record)
    best = adversary.best_return(proposal, jnp.where(jnp.any(traj.done, axis=0), collection.best_return, -jnp.inf))
    collection = collection.replace(best_return=best)
    scores = lrn.score_rollout(setup, proposal.levels, collection)
    overlap = jnp.all(traj.indist, axis=0) & ~proposal.replay  # bool[N]: a new level a frozen one explains
    outcome = Outcome(collection=collection, scores=scores, overlap=overlap)

    # UPDATE ADVERSARY
    adversary_state, inserted, adversary_metrics = adversary.update(setup, runner, proposal, outcome, k_learn)

    # UPDATE NETWORK
    learner, ppo_metrics = lrn.train(setup, runner.learner, proposal.train, k_learn, collection)

    # ADVANCE ADVERSARY
    runner = runner.replace(adversary=adversary_state, learner=learner)
    runner, advance_metrics = adversary.advance(setup, runner, proposal, outcome)
    runner = runner.replace(rng=rng, updates_done=runner.updates_done + 1)

    # METRICS
    replayed = jnp.where(proposal.replay, 1.0, 0.0)
    metrics = {
        "replay": jnp.mean(proposal.replay.astype(jnp.float32)),  # per-env replay (SFL's mix): the share replayed
        "mean_return": jnp.mean(collection.mean_return),
        "mean_score": jnp.mean(jnp.where(jnp.isfinite(scores), scores, 0.0)),
        "trained_fraction_masked": jnp.where(proposal.train, jnp.mean(traj.indist.astype(jnp.float32)), 0.0),
        "active_buffer": runner.adversary.active.astype(jnp.float32),
        "rejected": jnp.sum(overlap).astype(jnp.float32),
        "inserted": jnp.sum(inserted).astype(jnp.float32),
        **nonfinite(traj),  # the driver stops the run on a NaN reward or observation
    }
    if frozen is not None:  # rollout envs whose first observation more frozen levels share than the tracker has slots
        metrics["tracker_overflow"] = jnp.sum(traj.overflow[0] > 0).astype(jnp.float32)
    if proposal.edit is not None:
        metrics["edit"] = proposal.edit.astype(jnp.float32)
    if proposal.rehearse is not None:  # remidi.rehearsal: the update trained on a frozen buffer's levels
        metrics["rehearsal"] = proposal.rehearse.astype(jnp.float32)
    for name, tagged in jax.vmap(setup.task.level_tags)(proposal.levels).items():
        metrics[f"replayed/{name}"] = jnp.sum(jnp.where(tagged, replayed, 0.0))
    return runner, {**metrics, **{f"ppo/{name}": value for name, value in ppo_metrics.items()}, **adversary_metrics,
                    **advance_metrics, **(proposal.nonfinite or {})}


#: how the driver reduces a step metric over a block: "sum", "last", "mean" (one not listed) or
#: "nanmean" (over the updates where it is defined; NaN if none); ``replayed/<tag>`` counts become
#: the block's ``replay_fraction/<tag>``
BLOCK_REDUCTIONS = {"rejected": "sum", "inserted": "sum", "tracker_overflow": "sum", "active_buffer": "last",
                    "belief/loss": "nanmean",
                    **{f"ppo/{name}": "nanmean" for name in lrn.PPO_METRICS}}


def buffer_tag_fractions(setup: Setup, runner: Runner) -> dict[str, jax.Array]:
    """What the adversary's buffers hold, and what the tracker reports of its state."""
    tracker = setup.tracker.metrics(setup, runner) if setup.tracker is not None else {}
    return {**setup.algo.adversary.metrics(setup, runner), **tracker}
