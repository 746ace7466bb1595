"""``remidi table RUN ...``: one Markdown table of finished runs (e.g. the paper's Table 1).

A run folder holds ``summary.json`` (one algorithm) or sub-folders that do (several algorithms
of one ``remidi run``). Each row is one experiment × algorithm: the chosen metrics as
mean ± std over seeds, then the seeds, the preset and the training wall time.
"""

from __future__ import annotations

import math
from pathlib import Path

from remidi.errors import ConfigError
from remidi.experiments import outputs


def summaries(folders: list[Path]) -> list[dict]:
    """The ``summary.json`` documents under ``folders``, in the order given (sub-folders sorted
    by the algorithm order recorded in ``config.json``, else by name)."""
    found = []
    for folder in map(Path, folders):
        if (folder / "summary.json").is_file():
            found.append(outputs.read_json(folder / "summary.json"))
            continue
        subs = sorted(folder.glob("*/summary.json")) if folder.is_dir() else []
        if not subs:
            raise ConfigError(f"RUN: no summary.json in {folder} (give finished run folders, or folders of them)")
        docs = [outputs.read_json(p) for p in subs]
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
    return 2 if metric.split("/")[0] in ("replay_fraction", "buffer_fraction", "solve_rate") else 1


def markdown_table(docs: list[dict], metrics: list[str] | None = None) -> str:
    """The table as Markdown; ``metrics`` default to the first three of the first summary."""
    if not docs:
        raise ConfigError("RUN: no finished runs given")
    metrics = metrics or list(docs[0]["metrics"])[:3]
    head = ["experiment", "algorithm", *metrics, "seeds", "preset", "wall time"]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for d in docs:
        wall = d.get("wall_s")
        wall = "n/a" if wall is None else (f"{wall / 60:.1f} min" if wall >= 60 else f"{wall:.0f} s")
        if d.get("resumed"):
            wall += " (last part)"
        cells = [d["experiment"], d["algo"], *(_cell(d["metrics"].get(m), _digits(m)) for m in metrics),
                 str(len(d["seeds"])), d["preset"], wall]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
