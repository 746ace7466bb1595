"""The learner: the agent's policy, how it plays an update's levels and learns from them, top to
bottom as PureJaxRL's PPO: collect trajectories, calculate the advantages, update the network.

The train step calls :func:`collect`, :func:`score_rollout` and :func:`train`; :func:`play` is the
rollout alone, of any number of levels and steps; :func:`rollout` steps any policy on any
environments. Shapes: ``T`` rollout steps, ``N`` envs.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Any, Callable

import jax
import jax.numpy as jnp
import optax
from flax import struct
from flax.training.train_state import TrainState

from remidi.engine.adversaries import scores as sc
from remidi.engine.core import normalize as nrm
from remidi.engine.core.networks import flatten_obs
from remidi.engine.core.networks.base import CATEGORICAL
from remidi.engine.core.ppo import PPOConfig, create_train_state
from remidi.envs.interface import AutoReplayState, UnderspecifiedEnv, info_flag

if TYPE_CHECKING:
    from remidi.engine.setup import Setup


@struct.dataclass
class LearnerState:
    """The agent: PPO's ``train_state``, ``obs_stats`` (running observation statistics under
    ``normalize_obs``, else None) and ``frozen_params`` (``remidi.policy=combine``: the policy frozen
    with each buffer but the last, leaves [K−1, ...]; else None)."""

    train_state: TrainState
    obs_stats: object = None
    frozen_params: object = None


@struct.dataclass
class Trajectory:
    """A rollout; every field has leading dims [T, N]."""

    obs: Any  # observation pytree, leaves [T, N, ...]
    reset: jax.Array  # bool: step t is the first of an episode
    action: jax.Array  # i32 (Discrete), i32[T, N, k] (MultiDiscrete: one per component) or f32[T, N, A] (Box)
    log_prob: jax.Array  # f32
    value: jax.Array  # f32
    reward: jax.Array  # f32
    done: jax.Array  # bool: the episode ended at step t
    indist: jax.Array  # bool: the prefix up to obs[t] is indistinguishable from a frozen level
    overflow: jax.Array  # i32: frozen levels sharing the episode's first observation, beyond the tracker's slots
    solved: Any = None  # bool: the step's info flag of solving (Stepping.solved_info); None without one


@struct.dataclass
class Collection:
    """One update's rollout ``traj`` [T, N], GAE's ``advantages`` and value ``targets`` (f32[T, N],
    in units of ``reward × reward_scale``), and per env the ``mean_return`` and ``best_return``
    (f32[N], the environment's units) of its episodes (without a finished episode: its partial
    return)."""

    traj: Trajectory
    advantages: jax.Array
    targets: jax.Array
    mean_return: jax.Array
    best_return: jax.Array


@dataclass(frozen=True)
class Stepping:
    """The environments a rollout steps: ``raw`` (the env), ``params`` (its parameters),
    ``deterministic_reset`` (its reset ignores its key, so a restart restores the episode's first
    state), ``tracker_env`` (where a tracker plays the frozen levels: training levels, so a larger
    evaluation env passes the training one; default ``raw``) and ``solved_info`` (the info key the
    trajectory records as ``solved``; None: none). An env whose episode ends restarts its level
    (:meth:`restart_where_done` over N envs; the same rule as :class:`~remidi.envs.interface.AutoReplay` for one env)."""

    raw: UnderspecifiedEnv
    params: Any
    deterministic_reset: bool = False
    tracker_env: UnderspecifiedEnv | None = None
    solved_info: str | None = None

    def __post_init__(self):
        if self.tracker_env is None:
            object.__setattr__(self, "tracker_env", self.raw)

    def restart_where_done(self, state: AutoReplayState, stepped, reset_keys):
        """The N envs' step ``stepped = (obs, env_state, reward, done, info)`` from ``state``, the
        level restarted where the episode ended (from its first state, or reset with ``reset_keys``
        [N]): ``(obs, state, reward, done, info)``."""
        next_obs, env_state, reward, done, info = stepped
        if self.deterministic_reset:
            fresh = state.start
        else:
            fresh = jax.vmap(self.raw.reset_to_level, in_axes=(0, 0, None))(reset_keys, state.level, self.params)
        next_obs, env_state = jax.tree.map(
            lambda new, x: jnp.where(done.reshape(done.shape + (1,) * (x.ndim - 1)), new, x),
            fresh, (next_obs, env_state))
        state = state.replace(env_state=env_state)
        if self.solved_info is not None:
            state = state.replace(solved=jax.vmap(partial(info_flag, key=self.solved_info))(info))
        return next_obs, state, reward, done, info


@dataclass(frozen=True)
class Policy:
    """The policy a rollout acts with: ``apply({"params": params}, carry, obs[1, N, ...], reset
    bool[1, N]) -> carry, (logits [1, N, P], value [1, N])``, its ``params`` and its initial
    recurrent state ``carry`` (leaves [N, ...])."""

    apply: Callable
    params: Any
    carry: Any


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


def policy_apply(setup: Setup, learner: LearnerState):
    """The network's ``apply`` on observations as the agent sees them: under ``normalize_obs``
    flattened to ``f32[T, N, D]`` and normalised with the statistics as the update started."""
    stats = learner.obs_stats
    if stats is None:
        return setup.net.apply

    def apply(variables, carry, obs, reset):
        return setup.net.apply(variables, carry, nrm.normalize(stats, flatten_obs(obs)), reset)

    return apply


# ---------------------------------------------------------------------------- the rollout
def collect(setup: Setup, learner: LearnerState, rng, levels, frozen) -> Collection:
    """Roll out on ``levels`` [N] (with the tracker of ``frozen`` beside the envs, None: none),
    then compute the advantages and each env's episode returns: a :class:`Collection`."""
    cfg = setup.cfg
    # COLLECT TRAJECTORIES
    traj, last_value = play(setup, learner, rng, levels, cfg.num_steps, frozen)
    # CALCULATE ADVANTAGE, on the rewards PPO learns from (× reward_scale)
    advantages, targets = compute_gae(traj.reward * cfg.reward_scale, traj.value, traj.done, last_value, cfg.ppo.gamma,
                                      cfg.ppo.gae_lambda)
    mean_return, best_return, _ = sc.episode_returns(traj.reward, traj.done)
    return Collection(traj=traj, advantages=advantages, targets=targets, mean_return=mean_return,
                      best_return=best_return)


