"""Plots: panels of training curves, mean ± std over seeds.

Each algorithm keeps one colour, line style and marker everywhere (:func:`algorithm_style`) and the
run's order, so a resumed run draws what a fresh one does and identical curves stay visible.
Value axes contain every curve, band and reference line with a margin (:func:`padded`); legends
sit off the data; the title names the run (:func:`run_title`) and the caption says what a line,
band or bar is. Figures are built (``*_figure``) apart from saving, so tests can walk them."""

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
    "sfl": ("#17becf", "-.", "h"),
    "remidi-sfl": ("#393b79", "-", "d"),
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
    """Matplotlib keywords (color, linestyle, marker) of algorithm ``name``, fixed per name. A
    results-page label (``remidi (combine)``) takes its algorithm's style, recoloured by
    :data:`VARIANT_STYLES` where its first word names one."""
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
    """The style of each of ``names`` in one figure (``style``, default :func:`algorithm_style`),
    no two alike: a name styled like an earlier one takes the next free line style, then marker."""
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
    """Matplotlib keywords of a panel's ``i``-th non-algorithm curve: the ``i``-th cycle colour with
    its own line style and marker, so coinciding curves stay visible."""
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    return {"color": colors[i % len(colors)], "linestyle": SERIES_LINES[i % len(SERIES_LINES)],
            "marker": SERIES_MARKERS[i % len(SERIES_MARKERS)]}


@dataclass
class Curve:
    """One line: ``values`` f[S, T] over seeds and log points, drawn as mean ± std. ``style``:
    matplotlib keywords; default: the colour cycle by position, solid, no marker."""

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
    # the y range shown at least (either end None: the data's); the data and the references widen it
    ylim: tuple[float | None, float | None] | None = None
    # draw curves whose means coincide (root-mean-square gap under 2% of the panel's range) once,
    # labelled "a, b", in dashes of each one's colour
    merge_coinciding: bool = False
    # algorithms of the run for which the metric is undefined (DR's replay share): named in the panel
    missing: list[str] = field(default_factory=list)


# what a panel figure draws, said in its caption
MEAN_STD = "line: mean over seeds; band: ± 1 standard deviation over seeds"
# a reference line's colour (drawn opaque) and the words the captions name it by: one place for both
REFERENCE_COLOR = "dimgray"
REFERENCE_STYLE = "dashed grey"
REFERENCE_LINES = f"{REFERENCE_STYLE}: the reference value its legend names"
BARS_STD = "bar: mean over seeds; error bar: ± 1 standard deviation over seeds"
MARGIN = 0.08  # of a value axis' shown range, left free beyond the data at each end
DASH = 3.0  # a shared line's dash per curve, in line widths
LEGEND_FONT = 8


def seeds_text(seeds) -> str:
    """``1 seed (3)``, ``3 seeds (0–2)``, ``4 seeds (0, 1, 5, 9)``: how many seeds, and which."""
    seeds = sorted(int(s) for s in seeds)
    spans: list[list[int]] = []
    for s in seeds:
        if spans and s == spans[-1][1] + 1:
            spans[-1][1] = s
        else:
            spans.append([s, s])
    which = ", ".join(str(a) if a == b else f"{a}, {b}" if b == a + 1 else f"{a}–{b}" for a, b in spans)
    return f"{len(seeds)} seed{'' if len(seeds) == 1 else 's'} ({which})"


def run_title(experiment: str = "", preset: str | None = None, seeds=None) -> str:
    """The run a figure shows: ``lever, preset smoke, 2 seeds (0, 1)`` (what is not known left out)."""
    parts = [experiment] if experiment else []
    if preset:
        parts.append(f"preset {preset}")
    if seeds:
        parts.append(seeds_text(seeds))
    return ", ".join(parts)


def padded(lo: float, hi: float, want: tuple[float | None, float | None] | None = None,
           margin: float = MARGIN) -> tuple[float, float]:
    """Value-axis limits showing [``lo``, ``hi``] and ``want``'s given ends with ``margin`` of the
    range free at both ends, so nothing lies on the frame and equal asked ranges get equal limits."""
    want_lo, want_hi = want if want is not None else (None, None)
    lo = lo if want_lo is None else min(lo, want_lo)
    hi = hi if want_hi is None else max(hi, want_hi)
    span = (hi - lo) or abs(hi) or 1.0
    return lo - margin * span, hi + margin * span


def algorithm_curves(results: dict, metric: str) -> list[Curve]:
    """One styled curve of ``metric`` per algorithm of ``results`` ({algo: RunResult}, in order),
    leaving out algorithms without a defined value of it (DR's replay share)."""
    curves = []
    for algo, result in results.items():
        values = result.history.get(metric)
        if values is None or not np.isfinite(np.asarray(values, dtype=float)).any():
            continue
        curves.append(Curve(algo, result.steps, values, algorithm_style(algo)))
    return curves


