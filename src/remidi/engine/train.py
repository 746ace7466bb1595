"""The one UED train step shared by every algorithm (:mod:`remidi.engine.algorithms`).

One train step, top to bottom (:func:`train_step`), each stage a small function below it:

1. :func:`choose_levels`: *replay* (probability ``buffer.replay_prob`` once the active buffer
   holds enough levels) samples N levels from the active buffer; otherwise N fresh random levels.
   An algorithm that does not replay (DR) always takes fresh levels.
2. :func:`collect`: roll the policy out once on them (with the distinguishability tracker against
   the frozen buffers, for a buffer sequence: ReMiDi), then :func:`score_rollout`.
3. :func:`update_buffer`: replayed levels get their new scores; fresh levels go into the active
   buffer by score, except those whose rollout was indistinguishable from a frozen level at every
   step ("complete overlap"), which are scored −inf and therefore never inserted.
4. :func:`train`: PPO on replayed levels (and on fresh ones for an algorithm that trains on them:
   DR), with the loss masked to the distinguishable steps.
5. :func:`switch_buffer`: for a buffer sequence, after ``remidi.steps_per_buffer`` updates (or
   replays) in the active buffer, freeze it and move to the next; stay on the last.
6. :func:`step_metrics`: the step's scalars (:data:`BLOCK_REDUCTIONS` says how the driver
   reduces each over a block).

Which branch a stage takes depends on the :class:`~remidi.engine.algorithms.Algorithm`'s fields,
never on its name: PLR⊥ is ReMiDi with one buffer, minimax return is PLR⊥ scored by negative
return. Everything in a step is a pure function of :class:`Runner`, jit-ed and vmapped over seeds
by the driver.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
from flax import struct
from flax.training.train_state import TrainState

from remidi.engine import buffer as buf
from remidi.engine.algorithms import ALGORITHMS, Algorithm, get_algorithm
from remidi.engine import normalize as nrm
from remidi.engine import scores as sc
from remidi.engine.distributions import for_task
from remidi.engine.networks import flatten_obs, make_network
from remidi.engine.ppo import Batch, PPOConfig, compute_gae, create_train_state, ppo_update
from remidi.engine import tracker as trk
from remidi.engine.rollout import Frozen, Trajectory, combined_logits, rollout
from remidi.envs.interface import UEDTask, tree_equal

POLICIES = ("masked", "combine")


@dataclass(frozen=True)
class ReMiDiConfig:
    num_buffers: int = field(default=2, metadata={
        "help": "ReMiDi: number of level buffers (adversaries) in sequence"})
    buffer_capacity: int = field(default=32, metadata={
        "help": "ReMiDi: size of each buffer"})
    steps_per_buffer: int = field(default=1000, metadata={
        "help": "ReMiDi: updates (train steps) on a buffer before it is frozen (replays with remidi.count=replays)"})
    # what steps_per_buffer counts. Every preset counts "updates" (train steps, replay or not): the
    # paper's text switches adversaries "every N iterations" and the authors' code counts every
    # train step; the switch then falls on the same update for every seed and does not move with
    # buffer.replay_prob. "replays" (only replay steps count) is kept for experimentation.
    count: str = field(default="updates", metadata={
        "help": "ReMiDi: what steps_per_buffer counts: updates (every preset: the paper's and its authors' "
                "unit) or replays"})
    tracker: str = field(default="prefix", metadata={
        "help": "ReMiDi: prefix (one frozen level made the whole prefix) or per_step (authors' rule)"})
    # slots per env of the candidate tracker (engine/tracker.py): only frozen levels sharing the
    # env's first observation are stepped, at most this many; 0 steps every frozen level (the
    # reference tracker; also used for tracker=per_step and for tasks without a deterministic reset)
    tracker_budget: int = field(default=64, metadata={
        "help": "ReMiDi: frozen levels tracked per env (0: all, the reference tracker)"})
    # "masked": one shared network, its loss masked on indistinguishable steps (the paper's
    # practical ReMiDi); "combine": the paper's Algorithm 1, a frozen copy of the policy per
    # buffer acts on the trajectories realisable under that buffer's levels
    policy: str = field(default="masked", metadata={
        "help": "ReMiDi: masked (one network) or combine (a frozen policy per buffer)"})


@dataclass(frozen=True)
class AccelConfig:
    """ACCEL's editing (algorithms with ``edits``: ``accel``, ``remidi-accel``)."""

    num_edits: int = field(default=5, metadata={
        "help": "ACCEL: edits per edited level (a maze edit flips one wall or moves the goal)"})
    easy_start: bool = field(default=False, metadata={
        "help": "ACCEL: fresh levels from the task's easy generator (mazes: no walls)"})


