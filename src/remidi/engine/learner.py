"""The learner: the agent's policy, how it plays an update's levels and how it learns from them.

Its state (:class:`LearnerState`, ``Runner.learner``) is PPO's train state, with the running
observation statistics under ``normalize_obs`` and, under ReMiDi's ``remidi.policy=combine``, the
policy frozen with each earlier adversary. The train step (:mod:`remidi.engine.train`) calls
:func:`collect` (roll out, GAE), :func:`score_rollout` (each level's score for the adversary),
:func:`train` (masked PPO, then the statistics) and :func:`freeze_policy` (Combine's copy at an
adversary switch); PAIRED's antagonist plays and learns through :func:`collect` and :func:`learn`
with its own train state; SFL's adversary plays candidate levels with the current policy through
:func:`play` (the rollout alone, of any number of levels and steps).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct
from flax.training.train_state import TrainState

from remidi.engine.adversaries import scores as sc
from remidi.engine.config import score_name
from remidi.engine.core import normalize as nrm
from remidi.engine.core.distributions import for_task
from remidi.engine.core.networks import flatten_obs
from remidi.engine.core.ppo import Batch, compute_gae, create_train_state, ppo_update
from remidi.engine.core.rollout import Policy, Stepping, Trajectory, rollout
from remidi.engine.setup import Setup, policy_apply


@struct.dataclass
class LearnerState:
    """The agent: ``train_state`` (PPO's), ``obs_stats`` (``normalize_obs``: running observation
    statistics, :mod:`remidi.engine.core.normalize`; else None) and ``frozen_params``
    (``remidi.policy=combine``: the policy frozen with each buffer but the last, leaves [K−1, ...];
    else None)."""

    train_state: TrainState
    obs_stats: object = None
    frozen_params: object = None


def combines(setup: Setup) -> bool:
    """A buffer sequence (ReMiDi) with ``remidi.policy=combine`` and at least two buffers."""
    return setup.algo.buffer_sequence and setup.cfg.remidi.policy == "combine" and setup.cfg.remidi.num_buffers >= 2


def init_learner(setup: Setup, rng, example_obs) -> LearnerState:
    """A fresh agent from ``rng`` (its network initialised on ``example_obs``)."""
    cfg = setup.cfg
    train_state = create_train_state(rng, setup.net, example_obs, cfg.num_envs, cfg.ppo)
    frozen_params = None
    if combines(setup):  # filled in at each buffer switch
        frozen_params = jax.tree.map(lambda x: jnp.stack([x] * (cfg.remidi.num_buffers - 1)), train_state.params)
    obs_stats = None
    if cfg.normalize_obs:
        obs_stats = nrm.init_stats(flatten_obs(jax.tree.map(lambda x: x[None, None], example_obs)).shape[-1])
    return LearnerState(train_state=train_state, obs_stats=obs_stats, frozen_params=frozen_params)


def collect(setup: Setup, learner: LearnerState, rng, levels, frozen):
    """Roll out on ``levels`` [N] (with the tracker of ``frozen`` beside the envs, None: none)
    and compute GAE and scores.

    Returns ``(traj, advantages f32[T, N], targets f32[T, N], mean_return f32[N],
    max_return f32[N])``; ``max_return`` is this rollout's best episode (the caller combines it
    with the buffer's record for MaxMC). Advantages and targets are in units of
    ``reward × reward_scale``, returns in the environment's.
    """
    cfg = setup.cfg
    traj, last_value = play(setup, learner, rng, levels, cfg.num_steps, frozen)
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
    return sc.score_levels(score.name, sc.ScoreInputs(
        mean_return=mean_return, values=traj.value * unscale, advantages=adv * unscale, max_return=max_return,
        done=traj.done, optimal_return=optimal, reward=traj.reward, solved=setup.task.solved,
        solved_flags=traj.solved))


def play(setup: Setup, learner: LearnerState, rng, levels, num_steps: int, frozen):
    """The current policy's rollout on ``levels`` [B] for ``num_steps`` steps (with the tracker of
    ``frozen`` beside the envs; None: none), nothing learnt: ``(traj [T, B], last_value f32[B])``.
    :func:`collect`'s rollout, and SFL's learnability rollouts of candidate levels
    (:mod:`remidi.engine.adversaries.sfl`), whose B and T are their own."""
    task = setup.task
    num_levels = jax.tree.leaves(levels)[0].shape[0]
    if setup.cfg.reseed:  # a stochastic environment: each rollout draws the levels' own randomness afresh
        levels = jax.vmap(task.reseed_level)(jax.random.split(jax.random.fold_in(rng, 17), num_levels), levels)
    carry = setup.net.initialize_carry(num_levels)
    return rollout(rng, Stepping(task.env, task.params, task.deterministic_reset,
                                 solved_info=sc.info_key(task.solved)),
                   Policy(policy_apply(setup, learner), learner.train_state.params, carry), levels, num_steps, frozen,
                   dist=for_task(task))


#: PPO's diagnostics of an update that trains, logged as ``ppo/<name>`` (the mean over its epochs'
#: minibatches that trained; NaN on updates that do not train or whose every step ReMiDi masked,
#: left out of a block's mean)
PPO_METRICS = ("policy_loss", "value_loss", "entropy", "approx_kl", "clip_frac", "grad_norm")


def learn(setup: Setup, learner: LearnerState, rng, traj: Trajectory, adv, targets) -> tuple[TrainState, dict]:
    """Masked PPO on a rollout of ``learner``'s policy: only the distinguishable steps
    (``~indist``) are trained on. Returns the new train state and :data:`PPO_METRICS` (f32[])."""
    batch = Batch(obs=traj.obs, reset=traj.reset, actions=traj.action, log_probs=traj.log_prob,
                  values=traj.value, advantages=adv, targets=targets, mask=~traj.indist)
    carry = setup.net.initialize_carry(setup.cfg.num_envs)
    train_state, metrics = ppo_update(learner.train_state, carry, batch, rng, setup.cfg.ppo,
                                      policy_apply(setup, learner), for_task(setup.task))
    return train_state, {name: metrics[name].astype(jnp.float32) for name in PPO_METRICS}


def train(setup: Setup, learner: LearnerState, trained, rng, traj: Trajectory, adv, targets):
    """Masked PPO on the rollout if ``trained`` (bool[]: the proposal's ``train``: a replay, or
    fresh levels of an adversary that trains on them), otherwise the train state as it was; then
    the observation statistics absorb the rollout's observations. Returns the learner with PPO's
    diagnostics (:data:`PPO_METRICS`; NaN when nothing was trained)."""
    if setup.algo.trains_on_fresh:  # every proposal is trained on: no branch in the program
        train_state, metrics = learn(setup, learner, rng, traj, adv, targets)
    else:
        def skip(r):
            return r.train_state, {name: jnp.float32(jnp.nan) for name in PPO_METRICS}

        train_state, metrics = jax.lax.cond(trained, lambda r: learn(setup, r, rng, traj, adv, targets), skip, learner)
    obs_stats = learner.obs_stats
    if obs_stats is not None:
        obs_stats = nrm.update_stats(obs_stats, flatten_obs(traj.obs))
    return learner.replace(train_state=train_state, obs_stats=obs_stats), metrics


def freeze_policy(learner: LearnerState, active, switch) -> LearnerState:
    """Combine: at an adversary switch (``switch`` bool[]) the policy trained on the adversary
    being frozen (``active``) is kept as its policy; nothing without Combine."""
    if learner.frozen_params is None:
        return learner
    frozen_params = jax.tree.map(
        lambda f, p: f.at[active].set(jnp.where(switch, p, f[active]), mode="drop"),
        learner.frozen_params, learner.train_state.params)
    return learner.replace(frozen_params=frozen_params)
