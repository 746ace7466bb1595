"""A UED run's configuration: :class:`UEDConfig` and its sections, and what it derives for an
algorithm (score, number of buffers, buffer settings). Each key's help text is its field's
metadata (``remidi list`` prints them)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from remidi.engine.core.ppo import PPOConfig
from remidi.errors import ConfigError, one_of

POLICIES = ("masked", "combine")


@dataclass(frozen=True)
class BufferConfig:
    """Static (hashable) buffer hyperparameters.

    Attributes:
        capacity: number of slots.
        prioritization: a :data:`~remidi.engine.adversaries.level_buffer.REPLAY_RULES` name:
            ``"rank"`` (∝ (1/rank)^(1/temperature)) or ``"topk"`` (softmax of score/temperature over
            the ``topk_k`` best valid entries).
        temperature: β of both, > 0.
        topk_k: k of top-k, ≥ 1 (clipped to the valid entries).
        staleness_coef: ρ; weights = (1-ρ)·score weights + ρ·staleness weights.
        replay_prob: probability of a replay step (read by the train step).
        min_fill: fraction of the capacity valid before replay is allowed.
        duplicate_check: inserting a level equal to a valid entry updates that entry."""

    capacity: int = field(default=4000, metadata={"help": "PLR level buffer size (plr, minimax-return)"})
    prioritization: str = field(default="rank", metadata={"help": "replay rule: rank, topk, or one registered with remidi.register_replay_rule"})
    temperature: float = field(default=1.0, metadata={"help": "β of rank prioritisation and of the top-k softmax"})
    topk_k: int = field(default=32, metadata={"help": "k of top-k prioritisation"})
    staleness_coef: float = field(default=0.3, metadata={"help": "ρ: weight of staleness in the replay distribution"})
    replay_prob: float = field(default=0.8, metadata={"help": "probability that a train step replays buffer levels"})
    min_fill: float = field(default=0.0, metadata={"help": "fraction of the buffer that must be filled before replay"})
    duplicate_check: bool = field(default=False, metadata={
        "help": "re-inserting a level already in the buffer updates it"})


def _is_int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _is_real(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _check_unit_interval(name: str, value) -> None:
    if not (_is_real(value) and 0.0 <= value <= 1.0):
        raise ConfigError(f"{name}: must be a number in [0, 1], got {value!r}")


@dataclass(frozen=True)
class ReMiDiConfig:
    num_buffers: int = field(default=2, metadata={
        "help": "ReMiDi: number of level buffers (adversaries) in sequence"})
    buffer_capacity: int = field(default=32, metadata={
        "help": "ReMiDi: size of each buffer"})
    steps_per_buffer: int = field(default=1000, metadata={
        "help": "ReMiDi: updates (train steps) on a buffer before it is frozen (replays with remidi.count=replays)"})
    # "updates", as the paper and its authors' code: the switch falls on the same update for every
    # seed, whatever buffer.replay_prob; "replays" is for experiments
    count: str = field(default="updates", metadata={
        "help": "ReMiDi: what steps_per_buffer counts: updates (every preset: the paper's and its authors' "
                "unit) or replays"})
    tracker: str = field(default="prefix", metadata={
        "help": "ReMiDi: prefix (one frozen level made the whole prefix), per_step (authors' rule), tolerance "
                "(prefix, with observations compared up to remidi.tracker_tolerance: for continuous or noisy "
                "observations; engine/trackers/tolerance.py), belief "
                "(a learned model per buffer judges the prefix: for environments whose observations are random "
                "given the level; engine/trackers/belief.py) or simulated (the frozen levels simulated under fresh randomness "
                "with a learnt noise model, the belief_* keys as for belief; engine/trackers/simulated.py)"})
    # the candidate tracker's slots per env (engine/trackers/exact.py); 0: the reference tracker
    tracker_budget: int = field(default=64, metadata={
        "help": "ReMiDi: frozen levels tracked per env (0: all, the reference tracker)"})
    # tracker=tolerance: |a − b| ≤ tracker_tolerance + tracker_rtol·|b| (engine/trackers/tolerance.py)
    tracker_tolerance: float = field(default=0.0, metadata={
        "help": "ReMiDi, tracker=tolerance: the absolute tolerance of a float observation entry, in the "
                "observation's units (wider than its noise, narrower than what tells levels apart)"})
    tracker_rtol: float = field(default=0.0, metadata={
        "help": "ReMiDi, tracker=tolerance: the tolerance relative to the frozen level's |entry|, added to "
                "tracker_tolerance"})
    # tracker=belief / simulated (engine/trackers/belief.py, calibration.py)
    belief_false_rate: float = field(default=0.05, metadata={
        "help": "ReMiDi, tracker=belief: share of the adversary's own trajectory prefixes its frozen model may call "
                "distinguishable (the threshold is at most this quantile; belief_spread may lower it)"})
    belief_margin: float = field(default=1e-3, metadata={
        "help": "ReMiDi, tracker=belief: nats per step the threshold is lowered below the calibrated quantile "
                "(a tolerance for score differences the model should not care about)"})
    # why 6 (calibration.spread_fence): at the lever-noisy switch (paper seeds 100–101, smoke 0–1) the
    # fence lies 0.4–2.1 nats below the lowest of 10⁴ fresh hidden levels and 1.8–12.8 above the highest
    # visible one; 4 lets 0.6 % of hidden levels through, 5 lets 3 in 10⁴, 8 lies 0.1 nats above visible
    belief_spread: float = field(default=6.0, metadata={
        "help": "ReMiDi, tracker=belief or simulated: the threshold is at most the median of the held-out scores "
                "minus this many robust standard deviations of one model version's scores (the median over "
                "recorded rollouts of each one's MAD × 1.4826), per prefix-length bucket, before the margin "
                "(0: the false-rate quantile alone)"})
    belief_hidden: int = field(default=64, metadata={"help": "ReMiDi, tracker=belief: the model's GRU units"})
    belief_lr: float = field(default=1e-2, metadata={"help": "ReMiDi, tracker=belief: the model's Adam learning rate"})
    belief_epochs: int = field(default=4, metadata={
        "help": "ReMiDi, tracker=belief: the model's updates on each rollout of its adversary's levels (a replay "
                "of its buffer; every update of a generator)"})
    belief_reference: bool = field(default=False, metadata={
        "help": "ReMiDi, tracker=belief: judge by the log-likelihood ratio of each frozen model over a model of the "
                "task generator's trajectories (learnt on the rollouts of fresh levels), not by the likelihood alone"})
    belief_calibration: int = field(default=16, metadata={
        "help": "ReMiDi, tracker=belief: rollouts of the adversary's levels whose prefix scores (held out: scored "
                "before the model fits on them) calibrate the threshold at the freeze"})
    # "masked": one network, loss masked on indistinguishable steps (the paper's practical ReMiDi);
    # "combine": Algorithm 1, a frozen policy per buffer acts where that buffer's levels explain the prefix
    policy: str = field(default="masked", metadata={
        "help": "ReMiDi: masked (one network) or combine (a frozen policy per buffer)"})
    # the paper's §7 limitation (adversaries/plr.py, rehearse_frozen)
    rehearsal: float = field(default=0.0, metadata={
        "help": "ReMiDi: probability that an update, once a buffer is frozen, trains unmasked on a batch of an "
                "earlier (frozen) buffer's levels instead (0: the paper's ReMiDi)"})


@dataclass(frozen=True)
class AccelConfig:
    """ACCEL's editing (algorithms with ``edits``: ``accel``, ``remidi-accel``)."""

    num_edits: int = field(default=5, metadata={
        "help": "ACCEL: edits per edited level (a maze edit flips one wall or moves the goal)"})
    easy_start: bool = field(default=False, metadata={
        "help": "ACCEL: fresh levels from the task's easy generator (mazes: no walls)"})