@dataclass(frozen=True)
class UEDConfig:
    """A UED run's hyper-parameters (hashable; static under jit)."""

    num_updates: int = field(default=2500, metadata={
        "help": "train steps (one rollout + one PPO update or buffer insertion each)"})
    num_envs: int = field(default=32, metadata={"help": "parallel environments (levels) per train step"})
    num_steps: int = field(default=16, metadata={"help": "environment steps per env per rollout"})
    # one of scores.SCORES; minimax-return always uses neg_return (its Algorithm's score)
    score: str = field(default="perfect_regret", metadata={
        "help": "level score of the PLR family: perfect_regret, pvl, maxmc, neg_return, learnability (SFL: "
                "p(1 − p), p the level's solve rate in the rollout)"})
    # perfect_regret against the paper's discounted utility U = E[Σ_t γ^t r_t] (γ = ppo.gamma) on
    # both sides; False: undiscounted returns on both sides
    discounted_regret: bool = field(default=True, metadata={
        "help": "perfect_regret on the paper's discounted utility Σ γ^t r_t (γ = ppo.gamma), both the "
                "optimum and the agent's return; false: undiscounted on both sides"})
    network: str = field(default="mlp", metadata={"help": "actor-critic: mlp, maze_lstm or mlp_lstm"})
    hidden_size: int = field(default=0, metadata={
        "help": "width of each fully-connected trunk layer (0: the network's default)"})
    lstm_size: int = field(default=0, metadata={
        "help": "units of the network's LSTM (0: the network's default)"})
    # PPO learns from rewards × reward_scale (returns, scores and metrics stay unscaled)
    reward_scale: float = field(default=1.0, metadata={
        "help": "PPO learns from reward × reward_scale (returns and scores stay unscaled)"})
    normalize_obs: bool = field(default=False, metadata={
        "help": "normalise observations by their running mean and std (kept in checkpoints)"})
    eval_every: int = field(default=100, metadata={"help": "updates between evaluations (and logged points)"})
    eval_attempts: int = field(default=10, metadata={"help": "sampled attempts per evaluation level"})
    checkpoint_every: int = field(default=500, metadata={
        "help": "updates between checkpoints (checkpoint.npz in the run folder)"})
    ppo: PPOConfig = field(default_factory=PPOConfig)
    buffer: buf.BufferConfig = field(default_factory=buf.BufferConfig)
    remidi: ReMiDiConfig = field(default_factory=ReMiDiConfig)
    accel: AccelConfig = field(default_factory=AccelConfig)

    def __post_init__(self):
        # the learning-rate schedule spans the run: ppo.total_updates is always num_updates
        object.__setattr__(self, "ppo", dataclasses.replace(self.ppo, total_updates=self.num_updates))


DERIVED_KEYS = ("ppo.total_updates",)  # not settable: follows num_updates


def score_name(cfg: UEDConfig, algo: Algorithm) -> str:
    """The score ``algo`` ranks levels by under ``cfg``."""
    return algo.score_name(cfg.score)


def num_buffers(cfg: UEDConfig, algo: Algorithm) -> int:
    """K, the number of level buffers: ``remidi.num_buffers`` for a buffer sequence, else 1."""
    return cfg.remidi.num_buffers if algo.buffer_sequence else 1


