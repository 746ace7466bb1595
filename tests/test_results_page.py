"""docs/results.md is generated from committed data (tools/results/): the page and the README's
claims table match what the data give (one test, the generator's --check), the verdict rule says
what it states, and collecting a run keeps what the page needs. The tables' wording is checked by
the page itself, not sentence by sentence here."""

import csv
import dataclasses
import gzip
import json
import math

import numpy as np
import pytest

from remidi.errors import ConfigError
from tools.results import claims, data, figures, tables, verdicts
from tools.results import page as rp
from remidi.runs import table as run_table


def test_the_page_and_the_readme_match_the_committed_data(capsys):
    """``python -m tools.results.page --check``: every generated block of docs/results.md and of
    the README's claims table is what the committed data give (their wording included: a change
    of a table's code shows as a stale block, regenerated and reviewed in the page's diff)."""
    assert rp.main(["--check"]) == 0, capsys.readouterr().out + "\nrun python -m tools.results.page"


def write_run(root, experiment, algo, seeds, summary=None, evaluate=None, attempts=30, update=100, cvar_levels=256):
    """A finished run folder (100 updates) as `remidi run` and `remidi evaluate` write it (metrics:
    name → per seed); ``attempts`` and ``update``: what its evaluation recorded."""
    folder = root / experiment / f"{algo}-s{seeds[0]}"
    folder.mkdir(parents=True)
    entry = lambda per: {"mean": float(np.mean(per)), "std": 0.0, "per_seed": list(per)}  # noqa: E731
    (folder / "config.json").write_text(json.dumps({"code": {"commit": "abc1234def"}, "config": {"num_updates": 100}}))
    (folder / "summary.json").write_text(json.dumps({
        "experiment": experiment, "algo": algo, "preset": "cpu", "seeds": list(seeds), "wall_s": 60.0,
        "metrics": {k: entry(v) for k, v in (summary or {}).items()}}))
    if evaluate:
        (folder / "evaluate.json").write_text(json.dumps({"args": {"attempts": attempts, "cvar_levels": cvar_levels},
                                                          "algorithms": {algo: {
            "seeds": list(seeds), "update": update, "metrics": {k: entry(v) for k, v in evaluate.items()}}}}))
    return folder


CLAIM = claims.Claim("x", "Fig. X", "A beats B and C", "evaluate:solve_rate/mean", ("tmaze",),
                 greater=(("remidi", "plr"), ("remidi", "minimax-return")))


def verdict_of(tmp_path, remidi, plr, mr):
    for algo, values in (("remidi", remidi), ("plr", plr), ("minimax-return", mr)):
        write_run(tmp_path, "tmaze", algo, list(range(len(values))), evaluate={"solve_rate/mean": values})
    return verdicts.evaluate_claim(CLAIM, data.load_runs(tmp_path))


@pytest.mark.parametrize("attempts, update, cvar_levels, needle", [
    (10, 100, 256, "--attempts 10"), (30, 60, 256, "at update 60 of 100"), (30, 100, 64, "cvar_levels 64")])
def test_an_evaluation_of_other_arguments_or_an_unfinished_run_is_refused(tmp_path, attempts, update, cvar_levels,
                                                                          needle):
    """The page states its evaluate: metrics as the final checkpoint's with 30 attempts, and
    compares CVaR over the same levels."""
    write_run(tmp_path, "tmaze", "plr", [0, 1], evaluate={"solve_rate/mean": [0.1, 0.2]}, attempts=attempts,
              update=update, cvar_levels=cvar_levels)
    with pytest.raises(ConfigError, match=needle):
        data.load_runs(tmp_path)


def test_clear_separation_on_ten_seeds_is_reproduced(tmp_path):
    r = verdict_of(tmp_path, [0.5 + 0.01 * i for i in range(10)], [0.1 + 0.01 * i for i in range(10)],
                   [0.2 + 0.01 * i for i in range(10)])
    assert r["verdict"] == "reproduced"
    for t in r["tests"]:
        assert t["poi"] == 1.0 and t["poi_ci"][0] == 1.0
        assert t["p"] == pytest.approx(1 / 184756)  # full separation of 10 against 10: 1 / C(20, 10)
        assert t["p_holm"] == pytest.approx(2 / 184756)  # both comparisons equal: Holm multiplies the smaller by 2


def test_an_ordering_in_the_mean_only_says_that_no_test_passes(tmp_path):
    """Every comparison holds in the mean and none passes: "partly" by the rule's letter, printed
    "partly (no test passes)" wherever the verdict appears, so that no reader takes it for a claim
    that holds in some settings."""
    rng = np.random.default_rng(0)
    noise = lambda: rng.normal(0, 0.3, 10)  # noqa: E731
    r = verdict_of(tmp_path, 0.35 + noise(), 0.3 + noise(), 0.3 + noise())
    assert all(t["in_mean"] for t in r["tests"]) and not any(t["passes"] for t in r["tests"])
    assert r["verdict"] == r["rule_verdict"] == "partly (no test passes)"
    assert "| **partly (no test passes)** (`cpu` preset" in tables.verdict_table([r])
    assert "| **partly (no test passes)** (`cpu` preset" in tables.claims_table([r])


def test_one_comparison_passing_and_one_holding_in_the_mean_only_is_plain_partly(tmp_path):
    r = verdict_of(tmp_path, [0.5 + 0.01 * i for i in range(10)], [0.1 + 0.01 * i for i in range(10)],
                   [0.49 + 0.01 * i for i in range(10)])
    assert [t["passes"] for t in r["tests"]] == [True, False] and all(t["in_mean"] for t in r["tests"])
    assert r["verdict"] == "partly"
    assert "| **partly** (" in tables.verdict_table([r]) and "no test passes" not in tables.claims_table([r])


