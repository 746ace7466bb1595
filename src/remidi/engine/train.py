"""The one UED train step shared by every algorithm (:mod:`remidi.engine.algorithms`).

One train step, top to bottom (:func:`train_step`), each stage a call to the algorithm's
adversary (:mod:`remidi.engine.adversary`) or a small function below:

1. ``adversary.propose``: the N levels of this update (DR: fresh random levels; the PLR family: a
   replay from the active buffer with probability ``buffer.replay_prob``, else fresh levels;
   ACCEL: after a replay, edits of the replayed levels; ReMiDi with ``remidi.rehearsal``: a
   frozen buffer's levels), and whether the learner trains on them.
2. :func:`collect`: roll the policy out once on them, with the distinguishability tracker against
   ``adversary.frozen`` (ReMiDi's earlier buffers), then :func:`score_rollout`.
3. ``adversary.update``: replayed levels get their new scores; new levels go into the active
   buffer by score, except those whose rollout was indistinguishable from a frozen level at every
   step ("complete overlap"), scored −inf and therefore never inserted.
4. :func:`train`: masked PPO on the rollout if the proposal is trained on, the loss masked to the
   distinguishable steps (a rehearsal of frozen levels, ``remidi.rehearsal``: on every step).
5. ``adversary.advance``: a buffer sequence's switch after ``remidi.steps_per_buffer`` updates
   (freeze the active buffer, move to the next, stay on the last); ACCEL's memory of the replay.
6. :func:`step_metrics`: the step's scalars, and PPO's diagnostics (:data:`BLOCK_REDUCTIONS` says
   how the driver reduces each over a block).

No stage compares an algorithm's name or tests its flags: PLR⊥ is ReMiDi's adversary with one
buffer, minimax return is PLR⊥ scored by negative return. Everything in a step is a pure function
of :class:`Runner`, jit-ed and vmapped over seeds by the driver. The run's configuration is
:mod:`remidi.engine.config`, evaluation :mod:`remidi.engine.evaluation`, validation
:mod:`remidi.engine.validation`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import partial

import jax
import jax.numpy as jnp
from flax import struct
from flax.training.train_state import TrainState

from remidi.engine import buffer as buf
from remidi.engine.algorithms import Algorithm, get_algorithm
from remidi.engine import normalize as nrm
from remidi.engine import scores as sc
from remidi.engine.config import UEDConfig, buffer_config, num_buffers, score_name
from remidi.engine.distributions import for_task
from remidi.engine.networks import flatten_obs, make_network
from remidi.engine.ppo import Batch, compute_gae, create_train_state, ppo_update
from remidi.engine.adversary import Proposal, belief_freezes, belief_learns, belief_memory, tag_counts
from remidi.engine.rollout import Frozen, Trajectory, rollout
from remidi.envs.interface import UEDTask

@struct.dataclass
class Runner:
    """Everything one seed's training carries from step to step."""

    rng: jax.Array
    train_state: TrainState
    buffers: buf.BufferState  # K stacked buffers, leaves [K, capacity, ...]
    active: jax.Array  # i32[], index of the buffer being filled and replayed
    count: jax.Array  # i32[], updates (or replays) spent on the active buffer
    update: jax.Array  # i32[], train steps done
    frozen_params: object = None  # remidi.policy=combine: the policy frozen with each buffer, leaves [K−1, ...]
    obs_stats: object = None  # normalize_obs: running observation statistics (engine/normalize.py)
    edit_next: object = None  # ACCEL: bool[], the next update edits the levels this one replayed
    last_replayed: object = None  # ACCEL: the levels of the last replay, leaves [N, ...]
    generator: object = None  # PAIRED: the level generator's TrainState
    antagonist: object = None  # PAIRED: the antagonist's TrainState
    next_generators: object = None  # ReMiDi over PAIRED: the fresh generators of the later buffers, leaves [K−1, ...]
    belief: object = None  # remidi.tracker=belief: the buffers' learned models (engine/belief.py BeliefMemory)


@dataclass(frozen=True)
class Setup:
    """Static pieces of a run: the task, the config, the algorithm and the network (derived
    from the other three, so left out of equality). Hashable: a static argument under jit."""

    task: UEDTask
    cfg: UEDConfig
    algo: Algorithm
    net: object = field(compare=False)


def make_setup(task: UEDTask, cfg: UEDConfig, algo: str | Algorithm) -> Setup:
    """The set-up of a run of ``algo`` (a name or an :class:`Algorithm`)."""
    return Setup(task=task, cfg=cfg, algo=get_algorithm(algo), net=network_for(cfg, task))


