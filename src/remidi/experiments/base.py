"""The experiment contract and the driver that every ``remidi run`` goes through.

An :class:`Experiment` says which algorithms and presets it has, how to build and validate its
configuration, how to train one algorithm for a set of seeds (returning a :class:`RunResult`)
and how to plot results. :func:`run_experiment` does the rest identically for all of them:
validate everything before writing anything, write ``config.json`` first (so a killed run can
be resumed), then ``metrics.csv``, ``summary.json`` and the plots.

With several algorithms, each gets a sub-folder ``OUT/<algo>/`` and the comparison plots (one
panel per algorithm) go to ``OUT/``; with one, everything goes to ``OUT/`` directly.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from remidi import __version__
from remidi.errors import ConfigError, one_of
from remidi.experiments import outputs
from remidi.experiments.config import apply_overrides, config_from_dict, config_to_dict


@dataclass
class RunResult:
    """What training one algorithm for all seeds produced.

    ``history[name]`` f[S, T] at ``steps`` i[T]; ``final[name]`` f[S] (defaults to the last
    history entry); ``extra`` goes into summary.json as additional top-level keys.
    """

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
    plot: Callable[[Path, dict[str, RunResult], Any], None]  # (folder, {algo: result}, config)


def resolve_config(exp: Experiment, preset: str, overrides: dict[str, Any]):
    if preset not in exp.presets:
        raise one_of("--preset", preset, exp.presets)
    config = apply_overrides(exp.config_factory(), exp.presets[preset], source=f"preset {preset}")
    return apply_overrides(config, overrides)


def parse_algos(exp: Experiment, text: str | None) -> list[str]:
    if text is None or text == "all":
        return list(exp.algorithms)
    algos = [a.strip() for a in text.split(",") if a.strip()]
    if not algos:
        raise one_of("--algo", text, exp.algorithms)
    for algo in algos:
        if algo not in exp.algorithms:
            raise one_of("--algo", algo, exp.algorithms + ("all",))
    if len(set(algos)) != len(algos):
        raise ConfigError(f"--algo: {text!r} names an algorithm twice")
    return algos


def run_experiment(exp: Experiment, *, algos: list[str], preset: str, seeds: list[int],
                   overrides: dict[str, Any], out: Path, progress: bool = True,
                   argv: list[str] | None = None) -> dict[str, dict]:
    """Validate, train every algorithm, write all outputs; return ``{algo: summary}``."""
    config = resolve_config(exp, preset, overrides)
    for algo in algos:
        exp.validate(config, algo)
    if not seeds:
        raise ConfigError("--seeds: must be an integer ≥ 1")
    out = Path(out)
    folders = {algo: (out / algo if len(algos) > 1 else out) for algo in algos}
    for folder in dict.fromkeys([out, *folders.values()]):  # check every folder before writing anything
        outputs.prepare_out_dir(folder, create=False)
    for algo, folder in folders.items():
        outputs.prepare_out_dir(folder)
        write_run_config(folder, exp, algo, preset, seeds, config, argv)
    return _train_and_write(exp, folders, preset, seeds, config, out, resume=False, progress=progress)


def resume_experiment(exp_lookup: Callable[[str], Experiment], folder: Path, progress: bool = True) -> dict[str, dict]:
    """Continue the run in ``folder`` from its last checkpoint.

    ``folder`` is one algorithm's run (it holds config.json), or the folder of a several-algorithm
    run, whose unfinished algorithms (no summary.json) are resumed before the comparison plots
    are redrawn.
    """
    folder = Path(folder)
    if not (folder / "config.json").exists() and folder.is_dir():
        subs = sorted(p for p in folder.iterdir() if (p / "config.json").exists())
        if subs:
            return _resume_several(exp_lookup, folder, subs, progress)
    folder = outputs.prepare_out_dir(folder, resume=True)
    exp, algo, preset, seeds, config = _saved_run(exp_lookup, folder)
    return _train_and_write(exp, {algo: folder}, preset, seeds, config, folder, resume=True, progress=progress)


def _saved_run(exp_lookup, folder: Path):
    saved = outputs.read_json(folder / "config.json")
    exp = exp_lookup(saved["experiment"])
    config = config_from_dict(type(exp.config_factory()), saved["config"])
    exp.validate(config, saved["algo"])
    return exp, saved["algo"], saved["preset"], saved["seeds"], config


def _resume_several(exp_lookup, folder: Path, subs: list[Path], progress: bool) -> dict[str, dict]:
    runs = [(sub, *_saved_run(exp_lookup, sub)) for sub in subs]
    summaries = {}
    for sub, exp, algo, preset, seeds, config in runs:
        if (sub / "summary.json").exists():
            summaries[algo] = outputs.read_json(sub / "summary.json")
        else:
            summaries.update(_train_and_write(exp, {algo: sub}, preset, seeds, config, sub, resume=True,
                                              progress=progress))
    exp, config = runs[0][1], runs[0][5]
    results = {algo: result_from_files(sub) for sub, _, algo, *_ in runs}
    exp.plot(folder, results, config)
    return summaries


def result_from_files(folder: Path) -> RunResult:
    """Rebuild a :class:`RunResult` from a finished run's metrics.csv and summary.json."""
    rows = outputs.read_metrics_csv(folder / "metrics.csv")
    summary = outputs.read_json(folder / "summary.json")
    seeds = summary["seeds"]
    steps = sorted({step for _, step, _, _ in rows})
    names = list(dict.fromkeys(name for _, _, name, _ in rows))
    history = {name: np.full((len(seeds), len(steps)), np.nan) for name in names}
    seed_index, step_index = {s: i for i, s in enumerate(seeds)}, {s: i for i, s in enumerate(steps)}
    for seed, step, name, value in rows:
        history[name][seed_index[seed], step_index[step]] = value
    extra = {k: v for k, v in summary.items() if k not in ("experiment", "algo", "preset", "seeds", "metrics")}
    return RunResult(steps=np.asarray(steps), history=history, extra=extra)


def write_run_config(folder: Path, exp: Experiment, algo: str, preset: str, seeds: list[int], config, argv) -> None:
    outputs.write_json(folder / "config.json", {
        "experiment": exp.name,
        "algo": algo,
        "preset": preset,
        "seeds": seeds,
        "config": config_to_dict(config),
        "command": ["remidi", *(argv if argv is not None else sys.argv[1:])],
        "remidi_version": __version__,
    })


def _train_and_write(exp, folders, preset, seeds, config, out, *, resume, progress):
    results: dict[str, RunResult] = {}
    summaries: dict[str, dict] = {}
    for algo, folder in folders.items():
        ctx = RunContext(exp.name, algo, preset, seeds, config, folder, resume=resume, progress=progress)
        result = exp.train(ctx)
        results[algo] = result
        outputs.write_metrics_csv(folder / "metrics.csv", outputs.metric_rows(result.steps, result.history, seeds))
        summaries[algo] = outputs.write_summary(
            folder / "summary.json", experiment=exp.name, algo=algo, preset=preset, seeds=seeds,
            final=result.final_metrics(), **result.extra)
        exp.plot(folder, {algo: result}, config)
    if len(folders) > 1:
        exp.plot(out, results, config)
    return summaries
