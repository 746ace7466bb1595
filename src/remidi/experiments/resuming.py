"""``remidi run --resume DIR``: continue a run from its folder (its config.json and last
checkpoint), one algorithm's or every unfinished one of a several-algorithm run, and read back
what a run folder records (:func:`saved_run`, :func:`finished_run`, :func:`result_from_files`)."""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path
from typing import Callable

import numpy as np

from remidi.errors import COMMAND_LINE, ConfigError, Naming
from remidi.experiments import outputs
from remidi.experiments.base import Experiment, RunResult, RunSpec
from remidi.experiments.overrides import config_from_dict
from remidi.experiments.running import _check_devices, _secondary_process, _train_and_write, write_run_config
from remidi.files import writable


def resume_experiment(exp_lookup: Callable[[str, dict | None], Experiment], folder: Path,
                      progress: bool = True, naming: Naming = COMMAND_LINE) -> dict[str, dict]:
    """Continue the run in ``folder`` from its last checkpoint. ``exp_lookup(name, task)``: the
    experiment of ``config.json``'s ``experiment`` and ``task`` (:func:`remidi.experiments.saved_experiment`).

    ``folder`` is one algorithm's run, or a several-algorithm run whose unfinished algorithms are
    resumed before the comparison plots are redrawn. The recorded ``devices`` are kept. A finished
    run is checked and returned as it is. ``naming``: the caller's words in errors."""
    folder = Path(folder)
    if _secondary_process(_saved_devices(folder)):  # only process 0 writes the run folder; the others
        with tempfile.TemporaryDirectory(prefix="remidi-process-") as scratch:  # resume a scratch copy of it
            shutil.copytree(folder, Path(scratch) / "run")
            return _resume(exp_lookup, Path(scratch) / "run", progress=False, notes=False, naming=naming)
    if not folder.is_dir():  # _resume says what is wrong
        return _resume(exp_lookup, folder, progress, naming=naming)
    # one process writes a run at a time; one algorithm of a several-algorithm run locks the whole run
    part_of = (folder / "config.json").exists() and outputs.several_algorithm_run(folder.parent)
    with outputs.folder_lock(folder.parent if part_of else folder, naming.resume):
        return _resume(exp_lookup, folder, progress, naming=naming)


def finished_run(folder: Path) -> bool:
    """Whether ``folder``'s run is finished: its summary.json (every algorithm's) is written."""
    folder = Path(folder)
    if (folder / "config.json").exists():
        return (folder / "summary.json").exists()
    subs = [p for p in folder.iterdir() if (p / "config.json").exists()] if folder.is_dir() else []
    return (bool(subs) and all((p / "summary.json").exists() for p in subs)
            and not _missing_algorithms(folder, subs))


def _missing_algorithms(folder: Path, subs: list[Path]) -> list[str]:
    """The algorithms a several-algorithm run's config.json files list that have no sub-folder with
    a config.json (a run stopped while writing them, before training). None for a folder of separate
    runs, or a damaged config.json (resuming says what is wrong)."""
    if not outputs.several_algorithm_run(folder):
        return []
    algos = outputs.read_json(subs[0] / "config.json").get("algos") or []
    return [a for a in algos if isinstance(a, str) and a and Path(a).name == a
            and not (folder / a / "config.json").exists()]


def _write_missing_configs(exp_lookup, folder: Path, subs: list[Path], naming: Naming) -> list[Path]:
    """Write the config.json of :func:`_missing_algorithms` from one that was written (the
    algorithms share all but ``algo``), so --resume trains them; returns their sub-folders."""
    missing = _missing_algorithms(folder, subs)
    if not missing:
        return []
    exp, _, preset, seeds, config = saved_run(exp_lookup, subs[0], naming.resume)
    saved = outputs.read_json(subs[0] / "config.json")
    command = saved.get("command") if isinstance(saved.get("command"), list) else ["remidi"]
    made = []
    for algo in missing:
        sub = outputs.prepare_out_dir(folder / algo, naming=naming)
        spec = RunSpec(exp, saved["algos"], preset, seeds, devices=_saved_devices(subs[0]),
                       log=_saved_log(subs[0], naming.resume), argv=command[1:])
        write_run_config(sub, spec, algo, config)
        made.append(sub)
    return made


