"""A fresh ``remidi run``: validate everything before writing anything, write ``config.json``
first (so a killed run can be resumed), then train and write ``metrics.csv``, ``summary.json``
and the plots, identically for every :class:`~remidi.experiments.base.Experiment`.

A UED run whose rollouts alone cannot fit the device is refused up front (:func:`_check_memory`,
a lower bound); one that runs out of memory anyway (:class:`TooLarge`) is one line naming
``num_envs``, and a fresh run then removes what it made (resuming would fail the same way),
keeping what was there before and the algorithms that finished.

With several algorithms each gets ``OUT/<algo>/`` and the comparison plots go to ``OUT/``; with
one, everything goes to ``OUT/``. ``devices`` (``--devices N``, recorded and reused by
``--resume``) shards the seeds (``Experiment.shards_seeds``; ``docs/devices.md``). In a
multi-process JAX run only process 0 writes the run folder."""

from __future__ import annotations

import re
import shutil
import sys
import tempfile
import time
from pathlib import Path
from dataclasses import replace
from typing import Callable

from remidi import __version__
from remidi.errors import COMMAND_LINE, ConfigError, Naming
from remidi.experiments import outputs
from remidi.experiments.base import MAX_SEED, Experiment, RunContext, RunResult, RunSpec, resolve_config
from remidi.experiments.overrides import config_to_dict
from remidi.experiments.remidi_account import remidi_account, remidi_line
from remidi.files import code_version


def run_experiment(spec: RunSpec, out: Path, progress: bool = True) -> dict[str, dict]:
    """Validate, train every algorithm of ``spec`` into ``out``, write all outputs; return
    ``{algo: summary}``. ``spec.devices``: :func:`_check_devices`; ``spec.log``: backends of
    :mod:`remidi.loggers`; ``spec.naming``: the caller's words in errors and notes."""
    exp, seeds, devices, naming = spec.exp, spec.seeds, spec.devices, spec.naming
    notes: list[str] = []
    config = resolve_config(exp, spec.preset, spec.overrides, notes, naming)
    for algo in spec.algos:
        exp.validate(config, algo)
    if exp.budget_line is not None:  # one line per algorithm: the budget it gets (an import-path task's)
        notes += [line for line in (exp.budget_line(config, algo) for algo in spec.algos) if line is not None]
    check_seeds(seeds, naming)
    _check_devices(exp, devices, len(seeds))
    _check_memory(exp, config, len(seeds), devices, naming)
    if exp.run_warnings is not None:  # once for the run's algorithms, printed with the notes
        notes += [f"warning: {warning}" for warning in exp.run_warnings(spec, config)]
    if _secondary_process(devices):  # only process 0 writes OUT; the others train alongside it (the
        with tempfile.TemporaryDirectory(prefix="remidi-process-") as scratch:  # mesh spans them) into scratch
            return _write_and_train(replace(spec, log=[]), config, Path(scratch) / "run", [], False)
    return _write_and_train(spec, config, Path(out), notes, progress)


def check_seeds(seeds: list[int], naming: Naming = COMMAND_LINE) -> None:
    """ConfigError (one line, in the caller's words) unless ``seeds`` names at least one seed, each
    a 32-bit random key."""
    if not seeds:
        raise ConfigError(f"{naming.seeds}: must be an integer ≥ 1")
    if min(seeds) < 0 or max(seeds) > MAX_SEED:
        raise ConfigError(f"{naming.first_seed}: every seed must be in [0, {MAX_SEED}] (a 32-bit random key), got "
                          f"{min(seeds)}..{max(seeds)}{naming.seed_fix}")
    repeated = sorted({seed for seed in seeds if list(seeds).count(seed) > 1})
    if repeated:  # a seed trained twice would count twice in every mean and spread
        raise ConfigError(f"{naming.seeds}: seed {repeated[0]} is given twice; give each seed once")


