"""The one UED train step shared by every algorithm (:mod:`remidi.engine.algorithms`).

One train step, top to bottom (:func:`train_step`), each stage a call to one of the run's three
components, chosen when the run is set up (:func:`make_setup`): the algorithm's adversary
(:mod:`remidi.engine.adversaries`), the distinguishability tracker (:mod:`remidi.engine.trackers`)
and the learner (:mod:`remidi.engine.learner`):

1. ``adversary.propose``: the N levels of this update (DR: fresh random levels; the PLR family: a
   replay from the active buffer with probability ``buffer.replay_prob``, else fresh levels;
   ACCEL: after a replay, edits of the replayed levels; ReMiDi with ``remidi.rehearsal``: a
   frozen buffer's levels; SFL: its buffer refreshed if due, then a per-env mix of its levels
   and fresh ones), and whether the learner trains on them.
2. ``learner.collect``: roll the policy out once on them, with the tracker beside the
   environments against ``tracker.frozen`` (ReMiDi's earlier buffers), then
   ``learner.score_rollout``.
3. ``adversary.update``: replayed levels get their new scores; new levels go into the active
   buffer by score, except those whose rollout was indistinguishable from a frozen level at every
   step ("complete overlap"), scored −inf and therefore never inserted; ``tracker.learn``: a
   learned tracker's model learns from the rollout.
4. ``learner.train``: masked PPO on the rollout if the proposal is trained on, the loss masked to
   the distinguishable steps (a rehearsal of frozen levels, ``remidi.rehearsal``: on every step).
5. ``adversary.advance``: a sequence's switch after ``remidi.steps_per_buffer`` updates (freeze
   the active buffer, move to the next, stay on the last); ACCEL's memory of the replay; at a
   switch ``learner.freeze_policy`` (Combine) and ``tracker.freeze``.
6. :func:`step_metrics`: the step's scalars, and PPO's diagnostics (:data:`BLOCK_REDUCTIONS` says
   how the driver reduces each over a block); ``nonfinite/...`` flags a NaN or infinite reward or
   observation in any of the step's rollouts, which stops the run.

No stage compares an algorithm's name or tests its flags: PLR⊥ is ReMiDi's adversary with one
buffer, minimax return is PLR⊥ scored by negative return. Everything in a step is a pure function
of :class:`Runner`, jit-ed and vmapped over seeds by the driver (:mod:`remidi.engine.run.driver`).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from remidi.engine import learner as lrn
from remidi.engine.adversaries.base import Proposal, tag_counts
from remidi.engine.algorithms import Algorithm, get_algorithm
from remidi.engine.config import UEDConfig
from remidi.engine.learner import Trajectory, nonfinite
from remidi.engine.setup import Setup, example_observation, network_for
from remidi.engine.trackers import tracker_for
from remidi.envs.interface import UEDTask


@struct.dataclass
class Runner:
    """Everything one seed's training carries from step to step: its key, the updates done, and
    one state per component: the learner's (:class:`~remidi.engine.learner.LearnerState`), the
    adversary's (:class:`~remidi.engine.adversaries.base.AdversaryState` or the adversary's own
    subclass) and the tracker's (None for the exact trackers)."""

    rng: jax.Array
    update: jax.Array  # i32[], train steps done
    learner: lrn.LearnerState
    adversary: object
    tracker: object = None


def make_setup(task: UEDTask, cfg: UEDConfig, algo: str | Algorithm) -> Setup:
    """The set-up of a run of ``algo`` (a name or an :class:`Algorithm`): its network and its
    tracker chosen once, here."""
    algo = get_algorithm(algo)
    return Setup(task=task, cfg=cfg, algo=algo, net=network_for(cfg, task), tracker=tracker_for(task, cfg, algo))


def init_runner(setup: Setup, rng) -> Runner:
    rng, k_net, k_level = jax.random.split(rng, 3)
    example_obs, example_level = example_observation(setup.task, k_level)
    return Runner(rng=rng, update=jnp.zeros((), jnp.int32), learner=lrn.init_learner(setup, k_net, example_obs),
                  adversary=setup.algo.adversary.init(setup, example_level, example_obs, rng),
                  tracker=setup.tracker.init(setup, rng))


