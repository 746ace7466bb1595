"""The results page's data: the runs committed under ``docs/results/data`` (:func:`load_runs`:
one :class:`Run` per experiment and algorithm, its parts merged by seed), a claim's metric per
seed (:func:`metric_values`), and :func:`collect`, which copies a finished run's small outputs
there.

``DATA/<experiment>/<run>/`` is one ``remidi run`` of one algorithm (a part of its seeds):
``config.json``, ``summary.json``, ``evaluate.json`` (``remidi evaluate --attempts 30``) and
``metrics.csv.gz``. Parts of one experiment × algorithm are merged by seed (a seed twice is an
error), so seeds can be run in parts. An unfinished run's folder holds ``progress.json`` in
place of ``summary.json`` (:func:`collect_unfinished`): its training evaluations so far, which
the page draws beside the scale study and no claim reads."""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from remidi.errors import ConfigError
from remidi.experiments import outputs
from remidi.files import atomic_write
from remidi.runs.evaluate import DEFAULTS, files_stem
from remidi.runs.table import label  # how the page names an algorithm's runs

from tools.results.claims import EXTRA_TABLES, SCALE_PRESETS, SECTIONS

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "docs" / "results" / "data"
#: committed runs trained again (same experiment, algorithm, preset, seeds and commit) to measure
#: what the first run's folder did not keep, e.g. its final checkpoint for ``remidi evaluate
#: --action mode``: laid out as :data:`DATA`, read only by the tables that set them beside their
#: originals (so a seed is never counted twice)
REPEATS = ROOT / "docs" / "results" / "repeats"


def run_label(summary: dict, config: dict) -> str:
    """How the page names a run's algorithm: :func:`label`, and ``@PRESET`` for a scale-study
    preset (``plr @cpu4x``), so that runs of one algorithm at two scales stay apart."""
    name = label(summary["algo"], config.get("config", {}), config.get("command"))
    return f"{name} @{summary['preset']}" if summary.get("preset") in SCALE_PRESETS else name


def device_name(code: dict) -> str:
    """A part's device as the tables name it: ``code["device"]``, and for a CPU the model and vector
    instruction set it recorded (``code["cpu"]``, recorded by runs from the commit that added it),
    e.g. ``"cpu: cpu (Intel(R) Xeon(R) Processor, AVX-512)"``; ``"not recorded"`` without one."""
    device = code.get("device") or "not recorded"
    return f"{device} ({code['cpu']})" if device.startswith("cpu") and code.get("cpu") else device


def lost_note(progress: dict) -> str:
    """``"first attempt, lost <date>"`` for an unfinished run whose folder was lost before it
    finished (``lost`` in its progress, :func:`load_unfinished`), else ``""``."""
    return f"first attempt, lost {progress['lost']}" if progress.get("lost") else ""


def _add_device(devices: list, device: str) -> None:
    """Append the device of a run's next part to ``devices`` (the run's devices in training order),
    unless the part before trained there too."""
    if not devices or devices[-1] != device:
        devices.append(device)


@dataclass
class Run:
    """One experiment × algorithm, its parts merged: per source (``summary``, ``evaluate``) and
    metric ``{seed: value}``; ``curves``: metric → (steps i[T], values f[S, T]) in ``seeds`` order."""

    experiment: str
    algo: str
    seeds: list[int] = field(default_factory=list)
    values: dict[str, dict[str, dict[int, float]]] = field(default_factory=dict)
    curves: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    folders: list[str] = field(default_factory=list)
    commits: set = field(default_factory=set)
    wall_s: float = 0.0
    resumed: bool = False  # some part was resumed: its summary's wall time is its last part's alone
    config: dict = field(default_factory=dict)  # the first part's config.json "config"
    preset: str = ""
    # per run folder, in ``folders`` order: (its seeds, then the commits, devices and JAX versions of
    # its parts in the order they trained: commits and JAX versions ordered sets (dict keys), devices
    # a list naming a device again where a later part returned to it)
    groups: list = field(default_factory=list)