def buffer_config(cfg: UEDConfig, algo: Algorithm) -> buf.BufferConfig:
    """Each buffer's settings (a buffer sequence's buffers hold ``remidi.buffer_capacity``)."""
    if algo.buffer_sequence:
        return dataclasses.replace(cfg.buffer, capacity=cfg.remidi.buffer_capacity)
    return cfg.buffer


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
    (``PRNGKey(0)`` if None), reset with the same key. Returns ``(obs, level)``."""
    key = jax.random.PRNGKey(0) if key is None else key
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
    edit_next = last_replayed = None
    if setup.algo.edits:
        edit_next = jnp.asarray(False)
        last_replayed = jax.tree.map(lambda x: jnp.stack([x] * cfg.num_envs), example_level)
    return Runner(rng=rng, train_state=train_state, buffers=buffers, active=zero, count=zero, update=zero,
                  frozen_params=frozen_params, obs_stats=obs_stats, edit_next=edit_next, last_replayed=last_replayed)


def combines(setup: Setup) -> bool:
    """A buffer sequence (ReMiDi) with ``remidi.policy=combine`` and at least two buffers."""
    return setup.algo.buffer_sequence and setup.cfg.remidi.policy == "combine" and setup.cfg.remidi.num_buffers >= 2


# ------------------------------------------------------------------------------- pieces
def frozen_levels(setup: Setup, runner: Runner) -> Frozen | None:
    """The levels of every buffer before the active one, as one batch of F = (K−1)·capacity."""
    if not setup.algo.buffer_sequence or setup.cfg.remidi.num_buffers < 2:
        return None
    earlier = jax.tree.map(lambda x: x[:-1], runner.buffers)  # the last buffer is never frozen
    k = earlier.valid.shape[0]
    valid = earlier.valid & (jnp.arange(k) < runner.active)[:, None]
    flat = jax.tree.map(lambda x: x.reshape((-1,) + x.shape[2:]), earlier.levels)
    return Frozen(levels=flat, valid=valid.reshape(-1), params=runner.frozen_params, budget=tracker_budget(setup))


def tracker_budget(setup: Setup) -> int:
    """Slots per env of the candidate tracker, or 0 for the reference tracker (see ReMiDiConfig)."""
    r = setup.cfg.remidi
    if r.tracker != "prefix" or not setup.task.deterministic_reset:
        return 0
    return min(r.tracker_budget, (r.num_buffers - 1) * r.buffer_capacity)


def collect(setup: Setup, runner: Runner, rng, levels, frozen):
    """Roll out on ``levels`` [N] and compute GAE and scores.

    Returns ``(traj, advantages f32[T, N], targets f32[T, N], mean_return f32[N],
    max_return f32[N])``; ``max_return`` is this rollout's best episode (the caller combines it
    with the buffer's record for MaxMC). Advantages and targets are in units of
    ``reward × reward_scale``, returns in the environment's.
    """
    cfg, task = setup.cfg, setup.task
    carry = setup.net.initialize_carry(cfg.num_envs)
    traj, last_value = rollout(rng, task.env, task.params, policy_apply(setup, runner), runner.train_state.params,
                               carry, levels, cfg.num_steps, frozen, cfg.remidi.tracker, dist=for_task(task.continuous),
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
    optimal = None
    if score_name(setup.cfg, setup.algo) == "perfect_regret":
        if setup.cfg.discounted_regret:
            gamma = setup.cfg.ppo.gamma
            optimal = jax.vmap(lambda level: setup.task.optimal_discounted_return(level, gamma))(levels)
            mean_return, _, _ = sc.episode_returns(traj.reward, traj.done, gamma)
        else:
            optimal = jax.vmap(setup.task.optimal_return)(levels)
    unscale = 1.0 / setup.cfg.reward_scale
    return sc.score_levels(score_name(setup.cfg, setup.algo), mean_return=mean_return, values=traj.value * unscale,
                           advantages=adv * unscale, max_return=max_return, done=traj.done, optimal_return=optimal,
                           reward=traj.reward, solved=setup.task.solved)


def learn(setup: Setup, runner: Runner, rng, traj: Trajectory, adv, targets) -> TrainState:
    """Masked PPO on a rollout of ``runner``'s policy: only the distinguishable steps
    (``~indist``) are trained on. Returns the new train state."""
    batch = Batch(obs=traj.obs, reset=traj.reset, actions=traj.action, log_probs=traj.log_prob,
                  values=traj.value, advantages=adv, targets=targets, mask=~traj.indist)
    carry = setup.net.initialize_carry(setup.cfg.num_envs)
    train_state, _ = ppo_update(runner.train_state, carry, batch, rng, setup.cfg.ppo, policy_apply(setup, runner),
                                for_task(setup.task.continuous))
    return train_state


def tag_counts(setup: Setup, levels, weight) -> dict[str, jax.Array]:
    """Σ weight over the levels [N] that carry each tag."""
    tags = jax.vmap(setup.task.level_tags)(levels)
    return {name: jnp.sum(jnp.where(t, weight, 0.0)) for name, t in tags.items()}


# ---------------------------------------------------------------------------- the step
def train_step(setup: Setup, runner: Runner):
    """One update. Returns ``(runner, metrics)``, metrics a dict of f32[] scalars."""
    rng, k_branch, k_roll, k_levels, k_learn, k_sample = jax.random.split(runner.rng, 6)
    frozen = frozen_levels(setup, runner)
    # 1. choose the levels: a replay sample from the active buffer, or fresh random levels
    chosen = choose_levels(setup, runner, k_branch, k_levels, k_sample)
    # 2. one rollout (with the tracker against the frozen buffers, for a buffer sequence), then score
    traj, adv, targets, mean_ret, best_ret = collect(setup, runner, k_roll, chosen.levels, frozen)
    best_ret = best_return_record(setup, chosen, best_ret)
    scores = score_rollout(setup, chosen.levels, traj, adv, mean_ret, best_ret)
    overlap = jnp.all(traj.indist, axis=0) & ~chosen.replay  # bool[N]: new level overlapping a frozen one completely
    # 3. the buffer: new scores for replayed levels, fresh ones inserted by score unless they overlap
    buffers, inserted = update_buffer(setup, runner, chosen, scores, overlap, best_ret)
    # 4. train (masked PPO)
    train_state = train(setup, runner, chosen.replay, k_learn, traj, adv, targets)
    obs_stats = runner.obs_stats  # the statistics absorb this rollout's observations
    if obs_stats is not None:
        obs_stats = nrm.update_stats(obs_stats, flatten_obs(traj.obs))
    # 5. a buffer sequence's switching rule (a no-op with one buffer)
    active, count, frozen_params = switch_buffer(setup, runner, chosen.replay, train_state.params)
    edit_next, last_replayed = remember_replay(setup, runner, chosen)
    runner = Runner(rng=rng, train_state=train_state, buffers=buffers, active=active, count=count,
                    update=runner.update + 1, frozen_params=frozen_params, obs_stats=obs_stats,
                    edit_next=edit_next, last_replayed=last_replayed)
    # 6. what the step reports
    return runner, step_metrics(setup, runner, chosen, traj, mean_ret, scores, overlap, inserted, frozen)


@struct.dataclass
class Chosen:
    """The levels of one update and where they came from.

    replay: bool[], replayed from the active buffer (else fresh from the generator, or edited);
    levels: leaves [N, ...]; buffer: the active buffer as sampled (its replay counters advanced;
    the active buffer as it was for an algorithm that does not replay); slots: i32[N], the
    replayed levels' slots in it (None for an algorithm that does not replay); edit: bool[], the
    levels are edits of the last replay's (None for an algorithm that does not edit).
    """

    replay: jax.Array
    levels: object
    buffer: buf.BufferState
    slots: jax.Array | None
    edit: jax.Array | None = None


def choose_levels(setup: Setup, runner: Runner, k_branch, k_levels, k_sample) -> Chosen:
    """Stage 1: replay N levels of the active buffer (probability ``buffer.replay_prob`` once it can
    replay, for an algorithm that replays), else N fresh levels from the task's generator. An
    algorithm that edits (ACCEL) instead edits the levels of the update before, if that one
    replayed."""
    cfg, algo = setup.cfg, setup.algo
    bcfg = buffer_config(cfg, algo)
    active = buf.select_buffer(runner.buffers, runner.active)
    n = cfg.num_envs
    if not algo.replays:
        replay = jnp.asarray(False)
    else:
        replay = buf.can_replay(active, bcfg) & (jax.random.uniform(k_branch) < bcfg.replay_prob)
    generate = setup.task.easy_level if algo.edits and cfg.accel.easy_start else setup.task.sample_level
    new = jax.vmap(generate)(jax.random.split(k_levels, n))
    if not algo.replays:
        return Chosen(replay=replay, levels=new, buffer=active, slots=None)
    sampled, slots, replayed = buf.sample_replay(active, bcfg, k_sample, n)
    if not algo.edits:
        levels = jax.tree.map(lambda r, f: jnp.where(replay, r, f), replayed, new)
        return Chosen(replay=replay, levels=levels, buffer=sampled, slots=slots)
    edit = runner.edit_next
    replay = replay & ~edit
    edited = edit_levels(setup, runner.last_replayed, jax.random.fold_in(k_levels, 1))
    levels = jax.tree.map(lambda e, r, f: jnp.where(edit, e, jnp.where(replay, r, f)), edited, replayed, new)
    return Chosen(replay=replay, levels=levels, buffer=sampled, slots=slots, edit=edit)


def edit_levels(setup: Setup, levels, rng):
    """ACCEL's edits: ``accel.num_edits`` edits of each of ``levels`` [N] by the task's mutator."""
    n = jax.tree.leaves(levels)[0].shape[0]
    edits = setup.cfg.accel.num_edits
    return jax.vmap(lambda key, level: setup.task.mutate_level(key, level, edits))(jax.random.split(rng, n), levels)


def remember_replay(setup: Setup, runner: Runner, chosen: Chosen):
    """ACCEL: ``(edit_next, last_replayed)``: after a replay the next update edits its levels."""
    if not setup.algo.edits:
        return runner.edit_next, runner.last_replayed
    last = jax.tree.map(lambda c, o: jnp.where(chosen.replay, c, o), chosen.levels, runner.last_replayed)
    return chosen.replay, last


def best_return_record(setup: Setup, chosen: Chosen, best_return):
    """f32[N]: MaxMC's record, the best return ever seen on a level: this rollout's best episode
    ``best_return`` [N], and for a replayed level the buffer's record too."""
    if not setup.algo.replays:
        return best_return
    record = chosen.buffer.extras["max_return"][chosen.slots]
    return jnp.where(chosen.replay, jnp.maximum(best_return, record), best_return)