def _merge(curves: list[Curve], colors: list[str]) -> list[list[Curve]]:
    """Group coinciding curves: ``[[first, joined, ...]]``, a curve joining an earlier one whose mean
    is within 2% of the panel's range (RMS over log points). Default colours are given by position
    first, so a curve keeps its colour whatever it merges with."""
    means = [np.nanmean(np.asarray(c.values, dtype=float), axis=0) for c in curves]
    finite = np.concatenate([m[np.isfinite(m)] for m in means]) if means else np.zeros(0)
    span = float(finite.max() - finite.min()) if finite.size else 0.0
    tol = max(0.02 * span, 1e-9)
    groups: list[tuple[list[Curve], np.ndarray]] = []
    for i, (curve, mean) in enumerate(zip(curves, means)):
        curve = Curve(curve.label, curve.steps, curve.values, curve.style or {"color": colors[i % len(colors)]})
        for members, first_mean in groups:
            gap = mean - first_mean
            if (np.array_equal(members[0].steps, curve.steps) and np.array_equal(np.isnan(mean), np.isnan(first_mean))
                    and np.sqrt(np.nanmean(gap ** 2) if np.isfinite(gap).any() else 0.0) <= tol):
                members.append(curve)
                break
        else:
            groups.append(([curve], mean))
    return [members for members, _ in groups]


def _mean_std(values) -> tuple[np.ndarray, np.ndarray]:
    values = np.asarray(values, dtype=float)
    with warnings.catch_warnings():  # "mean of empty slice" where every seed is NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(values, axis=0), np.nanstd(values, axis=0)


def _draw_group(ax, members: list[Curve], first: int, count: int):
    """Draw ``members`` (one curve, or several coinciding: the first's mean and band) and return the
    legend handle (for several, a tuple of one dashed ``Line2D`` per member colour). ``first``: the
    group's first line among the panel's ``count``, spreading marker positions."""
    mean, std = _mean_std(members[0].values)
    steps, k = members[0].steps, len(members)
    lines = []
    for j, curve in enumerate(members):
        style = dict(curve.style)
        if k > 1:  # pattern: on for one dash, off for the others'; member j's dash comes j-th
            style["linestyle"] = (((k - j) % k) * DASH, (DASH, (k - 1) * DASH))
        if style.get("marker"):  # at most ~8 markers, spread over the curves so coinciding ones show each
            i, every = first + j, max(1, len(mean) // 8)
            shift = i * every // count if count <= every else i % every
            style["markevery"] = (shift, every) if every > 1 else 1
            style.setdefault("markersize", 4)
        (line,) = ax.plot(steps, mean, label=curve.label, linewidth=1.6, **style)
        lines.append(line)
    ax.fill_between(steps, mean - std, mean + std, color=lines[0].get_color(), alpha=0.15, linewidth=0)
    return lines[0] if k == 1 else tuple(lines)


def _data_range(panel: Panel) -> tuple[float, float] | None:
    """The lowest and highest value a panel draws: means, mean ± std, references (None: none)."""
    found = [float(y) for y, _ in panel.references]
    for curve in panel.curves:
        mean, std = _mean_std(curve.values)
        for v in (mean, mean - std, mean + std):
            found.extend(v[np.isfinite(v)].tolist())
    return (min(found), max(found)) if found else None


def _draw_panel(ax, panel: Panel, colors: list[str]) -> list[tuple[object, str]]:
    """Draw ``panel`` into ``ax``; return its legend entries ``[(handle, label)]``."""
    if panel.merge_coinciding:
        groups = _merge(panel.curves, colors)
    else:
        groups = [[Curve(c.label, c.steps, c.values, c.style or {"color": colors[i % len(colors)]})]
                  for i, c in enumerate(panel.curves)]
    count = sum(len(g) for g in groups)
    entries, first = [], 0
    for members in groups:
        entries.append((_draw_group(ax, members, first, count), ", ".join(c.label for c in members)))
        first += len(members)
    for y, label in panel.references:
        line = ax.axhline(y, linestyle=(0, (4, 3)), color=REFERENCE_COLOR, linewidth=1, label=label)
        if label not in {text for _, text in entries}:
            entries.append((line, label))
    found = _data_range(panel)
    if found is None and panel.ylim is not None and None not in panel.ylim:
        found = panel.ylim
    if found is not None:
        ax.set_ylim(*padded(*found, panel.ylim))
    ax.set_title(panel.title)
    ax.set_xlabel(panel.xlabel)
    ax.set_ylabel(panel.ylabel)
    if panel.missing:
        # under the panel's x label (inside the panel it covered curves), wrapped to its width
        note = "\n".join(textwrap.wrap(f"n/a: {', '.join(panel.missing)}", 70))
        ax.annotate(note, xy=(1, 0), xycoords=("axes fraction", ax.xaxis.label), xytext=(0, -2),
                    textcoords="offset points", fontsize=8, color="dimgray", ha="right", va="top")
    ax.grid(alpha=0.3)
    return entries


def _legend_below(ax, entries: list[tuple[object, str]], renderer):
    """The legend of ``entries`` below the x axis (and any note), in as many columns (≤ 3) as fit
    the panel's width; placed in points below the frame, so it follows the axes through layout."""
    from matplotlib.legend_handler import HandlerTuple
    from matplotlib.transforms import ScaledTranslation

    fig = ax.figure
    left = ax.yaxis.get_tightbbox(renderer)
    width = ax.bbox.x1 - (left.x0 if left is not None else ax.bbox.x0)  # the panel's, its y axis included
    below = [ax.bbox, ax.xaxis.get_tightbbox(renderer)] + [t.get_window_extent(renderer) for t in ax.texts]
    drop = (ax.bbox.y0 - min(b.y0 for b in below if b is not None)) * 72 / fig.dpi + 3  # points
    anchor = ax.transAxes + ScaledTranslation(0, -drop / 72, fig.dpi_scale_trans)
    handles, labels = [h for h, _ in entries], [label for _, label in entries]
    for ncols in range(min(3, len(entries)), 0, -1):
        legend = ax.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0), bbox_transform=anchor,
                           ncols=ncols, fontsize=LEGEND_FONT, handler_map={tuple: HandlerTuple(ndivide=1, pad=0)},
                           handlelength=2.5)
        if ncols == 1 or legend.get_window_extent(renderer).width <= width:
            break
    return legend