def play(setup: Setup, learner: LearnerState, rng, levels, num_steps: int, frozen):
    """The current policy's rollout on ``levels`` [B] for ``num_steps`` steps (with the tracker of
    ``frozen`` beside the envs; None: none), nothing learnt: ``(traj [T, B], last_value f32[B])``."""
    num_levels = jax.tree.leaves(levels)[0].shape[0]
    if setup.cfg.reseed:  # a stochastic environment: each rollout draws the levels' own randomness afresh
        keys = jax.random.split(jax.random.fold_in(rng, 17), num_levels)
        levels = jax.vmap(setup.task.reseed_level)(keys, levels)
    policy = Policy(policy_apply(setup, learner), learner.train_state.params, setup.net.initialize_carry(num_levels))
    return rollout(rng, setup.envs, policy, levels, num_steps, frozen, dist=setup.dist)


def rollout(rng, envs: Stepping, policy: Policy, levels, num_steps: int, frozen=None, dist=CATEGORICAL):
    """Roll out ``policy`` on ``levels`` (leaves [N, ...]) of ``envs`` for ``num_steps`` steps:
    ``(trajectory, last_value f32[N])``.

    An env whose episode ends restarts its level (the step's observation and state are the fresh
    episode's; ``done`` and the reward are the terminal ones). With ``frozen``
    (:class:`~remidi.engine.trackers.base.Frozen`) its tracker steps the envs beside the frozen
    levels and judges at every step whether the prefix is indistinguishable from one (``indist``;
    all False without ``frozen``); with ``frozen.params`` :func:`combine` chooses the actions, but
    ``log_prob`` and ``value`` stay the current policy's (PPO trains only where it acted,
    ``~indist``).
    """
    env, apply_fn, params = envs.raw, policy.apply, policy.params
    num_envs = jax.tree.leaves(levels)[0].shape[0]
    rng, rng_reset = jax.random.split(rng)
    reset_keys = jax.random.split(rng_reset, num_envs)
    tracker = frozen.tracker if frozen is not None else None
    if tracker is None:
        obs, env_state = jax.vmap(env.reset_to_level, in_axes=(0, 0, None))(reset_keys, levels, envs.params)
        tstate = None
    else:
        obs, env_state, tstate = tracker.reset(envs, frozen, reset_keys, levels)
    # each env's episode restarts its level: from its first state where the reset ignores its key
    state = AutoReplayState(env_state=env_state, level=levels, start=(obs, env_state) if envs.deterministic_reset else None,
                            solved=jnp.zeros((num_envs,), bool) if envs.solved_info is not None else None)
    combining = frozen is not None and frozen.params is not None

    def _env_step(carry, key):
        state, obs, reset, (hidden, frozen_hidden), tstate = carry
        k_act, k_env = jax.random.split(key)
        # SELECT ACTION
        indist = tracker.indistinguishable(tstate) if tracker is not None else jnp.zeros((num_envs,), bool)
        if frozen is not None and frozen.rehearse is not None:  # a rehearsal: no step explained
            indist = indist & ~frozen.rehearse
        obs_in = jax.tree.map(lambda x: x[None], obs)
        hidden, (logits, value) = apply_fn({"params": params}, hidden, obs_in, reset[None])
        logits, value = logits[0], value[0]
        acting = logits
        if combining:
            frozen_hidden, acting = combine(frozen, tstate, apply_fn, frozen_hidden, obs_in, reset, logits)
        action = dist.sample(k_act, acting)
        log_prob = dist.log_prob(logits, action)
        # STEP ENV, restarting the level where the episode ended (each env's key split in two: step, restart)
        env_keys = jax.random.split(k_env, num_envs)
        if tracker is None:
            keys = jax.vmap(jax.random.split)(env_keys)
            stepped = jax.vmap(env.step, in_axes=(0, 0, 0, None))(keys[:, 0], state.env_state, action, envs.params)
            next_obs, state, reward, done, _ = envs.restart_where_done(state, stepped, keys[:, 1])
        else:
            next_obs, state, reward, done, tstate = tracker.step(envs, frozen, env_keys, state, tstate, action)
        overflow = tracker.overflow(tstate) if tracker is not None else jnp.zeros((num_envs,), jnp.int32)
        record = Trajectory(obs=obs, reset=reset, action=action, log_prob=log_prob, value=value,
                            reward=reward.astype(jnp.float32), done=done, indist=indist, overflow=overflow,
                            solved=state.solved)
        return (state, next_obs, done, (hidden, frozen_hidden), tstate), record

    first = jnp.ones((num_envs,), bool)
    frozen_carry = None
    if combining:
        copies = jax.tree.leaves(frozen.params)[0].shape[0]
        frozen_carry = jax.tree.map(lambda x: jnp.broadcast_to(x, (copies,) + x.shape), policy.carry)
    carry = (state, obs, first, (policy.carry, frozen_carry), tstate)
    (state, obs, reset, (hidden, _), _), traj = jax.lax.scan(_env_step, carry, jax.random.split(rng, num_steps))
    _, (_, last_value) = apply_fn({"params": params}, hidden, jax.tree.map(lambda x: x[None], obs), reset[None])
    return traj, last_value[0]


