"""The experiment contract and the driver that every ``remidi run`` goes through.

An :class:`Experiment` says which algorithms and presets it has, how to build and validate its
configuration, how to train one algorithm for a set of seeds (returning a :class:`RunResult`)
and how to plot results. :func:`run_experiment` does the rest identically for all of them:
validate everything before writing anything, write ``config.json`` first (so a killed run can
be resumed), then ``metrics.csv``, ``summary.json`` and the plots. A UED run whose rollouts alone
cannot fit the device's memory is refused with the rest of the input (:func:`_check_memory`, a
lower bound); one that runs out of memory all the same (XLA's ``RESOURCE_EXHAUSTED`` at
allocation or compilation, MemoryError: :class:`TooLarge`) is one line naming ``num_envs``; a
fresh run then removes the files and folders it made (resuming would fail the same way), keeping
what was there before and the algorithms that finished; a resumed one leaves its folder as it is.

With several algorithms, each gets a sub-folder ``OUT/<algo>/`` and the comparison plots (one
panel per metric, one curve per algorithm, in the order given; tabular: one panel per algorithm)
go to ``OUT/``; with one, everything goes to ``OUT/`` directly.

``devices`` (``remidi run --devices N``, recorded in ``config.json`` and reused by ``--resume``)
shards the seeds over N devices for the experiments that support it (``Experiment.shards_seeds``;
``docs/devices.md``). In a multi-process JAX run only process 0 writes the run folder.
"""

from __future__ import annotations

import os
import re
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from remidi import __version__
from remidi.errors import ConfigError, one_of
from remidi.files import code_version, writable
from remidi.experiments import outputs
from remidi.experiments.config import apply_overrides, config_from_dict, config_to_dict, scale_dependents


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
    devices: int = 1  # devices the seeds are sharded over (experiments with shards_seeds)
    # called as each block of training finishes: (step, {metric: f[S]}), for experiment tracking;
    # experiments that train in one piece (the tabular games) never call it
    on_block: Callable[[int, dict], None] | None = None


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
    shards_seeds: bool = False  # train honours RunContext.devices (remidi run --devices N)
    # preset → {key: why it deviates from the paper}: shown by `remidi list` for presets that stand
    # in for the paper's at a smaller scale (e.g. cpu)
    preset_reasons: dict[str, dict[str, str]] = field(default_factory=dict)
    # config → the UEDTask a run of this experiment trains on (UED experiments; None for the tabular
    # games): for tools that reload a run's agent (remidi evaluate)
    make_task: Callable[[Any], Any] | None = None
    # what `remidi run` trains without --algo (None: every algorithm); --algo all trains every one
    default_algorithms: tuple[str, ...] | None = None
    # a user's task given by import path: {"import": "module:function", "folder": the folder it is
    # imported from}, recorded in config.json so that --resume and evaluate rebuild it from anywhere
    task_ref: dict[str, Any] | None = None


def default_preset(exp: Experiment) -> str:
    """``smoke`` where the experiment has it (every built-in one), else its first preset."""
    return "smoke" if "smoke" in exp.presets else next(iter(exp.presets))


def resolve_config(exp: Experiment, preset: str, overrides: dict[str, Any], notes: list[str] | None = None):
    """The preset's configuration with ``overrides`` on top; keys that depend on a length the
    overrides change (``exp.scaled_keys``) and that they leave alone are scaled in proportion,
    and a line saying so is appended to ``notes``."""
    if preset not in exp.presets:
        raise one_of("--preset", preset, exp.presets)
    base = apply_overrides(exp.config_factory(), exp.presets[preset], source=f"preset {preset}")
    config, note = scale_dependents(apply_overrides(base, overrides), base, overrides, exp.scaled_keys,
                                    exp.divisor_keys)
    if note is not None and notes is not None:
        notes.append(note)
    return config