def _write_and_train(spec: RunSpec, config, out: Path, notes: list[str], progress: bool) -> dict[str, dict]:
    folders = {algo: (out / algo if len(spec.algos) > 1 else out) for algo in spec.algos}
    naming = spec.naming
    for folder in dict.fromkeys([out, *folders.values()]):  # check every folder before writing anything
        outputs.prepare_out_dir(folder, create=False, naming=naming)
    for note in notes:  # only once the run is known to be valid: an error stays the only line
        print(f"remidi: {note}", file=sys.stderr, flush=True)
    before = _existing_paths(out, list(folders.values()))
    try:
        outputs.prepare_out_dir(out, naming=naming)
        with outputs.folder_lock(out, naming.out):
            for folder in dict.fromkeys([out, *folders.values()]):  # again: a run another process began here since
                outputs.prepare_out_dir(folder, create=False, naming=naming)
            for algo, folder in folders.items():
                outputs.prepare_out_dir(folder, naming=naming)
                write_run_config(folder, spec, algo, config)
            return _train_and_write(spec, config, folders, out, resume=False, progress=progress)
    except TooLarge as err:  # resuming would fail the same way: remove what this run wrote, keep finished algorithms
        finished = [algo for algo, folder in folders.items() if (folder / "summary.json").exists()]
        _remove_new_paths(out, [folders[algo] for algo in folders if algo not in finished], before)
        kept = f" (kept the finished {', '.join(finished)} in {out})" if finished else ""
        raise TooLarge(f"{err}; removed what this run wrote{kept}") from None


class TooLarge(ConfigError):
    """The run does not fit the device: XLA ran out of memory (``RESOURCE_EXHAUSTED``), NumPy raised
    MemoryError, or an array outgrew XLA's 32-bit indices."""


def too_large_message(err: BaseException, config, naming: Naming = COMMAND_LINE) -> str | None:
    """One line for an error saying the run is too large for the device, naming ``num_envs`` (the
    usual culprit) and the size XLA asked for; None for any other error."""
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
    fix = (f"lower num_envs ({naming.setting('num_envs', 'N')})" if num_envs is not None
           else "use a smaller configuration")
    return f"{size}the run {what}; {fix} or the number of seeds"


def _size(num_bytes: float) -> str:
    """``3.0 GiB``, ``104 MiB``."""
    return f"{num_bytes / 2**30:,.1f} GiB" if num_bytes >= 2**30 else f"{num_bytes / 2**20:,.0f} MiB"


def _device_memory() -> tuple[int | None, str]:
    """``(bytes, what)``: the first device's memory (an accelerator's limit, else physical memory);
    None where it cannot be told."""
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


def _check_memory(exp: Experiment, config, num_seeds: int, devices: int, naming: Naming = COMMAND_LINE) -> None:
    """Refuse a UED run before anything is written when its rollouts alone cannot fit one device
    (per seed: ``num_steps × num_envs`` observations plus reward, value and log-probability). A lower
    bound: a run that passes can still raise :class:`TooLarge`."""
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
                       f"({naming.setting('num_envs', 'N')}), num_steps or the number of seeds")


def _existing_paths(out: Path, folders: list[Path]) -> set[Path]:
    """What exists before a run writes: ``out``'s parents, ``out`` and each of ``folders`` with the
    entries directly in them."""
    found = {p for p in Path(out).parents if p.exists()}
    for folder in map(Path, dict.fromkeys([Path(out), *folders])):
        if folder.is_dir():
            found |= {folder, *folder.iterdir()}
    return found


def _remove_new_paths(out: Path, folders: list[Path], before: set[Path]) -> None:
    """Remove what a failed fresh run wrote: the entries of ``folders`` not in ``before``, then
    ``out``, the folders and their parents where new and left empty. Nothing older is touched."""
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