def test_one_comparison_passing_and_one_reversed_is_partly(tmp_path):
    r = verdict_of(tmp_path, [0.5 + 0.01 * i for i in range(10)], [0.1 + 0.01 * i for i in range(10)],
                   [0.9 + 0.01 * i for i in range(10)])
    assert [t["passes"] for t in r["tests"]] == [True, False]
    assert r["verdict"] == "partly"


def test_each_verdict_names_the_scale_of_its_runs(tmp_path):
    """The share of the paper preset's environment steps (num_updates × num_envs × num_steps), from
    what the runs' config.json records, else from the preset an algorithm's name gives."""
    r = verdict_of(tmp_path, [0.9] * 10, [0.1] * 10, [0.1] * 10)  # config.json: num_updates 100 only
    assert r["scale"] == "`cpu` preset: 5% of the paper's environment steps"  # the cpu preset's 1500 × 32 × 256
    runs = data.load_runs(tmp_path)
    for algo in ("remidi", "plr"):
        runs["tmaze", algo].config.update(num_updates=6000, num_envs=32, num_steps=256)
    assert verdicts.claim_scale(CLAIM, runs) == \
        "`cpu` preset: 20% of the paper's environment steps; `cpu` preset: 5%"  # minimax-return still at cpu's
    claim = claims.Claim("s", "x", "PLR⊥ learns with more steps", CLAIM.metric, ("tmaze",), greater=(("plr @cpu4x", "plr"),))
    assert verdicts.claim_scale(claim, {}) == "`cpu4x` preset: 20% of the paper's environment steps"
    brax = claims.Claim("b", "x", "walks", "evaluate:return/undisturbed", ("brax-ant",), greater=(("remidi @cpu", "plr"),))
    assert verdicts.claim_scale(brax, {}) == "`cpu` preset: 15% of the paper's environment steps"  # 120 × 64 × 100
    tab = claims.Claim("t", "x", "stagnates", "summary:regret/h1", ("tabular-shared",), greater=(("mmr @paper", "remidi"),))
    assert verdicts.claim_scale(tab, {}) == "`paper` preset: the paper's stated settings"
    kinetix = next(c for c in claims.CLAIMS if c.key == "kinetix-sfl-over-plr")
    kinetix_runs = {("kinetix-s", "plr"): data.Run("kinetix-s", "plr", preset="cpu")}  # Kinetix's sizes, not ReMiDi's
    assert verdicts.claim_scale(kinetix, kinetix_runs) == "`cpu` preset: 0.153% of Kinetix's environment steps"


def test_a_claim_on_runs_older_than_a_fix_it_needs_is_stale(tmp_path, monkeypatch):
    """A run whose commits predate a correction its claim needs: the claim shows "stale" with the
    commit and the change, not its verdict by the rule (kept apart); other claims are untouched."""
    verdict_of(tmp_path, [0.5 + 0.01 * i for i in range(10)], [0.1 + 0.01 * i for i in range(10)],
               [0.2 + 0.01 * i for i in range(10)])  # every run at commit abc1234def
    runs = data.load_runs(tmp_path)
    fix = claims.Fix("fff0000", "the reservoir keeps the highest key", runs=(("tmaze", "remidi"),), before=("abc1234",))
    assert claims.stale_fix(CLAIM, runs, (fix,)) is fix
    later = claims.Fix("fff0000", "later", runs=(("tmaze", "remidi"),), before=("9999999",))  # runs made after it
    other = claims.Fix("fff0000", "other runs", runs=(("lever", "remidi"),), before=("abc1234",))
    assert claims.stale_fix(CLAIM, runs, (later, other)) is None
    monkeypatch.setattr(claims, "FIXES", (fix,))
    r = verdicts.evaluate_claim(CLAIM, runs)
    assert r["rule_verdict"] == "reproduced"
    assert r["verdict"] == "stale: its runs predate fff0000 (the reservoir keeps the highest key); rerun queued"
    assert "**stale: its runs predate fff0000" in tables.verdict_table([r])
    assert claims.stale_fix(claims.CLAIMS[0], runs, (fix,)) is None  # a claim that reads none of those runs


def test_the_t_maze_remidi_over_paired_claims_read_their_rerun():
    """Their committed runs are the rerun at ab3ea79, after the reservoir fix, so no claim reads
    stale; the same claims over runs from before it (569c639) would."""
    runs = data.load_runs(data.DATA)
    by_key = {c.key: c for c in claims.CLAIMS}
    key = ("tmaze", "remidi-paired (perfect)")
    assert {str(c)[:7] for c in runs[key].commits} == {"ab3ea79"}
    for claim in ("tmaze-remidi-paired-generated", "tmaze-remidi-paired-heldout"):
        assert claims.stale_fix(by_key[claim], runs) is None
        before = {**runs, key: dataclasses.replace(runs[key], commits={"569c639" + "0" * 33})}
        assert claims.stale_fix(by_key[claim], before).commit == "ab3ea79"
    assert claims.stale_fix(by_key["tmaze-paired"], runs) is None
    assert claims.stale_fix(by_key["lever-remidi-paired"], runs) is None  # remade at ab3ea79


def test_the_reverse_ordering_is_not_reproduced(tmp_path):
    r = verdict_of(tmp_path, [0.1] * 10, [0.5 + 0.01 * i for i in range(10)], [0.4 + 0.01 * i for i in range(10)])
    assert r["verdict"] == "not reproduced"


def test_fewer_seeds_than_the_claim_needs_is_pending(tmp_path):
    r = verdict_of(tmp_path, [0.9] * 9, [0.1] * 10, [0.1] * 10)
    assert r["verdict"] == "pending"