def combine(frozen, tstate, apply_fn: Callable, frozen_hidden, obs_in, reset, logits):
    """ReMiDi's ``Combine`` (Algorithm 1): ``(frozen_hidden, acting logits f32[N, P])``.

    Each frozen buffer's policy (``frozen.params``, leaves [B, ...]; recurrent state
    ``frozen_hidden`` [B, ...]) reads ``obs_in`` [1, N, ...]; the earliest buffer whose level (or
    learned model, ``frozen.tracker.buffer_match``) explains env n's whole prefix acts there, the
    current policy (``logits`` f32[N, P]) where none does."""
    copies = jax.tree.leaves(frozen.params)[0].shape[0]
    capacity = frozen.valid.shape[0] // copies
    frozen_hidden, (frozen_logits, _) = jax.vmap(
        lambda p, h: apply_fn({"params": p}, h, obs_in, reset[None]))(frozen.params, frozen_hidden)
    matched = frozen.tracker.buffer_match(tstate, copies, capacity)
    return frozen_hidden, combined_logits(matched, frozen_logits[:, 0], logits)


def combined_logits(buffer_match: jax.Array, frozen_logits: jax.Array, logits: jax.Array) -> jax.Array:
    """f32[N, P]: the output of the policy acting on each env, the earliest matching buffer's.

    ``buffer_match`` bool[N, B] (frozen buffer b explains env n's whole prefix), ``frozen_logits``
    f32[B, N, P], ``logits`` f32[N, P] (current: where no buffer matches).
    """
    earliest = jnp.argmax(buffer_match, axis=-1)  # first True (0 if none)
    chosen = jnp.take_along_axis(jnp.moveaxis(frozen_logits, 0, 1), earliest[:, None, None], axis=1)[:, 0]
    return jnp.where(buffer_match.any(axis=-1)[:, None], chosen, logits)


