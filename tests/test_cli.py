"""The command line: outputs of a run, and one-line errors (exit 2) that write nothing."""

import csv
import json

import pytest

from remidi.cli import main

FAST = ["--set", "iterations=60", "--set", "iters_per_adversary=20", "--set", "log_every=10"]


def run_cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_run_writes_all_outputs(tmp_path, capsys):
    out = tmp_path / "run"
    code, stdout, _ = run_cli(capsys, "run", "tabular-shared", "--algo", "remidi", "--seeds", "3",
                              "--out", str(out), "--quiet", *FAST)
    assert code == 0
    for name in ("config.json", "metrics.csv", "summary.json", "regret.png", "adversary.png"):
        assert (out / name).exists(), name
    summary = json.loads((out / "summary.json").read_text())
    assert summary["experiment"] == "tabular-shared" and summary["algo"] == "remidi"
    assert summary["preset"] == "smoke" and summary["seeds"] == [0, 1, 2]
    for key in ("regret/h1", "regret/h3", "regret/h5", "adversary_prob/theta1", "adversary_prob/theta6"):
        m = summary["metrics"][key]
        assert set(m) == {"mean", "std", "per_seed"} and len(m["per_seed"]) == 3
    assert summary["reference"]["blp_regret"] == pytest.approx({"h1": 0.175, "h3": 0.175, "h5": 1.0})
    config = json.loads((out / "config.json").read_text())
    assert config["config"]["iterations"] == 60 and config["algo"] == "remidi"
    with open(out / "metrics.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert set(rows[0]) == {"seed", "step", "metric", "value"}
    assert {r["seed"] for r in rows} == {"0", "1", "2"}
    assert {r["step"] for r in rows} == {str(s) for s in range(0, 61, 10)}


def test_several_algorithms_get_subfolders_and_comparison_plots(tmp_path, capsys):
    out = tmp_path / "both"
    code, _, _ = run_cli(capsys, "run", "tabular-distinct", "--seeds", "2", "--out", str(out), "--quiet", *FAST)
    assert code == 0
    assert (out / "regret.png").exists() and (out / "adversary.png").exists()
    for algo in ("mmr", "remidi"):
        assert (out / algo / "summary.json").exists()


@pytest.mark.parametrize("argv, needle", [
    (["run", "nope"], "experiment: unknown value 'nope'; allowed: tabular-distinct, tabular-shared"),
    (["run", "tabular-shared", "--algo", "plr"], "--algo: unknown value 'plr'; allowed: mmr, remidi, all"),
    (["run", "tabular-shared", "--preset", "huge"], "--preset: unknown value 'huge'; allowed: paper, smoke"),
    (["run", "tabular-shared", "--set", "bogus=1"], "--set: unknown key 'bogus'; allowed: iterations"),
    (["run", "tabular-shared", "--set", "iterations=-5"], "iterations: must be an integer ≥ 1"),
    (["run", "tabular-shared", "--set", "policy_lr=abc"], "policy_lr: expected a number"),
    (["run", "tabular-shared", "--set", "support_threshold=2"], "support_threshold: must be in (0, 1]"),
    (["run", "tabular-shared", "--set", "optimizer=lbfgs"], "optimizer: unknown value 'lbfgs'; allowed: adam, sgd"),
    (["run", "tabular-shared", "--algo", "remidi", "--set", "num_adversaries=50"], "num_adversaries: must be small enough"),
    (["run", "tabular-shared", "--seeds", "0"], "--seeds: must be an integer ≥ 1"),
    (["run", "tabular-shared", "--set", "iterations"], "--set: expected key=value"),
    (["run", "tabular-shared", "--seeds", "two"], "invalid int value"),
])
def test_bad_input_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, argv, needle):
    out = tmp_path / "never"
    code, stdout, err = run_cli(capsys, *argv, "--out", str(out))
    assert code == 2
    assert err.startswith("remidi: error: ") and err.count("\n") == 1, err
    assert needle in err
    assert not out.exists()


def test_existing_run_is_never_overwritten(tmp_path, capsys):
    out = tmp_path / "run"
    assert run_cli(capsys, "run", "tabular-shared", "--algo", "mmr", "--seeds", "1", "--out", str(out), "--quiet", *FAST)[0] == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    code, _, err = run_cli(capsys, "run", "tabular-shared", "--algo", "mmr", "--seeds", "1", "--out", str(out), *FAST)
    assert code == 2 and "already holds a run" in err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_help_for_every_subcommand(capsys):
    for sub in ([], ["solve"], ["run"], ["list"]):
        with pytest.raises(SystemExit) as exc:
            main([*sub, "--help"])
        assert exc.value.code == 0
        assert "usage: remidi" in capsys.readouterr().out
