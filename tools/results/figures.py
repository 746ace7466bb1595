"""The results page's figures: per experiment its training curves, per claim an interval plot of
its primary metric, and the scale study's solve rate against environment steps."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from remidi import stats

from tools.results.claims import SCALE_TASKS, SECTIONS
from tools.results.data import ROOT, lost_note, metric_values

FIGURES = ROOT / "docs" / "results"


def draw_figures(runs: dict, results: list[dict], folder: Path = FIGURES, unfinished: dict | None = None) -> list[Path]:
    """Per experiment its training curves (mean ± std over seeds) and per claim an interval plot."""
    from remidi.experiments.plots import Curve, Panel, distinct_styles, plot_panels

    written = []
    for exp, (algos, _, curves) in SECTIONS.items():
        present = [a for a in algos if (exp, a) in runs]
        if not curves or not present:
            continue
        panels, styles = [], distinct_styles(present, _style)  # one style per algorithm in every panel
        for name in curves:
            lines = [Curve(a, *runs[exp, a].curves[name], styles[a]) for a in present
                     if name in runs[exp, a].curves and np.isfinite(runs[exp, a].curves[name][1]).any()]
            panels.append(Panel(name, lines, ylabel=name, xlabel="update",
                                missing=[a for a in present if a not in {c.label for c in lines}]))
        path = folder / f"{exp}-curves.png"
        plot_panels(path, panels, title=exp)  # the default caption says what lines and bands are
        written.append(path)
    for exp, what in SCALE_TASKS:
        path = folder / f"scale-{exp}.png"
        scale_figure(path, runs, exp, what, unfinished)
        written.append(path)
    for r in results:
        path = folder / f"claim-{r['claim'].key}.png"
        if r["verdict"] != "pending":
            _interval_figure(path, r, runs)
            written.append(path)
        else:  # a claim back to pending (e.g. its seed count raised) keeps no figure of an old verdict
            path.unlink(missing_ok=True)
    return written


SCALE_ALGOS = ("plr", "minimax-return", "remidi")
# the scale study's presets, each in its line style; `paper`: an unfinished run (collect_unfinished)
SCALE_LINES = {"cpu": "-", "cpu4x": "--", "paper": ":"}


def _curve(run, preset: str) -> dict | None:
    """``run``'s held-out solve rate: environment steps x [T] (update × num_envs × num_steps) of
    its training evaluations, their mean over seeds [T] and its 95% bootstrap interval [T, 2]."""
    if run is None or "solve_rate/mean" not in run.curves:
        return None
    steps, values = run.curves["solve_rate/mean"]
    x = np.asarray(steps, float) * run.config["num_envs"] * run.config["num_steps"]
    keep = np.isfinite(values).all(axis=0)
    band = np.array([stats.bootstrap_ci(values[:, t]) for t in np.flatnonzero(keep)])
    return {"preset": preset, "x": x[keep], "mean": values[:, keep].mean(axis=0), "band": band,
            "seeds": len(run.seeds), "final": None, "updates": None, "lost": ""}


def scale_curves(runs: dict, experiment: str, algo: str, unfinished: dict | None = None) -> list[dict]:
    """``algo``'s held-out solve rate at each scale of the study (:func:`_curve`): per preset with
    finished runs, with ``final``, its final checkpoint's (``remidi evaluate``, 30 attempts) mean and
    interval at the last x; then an unfinished run of another preset (``unfinished``:
    :func:`~tools.results.data.load_unfinished`), with ``updates``: (reached, of)."""
    found = []
    for preset in ("cpu", "cpu4x"):
        name = algo if preset == "cpu" else f"{algo} @{preset}"
        c = _curve(runs.get((experiment, name)), preset)
        if c is not None:
            final = list(metric_values(runs, experiment, name, "evaluate:solve_rate/mean").values())
            c["final"] = (float(np.mean(final)), stats.bootstrap_ci(final)) if final else None
            found.append(c)
    for (exp, _), (run, progress) in (unfinished or {}).items():
        if exp == experiment and progress["algo"] == algo:
            c = _curve(run, progress["preset"])
            if c is not None:
                c["updates"] = (progress["updates"], progress["num_updates"])
                c["lost"] = lost_note(progress)
                found.append(c)
    return found


def scale_figure(path: Path, runs: dict, experiment: str, what: str, unfinished: dict | None = None) -> None:
    """Held-out solve rate against environment steps for PLR⊥, minimax return and ReMiDi at every
    scale of the study (line style: the preset), means over seeds with their 95% bootstrap
    bands; a diamond with its interval: the final checkpoint's evaluation (30 attempts); an
    unfinished run's last evaluation: a square, the updates it reached in its legend entry."""
    import matplotlib.pyplot as plt

    from remidi.experiments.plots import algorithm_style, padded

    fig, ax = plt.subplots(figsize=(10, 5.2), layout="constrained")
    low, high, right = [0.0], [0.0], [0.0]
    for algo in SCALE_ALGOS:
        color = algorithm_style(algo)["color"]
        for c in scale_curves(runs, experiment, algo, unfinished):
            reached = "" if c["updates"] is None else f", {c['updates'][0]:,} of {c['updates'][1]:,} updates"
            reached += f"; {c['lost']}" if c["lost"] else ""
            ax.plot(c["x"], c["mean"], color=color, linestyle=SCALE_LINES[c["preset"]], linewidth=1.6,
                    label=f"{algo} ({c['preset']}, {c['seeds']} seeds{reached})")
            ax.fill_between(c["x"], c["band"][:, 0], c["band"][:, 1], color=color, alpha=0.15, linewidth=0)
            low.append(float(c["band"][:, 0].min()))
            high.append(float(c["band"][:, 1].max()))
            right.append(float(c["x"][-1]))
            if c["final"] is not None:
                mean, (lo, hi) = c["final"]
                ax.errorbar([c["x"][-1]], [mean], yerr=[[mean - lo], [hi - mean]], color=color, marker="D",
                            markerfacecolor="white", capsize=3, linestyle="none")
                low.append(lo)
                high.append(hi)
            if c["updates"] is not None:  # where the unfinished run stands (its updates: in the legend)
                ax.plot([c["x"][-1]], [c["mean"][-1]], color=color, marker="s", linestyle="none")
    ax.set_ylim(*padded(min(low), max(high), (0.0, None)))
    ax.set_xlim(*padded(0.0, max(right)))
    ax.xaxis.set_major_formatter(lambda x, _: f"{x / 1e6:g}M" if x else "0")
    ax.set_xlabel("environment steps (update × envs × steps per rollout)")
    ax.set_ylabel("held-out solve rate (mean of the ten mazes)")
    ax.set_title(f"scale study, {what}: held-out solve rate against training")
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.supxlabel("line: mean over seeds of training's evaluations (10 attempts per maze); band: its 95% bootstrap "
                  "interval; diamond: the final checkpoint's mean (30 attempts) with its 95% interval; solid: cpu "
                  "preset, dashed: cpu4x, dotted: the paper preset (LSTM 256); square: a run still training, at its "
                  "last evaluation (its updates in the legend)",
                  fontsize=8, wrap=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _style(name: str) -> dict:
    """The algorithm's plot style; a learned generator with PAIRED's own estimator drawn apart
    from the same algorithm with perfect regret."""
    from remidi.experiments.plots import algorithm_style

    style = algorithm_style(name)
    return {**style, "linestyle": ":", "marker": "1"} if name.endswith("(paired)") else style


def _interval_figure(path: Path, result: dict, runs: dict) -> None:
    """The claim's algorithms: mean and its 95% interval per experiment (rliable's style), and a
    bound claim's allowed interval shaded across its algorithm's rows."""
    import matplotlib.pyplot as plt

    from remidi.runs.compare import _interval
    from remidi.experiments.plots import _save, algorithm_style

    claim = result["claim"]
    algos = claim.algorithms
    rows = [(exp, a) for exp in claim.experiments for a in algos]
    # wrapped, so that a long claim title never cuts off the verdict (its own last line)
    title = textwrap.wrap(f"{claim.title}: {claim.metric.split(':', 1)[1]} (mean, 95% CI, seeds)", 95)
    title += textwrap.wrap(f"verdict: {result['verdict']}", 95)  # a stale verdict takes more than one line
    fig, ax = plt.subplots(figsize=(6, 0.5 + 0.4 * len(rows) + 0.15 * len(title)))
    for y, (exp, a) in enumerate(rows):
        x = list(metric_values(runs, exp, a, claim.metric).values())
        if x:
            _interval(ax, y, float(np.mean(x)), stats.bootstrap_ci(x, np.mean), algorithm_style(a)["color"])
            ax.plot(x, [y] * len(x), "k.", markersize=3, alpha=0.5)
    for name, lo, hi in claim.bounds:  # the interval the claim allows, on each of its algorithm's rows
        for y in [y for y, (_, a) in enumerate(rows) if a == name]:
            ax.fill_betweenx([y - 0.4, y + 0.4], lo, hi, color="tab:green", alpha=0.15, linewidth=0)
    if claim.bounds:  # said under the axis, where no legend covers a point
        named = len({b[0] for b in claim.bounds}) > 1
        ax.set_xlabel("shaded: the claimed bound " + ", ".join(
            f"{name} [{lo:g}, {hi:g}]" if named else f"[{lo:g}, {hi:g}]" for name, lo, hi in claim.bounds), fontsize=7)
    ax.set_yticks(range(len(rows)), [f"{e} / {a}" if len(claim.experiments) > 1 else a for e, a in rows], fontsize=8)
    ax.invert_yaxis()
    fig.suptitle("\n".join(title), fontsize=8)  # centred on the figure, not on the narrower axes
    ax.grid(alpha=0.3, axis="x")
    _save(fig, path)

