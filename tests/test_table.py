"""`remidi table`: finished runs as one Markdown table, in the run's algorithm order."""

import json

import pytest

from remidi.cli import main


def write_run(folder, experiment, algo, values, wall=75.0, algos=None, seeds=(0, 1)):
    folder.mkdir(parents=True)
    metrics = {name: {"mean": sum(v) / len(v), "std": 0.5, "per_seed": v} if v is not None
               else {"mean": None, "std": None, "per_seed": [None]} for name, v in values.items()}
    (folder / "summary.json").write_text(json.dumps({"experiment": experiment, "algo": algo, "preset": "smoke",
                                                     "seeds": list(seeds), "metrics": metrics, "wall_s": wall,
                                                     "resumed": False}))
    (folder / "config.json").write_text(json.dumps({"algo": algo, "algos": algos or [algo]}))


def test_table_rows_follow_the_run_order_and_show_mean_sample_std_iqm_and_ci(tmp_path, capsys):
    order = ["remidi", "plr"]  # as the user gave them: not alphabetical
    write_run(tmp_path / "hop" / "plr", "brax-hopper", "plr", {"return/undisturbed": [1.0, 2.0],
                                                              "replay_fraction/type_b": [0.9, 1.0]}, algos=order)
    write_run(tmp_path / "hop" / "remidi", "brax-hopper", "remidi", {"return/undisturbed": [10.0, 20.0],
                                                                    "replay_fraction/type_b": None}, 30.0, order)
    assert main(["table", str(tmp_path / "hop"), "--metrics", "return/undisturbed,replay_fraction/type_b"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0] == ("| experiment | algorithm | return/undisturbed | return/undisturbed IQM"
                        " | return/undisturbed 95% CI | replay_fraction/type_b | replay_fraction/type_b IQM"
                        " | replay_fraction/type_b 95% CI"
                        " | seeds | preset | wall time |")
    # ± is recomputed from per_seed with ddof 1 (the summary's "std": 0.5 is ddof 0): sd of (10, 20) = 7.07;
    # of two seeds the IQM is their mean; the bootstrap means of two seeds are a, (a+b)/2, b with
    # probabilities 1/4, 1/2, 1/4, so the 2.5% and 97.5% percentiles are a and b
    assert lines[2] == ("| brax-hopper | remidi | 15.0 ± 7.1 | 15.0 | [10.0, 20.0] | n/a | n/a | n/a"
                        " | 2 | smoke | 30 s |")
    assert lines[3] == ("| brax-hopper | plr | 1.5 ± 0.7 | 1.5 | [1.0, 2.0] | 0.95 ± 0.07 | 0.95 | [0.90, 1.00]"
                        " | 2 | smoke | 1.2 min |")
    assert lines[4:] == ["", "± is the sample standard deviation over seeds (ddof 1); IQM is the interquartile mean "
                         "(mean of the middle 50% of seeds); 95% CI is the percentile-bootstrap confidence interval "
                         "of the mean over seeds (10,000 resamples)."]


def test_table_iqm_and_ci_on_four_seeds_and_one_seed(tmp_path, capsys):
    write_run(tmp_path / "a", "tmaze", "plr", {"solve_rate/mean": [0.0, 0.1, 0.3, 1.0]}, seeds=range(4))
    write_run(tmp_path / "b", "tmaze", "remidi", {"solve_rate/mean": [0.5]}, seeds=[0])
    assert main(["table", str(tmp_path / "a"), str(tmp_path / "b")]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    # mean 0.35; sd ddof 1 = sqrt((0.1225 + 0.0625 + 0.0025 + 0.4225) / 3) = 0.4509; IQM = mean(0.1, 0.3) = 0.2;
    # the interval of the mean lies inside [min, max] and around the mean
    cells = lines[2].split(" | ")
    assert cells[:5] == ["| tmaze", "plr", "0.35 ± 0.45", "0.20", cells[4]] and cells[5] == "4"
    low, high = map(float, cells[4].strip("[]").split(", "))
    assert 0.0 <= low < 0.35 < high <= 1.0 and high - low > 0.3
    assert lines[3].startswith("| tmaze | remidi | 0.50 | 0.50 | n/a | 1 |"), lines[3]  # one seed: no sd, no CI


def test_a_folder_without_runs_is_one_line_exit_2(tmp_path, capsys):
    assert main(["table", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "RUN: no summary.json in" in err


def test_last_k_averages_each_seeds_last_logged_points(tmp_path, capsys):
    folder = tmp_path / "run"
    write_run(folder, "tmaze", "plr", {"solve_rate/mean": [0.0, 1.0]})
    rows = ["seed,step,metric,value"]
    for seed, values in ((0, [0.9, 0.1, 0.2, 0.3]), (1, [0.0, 0.5, float("nan"), 0.7])):
        rows += [f"{seed},{10 * (t + 1)},solve_rate/mean,{v}" for t, v in enumerate(values)]
    (folder / "metrics.csv").write_text("\n".join(rows) + "\n")
    assert main(["table", str(folder), "--metrics", "solve_rate/mean", "--last", "3"]) == 0
    line = capsys.readouterr().out.strip().splitlines()[2]
    # seed 0: mean(0.1, 0.2, 0.3) = 0.2; seed 1: mean(0.5, 0.7) = 0.6 (NaN left out) → 0.40 ± 0.28 (ddof 1)
    assert line.startswith("| tmaze | plr | 0.40 ± 0.28 | 0.40 | [0.20, 0.60] | 2 |"), line
    assert main(["table", str(folder), "--last", "0"]) == 2
    assert "--last: must be an integer ≥ 1" in capsys.readouterr().err


def test_a_metric_no_run_has_is_one_line_exit_2(tmp_path, capsys):
    write_run(tmp_path / "run", "tmaze", "plr", {"solve_rate/mean": [0.0, 1.0]})
    assert main(["table", str(tmp_path / "run"), "--metrics", "solve_rate/mean,nosuch"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--metrics: no run has 'nosuch'; allowed: solve_rate/mean" in err


@pytest.mark.parametrize("text, needle", [
    ('{"experiment": "x"', "cannot be read (JSONDecodeError"),
    ("[1, 2]", "is not a run summary (a JSON list, not an object)"),
    ('{"experiment": "x"}', "is not a run summary (no algo, preset, seeds, metrics)"),
])
def test_a_malformed_summary_is_one_line_exit_2(tmp_path, capsys, text, needle):
    (tmp_path / "summary.json").write_text(text)
    assert main(["table", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err and str(tmp_path / "summary.json") in err, err


@pytest.mark.parametrize("text, needle", [
    ('{"algo": "dr"', "config.json cannot be read (JSONDecodeError"),
    ("[1, 2]", "config.json is a JSON list, not an object"),
    ('{"algo": "dr", "config": [1]}', "config.json: config is not an object"),
])
@pytest.mark.parametrize("several", [False, True])
def test_a_malformed_config_is_one_line_exit_2(tmp_path, capsys, text, needle, several):
    """A run's config.json names its row (and a several-algorithm run's order): damaged, it is one
    line naming the file (before: a JSONDecodeError or AttributeError traceback)."""
    run = tmp_path / "run"
    folder = run / "dr" if several else run
    write_run(folder, "lever", "dr", {"solve_rate/visible": [1.0, 1.0]})
    (folder / "config.json").write_text(text)
    assert main(["table", str(run)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err and str(folder / "config.json") in err, err


@pytest.mark.parametrize("text, needle", [
    ("", "metrics.csv, line 1: the file is empty"),
    ("seed,step,metric,value\n0,10,solve_rate/mean,0.5\n0,20,solve_rate/mean,abc\n",
     "metrics.csv, line 3: expected seed,step,metric,value"),
    ("seed,step,metric,value\n0,10,solve_rate/mean\n", "metrics.csv, line 2: expected seed,step,metric,value"),
    ("a,b\n", "metrics.csv, line 1: expected the header seed,step,metric,value"),
])
def test_last_k_on_a_malformed_metrics_csv_is_one_line_naming_file_and_line(tmp_path, capsys, text, needle):
    folder = tmp_path / "run"
    write_run(folder, "tmaze", "plr", {"solve_rate/mean": [0.0, 1.0]})
    (folder / "metrics.csv").write_text(text)
    assert main(["table", str(folder), "--last", "2"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("remidi: error: ") and err.count("\n") == 1 and needle in err, err
    assert str(folder / "metrics.csv") in err


def test_default_columns_are_the_claims_metrics_the_headline_and_the_level_shares(tmp_path, capsys):
    """tmaze's summary lists the held-out solve rates before the replay shares that carry the
    paper's claim (Fig. 7a): the default columns are solve_rate/mean and the shares, per experiment;
    a game without shares (tabular) keeps its first three."""
    rates = {f"solve_rate/{name}": [0.5, 0.5] for name in ("SixteenRooms", "Labyrinth", "StandardMaze")}
    write_run(tmp_path / "t", "tmaze", "plr", {"solve_rate/mean": [0.5, 0.5], **rates,
                                               "replay_fraction/tmaze": [0.9, 1.0], "buffer_fraction/tmaze": [0.8, 1.0]})
    write_run(tmp_path / "b", "blindfold", "plr", {"solve_rate/mean": [0.5, 0.5], **rates,
                                                   "replay_fraction/blind": [0.9, 1.0],
                                                   "buffer_fraction/blind": [0.8, 1.0]})
    write_run(tmp_path / "g", "tabular-shared", "mmr", {f"regret/h{i}": [0.5, 0.5] for i in (1, 3, 5, 7)})
    assert main(["table", str(tmp_path / "t"), str(tmp_path / "b"), str(tmp_path / "g")]) == 0
    head = capsys.readouterr().out.splitlines()[0]
    shown = [cell for cell in head.strip("| ").split(" | ") if not cell.endswith((" IQM", " 95% CI"))]
    assert shown == ["experiment", "algorithm", "solve_rate/mean", "replay_fraction/tmaze", "buffer_fraction/tmaze",
                     "replay_fraction/blind", "buffer_fraction/blind", "regret/h1", "regret/h3", "regret/h5",
                     "seeds", "preset", "wall time"], head


def test_default_columns_show_every_evaluation_sets_primary_metric(tmp_path, capsys):
    """Where the headline is one evaluation set's metric, every set's primary metric is shown: the
    lever's visible and hidden levels' solve rates, a user's task's sets "random" and the hand-made
    "single" (returns: that task has no solve criterion); a headline over all sets (tmaze's
    solve_rate/mean) still stands for them."""
    two = [0.5, 0.5]
    lever = {name: two for name in ("solve_rate/visible", "solve_rate/hidden", "regret/visible/mean",
                                    "replay_fraction/hidden", "buffer_fraction/hidden", "mean_return",
                                    "discounted_return/hidden", "discounted_return/visible", "return/hidden",
                                    "return/visible")}
    write_run(tmp_path / "l", "lever", "plr", lever)
    mine = {name: two for name in ("return/random", "return/single", "regret/random/mean", "replay_fraction/far",
                                   "buffer_fraction/far", "discounted_return/random", "discounted_return/single")}
    write_run(tmp_path / "m", "mine", "plr", mine)
    maze = {name: two for name in ("solve_rate/mean", "solve_rate/Labyrinth", "solve_rate/SixteenRooms",
                                   "replay_fraction/tmaze", "discounted_return/Labyrinth",
                                   "discounted_return/SixteenRooms")}
    write_run(tmp_path / "t", "tmaze", "plr", maze)
    assert main(["table", str(tmp_path / "l"), str(tmp_path / "m"), str(tmp_path / "t")]) == 0
    head = capsys.readouterr().out.splitlines()[0]
    shown = [cell for cell in head.strip("| ").split(" | ") if not cell.endswith((" IQM", " 95% CI"))]
    assert shown == ["experiment", "algorithm", "solve_rate/visible", "solve_rate/hidden", "replay_fraction/hidden",
                     "buffer_fraction/hidden", "return/random", "return/single", "replay_fraction/far",
                     "buffer_fraction/far", "solve_rate/mean", "replay_fraction/tmaze", "seeds", "preset",
                     "wall time"], head


def test_an_unfinished_algorithm_of_a_several_algorithm_run_is_noted(tmp_path, capsys):
    """Its sub-folder holds config.json but no summary.json: the table shows the finished ones and
    a note names the one left out (before: silently one row fewer)."""
    write_run(tmp_path / "remidi", "lever", "remidi", {"solve_rate/visible": [1.0, 1.0]}, algos=["plr", "remidi"])
    (tmp_path / "plr").mkdir()
    (tmp_path / "plr" / "config.json").write_text(json.dumps({"algo": "plr", "algos": ["plr", "remidi"]}))
    assert main(["table", str(tmp_path)]) == 0
    captured = capsys.readouterr()
    assert "| remidi |" in captured.out and "| plr |" not in captured.out
    assert captured.err == (f"remidi: note: {tmp_path / 'plr'} is left out: unfinished (no summary.json; "
                            f"remidi run --resume {tmp_path} finishes it)\n")


def test_a_folder_of_separate_runs_is_no_several_algorithm_run(tmp_path, capsys):
    """runs/lever/<time>/ of single-algorithm runs: the note names the unfinished run itself, the
    folder is finished when every run in it is, and --resume of the folder is refused (it would
    have written a config.json for each recorded algorithm named after it and trained new runs)."""
    from remidi.experiments.resuming import finished_run

    write_run(tmp_path / "t1", "lever", "plr", {"solve_rate/visible": [1.0, 1.0]})
    write_run(tmp_path / "t2", "lever", "remidi", {"solve_rate/visible": [1.0, 1.0]})
    assert finished_run(tmp_path)
    (tmp_path / "t3").mkdir()
    (tmp_path / "t3" / "config.json").write_text(json.dumps({"algo": "plr", "algos": ["plr"]}))
    assert not finished_run(tmp_path)
    assert main(["table", str(tmp_path)]) == 0
    assert capsys.readouterr().err == (f"remidi: note: {tmp_path / 't3'} is left out: unfinished (no summary.json; "
                                       f"remidi run --resume {tmp_path / 't3'} finishes it)\n")
    assert main(["run", "--resume", str(tmp_path)]) == 2
    assert f"--resume: {tmp_path} holds separate runs, not one several-algorithm run" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t1", "t2", "t3"]


def test_two_runs_of_one_algorithm_in_different_forms_get_two_names(tmp_path, capsys):
    """ReMiDi's masked and combine runs (and a run without config.json) are told apart by what
    their config changes, as the results page names them."""
    for name, config in (("masked", {"remidi": {"policy": "masked"}}), ("combine", {"remidi": {"policy": "combine"}}),
                         ("bare", None)):
        write_run(tmp_path / name, "lever", "remidi", {"solve_rate/visible": [1.0, 1.0]})
        if config is None:
            (tmp_path / name / "config.json").unlink()
        else:
            command = ["remidi", "run", "lever", "--set", f"remidi.policy={config['remidi']['policy']}"]
            (tmp_path / name / "config.json").write_text(json.dumps({"algo": "remidi", "config": config,
                                                                     "command": command}))
    assert main(["table", *(str(tmp_path / n) for n in ("masked", "combine", "bare"))]) == 0
    rows = capsys.readouterr().out.strip().splitlines()[2:5]
    assert [row.split(" | ")[1] for row in rows] == ["remidi (masked)", "remidi (combine)", "remidi"]