def network_for(cfg: UEDConfig, task: UEDTask):
    """The network ``cfg.network`` for the task's actions, with ``hidden_size``/``lstm_size``
    where set (ConfigError if that network has no such layer)."""
    from remidi.engine.networks import NETWORKS
    from remidi.errors import ConfigError

    options = {}
    cls = NETWORKS.get(cfg.network)
    fields = {f.name: f.default for f in dataclasses.fields(cls)} if cls is not None else {}
    for key, option, value in (("hidden_size", "hidden", cfg.hidden_size), ("lstm_size", "lstm_size", cfg.lstm_size)):
        if value == 0:
            continue
        if option not in fields:
            raise ConfigError(f"{key}: the network {cfg.network} has no such layer; leave it 0 or pick a network "
                              f"that has one")
        options[option] = (value,) * len(fields[option]) if option == "hidden" else value
    return make_network(cfg.network, task.num_actions, task.continuous, **options)


def policy_apply(setup: Setup, runner: Runner):
    """The network's ``apply`` reading observations as the agent sees them (normalised with the
    runner's running statistics under ``normalize_obs``)."""
    return nrm.normalizing_apply(setup.net.apply, runner.obs_stats)


def example_observation(task: UEDTask, key=None):
    """One observation (unbatched leaves): the first of a level the task samples with ``key``
    (``PRNGKey(0)`` if None), reset with the same key. Returns ``(obs, level)``.

    One compiled program: called outside a trace, the generator's and the reset's operations
    would each compile a program of their own (about a hundred for the maze, seconds per process)."""
    return _first_observation(task, jax.random.PRNGKey(0) if key is None else key)


@partial(jax.jit, static_argnums=0)
def _first_observation(task: UEDTask, key):
    level = task.sample_level(key)
    return task.env.reset_to_level(key, level, task.params)[0], level


def init_runner(setup: Setup, rng) -> Runner:
    task, cfg = setup.task, setup.cfg
    rng, k_net, k_level = jax.random.split(rng, 3)
    example_obs, example_level = example_observation(task, k_level)
    train_state = create_train_state(k_net, setup.net, example_obs, cfg.num_envs, cfg.ppo)
    one = buf.init_buffer(buffer_config(cfg, setup.algo), example_level, extra_names=("max_return",))
    buffers = buf.stack_buffers([one] * num_buffers(cfg, setup.algo))
    zero = jnp.zeros((), jnp.int32)
    frozen_params = None
    if combines(setup):  # filled in at each buffer switch
        frozen_params = jax.tree.map(lambda x: jnp.stack([x] * (cfg.remidi.num_buffers - 1)), train_state.params)
    obs_stats = None
    if cfg.normalize_obs:
        obs_stats = nrm.init_stats(flatten_obs(jax.tree.map(lambda x: x[None, None], example_obs)).shape[-1])
    return Runner(rng=rng, train_state=train_state, buffers=buffers, active=zero, count=zero, update=zero,
                  frozen_params=frozen_params, obs_stats=obs_stats, belief=belief_memory(setup, rng),
                  **setup.algo.adversary.memory(setup, example_level, example_obs, rng))


def combines(setup: Setup) -> bool:
    """A buffer sequence (ReMiDi) with ``remidi.policy=combine`` and at least two buffers."""
    return setup.algo.buffer_sequence and setup.cfg.remidi.policy == "combine" and setup.cfg.remidi.num_buffers >= 2


# ------------------------------------------------------------------------------- pieces
def frozen_levels(setup: Setup, runner: Runner) -> Frozen | None:
    """The earlier adversaries' levels for the tracker (:meth:`~remidi.engine.adversary.RandomLevels.frozen`)."""
    return setup.algo.adversary.frozen(setup, runner)


