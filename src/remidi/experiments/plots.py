"""Plots: panels of training curves, mean ± std over seeds.

Every algorithm keeps one colour, line style and marker in every plot of every experiment
(:func:`algorithm_style`), and the algorithms appear in the order the run was given them, so a
resumed run draws exactly what a fresh one does and two identical curves stay visible (different
dashes, markers at different positions).
"""

from __future__ import annotations

import math
import os
import textwrap
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

# one style per algorithm name: (colour, line style, marker)
ALGORITHM_STYLES = {
    "dr": ("#7f7f7f", "-", "o"),
    "plr": ("#1f77b4", "--", "s"),
    "minimax-return": ("#ff7f0e", ":", "^"),
    "remidi": ("#d62728", "-", "D"),
    "mmr": ("#9467bd", "--", "v"),
    "accel": ("#2ca02c", "-.", "P"),
    "remidi-accel": ("#8c564b", "-", "X"),
    "paired": ("#bcbd22", "-.", "p"),
    "remidi-paired": ("#e377c2", "-", "*"),
}
_SPARE = [("#e377c2", "--", "*"), ("#17becf", ":", "h")]
# a variant of a buffer sequence (the results page's "remidi (combine)", "remidi (belief, margin 2)"):
# the algorithm's marker, the variant's colour and line style, by the variant's first word
VARIANT_STYLES = {
    "combine": ("#8b0000", "--"),
    "rehearsal": ("#ff9896", "-."),
    "belief": ("#008b8b", "--"),
    "simulated": ("#393b79", ":"),
}


def algorithm_style(name: str) -> dict:
    """Matplotlib keywords (color, linestyle, marker) of algorithm ``name``: fixed per name. A
    results-page label (``paired (perfect)``, ``remidi (combine)``) takes its algorithm's style,
    with the colour and line style of :data:`VARIANT_STYLES` where its first word names one."""
    name, _, variant = name.partition(" (")
    if name in ALGORITHM_STYLES:
        color, linestyle, marker = ALGORITHM_STYLES[name]
    else:  # an algorithm this module does not know: a spare style chosen by the name alone
        color, linestyle, marker = _SPARE[sum(map(ord, name)) % len(_SPARE)]
    first = variant.rstrip(")").replace(",", " ").split()
    if first and first[0] in VARIANT_STYLES:
        color, linestyle = VARIANT_STYLES[first[0]]
    return {"color": color, "linestyle": linestyle, "marker": marker}


SERIES_LINES = ("-", "--", ":", "-.")
SERIES_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")


def distinct_styles(names: list[str], style=None) -> dict[str, dict]:
    """The plot style of each of ``names`` in one figure (``style(name)``, default
    :func:`algorithm_style`), with no two alike: a name whose style an earlier one already has
    (``remidi (rehearsal 0.1)`` and ``(rehearsal 0.3)``, ``remidi`` and ``remidi (masked)``) takes
    the next line style, then the next marker, that no earlier name has with its colour."""
    style = style or algorithm_style
    out, used = {}, set()
    for name in names:
        s = dict(style(name))
        lines = [s["linestyle"]] + [x for x in SERIES_LINES if x != s["linestyle"]]
        markers = [s["marker"]] + [m for m in SERIES_MARKERS if m != s["marker"]]
        s["linestyle"], s["marker"] = next(
            ((ls, m) for m in markers for ls in lines if (s["color"], ls, m) not in used), (lines[0], markers[0]))
        used.add((s["color"], s["linestyle"], s["marker"]))
        out[name] = s
    return out


def series_style(i: int) -> dict:
    """Matplotlib keywords of the ``i``-th curve of a panel whose curves are not algorithms (the
    tabular games' observations): the colour cycle's ``i``-th colour with its own line style and
    marker, so curves that coincide stay visible (the markers are shifted per curve)."""
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    return {"color": colors[i % len(colors)], "linestyle": SERIES_LINES[i % len(SERIES_LINES)],
            "marker": SERIES_MARKERS[i % len(SERIES_MARKERS)]}


@dataclass
class Curve:
    """One line: ``values`` f[S, T] over seeds and log points, drawn as mean ± std. ``style``:
    matplotlib keywords (``color``, ``linestyle``, ``marker``); default: the colour cycle by
    position, solid, no marker."""

    label: str
    steps: np.ndarray
    values: np.ndarray
    style: dict = field(default_factory=dict)


@dataclass
class Panel:
    title: str
    curves: list[Curve]
    ylabel: str = ""
    xlabel: str = "step"
    references: list[tuple[float, str]] = field(default_factory=list)  # dashed horizontal lines, in the legend
    ylim: tuple[float, float] | None = None
    # draw curves whose means coincide (root-mean-square gap under 2% of the panel's range) once,
    # labelled "a, b"
    merge_coinciding: bool = False
    # algorithms of the run for which the metric is undefined (DR's replay share): named in the panel
    missing: list[str] = field(default_factory=list)


def algorithm_curves(results: dict, metric: str) -> list[Curve]:
    """One styled curve of ``metric`` per algorithm of ``results`` ({algo: RunResult}, in order),
    leaving out algorithms without the metric or without a single defined value of it (DR's
    replay share: it never replays)."""
    curves = []
    for algo, result in results.items():
        values = result.history.get(metric)
        if values is None or not np.isfinite(np.asarray(values, dtype=float)).any():
            continue
        curves.append(Curve(algo, result.steps, values, algorithm_style(algo)))
    return curves


