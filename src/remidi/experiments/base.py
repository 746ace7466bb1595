"""The experiment contract: what every ``remidi run`` goes through.

An :class:`Experiment` names its algorithms and presets, builds and validates its configuration,
trains one algorithm over seeds (a :class:`RunResult`) and plots; a :class:`RunSpec` is one run of
it. :mod:`~remidi.experiments.running` trains a fresh run, :mod:`~remidi.experiments.resuming`
continues one."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from remidi.errors import COMMAND_LINE, ConfigError, Naming, one_of
from remidi.experiments.overrides import apply_overrides, scale_dependents


@dataclass
class RunResult:
    """What training one algorithm for all seeds produced: ``history[name]`` f[S, T] at ``steps``
    i[T]; ``final[name]`` f[S] (default: the last history entry); ``extra``: more summary.json keys."""

    steps: np.ndarray
    history: dict[str, np.ndarray]
    final: dict[str, np.ndarray] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)

    def final_metrics(self) -> dict[str, np.ndarray]:
        if self.final:
            return self.final
        return {name: np.asarray(v)[:, -1] for name, v in self.history.items()}


@dataclass
class RunContext:
    experiment: str
    algo: str
    preset: str
    seeds: list[int]
    config: Any
    out: Path
    resume: bool = False
    progress: bool = True
    devices: int = 1  # devices the seeds are sharded over (experiments with shards_seeds)
    # called as each block of training finishes: (step, {metric: f[S]}), for experiment tracking;
    # experiments that train in one piece (the tabular games) never call it
    on_block: Callable[[int, dict], None] | None = None
    naming: Naming = COMMAND_LINE  # the caller's words, for the notes training says (the run's RunSpec.naming)


@dataclass(frozen=True)
class Experiment:
    name: str
    description: str
    algorithms: tuple[str, ...]
    config_factory: Callable[[], Any]
    presets: dict[str, dict[str, Any]]  # preset name → overrides of the paper defaults
    preset_seeds: dict[str, int]  # default number of seeds per preset
    validate: Callable[[Any, str], None]  # (config, algo) → raise ConfigError
    train: Callable[[RunContext], RunResult]
    # (folder, {algo: result}, config, preset=..., seeds=...): the preset and seeds the run was given,
    # named in the figures
    plot: Callable[..., None]
    # length key → keys measured against it, scaled in proportion when only the length is set
    # (config.scale_dependents), e.g. {"num_updates": ("eval_every", ...)}
    scaled_keys: dict[str, tuple[str, ...]] = field(default_factory=dict)
    # scaled keys that must divide their length (block lengths: a short last block compiles again)
    divisor_keys: tuple[str, ...] = ()
    # scaled key → the least it is scaled to (never above the new length), e.g. {"eval_every": 10}: a
    # short run still evaluates every 10 updates, not every one
    scale_floors: dict[str, int] = field(default_factory=dict)
    # (config, --set overrides, the caller's Naming) → one line a fresh run says first (None: nothing
    # to say), e.g. the defaults an import-path task's run derived from what the task provides
    config_note: Callable[[Any, dict, Naming], str | None] | None = None
    # (config, overrides) → the config with the keys the experiment derives from others (an import-path
    # task's buffer sizes and schedule, from num_updates, num_envs, ...) recomputed where the overrides
    # leave them alone; None: nothing is derived
    derive_config: Callable[[Any, dict], Any] | None = None
    # (config, algo) → one line stating the budget ``algo`` gets (its buffers, schedule, score), said at
    # the start of a fresh run, one line per algorithm; None: not said
    budget_line: Callable[[Any, str], str | None] | None = None
    shards_seeds: bool = False  # train honours RunContext.devices (remidi run --devices N)
    # preset → {key: why it deviates from the paper}: shown by `remidi list` for presets that stand
    # in for the paper's at a smaller scale (e.g. cpu)
    preset_reasons: dict[str, dict[str, str]] = field(default_factory=dict)
    # lines `remidi list NAME` prints after the presets: what a user must know to read the results
    # page's runs of this experiment (e.g. a setting its claims use that is not the default)
    notes: tuple[str, ...] = ()
    # config → the UEDTask a run of this experiment trains on (UED experiments; None for the tabular
    # games): for tools that reload a run's agent (remidi evaluate)
    make_task: Callable[[Any], Any] | None = None
    # history → more history: the metrics a run derives from those it logs (f[S, T] each, e.g. the
    # mean solve rate over held-out sets), for tools that read a run's history (the results page)
    derive: Callable[[dict], dict] | None = None
    # what `remidi run` trains without --algo (None: every algorithm); --algo all trains every one
    default_algorithms: tuple[str, ...] | None = None
    # a user's task given by import path: {"import": "module:function", "folder": the folder it is
    # imported from}, recorded in config.json so that --resume and evaluate rebuild it from anywhere
    task_ref: dict[str, Any] | None = None
    # config → the level scores (``--set score=NAME``) its task can use, those whose needs it meets
    # (remidi list NAME; UED experiments); None: the experiment has no level scores
    scores: Callable[[Any], list[str]] | None = None
    # (RunSpec, config) → one-line warnings about a valid run that would train degenerately, said
    # once at the start of a fresh run for all its algorithms (UED experiments: the engine's
    # run_warnings); None: nothing to check
    run_warnings: Callable[[Any, Any], list[str]] | None = None


@dataclass(frozen=True)
class RunSpec:
    """One run of an experiment, as ``remidi run`` or ``run_ued`` asks for it: the algorithms in the
    order given, the preset and ``--set`` overrides, the seeds, the devices they shard over, the logging
    backends, the command config.json records (None: this process's) and ``naming``, the caller's
    words in messages (:class:`~remidi.errors.Naming`)."""

    exp: Experiment
    algos: list[str]
    preset: str
    seeds: list[int]
    overrides: dict[str, Any] = field(default_factory=dict)
    devices: int = 1
    log: list[str] = field(default_factory=list)
    argv: list[str] | None = None
    naming: Naming = COMMAND_LINE


def default_preset(exp: Experiment) -> str:
    """``smoke`` where the experiment has it (every built-in one), else its first preset."""
    return "smoke" if "smoke" in exp.presets else next(iter(exp.presets))


def resolve_config(exp: Experiment, preset: str, overrides: dict[str, Any], notes: list[str] | None = None,
                   naming: Naming = COMMAND_LINE):
    """The preset's configuration with ``overrides`` on top; keys depending on a changed length
    (``exp.scaled_keys``) are scaled in proportion, said in a line appended to ``notes``."""
    if preset not in exp.presets:
        raise one_of("--preset", preset, exp.presets)
    base = apply_overrides(exp.config_factory(), exp.presets[preset], source=f"preset {preset}")
    config, note = scale_dependents(apply_overrides(base, overrides, source=naming.overrides), base, overrides,
                                    exp.scaled_keys, exp.divisor_keys, exp.scale_floors, naming.where_set)
    if exp.derive_config is not None:
        config = exp.derive_config(config, overrides)
    said = exp.config_note(config, overrides, naming) if exp.config_note is not None else None
    if notes is not None:
        notes.extend(line for line in (said, note) if line is not None)
    return config


def parse_algos(exp: Experiment, text: str | None, key: str = "--algo") -> list[str]:
    """The algorithms ``text`` names (comma-separated, or ``all``; None: the experiment's default
    ones); ConfigError (one line, starting with ``key``, the caller's name for them) otherwise."""
    if text is None:
        return list(exp.default_algorithms or exp.algorithms)
    if text == "all":
        return list(exp.algorithms)
    algos = [a.strip() for a in text.split(",")]
    if not any(algos):
        raise one_of(key, text, exp.algorithms)
    if not all(algos):
        raise ConfigError(f"{key}: {text!r} has an empty name; give algorithms separated by single commas "
                          f"(allowed: {', '.join(exp.algorithms + ('all',))})")
    for algo in algos:
        if algo not in exp.algorithms:
            why = exp.algorithms.refusal(algo) if hasattr(exp.algorithms, "refusal") else None
            if why is not None:
                raise ConfigError(f"{key}: {algo} cannot run on {exp.name}: {why}; "
                                  f"allowed: {', '.join(exp.algorithms + ('all',))}")
            raise one_of(key, algo, exp.algorithms + ("all",))
    if len(set(algos)) != len(algos):
        raise ConfigError(f"{key}: {text!r} names an algorithm twice")
    return algos


MAX_SEED = 2**32 - 1  # jax.random.PRNGKey takes 32-bit seeds
