"""``remidi table RUN ...``: one Markdown table of finished runs (e.g. the paper's Table 1).

A run folder holds ``summary.json`` or sub-folders that do. Each row is one experiment ×
algorithm: per metric, mean ± sample std (ddof 1), IQM and the 95% percentile-bootstrap interval
of the mean (:mod:`remidi.stats`; :data:`CI_SEED` makes it reproducible); then seeds, preset and
wall time. The interval is of the mean, which the results page's verdicts judge.

``last=K`` (``--last K``) uses each seed's mean over the last K logged points of ``metrics.csv``
(NaN points left out) for noisy evaluation metrics."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from remidi import stats
from remidi.errors import ConfigError
from remidi.experiments import outputs
from remidi.runs import require_folder

# remidi.belief_spread's default (engine/config.py, ReMiDiConfig; this module stays free of JAX):
# a learned-tracker run with another value is named with it (label)
BELIEF_SPREAD = 6.0

CI_SEED = 0  # the bootstrap's random seed: the same data give the same table, digit for digit
NOTE = ("± is the sample standard deviation over seeds (ddof 1); IQM is the interquartile mean "
        "(mean of the middle 50% of seeds); 95% CI is the percentile-bootstrap confidence interval "
        f"of the mean over seeds ({stats.N_RESAMPLES:,} resamples).")


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
    """The ``summary.json`` documents under ``folders`` in the order given (sub-folders in
    ``config.json``'s algorithm order, else by name)."""
    found = []
    for folder in map(Path, folders):
        require_folder("RUN", folder)
        if (folder / "summary.json").is_file():
            found.append({**_read_summary(folder / "summary.json"), "folder": str(folder)})
            continue
        subs = sorted(folder.glob("*/summary.json")) if folder.is_dir() else []
        if not subs:
            raise ConfigError(f"RUN: no summary.json in {folder} (give finished run folders, or folders of them)")
        docs = [{**_read_summary(p), "folder": str(p.parent)} for p in subs]
        config = subs[0].parent / "config.json"  # each algorithm's config.json records the run's order
        order = outputs.read_json_object(config, "RUN").get("algos", []) if config.is_file() else []
        docs.sort(key=lambda d: (order.index(d["algo"]) if d["algo"] in order else len(order), d["algo"]))
        found.extend(docs)
    return found


def unfinished(folders: list[Path]) -> list[tuple[Path, Path]]:
    """The runs in ``folders``' sub-folders without summary.json yet, each with the folder whose
    --resume finishes it; :func:`summaries` leaves them out and the commands say so."""
    found = []
    for folder in map(Path, folders):
        if folder.is_dir() and not (folder / "summary.json").is_file():
            whole = outputs.several_algorithm_run(folder)
            found += sorted((sub, folder if whole else sub) for sub in folder.iterdir()
                            if (sub / "config.json").is_file() and not (sub / "summary.json").is_file())
    return found


def label(algo: str, config: dict, command: list | None = None) -> str:
    """How a table and the results page name an algorithm's runs: a learned generator's with its
    regret estimator (``paired (perfect)``, ``remidi-paired (perfect, belief)``); a buffer sequence's
    with what differs from its exact single-policy form (``remidi (belief, margin 2)``,
    ``remidi (tolerance)``, ``remidi (rehearsal 0.2)``, ...; ``remidi (masked)`` where the command
    named the default policy, a baseline beside its variants); the others by name."""
    estimator = config.get("paired", {}).get("estimator")
    if algo in ("paired", "remidi-paired") and estimator:
        belief = algo == "remidi-paired" and config.get("remidi", {}).get("tracker") == "belief"
        return f"{algo} ({estimator}, belief)" if belief else f"{algo} ({estimator})"
    r = config.get("remidi", {})
    parts = []
    if r.get("tracker") == "belief":
        parts.append("belief")
        if r.get("belief_margin", 1e-3) != 1e-3:
            parts.append(f"margin {r['belief_margin']:g}")
    if r.get("tracker") == "tolerance":
        parts.append("tolerance")
    if r.get("tracker") == "simulated":
        parts.append("simulated, ratio" if r.get("belief_reference") else "simulated")
        if r.get("belief_false_rate", 0.05) != 0.05:
            parts.append(f"false rate {r['belief_false_rate']:g}")
        if r.get("belief_margin", 1e-3) != 1e-3:
            parts.append(f"margin {r['belief_margin']:g}")
    # a run from before remidi.belief_spread has no such key and is named as it always was
    if r.get("tracker") in ("belief", "simulated") and r.get("belief_spread", BELIEF_SPREAD) != BELIEF_SPREAD:
        parts.append(f"spread {r['belief_spread']:g}")
    if r.get("policy") == "combine":
        parts.append("combine")
    elif any(str(token).endswith("remidi.policy=masked") for token in command or []):
        parts.append("masked")
    if r.get("rehearsal"):
        parts.append(f"rehearsal {r['rehearsal']:g}")
    return f"{algo} ({', '.join(parts)})" if algo.startswith("remidi") and parts else algo


def per_seed(entry: dict | None) -> list[float]:
    """A metric entry's per-seed values f[S] (None → NaN); ``[mean]`` without them; ``[]`` for no entry."""
    if entry is None:
        return []
    values = entry.get("per_seed", [entry.get("mean")])
    return [math.nan if v is None else float(v) for v in values]


def _cells(entry: dict | None, digits: int) -> list[str]:
    """The metric's three cells: mean ± sample std (the mean alone for one seed), IQM, 95% CI of the
    mean; ``n/a`` where undefined."""
    values = per_seed(entry)
    mean, std = stats.mean_and_sample_std(values)
    if not math.isfinite(mean):
        return ["n/a"] * 3
    low, high = stats.bootstrap_ci(values, np.mean, seed=CI_SEED)
    return [f"{mean:.{digits}f}" if len(values) <= 1 else f"{mean:.{digits}f} ± {std:.{digits}f}",
            f"{float(stats.iqm(values)):.{digits}f}",
            f"[{low:.{digits}f}, {high:.{digits}f}]" if math.isfinite(low) else "n/a"]


def _digits(metric: str) -> int:
    """Decimals a metric is shown with: 3 for the tabular games, 2 for shares and solve rates, 1 else."""
    kind = metric.split("/")[0]
    if kind in ("regret", "adversary_prob", "policy"):  # the tabular games' values near 0.175, 1/64
        return 3
    return 2 if kind in ("replay_fraction", "buffer_fraction") or "solve_rate" in metric else 1


def windowed(doc: dict, metrics: list[str], last: int) -> dict[str, dict]:
    """``{metric: {"mean", "std", "per_seed"}}``: per seed the mean of the last ``last`` logged points
    (NaN left out), then over seeds (``std`` ddof 0; the table computes its own from ``per_seed``)."""
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


def _name(doc: dict) -> str:
    """The row's algorithm, by :func:`label` from the run's ``config.json`` (so ReMiDi variants differ),
    else by its summary."""
    config = Path(doc["folder"]) / "config.json"
    if not config.is_file():
        return doc["algo"]
    run = outputs.read_json_object(config, "RUN")
    if not isinstance(run.get("config", {}), dict):
        raise ConfigError(f"RUN: {config}: config is not an object")
    return label(doc["algo"], run.get("config", {}), run.get("command"))


SHARES = ("replay_fraction", "buffer_fraction")  # the level shares that carry the UED experiments' claims


def evaluation_sets(names: list[str]) -> list[str]:
    """The evaluation sets among metric ``names``, in first-metric order: those with a
    ``discounted_return/<set>`` (every set logs it, no training metric is named so)."""
    sets = {name.split("/", 1)[1] for name in names if name.startswith("discounted_return/") and name.count("/") == 1}
    order = [name.split("/", 1)[1] for name in names if name.count("/") == 1 and name.split("/", 1)[1] in sets]
    return list(dict.fromkeys(order))


def primary_metric(names: list[str], eval_set: str) -> str:
    """An evaluation set's primary metric among ``names``: its solve rate, else its return."""
    return f"solve_rate/{eval_set}" if f"solve_rate/{eval_set}" in names else f"return/{eval_set}"


def default_metrics(docs: list[dict]) -> list[str]:
    """The columns without ``--metrics``, per experiment in run order: each evaluation set's
    :func:`primary_metric` where the headline (the summary's first metric) is one of them, else the
    headline that sums them up (``solve_rate/mean``); then the first two level shares
    (``replay_fraction/<tag>``, ``buffer_fraction/<tag>``). Without shares or sets: the first three metrics."""
    first: dict[str, dict] = {}
    for doc in docs:
        first.setdefault(doc["experiment"], doc)
    metrics: list[str] = []
    for doc in first.values():
        names = list(doc["metrics"])
        shares = [name for name in names if name.split("/")[0] in SHARES][:2]
        primaries = [primary_metric(names, s) for s in evaluation_sets(names)]
        headline = names[:1] if not primaries or names[0] not in primaries else primaries
        metrics += headline + shares if shares or primaries else names[:3]
    return list(dict.fromkeys(metrics))


def markdown_table(docs: list[dict], metrics: list[str] | None = None, last: int | None = None) -> str:
    """The table as Markdown, then a blank line and :data:`NOTE`; ``metrics`` default to
    :func:`default_metrics`; ``last``: :func:`windowed`."""
    if not docs:
        raise ConfigError("RUN: no finished runs given")
    if last is not None and (not isinstance(last, int) or last < 1):
        raise ConfigError(f"--last: must be an integer ≥ 1, got {last!r}")
    metrics = metrics or default_metrics(docs)
    known = {name for d in docs for name in d["metrics"]}
    unknown = [m for m in metrics if m not in known]
    if unknown:
        raise ConfigError(f"--metrics: no run has {', '.join(map(repr, unknown))}; allowed: {', '.join(sorted(known))}")
    head = ["experiment", "algorithm", *(c for m in metrics for c in (m, f"{m} IQM", f"{m} 95% CI")),
            "seeds", "preset", "wall time"]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for d in docs:
        wall = d.get("wall_s")
        wall = "n/a" if wall is None else (f"{wall / 60:.1f} min" if wall >= 60 else f"{wall:.0f} s")
        if d.get("resumed"):
            wall += " (last part)"
        values = windowed(d, metrics, last) if last is not None else d["metrics"]
        cells = [d["experiment"], _name(d), *(c for m in metrics for c in _cells(values.get(m), _digits(m))),
                 str(len(d["seeds"])), d["preset"], wall]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n\n" + NOTE
