"""What every experiment writes into its output folder, atomically.

* ``config.json``: everything needed to rerun (experiment, algorithm, preset, seeds, the resolved
  configuration, the command line, the package version).
* ``metrics.csv``: long format, one row per (seed, step, metric, value).
* ``summary.json``: ``{"experiment", "algo", "preset", "seeds", "metrics": {NAME: {"mean", "std",
  "per_seed"}}}`` of final values; ``std`` with ddof 1 (null for one seed).
* PNG plots.

Each file is written to a temporary name beside it and moved into place, so a killed run leaves no
half-written file; a folder holding a run is reused only to resume it."""

from __future__ import annotations

import csv
import gzip
import io
import json
import math
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np

from remidi.errors import COMMAND_LINE, ConfigError, Naming
from remidi.files import atomic_write, remove_temporaries


def prepare_out_dir(out: Path, *, resume: bool = False, create: bool = True, naming: Naming = COMMAND_LINE) -> Path:
    """Check that ``out`` can receive a new run (or holds the run to resume); create it unless
    ``create`` is False (check only). ``naming``: the caller's words in its errors."""
    out = Path(out)
    flag = naming.resume if resume else naming.out
    if out.exists() and not out.is_dir():
        raise ConfigError(f"{flag}: {out} exists and is not a folder")
    holds_run = (out / "config.json").exists()
    if resume and not out.exists():
        raise ConfigError(f"{flag}: {out} does not exist")
    if resume and not holds_run:
        raise ConfigError(f"{flag}: {out} holds no run (no config.json)")
    if not resume and out.is_dir() and not holds_run:  # a several-algorithm run: one sub-folder per algorithm
        holds_run = any((sub / "config.json").exists() for sub in out.iterdir() if sub.is_dir())
    if not resume and holds_run:
        raise ConfigError(f"{flag}: {out} already holds a run; choose another folder or pass {naming.resuming(out)}")
    if not resume:
        existing = next(p for p in (out, *out.parents) if p.exists())  # the folder it will be made in
        if not existing.is_dir():
            raise ConfigError(f"{flag}: {out} cannot be made: {existing} is a file, not a folder")
        if not os.access(existing, os.W_OK | os.X_OK):
            raise ConfigError(f"{flag}: {out} cannot be made: {existing} is not writable")
    if create:
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise ConfigError(f"{flag}: {out} cannot be made ({err.strerror or type(err).__name__})") from None
    return out


OUTPUT_FILES = ("config.json", "metrics.csv", "summary.json")  # written by the run alone (not evaluate, render)


def remove_stale_temporaries(folder: Path) -> list[Path]:
    """Delete the temporaries an interrupted write left in ``folder`` (``.<name>.<random>.tmp`` of
    :data:`OUTPUT_FILES`; a plot's ``.<plot>.png[.<pid>].tmp.png`` whose process is gone). Called by
    --resume under :func:`folder_lock`; a live ``evaluate`` or ``render`` process's plots are kept."""
    plots = list(folder.glob(".*.png.tmp.png"))  # before plots carried their process id
    for path in folder.glob(".*.png.*.tmp.png"):
        pid = path.name.split(".")[-3]
        if pid.isdigit() and not _alive(int(pid)):
            plots.append(path)
    for path in plots:
        path.unlink(missing_ok=True)
    return remove_temporaries(folder, OUTPUT_FILES) + plots


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process
        return True
    return True


def several_algorithm_run(folder: Path) -> bool:
    """Whether ``folder`` is one several-algorithm run: sub-folders named after their algorithm whose
    config.json lists several, theirs among them. A folder of separate runs is not."""
    if not Path(folder).is_dir():
        return False
    subs = [p for p in Path(folder).iterdir() if (p / "config.json").is_file()]
    try:
        saved = [read_json(p / "config.json") for p in subs]
        algos = saved[0].get("algos") if saved else None
        named = all(p.name == doc.get("algo") for p, doc in zip(subs, saved))
    except (OSError, ValueError, AttributeError):
        return False
    if algos is None:  # runs written before config.json recorded the algorithms
        return named and len(subs) > 1
    return (isinstance(algos, list) and len(algos) > 1 and all(isinstance(a, str) for a in algos)
            and named and all(p.name in algos for p in subs))


@contextmanager
def folder_lock(folder: Path, flag: str):
    """Within: this process holds an exclusive lock on run folder ``folder`` (``flock``; on NFS a
    POSIX lock on a hidden ``.remidi.lock``; none without locking), so a second writer (two
    ``--resume``, a scheduler's requeue) gets a one-line ConfigError, not interleaved checkpoints."""
    try:
        import fcntl

        fd = os.open(folder, os.O_RDONLY)
    except (ImportError, OSError):
        yield
        return
    busy = ConfigError(f"{flag}: {folder} is in use by another remidi process (a run writing there); wait for it "
                       f"to end, or write elsewhere")
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise busy from None
        except OSError:  # NFS: flock becomes a POSIX lock, which needs a file open for writing
            os.close(fd)
            fd = os.open(Path(folder) / ".remidi.lock", os.O_RDWR | os.O_CREAT, 0o666)
            try:
                fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except (BlockingIOError, PermissionError):
                raise busy from None
            except OSError:  # no locks at all here
                pass
        yield
    finally:
        os.close(fd)  # releases the lock


