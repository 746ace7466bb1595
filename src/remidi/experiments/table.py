"""``remidi table RUN ...``: one Markdown table of finished runs (e.g. the paper's Table 1).

A run folder holds ``summary.json`` (one algorithm) or sub-folders that do (several algorithms
of one ``remidi run``). Each row is one experiment × algorithm: the chosen metrics as
mean ± std over seeds, then the seeds, the preset and the training wall time.

``last=K`` (``--last K``) replaces each seed's final value by its mean over the last K logged
points of ``metrics.csv`` (for evaluation metrics whose single last point is noisy, such as a
held-out solve rate); points where a metric is undefined (NaN) are left out of that mean.
"""

from __future__ import annotations

import math
from pathlib import Path

from remidi.errors import ConfigError
from remidi.experiments import outputs


def _read_summary(path: Path) -> dict:
    """One run's ``summary.json``; ConfigError (one line, naming the file) if it is not one."""
    try:
        doc = outputs.read_json(path)
        if not isinstance(doc, dict):
            raise TypeError(f"a JSON {type(doc).__name__}, not an object")
        missing = [key for key in ("experiment", "algo", "preset", "seeds", "metrics") if key not in doc]
        if missing:
            raise KeyError(", ".join(missing))
        if not isinstance(doc["metrics"], dict) or not all(isinstance(m, dict) for m in doc["metrics"].values()):
            raise TypeError("metrics is not an object of {mean, std, per_seed} entries")
    except (OSError, ValueError) as err:
        raise ConfigError(f"RUN: {path} cannot be read ({type(err).__name__}: "
                          f"{(str(err).strip().splitlines() or [''])[0]})") from None
    except KeyError as err:
        raise ConfigError(f"RUN: {path} is not a run summary (no {err.args[0]})") from None
    except TypeError as err:
        raise ConfigError(f"RUN: {path} is not a run summary ({err})") from None
    return doc


def summaries(folders: list[Path]) -> list[dict]:
    """The ``summary.json`` documents under ``folders``, in the order given (sub-folders sorted
    by the algorithm order recorded in ``config.json``, else by name)."""
    found = []
    for folder in map(Path, folders):
        if (folder / "summary.json").is_file():
            found.append({**_read_summary(folder / "summary.json"), "folder": str(folder)})
            continue
        subs = sorted(folder.glob("*/summary.json")) if folder.is_dir() else []
        if not subs:
            raise ConfigError(f"RUN: no summary.json in {folder} (give finished run folders, or folders of them)")
        docs = [{**_read_summary(p), "folder": str(p.parent)} for p in subs]
        config = subs[0].parent / "config.json"  # each algorithm's config.json records the run's order
        order = outputs.read_json(config).get("algos", []) if config.is_file() else []
        docs.sort(key=lambda d: (order.index(d["algo"]) if d["algo"] in order else len(order), d["algo"]))
        found.extend(docs)
    return found


def _cell(entry: dict | None, digits: int) -> str:
    if entry is None or entry.get("mean") is None or not math.isfinite(entry["mean"]):
        return "n/a"
    mean, std = entry["mean"], entry.get("std") or 0.0
    if len(entry.get("per_seed", [])) <= 1:
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


def _digits(metric: str) -> int:
    kind = metric.split("/")[0]
    if kind in ("regret", "adversary_prob", "policy"):  # the tabular games' values near 0.175, 1/64
        return 3
    return 2 if kind in ("replay_fraction", "buffer_fraction", "solve_rate") else 1


def windowed(doc: dict, metrics: list[str], last: int) -> dict[str, dict]:
    """``{metric: {"mean", "std", "per_seed"}}``: per seed, the mean of the metric's last ``last``
    logged points in the run's ``metrics.csv`` (NaN points left out); then mean and std over seeds."""
    path = Path(doc["folder"]) / "metrics.csv"
    if not path.is_file():
        raise ConfigError(f"--last: no metrics.csv in {doc['folder']}")
    series: dict[tuple[str, int], list[tuple[int, float]]] = {}
    for seed, step, name, value in outputs.read_metrics_csv(path):
        if name in metrics:
            series.setdefault((name, seed), []).append((step, value))
    per_seed = {}
    for name in metrics:
        per_seed[name] = []
        for seed in doc["seeds"]:
            points = [v for _, v in sorted(series.get((name, seed), []))[-last:] if math.isfinite(v)]
            per_seed[name].append(sum(points) / len(points) if points else math.nan)
    return outputs.summarize(per_seed)  # a seed without a defined point makes the mean NaN: n/a


def markdown_table(docs: list[dict], metrics: list[str] | None = None, last: int | None = None) -> str:
    """The table as Markdown; ``metrics`` default to the first three of the first summary; with
    ``last``, each metric is the mean of its last ``last`` logged points (:func:`windowed`)."""
    if not docs:
        raise ConfigError("RUN: no finished runs given")
    if last is not None and (not isinstance(last, int) or last < 1):
        raise ConfigError(f"--last: must be an integer ≥ 1, got {last!r}")
    metrics = metrics or list(docs[0]["metrics"])[:3]
    known = {name for d in docs for name in d["metrics"]}
    unknown = [m for m in metrics if m not in known]
    if unknown:
        raise ConfigError(f"--metrics: no run has {', '.join(map(repr, unknown))}; allowed: {', '.join(sorted(known))}")
    head = ["experiment", "algorithm", *metrics, "seeds", "preset", "wall time"]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for d in docs:
        wall = d.get("wall_s")
        wall = "n/a" if wall is None else (f"{wall / 60:.1f} min" if wall >= 60 else f"{wall:.0f} s")
        if d.get("resumed"):
            wall += " (last part)"
        values = windowed(d, metrics, last) if last is not None else d["metrics"]
        cells = [d["experiment"], d["algo"], *(_cell(values.get(m), _digits(m)) for m in metrics),
                 str(len(d["seeds"])), d["preset"], wall]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