def test_a_bound_passes_only_when_the_interval_lies_inside(tmp_path):
    claim = claims.Claim("b", "Fig. B", "near 0.175", "summary:regret/h1", ("tabular-shared",),
                     bounds=(("remidi", 0.15, 0.20),), min_seeds=4)
    write_run(tmp_path / "in", "tabular-shared", "remidi", [0, 1, 2, 3], summary={"regret/h1": [0.18, 0.19, 0.18, 0.19]})
    write_run(tmp_path / "edge", "tabular-shared", "remidi", [0, 1, 2, 3], summary={"regret/h1": [0.12, 0.22, 0.17, 0.19]})
    assert verdicts.evaluate_claim(claim, data.load_runs(tmp_path / "in"))["verdict"] == "reproduced"
    edge = verdicts.evaluate_claim(claim, data.load_runs(tmp_path / "edge"))
    assert edge["tests"][0]["in_mean"] and edge["verdict"] == "partly (no test passes)"  # its one test fails
    write_run(tmp_path / "out", "tabular-shared", "remidi", [0, 1, 2, 3], summary={"regret/h1": [0.12, 0.22, 0.25, 0.23]})
    out = verdicts.evaluate_claim(claim, data.load_runs(tmp_path / "out"))  # a claim of bounds only: none holds in the mean
    assert not out["tests"][0]["in_mean"] and out["verdict"] == "not reproduced"


def test_a_no_worse_test_passes_only_when_the_differences_interval_lies_above_minus_the_margin(tmp_path):
    """"A no worse than B by more than δ": the 95% interval of mean(A) − mean(B) (independent
    bootstrap) above −δ. Checked against a bootstrap written here in numpy (same percentile rule)."""
    claim = claims.Claim("nw", "constructed", "A no worse than B", "summary:solve_rate/lit", ("tabular-shared",),
                         no_worse=(("remidi", "plr", 0.05),), min_seeds=5)
    cases = {"equal": ([0.50, 0.52, 0.48, 0.51, 0.49], "reproduced"),
             "slightly below": ([0.47, 0.49, 0.45, 0.48, 0.46], "partly (no test passes)"),  # −0.03 in the mean
             "far below": ([0.30, 0.32, 0.28, 0.31, 0.29], "not reproduced")}
    plr = [0.50, 0.53, 0.47, 0.51, 0.49]
    rng = np.random.default_rng(1)
    for name, (remidi, expected) in cases.items():
        folder = tmp_path / name.replace(" ", "-")
        write_run(folder, "tabular-shared", "remidi", [0, 1, 2, 3, 4], summary={"solve_rate/lit": remidi})
        write_run(folder, "tabular-shared", "plr", [0, 1, 2, 3, 4], summary={"solve_rate/lit": plr})
        r = verdicts.evaluate_claim(claim, data.load_runs(folder))
        (t,) = r["tests"]
        assert r["verdict"] == expected, name
        assert t["difference"] == pytest.approx(np.mean(remidi) - np.mean(plr))
        draws = [np.mean(rng.choice(remidi, 5)) - np.mean(rng.choice(plr, 5)) for _ in range(20000)]
        assert t["difference_ci"][0] == pytest.approx(np.percentile(draws, 2.5), abs=0.004)


def test_the_key_numbers_name_the_smallest_and_largest_group(tmp_path):
    r = verdict_of(tmp_path, [0.5 + 0.01 * i for i in range(12)], [0.1 + 0.01 * i for i in range(10)],
                   [0.2 + 0.01 * i for i in range(10)])
    assert tables.key_numbers(r).endswith("(10–12 seeds)")


def test_an_empty_active_buffer_has_no_share_of_anything(tmp_path):
    """buffer_fraction/<tag> is logged 0 for an empty buffer: the page reads it as undefined, so
    a bound like [0, 0.1] fails rather than passes on a run whose buffer holds nothing."""
    write_run(tmp_path, "lever-noisy", "remidi", [0, 1, 2],
              summary={"buffer_fraction/hidden": [0.0, 0.0, 0.0], "buffer_size": [32.0, 0.0, 32.0]})
    runs = data.load_runs(tmp_path)
    values = data.metric_values(runs, "lever-noisy", "remidi", "summary:buffer_fraction/hidden")
    assert values[0] == 0.0 and math.isnan(values[1]) and values[2] == 0.0
    claim = claims.Claim("b", "x", "keeps hidden out", "summary:buffer_fraction/hidden", ("lever-noisy",),
                     bounds=(("remidi", 0.0, 0.1),), min_seeds=3)
    assert verdicts.evaluate_claim(claim, runs)["verdict"] != "reproduced"


def test_parts_of_one_algorithm_are_merged_by_seed_and_a_seed_twice_is_an_error(tmp_path):
    write_run(tmp_path, "tmaze", "plr", [0, 1], evaluate={"solve_rate/mean": [0.1, 0.2]})
    write_run(tmp_path, "tmaze", "plr", [5, 6], evaluate={"solve_rate/mean": [0.3, 0.4]})
    runs = data.load_runs(tmp_path)
    assert data.metric_values(runs, "tmaze", "plr", "evaluate:solve_rate/mean") == {0: 0.1, 1: 0.2, 5: 0.3, 6: 0.4}
    assert runs["tmaze", "plr"].seeds == [0, 1, 5, 6]
    write_run(tmp_path, "tmaze", "plr", [1, 2], evaluate={"solve_rate/mean": [0.5, 0.6]})
    with pytest.raises(ConfigError, match="seed 1 of tmaze / plr is in two runs"):
        data.load_runs(tmp_path)


def test_collect_keeps_the_files_and_the_curves_the_page_draws(tmp_path):
    run = write_run(tmp_path / "runs", "tmaze", "plr", [3, 4], summary={"solve_rate/mean": [0.1, 0.2]},
                    evaluate={"solve_rate/mean": [0.1, 0.2]})
    with open(run / "metrics.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["seed", "step", "metric", "value"])
        for step in range(0, 3000, 10):  # 300 log points, two metrics, one the page does not draw
            for seed in (3, 4):
                w.writerow([seed, step, "solve_rate/mean", step / 3000])
                w.writerow([seed, step, "regret/undrawn", 1.0])
    [target] = data.collect(run, tmp_path / "data")
    assert target == tmp_path / "data" / "tmaze" / "plr-s3"
    assert {p.name for p in target.iterdir()} == {"config.json", "summary.json", "evaluate.json", "metrics.csv.gz"}
    with gzip.open(target / "metrics.csv.gz", "rt") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["metric"] for r in rows} == {"solve_rate/mean"}
    steps = sorted({int(r["step"]) for r in rows})
    assert len(steps) == data.MAX_POINTS and steps[0] == 0 and steps[-1] == 2990
    runs = data.load_runs(tmp_path / "data")
    curve_steps, values = runs["tmaze", "plr"].curves["solve_rate/mean"]
    assert values.shape == (2, data.MAX_POINTS) and np.array_equal(curve_steps, steps)