def parse_algos(exp: Experiment, text: str | None) -> list[str]:
    if text is None:
        return list(exp.default_algorithms or exp.algorithms)
    if text == "all":
        return list(exp.algorithms)
    algos = [a.strip() for a in text.split(",")]
    if not any(algos):
        raise one_of("--algo", text, exp.algorithms)
    if not all(algos):
        raise ConfigError(f"--algo: {text!r} has an empty name; give algorithms separated by single commas "
                          f"(allowed: {', '.join(exp.algorithms + ('all',))})")
    for algo in algos:
        if algo not in exp.algorithms:
            why = exp.algorithms.refusal(algo) if hasattr(exp.algorithms, "refusal") else None
            if why is not None:
                raise ConfigError(f"--algo: {algo} cannot run on {exp.name}: {why}; "
                                  f"allowed: {', '.join(exp.algorithms + ('all',))}")
            raise one_of("--algo", algo, exp.algorithms + ("all",))
    if len(set(algos)) != len(algos):
        raise ConfigError(f"--algo: {text!r} names an algorithm twice")
    return algos


MAX_SEED = 2**32 - 1  # jax.random.PRNGKey takes 32-bit seeds


def run_experiment(exp: Experiment, *, algos: list[str], preset: str, seeds: list[int],
                   overrides: dict[str, Any], out: Path, progress: bool = True,
                   argv: list[str] | None = None, devices: int = 1, log: list[str] | None = None) -> dict[str, dict]:
    """Validate, train every algorithm, write all outputs; return ``{algo: summary}``.

    ``devices``: shard the seeds over that many devices (:func:`_check_devices`). ``log``: the
    experiment-tracking backends (:mod:`remidi.experiments.tracking`, checked by its ``parse_log``)."""
    notes: list[str] = []
    config = resolve_config(exp, preset, overrides, notes)
    for algo in algos:
        exp.validate(config, algo)
    if not seeds:
        raise ConfigError("--seeds: must be an integer ≥ 1")
    if min(seeds) < 0 or max(seeds) > MAX_SEED:
        raise ConfigError(f"--seed: every seed must be in [0, {MAX_SEED}] (a 32-bit random key), got "
                          f"{min(seeds)}..{max(seeds)}; lower --seed or --seeds")
    _check_devices(exp, devices, len(seeds))
    _check_memory(exp, config, len(seeds), devices)
    if _secondary_process(devices):  # only process 0 writes OUT; the others train alongside it (the
        with tempfile.TemporaryDirectory(prefix="remidi-process-") as scratch:  # mesh spans them) into scratch
            return _write_and_train(exp, algos, preset, seeds, config, Path(scratch) / "run", [], False, argv, devices)
    return _write_and_train(exp, algos, preset, seeds, config, Path(out), notes, progress, argv, devices, log or [])


def _write_and_train(exp, algos, preset, seeds, config, out: Path, notes, progress, argv, devices,
                     log: list[str] = ()) -> dict[str, dict]:
    folders = {algo: (out / algo if len(algos) > 1 else out) for algo in algos}
    for folder in dict.fromkeys([out, *folders.values()]):  # check every folder before writing anything
        outputs.prepare_out_dir(folder, create=False)
    for note in notes:  # only once the run is known to be valid: an error stays the only line
        print(f"remidi: {note}", file=sys.stderr, flush=True)
    before = _existing_paths(out, list(folders.values()))
    try:
        outputs.prepare_out_dir(out)
        with outputs.folder_lock(out, "--out"):
            for folder in dict.fromkeys([out, *folders.values()]):  # again: a run another process began here since
                outputs.prepare_out_dir(folder, create=False)
            for algo, folder in folders.items():
                outputs.prepare_out_dir(folder)
                write_run_config(folder, exp, algo, preset, seeds, config, argv, devices=devices,
                                 algos=list(folders), log=list(log))
            return _train_and_write(exp, folders, preset, seeds, config, out, resume=False, progress=progress,
                                    devices=devices, log=list(log))
    except TooLarge as err:  # resuming would fail the same way: remove what this run wrote, keep finished algorithms
        finished = [algo for algo, folder in folders.items() if (folder / "summary.json").exists()]
        _remove_new_paths(out, [folders[algo] for algo in folders if algo not in finished], before)
        kept = f" (kept the finished {', '.join(finished)} in {out})" if finished else ""
        raise TooLarge(f"{err}; removed what this run wrote{kept}") from None