def _check_devices(exp: Experiment, devices, num_seeds: int) -> None:
    """``--devices``: 1 always; more only for an experiment that shards its seeds, at most the devices
    JAX sees and a divisor of the number of seeds."""
    if devices == 1 and not isinstance(devices, bool):
        return  # today's path, without asking JAX anything
    if not exp.shards_seeds:
        raise ConfigError(f"--devices: {exp.name} trains on one device; allowed: 1")
    from remidi.engine.run.driver import check_devices

    check_devices(devices, num_seeds)


def _secondary_process(devices) -> bool:
    """True in a process other than 0 of a multi-process JAX run; asked only of sharded runs, so a
    one-device run never touches JAX here."""
    if devices == 1:
        return False
    import jax

    return jax.process_index() != 0


def write_run_config(folder: Path, spec: RunSpec, algo: str, config) -> None:
    """``folder/config.json`` of ``algo``'s part of ``spec``, trained with ``config``; it records all
    the run's algorithms in the user's order (plots keep it on resume) and the logging backends."""
    exp = spec.exp
    outputs.write_json(folder / "config.json", {
        "experiment": exp.name,
        "algo": algo,
        "algos": list(spec.algos) if spec.algos else [algo],
        "preset": spec.preset,
        "seeds": spec.seeds,
        "devices": spec.devices,
        "log": list(spec.log or []),
        "config": config_to_dict(config),
        **({"task": dict(exp.task_ref)} if exp.task_ref else {}),
        "command": ["remidi", *(spec.argv if spec.argv is not None else sys.argv[1:])],
        "remidi_version": __version__,
        "code": code_version(),
    })


def _train_and_write(spec: RunSpec, config, folders: dict[str, Path], out: Path, *, resume: bool, progress: bool,
                     compare: Callable[[dict[str, RunResult]], None] | None = None):
    """Train each of ``folders``' algorithms and write metrics.csv, the plots, then summary.json,
    which marks the run finished (:func:`finished_run`), so a run stopped while plotting is replotted
    on resume. ``compare(results)`` draws the comparison plots, before the last summary.json for the
    same reason."""
    exp, preset, seeds, devices, log = spec.exp, spec.preset, spec.seeds, spec.devices, spec.log
    results: dict[str, RunResult] = {}
    summaries: dict[str, dict] = {}
    if compare is None and len(folders) > 1:
        compare = lambda finished: exp.plot(out, finished, config, preset=preset, seeds=seeds)  # noqa: E731
    for algo, folder in folders.items():
        run_logger = None
        if log:
            from remidi.loggers import RunLogger

            run_logger = RunLogger(list(log), folder, f"{exp.name}/{algo}", outputs.read_json(folder / "config.json"),
                                   seeds, group=str(Path(out).resolve()))
        ctx = RunContext(exp.name, algo, preset, seeds, config, folder, resume=resume, progress=progress,
                         devices=devices, on_block=run_logger.log if run_logger is not None else None,
                         naming=spec.naming)
        started = time.perf_counter()
        try:
            result = exp.train(ctx)
        except BaseException as err:  # Ctrl-C or an error: close the logged runs, a resume continues them
            if run_logger is not None:
                run_logger.close()
            message = too_large_message(err, config, spec.naming)
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
        did = remidi_account(algo, result, getattr(config, "num_envs", None)) if exp.make_task is not None else None
        summaries[algo] = outputs.write_summary(
            folder / "summary.json", experiment=exp.name, algo=algo, preset=preset, seeds=seeds,
            final=result.final_metrics(), **timing, **result.extra, **({"remidi_did": did} if did else {}))
        if run_logger is not None:
            run_logger.log_history(result.steps, result.history)  # what was not streamed (the tabular games)
            run_logger.finish(summaries[algo], sorted(folder.glob("*.png")))
    for algo, summary in summaries.items():  # what each buffer sequence did, once every algorithm has trained
        line = remidi_line(algo, summary, summaries) if "remidi_did" in summary else None
        if line is not None and not _secondary_process(devices):
            print(f"remidi: {line}", file=sys.stderr, flush=True)
    return summaries