def _merge_seeds(run: Run, source: str, seeds: list[int], metrics: dict, folder: Path) -> None:
    for name, entry in metrics.items():
        per = run.values.setdefault(source, {}).setdefault(name, {})
        for seed, value in zip(seeds, entry["per_seed"]):
            if seed in per:
                raise ConfigError(f"data: seed {seed} of {run.experiment} / {run.algo} is in two runs ({folder})")
            per[seed] = math.nan if value is None else float(value)


EVAL_ATTEMPTS = 30  # `remidi evaluate --attempts`: what the page's "final checkpoint" metrics are


#: the evaluations the page reads, by source: ``evaluate:`` (actions sampled from the policy, as it
#: trained) and ``evaluate-mode:`` (its most likely action, ``remidi evaluate --action mode``)
EVALUATIONS = {files_stem(action): action for action in ("sample", "mode")}


def _evaluation(folder: Path, algo: str, config: dict, source: str = "evaluate") -> dict:
    """``algo``'s entry of the run's ``<source>.json``, checked. The page states its ``evaluate:`` metrics as the final checkpoint's with
    :data:`EVAL_ATTEMPTS` attempts, and its CVaR and perfect-maze metrics as ``remidi
    evaluate``'s defaults give them: refuse (ConfigError naming the run) an evaluation of an
    unfinished run's checkpoint, with other arguments or acting otherwise than its source says,
    rather than mix it in."""
    where = folder / f"{source}.json"
    evaluated = outputs.read_json(where)
    entry, args = evaluated["algorithms"][algo], evaluated.get("args", {})
    if args.get("action", "sample") != EVALUATIONS[source]:
        raise ConfigError(f"{where}: evaluated with --action {args.get('action', 'sample')}; the page's {source}: "
                          f"metrics act by {EVALUATIONS[source]}")
    if args.get("attempts") != EVAL_ATTEMPTS:
        raise ConfigError(f"{where}: evaluated with --attempts {args.get('attempts')}; the page's metrics are "
                          f"{EVAL_ATTEMPTS} attempts (remidi evaluate RUN --attempts {EVAL_ATTEMPTS})")
    for key, default in DEFAULTS.items():  # the CVaR and perfect-maze tables compare runs on the same levels
        want = list(default) if isinstance(default, tuple) else default
        if key != "attempts" and key in args and args[key] != want:
            raise ConfigError(f"{where}: evaluated with {key} {args[key]!r}; the page compares runs evaluated with "
                              f"remidi evaluate's default {want!r}")
    updates = config.get("config", {}).get("num_updates")
    if entry.get("update") != updates:
        raise ConfigError(f"{where}: evaluated at update {entry.get('update')} of {updates}; the page reads the final "
                          f"checkpoint (finish the run, then evaluate it again)")
    return entry


def _later_jax(code: dict) -> list[str]:
    """The JAX versions of a run's later parts, for a run from before parts were recorded whose
    device was written by hand as several machines (``"gpu: … (updates 1-900), then cpu"``): those
    its ``note`` names (``"… (JAX 0.11.2) …"``), else ``["not recorded"]``; [] for one machine."""
    if ", then " not in code.get("device", ""):
        return []
    return re.findall(r"JAX (\d+(?:\.\d+)+)", code.get("note", "")) or ["not recorded"]


