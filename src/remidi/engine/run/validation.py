"""Validation of a run before anything is written: the task, every :class:`UEDConfig` key (one-line
ConfigError naming it), whether the network reads the observations, and warnings about valid
runs that would train degenerately."""

from __future__ import annotations

import dataclasses

import jax

from remidi.engine.adversaries import scores as sc
from remidi.engine.adversaries.paired import ESTIMATORS, GENERATOR_NETWORKS, OVERLAP_REGRETS, LevelGenerator
from remidi.engine.adversaries.plr import LevelBuffers
from remidi.engine.adversaries.sfl import LearnabilityBuffers
from remidi.engine.algorithms import ALGORITHMS, Algorithm, get_algorithm
from remidi.engine.adversaries.level_buffer import validate_buffer_config
from remidi.engine.config import (POLICIES, UEDConfig, buffer_config, score_name,
                                  validate_sfl_config)
from remidi.engine.core.ppo import validate_ppo_config
from remidi.engine.run.task_checks import check_network_reads_observations, step_reads_its_key, validate_task
from remidi.engine.setup import network_for
from remidi.engine.trackers import REPLAYING, tracker_advice, validate_tracker
from remidi.engine.trackers.exact import MODES as EXACT_MODES
from remidi.envs.interface import UEDTask, tree_equal
from remidi.errors import COMMAND_LINE, ConfigError, Naming, choice, positive_int, require


def run_warnings(cfg: UEDConfig, algos, task: UEDTask, check_step: bool = False,
                 num_steps_from: str | None = None, naming: Naming = COMMAND_LINE) -> list[str]:
    """One-line warnings about a valid run of ``algos`` (one, or a list: each warning once) that would
    train degenerately without saying so:

    * a score that needs finished episodes on rollouts shorter than the episode limit (such levels
      are scored as ``Score.unfinished`` says), with the ``--set`` that fixes it; ``num_steps_from``
      names who chose ``num_steps`` if not the user;
    * ReMiDi on a task whose reset depends on its key: the tracker assumes an episode is a function
      of level and actions, so identical levels may look distinguishable;
    * with ``check_step`` (costly to trace, so for users' tasks only): ReMiDi's exact tracker on a
      task whose step draws from its key, recommending the trackers that can read its observations.

    ``naming``: the caller's words for suggested settings."""
    algos = [get_algorithm(a) for a in ([algos] if isinstance(algos, (str, Algorithm)) else algos)]
    short = short_rollout_warning(cfg, algos, task, num_steps_from, naming)
    out = [short] if short is not None else []
    for algo in algos:
        out += _algorithm_warnings(cfg, algo, task, check_step, naming)
    return list(dict.fromkeys(out))  # one algorithm's warning said once, however many share it


def short_rollout_warning(cfg: UEDConfig, algos: list[Algorithm], task: UEDTask,
                          num_steps_from: str | None = None, naming: Naming = COMMAND_LINE) -> str | None:
    """:func:`run_warnings`' short-rollout line (naming each score's algorithms when several), or None."""
    if cfg.num_steps >= task.max_episode_steps:
        return None
    users: dict[str, list[str]] = {}  # score → the algorithms whose buffers it ranks
    for algo in algos:
        score = sc.SCORES[score_name(cfg, algo)]
        if algo.replays and score.needs_finished_episodes:
            users.setdefault(score.name, []).append(algo.name)
    if not users:
        return None
    scores = [sc.SCORES[name] for name in users]
    named = [f"{name} ({', '.join(names)})" if len(algos) > 1 else name for name, names in users.items()]
    if len(scores) == 1:
        head, fate = f"score {named[0]} uses", f"levels whose episode does not end {scores[0].unfinished}"
    else:
        head = f"scores {', '.join(named[:-1])} and {named[-1]} use"
        fate = "; ".join(f"with {s.name}, levels whose episode does not end {s.unfinished}" for s in scores)
    who = f", {num_steps_from}'s choice for a short run" if num_steps_from else ""
    others = [s.name for s in sc.SCORES.values() if not s.needs_finished_episodes]
    fix = (f"{naming.setting('num_steps', task.max_episode_steps)} (or more) scores every level by a finished episode"
           + (f", or {naming.setting('score', others[0])}" if others else ""))
    return (f"{head} the episodes that end inside a rollout, but num_steps ({cfg.num_steps}{who}) is shorter than "
            f"an episode can last ({task.max_episode_steps}): {fate}; {fix}")


