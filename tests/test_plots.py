"""Plots: one style and one order per algorithm everywhere, no legend entry for a curve that is not
drawn, reference lines in the legend, coinciding curves drawn once (no training: made-up results)."""

import json

import numpy as np
import pytest

from remidi.experiments import get_experiment, plots
from remidi.experiments.base import RunResult, RunSpec
from remidi.experiments.resuming import _run_order
from remidi.experiments.running import write_run_config

STEPS = np.array([10, 20, 30, 40])


def legend(ax):
    return [t.get_text() for t in ax.get_legend().get_texts()]


def lever_result(algo, seed_values):
    rng = np.random.default_rng(0)
    history = {m: rng.uniform(0, 1, (2, len(STEPS))) for m in
               ("solve_rate/visible", "solve_rate/hidden", "regret/visible/mean", "buffer_fraction/hidden")}
    history["regret/hidden/worst"] = np.full((2, len(STEPS)), 20.0)
    history["replay_fraction/hidden"] = np.full((2, len(STEPS)), seed_values)
    return RunResult(steps=STEPS, history=history)


def test_fixed_style_per_algorithm():
    styles = [plots.algorithm_style(a) for a in ("dr", "plr", "minimax-return", "remidi")]
    assert len({s["color"] for s in styles}) == 4
    assert len({(s["linestyle"], s["marker"]) for s in styles}) == 4  # identical curves stay visible
    assert plots.algorithm_style("plr") == plots.algorithm_style("plr")
    assert plots.algorithm_style("my-algo") == plots.algorithm_style("my-algo")
    # the results page's labels: an estimator keeps its algorithm's style, the masked policy too;
    # ReMiDi's variants each get a colour and line style of their own, and keep ReMiDi's marker
    assert plots.algorithm_style("paired (perfect)") == plots.algorithm_style("paired")
    assert plots.algorithm_style("remidi (masked)") == plots.algorithm_style("remidi")
    variants = [plots.algorithm_style(f"remidi ({v})") for v in ("combine", "rehearsal 0.3", "belief, margin 2",
                                                                 "simulated, ratio, false rate 0, margin 5")]
    assert len({s["color"] for s in variants + styles}) == 8
    assert {s["marker"] for s in variants} == {plots.algorithm_style("remidi")["marker"]}
    # in one figure no two names are drawn alike, however their labels differ
    names = ["plr", "remidi", "remidi (masked)", "remidi (rehearsal 0.1)", "remidi (rehearsal 0.3)", "remidi (belief)",
             "remidi (belief, margin 2)", "remidi (combine)"]
    figure = plots.distinct_styles(names)
    assert len({(s["color"], s["linestyle"], s["marker"]) for s in figure.values()}) == len(names)
    assert figure["plr"] == plots.algorithm_style("plr") and figure["remidi"] == plots.algorithm_style("remidi")


def test_lever_plot(figures, tmp_path):
    lever = get_experiment("lever")
    results = {"remidi": lever_result("remidi", 0.0), "dr": lever_result("dr", np.nan),
               "plr": lever_result("plr", 1.0)}
    lever.plot(tmp_path, results, lever.config_factory())
    axes = {ax.get_title(): ax for ax in figures["training.png"].axes if ax.get_visible()}
    hidden = axes["solve rate, hidden answer"]
    assert legend(hidden) == ["remidi", "dr", "plr", "chance (1/64)"]  # the run's order, then the reference
    assert hidden.get_ylim()[0] <= 0 and hidden.get_ylim()[1] >= 1
    chance = [line for line in hidden.get_lines() if line.get_label() == "chance (1/64)"]
    assert chance and chance[0].get_ydata()[0] == pytest.approx(1 / 64) and chance[0].get_linestyle() == "--"
    assert hidden.get_ylabel() == "solve_rate/hidden"
    replay = axes["share of hidden levels among replayed"]
    assert legend(replay) == ["remidi", "plr"]  # dr never replays ...
    assert [t.get_text() for t in replay.texts] == ["n/a: dr"]  # ... and the panel says so
    assert not axes["solve rate, hidden answer"].texts
    # a panel keeps its curves and reference lines clear of the frame, its legend below it
    # (tests/test_plot_bounds.py checks every panel of every experiment)
    regret = axes["mean regret over visible levels"]
    lo, hi = regret.get_ylim()
    drawn = np.concatenate([line.get_ydata() for line in regret.get_lines()])
    assert min(hi - drawn.max(), drawn.min() - lo) >= 0.99 * plots.MARGIN / (1 + 2 * plots.MARGIN) * (hi - lo)
    figures["training.png"].canvas.draw()
    assert regret.get_legend().get_window_extent().y1 < regret.get_window_extent().y0
    colours = {line.get_label(): line.get_color() for ax in axes.values() for line in ax.get_lines()}
    for algo in results:
        assert colours[algo] == plots.algorithm_style(algo)["color"]
    worst = axes["worst-case regret over hidden levels"]
    assert "minimax regret (19.6875)" in legend(worst)