def load_runs(data: Path = DATA) -> dict[tuple[str, str], Run]:
    """``{(experiment, algo): Run}`` of every run folder under ``data``."""
    runs: dict[tuple[str, str], Run] = {}
    for folder in sorted(p.parent for p in Path(data).glob("*/*/summary.json")):
        summary = outputs.read_json(folder / "summary.json")
        config = outputs.read_json(folder / "config.json")
        key = (summary["experiment"], run_label(summary, config))
        run = runs.setdefault(key, Run(*key, preset=summary["preset"]))
        seeds = list(summary["seeds"])
        _merge_seeds(run, "summary", seeds, summary["metrics"], folder)
        for source in EVALUATIONS:
            if (folder / f"{source}.json").is_file():
                entry = _evaluation(folder, summary["algo"], config, source)
                _merge_seeds(run, source, list(entry["seeds"]), entry["metrics"], folder)
        _add_part(run, folder, seeds, config, data)
        started = config.get("code") or {}  # what the run recorded when it started
        parts = summary.get("parts")  # each invocation that trained it
        jaxes = []
        if not parts:  # a run before parts were recorded: the start's record, the last part's time
            parts = [{"code": started, "wall_s": summary.get("wall_s", 0.0)}]
            run.resumed |= bool(summary.get("resumed"))
            jaxes = _later_jax(started)
        # the parts in the order they trained: commits and JAX versions as ordered sets (dicts), the
        # devices as a sequence that names a device again when a later part returns to it
        group = (tuple(seeds), {}, [], {})
        for part in parts:
            code = part.get("code") or started  # None: a part before parts were recorded
            group[1][code.get("commit") or started.get("commit")] = None
            _add_device(group[2], device_name(code))
            group[3][code.get("jax") or started.get("jax") or "not recorded"] = None
            run.wall_s += float(part.get("wall_s") or 0.0)
            run.resumed |= part.get("code") is None  # that part's time is unknown
        group[3].update(dict.fromkeys(jaxes))
        run.commits |= set(group[1])
        run.groups.append(group)
    for run in runs.values():  # "run:<metric>": per seed, the mean of its logged points over the whole run
        for name, (_, values) in run.curves.items():
            if values.shape[0] != len(run.seeds):  # logged by some parts only: no per-seed alignment
                continue
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # a seed that never logged it: NaN
                means = np.nanmean(values, axis=1)
            run.values.setdefault("run", {})[name] = dict(zip(run.seeds, map(float, means)))
    return runs


def _add_part(run: Run, folder: Path, seeds: list[int], config: dict, data: Path) -> None:
    """Merge one run folder's curves (``metrics.csv.gz``), seeds, config and folder into ``run``."""
    if (folder / "metrics.csv.gz").is_file():
        rows = outputs.read_metrics_csv(folder / "metrics.csv.gz")
        steps = np.array(sorted({step for _, step, _, _ in rows}))
        index = {s: i for i, s in enumerate(steps)}
        part: dict[str, np.ndarray] = {}
        for seed, step, name, value in rows:
            part.setdefault(name, np.full((len(seeds), len(steps)), np.nan))[seeds.index(seed), index[step]] = value
        for name, values in part.items():
            if name in run.curves and not np.array_equal(run.curves[name][0], steps):
                raise ConfigError(f"data: {folder} logs {name} at other steps than the other parts")
            old = run.curves.get(name, (steps, np.zeros((0, len(steps)))))[1]
            run.curves[name] = (steps, np.concatenate([old, values]))
    run.seeds += seeds
    run.config = run.config or config.get("config", {})
    page_dir = Path(data).resolve().parents[1]  # docs/: the page's links are relative to it
    run.folders.append(str(folder.resolve().relative_to(page_dir)) if folder.resolve().is_relative_to(page_dir)
                       else str(folder))


PROGRESS = "progress.json"  # an unfinished run's committed folder: how far it trained


def load_unfinished(data: Path = DATA) -> dict[tuple[str, str], tuple[Run, dict]]:
    """``{(experiment, "algo @preset"): (run, progress)}`` of the unfinished runs under ``data``
    (folders with ``progress.json``, :func:`collect_unfinished`): their training evaluations so far
    (``run.curves``) and ``progress`` (``updates`` reached of ``num_updates``, the ``devices`` and
    ``commit`` they trained on, and ``lost``: the date the run's folder was lost, written by hand
    into the progress of a run whose machine went before it finished, until a restarted run's
    collection replaces it). The page draws them beside the scale study's curves; no claim reads
    them."""
    out = {}
    for folder in sorted(p.parent for p in Path(data).glob(f"*/*/{PROGRESS}")):
        progress = outputs.read_json(folder / PROGRESS)
        config = outputs.read_json(folder / "config.json")
        key = (progress["experiment"], f"{progress['algo']} @{progress['preset']}")
        if key in out:
            raise ConfigError(f"data: {key[0]} / {key[1]} has two unfinished runs ({folder})")
        run = Run(*key, preset=progress["preset"], commits={progress["commit"]})
        _add_part(run, folder, list(progress["seeds"]), config, data)
        out[key] = (run, progress)
    return out