def _merge(curves: list[Curve], colors: list[str]) -> list[Curve]:
    """Curves with default styles get their colour by position first (so a curve keeps its colour
    whatever it is merged with); then each curve whose mean is within 2% of the panel's range of an
    earlier one (root mean square over the log points) is folded into it, its label appended."""
    means = [np.nanmean(np.asarray(c.values, dtype=float), axis=0) for c in curves]
    finite = np.concatenate([m[np.isfinite(m)] for m in means]) if means else np.zeros(0)
    span = float(finite.max() - finite.min()) if finite.size else 0.0
    tol = max(0.02 * span, 1e-9)
    groups: list[tuple[Curve, np.ndarray, list[str]]] = []
    for i, (curve, mean) in enumerate(zip(curves, means)):
        style = curve.style or {"color": colors[i % len(colors)]}
        for first, first_mean, labels in groups:
            gap = mean - first_mean
            if (np.array_equal(first.steps, curve.steps) and np.array_equal(np.isnan(mean), np.isnan(first_mean))
                    and np.sqrt(np.nanmean(gap ** 2) if np.isfinite(gap).any() else 0.0) <= tol):
                labels.append(curve.label)
                break
        else:
            groups.append((Curve(curve.label, curve.steps, curve.values, style), mean, [curve.label]))
    return [Curve(", ".join(labels), first.steps, first.values, first.style) for first, _, labels in groups]


def plot_panels(path: Path, panels: list[Panel], title: str = "", columns: int = 3) -> None:
    """Save ``panels`` into the PNG ``path``, at most ``columns`` per row."""
    cols = min(columns, len(panels))
    rows = math.ceil(len(panels) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 4.0 * rows), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax in axes.flat[len(panels):]:
        ax.set_visible(False)
    for ax, panel in zip(axes.flat, panels):
        curves = (_merge(panel.curves, colors) if panel.merge_coinciding else
                  [Curve(c.label, c.steps, c.values, c.style or {"color": colors[i % len(colors)]})
                   for i, c in enumerate(panel.curves)])
        for i, curve in enumerate(curves):
            values = np.asarray(curve.values, dtype=float)
            with warnings.catch_warnings():  # "mean of empty slice" where every seed is NaN
                warnings.simplefilter("ignore", RuntimeWarning)
                mean, std = np.nanmean(values, axis=0), np.nanstd(values, axis=0)
            style = dict(curve.style)
            if style.get("marker"):  # at most ~8 markers, spread over the curves so coinciding ones show each
                every = max(1, len(mean) // 8)
                shift = i * every // len(curves) if len(curves) <= every else i % every
                style["markevery"] = (shift, every) if every > 1 else 1
                style.setdefault("markersize", 4)
            ax.plot(curve.steps, mean, label=curve.label, linewidth=1.6, **style)
            ax.fill_between(curve.steps, mean - std, mean + std, color=style.get("color"), alpha=0.15, linewidth=0)
        seen = set()
        for y, label in panel.references:
            ax.axhline(y, linestyle=(0, (4, 3)), color="black", linewidth=1, alpha=0.6,
                       label=None if label in seen else label)
            seen.add(label)
        # a fixed end of the range stays; a free one gets headroom, so that neither the frame nor the
        # legend hides a curve or a reference line
        lo, hi = ax.get_ylim()
        span = (hi - lo) or 1.0
        want_lo, want_hi = panel.ylim if panel.ylim is not None else (None, None)
        ax.set_ylim(lo - 0.05 * span if want_lo is None else want_lo, hi + 0.25 * span if want_hi is None else want_hi)
        ax.set_title(panel.title)
        ax.set_xlabel(panel.xlabel)
        if panel.missing:
            # under the panel's x label (inside the panel it covered curves), wrapped to its width
            note = "\n".join(textwrap.wrap(f"n/a: {', '.join(panel.missing)}", 70))
            ax.annotate(note, xy=(1, 0), xycoords=("axes fraction", ax.xaxis.label), xytext=(0, -2),
                        textcoords="offset points", fontsize=8, color="dimgray", ha="right", va="top")
        ax.set_ylabel(panel.ylabel)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8, loc="best")
    if title:
        fig.suptitle(title)
    _save(fig, path)


def plot_bars(path: Path, title: str, labels: list[str], series: dict[str, np.ndarray], ylabel: str = "",
              ylim: tuple[float, float] | None = None) -> None:
    """Grouped bar chart into the PNG ``path``: one group per label, one bar per series (an
    algorithm, in its fixed colour); ``series[name]`` f[len(labels), S] over seeds, drawn as mean
    with a ± std error bar."""
    fig, ax = plt.subplots(figsize=(min(14.0, max(6.0, 0.55 * len(labels) * max(1, len(series)) ** 0.5 + 2)), 4.2))
    width = 0.8 / max(1, len(series))
    x = np.arange(len(labels))
    for i, (name, values) in enumerate(series.items()):
        values = np.asarray(values, dtype=float)
        ax.bar(x + (i - (len(series) - 1) / 2) * width, values.mean(axis=1), width, yerr=values.std(axis=1),
               label=name, color=algorithm_style(name)["color"], capsize=2)
    ax.set_xticks(x, labels, rotation=35, ha="right", fontsize=8)
    ax.set_title(title)
    ax.set_ylabel(ylabel)
    if ylim is not None:
        ax.set_ylim(*ylim)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8)
    _save(fig, path)


def _save(fig, path: Path) -> None:
    """Save atomically (temporary file, then rename) and close the figure."""
    fig.tight_layout()
    tmp = Path(path).with_name(f".{Path(path).name}.{os.getpid()}.tmp.png")  # two writers never share one
    try:
        fig.savefig(tmp, dpi=110)
        tmp.replace(path)
    except OSError as err:  # a full disk: the plot before stays; name the plot, not the temporary
        tmp.unlink(missing_ok=True)
        raise OSError(err.errno, err.strerror or str(err), str(path)) from None
    finally:
        plt.close(fig)