def test_tabular_plot_reference_in_legend_and_coinciding_curves_once(figures, tmp_path):
    exp = get_experiment("tabular-shared")
    same = np.tile(np.linspace(0.1, 0.5, len(STEPS)), (3, 1))
    history = {"regret/h1": same + 0.1, "regret/h3": same + 0.3, "regret/h5": same + 0.9,
               **{f"adversary_prob/theta{i}": same * (0.1 if i <= 4 else 1.0) for i in range(1, 7)}}
    history["adversary_prob/theta2"] = same * 0.5
    reference = {"blp_regret": {"h1": 0.175, "h3": 0.175, "h5": 1.0}}
    results = {algo: RunResult(steps=STEPS, history=history, extra={"reference": reference})
               for algo in ("mmr", "remidi")}
    exp.plot(tmp_path, results, exp.config_factory())
    regret = figures["regret.png"].axes[0]
    assert legend(regret) == ["observation h1", "observation h3", "observation h5", "exact BLP: 0.175 (h1, h3), 1 (h5)"]
    assert not regret.texts  # no text drawn over the curves
    adversary = figures["adversary.png"].axes[0]
    assert legend(adversary) == ["theta1, theta3, theta4", "theta2", "theta5, theta6"]
    assert [ax.get_title() for ax in figures["adversary.png"].axes] == [
        "mmr: adversary level probabilities", "remidi: adversary level probabilities"]


def test_the_caption_names_the_colour_reference_lines_are_drawn_in(figures, tmp_path):
    """The footer of a figure with reference lines names their colour as drawn (an opaque grey, not
    black), in the lever's training plot and the tabular game's regret plot."""
    import matplotlib.colors as mcolors

    lever = get_experiment("lever")
    lever.plot(tmp_path, {"plr": lever_result("plr", 1.0)}, lever.config_factory())
    tabular = get_experiment("tabular-shared")
    history = {"regret/h1": np.tile(np.linspace(0.1, 0.5, len(STEPS)), (2, 1))}
    tabular.plot(tmp_path, {"mmr": RunResult(steps=STEPS, history=history,
                                             extra={"reference": {"blp_regret": {"h1": 0.175}}})},
                 tabular.config_factory())
    for name, reference in (("training.png", "chance (1/64)"), ("regret.png", "exact BLP: 0.175 (h1)")):
        fig = figures[name]
        caption = fig._supxlabel.get_text().replace("\n", " ")
        assert "dashed grey" in caption and "black" not in caption, caption
        lines = [line for ax in fig.axes for line in ax.get_lines() if line.get_label() == reference]
        assert lines, name
        for line in lines:
            r, g, b, a = mcolors.to_rgba(line.get_color(), line.get_alpha())
            assert r == g == b and 0.25 < r < 0.75 and a == 1.0, (name, r, a)  # opaque grey, as the words say


def test_several_algorithm_run_records_and_keeps_the_given_order(tmp_path):
    lever = get_experiment("lever")
    for algo in ("remidi", "dr", "plr"):
        (tmp_path / algo).mkdir()
        write_run_config(tmp_path / algo, RunSpec(lever, ["remidi", "dr", "plr"], "smoke", [0], argv=["run"]), algo,
                         lever.config_factory())
    assert json.loads((tmp_path / "dr" / "config.json").read_text())["algos"] == ["remidi", "dr", "plr"]
    order = sorted(("dr", "plr", "remidi"), key=lambda a: _run_order(tmp_path / a, lever, a))
    assert order == ["remidi", "dr", "plr"]  # not alphabetical
    # runs recorded before config.json had "algos": the experiment's order
    for algo in ("remidi", "dr", "plr"):
        path = tmp_path / algo / "config.json"
        path.write_text(json.dumps({k: v for k, v in json.loads(path.read_text()).items() if k != "algos"}))
    order = sorted(("remidi", "plr", "dr"), key=lambda a: _run_order(tmp_path / a, lever, a))
    assert order == ["dr", "plr", "remidi"]


def test_tabular_regret_curves_are_told_apart_and_labelled_in_words(figures, tmp_path):
    """Under BLP h1 and h3 both end at 0.175: the two curves differ in line style and marker (the
    markers at shifted points), and the axes read as words, not metric keys."""
    exp = get_experiment("tabular-shared")
    steps = np.arange(10, 170, 10)
    same = np.tile(np.linspace(0.5, 0.175, len(steps)), (2, 1))
    history = {"regret/h1": same, "regret/h3": same, "regret/h5": same + 0.8,
               **{f"adversary_prob/theta{i}": np.full_like(same, 1 / 6) for i in range(1, 7)}}
    reference = {"blp_regret": {"h1": 0.175, "h3": 0.175, "h5": 1.0}}
    exp.plot(tmp_path, {"remidi": RunResult(steps=steps, history=history, extra={"reference": reference})},
             exp.config_factory())
    regret = figures["regret.png"].axes[0]
    lines = {line.get_label(): line for line in regret.get_lines() if line.get_label().startswith("observation")}
    assert list(lines) == ["observation h1", "observation h3", "observation h5"]
    h1, h3 = lines["observation h1"], lines["observation h3"]
    assert (h1.get_linestyle(), h1.get_marker()) != (h3.get_linestyle(), h3.get_marker())
    assert h1.get_markevery() != h3.get_markevery()  # the markers of coinciding curves do not cover each other
    for fig, ax in ((figures["regret.png"], regret), (figures["adversary.png"], figures["adversary.png"].axes[0])):
        assert "/" not in ax.get_ylabel() and "<" not in ax.get_ylabel(), ax.get_ylabel()