def _resume(exp_lookup: Callable[[str, dict | None], Experiment], folder: Path, progress: bool,
            notes: bool = True, naming: Naming = COMMAND_LINE) -> dict[str, dict]:
    """Resume ``folder`` (:func:`resume_experiment`); ``notes``: say which runs have no checkpoint
    yet (process 0 only)."""
    flag = naming.resume
    if not (folder / "config.json").exists() and folder.is_dir():
        subs = sorted(p for p in folder.iterdir() if (p / "config.json").exists())
        if subs and not outputs.several_algorithm_run(folder):
            raise ConfigError(f"{flag}: {folder} holds separate runs, not one several-algorithm run; resume each "
                              f"(e.g. {naming.resuming(subs[0])})")
        if subs:
            subs = sorted(subs + _write_missing_configs(exp_lookup, folder, subs, naming))
            return _resume_several(exp_lookup, folder, subs, progress, notes, naming)
    folder = outputs.prepare_out_dir(folder, resume=True, naming=naming)
    exp, algo, preset, seeds, config = saved_run(exp_lookup, folder, flag)
    devices = _saved_devices(folder)
    _check_devices(exp, devices, len(seeds))
    if finished_run(folder):  # nothing to train: its results as they are (a rerun would overwrite wall_s)
        return {algo: _finished_summary(folder, naming)}
    _check_writable(folder, flag)
    outputs.remove_stale_temporaries(folder)
    if notes:
        _note_fresh_start(exp, folder)
    spec = RunSpec(exp, [algo], preset, seeds, devices=devices, log=_saved_log(folder, flag), naming=naming)
    return _train_and_write(spec, config, {algo: folder}, folder, resume=True, progress=progress)


def _note_fresh_start(exp: Experiment, folder: Path) -> None:
    """Say so when the UED run in ``folder`` has no checkpoint yet: --resume trains it from the start."""
    from remidi.engine.run.checkpoint import CHECKPOINT

    if exp.make_task is not None and not (folder / CHECKPOINT).exists():
        print(f"remidi: note: {folder} has no checkpoint yet (the run stopped before its first); "
              f"it trains from its start", file=sys.stderr, flush=True)


def _check_writable(folder: Path, flag: str = "--resume") -> None:
    """ConfigError (one line) for a run folder to resume that cannot be written, before any training."""
    if not writable(folder):
        raise ConfigError(f"{flag}: {folder} is not writable: the resumed run could not write its checkpoints "
                          f"and results; resume a writable copy of it")


def _finished_summary(folder: Path, naming: Naming = COMMAND_LINE) -> dict:
    """A finished run's summary.json, checked: a damaged one is a one-line error."""
    return outputs.read_json_object(folder / "summary.json", naming.resume,
                                    f"; delete it, and {naming.resumes} writes the run's outputs again from "
                                    f"checkpoint.npz")


def _saved_log(folder: Path, flag: str = "--resume") -> list[str]:
    """The tracking backends recorded in ``folder/config.json``, checked again (a missing package is
    said before anything is written)."""
    from remidi.loggers import parse_log

    saved = outputs.read_json(folder / "config.json").get("log") or []
    if not isinstance(saved, list) or not all(isinstance(name, str) for name in saved):
        raise ConfigError(f"{flag}: {folder / 'config.json'}: log must be a list of backend names, got {saved!r}")
    return parse_log(",".join(saved))


def saved_run(exp_lookup, folder: Path, flag: str = "--resume"):
    """``(experiment, algo, preset, seeds, config)`` of the run recorded in ``folder/config.json``;
    ConfigError (one line, starting with ``flag`` and naming the file) when it is unreadable or
    incomplete."""
    path = folder / "config.json"
    try:
        saved = outputs.read_json(path)
        exp = exp_lookup(saved["experiment"], saved.get("task"))
        config = config_from_dict(type(exp.config_factory()), saved["config"])
        algo, preset, seeds = saved["algo"], saved["preset"], saved["seeds"]
        if not (isinstance(seeds, list) and seeds and all(isinstance(s, int) and s >= 0 for s in seeds)):
            raise ValueError(f"seeds must be a list of integers ≥ 0, got {seeds!r}")
    except ConfigError as err:
        raise ConfigError(f"{flag}: {path}: {err}") from None
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
        what = f"no {err}" if isinstance(err, KeyError) else (str(err).strip().splitlines() or [""])[0]
        raise ConfigError(f"{flag}: {path} is not a readable run config ({type(err).__name__}: {what})") from None
    _check_registered(exp, algo, config, f"{flag}: {path}")
    exp.validate(config, algo)
    return exp, algo, preset, seeds, config