# ---------------------------------------------------------------------------- the step
def train_step(setup: Setup, runner: Runner):
    """One update. Returns ``(runner, metrics)``, metrics a dict of f32[] scalars."""
    adversary, tracker = setup.algo.adversary, setup.tracker
    rng, k_branch, k_roll, k_levels, k_learn, k_sample = jax.random.split(runner.rng, 6)
    frozen = tracker.frozen(setup, runner)  # the earlier adversaries' levels (None: nothing frozen)
    # 1. the adversary proposes the levels: a replay from its buffer, fresh random levels, or edits
    proposal = adversary.propose(setup, runner, k_branch, k_levels, k_sample)
    # 2. one rollout (with the tracker against the frozen levels), then score
    collection = lrn.collect(setup, runner.learner, k_roll, proposal.levels, frozen)
    mean_ret = collection.mean_return
    traj = collection.traj.replace(indist=proposal.explained(collection.traj.indist))  # a rehearsal: no step explained
    # MaxMC's record takes only episodes that ended: an unfinished episode's partial return is no
    # return (with negative rewards it would beat every full one and stay in the record)
    best_ret = adversary.best_return(proposal, jnp.where(jnp.any(traj.done, axis=0), collection.best_return, -jnp.inf))
    collection = collection.replace(traj=traj, best_return=best_ret)
    scores = lrn.score_rollout(setup, proposal.levels, collection)
    overlap = jnp.all(traj.indist, axis=0) & ~proposal.replay  # bool[N]: new level overlapping a frozen one completely
    # 3. the adversary takes the scores: replayed levels rescored, new ones inserted unless they overlap
    #    (PAIRED: the antagonist plays the levels, the generator is paid its regret estimate);
    #    a learned tracker's model learns from the rollout
    adversary_state, inserted, adversary_metrics = adversary.update(setup, runner, proposal, scores, overlap,
                                                                    best_ret, mean_ret, k_learn)
    tracker_state, tracker_metrics = tracker.learn(setup, runner, proposal, traj)
    # 4. train (masked PPO) if the proposal is trained on
    learner, ppo_metrics = lrn.train(setup, runner.learner, proposal.train, k_learn, collection)
    # 5. the adversary moves on (from the state its update left): a sequence's switch, ACCEL's
    #    memory of the replay, a fresh generator; at a switch the policy (Combine) and the
    #    tracker's model are frozen with the adversary
    runner = runner.replace(adversary=adversary_state, tracker=tracker_state)
    moved = adversary.advance(setup, runner, proposal)
    switch = moved.active != runner.adversary.active
    learner = lrn.freeze_policy(learner, runner.adversary.active, switch)
    tracker_state = tracker.freeze(setup, runner, switch)
    runner = runner.replace(rng=rng, update=runner.update + 1, learner=learner, adversary=moved, tracker=tracker_state)
    # 6. what the step reports
    return runner, {**step_metrics(setup, runner, proposal, traj, (mean_ret, scores, overlap, inserted), frozen),
                    **{f"ppo/{name}": value for name, value in ppo_metrics.items()}, **adversary_metrics,
                    **tracker_metrics, **(proposal.nonfinite or {})}


#: how the driver reduces a step metric over a block of updates: "sum", "last", "mean" (any
#: metric not listed) or "nanmean" (the mean over the updates where it is defined, NaN if none).
#: ``replayed/<tag>`` counts become the block's ``replay_fraction/<tag>``.
BLOCK_REDUCTIONS = {"rejected": "sum", "inserted": "sum", "tracker_overflow": "sum", "active_buffer": "last",
                    "belief/loss": "nanmean",
                    **{f"ppo/{name}": "nanmean" for name in lrn.PPO_METRICS}}


def step_metrics(setup: Setup, runner: Runner, chosen: Proposal, traj: Trajectory, outcome, frozen) -> dict:
    """Stage 6: the step's f32[] scalars (``runner`` is the one after the step; ``outcome``:
    ``(mean_return f32[N], scores f32[N], overlap bool[N], inserted bool[N])``)."""
    mean_return, scores, overlap, inserted = outcome
    trained = chosen.train
    metrics = {
        "replay": jnp.mean(chosen.replay.astype(jnp.float32)),  # per-env replay (SFL's mix): the share replayed
        "mean_return": jnp.mean(mean_return),
        "mean_score": jnp.mean(jnp.where(jnp.isfinite(scores), scores, 0.0)),
        "trained_fraction_masked": jnp.where(trained, jnp.mean(traj.indist.astype(jnp.float32)), 0.0),
        "active_buffer": runner.adversary.active.astype(jnp.float32),
        "rejected": jnp.sum(overlap).astype(jnp.float32),
        "inserted": jnp.sum(inserted).astype(jnp.float32),
        **nonfinite(traj),  # the driver stops the run on a NaN reward or observation
    }
    if frozen is not None:  # rollout envs whose first observation more frozen levels share than the tracker has slots
        metrics["tracker_overflow"] = jnp.sum(traj.overflow[0] > 0).astype(jnp.float32)
    if chosen.edit is not None:
        metrics["edit"] = chosen.edit.astype(jnp.float32)
    if chosen.rehearse is not None:  # remidi.rehearsal: the update trained on a frozen buffer's levels
        metrics["rehearsal"] = chosen.rehearse.astype(jnp.float32)
    for name, c in tag_counts(setup, chosen.levels, jnp.where(chosen.replay, 1.0, 0.0)).items():
        metrics[f"replayed/{name}"] = c
    return metrics


def buffer_tag_fractions(setup: Setup, runner: Runner) -> dict[str, jax.Array]:
    """What the adversary's buffers hold, and what the tracker reports of its state."""
    return {**setup.algo.adversary.metrics(setup, runner), **setup.tracker.metrics(setup, runner)}