# ---------------------------------------------------------------------------- advantages and scores
def compute_gae(rewards, values, dones, last_value, gamma: float, lam: float):
    """Generalised advantage estimation: ``(advantages, targets)``, both ``f32[T, N]``.

    ``rewards``, ``values``: ``f32[T, N]``; ``dones``: ``bool[T, N]`` (episode ended at step t: no
    bootstrapping from t+1); ``last_value``: ``f32[N]``, the value after the last step.
    """
    not_done = 1.0 - dones.astype(jnp.float32)
    next_values = jnp.concatenate([values[1:], last_value[None]], axis=0)
    deltas = rewards + gamma * not_done * next_values - values

    def _get_advantages(next_advantage, x):
        delta, nd = x
        advantage = delta + gamma * lam * nd * next_advantage
        return advantage, advantage

    _, advantages = jax.lax.scan(_get_advantages, jnp.zeros_like(last_value), (deltas, not_done), reverse=True)
    return advantages, advantages + values


def score_rollout(setup: Setup, levels, collection: Collection):
    """f32[N]: each level's score, in the environment's reward units (values and advantages,
    learnt on ``reward × reward_scale``, are scaled back). Perfect regret compares the optimum and
    the mean return both discounted by ``ppo.gamma`` (the paper's utility), or both undiscounted
    with ``discounted_regret`` off. ``collection.best_return`` is MaxMC's record."""
    traj, mean_return = collection.traj, collection.mean_return
    score = setup.score
    optimal = None
    if score.needs_optimum:
        if setup.cfg.discounted_regret:
            gamma = setup.cfg.ppo.gamma
            optimal = jax.vmap(lambda level: setup.task.optimal_discounted_return(level, gamma))(levels)
            mean_return, _, _ = sc.episode_returns(traj.reward, traj.done, gamma)
        else:
            optimal = jax.vmap(setup.task.optimal_return)(levels)
    unscale = 1.0 / setup.cfg.reward_scale
    return score.fn(sc.ScoreInputs(  # the score resolved at set-up (Setup.score)
        mean_return=mean_return, values=traj.value * unscale, advantages=collection.advantages * unscale,
        max_return=collection.best_return, done=traj.done, optimal_return=optimal, reward=traj.reward,
        solved=setup.task.solved, solved_flags=traj.solved))


# ---------------------------------------------------------------------------- masked PPO
#: PPO's diagnostics, logged as ``ppo/<name>``: the mean over the minibatches that trained (NaN
#: when none did, left out of a block's mean)
PPO_METRICS = ("policy_loss", "value_loss", "entropy", "approx_kl", "clip_frac", "grad_norm")


def train(setup: Setup, learner: LearnerState, trained, rng, collection: Collection):
    """Masked PPO on the collection, then the observation statistics: ``(learner, metrics)``.

    Only the distinguishable steps (``~indist``) enter the loss, and only when ``trained``
    (bool[]); otherwise the train state is left as it was. ``metrics``: :data:`PPO_METRICS`,
    f32[] each (NaN when nothing was trained)."""
    # UPDATE NETWORK
    traj = collection.traj
    batch = Batch(obs=traj.obs, reset=traj.reset, actions=traj.action, log_probs=traj.log_prob,
                  values=traj.value, advantages=collection.advantages, targets=collection.targets,
                  mask=~traj.indist & trained)
    carry = setup.net.initialize_carry(setup.cfg.num_envs)
    train_state, metrics = ppo_update(learner.train_state, carry, batch, rng, setup.cfg.ppo,
                                      policy_apply(setup, learner), setup.dist)
    # UPDATE OBSERVATION STATISTICS, with what this rollout saw
    obs_stats = learner.obs_stats
    if obs_stats is not None:
        obs_stats = nrm.update_stats(obs_stats, flatten_obs(traj.obs))
    metrics = {name: metrics[name].astype(jnp.float32) for name in PPO_METRICS}
    return learner.replace(train_state=train_state, obs_stats=obs_stats), metrics