def test_render_replaces_blocks_and_refuses_unknown_ones():
    page = "a\n<!-- generated:x -->\nold\n<!-- /generated:x -->\nb\n<!-- generated:y -->\n<!-- /generated:y -->\n"
    out = rp.render(page, {"x": "new", "y": "| t |"})
    assert out == "a\n<!-- generated:x -->\nnew\n<!-- /generated:x -->\nb\n<!-- generated:y -->\n| t |\n<!-- /generated:y -->\n"
    assert rp.stale_blocks(out, {"x": "new", "y": "| t |"}) == []
    assert rp.stale_blocks(page, {"x": "new", "y": "| t |"}) == ["x", "y"]
    with pytest.raises(ConfigError, match="unknown generated block 'x'"):
        rp.render(page, {"y": ""})


def test_labels_name_what_differs_from_the_exact_single_policy_form():
    assert run_table.label("remidi", {}) == "remidi"
    assert run_table.label("remidi", {"remidi": {"tracker": "belief", "belief_margin": 2.0}}) == "remidi (belief, margin 2)"
    assert run_table.label("remidi", {"remidi": {"tracker": "belief", "belief_margin": 1e-3}}) == "remidi (belief)"
    # remidi.belief_spread: named where it differs from the default; a run from before the key is named as before
    from remidi.engine.config import ReMiDiConfig

    assert run_table.BELIEF_SPREAD == ReMiDiConfig().belief_spread
    spread = {"tracker": "belief", "belief_spread": run_table.BELIEF_SPREAD}
    assert run_table.label("remidi", {"remidi": spread}) == "remidi (belief)"
    assert run_table.label("remidi", {"remidi": {"tracker": "belief", "belief_spread": 0.0}}) == "remidi (belief, spread 0)"
    assert run_table.label("remidi", {"remidi": {"tracker": "simulated", "belief_spread": 0.0, "belief_margin": 5.0}}) \
        == "remidi (simulated, margin 5, spread 0)"
    assert run_table.label("remidi", {"remidi": {"policy": "combine"}}) == "remidi (combine)"
    assert run_table.label("remidi-accel", {"remidi": {"rehearsal": 0.1}}) == "remidi-accel (rehearsal 0.1)"
    assert run_table.label("remidi", {"remidi": {"policy": "masked"}},
                    ["remidi", "run", "tmaze", "--set", "remidi.policy=masked"]) == "remidi (masked)"
    assert run_table.label("plr", {"remidi": {"policy": "combine"}}) == "plr"  # only a buffer sequence has these forms
    assert run_table.label("paired", {"paired": {"estimator": "perfect"}}) == "paired (perfect)"
    assert run_table.label("remidi-paired", {"paired": {"estimator": "perfect"}, "remidi": {"tracker": "belief"}}) == \
        "remidi-paired (perfect, belief)"
    assert run_table.label("remidi-paired", {"paired": {"estimator": "perfect"}, "remidi": {"tracker": "prefix"}}) == \
        "remidi-paired (perfect)"


def test_a_claim_figure_shows_its_whole_title_and_the_verdict(tmp_path, monkeypatch):
    """The longest claim title on the page, wrapped: every line of it lies inside the figure and
    the last one names the verdict (one long line once cut the verdict off at the right edge)."""
    from remidi.experiments import plots

    claim = max(claims.CLAIMS, key=lambda c: len(c.title) + len(c.metric))
    drawn = []
    monkeypatch.setattr(plots, "_save", lambda fig, path: drawn.append(fig))
    result = {"claim": claim, "verdict": "not reproduced"}
    figures._interval_figure(tmp_path / "claim.png", result, {})
    (fig,) = drawn
    fig.tight_layout()
    fig.canvas.draw()
    import matplotlib.text

    texts = [t for t in fig.findobj(matplotlib.text.Text) if t.get_visible() and t.get_text()]
    for t in texts:  # the title, the algorithms' names, the ticks
        box = t.get_window_extent()
        assert 0 <= box.x0 and box.x1 <= fig.bbox.width and 0 <= box.y0 and box.y1 <= fig.bbox.height, t
    title = max(texts, key=lambda t: len(t.get_text())).get_text()
    assert title.splitlines()[-1] == "verdict: not reproduced"
    assert claim.title in title.replace("\n", " ")


def test_the_brax_floors_table_names_the_algorithms_above_standing_still(tmp_path):
    for algo, values in (("plr", [-70.0, -80.0]), ("remidi", [90.0, 110.0])):
        write_run(tmp_path, "brax-ant", algo, [0, 1], evaluate={"return/undisturbed": values})
    floors = {"brax-ant": {"zero_action": 83.2, "normal_actions": -74.7},
              "brax-hopper": {"zero_action": 97.6, "normal_actions": 16.9}}
    rows = tables.floors_table(data.load_runs(tmp_path), floors).splitlines()[2:]
    # a row per morphology with floors, "—" where it has no run
    assert rows == ["| ant | 83.2 | -74.7 | -75.0 | — | 100.0 | remidi |", "| hopper | 97.6 | 16.9 | — | — | — | — |"]
    with pytest.raises(ConfigError, match="back end"):  # the runs' back end is not the floors'
        tables.floors_table(data.load_runs(tmp_path), {**floors, "config": {"backend": "spring"}})