def _check_registered(exp: Experiment, algo: str, config, where: str) -> None:
    """ConfigError unless the saved algorithm, (UED) score and network are known to this process
    (a plugin's must be loaded again)."""
    hint = "registered by a plugin? load it again: REMIDI_PLUGINS=module (docs/extending.md)"
    if algo not in exp.algorithms:
        raise ConfigError(f"{where}: the run's algorithm {algo!r} is unknown here ({hint}); "
                          f"allowed: {', '.join(exp.algorithms)}")
    score = getattr(config, "score", None)
    if exp.make_task is not None and isinstance(score, str):
        from remidi.engine.adversaries.scores import SCORES

        if score not in SCORES:
            raise ConfigError(f"{where}: the run's score {score!r} is unknown here ({hint}); "
                              f"allowed: {', '.join(SCORES)}")
    network = getattr(config, "network", None)
    if exp.make_task is not None and isinstance(network, str):
        from remidi.engine.core.networks import NETWORKS

        if network not in NETWORKS:
            raise ConfigError(f"{where}: the run's network {network!r} is unknown here ({hint}); "
                              f"allowed: {', '.join(NETWORKS)}")


def _saved_devices(folder: Path):
    """``devices`` of the run in ``folder`` (1 when unrecorded or unreadable); of a several-algorithm
    folder, the largest."""
    folder = Path(folder)
    try:
        paths = [folder / "config.json"] if (folder / "config.json").exists() else sorted(folder.glob("*/config.json"))
        return max((outputs.read_json(path).get("devices", 1) for path in paths), default=1)
    except (OSError, ValueError, AttributeError, TypeError):
        return 1


def _run_order(sub: Path, exp: Experiment, algo: str) -> tuple[int, int]:
    """Where ``algo`` stands in its several-algorithm run: the user's order (``algos``), then the
    experiment's, so a resumed run plots like a fresh one."""
    saved = outputs.read_json(sub / "config.json").get("algos") or []
    given = saved.index(algo) if algo in saved else len(saved)
    return given, exp.algorithms.index(algo) if algo in exp.algorithms else len(exp.algorithms)


def _resume_several(exp_lookup, folder: Path, subs: list[Path], progress: bool, notes: bool,
                    naming: Naming = COMMAND_LINE) -> dict[str, dict]:
    flag = naming.resume
    runs = [(sub, *saved_run(exp_lookup, sub, flag)) for sub in subs]
    runs.sort(key=lambda run: _run_order(run[0], run[1], run[2]))
    devices = {sub: _saved_devices(sub) for sub in subs}
    logs = {sub: _saved_log(sub, flag) for sub in subs}
    for sub, exp, algo, preset, seeds, config in runs:  # every run checked before any trains
        _check_devices(exp, devices[sub], len(seeds))
    summaries = {}
    unfinished = [run for run in runs if not (run[0] / "summary.json").exists()]
    for sub in [folder, *(run[0] for run in unfinished)] if unfinished else []:
        _check_writable(sub, flag)
        outputs.remove_stale_temporaries(sub)

    def compare(last: dict[str, RunResult]) -> None:  # with the last unfinished algorithm's result, before its summary
        exp, preset, seeds, config = runs[0][1], runs[0][3], runs[0][4], runs[0][5]
        exp.plot(folder, {algo: last[algo] if algo in last else result_from_files(sub) for sub, _, algo, *_ in runs},
                 config, preset=preset, seeds=seeds)

    for sub, exp, algo, preset, seeds, config in runs:  # nothing trained (finished): the folder stays as it is
        if (sub / "summary.json").exists():
            summaries[algo] = _finished_summary(sub, naming)
        else:
            if notes:
                _note_fresh_start(exp, sub)
            spec = RunSpec(exp, [algo], preset, seeds, devices=devices[sub], log=logs[sub], naming=naming)
            summaries.update(_train_and_write(spec, config, {algo: sub}, sub, resume=True, progress=progress,
                                              compare=compare if sub == unfinished[-1][0] else None))
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