@struct.dataclass
class Batch:
    """A rollout for PPO, every field ``[T, N, ...]``: ``obs`` pytree; ``reset`` bool (an episode
    starts); ``actions`` i32 (``i32[T, N, k]`` multi-discrete, ``f32[T, N, A]`` continuous);
    ``log_probs``, ``values``, ``advantages``, ``targets`` f32; ``mask`` bool (train on this step)."""

    obs: Any
    reset: jax.Array
    actions: jax.Array
    log_probs: jax.Array
    values: jax.Array
    advantages: jax.Array
    targets: jax.Array
    mask: jax.Array


def ppo_update(train_state: TrainState, init_carry, batch: Batch, rng: jax.Array, cfg: PPOConfig,
               apply_fn: Callable | None = None, dist=CATEGORICAL):
    """``cfg.epochs`` x ``cfg.minibatches`` masked PPO steps on a rollout: ``(train_state, metrics)``.

    ``init_carry``: the net's carry for the ``N`` envs at the first step (env axis first). A
    minibatch is a shuffled group of ``N / minibatches`` envs with their whole ``T``-step sequences,
    so a recurrent net replays it from its slice of ``init_carry``. An all-masked minibatch leaves
    params, optimiser state and step count unchanged and is left out of the metrics' means (its
    zeros would dilute them; NaN if none trained); ``masked_fraction`` is over all minibatches.
    Static: ``cfg`` (validated at set-up, :func:`~remidi.engine.core.ppo.validate_ppo_config`),
    ``apply_fn``, ``dist``.
    """
    apply_fn = train_state.apply_fn if apply_fn is None else apply_fn
    num_envs = batch.mask.shape[1]
    size = num_envs // cfg.minibatches

    def _update_minibatch(state, ids):
        carry, minibatch = init_carry, batch
        if ids is not None:  # a group of envs, each with its whole sequence
            carry = jax.tree.map(lambda x: x[ids], init_carry)
            minibatch = jax.tree.map(lambda x: x[:, ids], batch)
        grad_fn = jax.value_and_grad(ppo_loss, has_aux=True)
        (_, metrics), grads = grad_fn(state.params, apply_fn, carry, minibatch, cfg, dist)
        stepped = state.apply_gradients(grads=grads)
        any_unmasked = jnp.any(minibatch.mask)
        state = jax.tree.map(lambda new, old: jnp.where(any_unmasked, new, old), stepped, state)
        metrics["grad_norm"] = optax.tree.norm(grads)
        metrics["trained"] = any_unmasked
        return state, metrics

    def _update_epoch(state, key):
        if cfg.minibatches == 1:  # every env in the one minibatch: shuffling would only reorder sums
            state, metrics = _update_minibatch(state, None)
            return state, jax.tree.map(lambda x: x[None], metrics)
        groups = jax.random.permutation(key, num_envs).reshape(cfg.minibatches, size)
        return jax.lax.scan(_update_minibatch, state, groups)

    train_state, metrics = jax.lax.scan(_update_epoch, train_state, jax.random.split(rng, cfg.epochs))
    trained = metrics.pop("trained")  # bool[epochs, minibatches]
    count = jnp.sum(trained)
    out = {name: jnp.where(count > 0, jnp.sum(jnp.where(trained, v, 0.0)) / jnp.maximum(count, 1), jnp.nan)
           for name, v in metrics.items() if name != "masked_fraction"}
    return train_state, {**out, "masked_fraction": jnp.mean(metrics["masked_fraction"])}


