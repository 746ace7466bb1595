"""``remidi compare RUN ... --metric M --algo A --baseline B``: is A better than B on M?

Per experiment among the finished runs (each holding both algorithms), from ``M``'s per-seed values
(``summary.json``, or with ``--last K`` the mean of the last K points): each algorithm's mean ±
std (ddof 1), IQM and 95% bootstrap intervals; the difference of means; the probability of
improvement P(A > B) + ½ P(A = B) with its interval; the exact one-sided permutation p-value (by
seed with ``--paired``) and, over several experiments, its Holm–Bonferroni adjustment and the
averaged probability of improvement (rliable's scale-free aggregate). ``--out FIG.png`` draws the
interval plot. :func:`compare` works from per-seed values, :func:`compare_runs` from summaries.

Run folders of one experiment × algorithm are merged; a seed in two of them is an error."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping

import numpy as np

from remidi import stats
from remidi.errors import ConfigError
from remidi.runs.table import CI_SEED, _digits, per_seed, windowed

CONFIDENCE = 0.95


def describe(values: Mapping[int, float]) -> dict:
    """``{"seeds", "n", "mean", "std", "iqm", "mean_ci", "iqm_ci"}`` of one algorithm's
    ``{seed: value}`` (std ddof 1; intervals: percentile bootstrap over seeds)."""
    x = np.array(list(values.values()), dtype=float)
    mean, std = stats.mean_and_sample_std(x)
    return {"seeds": list(values), "n": len(x), "mean": mean, "std": std,
            "iqm": float(stats.iqm(x)) if len(x) and not np.isnan(x).any() else math.nan,
            "mean_ci": list(stats.bootstrap_ci(x, np.mean, confidence=CONFIDENCE, seed=CI_SEED)),
            "iqm_ci": list(stats.bootstrap_ci(x, stats.iqm, confidence=CONFIDENCE, seed=CI_SEED))}


def compare(algo: Mapping[str, Mapping[int, float]], baseline: Mapping[str, Mapping[int, float]], *,
            paired: bool = False) -> dict:
    """The comparison of ``algo`` against ``baseline`` (each ``{experiment: {seed: value}}``, the
    same experiments) as a JSON-ready dict::

        {"paired": bool, "confidence": 0.95,
         "experiments": {experiment: {"algo": {seeds, n, mean, std, iqm, mean_ci, iqm_ci},
                                      "baseline": {...}, "difference": mean(algo) − mean(baseline),
                                      "probability_of_improvement": P, "poi_ci": [low, high],
                                      "p_value": one-sided, "exact": bool, "p_holm": Holm-adjusted}},
         "probability_of_improvement": P averaged over experiments, "poi_ci": [low, high]}

    ``paired``: pair by seed; ConfigError unless both have the same seeds everywhere. Deterministic."""
    if list(algo) != list(baseline):
        raise ConfigError(f"compare: the algorithm ran {', '.join(algo)} and the baseline {', '.join(baseline)}; "
                          "both need the same experiments")
    rows, x_all, y_all, x_strata, y_strata = {}, [], [], [], []
    for exp in algo:
        a, b = dict(algo[exp]), dict(baseline[exp])
        if paired and sorted(a) != sorted(b):
            raise ConfigError(f"--paired: on {exp} the algorithm has seeds {sorted(a)} and the baseline "
                              f"{sorted(b)}; pairing needs the same seeds")
        x = np.array(list(a.values()), float)
        y = np.array([b[s] for s in a] if paired else list(b.values()), float)  # paired: in x's seed order
        poi = stats.probability_of_improvement(x, y, confidence=CONFIDENCE, seed=CI_SEED)
        rows[exp] = {"algo": describe(a), "baseline": describe(b),
                     "difference": float(np.mean(x) - np.mean(y)) if len(x) and len(y) else math.nan,
                     "probability_of_improvement": poi.value, "poi_ci": [poi.low, poi.high],
                     "p_value": stats.permutation_pvalue(x, y, paired=paired, alternative="greater"),
                     "exact": stats.permutation_count(len(x), len(y), paired) <= stats.MAX_EXACT}
        x_all += list(x)
        y_all += list(y)
        x_strata += [exp] * len(x)
        y_strata += [exp] * len(y)
    for exp, p in zip(rows, stats.holm([r["p_value"] for r in rows.values()])):
        rows[exp]["p_holm"] = float(p)
    pooled = stats.probability_of_improvement(x_all, y_all, x_strata=x_strata, y_strata=y_strata,
                                              confidence=CONFIDENCE, seed=CI_SEED)
    return {"paired": paired, "confidence": CONFIDENCE, "experiments": rows,
            "probability_of_improvement": pooled.value, "poi_ci": [pooled.low, pooled.high]}


def _values(docs: list[dict], metric: str, algo: str, last: int | None) -> dict[str, dict[int, float]]:
    """``{experiment: {seed: value}}`` of ``metric`` for ``algo`` over ``docs`` (runs merged)."""
    out: dict[str, dict[int, float]] = {}
    where: dict[tuple[str, int], str] = {}
    for d in docs:
        if d["algo"] != algo or metric not in d["metrics"]:
            continue
        entry = windowed(d, [metric], last)[metric] if last is not None else d["metrics"][metric]
        values = per_seed(entry)
        if len(values) != len(d["seeds"]):
            raise ConfigError(f"RUN: {d['folder']} has {len(values)} values of {metric} for {len(d['seeds'])} seeds")
        for seed, value in zip(d["seeds"], values):
            if (d["experiment"], seed) in where:
                raise ConfigError(f"RUN: seed {seed} of {d['experiment']} / {algo} is in two runs "
                                  f"({where[d['experiment'], seed]}, {d['folder']})")
            where[d["experiment"], seed] = d["folder"]
            out.setdefault(d["experiment"], {})[seed] = value
    return out


def compare_runs(docs: list[dict], metric: str, algo: str, baseline: str, *, paired: bool = False,
                 last: int | None = None) -> dict:
    """:func:`compare` on the runs ``docs``, with ``"metric"``, ``"algo"`` and ``"baseline"`` added;
    every experiment must have both. ConfigError (one line) for an unknown metric or algorithm."""
    if not docs:
        raise ConfigError("RUN: no finished runs given")
    if last is not None and (not isinstance(last, int) or last < 1):
        raise ConfigError(f"--last: must be an integer ≥ 1, got {last!r}")
    known = sorted({name for d in docs for name in d["metrics"]})
    if metric not in known:
        raise ConfigError(f"--metric: no run has {metric!r}; allowed: {', '.join(known)}")
    algos = list(dict.fromkeys(d["algo"] for d in docs))
    for flag, name in (("--algo", algo), ("--baseline", baseline)):
        if name not in algos:
            raise ConfigError(f"{flag}: no run of {name!r}; allowed: {', '.join(algos)}")
    if algo == baseline:
        raise ConfigError(f"--baseline: {baseline!r} is also --algo; compare two different algorithms")
    a, b = _values(docs, metric, algo, last), _values(docs, metric, baseline, last)
    for name, mine, other in ((algo, a, b), (baseline, b, a)):
        missing = [exp for exp in other if exp not in mine]
        if missing:
            raise ConfigError(f"RUN: no run of {name} with {metric} on {', '.join(missing)}; "
                              f"every experiment needs both algorithms")
    return {"metric": metric, "algo": algo, "baseline": baseline, **compare(a, {e: b[e] for e in a}, paired=paired)}


def _f(value: float, digits: int) -> str:
    return "n/a" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def _ci(ci, digits: int) -> str:
    return "n/a" if not math.isfinite(ci[0]) else f"[{ci[0]:.{digits}f}, {ci[1]:.{digits}f}]"


def _p(value: float) -> str:
    return "n/a" if not math.isfinite(value) else f"{value:.3g}"


def format_comparison(result: dict) -> str:
    """The comparison as text (one block per experiment, then the average); ``result`` from
    :func:`compare_runs`."""
    algo, base, metric = result["algo"], result["baseline"], result["metric"]
    digits = _digits(metric)
    width = max(len(algo), len(base))
    test = "paired by seed" if result["paired"] else "independent groups"
    lines = [f"{metric}: {algo} against {base} (one-sided: is {algo}'s mean higher?)"]
    rows = result["experiments"]
    for exp, r in rows.items():
        lines.append(f"\n{exp}")
        for name, side in ((algo, r["algo"]), (base, r["baseline"])):
            spread = "" if side["n"] <= 1 else f" ± {_f(side['std'], digits)}"
            lines.append(f"  {name:<{width}}  {side['n']:2d} seeds  mean {_f(side['mean'], digits)}{spread}  "
                         f"95% CI {_ci(side['mean_ci'], digits)}  IQM {_f(side['iqm'], digits)}")
        lines.append(f"  difference of means   {_f(r['difference'], digits)}")
        lines.append(f"  P({algo} > {base})  {_f(r['probability_of_improvement'], 2)}  "
                     f"95% CI {_ci(r['poi_ci'], 2)}")
        p_line = (f"  permutation p-value   {_p(r['p_value'])} ({'exact' if r['exact'] else 'Monte Carlo'}, "
                  f"one-sided, {test})")
        if len(rows) > 1:
            p_line += f"; Holm over {len(rows)} experiments: {_p(r['p_holm'])}"
        lines.append(p_line)
    if len(rows) > 1:
        lines.append(f"\naverage over {len(rows)} experiments: P({algo} > {base})  "
                     f"{_f(result['probability_of_improvement'], 2)}  95% CI {_ci(result['poi_ci'], 2)} "
                     f"(seeds resampled within each experiment)")
    lines.append("\n± is the sample standard deviation over seeds (ddof 1); intervals: percentile bootstrap "
                 f"over seeds ({stats.N_RESAMPLES:,} resamples); P(A > B) counts ties as ½.")
    return "\n".join(lines)


def comparison_figure(result: dict):
    """rliable-style interval figure: panels mean, IQM and P(algo > baseline), per experiment and
    algorithm a capped bar over the 95% interval and a white diamond at the estimate. Value axes
    reach past the intervals (P's past [0, 1]), so clipped ends stay visible."""
    import matplotlib.pyplot as plt

    from remidi.experiments.plots import _captioned, algorithm_style, padded  # sets the Agg backend

    algo, base, rows, metric = result["algo"], result["baseline"], result["experiments"], result["metric"]
    several = len(rows) > 1
    count = 2 * len(rows)
    fig, axes = plt.subplots(1, 3, figsize=(12, 1.9 + 0.42 * max(count, len(rows) + several)), layout="constrained")
    for ax, key, what in ((axes[0], "mean", "mean"), (axes[1], "iqm", "IQM")):
        labels, found = [], []
        for exp, r in rows.items():
            for name, side in ((algo, r["algo"]), (base, r["baseline"])):
                y = len(labels)
                labels.append(f"{exp} / {name} ({side['n']})" if several else f"{name} ({side['n']} seeds)")
                _interval(ax, y, side[key], side[f"{key}_ci"], algorithm_style(name)["color"])
                found += [v for v in (side[key], *side[f"{key}_ci"]) if math.isfinite(v)]
        _rows(ax, labels)
        if found:
            ax.set_xlim(*padded(min(found), max(found)))
        ax.locator_params(axis="x", nbins=5)
        ax.set_title(f"{what} over seeds", fontsize=9)
        ax.set_xlabel(f"{metric} ({what} over seeds)", fontsize=9)
    ax = axes[2]
    labels = list(rows) + (["average"] if several else [])
    points = [(r["probability_of_improvement"], r["poi_ci"]) for r in rows.values()]
    if several:
        points.append((result["probability_of_improvement"], result["poi_ci"]))
    for y, (value, ci) in enumerate(points):
        _interval(ax, y, value, ci, algorithm_style(algo)["color"])
    ax.axvline(0.5, color="k", linestyle="--", linewidth=0.8)
    ax.set_xlim(*padded(0.0, 1.0))
    _rows(ax, labels)
    ax.set_title(f"P({algo} > {base})", fontsize=9)
    ax.set_xlabel("probability of improvement", fontsize=9)
    for ax in axes:
        ax.grid(alpha=0.3, axis="x")
    _captioned(fig, f"{metric}: {algo} against {base}",
               f"bar: the {CONFIDENCE:.0%} interval (percentile bootstrap over seeds, {stats.N_RESAMPLES:,} "
               f"resamples), its ends capped; white diamond: the estimate; (n): seeds; P({algo} > {base}): the "
               f"probability that a seed of {algo} scores higher than one of {base}, ties counting ½; dashed: "
               f"P = 0.5, no difference")
    return fig


def plot_comparison(result: dict, path: Path) -> None:
    """Save :func:`comparison_figure` into the PNG ``path``."""
    from remidi.experiments.plots import _save

    _save(comparison_figure(result), path)


def _rows(ax, labels: list[str]) -> None:
    """One row per label, top to bottom, with room above the first and below the last."""
    ax.set_yticks(range(len(labels)), labels, fontsize=8)
    ax.set_ylim(len(labels) - 0.3, -0.7)


def _interval(ax, y: float, value: float, ci, color: str) -> None:
    """One interval-plot row: a bar over ``ci`` capped at both ends and a diamond at ``value``
    (undefined parts left out). Its ± 0.4 height counts for autoscaling, keeping caps off the frame."""
    ends = [v for v in (*ci, value) if math.isfinite(v)]
    if ends:
        ax.update_datalim([(min(ends), y - 0.4), (max(ends), y + 0.4)])
    if math.isfinite(ci[0]) and math.isfinite(ci[1]):
        ax.plot([ci[0], ci[1]], [y, y], color=color, linewidth=8, alpha=0.6, solid_capstyle="butt")
        ax.plot([ci[0], ci[1]], [y, y], linestyle="none", marker="|", markersize=15, markeredgewidth=2, color=color)
    if math.isfinite(value):
        ax.plot([value], [y], linestyle="none", marker="D", markersize=6, markerfacecolor="white",
                markeredgecolor="k", markeredgewidth=1.2)