def test_the_mean_action_table_reads_the_seeds_evaluated_both_ways(tmp_path):
    """evaluate-mode.json (``remidi evaluate --action mode``) is its own source, collected beside
    evaluate.json; the table compares both on the seeds that have both, and an evaluation that
    acted otherwise than its file says is refused."""
    runs_dir = tmp_path / "runs"
    write_run(runs_dir, "brax-ant", "plr", [0, 1], evaluate={"return/undisturbed": [-70.0, -80.0]})
    folder = write_run(runs_dir, "brax-ant", "remidi", [5, 6, 7], evaluate={"return/undisturbed": [10.0, 20.0, 30.0]})
    mode = json.loads((folder / "evaluate.json").read_text())
    mode["args"]["action"] = "mode"
    mode["algorithms"]["remidi"]["metrics"]["return/undisturbed"]["per_seed"] = [100.0, 110.0, 120.0]
    (folder / "evaluate-mode.json").write_text(json.dumps(mode))
    for run in ("brax-ant/plr-s0", "brax-ant/remidi-s5"):
        (runs_dir / run / "metrics.csv").write_text("seed,step,metric,value\n")
        data.collect(runs_dir / run, tmp_path / "data")
    assert (tmp_path / "data" / "brax-ant" / "remidi-s5" / "evaluate-mode.json").is_file()
    rows = tables.mode_table(data.load_runs(tmp_path / "data")).splitlines()[2:]
    assert rows[:3] == ["| ant | plr | — | — | — |", "| ant | minimax-return | — | — | — |",
                        "| ant | remidi | 3 seeds (5–7) | 20.0 | 110.0 |"]
    mode["args"]["action"] = "sample"  # a sampled evaluation under the mode's name
    (folder / "evaluate-mode.json").write_text(json.dumps(mode))
    with pytest.raises(ConfigError, match="evaluate-mode.json: evaluated with --action sample"):
        data.collect(folder, tmp_path / "again")
    assert not (tmp_path / "again").exists()  # refused before anything is copied


def test_a_run_trained_again_is_set_beside_its_original_and_counted_in_no_claim(tmp_path):
    """A committed run trained again (its seeds, commit and preset) to keep what its folder did not:
    collected into the repeats folder (its carried archive under inflight/repeats deleted), its
    mean-action row marked "trained again" under the original's, its sampled evaluation compared
    seed by seed with the original's, and never merged into the runs the claims read."""
    write_run(tmp_path / "data", "brax-ant", "remidi", [0, 1, 2], evaluate={"return/undisturbed": [10.0, 20.0, 30.0]})
    again = write_run(tmp_path / "runs", "brax-ant", "remidi", [0, 1, 2],
                      evaluate={"return/undisturbed": [10.0, 26.0, 30.0]})
    mode = json.loads((again / "evaluate.json").read_text())
    mode["args"]["action"] = "mode"
    mode["algorithms"]["remidi"]["metrics"]["return/undisturbed"]["per_seed"] = [40.0, 50.0, 60.0]
    (again / "evaluate-mode.json").write_text(json.dumps(mode))
    (again / "metrics.csv").write_text("seed,step,metric,value\n")
    carried = tmp_path / "inflight" / "repeats" / "brax-ant" / "remidi-s0.txz"
    carried.parent.mkdir(parents=True)
    carried.write_bytes(b"archive")
    (tmp_path / "inflight" / "brax-ant").mkdir()
    original_archive = tmp_path / "inflight" / "brax-ant" / "remidi-s0.txz"  # a data run's, left alone
    original_archive.write_bytes(b"archive")
    for folder, out in ((tmp_path / "data" / "brax-ant" / "remidi-s0", "/runs/brax-ant/remidi-s0"),
                        (again, "/runs/repeats/brax-ant/remidi-s0")):
        doc = json.loads((folder / "config.json").read_text())
        (folder / "config.json").write_text(json.dumps({**doc, "command": ["remidi", "run", "--out", out]}))
    kept = (tmp_path / "data" / "brax-ant" / "remidi-s0" / "evaluate.json").read_bytes()
    with pytest.raises(ConfigError, match="--collect-repeat"):  # collected as a run of its own: refused
        data.collect(again, tmp_path / "data")
    assert (tmp_path / "data" / "brax-ant" / "remidi-s0" / "evaluate.json").read_bytes() == kept
    assert data.collect(again, tmp_path / "repeats") == [tmp_path / "repeats" / "brax-ant" / "remidi-s0"]
    assert not carried.exists() and original_archive.exists()
    runs, repeats = data.load_runs(tmp_path / "data"), data.load_runs(tmp_path / "repeats")
    original = data.metric_values(runs, "brax-ant", "remidi", "evaluate:return/undisturbed")
    assert original == {0: 10.0, 1: 20.0, 2: 30.0}  # the original's values alone
    rows = tables.mode_table(runs, repeats).splitlines()[2:]
    assert rows[2] == "| ant | remidi | 3 seeds (0–2), trained again | 22.0 | 50.0 |"
    assert tables.mode_table(runs, {}) == tables.mode_table(runs)  # no repeats: the table as before
    row = tables.repeat_table(runs, repeats).splitlines()[2]
    assert row == ("| brax-ant | remidi | 3 seeds (0–2) | `return/undisturbed` | 20.0 | 22.0 | 6.0 | 2 / 3 | "
                   "abc1234, on not recorded |")
    assert tables.repeat_table(runs, {}) == "_No committed data yet._"