def _captioned(fig, title: str, caption: str) -> None:
    """The figure's title above its panels and caption below, wrapped to its width."""
    width = int(fig.get_figwidth() * 15)  # characters of 9-point text per line
    if title:
        fig.suptitle("\n".join(textwrap.wrap(title, width)), fontsize=13, fontweight="bold")
    if caption:
        fig.supxlabel("\n".join(textwrap.wrap(caption, width)), fontsize=9)


def panels_figure(panels: list[Panel], title: str = "", columns: int = 3, caption: str | None = None):
    """The figure of ``panels``, at most ``columns`` per row, each with its legend below; ``title``
    above (:func:`run_title`), ``caption`` below (default: what a line, band and dashed line are).
    Constrained layout."""
    cols = min(columns, len(panels))
    rows = math.ceil(len(panels) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 4.0 * rows), squeeze=False, layout="constrained")
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax in axes.flat[len(panels):]:
        ax.set_visible(False)
    entries = [_draw_panel(ax, panel, colors) for ax, panel in zip(axes.flat, panels)]
    renderer = fig.canvas.get_renderer()
    extra = [0.0] * rows  # inches of legend under each row of panels
    for k, (ax, found) in enumerate(zip(axes.flat, entries)):
        if found:
            height = _legend_below(ax, found, renderer).get_window_extent(renderer).height / fig.dpi
            extra[k // cols] = max(extra[k // cols], height + 0.1)
    fig.set_figheight(4.0 * rows + sum(extra))
    if caption is None:
        caption = MEAN_STD + ("; " + REFERENCE_LINES if any(p.references for p in panels) else "")
    _captioned(fig, title, caption)
    return fig


def plot_panels(path: Path, panels: list[Panel], title: str = "", columns: int = 3,
                caption: str | None = None) -> None:
    """Save :func:`panels_figure` into the PNG ``path``."""
    _save(panels_figure(panels, title, columns, caption), path)


def bars_figure(title: str, labels: list[str], series: dict[str, np.ndarray], ylabel: str = "",
                ylim: tuple[float, float] | None = None, caption: str | None = None):
    """Grouped bar chart: one group per label, one bar per series (an algorithm, in its colour);
    ``series[name]`` f[len(labels), S], drawn as mean ± std. ``ylim``: the range shown at least; legend
    right of the axes; ``caption`` below (default: what a bar and error bar are)."""
    fig, ax = plt.subplots(figsize=(min(14.0, max(6.0, 0.55 * len(labels) * max(1, len(series)) ** 0.5 + 2)) + 1.5,
                                    4.6), layout="constrained")
    width = 0.8 / max(1, len(series))
    x = np.arange(len(labels))
    found = [0.0]  # the bars stand on 0
    for i, (name, values) in enumerate(series.items()):
        mean, std = _mean_std(np.asarray(values, dtype=float).T)
        ax.bar(x + (i - (len(series) - 1) / 2) * width, mean, width, yerr=std, label=name,
               color=algorithm_style(name)["color"], capsize=2)
        found.extend(v for v in np.concatenate([mean - std, mean + std]) if np.isfinite(v))
    ax.set_xticks(x, labels, rotation=35, ha="right", fontsize=8)
    ax.set_title(title)
    ax.set_ylabel(ylabel)
    ax.set_ylim(*padded(min(found), max(found), ylim))
    ax.grid(alpha=0.3, axis="y")
    if series:
        ax.legend(fontsize=LEGEND_FONT, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    _captioned(fig, "", BARS_STD if caption is None else caption)
    return fig


def plot_bars(path: Path, title: str, labels: list[str], series: dict[str, np.ndarray], ylabel: str = "",
              ylim: tuple[float, float] | None = None, caption: str | None = None) -> None:
    """Save :func:`bars_figure` into the PNG ``path``."""
    _save(bars_figure(title, labels, series, ylabel, ylim, caption), path)


def _save(fig, path: Path) -> None:
    """Save atomically (temporary file, then rename) and close the figure; laid out tightly first
    unless it has a layout engine."""
    if fig.get_layout_engine() is None:
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