class TooLarge(ConfigError):
    """The run does not fit the device: XLA ran out of memory (``RESOURCE_EXHAUSTED``), NumPy raised
    MemoryError, or an array outgrew XLA's 32-bit indices."""


def too_large_message(err: BaseException, config) -> str | None:
    """One line for an error that says the run is too large for the device, naming ``num_envs``
    (the usual culprit) and the size XLA asked for; None for any other error."""
    text = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
    if isinstance(err, MemoryError):
        what = "does not fit in memory (MemoryError)"
    elif type(err).__name__ in ("JaxRuntimeError", "XlaRuntimeError") and "RESOURCE_EXHAUSTED" in text:
        found = re.search(r"allocat\w* (\d+) bytes", text)
        asked = f": XLA asked for {_size(int(found.group(1)))}" if found else ""
        what = f"does not fit in the device's memory{asked}"
    elif type(err).__name__ in ("JaxRuntimeError", "XlaRuntimeError") and "2147483647" in text:
        what = "is too large for XLA (an array with more than 2^31 elements)"
    else:
        return None
    num_envs = getattr(config, "num_envs", None)
    size = f"num_envs={num_envs}: " if num_envs is not None else ""
    fix = "lower num_envs (--set num_envs=N)" if num_envs is not None else "use a smaller configuration"
    return f"{size}the run {what}; {fix} or the number of seeds"


def _size(num_bytes: float) -> str:
    """``3.0 GiB``, ``104 MiB``."""
    return f"{num_bytes / 2**30:,.1f} GiB" if num_bytes >= 2**30 else f"{num_bytes / 2**20:,.0f} MiB"


def _device_memory() -> tuple[int | None, str]:
    """``(bytes, what)``: the memory of the first device JAX sees (an accelerator's limit, a CPU's
    physical memory); None where it cannot be told."""
    import os

    import jax

    device = jax.local_devices()[0]
    stats = device.memory_stats() or {}
    if stats.get("bytes_limit"):
        return int(stats["bytes_limit"]), f"the {device.device_kind} ({device.platform})"
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"), "this machine's memory"
    except (ValueError, OSError, AttributeError):
        return None, "this machine's memory"