def _algorithm_warnings(cfg: UEDConfig, algo: Algorithm, task: UEDTask, check_step: bool,
                        naming: Naming = COMMAND_LINE) -> list[str]:
    """:func:`run_warnings`' warnings about one algorithm (SFL's refresh, ReMiDi's tracker)."""
    out = []
    if isinstance(algo.adversary, LearnabilityBuffers) and cfg.sfl.rollout_steps < task.max_episode_steps:
        out.append(f"sfl.rollout_steps ({cfg.sfl.rollout_steps}) is shorter than an episode can last "
                   f"({task.max_episode_steps}): a candidate level none of whose episodes ends inside the refresh's "
                   f"rollout is never kept; raise sfl.rollout_steps")
    if algo.buffer_sequence and cfg.remidi.num_buffers > 1 and not task.deterministic_reset:
        level = task.sample_level(jax.random.PRNGKey(0))
        obs = [task.env.reset_to_level(jax.random.PRNGKey(k), level, task.params)[0] for k in (1, 2)]
        if not bool(tree_equal(obs[0], obs[1])):
            out.append("this task's reset depends on its random key (one level, two keys, two first "
                       "observations), but ReMiDi's tracker assumes an episode is a function of the level and the "
                       "actions; put the random seed into the level (UEDTask.deterministic_reset)")
    if check_step and algo.buffer_sequence and cfg.remidi.num_buffers > 1 \
            and cfg.remidi.tracker in EXACT_MODES and step_reads_its_key(task):
        advice = tracker_advice(task, naming)  # only trackers that can read the task's observations
        out.append("this task's env.step_env draws from its random key, but ReMiDi's exact tracker steps "
                   "each frozen level with the agent's own draws, so a prefix that another draw of a frozen level "
                   "would give counts as distinguishable; draw the step's randomness from a seed the level holds "
                   "(remidi.envs.noisy does; UEDTask.reseed_level redraws it)"
                   + (f" or {advice}" if advice else ""))
    return out


def rehearses(algo: Algorithm) -> bool:
    """``algo`` can take ``remidi.rehearsal``: a sequence of level buffers."""
    return isinstance(algo.adversary, LevelBuffers) and algo.buffer_sequence


def validate_section(prefix: str, validate) -> None:
    """Call ``validate()`` and re-raise its ConfigError with the keys' full names (``prefix`` + key)."""
    try:
        validate()
    except ConfigError as err:
        msg = str(err)
        raise ConfigError(msg if msg.startswith(prefix) else prefix + msg) from None


def task_refusal(algo: Algorithm, task: UEDTask) -> str | None:
    """Why ``task`` cannot run ``algo`` (missing mutator, level builder or solve criterion); None if it can."""
    if algo.edits and task.mutate_level is None:
        return f"{algo.name} edits levels, but this task has no level mutator (UEDTask.mutate_level)"
    if isinstance(algo.adversary, LevelGenerator) and task.level_builder is None:
        return (f"{algo.name} learns a level generator, but this task has no level-building MDP "
                f"(UEDTask.level_builder)")
    if isinstance(algo.adversary, LearnabilityBuffers) and task.solved is None:
        return (f"{algo.name} keeps the levels whose solve rate p maximises p(1 − p), but this task has no solve "
                f"criterion (UEDTask.solved)")
    return None