def test_the_scale_curves_put_each_preset_on_the_environment_steps_it_trained(tmp_path):
    """PLR⊥ at cpu and at cpu4x: x is update × num_envs × num_steps of each run's own config, the
    band a bootstrap interval around the mean of the seeds' evaluations, the final point the
    evaluate metric's mean; an algorithm without runs draws nothing."""
    from remidi.experiments import outputs

    for preset, label, updates, values in (("cpu", "plr", [150, 300], [[0.0, 0.1], [0.2, 0.3]]),
                                           ("cpu4x", "plr", [150, 300, 450], [[0.1, 0.2, 0.4], [0.3, 0.4, 0.6]])):
        folder = write_run(tmp_path / preset, "tmaze", label, [0, 1], evaluate={"solve_rate/mean": [0.5, 0.7]},
                           update=updates[-1])
        doc = json.loads((folder / "summary.json").read_text())
        (folder / "summary.json").write_text(json.dumps({**doc, "preset": preset}))
        (folder / "config.json").write_text(json.dumps({"code": {"commit": "abc1234def"}, "config": {
            "num_updates": updates[-1], "num_envs": 32, "num_steps": 256}}))
        outputs.write_metrics_csv(folder / "metrics.csv.gz", [(seed, step, "solve_rate/mean", v)
                                                              for seed, row in enumerate(values)
                                                              for step, v in zip(updates, row)])
    runs = {**data.load_runs(tmp_path / "cpu"), **data.load_runs(tmp_path / "cpu4x")}
    assert ("tmaze", "plr @cpu4x") in runs
    cpu, cpu4x = figures.scale_curves(runs, "tmaze", "plr")
    assert (cpu["preset"], cpu4x["preset"]) == ("cpu", "cpu4x")
    np.testing.assert_array_equal(cpu4x["x"], np.array([150, 300, 450]) * 32 * 256)
    np.testing.assert_allclose(cpu4x["mean"], [0.2, 0.3, 0.5])
    assert all(lo <= m <= hi for (lo, hi), m in zip(cpu4x["band"], cpu4x["mean"]))
    assert cpu["final"][0] == pytest.approx(0.6) and cpu["seeds"] == 2
    assert figures.scale_curves(runs, "tmaze", "remidi") == []
    figures.scale_figure(tmp_path / "scale.png", runs, "tmaze", "T-maze")
    assert (tmp_path / "scale.png").stat().st_size > 10_000


def test_an_unfinished_run_is_collected_from_its_history_and_drawn_where_it_stands(tmp_path):
    """collect_unfinished reads config.json and checkpoint.history.npz alone: each block ends at
    eval_every × its number, the experiment's derived mean solve rate is added, progress.json says
    the updates reached of the run's and the device it started on (no checkpoint beside it); the
    scale curves and the table show it with those updates, its mean and the seeds above 0; a
    finished run is refused."""
    from remidi.envs.maze_names import HELD_OUT_NAMES
    from remidi.engine.run.checkpoint import HISTORY

    run = tmp_path / "runs" / "remidi-paper-s0"
    run.mkdir(parents=True)
    (run / "config.json").write_text(json.dumps({
        "experiment": "tmaze", "algo": "remidi", "preset": "paper", "seeds": [3, 4],
        "code": {"commit": "abc1234def", "device": "gpu: NVIDIA H200"},
        "config": {"num_updates": 30000, "eval_every": 250, "num_envs": 32, "num_steps": 256}}))
    # block b, seed s: every maze solved at rate 0.1 × b × s (seed 0 of the two never solves one)
    arrays = {f"h{b}|solve_rate/{n}": np.array([0.0, 0.1 * b]) for b in range(3) for n in HELD_OUT_NAMES}
    arrays.update({f"p{b}|replay": np.zeros((2, 250)) for b in range(3)})
    np.savez(run / HISTORY, **arrays)
    target = data.collect_unfinished(run, tmp_path / "data")
    assert target == tmp_path / "data" / "tmaze" / "remidi-paper-s3"  # named by its first seed
    progress = json.loads((target / data.PROGRESS).read_text())
    assert (progress["updates"], progress["num_updates"]) == (750, 30000)
    assert progress["devices"] == ["gpu: NVIDIA H200 (at its start)"] and progress["seeds"] == [3, 4]
    assert data.load_runs(tmp_path / "data") == {}  # no claim reads it
    unfinished = data.load_unfinished(tmp_path / "data")
    found, _ = unfinished["tmaze", "remidi @paper"]
    steps, values = found.curves["solve_rate/mean"]
    np.testing.assert_array_equal(steps, [250, 500, 750])
    np.testing.assert_allclose(values, [[0.0, 0.0, 0.0], [0.0, 0.1, 0.2]])
    (curve,) = figures.scale_curves({}, "tmaze", "remidi", unfinished)
    assert curve["updates"] == (750, 30000) and curve["preset"] == "paper"
    np.testing.assert_array_equal(curve["x"], np.array([250, 500, 750]) * 32 * 256)
    row = tables.unfinished_table(unfinished).splitlines()[2]
    assert "| 750 of 30,000 | 6.1M of 245.8M |" in row and "| 0.100 [" in row and "| 1 / 2 |" in row
    progress = {**progress, "lost": "2026-11-29"}  # its machine went before it finished: marked so
    row = tables.unfinished_table({("tmaze", "remidi @paper"): (found, progress)}).splitlines()[2]
    assert "| 750 of 30,000 (first attempt, lost 2026-11-29) |" in row
    figures.scale_figure(tmp_path / "scale.png", {}, "tmaze", "T-maze", unfinished)
    np.savez(run / HISTORY, **{k: v for k, v in arrays.items() if not k.startswith("h1|")})  # block 1 lost
    with pytest.raises(ConfigError, match="holds 2 of 3"):
        data.collect_unfinished(run, tmp_path / "data")
    (run / "summary.json").write_text("{}")
    with pytest.raises(ConfigError, match="finished run"):
        data.collect_unfinished(run, tmp_path / "data")


