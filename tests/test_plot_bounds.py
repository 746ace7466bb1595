"""Every plot shows what it claims: each experiment's figures, built by its own plotting code on
made-up results (no training), keep every curve, band, interval and reference line inside their
axes, clear of the frame, and every legend off the data and off the labels, inside the figure.

The figures are those the plot functions would save (``plots._save`` replaced), laid out as
saving lays them out, and checked in display coordinates:

* every finite point of a ``Line2D`` (curves, markers' lines, ``axhline``/``axvline``), of a
  ``PolyCollection`` (± std bands), a ``LineCollection`` (error bars, intervals) and a bar lies
  inside its axes at least :data:`MARGIN_X` of the axes' width and :data:`MARGIN_Y` of its height
  away from the frame; a
  reference line that runs from frame to frame (``axhline``) is exempt along its length only;
* a legend's box crosses no plotted line, band, bar or point of any axes, no axis (tick labels
  and label), title or caption, and lies inside the figure; so does every other text.
"""

from __future__ import annotations

import math

import matplotlib.collections as mcollections
import matplotlib.lines as mlines
import matplotlib.patches as mpatches
import numpy as np
import pytest
from matplotlib.path import Path as MplPath
from matplotlib.transforms import Bbox

from remidi.experiments import get_experiment
from remidi.experiments.base import RunResult
from remidi.runs.compare import compare, plot_comparison
from remidi.experiments.lever import IGNORE_VISIBLE, MMR_HIDDEN

# of the axes' width and height: less reads as lying on the frame (matplotlib's own x margins
# leave 4.5%; a curve 5.7% below the top frame, under the legend, read as on it)
MARGIN_X, MARGIN_Y = 0.04, 0.06
STEPS = np.array([50, 100, 150, 200, 250, 300])
SEEDS = (0, 1, 2)


# ------------------------------------------------------------------------------ the check
def _display_points(artist) -> list[np.ndarray]:
    """The artist's data as arrays of display points (one per connected piece), NaNs dropped."""
    if isinstance(artist, mlines.Line2D):
        xy = np.column_stack([np.asarray(artist.get_xdata(), float), np.asarray(artist.get_ydata(), float)])
        return [artist.get_transform().transform(xy[np.isfinite(xy).all(axis=1)])]
    if isinstance(artist, mcollections.Collection):
        transform = artist.get_transform()
        if isinstance(artist, mcollections.LineCollection):
            pieces = [np.asarray(s, float) for s in artist.get_segments()]
        else:
            pieces = [p.vertices for p in artist.get_paths()]
        return [transform.transform(p[np.isfinite(p).all(axis=1)]) for p in pieces if len(p)]
    if isinstance(artist, mpatches.Rectangle):
        return [artist.get_transform().transform(artist.get_path().vertices)]
    return []


def _data_artists(ax):
    for artist in [*ax.lines, *ax.collections, *ax.patches]:
        if artist.get_visible() and (not isinstance(artist, mpatches.Patch) or isinstance(artist, mpatches.Rectangle)):
            yield artist


def _spans(points: np.ndarray, lo: float, hi: float) -> bool:
    """Whether ``points`` (one coordinate) run from one frame to the other: a reference line."""
    return len(points) > 0 and abs(points.min() - lo) < 0.5 and abs(points.max() - hi) < 0.5


def contained(fig) -> list[str]:
    """What lies outside its axes or on its frame, one line each (empty: all inside)."""
    problems = []
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        box = ax.get_window_extent()
        mx, my = MARGIN_X * box.width, MARGIN_Y * box.height
        for artist in _data_artists(ax):
            for pts in _display_points(artist):
                if not len(pts):
                    continue
                name = f"{ax.get_title()!r}: {type(artist).__name__} {artist.get_label()!r}"
                x, y = pts[:, 0], pts[:, 1]
                if not _spans(x, box.x0, box.x1) and (x.min() < box.x0 + mx - 0.5 or x.max() > box.x1 - mx + 0.5):
                    problems.append(f"{name}: x from {x.min() - box.x0:.0f} to {x.max() - box.x0:.0f} px "
                                    f"in an axes {box.width:.0f} px wide (margin {mx:.0f})")
                if not _spans(y, box.y0, box.y1) and (y.min() < box.y0 + my - 0.5 or y.max() > box.y1 - my + 0.5):
                    problems.append(f"{name}: y from {y.min() - box.y0:.0f} to {y.max() - box.y0:.0f} px "
                                    f"in an axes {box.height:.0f} px high (margin {my:.0f})")
    return problems