def validate_sfl(cfg: UEDConfig, algo: Algorithm, task: UEDTask) -> None:
    """ConfigError for an SFL run (``sfl``, ``remidi-sfl``) the task or keys refuse."""
    if task.solved is None:
        raise ConfigError(f"--algo: {task_refusal(algo, task)}; allowed: {', '.join(supported_algorithms(task))}")
    validate_section("sfl.", lambda: validate_sfl_config(cfg.sfl))
    s, capacity = cfg.sfl, algo.adversary.capacity(cfg)
    key = "remidi.buffer_capacity" if algo.buffer_sequence else "sfl.buffer_size"
    require(capacity <= s.batch_size * s.num_batches, key, f"at most sfl.batch_size × sfl.num_batches = "
            f"{s.batch_size} × {s.num_batches} (the candidates of a refresh)", capacity)
    r = cfg.remidi
    require(r.count == "updates", "remidi.count", "updates with SFL (every update trains on its buffer)", r.count)
    require(r.tracker in REPLAYING or not algo.buffer_sequence, "remidi.tracker", "prefix, per_step or tolerance "
            "with ReMiDi over SFL (a learned tracker learns from whole updates of the adversary's levels; SFL mixes "
            "them with fresh ones in every update)", r.tracker)


def supported_algorithms(task: UEDTask) -> list[str]:
    """The registered algorithms ``task`` can run, in order."""
    return [name for name, algo in ALGORITHMS.items() if task_refusal(algo, task) is None]