def update_buffer(setup: Setup, runner: Runner, chosen: Chosen, scores, overlap, best_return):
    """Stage 3: replayed levels get their new ``scores`` [N]; fresh levels are inserted into the
    active buffer by score, never one whose rollout overlaps a frozen level completely (``overlap``
    bool[N]: scored −inf). Returns ``(buffers, inserted bool[N])``; an algorithm that does not
    replay keeps its buffers as they are."""
    n = setup.cfg.num_envs
    if not setup.algo.replays:
        return runner.buffers, jnp.zeros((n,), bool)
    bcfg = buffer_config(setup.cfg, setup.algo)

    def rescore(_):
        return buf.update_scores(chosen.buffer, chosen.slots, scores, {"max_return": best_return}), jnp.zeros((n,), bool)

    def insert(_):
        active = buf.select_buffer(runner.buffers, runner.active)
        new_buf, ins, _ = buf.insert_batch(active, bcfg, chosen.levels, jnp.where(overlap, -jnp.inf, scores),
                                           {"max_return": best_return})
        return new_buf, ins

    new_buf, inserted = jax.lax.cond(chosen.replay, rescore, insert, None)
    return buf.replace_buffer(runner.buffers, runner.active, new_buf), inserted


def train(setup: Setup, runner: Runner, replay, rng, traj: Trajectory, adv, targets) -> TrainState:
    """Stage 4: masked PPO on the rollout if it replayed levels or the algorithm trains on fresh
    ones (robust PLR⊥ does not); otherwise the train state as it was."""
    if setup.algo.trains_on_fresh:
        return learn(setup, runner, rng, traj, adv, targets)
    return jax.lax.cond(replay, lambda r: learn(setup, r, rng, traj, adv, targets), lambda r: r.train_state, runner)