def ppo_loss(params, apply_fn: Callable, carry, batch: Batch, cfg: PPOConfig, dist=CATEGORICAL):
    """Masked PPO loss on one minibatch of ``M`` envs: ``(total_loss, metrics dict)``.

    ``carry``: the net's carry for the ``M`` envs at the first step of ``batch``. The masked steps'
    actions, log-probs, values, advantages and targets are zeroed before any arithmetic, so even a
    NaN there cannot reach the update; their observations still pass through the network (a
    recurrent net needs them) and must be finite.
    """
    mask = batch.mask
    action_mask = mask.reshape(mask.shape + (1,) * (batch.actions.ndim - mask.ndim))
    actions = jnp.where(action_mask, batch.actions, jnp.zeros_like(batch.actions))
    old_log_probs = jnp.where(mask, batch.log_probs, jnp.zeros_like(batch.log_probs))
    old_values = jnp.where(mask, batch.values, jnp.zeros_like(batch.values))
    advantages = jnp.where(mask, batch.advantages, jnp.zeros_like(batch.advantages))
    targets = jnp.where(mask, batch.targets, jnp.zeros_like(batch.targets))
    _, (logits, value) = apply_fn({"params": params}, carry, batch.obs, batch.reset)
    log_prob = dist.log_prob(logits, actions)
    log_ratio = jnp.where(mask, log_prob - old_log_probs, 0.0)
    ratio = jnp.exp(log_ratio)

    advantages = normalize_advantages(advantages, mask)
    surrogate = jnp.minimum(ratio * advantages, jnp.clip(ratio, 1.0 - cfg.clip_eps, 1.0 + cfg.clip_eps) * advantages)
    policy_loss = -masked_mean(surrogate, mask)

    value_sq = jnp.square(value - targets)
    if cfg.clip_value:
        clipped = old_values + jnp.clip(value - old_values, -cfg.clip_eps, cfg.clip_eps)
        value_sq = jnp.maximum(value_sq, jnp.square(clipped - targets))
    value_loss = 0.5 * masked_mean(value_sq, mask)

    entropy = masked_mean(dist.entropy(logits), mask)
    total = policy_loss + cfg.vf_coef * value_loss - cfg.ent_coef * entropy
    metrics = {
        "total_loss": total,
        "policy_loss": policy_loss,
        "value_loss": value_loss,
        "entropy": entropy,
        "approx_kl": masked_mean((ratio - 1.0) - log_ratio, mask),
        "clip_frac": masked_mean((jnp.abs(ratio - 1.0) > cfg.clip_eps).astype(jnp.float32), mask),
        "masked_fraction": 1.0 - jnp.mean(mask.astype(jnp.float32)),
    }
    return total, metrics


def masked_mean(x, mask):
    """``sum(mask * x) / max(sum(mask), 1)``; masked entries of ``x`` are never read."""
    total = jnp.sum(jnp.where(mask, x, 0.0))
    return total / jnp.maximum(jnp.sum(mask), 1)


def normalize_advantages(advantages, mask):
    """``advantages`` standardised over its unmasked entries (population std + 1e-8); masked
    entries, and a single unmasked one, become 0."""
    mean = masked_mean(advantages, mask)
    std = jnp.sqrt(masked_mean(jnp.square(advantages - mean), mask))
    return jnp.where(mask, (advantages - mean) / (std + 1e-8), 0.0)


# ---------------------------------------------------------------------------- non-finite rollouts
#: the prefix of the step metrics flagging non-finite rewards and observations (:func:`nonfinite`);
#: the driver stops the run on one and keeps them out of the history
NONFINITE = "nonfinite/"


def nonfinite_names(rollout_name: str | None = None) -> tuple[str, str]:
    """``nonfinite/reward`` and ``nonfinite/observation``, with ``/<rollout_name>`` for a rollout
    other than the agent's."""
    tail = "" if rollout_name is None else f"/{rollout_name}"
    return f"{NONFINITE}reward{tail}", f"{NONFINITE}observation{tail}"


def nonfinite(traj: Trajectory, rollout_name: str | None = None) -> dict[str, jax.Array]:
    """f32[] 1.0 or 0.0 under :func:`nonfinite_names`: whether a reward, and a floating observation
    leaf, of ``traj`` is NaN or ±inf. Unchecked, a NaN is silent: PLR's scores drop it, so nothing
    enters the buffer and nothing trains."""
    floats = [jnp.all(jnp.isfinite(x)) for x in jax.tree.leaves(traj.obs) if jnp.issubdtype(x.dtype, jnp.inexact)]
    tail = "" if rollout_name is None else f"/{rollout_name}"
    return {f"{NONFINITE}reward{tail}": jnp.asarray(~jnp.all(jnp.isfinite(traj.reward)), jnp.float32),
            f"{NONFINITE}observation{tail}": jnp.asarray(~jnp.all(jnp.stack(floats)) if floats else False, jnp.float32)}