def validate_ued_config(cfg: UEDConfig, algo: str | Algorithm, task: UEDTask) -> None:
    """ConfigError (one line naming the key and what is allowed) for an invalid run."""
    algo = get_algorithm(algo)
    validate_task(task)
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
    require(isinstance(cfg.reseed, bool), "reseed", "true or false", cfg.reseed)
    require(not cfg.reseed or task.reseed_level is not None, "reseed", "false for a task without reseed_level (its "
            "levels carry no randomness of their own to draw afresh)", cfg.reseed)
    if isinstance(algo.adversary, LearnabilityBuffers):
        validate_sfl(cfg, algo, task)
    choice("score", cfg.score, sc.SCORES)
    score = sc.SCORES[score_name(cfg, algo)]
    for needed, what, has in (
            (score.needs_optimum, "the environment's optimal return, which this task does not provide "
                                  "(UEDTask.optimal_return)", task.optimal_return is not None),
            (score.needs_solved, "a solve criterion, which this task does not define (UEDTask.solved)",
             task.solved is not None)):
        if needed and not has:
            raise ConfigError(f"score: {score.name} needs {what}; allowed: {', '.join(sc.task_scores(task))}")
    require(isinstance(cfg.discounted_regret, bool), "discounted_regret", "true or false", cfg.discounted_regret)
    if score.needs_optimum and cfg.discounted_regret and task.optimal_discounted_return is None:
        raise ConfigError(f"discounted_regret: this task gives no discounted optimal return "
                          f"(UEDTask.optimal_discounted_return), so {score.name} cannot use the discounted utility; "
                          f"allowed: false (undiscounted returns on both sides)")
    for key in ("hidden_size", "lstm_size"):
        require(isinstance(getattr(cfg, key), int) and getattr(cfg, key) >= 0, key,
                "an integer ≥ 0 (0: the network's default)", getattr(cfg, key))
    require(cfg.reward_scale > 0, "reward_scale", "> 0", cfg.reward_scale)
    # the network kind first (default sizes), so a preset's hidden_size cannot hide that it cannot read the task
    check_network_reads_observations(network_for(dataclasses.replace(cfg, hidden_size=0, lstm_size=0), task),
                                     cfg.network, task, cfg.normalize_obs)
    network_for(cfg, task)  # ConfigError if the network has no layer for hidden_size / lstm_size
    r = cfg.remidi
    positive_int("remidi.num_buffers", r.num_buffers)
    positive_int("remidi.buffer_capacity", r.buffer_capacity)
    positive_int("remidi.steps_per_buffer", r.steps_per_buffer)
    choice("remidi.count", r.count, ("updates", "replays"))
    require(r.count == "updates" or algo.replays or not algo.buffer_sequence, "remidi.count", "updates with a "
            "learned generator (a generator never replays, so counting replays would never switch it)", r.count)
    validate_tracker(cfg, algo, task)
    choice("remidi.policy", r.policy, POLICIES)
    if r.policy == "combine":
        require(not cfg.normalize_obs, "remidi.policy", "masked with normalize_obs (the frozen policies would read "
                "observations normalised by statistics gathered after they were frozen)", r.policy)
    require(isinstance(r.rehearsal, (int, float)) and not isinstance(r.rehearsal, bool) and 0 <= r.rehearsal <= 1,
            "remidi.rehearsal", "a probability in [0, 1]", r.rehearsal)
    if r.rehearsal > 0:
        sequences = [a for a in ALGORITHMS if rehearses(ALGORITHMS[a])]
        if not rehearses(algo):
            raise ConfigError(f"remidi.rehearsal: {algo.name} has no sequence of level buffers to rehearse; allowed: 0, "
                              f"or a probability with the algorithm {' or '.join(sequences)}")
        require(r.policy == "masked", "remidi.policy", "masked with remidi.rehearsal (under combine the frozen "
                "policies act on the earlier buffers' levels, so the trained one never does)", r.policy)
    positive_int("accel.num_edits", cfg.accel.num_edits)
    require(isinstance(cfg.accel.easy_start, bool), "accel.easy_start", "true or false", cfg.accel.easy_start)
    if algo.edits and task.mutate_level is None:
        raise ConfigError(f"--algo: {task_refusal(algo, task)}; allowed: {', '.join(supported_algorithms(task))}")
    if algo.edits and cfg.accel.easy_start and task.easy_level is None:
        raise ConfigError("accel.easy_start: this task has no easy-level generator (UEDTask.easy_level); "
                          "allowed: false")
    if isinstance(algo.adversary, LevelGenerator):
        if task.level_builder is None:
            raise ConfigError(f"--algo: {task_refusal(algo, task)}; allowed: {', '.join(supported_algorithms(task))}")
        p = cfg.paired
        choice("paired.estimator", p.estimator, ESTIMATORS)
        if p.estimator == "perfect" and task.optimal_return is None:
            raise ConfigError("paired.estimator: perfect needs the task's optimal return (UEDTask.optimal_return); "
                              "allowed: paired, flexible")
        require(isinstance(p.clip_negative, bool), "paired.clip_negative", "true or false", p.clip_negative)
        choice("paired.generator_network", p.generator_network, GENERATOR_NETWORKS)
        positive_int("paired.generator_hidden", p.generator_hidden)
        require(p.generator_lr > 0, "paired.generator_lr", "> 0", p.generator_lr)
        require(p.generator_ent_coef >= 0, "paired.generator_ent_coef", "≥ 0", p.generator_ent_coef)
        choice("paired.overlap_regret", p.overlap_regret, OVERLAP_REGRETS)
        require(cfg.remidi.policy == "masked", "remidi.policy", "masked with a learned level generator (Combine "
                "over generators is not implemented)", cfg.remidi.policy)
    validate_section("ppo.", lambda: validate_ppo_config(cfg.ppo, cfg.num_envs))
    validate_section("buffer.", lambda: validate_buffer_config(cfg.buffer))
    validate_section("buffer.", lambda: validate_buffer_config(buffer_config(cfg, algo)))
    if algo.buffer_sequence:
        needed = (r.num_buffers - 1) * r.steps_per_buffer
        if needed >= cfg.num_updates:
            raise ConfigError(
                f"remidi.num_buffers: must be small enough that the last buffer gets updates, but "
                f"(num_buffers − 1) × steps_per_buffer = ({r.num_buffers} − 1) × {r.steps_per_buffer} = {needed} "
                f"is not below num_updates = {cfg.num_updates}; lower remidi.num_buffers or "
                f"remidi.steps_per_buffer, or raise num_updates")