def switch_buffer(setup: Setup, runner: Runner, replay, params):
    """Stage 5: a buffer sequence's switching rule. Counts the update (or, with
    ``remidi.count=replays``, a replay) on the active buffer; after ``remidi.steps_per_buffer``
    it freezes the buffer (and, under ``remidi.policy=combine``, keeps ``params`` as its policy)
    and moves to the next, staying on the last. Returns ``(active i32[], count i32[],
    frozen_params)``."""
    cfg = setup.cfg
    count = runner.count + (replay.astype(jnp.int32) if cfg.remidi.count == "replays" else 1)
    k = runner.buffers.valid.shape[0]
    if setup.algo.buffer_sequence:
        switch = (count >= cfg.remidi.steps_per_buffer) & (runner.active + 1 < k)
    else:
        switch = jnp.asarray(False)
    frozen_params = runner.frozen_params
    if frozen_params is not None:  # Combine: the policy trained on the buffer being frozen is kept
        frozen_params = jax.tree.map(
            lambda f, p: f.at[runner.active].set(jnp.where(switch, p, f[runner.active]), mode="drop"),
            frozen_params, params)
    return jnp.where(switch, runner.active + 1, runner.active), jnp.where(switch, 0, count), frozen_params


#: how the driver reduces a step metric over a block of updates: "sum", "last" or "mean" (any
#: metric not listed). ``replayed/<tag>`` counts become the block's ``replay_fraction/<tag>``.
BLOCK_REDUCTIONS = {"rejected": "sum", "inserted": "sum", "tracker_overflow": "sum", "active_buffer": "last"}


def step_metrics(setup: Setup, runner: Runner, chosen: Chosen, traj: Trajectory, mean_return, scores, overlap,
                 inserted, frozen) -> dict[str, jax.Array]:
    """Stage 6: the step's f32[] scalars (``runner`` is the one after the step)."""
    trained = chosen.replay | setup.algo.trains_on_fresh
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
    for name, c in tag_counts(setup, chosen.levels, jnp.where(chosen.replay, 1.0, 0.0)).items():
        metrics[f"replayed/{name}"] = c
    return metrics


def buffer_tag_fractions(setup: Setup, runner: Runner) -> dict[str, jax.Array]:
    """Share of each tag among the valid levels of every buffer (``/b<k>``) and of the active one;
    nothing for DR, which has no buffer."""
    out = {}
    if not setup.algo.replays:
        return out
    valid = runner.buffers.valid  # bool[K, C]
    sizes = jnp.maximum(jnp.sum(valid, axis=1), 1)  # [K]
    counts = jax.vmap(lambda levels, v: tag_counts(setup, levels, v.astype(jnp.float32)))(runner.buffers.levels, valid)
    for name, c in counts.items():  # c: f32[K]
        fractions = c / sizes
        for b in range(valid.shape[0]):
            out[f"buffer_fraction/{name}/b{b}"] = fractions[b]
        out[f"buffer_fraction/{name}"] = fractions[runner.active]
    out["buffer_size"] = jnp.sum(valid[runner.active]).astype(jnp.float32)
    return out


# ---------------------------------------------------------------------------- evaluation
def first_episode_return(reward: jax.Array, done: jax.Array, gamma: float = 1.0) -> jax.Array:
    """f32[N]: return of the first episode of each env (``reward``, ``done``: [T, N]; the rollout
    starts the episode), discounted Σ_t γ^t r_t for ``gamma`` < 1."""
    ended_before = jnp.cumsum(done, axis=0) - done  # episodes finished before step t
    discount = jnp.power(jnp.float32(gamma), jnp.arange(reward.shape[0], dtype=jnp.float32))[:, None]
    return jnp.sum(jnp.where(ended_before == 0, discount * reward, 0.0), axis=0)


def eval_groups(task: UEDTask) -> list[tuple[object, list[str]]]:
    """The evaluation sets grouped by the environment that plays them (``task.eval_envs``, else
    ``task.env``), each group's names sorted: one rollout per group."""
    groups: list[tuple[object, list[str]]] = []
    for name in sorted(task.eval_sets):
        env = task.eval_envs.get(name, task.env)
        for genv, names in groups:
            if genv is env:
                names.append(name)
                break
        else:
            groups.append((env, [name]))
    return groups