def test_a_run_collected_while_it_trained_is_drawn_once_when_it_has_finished(tmp_path):
    """A scale-study run's unfinished folder is its finished one (``<algo>-<preset>-s<seed>``, the
    page labelling the preset): collecting the finished run removes progress.json, so the run is
    no longer drawn as unfinished beside itself (its archive carried between machines deleted),
    and collecting it as unfinished again is refused
    with its finished data untouched. A finished run of a preset the page does not label (the
    paper's) is refused where another preset's run of the algorithm lies, nothing written."""
    from remidi.engine.run.checkpoint import HISTORY
    from remidi.envs.maze_names import HELD_OUT_NAMES
    from remidi.experiments import outputs

    run = tmp_path / "runs" / "plr-cpu4x-s0"
    run.mkdir(parents=True)
    doc = {"experiment": "tmaze", "algo": "plr", "preset": "cpu4x", "seeds": [0, 1],
           "code": {"commit": "abc1234def", "device": "cpu: cpu"},
           "config": {"num_updates": 600, "eval_every": 150, "num_envs": 32, "num_steps": 256}}
    (run / "config.json").write_text(json.dumps(doc))
    np.savez(run / HISTORY, **{f"h{b}|solve_rate/{n}": np.array([0.1, 0.2]) for b in range(2) for n in HELD_OUT_NAMES})
    target = data.collect_unfinished(run, tmp_path / "data")
    assert list(data.load_unfinished(tmp_path / "data")) == [("tmaze", "plr @cpu4x")]
    (run / "summary.json").write_text(json.dumps({"experiment": "tmaze", "algo": "plr", "preset": "cpu4x",
                                                  "seeds": [0, 1], "metrics": {}}))
    outputs.write_metrics_csv(run / "metrics.csv", [(0, 600, "solve_rate/mean", 0.3)])
    carried = data.inflight(tmp_path / "data", "tmaze", "plr-cpu4x-s0")  # docs/results/carry.sh's archive
    other = data.inflight(tmp_path / "data", "tmaze", "remidi-cpu4x-s0")
    for archive in (carried, other):
        archive.parent.mkdir(parents=True, exist_ok=True)
        archive.write_bytes(b"xz")
    assert data.collect(run, tmp_path / "data") == [target]
    assert not carried.exists() and other.exists()  # the finished run's archive alone is deleted
    assert data.load_unfinished(tmp_path / "data") == {}
    assert list(data.load_runs(tmp_path / "data")) == [("tmaze", "plr @cpu4x")]
    (run / "summary.json").unlink()
    before = {p.name: p.read_bytes() for p in target.iterdir()}
    with pytest.raises(ConfigError, match="finished run's data"):
        data.collect_unfinished(run, tmp_path / "data")
    assert {p.name: p.read_bytes() for p in target.iterdir()} == before
    cpu = tmp_path / "data" / "tmaze" / "plr-s0"  # the cpu preset's committed seeds
    cpu.mkdir()
    (cpu / "summary.json").write_text(json.dumps({"preset": "cpu"}))
    paper = tmp_path / "runs" / "plr-paper-s0"
    paper.mkdir()
    (paper / "config.json").write_text(json.dumps({**doc, "preset": "paper"}))
    (paper / "summary.json").write_text(json.dumps({"experiment": "tmaze", "algo": "plr", "preset": "paper",
                                                    "seeds": [0, 1], "metrics": {}}))
    outputs.write_metrics_csv(paper / "metrics.csv", [(0, 600, "solve_rate/mean", 0.3)])
    with pytest.raises(ConfigError, match="holds the 'cpu' preset's run"):
        data.collect(paper, tmp_path / "data")
    assert [p.name for p in cpu.iterdir()] == ["summary.json"]


def test_the_seeds_of_a_run_resumed_elsewhere_before_parts_were_recorded_name_every_jax_version(tmp_path):
    """A run from before parts were recorded whose device was written by hand as two machines
    counts the JAX versions its note names (else 'not recorded'), not only its start's, and keeps
    its machines in the order they trained."""
    folder = tmp_path / "tmaze" / "remidi-masked-s0"
    folder.mkdir(parents=True)
    (folder / "summary.json").write_text(json.dumps({"experiment": "tmaze", "algo": "remidi", "preset": "cpu",
                                                     "seeds": [0, 1], "metrics": {}}))
    code = {"commit": "ab55b8c0", "jax": "0.11.2", "device": "gpu: NVIDIA H200 (updates 1-1050), then cpu",
            "note": "trained on a lent H200 (JAX 0.11.2), resumed on the CPU (JAX 0.10.2)"}
    (folder / "config.json").write_text(json.dumps({"code": code, "config": {}}))
    (run,) = data.load_runs(tmp_path).values()
    (group,) = run.groups
    assert list(group[2]) == [code["device"]] and list(group[3]) == ["0.11.2", "0.10.2"]
    claim = claims.Claim("k", "t", "s", "summary:x", ("tmaze",), bounds=(("remidi", 0.0, 1.0),))
    row = tables.claim_provenance_table([{"claim": claim}], {("tmaze", "remidi"): run}).splitlines()[2]
    assert "2 seeds (0, 1): ab55b8c · H200 + cpu · 0.11.2, 0.10.2 | 1 commit, 2 machines, 2 JAX versions |" in row
    (folder / "config.json").write_text(json.dumps({"code": {**code, "note": ""}, "config": {}}))
    (run,) = data.load_runs(tmp_path).values()
    assert list(run.groups[0][3]) == ["0.11.2", "not recorded"]