def _obstacles(fig, renderer) -> list[tuple[str, Bbox]]:
    """Boxes a legend must not cover: every axis (tick labels and label), title and note, and the
    figure's title and caption."""
    boxes = []
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        for what, artist in (("x axis", ax.xaxis), ("y axis", ax.yaxis)):
            box = artist.get_tightbbox(renderer)
            if box is not None:
                boxes.append((f"{ax.get_title()!r} {what}", box))
        for text in [ax.title, *ax.texts]:
            if text.get_visible() and text.get_text():
                boxes.append((f"{ax.get_title()!r} text {text.get_text()!r}", text.get_window_extent(renderer)))
    for text in [fig._suptitle, fig._supxlabel, *fig.texts]:
        if text is not None and text.get_visible() and text.get_text():
            boxes.append((f"figure text {text.get_text()!r}", text.get_window_extent(renderer)))
    return boxes


def _overlaps(a: Bbox, b: Bbox) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def legends_clear(fig) -> list[str]:
    """Legends over data, labels or another legend, and anything outside the figure, one line each."""
    renderer = fig.canvas.get_renderer()
    problems = []
    legends = [ax.get_legend() for ax in fig.axes if ax.get_visible() and ax.get_legend()] + list(fig.legends)
    canvas = Bbox.from_bounds(0, 0, fig.bbox.width, fig.bbox.height)
    for i, legend in enumerate(legends):
        box = legend.get_window_extent(renderer)
        name = f"legend {[t.get_text() for t in legend.get_texts()]}"
        if not (canvas.x0 - 0.5 <= box.x0 and box.x1 <= canvas.x1 + 0.5
                and canvas.y0 - 0.5 <= box.y0 and box.y1 <= canvas.y1 + 0.5):
            problems.append(f"{name} is cut off by the figure's edge")
        for ax in fig.axes:
            if not ax.get_visible():
                continue
            for artist in _data_artists(ax):
                for pts in _display_points(artist):
                    if not len(pts):
                        continue
                    filled = isinstance(artist, (mcollections.PolyCollection, mpatches.Patch))
                    drawn = artist.get_linestyle() not in ("None", "none", "", " ") \
                        if isinstance(artist, mlines.Line2D) else True
                    path = MplPath(pts, closed=filled)
                    hit = (path.intersects_bbox(box, filled=filled) if drawn and len(pts) > 1
                           else box.count_contains(pts) > 0)
                    if hit:
                        problems.append(f"{name} covers {ax.get_title()!r}'s {type(artist).__name__} "
                                        f"{artist.get_label()!r}")
        for what, obstacle in _obstacles(fig, renderer):
            if _overlaps(box, obstacle):
                problems.append(f"{name} covers the {what}")
        for other in legends[i + 1:]:
            if _overlaps(box, other.get_window_extent(renderer)):
                problems.append(f"{name} covers another legend")
    for what, obstacle in _obstacles(fig, renderer):
        if obstacle.x0 < -0.5 or obstacle.y0 < -0.5 or obstacle.x1 > fig.bbox.width + 0.5 \
                or obstacle.y1 > fig.bbox.height + 0.5:
            problems.append(f"the {what} is cut off by the figure's edge")
    return problems


def check(fig) -> None:
    if fig.get_layout_engine() is None:  # laid out as plots._save lays it out
        fig.tight_layout()
    fig.canvas.draw()
    problems = contained(fig) + legends_clear(fig)
    assert not problems, "\n".join(problems)