def first_step_policy(setup: Setup, runner: Runner, env, levels) -> jax.Array:
    """f32[L, A]: the action probabilities at the first step of each level (leaves [L, ...]) of
    the policy that acts there (under ``remidi.policy=combine``, the combined policy)."""
    task, net = setup.task, setup.net
    n = jax.tree.leaves(levels)[0].shape[0]
    keys = jax.random.split(jax.random.PRNGKey(0), n)
    obs, _ = jax.vmap(env.reset_to_level, in_axes=(0, 0, None))(keys, levels, task.params)
    obs_in, reset = jax.tree.map(lambda x: x[None], obs), jnp.ones((1, n), bool)
    _, (logits, _) = policy_apply(setup, runner)({"params": runner.train_state.params}, net.initialize_carry(n),
                                                 obs_in, reset)
    logits = logits[0]
    if combines(setup):
        frozen = frozen_levels(setup, runner)
        tstate = jax.vmap(trk.tracker_reset, in_axes=(None, None, 0, None, None, 0))(
            task.env, task.params, keys, frozen.levels, frozen.valid, obs)
        r = setup.cfg.remidi
        matched = jax.vmap(trk.buffer_match, in_axes=(0, None, None))(tstate, r.num_buffers - 1, r.buffer_capacity)
        _, (frozen_logits, _) = jax.vmap(lambda p: net.apply({"params": p}, net.initialize_carry(n), obs_in, reset))(
            frozen.params)
        logits = combined_logits(matched, frozen_logits[:, 0], logits)
    return jax.nn.softmax(logits, axis=-1)


def level_returns(setup: Setup, runner: Runner, env, levels, attempts: int, rng):
    """The first-episode return of ``attempts`` sampled episodes on each of ``levels`` (leaves
    [L, ...], played by ``env``; under ``remidi.policy=combine`` by the combined policy):
    ``(returns f32[L, attempts], discounted f32[L, attempts])``, the latter Σ_t γ^t r_t with
    γ = ``ppo.gamma``. One rollout of ``task.max_episode_steps`` on L·attempts envs."""
    task = setup.task
    frozen = frozen_levels(setup, runner) if combines(setup) else None  # act as the combined policy
    tiled = jax.tree.map(lambda x: jnp.repeat(x, attempts, axis=0), levels)  # each level's attempts side by side
    n = jax.tree.leaves(tiled)[0].shape[0]
    traj, _ = rollout(rng, env, task.params, policy_apply(setup, runner), runner.train_state.params,
                      setup.net.initialize_carry(n), tiled, task.max_episode_steps, frozen, tracker_env=task.env,
                      dist=for_task(task.continuous), deterministic_reset=task.deterministic_reset)
    returns = first_episode_return(traj.reward, traj.done).reshape(-1, attempts)
    discounted = first_episode_return(traj.reward, traj.done, setup.cfg.ppo.gamma).reshape(-1, attempts)
    return returns, discounted


def evaluate(setup: Setup, runner: Runner, rng) -> dict[str, jax.Array]:
    """Metrics on each evaluation set ``<set>``: ``eval_attempts`` sampled episodes per level (the
    first episode of each; the sets one environment plays are rolled out together,
    :func:`level_returns`) give ``solve_rate/<set>``, ``return/<set>`` and
    ``discounted_return/<set>`` (Σ_t γ^t r_t, γ = ``ppo.gamma``). With the task's optimal return,
    the regret per level gives ``regret/<set>/mean`` and ``regret/<set>/worst`` (over the set's
    levels): the *expected* regret ``optimal − E[return]`` (undiscounted), exact for a one-step
    task that knows its ``expected_return`` (which adds ``entropy/<set>``, the mean entropy of the
    policy over the set's levels), estimated from the sampled episodes otherwise."""
    task, cfg = setup.task, setup.cfg
    out = {}
    for i, (env, names) in enumerate(eval_groups(task)):
        levels = jax.tree.map(lambda *xs: jnp.concatenate(xs), *(task.eval_sets[name] for name in names))
        returns, discounted = level_returns(setup, runner, env, levels, cfg.eval_attempts, jax.random.fold_in(rng, i))
        optimal = None
        if task.optimal_return is not None:  # once for the group's sets (for mazes, a search per level)
            optimal = jax.vmap(task.optimal_return)(levels)
        start = 0
        for name in names:
            set_levels = task.eval_sets[name]
            count = jax.tree.leaves(set_levels)[0].shape[0]
            ret, set_discounted = returns[start:start + count], discounted[start:start + count]  # [count, attempts]
            set_optimal = None if optimal is None else optimal[start:start + count]
            start += count
            if task.solved is not None:
                out[f"solve_rate/{name}"] = jnp.mean(task.solved(ret).astype(jnp.float32))
            out[f"return/{name}"] = jnp.mean(ret)
            out[f"discounted_return/{name}"] = jnp.mean(set_discounted)
            if task.optimal_return is None:
                continue
            if task.expected_return is not None:
                probs = first_step_policy(setup, runner, env, set_levels)  # [L, A]
                expected = jax.vmap(task.expected_return)(set_levels, probs)
                entropy = -jnp.sum(probs * jnp.log(jnp.maximum(probs, 1e-30)), axis=-1)
                out[f"entropy/{name}"] = jnp.mean(entropy)
            else:
                expected = ret.mean(axis=1)
            regret = set_optimal - expected
            out[f"regret/{name}/mean"] = jnp.mean(regret)
            out[f"regret/{name}/worst"] = jnp.max(regret)
    return out