@pytest.mark.parametrize("flag", ["--collect", "--collect-unfinished"])
def test_a_folder_that_holds_no_run_is_one_line_and_exit_2_with_nothing_written(flag, tmp_path, capsys):
    page = tmp_path / "results.md"
    page.write_text("untouched\n")
    assert rp.main([flag, str(tmp_path / "nothing"), "--data", str(tmp_path / "data"), "--page", str(page)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("python -m tools.results.page: error: collect") and err.count("\n") == 1
    assert page.read_text() == "untouched\n" and not (tmp_path / "data").exists()


def test_a_bound_claims_figure_shades_the_interval_it_allows(tmp_path, monkeypatch):
    """A bound claim's figure shows the bound its verdict is judged by (the Kinetix claim's
    [0, 0.01] was once drawn as a lone point at 0 on an axis of ±0.04, the bound nowhere)."""
    from remidi.experiments import plots

    claim = next(c for c in claims.CLAIMS if c.key == "kinetix-remidi-masks-nothing")
    drawn = []
    monkeypatch.setattr(plots, "_save", lambda fig, path: drawn.append(fig))
    figures._interval_figure(tmp_path / "claim.png", {"claim": claim, "verdict": "reproduced"}, {})
    (ax,) = drawn[0].axes
    (band,) = ax.collections
    xs = band.get_paths()[0].vertices[:, 0]
    assert (xs.min(), xs.max()) == (0.0, 0.01)
    assert ax.get_xlabel() == "shaded: the claimed bound [0, 0.01]"


def test_every_figure_the_page_draws_is_on_the_page():
    """A figure drawn but not shown is a reader's loss (Kinetix's curves and five others once were):
    each experiment's curves with data, the scale figures and each claim figure appear on the page."""
    page = rp.PAGE.read_text()
    runs = data.load_runs(data.DATA)
    drawn = [f"{exp}-curves.png" for exp, (algos, _, curves) in claims.SECTIONS.items()
             if curves and any((exp, a) in runs for a in algos)]
    drawn += [f"scale-{exp}.png" for exp, _ in claims.SCALE_TASKS]
    missing = [name for name in drawn if f"(results/{name})" not in page]
    assert not missing, missing


def _held(verdict, remidi=None, plr=None):
    test = {"kind": "greater", "n": (5, 5)} if remidi is None else {"kind": "greater", "n": (5, 5), "mean": (remidi, plr)}
    return {"verdict": verdict, "rule_verdict": verdict.split(":", 1)[0], "tests": [test]}


@pytest.mark.parametrize("held, learns, reading", [
    (_held("pending"), _held("pending"), "pending"),
    (_held("reproduced", 0.3, 0.1), _held("not reproduced", 0.0, 0.1), "persists"),
    (_held("reproduced", 0.3, 0.1), _held("reproduced", 0.1, 0.0), "persists where the baseline learns"),
    (_held("partly (no test passes)", 0.3, 0.25), _held("reproduced", 0.25, 0.0), "narrows, undecided"),
    (_held("not reproduced", 0.2, 0.2), _held("reproduced", 0.2, 0.0), "closes"),  # a tie closes it
    (_held("not reproduced", 0.1, 0.3), _held("reproduced", 0.3, 0.0), "closes"),
    (_held("reproduced", 0.3, 0.1), _held("pending"), "persists"),
    (_held("not reproduced", math.nan, 0.1), _held("reproduced", 0.1, 0.0), "undefined (a mean is not finite)"),
    (_held("stale: its runs predate abc (x); rerun"), _held("pending"), "stale")])
def test_the_scale_studys_gap_reads_by_the_rule_stated_before_its_runs(held, learns, reading):
    assert verdicts.scale_gap(held, learns) == reading


def _scale_runs(root, cpu4x: dict) -> dict:
    """T-maze runs at cpu (ReMiDi 0.30–0.34, PLR⊥ and minimax return 0, 5 seeds each) and at cpu4x
    (``cpu4x``: algorithm -> 5 held-out solve rates), loaded as the page loads them."""
    for preset, algos in (("cpu", {"remidi": [0.3, 0.31, 0.32, 0.33, 0.34], "plr": [0.0] * 5,
                                   "minimax-return": [0.0] * 5}), ("cpu4x", cpu4x)):
        for algo, values in algos.items():
            folder = write_run(root / preset, "tmaze", algo, range(5), evaluate={"solve_rate/mean": values})
            doc = json.loads((folder / "summary.json").read_text())
            (folder / "summary.json").write_text(json.dumps({**doc, "preset": preset}))
    return {**data.load_runs(root / "cpu"), **data.load_runs(root / "cpu4x")}


def _scale_rows(runs: dict) -> list[list[str]]:
    table = tables.scale_gap_table([verdicts.evaluate_claim(c, runs) for c in claims.CLAIMS], runs)
    return [[c.strip() for c in row.split("|")[1:-1]] for row in table.splitlines()[2:]]


def test_the_scale_gap_table_puts_each_scale_of_a_task_beside_the_other(tmp_path):
    """T-maze at cpu (the paper's held-out claim's test against PLR⊥) and at cpu4x, where ReMiDi's
    lead passes and PLR⊥ solves more than at cpu: the gap persists where the baseline learns; the
    blindfold, without runs, reads pending at both scales."""
    rows = _scale_rows(_scale_runs(tmp_path, {"remidi": [0.5, 0.51, 0.52, 0.53, 0.54],
                                              "plr": [0.1, 0.11, 0.12, 0.13, 0.14]}))
    assert rows[0][:2] == ["T-maze", "`cpu` preset: 5% of the paper's environment steps"]
    assert rows[0][2].startswith("0.320 [") and rows[0][3] == "0.000 [0.000, 0.000]" and rows[0][4] == "+0.320"
    assert rows[0][5:7] == ["pending", "5 / 5"]  # the paper's claim needs 10 seeds
    assert rows[1][1].startswith("`cpu4x` preset: 20% of the paper's")
    assert rows[1][4:] == ["+0.400", "passes", "5 / 5", "**reproduced** (passes)", "**persists where the baseline learns**"]
    assert len(rows) == 4 and all(r[-2:] == ["**pending** (pending)", "**pending**"] for r in rows[3:])


def test_the_scale_gap_table_shows_one_side_before_the_other_has_finished(tmp_path):
    """PLR⊥ alone at cpu4x, no higher than its cpu mean: its mean shows, ReMiDi's and the difference do
    not, and the learns column says the claim's comparison does not hold in the mean (a tie)."""
    row = _scale_rows(_scale_runs(tmp_path, {"plr": [0.0] * 5}))[1]
    assert row[2:] == ["—", "0.000 [0.000, 0.000]", "—", "pending", "0 / 5", "**not reproduced** (does not hold in the mean)",
                       "**pending**"]