def _check_memory(exp: Experiment, config, num_seeds: int, devices: int) -> None:
    """Refuse a UED run before anything is written when its rollouts alone cannot fit one device: a
    block stores, per seed on the device, ``num_steps × num_envs`` observations and a reward, value
    and log-probability each (a lower bound of what training holds: parameters, buffers and the
    compiled program come on top). A run that passes can still run out of memory (then
    :class:`TooLarge`, after allocating)."""
    num_envs, num_steps = getattr(config, "num_envs", None), getattr(config, "num_steps", None)
    if exp.make_task is None or not isinstance(num_envs, int) or not isinstance(num_steps, int):
        return
    import jax

    try:  # shapes only: nothing is allocated or compiled
        task = exp.make_task(config)
        obs, _ = jax.eval_shape(lambda k: task.env.reset_to_level(k, task.sample_level(k), task.params),
                                jax.random.PRNGKey(0))
        per_step = sum(x.size * x.dtype.itemsize for x in jax.tree.leaves(obs)) + 3 * 4
    except Exception:  # noqa: BLE001 - a task this cannot size: training reports its own errors
        return
    seeds = max(1, num_seeds // max(1, devices))
    need = seeds * num_steps * num_envs * per_step
    have, what = _device_memory()
    if have is not None and need > have:
        raise TooLarge(f"num_envs={num_envs}: the rollouts alone need {_size(need)} ({seeds} seed"
                       f"{'s' if seeds != 1 else ''} × num_steps {num_steps} × num_envs {num_envs} × {per_step} "
                       f"bytes), more than the {_size(have)} of {what}; lower num_envs "
                       f"(--set num_envs=N), num_steps or the number of seeds")


def _existing_paths(out: Path, folders: list[Path]) -> set[Path]:
    """What exists before a run writes: ``out``'s parents, ``out`` and each of ``folders`` with the
    entries directly in them."""
    found = {p for p in Path(out).parents if p.exists()}
    for folder in map(Path, dict.fromkeys([Path(out), *folders])):
        if folder.is_dir():
            found |= {folder, *folder.iterdir()}
    return found


def _remove_new_paths(out: Path, folders: list[Path], before: set[Path]) -> None:
    """Remove what a failed fresh run wrote: the entries of ``folders`` that were not in ``before``
    (new sub-folders with all they hold), then ``out``, the folders and the parents they were made
    in when they are new and left empty. Nothing that existed before the run is touched."""
    for folder in map(Path, folders):
        for path in (list(folder.iterdir()) if folder.is_dir() else []):
            if path in before:
                continue
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink(missing_ok=True)
    for folder in sorted({Path(out), *map(Path, folders)}, key=lambda p: len(p.parts), reverse=True):
        for path in (folder, *folder.parents):
            if path in before or not path.is_dir() or any(path.iterdir()):
                break
            path.rmdir()


def resume_experiment(exp_lookup: Callable[[str, dict | None], Experiment], folder: Path,
                      progress: bool = True) -> dict[str, dict]:
    """Continue the run in ``folder`` from its last checkpoint. ``exp_lookup(name, task)``: the
    experiment of ``config.json``'s ``experiment`` and ``task`` (its user's task's import record,
    or None): :func:`remidi.experiments.saved_experiment`.

    ``folder`` is one algorithm's run (it holds config.json), or the folder of a several-algorithm
    run, whose unfinished algorithms (no summary.json) are resumed before the comparison plots
    are redrawn. The run keeps its recorded ``devices``. A finished run (:func:`finished_run`) is
    checked, then returned as it is: nothing is trained or written.
    """
    folder = Path(folder)
    if _secondary_process(_saved_devices(folder)):  # only process 0 writes the run folder; the others
        with tempfile.TemporaryDirectory(prefix="remidi-process-") as scratch:  # resume a scratch copy of it
            shutil.copytree(folder, Path(scratch) / "run")
            return _resume(exp_lookup, Path(scratch) / "run", progress=False, notes=False)
    if not folder.is_dir():  # _resume says what is wrong
        return _resume(exp_lookup, folder, progress)
    # one process writes a run at a time; one algorithm of a several-algorithm run locks the whole run
    part_of = (folder / "config.json").exists() and outputs.several_algorithm_run(folder.parent)
    with outputs.folder_lock(folder.parent if part_of else folder, "--resume"):
        return _resume(exp_lookup, folder, progress)


def finished_run(folder: Path) -> bool:
    """Whether ``folder`` holds a finished run: its summary.json is written (of a several-algorithm
    run, every algorithm's), so resuming it has nothing to train."""
    folder = Path(folder)
    if (folder / "config.json").exists():
        return (folder / "summary.json").exists()
    subs = [p for p in folder.iterdir() if (p / "config.json").exists()] if folder.is_dir() else []
    return (bool(subs) and all((p / "summary.json").exists() for p in subs)
            and not _missing_algorithms(folder, subs))


def _missing_algorithms(folder: Path, subs: list[Path]) -> list[str]:
    """The algorithms a several-algorithm run (:func:`outputs.several_algorithm_run`) records
    (``algos`` in its config.json files) that have no sub-folder with a config.json: a run stopped
    while it wrote them (one after another, before training) never trained them. None for a
    folder of separate runs, or where a config.json is damaged (resuming it says what is wrong)."""
    if not outputs.several_algorithm_run(folder):
        return []
    algos = outputs.read_json(subs[0] / "config.json").get("algos") or []
    return [a for a in algos if isinstance(a, str) and a and Path(a).name == a
            and not (folder / a / "config.json").exists()]


def _write_missing_configs(exp_lookup, folder: Path, subs: list[Path]) -> list[Path]:
    """Write the config.json of :func:`_missing_algorithms` from one that was written (every
    algorithm of a several-algorithm run shares its experiment, preset, seeds, config, devices,
    tracking and command), so that --resume trains them; returns their sub-folders."""
    missing = _missing_algorithms(folder, subs)
    if not missing:
        return []
    exp, _, preset, seeds, config = _saved_run(exp_lookup, subs[0])
    saved = outputs.read_json(subs[0] / "config.json")
    command = saved.get("command") if isinstance(saved.get("command"), list) else ["remidi"]
    made = []
    for algo in missing:
        sub = outputs.prepare_out_dir(folder / algo)
        write_run_config(sub, exp, algo, preset, seeds, config, command[1:], devices=_saved_devices(subs[0]),
                         algos=saved["algos"], log=_saved_log(subs[0]))
        made.append(sub)
    return made


def _resume(exp_lookup: Callable[[str, dict | None], Experiment], folder: Path, progress: bool,
            notes: bool = True) -> dict[str, dict]:
    """Resume ``folder`` (:func:`resume_experiment`); ``notes``: say which runs have no checkpoint
    yet (process 0 only)."""
    if not (folder / "config.json").exists() and folder.is_dir():
        subs = sorted(p for p in folder.iterdir() if (p / "config.json").exists())
        if subs and not outputs.several_algorithm_run(folder):
            raise ConfigError(f"--resume: {folder} holds separate runs, not one several-algorithm run; resume each "
                              f"(e.g. remidi run --resume {subs[0]})")
        if subs:
            subs = sorted(subs + _write_missing_configs(exp_lookup, folder, subs))
            return _resume_several(exp_lookup, folder, subs, progress, notes)
    folder = outputs.prepare_out_dir(folder, resume=True)
    exp, algo, preset, seeds, config = _saved_run(exp_lookup, folder)
    devices = _saved_devices(folder)
    _check_devices(exp, devices, len(seeds))
    if finished_run(folder):  # nothing to train: its results as they are (a rerun would overwrite wall_s)
        return {algo: _finished_summary(folder)}
    _check_writable(folder)
    outputs.remove_stale_temporaries(folder)
    if notes:
        _note_fresh_start(exp, folder)
    return _train_and_write(exp, {algo: folder}, preset, seeds, config, folder, resume=True, progress=progress,
                            devices=devices, log=_saved_log(folder))


def _note_fresh_start(exp: Experiment, folder: Path) -> None:
    """Say so when the UED run to resume in ``folder`` has no checkpoint yet (it stopped before
    its first): --resume then trains it from its start. (The tabular games keep no checkpoint.)"""
    from remidi.engine.run.checkpoint import CHECKPOINT

    if exp.make_task is not None and not (folder / CHECKPOINT).exists():
        print(f"remidi: note: {folder} has no checkpoint yet (the run stopped before its first); "
              f"it trains from its start", file=sys.stderr, flush=True)


def _check_writable(folder: Path) -> None:
    """ConfigError (one line) for a run folder to resume that cannot be written: before, the run
    compiled and trained a block before its first checkpoint failed."""
    if not writable(folder):
        raise ConfigError(f"--resume: {folder} is not writable: the resumed run could not write its checkpoints "
                          f"and results; resume a writable copy of it")


def _finished_summary(folder: Path) -> dict:
    """A finished run's summary.json, checked: a damaged one is a one-line error (the run's
    outputs are written again from its last checkpoint once it is deleted)."""
    return outputs.read_json_object(folder / "summary.json", "--resume",
                                    f"; delete it, and --resume writes the run's outputs again from checkpoint.npz")


def _saved_log(folder: Path) -> list[str]:
    """The tracking backends recorded in ``folder/config.json`` (checked again: a resume on a
    machine without the package says so before anything is written)."""
    from remidi.experiments.tracking import parse_log

    saved = outputs.read_json(folder / "config.json").get("log") or []
    if not isinstance(saved, list) or not all(isinstance(name, str) for name in saved):
        raise ConfigError(f"--resume: {folder / 'config.json'}: log must be a list of backend names, got {saved!r}")
    return parse_log(",".join(saved))


def _saved_run(exp_lookup, folder: Path, flag: str = "--resume"):
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
    """ConfigError unless the saved run's algorithm and (UED) score are known to this process: one
    registered by a plugin (remidi.register_algorithm / register_score) must be loaded again."""
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


def _saved_devices(folder: Path):
    """``devices`` of the run in ``folder`` (1 for runs recorded before ``--devices`` existed); of a
    several-algorithm folder, the largest of its runs'; 1 where nothing is readable (resuming then
    reports what is wrong)."""
    folder = Path(folder)
    try:
        paths = [folder / "config.json"] if (folder / "config.json").exists() else sorted(folder.glob("*/config.json"))
        return max((outputs.read_json(path).get("devices", 1) for path in paths), default=1)
    except (OSError, ValueError, AttributeError, TypeError):
        return 1


def _check_devices(exp: Experiment, devices, num_seeds: int) -> None:
    """``--devices``: 1 always; more only for an experiment that shards its seeds, and then at most
    the devices JAX sees and a divisor of the number of seeds (``driver.check_devices``)."""
    if devices == 1 and not isinstance(devices, bool):
        return  # today's path, without asking JAX anything
    if not exp.shards_seeds:
        raise ConfigError(f"--devices: {exp.name} trains on one device; allowed: 1")
    from remidi.engine.run.driver import check_devices

    check_devices(devices, num_seeds)


def _secondary_process(devices) -> bool:
    """True in a process other than 0 of a multi-process JAX run (``jax.distributed``); only asked
    of sharded runs, so a one-device run never touches JAX here."""
    if devices == 1:
        return False
    import jax

    return jax.process_index() != 0


def _run_order(sub: Path, exp: Experiment, algo: str) -> tuple[int, int]:
    """Where ``algo`` stands in its several-algorithm run: the order the user gave (``algos`` in
    config.json), then the experiment's own order, so a resumed run plots like a fresh one."""
    saved = outputs.read_json(sub / "config.json").get("algos") or []
    given = saved.index(algo) if algo in saved else len(saved)
    return given, exp.algorithms.index(algo) if algo in exp.algorithms else len(exp.algorithms)


def _resume_several(exp_lookup, folder: Path, subs: list[Path], progress: bool, notes: bool) -> dict[str, dict]:
    runs = [(sub, *_saved_run(exp_lookup, sub)) for sub in subs]
    runs.sort(key=lambda run: _run_order(run[0], run[1], run[2]))
    devices = {sub: _saved_devices(sub) for sub in subs}
    logs = {sub: _saved_log(sub) for sub in subs}
    for sub, exp, algo, preset, seeds, config in runs:  # every run checked before any trains
        _check_devices(exp, devices[sub], len(seeds))
    summaries = {}
    unfinished = [run for run in runs if not (run[0] / "summary.json").exists()]
    for sub in [folder, *(run[0] for run in unfinished)] if unfinished else []:
        _check_writable(sub)
        outputs.remove_stale_temporaries(sub)

    def compare(last: dict[str, RunResult]) -> None:  # with the last unfinished algorithm's result, before its summary
        exp, preset, seeds, config = runs[0][1], runs[0][3], runs[0][4], runs[0][5]
        exp.plot(folder, {algo: last[algo] if algo in last else result_from_files(sub) for sub, _, algo, *_ in runs},
                 config, preset=preset, seeds=seeds)

    for sub, exp, algo, preset, seeds, config in runs:  # nothing trained (finished): the folder stays as it is
        if (sub / "summary.json").exists():
            summaries[algo] = _finished_summary(sub)
        else:
            if notes:
                _note_fresh_start(exp, sub)
            summaries.update(_train_and_write(exp, {algo: sub}, preset, seeds, config, sub, resume=True,
                                              progress=progress, devices=devices[sub], log=logs[sub],
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


def write_run_config(folder: Path, exp: Experiment, algo: str, preset: str, seeds: list[int], config, argv,
                     devices: int = 1, algos: list[str] | None = None, log: list[str] | None = None) -> None:
    """``algos``: every algorithm of the run, in the order the user gave (plots keep it on resume);
    ``log``: its experiment-tracking backends (a resume continues them)."""
    outputs.write_json(folder / "config.json", {
        "experiment": exp.name,
        "algo": algo,
        "algos": list(algos) if algos else [algo],
        "preset": preset,
        "seeds": seeds,
        "devices": devices,
        "log": list(log or []),
        "config": config_to_dict(config),
        **({"task": dict(exp.task_ref)} if exp.task_ref else {}),
        "command": ["remidi", *(argv if argv is not None else sys.argv[1:])],
        "remidi_version": __version__,
        "code": code_version(),
    })


def _train_and_write(exp, folders, preset, seeds, config, out, *, resume, progress, devices=1, log=(),
                     compare: Callable[[dict[str, RunResult]], None] | None = None):
    """Train each of ``folders``' algorithms and write its outputs: metrics.csv, the plots, then
    summary.json, which marks the run finished (:func:`finished_run`), so a run stopped while it
    plots is resumed and plotted again. ``compare(results)`` draws a several-algorithm run's
    comparison plots (default, for several ``folders``: at ``out``); it runs before the last
    algorithm's summary.json is written, for the same reason."""
    results: dict[str, RunResult] = {}
    summaries: dict[str, dict] = {}
    if compare is None and len(folders) > 1:
        compare = lambda finished: exp.plot(out, finished, config, preset=preset, seeds=seeds)  # noqa: E731
    for algo, folder in folders.items():
        tracker = None
        if log:
            from remidi.experiments.tracking import Tracker

            tracker = Tracker(list(log), folder, f"{exp.name}/{algo}", outputs.read_json(folder / "config.json"),
                              seeds, group=str(Path(out).resolve()))
        ctx = RunContext(exp.name, algo, preset, seeds, config, folder, resume=resume, progress=progress,
                         devices=devices, on_block=tracker.log if tracker is not None else None)
        started = time.perf_counter()
        try:
            result = exp.train(ctx)
        except BaseException as err:  # Ctrl-C or an error: close the tracked runs, a resume continues them
            if tracker is not None:
                tracker.close()
            message = too_large_message(err, config)
            if message is not None:  # a resumed run keeps its folder: it resumes on a larger device
                kept = resume and (folder / "checkpoint.npz").exists()
                raise TooLarge(message + (f"; {folder} keeps its last checkpoint" if kept else "")) from None
            raise
        # wall time of the training (compilation included) in this invocation: a resumed run counts its last part
        timing = {"wall_s": round(time.perf_counter() - started, 1), "resumed": resume}
        results[algo] = result
        outputs.write_metrics_csv(folder / "metrics.csv", outputs.metric_rows(result.steps, result.history, seeds))
        exp.plot(folder, {algo: result}, config, preset=preset, seeds=seeds)
        if compare is not None and algo == list(folders)[-1]:
            compare(results)
        summaries[algo] = outputs.write_summary(
            folder / "summary.json", experiment=exp.name, algo=algo, preset=preset, seeds=seeds,
            final=result.final_metrics(), **timing, **result.extra)
        if tracker is not None:
            tracker.log_history(result.steps, result.history)  # what was not streamed (the tabular games)
            tracker.finish(summaries[algo], sorted(folder.glob("*.png")))
    return summaries