# ---------------------------------------------------------------------------- validation
def _observation_batch(task: UEDTask, flat: bool):
    """The task's first observation as a ``[1, 1, ...]`` batch (flattened to one vector if
    ``flat``), shapes only. Raises ConfigError, once, with the environment's own error when its
    level generator or reset fails (a network cannot be judged on an environment that does not run)."""
    from remidi.errors import ConfigError

    def first():
        obs = jax.tree.map(lambda x: x[None, None], example_observation(task)[0])
        return flatten_obs(obs) if flat else obs

    try:
        return jax.eval_shape(first)
    except Exception as err:  # the user's environment: report its own error, once
        message = str(err).strip().splitlines()[0] if str(err).strip() else ""
        raise ConfigError(f"task: sampling a level and resetting the environment to it failed: "
                          f"{type(err).__name__}{': ' + message if message else ''} (the environment must be a "
                          f"jaxued UnderspecifiedEnv and sample_level must return one of its levels)") from None


def _read_error(net, obs) -> Exception | None:
    """None if ``net`` can be initialised on the observation batch ``obs`` (traced abstractly),
    else the error it raised."""
    try:
        jax.eval_shape(lambda o: net.init(jax.random.PRNGKey(0), net.initialize_carry(1), o, jnp.ones((1, 1), bool)),
                       obs)
        return None
    except Exception as err:  # any failure to read the observation is the choice of network
        return err


def check_network_reads_observations(net, name: str, task: UEDTask, flat: bool = False) -> None:
    """Raise ConfigError unless ``net`` can be applied to the task's observations (flattened to
    one vector if ``flat``, as ``normalize_obs`` does; traced abstractly: nothing is compiled or
    run). The error names the networks that can; an environment that fails to produce an
    observation gets its own one-line error instead (:func:`_observation_batch`)."""
    from remidi.engine.networks import NETWORKS
    from remidi.errors import ConfigError

    obs = _observation_batch(task, flat)
    err = _read_error(net, obs)
    if err is None:
        return
    fits = [other for other in sorted(NETWORKS)
            if other != name and _read_error(make_network(other, task.num_actions, task.continuous), obs) is None]
    what = "this task's observations" + (" (flattened by normalize_obs)" if flat else "")
    raise ConfigError(f"network: {name} cannot read {what} ({type(err).__name__}); "
                      f"allowed: {', '.join(fits) or 'none of ' + ', '.join(sorted(NETWORKS))}")


def run_warnings(cfg: UEDConfig, algo: str | Algorithm, task: UEDTask) -> list[str]:
    """One-line warnings about a valid run that would train degenerately without saying so:

    * a score that needs finished episodes (``pvl``, ``maxmc``, ``learnability``) on rollouts
      shorter than the task's episode limit: a level whose episode does not end inside the rollout
      scores −inf, and with every episode too long the buffer holds one level and replays only it;
    * ReMiDi on a task whose reset depends on its random key (two resets of one level with two keys
      give different first observations): the tracker assumes an episode is a function of the
      level and the actions, so it may judge identical levels distinguishable.
    """
    out = []
    algo = get_algorithm(algo)
    name = score_name(cfg, algo)
    if algo.replays and name in ("pvl", "maxmc", "learnability") and cfg.num_steps < task.max_episode_steps:
        out.append(f"score {name} uses the episodes that end inside a rollout, but num_steps ({cfg.num_steps}) is "
                   f"shorter than an episode can last ({task.max_episode_steps}): levels whose episode does not end "
                   f"score -inf and are never inserted; raise num_steps or use another score")
    if algo.buffer_sequence and cfg.remidi.num_buffers > 1 and not task.deterministic_reset:
        level = task.sample_level(jax.random.PRNGKey(0))
        obs = [task.env.reset_to_level(jax.random.PRNGKey(k), level, task.params)[0] for k in (1, 2)]
        if not bool(tree_equal(obs[0], obs[1])):
            out.append("remidi: this task's reset depends on its random key (one level, two keys, two first "
                       "observations), but ReMiDi's tracker assumes an episode is a function of the level and the "
                       "actions; put the random seed into the level (UEDTask.deterministic_reset)")
    return out


def validate_section(prefix: str, validate) -> None:
    """Call ``validate()`` (a nested config's validator, whose errors name its keys without the
    section) and raise its ConfigError with the keys' full dotted names (``prefix`` + key)."""
    from remidi.errors import ConfigError

    try:
        validate()
    except ConfigError as err:
        msg = str(err)
        raise ConfigError(msg if msg.startswith(prefix) else prefix + msg) from None