def collect_unfinished(run: Path, data: Path = DATA) -> Path:
    """Copy an unfinished run's training evaluations so far (its ``config.json`` and
    ``checkpoint.history.npz``, the metrics logged up to its last checkpoint) into
    ``data/<experiment>/<algo>-<preset>-s<first seed>/``: ``config.json``, :data:`PROGRESS` and,
    gzipped, the curves the page draws with the metrics the experiment derives. The devices are its
    checkpoint's record of every part when ``checkpoint.npz`` lies beside the history at the same
    update, else the one the run started on. Returns the folder written."""
    from remidi.engine.run.checkpoint import CHECKPOINT, HISTORY, history_blocks, read_meta
    from remidi.experiments import get_experiment

    folder = Path(run)
    if (folder / "summary.json").is_file():
        raise ConfigError(f"collect-unfinished: {folder} is a finished run (summary.json): collect it with --collect")
    doc = outputs.read_json_object(folder / "config.json", "collect-unfinished",
                                      "; give a folder remidi run wrote")
    if not (folder / HISTORY).is_file():
        raise ConfigError(f"collect-unfinished: {folder} holds no {HISTORY} (no checkpoint written yet)")
    blocks = history_blocks(folder / HISTORY)
    history = {n: np.stack([b[n] for b in blocks], axis=1) for n in blocks[0]}  # f[S, T], as a finished run's
    cfg = doc["config"]
    steps = np.minimum(cfg["eval_every"] * np.arange(1, len(blocks) + 1), cfg["num_updates"])  # every block's end
    derive = get_experiment(doc["experiment"]).derive
    if derive is not None:
        history.update(derive(history))
    devices = [device_name(doc["code"]) + " (at its start)"]
    if (folder / CHECKPOINT).is_file():
        meta = read_meta(folder / CHECKPOINT, "collect-unfinished")
        if meta.get("done") == int(steps[-1]) and meta.get("parts"):
            devices = []
            for part in meta["parts"]:
                _add_device(devices, device_name(part.get("code") or {}))
    keep = set(SECTIONS.get(doc["experiment"], ([], [], []))[2])
    target = Path(data) / doc["experiment"] / f"{doc['algo']}-{doc['preset']}-s{doc['seeds'][0]}"
    if (target / "summary.json").is_file():  # the same run, finished and collected: its data stay
        raise ConfigError(f"collect-unfinished: {target} holds the finished run's data (summary.json); "
                          "nothing written")
    target.mkdir(parents=True, exist_ok=True)
    atomic_write(target / "config.json", lambda f: f.write((folder / "config.json").read_bytes()), binary=True)
    outputs.write_metrics_csv(target / "metrics.csv.gz", outputs.metric_rows(
        steps, {n: v for n, v in history.items() if n in keep}, doc["seeds"]))
    outputs.write_json(target / PROGRESS, {
        "experiment": doc["experiment"], "algo": doc["algo"], "preset": doc["preset"], "seeds": doc["seeds"],
        "updates": int(steps[-1]), "num_updates": int(cfg["num_updates"]), "devices": devices,
        "commit": doc["code"]["commit"]})
    return target


def metric_values(runs: dict, experiment: str, algo: str, metric: str) -> dict[int, float]:
    """``{seed: value}`` of ``metric`` (``"source:name"``) for one experiment × algorithm ({} if none).
    A tag's share of the active buffer (``buffer_fraction/<tag>``) is NaN for a seed whose active
    buffer is empty (``buffer_size`` 0): the run logs 0 there, which a bound like [0, 0.1] would pass."""
    source, name = metric.split(":", 1)
    run = runs.get((experiment, algo))
    if not run:
        return {}
    values = dict(sorted(run.values.get(source, {}).get(name, {}).items()))
    if name.startswith("buffer_fraction/") and not re.search(r"/b\d+$", name):  # the active buffer's
        sizes = run.values.get(source, {}).get("buffer_size", {})
        values = {seed: (math.nan if sizes.get(seed, 1.0) == 0 else v) for seed, v in values.items()}
    return values



MAX_POINTS = 100  # log points kept per curve in the committed metrics.csv.gz