def _clean(obj: Any) -> Any:
    """JSON-safe copy: NumPy scalars/arrays → Python, non-finite floats → None."""
    if isinstance(obj, Mapping):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        value = float(obj)
        return value if math.isfinite(value) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def write_json(path: Path, obj: Any) -> None:
    atomic_write(path, lambda fh: json.dump(_clean(obj), fh, indent=2, allow_nan=False))


def read_json(path: Path) -> Any:
    with open(path) as fh:
        return json.load(fh)


def read_json_object(path: Path, flag: str, advice: str = "") -> dict:
    """A run file's JSON object; ConfigError (one line: ``flag``, the file, what is wrong, then
    ``advice``) when it cannot be read or is not an object (a damaged or hand-edited file)."""
    try:
        doc = read_json(path)
    except (OSError, ValueError) as err:  # ValueError: JSONDecodeError, UnicodeDecodeError
        detail = str(err).strip().splitlines()[0] if str(err).strip() else ""
        raise ConfigError(f"{flag}: {path} cannot be read ({type(err).__name__}{': ' + detail if detail else ''})"
                          f"{advice}") from None
    if not isinstance(doc, dict):
        raise ConfigError(f"{flag}: {path} is a JSON {type(doc).__name__}, not an object{advice}")
    return doc


def metric_rows(steps: np.ndarray, history: Mapping[str, np.ndarray], seeds: Iterable[int]) -> Iterable[tuple]:
    """Long-format rows ``(seed, step, metric, value)`` from ``history[name]`` f[S, T]."""
    seeds = list(seeds)
    for name, values in history.items():
        values = np.asarray(values, dtype=float)
        for s, seed in enumerate(seeds):
            for t, step in enumerate(steps):
                yield seed, int(step), name, float(values[s, t])


METRICS_HEADER = ["seed", "step", "metric", "value"]


def write_metrics_csv(path: Path, rows: Iterable[tuple]) -> None:
    """Long-format rows ``(seed, step, metric, value)``; gzipped (reproducibly: no time stamp)
    when ``path`` ends in ``.gz``."""
    def write_rows(fh):
        w = csv.writer(fh)
        w.writerow(METRICS_HEADER)
        for seed, step, name, value in rows:
            w.writerow([seed, step, name, repr(float(value))])

    def write_gzipped(raw):
        with gzip.GzipFile(filename="", fileobj=raw, mode="wb", mtime=0) as zipped, io.TextIOWrapper(zipped, newline="") as fh:
            write_rows(fh)

    if Path(path).suffix == ".gz":
        atomic_write(path, write_gzipped, binary=True)
    else:
        atomic_write(path, write_rows)


def read_metrics_csv(path: Path) -> list[tuple[int, int, str, float]]:
    """The rows :func:`write_metrics_csv` wrote; ConfigError (one line naming file and line) for an
    empty file, another header, or a malformed row."""
    rows = []
    with (gzip.open(path, "rt", newline="") if Path(path).suffix == ".gz" else open(path, newline="")) as fh:
        r = csv.reader(fh)
        header = next(r, None)
        if header is None:
            raise ConfigError(f"{path}, line 1: the file is empty (expected the header {','.join(METRICS_HEADER)})")
        if header != METRICS_HEADER:
            raise ConfigError(f"{path}, line 1: expected the header {','.join(METRICS_HEADER)}, "
                              f"got {','.join(header)!r}")
        for row in r:
            try:
                seed, step, name, value = row
                rows.append((int(seed), int(step), name, float(value)))
            except ValueError:
                raise ConfigError(f"{path}, line {r.line_num}: expected seed,step,metric,value with integer "
                                  f"seed and step and a number value, got {','.join(row)!r}") from None
    return rows


def summarize(final: Mapping[str, np.ndarray]) -> dict[str, dict[str, Any]]:
    """``{name: {"mean", "std", "per_seed"}}`` of final values f[S]; ``std`` ddof 1, NaN (null in
    JSON) for one seed."""
    out = {}
    for name, values in final.items():
        values = np.asarray(values, dtype=float)
        std = float(values.std(ddof=1)) if values.size > 1 else float("nan")
        out[name] = {"mean": float(values.mean()), "std": std, "per_seed": values.tolist()}
    return out


def write_summary(path: Path, *, experiment: str, algo: str, preset: str, seeds: list[int],
                  final: Mapping[str, np.ndarray], **extra: Any) -> dict:
    summary = {"experiment": experiment, "algo": algo, "preset": preset, "seeds": seeds,
               "metrics": summarize(final), **extra}
    write_json(path, summary)
    return summary