def collect(setup: Setup, runner: Runner, rng, levels, frozen):
    """Roll out on ``levels`` [N] and compute GAE and scores.

    Returns ``(traj, advantages f32[T, N], targets f32[T, N], mean_return f32[N],
    max_return f32[N])``; ``max_return`` is this rollout's best episode (the caller combines it
    with the buffer's record for MaxMC). Advantages and targets are in units of
    ``reward × reward_scale``, returns in the environment's.
    """
    cfg, task = setup.cfg, setup.task
    if cfg.reseed:  # a stochastic environment: each rollout draws the levels' own randomness afresh
        levels = jax.vmap(task.reseed_level)(jax.random.split(jax.random.fold_in(rng, 17), cfg.num_envs), levels)
    carry = setup.net.initialize_carry(cfg.num_envs)
    traj, last_value = rollout(rng, task.env, task.params, policy_apply(setup, runner), runner.train_state.params,
                               carry, levels, cfg.num_steps, frozen, dist=for_task(task.continuous),
                               deterministic_reset=task.deterministic_reset)
    adv, targets = compute_gae(traj.reward * cfg.reward_scale, traj.value, traj.done, last_value, cfg.ppo.gamma,
                               cfg.ppo.gae_lambda)
    mean_return, best_return, _ = sc.episode_returns(traj.reward, traj.done)
    return traj, adv, targets, mean_return, best_return


def score_rollout(setup: Setup, levels, traj: Trajectory, adv, mean_return, max_return):
    """f32[N]: each level's score, in the environment's reward units (the critic's values and
    the advantages, learnt on ``reward × reward_scale``, are scaled back). Perfect regret compares
    the optimum and the agent's mean episodic return in the same units: both discounted by
    ``ppo.gamma`` (the paper's utility), or with ``discounted_regret`` off the undiscounted
    ``mean_return`` the rollout already gave."""
    score = sc.SCORES[score_name(setup.cfg, setup.algo)]
    optimal = None
    if score.needs_optimum:
        if setup.cfg.discounted_regret:
            gamma = setup.cfg.ppo.gamma
            optimal = jax.vmap(lambda level: setup.task.optimal_discounted_return(level, gamma))(levels)
            mean_return, _, _ = sc.episode_returns(traj.reward, traj.done, gamma)
        else:
            optimal = jax.vmap(setup.task.optimal_return)(levels)
    unscale = 1.0 / setup.cfg.reward_scale
    return sc.score_levels(score.name, mean_return=mean_return, values=traj.value * unscale,
                           advantages=adv * unscale, max_return=max_return, done=traj.done, optimal_return=optimal,
                           reward=traj.reward, solved=setup.task.solved)


#: PPO's diagnostics of an update that trains, logged as ``ppo/<name>`` (the mean over its epochs'
#: minibatches that trained; NaN on updates that do not train or whose every step ReMiDi masked,
#: left out of a block's mean)
PPO_METRICS = ("policy_loss", "value_loss", "entropy", "approx_kl", "clip_frac", "grad_norm")


def learn(setup: Setup, runner: Runner, rng, traj: Trajectory, adv, targets) -> tuple[TrainState, dict]:
    """Masked PPO on a rollout of ``runner``'s policy: only the distinguishable steps
    (``~indist``) are trained on. Returns the new train state and :data:`PPO_METRICS` (f32[])."""
    batch = Batch(obs=traj.obs, reset=traj.reset, actions=traj.action, log_probs=traj.log_prob,
                  values=traj.value, advantages=adv, targets=targets, mask=~traj.indist)
    carry = setup.net.initialize_carry(setup.cfg.num_envs)
    train_state, metrics = ppo_update(runner.train_state, carry, batch, rng, setup.cfg.ppo,
                                      policy_apply(setup, runner), for_task(setup.task.continuous))
    return train_state, {name: metrics[name].astype(jnp.float32) for name in PPO_METRICS}