def inflight(data: Path, experiment: str, name: str) -> Path:
    """Where ``docs/results/carry.sh`` keeps an unfinished run's folder between machines, beside
    ``data``: ``inflight/<experiment>/<run folder>.txz``, and for a repeat (``data`` named like
    :data:`REPEATS`) ``inflight/repeats/<experiment>/<run folder>.txz``."""
    under = Path(REPEATS.name) if Path(data).name == REPEATS.name else Path()
    return Path(data).parent / "inflight" / under / experiment / f"{name}.txz"


def _out(doc: dict) -> str | None:
    """The ``--out`` folder a run's ``config.json`` says it was started with (None if it names none):
    the same for every part of one run, wherever it was resumed."""
    command = doc.get("command") or []
    return next((command[i + 1] for i, arg in enumerate(command[:-1]) if arg == "--out"), None)


def collect(run: Path, data: Path = DATA) -> list[Path]:
    """Copy a finished run (one algorithm's folder, or a folder of them) into
    ``data/<experiment>/<algo>-s<first seed>/``: its ``config.json``, ``summary.json``,
    ``evaluate.json`` (and ``evaluate-mode.json``) and, gzipped, the rows of ``metrics.csv`` the page draws (:data:`~tools.results.claims.SECTIONS`'
    curves, at most :data:`MAX_POINTS` evenly spaced log points), and deletes the run's
    :func:`inflight` archive. Returns the folders written."""
    run = Path(run)
    folders = [run] if (run / "summary.json").is_file() else sorted(p.parent for p in run.glob("*/summary.json"))
    if not folders:
        raise ConfigError(f"collect: no finished run (summary.json) in {run}")
    written = []
    for folder in folders:
        summary = outputs.read_json(folder / "summary.json")
        exp, algo = summary["experiment"], summary["algo"]
        doc = outputs.read_json(folder / "config.json")
        for source in EVALUATIONS:  # refused before anything is copied
            if (folder / f"{source}.json").is_file():
                _evaluation(folder, algo, doc, source)
        name = re.sub(r"[^a-z0-9]+", "-", run_label(summary, doc)).strip("-")
        target = Path(data) / exp / f"{name}-s{summary['seeds'][0]}"
        finished = (target / "summary.json").is_file()  # the target holds a finished run's data
        config = target / "config.json"
        held_out = _out(outputs.read_json(config)) if finished and config.is_file() else None
        if held_out not in (None, _out(doc)):  # a finished run's data are replaced by the same run's alone
            raise ConfigError(f"collect: {target} holds the finished run trained into {held_out} and {folder} is "
                              f"another ({_out(doc)}); nothing written (a committed run trained again goes into "
                              "the repeats folder: --collect-repeat)")
        held = outputs.read_json(target / "summary.json").get("preset") if finished else None
        if held not in (None, summary["preset"]):  # the page labels only some presets (SCALE_PRESETS)
            raise ConfigError(f"collect: {target} holds the {held!r} preset's run and {folder} is the "
                              f"{summary['preset']!r} preset's; nothing written (a preset the page compares "
                              f"with its claims' runs needs its own label: tools/results/claims.py SCALE_PRESETS)")
        target.mkdir(parents=True, exist_ok=True)
        for name in ("config.json", "summary.json", *(f"{source}.json" for source in EVALUATIONS)):  # each whole or not
            if (folder / name).is_file():
                atomic_write(target / name, lambda f, src=folder / name: f.write(src.read_bytes()), binary=True)
        keep = set(SECTIONS.get(exp, ([], [], []))[2]) | {m.split(":", 1)[1] for e, _, metrics in EXTRA_TABLES.values()
                                                           if e == exp for m in metrics if m.startswith("run:")}
        rows = [r for r in outputs.read_metrics_csv(folder / "metrics.csv") if r[2] in keep]
        steps = sorted({r[1] for r in rows})
        kept = {steps[i] for i in np.unique(np.linspace(0, len(steps) - 1, min(len(steps), MAX_POINTS)).round()
                                            .astype(int))} if steps else set()
        outputs.write_metrics_csv(target / "metrics.csv.gz", (r for r in rows if r[1] in kept))
        (target / PROGRESS).unlink(missing_ok=True)  # collected while it trained: it is finished now
        inflight(data, exp, folder.name).unlink(missing_ok=True)  # carried across machines: no longer needed
        written.append(target)
    return written