@dataclass(frozen=True)
class PairedConfig:
    """PAIRED's generator and antagonist (algorithms with a learned level generator: ``paired``)."""

    estimator: str = field(default="paired", metadata={
        "help": "PAIRED: the generator's regret estimate: paired (antagonist's best − protagonist's mean), "
                "flexible (the better agent's best − the other's mean) or perfect (the task's optimum − protagonist's mean)"})
    clip_negative: bool = field(default=False, metadata={
        "help": "PAIRED: pay the generator max(regret, 0) instead of the regret"})
    generator_network: str = field(default="mlp", metadata={
        "help": "PAIRED: the generator's network: mlp (an MLP over its observation, sized for a CPU) or reference "
                "(the reference libraries' adversary: a 128-channel conv over a maze design, the embedded step "
                "and the noise into a 256-unit LSTM)"})
    generator_hidden: int = field(default=64, metadata={
        "help": "PAIRED: width of the generator's two trunk layers (generator_network mlp)"})
    generator_lr: float = field(default=1e-4, metadata={"help": "PAIRED: the generator's Adam learning rate"})
    generator_ent_coef: float = field(default=0.01, metadata={
        "help": "PAIRED: the generator's entropy-bonus coefficient"})
    overlap_regret: str = field(default="lowest", metadata={
        "help": "ReMiDi over PAIRED: what a generator is paid for a level an earlier generator's support explains "
                "completely: lowest (the lowest regret estimate of the update's levels) or zero"})