# ---------------------------------------------------------------------------- the step
def train_step(setup: Setup, runner: Runner):
    """One update. Returns ``(runner, metrics)``, metrics a dict of f32[] scalars."""
    adversary = setup.algo.adversary
    rng, k_branch, k_roll, k_levels, k_learn, k_sample = jax.random.split(runner.rng, 6)
    frozen = adversary.frozen(setup, runner)  # the earlier adversaries' levels (None: nothing frozen)
    # 1. the adversary proposes the levels: a replay from its buffer, fresh random levels, or edits
    proposal = adversary.propose(setup, runner, k_branch, k_levels, k_sample)
    # 2. one rollout (with the tracker against the frozen levels), then score
    traj, adv, targets, mean_ret, best_ret = collect(setup, runner, k_roll, proposal.levels, frozen)
    traj = traj.replace(indist=proposal.explained(traj.indist))  # a rehearsal of frozen levels: no step explained
    # MaxMC's record takes only episodes that ended: an unfinished episode's partial return is no
    # return (with negative rewards it would beat every full one and stay in the record)
    best_ret = adversary.best_return(proposal, jnp.where(jnp.any(traj.done, axis=0), best_ret, -jnp.inf))
    scores = score_rollout(setup, proposal.levels, traj, adv, mean_ret, best_ret)
    overlap = jnp.all(traj.indist, axis=0) & ~proposal.replay  # bool[N]: new level overlapping a frozen one completely
    # 3. the adversary takes the scores: replayed levels rescored, new ones inserted unless they overlap
    #    (PAIRED: the antagonist plays the levels, the generator is paid its regret estimate)
    changed, inserted, adversary_metrics = adversary.update(setup, runner, proposal, scores, overlap, best_ret,
                                                            mean_ret, k_learn)
    #    (remidi.tracker=belief: the active adversary's model learns from a rollout of its own levels,
    #    adversary.own_levels: a replay of the active buffer, every update of a generator)
    learnt, belief_metrics = belief_learns(setup, runner, proposal, traj)
    changed = {**changed, **learnt}
    # 4. train (masked PPO) if the proposal is trained on
    train_state, ppo_metrics = train(setup, runner, proposal.train, k_learn, traj, adv, targets)
    obs_stats = runner.obs_stats  # the statistics absorb this rollout's observations
    if obs_stats is not None:
        obs_stats = nrm.update_stats(obs_stats, flatten_obs(traj.obs))
    # 5. the adversary moves on (from the state its update left): a buffer sequence's switch,
    #    ACCEL's memory of the replay, a fresh generator
    runner = runner.replace(**changed)
    moved = adversary.advance(setup, runner, proposal, train_state.params)
    #    (remidi.tracker=belief: an adversary frozen now has its model frozen and calibrated with it)
    moved = {**moved, **belief_freezes(setup, runner, moved["active"] != runner.active)}
    runner = runner.replace(rng=rng, train_state=train_state, update=runner.update + 1, obs_stats=obs_stats, **moved)
    # 6. what the step reports
    return runner, {**step_metrics(setup, runner, proposal, traj, mean_ret, scores, overlap, inserted, frozen),
                    **{f"ppo/{name}": value for name, value in ppo_metrics.items()}, **adversary_metrics,
                    **belief_metrics}


def train(setup: Setup, runner: Runner, trained, rng, traj: Trajectory, adv, targets) -> tuple[TrainState, dict]:
    """Stage 4: masked PPO on the rollout if ``trained`` (bool[]: the proposal's ``train``: a
    replay, or fresh levels of an adversary that trains on them); otherwise the train state as it
    was. Returns it with PPO's diagnostics (:data:`PPO_METRICS`; NaN when nothing was trained)."""
    if setup.algo.trains_on_fresh:  # every proposal is trained on: no branch in the program
        return learn(setup, runner, rng, traj, adv, targets)

    def skip(r):
        return r.train_state, {name: jnp.float32(jnp.nan) for name in PPO_METRICS}

    return jax.lax.cond(trained, lambda r: learn(setup, r, rng, traj, adv, targets), skip, runner)


#: how the driver reduces a step metric over a block of updates: "sum", "last", "mean" (any
#: metric not listed) or "nanmean" (the mean over the updates where it is defined, NaN if none).
#: ``replayed/<tag>`` counts become the block's ``replay_fraction/<tag>``.
BLOCK_REDUCTIONS = {"rejected": "sum", "inserted": "sum", "tracker_overflow": "sum", "active_buffer": "last",
                    "belief/loss": "nanmean",
                    **{f"ppo/{name}": "nanmean" for name in PPO_METRICS}}


def step_metrics(setup: Setup, runner: Runner, chosen: Proposal, traj: Trajectory, mean_return, scores, overlap,
                 inserted, frozen) -> dict[str, jax.Array]:
    """Stage 6: the step's f32[] scalars (``runner`` is the one after the step)."""
    trained = chosen.train
    metrics = {
        "replay": chosen.replay.astype(jnp.float32),
        "mean_return": jnp.mean(mean_return),
        "mean_score": jnp.mean(jnp.where(jnp.isfinite(scores), scores, 0.0)),
        "trained_fraction_masked": jnp.where(trained, jnp.mean(traj.indist.astype(jnp.float32)), 0.0),
        "active_buffer": runner.active.astype(jnp.float32),
        "rejected": jnp.sum(overlap).astype(jnp.float32),
        "inserted": jnp.sum(inserted).astype(jnp.float32),
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
    """What the adversary's buffers hold (:meth:`~remidi.engine.adversary.RandomLevels.metrics`)."""
    return setup.algo.adversary.metrics(setup, runner)