def figure_text(fig) -> str:
    """Every title, caption and note of the figure, one string."""
    texts = [fig._suptitle, fig._supxlabel, *fig.texts] + [t for ax in fig.axes for t in (ax.title, *ax.texts)]
    return "\n".join(t.get_text() for t in texts if t is not None)


# ------------------------------------------------------------------------------ made-up runs
def curve(start, end, spread, seeds=len(SEEDS), rng=np.random.default_rng(0)):
    """f[S, T]: a straight line from ``start`` to ``end`` with seed-to-seed noise ``spread``."""
    return np.linspace(start, end, len(STEPS)) + rng.normal(0, spread, (seeds, len(STEPS)))


def lever_results() -> dict[str, RunResult]:
    """The four algorithms as a smoke run leaves them: the regret of the visible levels flat at
    the reference (1.96875, what ignoring the answer costs) except ReMiDi's; shares near 1 whose
    bands reach past 1; DR without a replay share."""
    results = {}
    for algo, learns in (("dr", False), ("plr", False), ("minimax-return", False), ("remidi", True)):
        history = {
            "solve_rate/visible": np.clip(curve(0.02, 0.9 if learns else 0.03, 0.08), 0, 1),
            "solve_rate/hidden": np.clip(curve(1 / 64, 1 / 64, 0.005), 0, 1),
            "regret/visible/mean": np.full((len(SEEDS), len(STEPS)), IGNORE_VISIBLE) if not learns
            else np.array([1.97, 1.97, 1.95, 1.84, 1.73, 1.61]) + curve(0, 0, 0.002),  # the smoke run's ReMiDi
            "regret/hidden/worst": np.minimum(20.0, curve(19.9, 19.99, 0.02)),
            "replay_fraction/hidden": np.full((len(SEEDS), len(STEPS)), np.nan) if algo == "dr"
            else np.clip(curve(0.9, 0.0 if learns else 0.99, 0.15), 0, 1),
            "buffer_fraction/hidden": np.clip(curve(0.9, 0.0 if learns else 0.98, 0.15), 0, 1),
        }
        results[algo] = RunResult(steps=STEPS, history=history)
    return results