@dataclass(frozen=True)
class SFLConfig:
    """SFL's learnability buffer (:mod:`remidi.engine.adversaries.sfl`).

    Defaults: the authors' published JaxUED maze configuration (amacrutherford/sampling-for-learnability);
    each help also gives Kinetix's. Presets scale them (``remidi list NAME``)."""

    batch_size: int = field(default=5000, metadata={
        "help": "SFL: fresh levels rolled out per batch of a buffer refresh (published: 5000 maze, 4096 Kinetix)"})
    num_batches: int = field(default=5, metadata={
        "help": "SFL: batches per refresh; batch_size × num_batches candidate levels (published: 5 maze, "
                "3 Kinetix)"})
    rollout_steps: int = field(default=2000, metadata={
        "help": "SFL: steps the current policy plays each candidate (several episodes; its solve rate p over "
                "the episodes that end) (published: 2000 maze, 512 Kinetix)"})
    buffer_size: int = field(default=1000, metadata={
        "help": "SFL: K, the candidates with the highest learnability p(1 − p) kept (remidi-sfl: each buffer "
                "keeps remidi.buffer_capacity) (published: 1000 maze, 1024 Kinetix)"})
    refresh_every: int = field(default=100, metadata={
        "help": "SFL: updates between refreshes of the buffer, the first before update 0 (remidi-sfl: counted "
                "on the active buffer, so a new buffer is filled at its first update) (published: 100 maze, "
                "the evaluation period; 128 Kinetix, buffer_update_frequency)"})
    sampled_envs_ratio: float = field(default=0.5, metadata={
        "help": "SFL: share of an update's envs drawn uniformly (with replacement) from the buffer, "
                "round(ratio × num_envs); the rest are fresh levels (published: 0.5 maze and Kinetix)"})


def validate_sfl_config(config: SFLConfig) -> None:
    """Raise :class:`~remidi.errors.ConfigError` (one line, naming the field without ``sfl.``) if invalid."""
    for name in ("batch_size", "num_batches", "rollout_steps", "buffer_size", "refresh_every"):
        value = getattr(config, name)
        if not (_is_int(value) and value >= 1):
            raise ConfigError(f"{name}: must be an integer ≥ 1, got {value!r}")
    _check_unit_interval("sampled_envs_ratio", config.sampled_envs_ratio)


@dataclass(frozen=True)
class UEDConfig:
    """A UED run's hyper-parameters (hashable; static under jit)."""

    num_updates: int = field(default=2500, metadata={
        "help": "train steps (one rollout + one PPO update or buffer insertion each)"})
    num_envs: int = field(default=32, metadata={"help": "parallel environments (levels) per train step"})
    num_steps: int = field(default=16, metadata={"help": "environment steps per env per rollout"})
    # one of scores.SCORES; minimax-return always uses neg_return (its Algorithm's score)
    score: str = field(default="perfect_regret", metadata={
        "help": "level score of the PLR family: a registered score (scores above: those this task can use)"})
    discounted_regret: bool = field(default=True, metadata={
        "help": "perfect_regret on the paper's discounted utility Σ γ^t r_t (γ = ppo.gamma), both the "
                "optimum and the agent's return; false: undiscounted on both sides"})
    network: str = field(default="mlp", metadata={
        "help": "actor-critic: a registered network (networks above: what each reads), e.g. mlp, maze_lstm, "
                "mlp_lstm, entity, cnn"})
    hidden_size: int = field(default=0, metadata={
        "help": "width of each fully-connected trunk layer (0: the network's default)"})
    lstm_size: int = field(default=0, metadata={
        "help": "units of the network's LSTM (0: the network's default)"})
    reward_scale: float = field(default=1.0, metadata={
        "help": "PPO learns from reward × reward_scale (returns and scores stay unscaled)"})
    reseed: bool = field(default=False, metadata={
        "help": "every rollout plays its levels with their own randomness drawn afresh (the task's reseed_level, "
                "e.g. a noisy level's seed): a stochastic environment, where the same level never shows the "
                "same noise twice"})
    normalize_obs: bool = field(default=False, metadata={
        "help": "normalise observations by their running mean and std (kept in checkpoints)"})
    eval_every: int = field(default=100, metadata={"help": "updates between evaluations (and logged points)"})
    eval_attempts: int = field(default=10, metadata={"help": "sampled attempts per evaluation level"})
    checkpoint_every: int = field(default=500, metadata={
        "help": "updates between checkpoints (checkpoint.npz in the run folder)"})
    ppo: PPOConfig = field(default_factory=PPOConfig)
    buffer: BufferConfig = field(default_factory=BufferConfig)
    remidi: ReMiDiConfig = field(default_factory=ReMiDiConfig)
    accel: AccelConfig = field(default_factory=AccelConfig)
    paired: PairedConfig = field(default_factory=PairedConfig)
    sfl: SFLConfig = field(default_factory=SFLConfig)

    def __post_init__(self):
        # the learning-rate schedule spans the run: ppo.total_updates is always num_updates
        object.__setattr__(self, "ppo", dataclasses.replace(self.ppo, total_updates=self.num_updates))


DERIVED_KEYS = ("ppo.total_updates",)  # not settable: follows num_updates


def score_name(cfg: UEDConfig, algo) -> str:
    """The score ``algo`` ranks levels by under ``cfg``."""
    return algo.score_name(cfg.score)


def num_buffers(cfg: UEDConfig, algo) -> int:
    """K, the number of level buffers: ``remidi.num_buffers`` for a buffer sequence, else 1."""
    return cfg.remidi.num_buffers if algo.buffer_sequence else 1


def buffer_config(cfg: UEDConfig, algo) -> BufferConfig:
    """Each buffer's settings (a buffer sequence's buffers hold ``remidi.buffer_capacity``)."""
    if algo.buffer_sequence:
        return dataclasses.replace(cfg.buffer, capacity=cfg.remidi.buffer_capacity)
    return cfg.buffer