def validate_ued_config(cfg: UEDConfig, algo: str | Algorithm, task: UEDTask) -> None:
    """Raise ConfigError (one line, naming the key and what is allowed) for an invalid run."""
    from remidi.engine.ppo import validate_ppo_config
    from remidi.engine.tracker import MODES
    from remidi.errors import ConfigError
    from remidi.errors import choice, positive_int, require

    algo = get_algorithm(algo)
    for key in ("num_updates", "num_envs", "num_steps", "eval_every", "eval_attempts", "checkpoint_every"):
        positive_int(key, getattr(cfg, key))
    steps = cfg.num_updates * cfg.ppo.epochs * cfg.ppo.minibatches  # the optimiser's int32 step count
    if steps >= 2**31:
        raise ConfigError(f"num_updates: must keep num_updates × ppo.epochs × ppo.minibatches below 2^31 "
                          f"(the optimiser counts its steps in 32 bits), got {cfg.num_updates} × {cfg.ppo.epochs} × "
                          f"{cfg.ppo.minibatches} = {steps}; lower num_updates")
    if cfg.eval_every > cfg.num_updates:
        raise ConfigError(f"eval_every: must be ≤ num_updates ({cfg.num_updates}), got {cfg.eval_every}; "
                          f"lower eval_every or raise num_updates")
    choice("score", cfg.score, sc.SCORES)
    if score_name(cfg, algo) == "perfect_regret" and task.optimal_return is None:
        raise ConfigError("score: perfect_regret needs the environment's optimal return, which this task "
                          f"does not provide; allowed: {', '.join(s for s in sc.SCORES if s != 'perfect_regret')}")
    require(isinstance(cfg.discounted_regret, bool), "discounted_regret", "true or false", cfg.discounted_regret)
    if score_name(cfg, algo) == "learnability" and task.solved is None:
        raise ConfigError("score: learnability needs a solve criterion, which this task does not define "
                          f"(UEDTask.solved); allowed: {', '.join(s for s in sc.SCORES if s != 'learnability')}")
    if (score_name(cfg, algo) == "perfect_regret" and cfg.discounted_regret
            and task.optimal_discounted_return is None):
        raise ConfigError("discounted_regret: this task gives no discounted optimal return "
                          "(UEDTask.optimal_discounted_return), so perfect_regret cannot use the discounted utility; "
                          "allowed: false (undiscounted returns on both sides)")
    for key in ("hidden_size", "lstm_size"):
        require(isinstance(getattr(cfg, key), int) and getattr(cfg, key) >= 0, key,
                "an integer ≥ 0 (0: the network's default)", getattr(cfg, key))
    require(cfg.reward_scale > 0, "reward_scale", "> 0", cfg.reward_scale)
    # the network kind first (at its default sizes), then the sizes: a preset's hidden_size must not
    # hide that the network picked cannot read the task's observations
    check_network_reads_observations(network_for(dataclasses.replace(cfg, hidden_size=0, lstm_size=0), task),
                                     cfg.network, task, cfg.normalize_obs)
    network_for(cfg, task)  # ConfigError if the network has no layer for hidden_size / lstm_size
    r = cfg.remidi
    positive_int("remidi.num_buffers", r.num_buffers)
    positive_int("remidi.buffer_capacity", r.buffer_capacity)
    positive_int("remidi.steps_per_buffer", r.steps_per_buffer)
    require(isinstance(r.tracker_budget, int) and not isinstance(r.tracker_budget, bool) and r.tracker_budget >= 0,
            "remidi.tracker_budget", "an integer ≥ 0 (0: the reference tracker)", r.tracker_budget)
    choice("remidi.count", r.count, ("updates", "replays"))
    choice("remidi.tracker", r.tracker, MODES)
    choice("remidi.policy", r.policy, POLICIES)
    if r.policy == "combine":
        require(not cfg.normalize_obs, "remidi.policy", "masked with normalize_obs (the frozen policies would read "
                "observations normalised by statistics gathered after they were frozen)", r.policy)
        require(r.tracker == "prefix", "remidi.tracker", "prefix with remidi.policy=combine (a policy per "
                "buffer acts where that buffer's levels produced the whole prefix)", r.tracker)
    positive_int("accel.num_edits", cfg.accel.num_edits)
    require(isinstance(cfg.accel.easy_start, bool), "accel.easy_start", "true or false", cfg.accel.easy_start)
    if algo.edits and task.mutate_level is None:
        raise ConfigError(f"--algo: {algo.name} edits levels, but this task has no level mutator "
                          f"(UEDTask.mutate_level); allowed: {', '.join(a for a in ALGORITHMS if not ALGORITHMS[a].edits)}")
    if algo.edits and cfg.accel.easy_start and task.easy_level is None:
        raise ConfigError("accel.easy_start: this task has no easy-level generator (UEDTask.easy_level); "
                          "allowed: false")
    validate_section("ppo.", lambda: validate_ppo_config(cfg.ppo, cfg.num_envs))
    validate_section("buffer.", lambda: buf.validate_buffer_config(cfg.buffer))
    validate_section("buffer.", lambda: buf.validate_buffer_config(buffer_config(cfg, algo)))
    if algo.buffer_sequence:
        needed = (r.num_buffers - 1) * r.steps_per_buffer
        if needed >= cfg.num_updates:
            raise ConfigError(
                f"remidi.num_buffers: must be small enough that the last buffer gets updates, but "
                f"(num_buffers − 1) × steps_per_buffer = ({r.num_buffers} − 1) × {r.steps_per_buffer} = {needed} "
                f"is not below num_updates = {cfg.num_updates}; lower remidi.num_buffers or "
                f"remidi.steps_per_buffer, or raise num_updates")