def test_the_check_catches_a_reference_line_on_the_frame_and_a_legend_over_a_curve():
    """The check itself: a curve on the frame, an ``axhline`` on it, and a legend in the middle of
    the data each fail it; the same figure with room and the legend beside the axes passes."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(layout="constrained")
    ax.plot([0, 1, 2], [0.2, 1.0, IGNORE_VISIBLE], label="regret")  # through the middle
    ax.axhline(IGNORE_VISIBLE, linestyle="--", label="reference")
    ax.set_ylim(0, IGNORE_VISIBLE + 0.001)
    ax.legend(loc="center")
    fig.canvas.draw()
    problems = contained(fig) + legends_clear(fig)
    assert any("Line2D 'regret'" in p and "y from" in p for p in problems)
    assert any("Line2D 'reference'" in p for p in problems)
    assert any("covers ''" + "'s Line2D 'regret'" in p for p in problems)
    ax.set_ylim(0, 2.2)
    ax.set_xlim(-0.2, 2.2)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0))
    check(fig)
    plt.close(fig)


def test_lever_training_plot(figures, tmp_path):
    lever = get_experiment("lever")
    lever.plot(tmp_path, lever_results(), lever.config_factory(), preset="smoke", seeds=list(SEEDS))
    fig = figures["training.png"]
    check(fig)
    text = figure_text(fig)
    assert "lever" in text and "preset smoke" in text and "3 seeds (0–2)" in text
    assert "± 1 standard deviation over seeds" in text
    regret = next(ax for ax in fig.axes if ax.get_title() == "mean regret over visible levels")
    assert regret.get_ylim()[1] > IGNORE_VISIBLE
    worst = next(ax for ax in fig.axes if ax.get_title() == "worst-case regret over hidden levels")
    assert worst.get_ylim()[0] < MMR_HIDDEN


def test_tabular_plots(figures, tmp_path):
    exp = get_experiment("tabular-shared")
    same = np.tile(np.linspace(0.1, 0.5, len(STEPS)), (len(SEEDS), 1))
    rng = np.random.default_rng(1)
    history = {"regret/h1": same + 0.1, "regret/h3": same + 0.3 + rng.normal(0, 0.2, same.shape),
               "regret/h5": same + 0.9, "regret/max": same + 0.9,
               **{f"adversary_prob/theta{i}": np.clip(same * (0.1 if i <= 4 else 1.0), 0, 1) for i in range(1, 7)}}
    history["adversary_prob/theta6"] = np.clip(1 - same + rng.normal(0, 0.2, same.shape), 0, 1)
    reference = {"blp_regret": {"h1": 0.175, "h3": 0.175, "h5": 1.0}}
    results = {algo: RunResult(steps=STEPS, history=history, extra={"reference": reference})
               for algo in ("mmr", "remidi")}
    exp.plot(tmp_path, results, exp.config_factory(), preset="smoke", seeds=list(SEEDS))
    for name in ("regret.png", "adversary.png"):
        check(figures[name])
        text = figure_text(figures[name])
        assert "tabular-shared" in text and "preset smoke" in text and "3 seeds (0–2)" in text, text
        assert "± 1 standard deviation over seeds" in text, text


def test_tabular_adversary_gives_each_level_one_colour_in_every_panel(figures, tmp_path):
    """θ1–θ4 coincide under MMR and only θ1, θ4 under ReMiDi: a level keeps its colour in both
    panels, and a line drawn for several levels shows each of their colours."""
    exp = get_experiment("tabular-shared")
    low = np.tile(np.linspace(0.1, 0.01, len(STEPS)), (2, 1))
    high = np.tile(np.linspace(0.2, 0.49, len(STEPS)), (2, 1))
    mid = np.tile(np.linspace(0.15, 0.3, len(STEPS)), (2, 1))
    mmr = {**{f"adversary_prob/theta{i}": low for i in (1, 2, 3, 4)}, "adversary_prob/theta5": high,
           "adversary_prob/theta6": high, "regret/h1": low}
    remidi = {"adversary_prob/theta1": mid, "adversary_prob/theta2": low, "adversary_prob/theta3": low,
              "adversary_prob/theta4": mid, "adversary_prob/theta5": high, "adversary_prob/theta6": low,
              "regret/h1": low}
    reference = {"blp_regret": {"h1": 0.175}}
    exp.plot(tmp_path, {"mmr": RunResult(STEPS, mmr, extra={"reference": reference}),
                        "remidi": RunResult(STEPS, remidi, extra={"reference": reference})}, exp.config_factory())
    fig = figures["adversary.png"]
    check(fig)
    colours = {}  # level -> the colours of its lines, over every panel
    for ax in fig.axes:
        lines = {line.get_label(): line for line in ax.get_lines() if line.get_label().startswith("theta")}
        assert sorted(lines) == [f"theta{i}" for i in range(1, 7)]  # every level drawn, in its own line
        for text in ax.get_legend().get_texts():
            shared = [lines[level] for level in text.get_text().split(", ")]
            if len(shared) > 1:  # one line for several levels: each one's dashes at their own place
                assert len({line.get_linestyle() for line in shared}) == 1  # dashed ...
                assert len({repr(line._unscaled_dash_pattern) for line in shared}) == len(shared)  # ... in turn
        for level, line in lines.items():
            colours.setdefault(level, set()).add(line.get_color())
    assert [[t.get_text() for t in ax.get_legend().get_texts()] for ax in fig.axes] == [
        ["theta1, theta2, theta3, theta4", "theta5, theta6"], ["theta1, theta4", "theta2, theta3, theta6", "theta5"]]
    assert all(len(c) == 1 for c in colours.values()), colours
    assert len({next(iter(c)) for c in colours.values()}) == 6  # and no two levels alike


def test_maze_training_and_final_plots(figures, tmp_path):
    from remidi.experiments.maze import SOLVE_RATES

    exp = get_experiment("tmaze")
    results = {}
    for algo, rate, share in (("dr", 0.3, None), ("plr", 0.05, 0.97), ("remidi", 0.95, 0.05)):
        history = {m: np.clip(curve(0.0, rate, 0.1), 0, 1) for m in SOLVE_RATES}
        history["solve_rate/mean"] = np.mean([history[m] for m in SOLVE_RATES], axis=0)
        nan = np.full((len(SEEDS), len(STEPS)), np.nan)
        history["replay_fraction/tmaze"] = nan if share is None else np.clip(curve(0.5, share, 0.1), 0, 1)
        history["buffer_fraction/tmaze"] = nan if share is None else np.clip(curve(0.5, share, 0.1), 0, 1)
        results[algo] = RunResult(steps=STEPS, history=history)
    exp.plot(tmp_path, results, exp.config_factory(), preset="cpu", seeds=list(SEEDS))
    for name in ("training.png", "final.png"):
        check(figures[name])
        assert "preset cpu" in figure_text(figures[name])


def test_brax_training_plot(figures, tmp_path):
    exp = get_experiment("brax-hopper")
    results = {}
    for algo, ret in (("dr", 120.0), ("plr", 15.0), ("remidi", 200.0)):
        history = {"return/undisturbed": curve(0.0, ret, 40.0),
                   "replay_fraction/type_b": np.clip(curve(0.5, 0.9 if algo == "plr" else 0.0, 0.2), 0, 1),
                   "buffer_fraction/type_b": np.clip(curve(0.5, 0.9 if algo == "plr" else 0.0, 0.2), 0, 1)}
        results[algo] = RunResult(steps=STEPS, history=history)
    exp.plot(tmp_path, results, exp.config_factory(), preset="smoke", seeds=[3])
    check(figures["training.png"])
    assert "1 seed (3)" in figure_text(figures["training.png"])


@pytest.mark.parametrize("experiments", [1, 3])
def test_comparison_plot(figures, tmp_path, experiments):
    """Intervals of [0, 1] and ones clipped at 1 stay inside the axes with their ends visible; the
    axes are labelled and the caption says what a bar and a tick are."""
    a = {"tmaze": {0: 0.3, 1: 0.25, 2: 0.4, 3: 0.35}, "blindfold": {0: 0.5, 1: 0.6, 2: 0.55},
         "lever": {0: 0.0, 1: 1.0}}
    b = {"tmaze": {0: 0.01, 1: 0.02, 2: 0.0, 3: 0.05}, "blindfold": {0: 0.1, 1: 0.05, 2: 0.2},
         "lever": {0: 0.5, 1: 0.5}}
    keep = list(a)[-experiments:]
    result = {"metric": "solve_rate/mean", "algo": "remidi", "baseline": "plr",
              **compare({e: a[e] for e in keep}, {e: b[e] for e in keep})}
    plot_comparison(result, tmp_path / "cmp.png")
    fig = figures["cmp.png"]
    check(fig)
    assert all(ax.get_xlabel() for ax in fig.axes)
    text = figure_text(fig)
    assert "95%" in text and "interval" in text and "estimate" in text
    poi = fig.axes[2]
    lo, hi = poi.get_xlim()
    assert lo < 0 and hi > 1  # an interval ending at 0 or 1 shows its end
    if experiments == 1:  # P's interval [0, 1]: the estimate 0.5 is marked on it
        ((value, ci),) = [(r["probability_of_improvement"], r["poi_ci"]) for r in result["experiments"].values()]
        assert ci == [0.0, 1.0] and math.isclose(value, 0.5)
        marks = [line for line in poi.lines if line.get_marker() not in (None, "None", "", "|")
                 and line.get_linestyle() in ("None", "none", "")]
        assert any(np.allclose(line.get_xdata(), 0.5) for line in marks)
