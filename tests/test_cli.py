"""The command line: outputs of a run, and one-line errors (exit 2) that write nothing."""

import csv
import json
import os
import shutil
from pathlib import Path

import pytest

from remidi.cli import main
from remidi.experiments import catalog

CATALOG = catalog()  # the built-in experiments, with their algorithms and presets
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
    (["run", "nope"], f"experiment: unknown value 'nope'; allowed: {', '.join(CATALOG)}"),
    (["run", "tabular-shared", "--algo", "plr"],
     f"--algo: unknown value 'plr'; allowed: {', '.join(CATALOG['tabular-shared']['algorithms'])}, all"),
    (["run", "tabular-shared", "--preset", "huge"],
     f"--preset: unknown value 'huge'; allowed: {', '.join(CATALOG['tabular-shared']['presets'])}"),
    (["run", "tabular-shared", "--set", "bogus=1"], "--set: unknown key 'bogus'; allowed: iterations"),
    (["run", "tabular-shared", "--set", "iterations=-5"], "iterations: must be an integer ≥ 1"),
    (["run", "tabular-shared", "--set", "policy_lr=abc"], "policy_lr: expected a number"),
    (["run", "tabular-shared", "--set", "support_threshold=2"], "support_threshold: must be in (0, 1]"),
    (["run", "tabular-shared", "--set", "optimizer=lbfgs"], "optimizer: unknown value 'lbfgs'; allowed: adam, sgd"),
    (["run", "tabular-shared", "--algo", "remidi", "--set", "num_adversaries=50"], "num_adversaries: must be small enough"),
    (["run", "tabular-shared", "--seeds", "0"], "--seeds: must be an integer ≥ 1"),
    (["run", "tabular-shared", "--set", "iterations"], "--set: expected key=value"),
    (["run", "tabular-shared", "--seeds", "two"], "invalid int value"),
    (["run", "tabular-shared", "--algo", "mmr,"], "--algo: 'mmr,' has an empty name"),
    (["run", "tabular-shared", "--algo", "mmr,,remidi"], "--algo: 'mmr,,remidi' has an empty name"),
    (["run", "tabular-shared", "--no-such-flag"], "remidi: error: unrecognized arguments: --no-such-flag"),
])
def test_bad_input_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, argv, needle):
    out = tmp_path / "never"
    code, stdout, err = run_cli(capsys, *argv, "--out", str(out))
    assert code == 2
    assert err.startswith("remidi: error: ") and err.count("\n") == 1, err
    assert needle in err
    assert not out.exists()


@pytest.fixture(scope="module")
def finished_tabular(tmp_path_factory):
    """A finished several-algorithm tabular run (mmr/ and its other algorithms' sub-folders),
    trained once for the tests that only need one to be refused or told it is finished: each test
    copies it (``shutil.copytree`` keeps the files' times) and checks its own copy."""
    out = tmp_path_factory.mktemp("tabular") / "both"
    assert main(["run", "tabular-shared", "--seeds", "1", "--out", str(out), "--quiet", *FAST]) == 0
    return out


def copy_of(run: Path, to: Path) -> Path:
    shutil.copytree(run, to)
    return to


def test_existing_run_is_never_overwritten(tmp_path, capsys, finished_tabular):
    out = copy_of(finished_tabular, tmp_path / "both") / "mmr"  # a folder holding one algorithm's run
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    code, _, err = run_cli(capsys, "run", "tabular-shared", "--algo", "mmr", "--seeds", "1", "--out", str(out), *FAST)
    assert code == 2 and "already holds a run" in err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_one_algorithm_into_a_finished_several_algorithm_run_writes_nothing(tmp_path, capsys, finished_tabular):
    """A several-algorithm run keeps config.json in each algorithm's sub-folder, none at the top:
    a later single-algorithm run into the same folder must be refused, not added beside them."""
    out = copy_of(finished_tabular, tmp_path / "both")
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    code, _, err = run_cli(capsys, "run", "tabular-shared", "--algo", "mmr", "--seeds", "1", "--out", str(out), *FAST)
    assert code == 2 and "already holds a run" in err and err.count("\n") == 1
    assert {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_help_for_every_subcommand(capsys):
    for sub in ([], ["solve"], ["run"], ["list"]):
        with pytest.raises(SystemExit) as exc:
            main([*sub, "--help"])
        assert exc.value.code == 0
        assert "usage: remidi" in capsys.readouterr().out


# with the default preset (smoke), the same configuration as tests/test_ued_engine.py's TINY, so the
# compiled programs are shared (through the persistent compilation cache) instead of compiled again
LEVER_TINY = ["--set", "num_updates=40", "--set", "eval_every=10", "--set", "checkpoint_every=10",
              "--set", "num_envs=8", "--set", "num_steps=4", "--set", "eval_attempts=2", "--set", "ppo.epochs=1",
              "--set", "buffer.capacity=16", "--set", "buffer.topk_k=8", "--set", "buffer.min_fill=0.25",
              "--set", "remidi.buffer_capacity=8", "--set", "remidi.steps_per_buffer=8"]


def interrupt_training(monkeypatch, at: int, algo: str | None = None):
    """Ctrl-C once training (of ``algo``, or of any algorithm) has done ``at`` updates: patches
    ``ued.train_seeds``; returns the real one, to put back before a resume."""
    from remidi.experiments import ued

    real = ued.train_seeds

    def interrupted(task, cfg, name, *args, on_block=None, **kwargs):
        def ctrl_c(done, metrics):
            if done == at and algo in (None, name):
                raise KeyboardInterrupt
        return real(task, cfg, name, *args, **kwargs, on_block=ctrl_c)

    monkeypatch.setattr(ued, "train_seeds", interrupted)
    return real


def assert_resumes_to_the_uninterrupted_result(monkeypatch, base: list, folder, at: int = 10, capsys=None) -> dict:
    """``remidi`` with ``base`` (its argv without ``--out``) into ``folder/full``, and again into
    ``folder/cut`` interrupted (Ctrl-C) after update ``at`` and resumed: both end with the same
    metrics.csv and summary metrics, and the resumed run's summary records its two parts (the
    updates each trained, back to back, each with its code and device); the interrupted and the
    resumed run compile nothing the full run did not (a runner restored from a checkpoint has
    the fresh one's types). With ``capsys``, the interrupted run said so in one line. Returns the
    summary's metrics."""
    import json

    from remidi.cli import main
    from remidi.engine.run import driver
    from remidi.experiments import ued

    assert main([*base, "--out", str(folder / "full")]) == 0
    programs = driver._run_block._cache_size(), driver._evaluate._cache_size()
    real = interrupt_training(monkeypatch, at)
    if capsys is not None:
        capsys.readouterr()
    assert main([*base, "--out", str(folder / "cut")]) == 130
    if capsys is not None:
        err = capsys.readouterr().err
        assert err.startswith("remidi: interrupted") and err.count("\n") == 1, err
    assert (folder / "cut" / "checkpoint.npz").exists() and not (folder / "cut" / "summary.json").exists()
    monkeypatch.setattr(ued, "train_seeds", real)
    assert main(["run", "--resume", str(folder / "cut"), "--quiet"]) == 0
    assert (driver._run_block._cache_size(), driver._evaluate._cache_size()) == programs
    assert (folder / "cut" / "metrics.csv").read_text() == (folder / "full" / "metrics.csv").read_text()
    full = json.loads((folder / "full" / "summary.json").read_text())
    cut = json.loads((folder / "cut" / "summary.json").read_text())
    assert full["metrics"] == cut["metrics"]
    (whole,), (first, second) = full["parts"], cut["parts"]
    assert whole["updates"][0] == first["updates"][0] == 0 and second["updates"][1] == whole["updates"][1]
    assert 0 < first["updates"][1] == second["updates"][0] < whole["updates"][1]
    assert all(p["code"]["device"] and p["wall_s"] >= 0 for p in (whole, first, second))
    return full["metrics"]


@pytest.mark.slow  # trains, interrupts and resumes: 11 s of a cold quick tier
@pytest.mark.usefixtures("no_png")
def test_interrupted_run_resumes_to_the_uninterrupted_result(tmp_path, monkeypatch, capsys):
    assert_resumes_to_the_uninterrupted_result(
        monkeypatch, ["run", "lever", "--algo", "remidi", "--seeds", "2", "--quiet", *LEVER_TINY], tmp_path,
        capsys=capsys)


def test_resume_errors_are_one_line(tmp_path, capsys):
    code, _, err = run_cli(capsys, "run", "--resume", str(tmp_path / "nothing"))
    assert code == 2 and "does not exist" in err and err.count("\n") == 1
    code, _, err = run_cli(capsys, "run", "--resume", str(tmp_path))  # a folder, but no run in it
    assert code == 2 and "holds no run" in err and err.count("\n") == 1
    code, _, err = run_cli(capsys, "run", "lever", "--resume", str(tmp_path))
    assert code == 2 and "--resume: takes only the run folder" in err
    for flag in (["--preset", "paper"], ["--seed", "3"], ["--seed", "0"]):  # before, these were ignored
        code, _, err = run_cli(capsys, "run", "--resume", str(tmp_path), *flag)
        assert code == 2 and "--resume: takes only the run folder" in err, flag


@pytest.mark.parametrize("argv, needle", [
    (["run", "lever", "--set", "buffer.replay_prob=1.5"], "buffer.replay_prob"),
    (["run", "lever", "--set", "buffer.capacity=-1"], "buffer.capacity"),
    (["run", "lever", "--set", "remidi.num_buffers=9"], "remidi.num_buffers: must be small enough"),
    (["run", "lever", "--set", "ppo.nope=1"], "--set: unknown key 'ppo.nope'; allowed:"),
    (["run", "lever", "--set", "score=regret"], "score: unknown value 'regret'"),
    # numbers that would overflow after config.json was written
    (["run", "lever", "--set", "num_updates=99999999999999999999"], "num_updates: must keep num_updates × ppo."),
    (["run", "lever", "--set", "num_updates=3000000000"], "below 2^31"),
    (["run", "lever", "--seed", "1099511627776"], "--seed: every seed must be in [0, 4294967295]"),
    (["run", "lever", "--seed", "4294967295", "--seeds", "2"], "--seed: every seed must be in [0, 4294967295]"),
])
def test_lever_bad_config_is_one_line_and_writes_nothing(tmp_path, capsys, argv, needle):
    out = tmp_path / "never"
    code, _, err = run_cli(capsys, *argv, "--out", str(out))
    assert code == 2 and needle in err and err.count("\n") == 1, err
    assert not out.exists()


@pytest.mark.slow  # trains several algorithms and resumes: 9 s of a cold quick tier
def test_resume_a_several_algorithm_run_finishes_the_unfinished_ones(tmp_path, capsys, monkeypatch):
    from remidi.experiments import ued

    real = interrupt_training(monkeypatch, 10, algo="remidi")
    out = tmp_path / "both"
    code, _, _ = run_cli(capsys, "run", "lever", "--algo", "plr,remidi", "--seeds", "2", "--quiet", *LEVER_TINY,
                         "--out", str(out))
    assert code == 130
    assert (out / "plr" / "summary.json").exists() and not (out / "remidi" / "summary.json").exists()
    plr_before = (out / "plr" / "metrics.csv").read_text()
    monkeypatch.setattr(ued, "train_seeds", real)
    code, _, err = run_cli(capsys, "run", "--resume", str(out), "--quiet")
    assert code == 0, err
    assert (out / "remidi" / "summary.json").exists() and (out / "training.png").exists()
    assert (out / "plr" / "metrics.csv").read_text() == plr_before  # finished runs are left alone


def test_resume_trains_an_algorithm_whose_config_was_never_written(tmp_path, capsys, monkeypatch):
    """A several-algorithm run writes each algorithm's config.json, one after another, before it
    trains; stopped in between (Ctrl-C), its --resume writes the missing one from a written one
    and trains it (before: it trained the others only and then called the run finished)."""
    from remidi.experiments import running

    real, calls = running.write_run_config, []

    def stopped(*args, **kwargs):
        calls.append(args[0])
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(running, "write_run_config", stopped)
    out = tmp_path / "both"
    code, _, _ = run_cli(capsys, "run", "lever", "--algo", "plr,remidi", "--seeds", "2", "--quiet", *LEVER_TINY,
                         "--out", str(out))
    assert code == 130 and (out / "plr" / "config.json").exists() and not (out / "remidi" / "config.json").exists()
    monkeypatch.setattr(running, "write_run_config", real)
    code, _, err = run_cli(capsys, "run", "--resume", str(out), "--quiet")
    assert code == 0, err
    assert (out / "plr" / "summary.json").exists() and (out / "remidi" / "summary.json").exists()
    saved = [json.loads((out / a / "config.json").read_text()) for a in ("plr", "remidi")]
    same = ("experiment", "algos", "preset", "seeds", "devices", "log", "config", "command")
    assert [saved[1][k] for k in same] == [saved[0][k] for k in same] and saved[1]["algo"] == "remidi"


def test_undefined_metrics_print_as_na(capsys):
    from remidi.cli.experiments import _print_summaries

    _print_summaries({"dr": {"experiment": "lever", "preset": "smoke", "seeds": [0], "metrics": {
        "replay_fraction/hidden": {"mean": None, "std": None, "per_seed": [None]},
        "solve_rate/visible": {"mean": 0.5, "std": 0.0, "per_seed": [0.5]}}}}, "out")
    printed = capsys.readouterr().out
    assert "n/a" in printed and "0.5000" in printed


def test_several_algorithms_into_a_folder_holding_one_of_them_writes_nothing(tmp_path, capsys):
    out = tmp_path / "both"
    (out / "remidi").mkdir(parents=True)
    (out / "remidi" / "config.json").write_text("{}")
    code, _, err = run_cli(capsys, "run", "tabular-shared", "--out", str(out), *FAST)
    assert code == 2 and "already holds a run" in err
    assert sorted(p.name for p in out.iterdir()) == ["remidi"]
    assert (out / "remidi" / "config.json").read_text() == "{}"


def test_derived_keys_are_not_settable(capsys, tmp_path):
    code, _, err = run_cli(capsys, "run", "lever", "--set", "ppo.total_updates=5", "--out", str(tmp_path / "x"))
    assert code == 2 and "unknown key 'ppo.total_updates'" in err


def test_version(capsys):
    from remidi import __version__

    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0 and capsys.readouterr().out.strip() == f"remidi {__version__}"


@pytest.mark.parametrize("argv, needle", [
    (["run", "lever", "--algo", "dr", "--set", "network=maze_lstm"],
     "network: maze_lstm reads image [H, W, C] (H, W ≥ 3; the mazes' 5×5×3 view) and agent_dir [] (an integer, "
     "0..3); this task's observation is f32[65] (not a dict or object with a field image); allowed: mlp, mlp_lstm"),
    (["run", "lever", "--algo", "dr", "--out", "{file}/sub"], "is a file, not a folder"),
    (["run", "lever", "--algo", "dr", "--out", "/proc/remidi-no-such/run"], "cannot be made"),
])
def test_bad_network_and_unwritable_out_are_one_line_errors(tmp_path, capsys, argv, needle):
    file = tmp_path / "file"
    file.write_text("x")
    argv = [a.replace("{file}", str(file)) for a in argv]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "run")]
    code, out, err = run_cli(capsys, *argv)
    assert code == 2 and needle in err and err.count("\n") == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"] and file.read_text() == "x"


@pytest.mark.parametrize("argv, needle", [
    (["run", "lever", "--algo", "remidi", "--set", "remidi.buffer_capacity=0"],
     "remidi.buffer_capacity: must be an integer ≥ 1, got 0"),
    (["run", "lever", "--set", "ppo.lr=abc"], "ppo.lr: expected a number, got 'abc'"),
    (["run", "lever", "--set", "ppo.epochs=0"], "ppo.epochs: 0 must be ≥ 1"),
    (["run", "lever", "--algo", "remidi", "--set", "remidi.steps_per_buffer=3000"],
     "(num_buffers − 1) × steps_per_buffer = (2 − 1) × 3000 = 3000 is not below num_updates = 300; "
     "lower remidi.num_buffers or remidi.steps_per_buffer, or raise num_updates"),
])
def test_errors_name_the_key_that_was_set(tmp_path, capsys, argv, needle):
    code, _, err = run_cli(capsys, *argv, "--out", str(tmp_path / "run"))
    assert code == 2 and needle in err and err.count("\n") == 1, err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("argv, flag", [
    (["table", "{missing}"], "RUN"),
    (["compare", "{missing}", "--metric", "m", "--algo", "a", "--baseline", "b"], "RUN"),
    (["status", "{missing}"], "RUN_DIR"),
    (["evaluate", "{missing}"], "RUN_DIR"),
    (["render", "buffers", "{missing}"], "RUN_DIR"),
    (["render", "episode", "{missing}", "--maze", "SixteenRooms"], "RUN_DIR"),
    (["run", "--resume", "{missing}"], "--resume"),
])
def test_a_missing_run_folder_is_said_not_to_exist(tmp_path, capsys, argv, flag):
    """A run-reading command given a folder that is not there says so (not that the folder "holds no
    run"); given a file, that it is no folder."""
    missing = tmp_path / "nonexistent"
    code, _, err = run_cli(capsys, *[a.format(missing=missing) for a in argv])
    assert code == 2 and err == f"remidi: error: {flag}: {missing} does not exist\n", err
    file = tmp_path / "file"
    file.write_text("x")
    code, _, err = run_cli(capsys, *[a.format(missing=file) for a in argv])
    assert code == 2 and err.count("\n") == 1 and "holds no run" not in err and "no summary.json" not in err, err


def test_resume_of_a_file_names_resume(tmp_path, capsys):
    file = tmp_path / "f"
    file.write_text("x")
    code, _, err = run_cli(capsys, "run", "--resume", str(file))
    assert code == 2 and err.startswith("remidi: error: --resume:") and file.read_text() == "x"


# ------------------------------------------------------------------ num_updates and its dependants
def test_setting_only_num_updates_scales_the_keys_measured_in_updates():
    from remidi.experiments import get_experiment
    from remidi.experiments.base import resolve_config

    lever = get_experiment("lever")
    notes = []
    cfg = resolve_config(lever, "smoke", {"num_updates": "20"}, notes)  # smoke: 300 updates, 50 / 100 / 100
    # eval_every, a block length, becomes the divisor of 20 nearest 50·20/300 = 3.3 (no short last
    # block, which would compile another program and stall the bar at 19/20)
    assert (cfg.num_updates, cfg.eval_every, cfg.checkpoint_every, cfg.remidi.steps_per_buffer) == (20, 4, 7, 7)
    assert cfg.ppo.total_updates == 20
    assert notes == ["num_updates 300 → 20, so scaled eval_every 50 → 4, checkpoint_every 100 → 7, "
                     "remidi.steps_per_buffer 100 → 7 (set them with --set to choose other values)"]
    for algo in lever.algorithms:
        lever.validate(cfg, algo)
    # keys the user set are kept; every scaled key stays ≥ 1
    cfg = resolve_config(lever, "paper", {"num_updates": "2", "eval_every": "2"})
    assert (cfg.eval_every, cfg.checkpoint_every, cfg.remidi.steps_per_buffer) == (2, 1, 1)
    # the preset's own length: nothing to scale
    notes = []
    assert resolve_config(lever, "smoke", {"num_updates": "300"}, notes) == resolve_config(lever, "smoke", {})
    assert notes == []
    assert resolve_config(lever, "smoke", {"num_updates": "97"}).eval_every == 97  # a prime: one block
    from remidi.experiments.overrides import nearest_divisor

    assert nearest_divisor(1500, 50) == 50 and nearest_divisor(20, 10 / 3) == 4
    assert nearest_divisor(10**20, 5e15) == 5 * 10**15  # no search over a length validation refuses
    tab = resolve_config(get_experiment("tabular-shared"), "smoke", {"iterations": "150"})
    assert (tab.log_every, tab.iters_per_adversary) == (1, 50)


def test_scaling_note_is_one_line_on_stderr_and_recorded_in_config(tmp_path, capsys):
    out = tmp_path / "run"
    code, _, err = run_cli(capsys, "run", "tabular-shared", "--algo", "mmr", "--seeds", "1", "--quiet",
                           "--set", "iterations=60", "--out", str(out))
    assert code == 0, err
    assert err == "remidi: iterations 1500 → 60, so scaled log_every 10 → 1, iters_per_adversary 500 → 20 " \
                  "(set them with --set to choose other values)\n"
    config = json.loads((out / "config.json").read_text())["config"]
    assert (config["iterations"], config["log_every"], config["iters_per_adversary"]) == (60, 1, 20)


@pytest.mark.parametrize("argv, needle", [
    (["--set", "num_updates=20", "--set", "eval_every=50"],
     "eval_every: must be ≤ num_updates (20), got 50; lower eval_every or raise num_updates"),
    (["--set", "num_updates=20", "--set", "remidi.steps_per_buffer=100"],
     "(num_buffers − 1) × steps_per_buffer = (2 − 1) × 100 = 100 is not below num_updates = 20; "
     "lower remidi.num_buffers or remidi.steps_per_buffer, or raise num_updates"),
    (["--set", "num_updates=1"],  # scaled to 1, still breaks the rule: the error is the only line
     "is not below num_updates = 1; lower remidi.num_buffers or remidi.steps_per_buffer, or raise num_updates"),
])
def test_broken_rule_names_the_rule_and_the_fix(tmp_path, capsys, argv, needle):
    out = tmp_path / "never"
    code, stdout, err = run_cli(capsys, "run", "lever", "--algo", "remidi", *argv, "--out", str(out))
    assert code == 2 and needle in err and err.startswith("remidi: error: ") and err.count("\n") == 1, err
    assert not out.exists() and stdout == ""


def test_tabular_rule_names_the_fix(tmp_path, capsys):
    code, _, err = run_cli(capsys, "run", "tabular-shared", "--algo", "remidi", "--set", "iterations=100",
                           "--set", "iters_per_adversary=60", "--out", str(tmp_path / "never"))
    assert code == 2 and err.count("\n") == 1
    assert ("(num_adversaries − 1) × iters_per_adversary = (3 − 1) × 60 = 120 is not below iterations = 100; "
            "lower num_adversaries or iters_per_adversary, or raise iterations") in err
    assert not (tmp_path / "never").exists()


def test_python_api_applies_the_same_validation(tmp_path):
    from remidi.errors import ConfigError
    from remidi.experiments import get_experiment
    from remidi.experiments.base import RunContext, RunSpec, resolve_config
    from remidi.experiments.running import run_experiment

    lever = get_experiment("lever")
    bad = {"num_updates": 6, "eval_every": 2, "remidi.steps_per_buffer": 1000}
    with pytest.raises(ConfigError, match="remidi.num_buffers: must be small enough"):
        run_experiment(RunSpec(lever, ["remidi"], "smoke", [0], overrides=bad), tmp_path / "a")
    assert not (tmp_path / "a").exists()
    # an experiment's train function, called directly, checks too (before any training)
    ctx = RunContext("lever", "remidi", "smoke", [0], resolve_config(lever, "smoke", bad), tmp_path / "b")
    with pytest.raises(ConfigError, match="remidi.num_buffers: must be small enough"):
        lever.train(ctx)
    tab = get_experiment("tabular-shared")
    ctx = RunContext("tabular-shared", "remidi", "smoke", [0],
                     resolve_config(tab, "smoke", {"iterations": 10, "iters_per_adversary": 10}), tmp_path / "c")
    with pytest.raises(ConfigError, match="num_adversaries: must be small enough"):
        tab.train(ctx)
    assert not (tmp_path / "b").exists() and not (tmp_path / "c").exists()


# ------------------------------------------------------------------------------- remidi list
def test_list_shows_every_key_with_its_default_and_meaning(capsys):
    from remidi.experiments import all_experiments
    from remidi.experiments.overrides import field_names

    code, out, _ = run_cli(capsys, "list", "lever")
    assert code == 0 and out.startswith(f"lever: {all_experiments()['lever'].description}\n")
    lines = out.splitlines()
    for key in field_names(all_experiments()["lever"].config_factory()):
        row = next(line for line in lines if line.split()[:1] == [key])
        assert len(row.split()) >= 3, row  # key, default, a description
    assert any(line.split()[:4] == ["num_updates", "300", "[paper:", "2500]"] for line in lines)
    assert any(line.split()[:2] == ["ppo.anneal_lr", "true"] for line in lines)
    code, out, _ = run_cli(capsys, "list", "tabular-shared")
    assert code == 0 and out.startswith("tabular-shared: ") and "lever" not in out
    assert any(line.split()[:2] == ["log_every", "10"] for line in out.splitlines())


def test_list_lever_says_which_paired_estimator_the_results_pages_claims_use(capsys):
    """PAIRED's own estimator stays PAIRED's default, and `remidi list lever` (and lever-noisy) says
    that the results page's PAIRED claims use the exact regret instead, and why."""
    for name in ("lever", "lever-noisy"):
        code, out, _ = run_cli(capsys, "list", name)
        lines = out.splitlines()
        assert any(line.split()[:2] == ["paired.estimator", "paired"] for line in lines)  # the default, unchanged
        (note,) = [line for line in lines if "paired.estimator=perfect" in line]
        assert note.lstrip().startswith("note:") and "results page" in note and "default" in note
        assert "cannot see a hidden answer" in note  # the why: PAIRED's antagonist misses the irreducible regret
    code, out, _ = run_cli(capsys, "list", "tabular-shared")
    assert "note:" not in out


def test_list_alone_is_one_line_per_experiment_with_its_presets(capsys):
    from remidi.experiments import all_experiments

    code, out, err = run_cli(capsys, "list")
    experiments = list(all_experiments().values())
    assert code == 0 and len(out.splitlines()) == len(experiments), out
    for line, exp in zip(out.splitlines(), experiments):
        assert line.split()[0] == exp.name and exp.description in line, line
        assert line.endswith(f"(presets: {', '.join(exp.presets)})"), line
    assert "remidi list NAME" in err


def test_every_settable_key_has_a_description():
    from remidi.experiments import all_experiments
    from remidi.experiments.overrides import field_names, key_help

    for exp in all_experiments().values():
        cfg = exp.config_factory()
        missing = [key for key in field_names(cfg) if not key_help(cfg, key)]
        assert not missing, f"{exp.name}: give these keys a help text in their field's metadata: {missing}"


def test_lever_tiny_is_the_engine_tests_tiny_configuration():
    # the suite's time depends on it: identical configurations compile to one shared program
    from remidi.experiments import get_experiment
    from remidi.experiments.base import resolve_config
    from remidi.experiments.overrides import parse_set_items
    from test_ued_engine import TINY

    overrides = parse_set_items(LEVER_TINY[1::2])
    assert resolve_config(get_experiment("lever"), "smoke", overrides) == TINY


def test_a_full_disk_is_one_line_and_loses_nothing(tmp_path, capsys, monkeypatch):
    """ENOSPC while a result file is written: one line naming the file, exit 1, the file before
    intact and no temporary left; the resume hint names the run folder."""
    import errno

    from remidi.experiments import outputs

    path = tmp_path / "summary.json"
    path.write_text("before")

    def full(fh):
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OSError) as err:
        outputs.atomic_write(path, full)
    assert err.value.filename == str(path) and path.read_text() == "before"
    assert [p.name for p in tmp_path.iterdir()] == ["summary.json"]
    # the temporary itself cannot be made (a read-only folder, a full quota): the file meant is named too
    import tempfile

    def refused(*args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied", str(tmp_path / ".summary.json.x.tmp"))

    with monkeypatch.context() as patch:
        patch.setattr(tempfile, "mkstemp", refused)
        with pytest.raises(OSError) as err:
            outputs.atomic_write(path, full)
    assert err.value.filename == str(path) and path.read_text() == "before"
    real = outputs.atomic_write

    def full_at_summary(target, write, binary=False):
        if target.name == "summary.json":
            return real(target, full, binary)
        return real(target, write, binary)

    monkeypatch.setattr(outputs, "atomic_write", full_at_summary)
    out = tmp_path / "run"
    code, _, err_text = run_cli(capsys, "run", "tabular-shared", "--algo", "mmr", "--seeds", "1", "--quiet",
                                *FAST, "--out", str(out))
    assert code == 1 and err_text.count("\n") == 1, err_text
    assert f"{out / 'summary.json'}: No space left on device; files written before are intact" in err_text
    assert f"continue with: remidi run --resume {out}" in err_text
    assert (out / "config.json").exists() and not list(out.glob(".*.tmp"))


def test_code_version_names_no_commit_for_an_untracked_copy_of_the_sources(tmp_path):
    """A copy of src/remidi inside another repository's ignored folder (how a run on a lent GPU
    gets a frozen commit's code) must not record that repository's commit as the run's code."""
    import shutil
    import subprocess
    import sys

    import remidi

    repo = tmp_path / "other"
    subprocess.run(["git", "init", "-q", str(repo)], check=True)
    (repo / ".gitignore").write_text("frozen/\n")
    subprocess.run(["git", "-C", str(repo), "add", ".gitignore"], check=True)
    subprocess.run(["git", "-C", str(repo), "-c", "user.email=t@t", "-c", "user.name=t", "commit", "-qm", "x"],
                   check=True)
    shutil.copytree(Path(remidi.__file__).parent, repo / "frozen" / "remidi",
                    ignore=shutil.ignore_patterns("__pycache__"))
    probe = "import json, remidi.files as f; print(json.dumps(f.code_version()))"
    done = subprocess.run([sys.executable, "-c", probe], cwd=repo, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(repo / "frozen"), "JAX_PLATFORMS": "cpu",
                               "XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false"})
    version = json.loads(done.stdout.strip().splitlines()[-1])
    assert version["commit"] is None and version["dirty"] is None
    assert version["device"] == "cpu: cpu" and version["jax"]
    assert version["xla_flags"] == "--xla_cpu_multi_thread_eigen=false"  # threading changes rounding: recorded
    assert version["cpu_cores"] == len(os.sched_getaffinity(0))
    # the CPU's model and instruction set: XLA's CPU kernels round differently on AVX2 and AVX-512
    flags = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").is_file() else ""
    if "avx512f" in flags:
        assert version["cpu"].endswith(", AVX-512")
    elif " avx2" in flags:
        assert version["cpu"].endswith(", AVX2")


@pytest.mark.parametrize("argv, needle", [
    (["run", "tabular-shared", "--out", ""], "--out: must name a folder, got ''"),
    (["run", "tabular-shared", "--out", "  "], "--out: must name a folder, got '  '"),
    (["run", "--resume", ""], "--resume: must name a folder, got ''"),
])
def test_an_empty_out_or_resume_folder_is_refused(tmp_path, capsys, monkeypatch, argv, needle):
    monkeypatch.chdir(tmp_path)  # an empty --out must not fall back to runs/<experiment>/<timestamp> here
    code, _, err = run_cli(capsys, *argv, "--quiet", *FAST)
    assert code == 2 and err.startswith("remidi: error: ") and err.count("\n") == 1 and needle in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.usefixtures("no_png")
def test_a_run_too_large_for_memory_is_one_line_and_keeps_nothing_of_itself(tmp_path, capsys, monkeypatch):
    """XLA's RESOURCE_EXHAUSTED at allocation or compile: one line naming num_envs and the size,
    exit 2; the files and folders this run made are removed (a resume would fail the same way),
    what was there before and the algorithms that finished are kept."""
    import jax

    from remidi.experiments import ued

    real = ued.train_seeds

    def out_of_memory(task, cfg, algo, *args, **kwargs):
        if algo == "remidi":
            raise jax.errors.JaxRuntimeError("RESOURCE_EXHAUSTED: Out of memory allocating 3221225472 bytes.")
        return real(task, cfg, algo, *args, **kwargs)

    monkeypatch.setattr(ued, "train_seeds", out_of_memory)
    base = ["run", "lever", "--seeds", "1", "--quiet", *LEVER_TINY]
    code, _, err = run_cli(capsys, *base, "--algo", "remidi", "--out", str(tmp_path / "new" / "run"))
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith("remidi: error: num_envs=8: the run does not fit in the device's memory: XLA asked "
                          "for 3.0 GiB; lower num_envs (--set num_envs=N) or the number of seeds; removed what "
                          "this run wrote"), err
    assert list(tmp_path.iterdir()) == []  # not even the parent folder it made

    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    code, _, err = run_cli(capsys, *base, "--algo", "plr,remidi", "--out", str(out))
    assert code == 2 and "num_envs=8: the run does not fit" in err and err.count("\n") == 1, err
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "plr"] and (out / "notes.txt").read_text() == "mine"
    assert (out / "plr" / "summary.json").exists() and f"(kept the finished plr in {out})" in err

    checkpoint = (out / "plr" / "checkpoint.npz").read_bytes()  # a resume keeps the folder as it is
    (out / "plr" / "summary.json").unlink()
    monkeypatch.setattr(ued, "train_seeds", lambda *a, **k: out_of_memory(None, None, "remidi"))
    code, _, err = run_cli(capsys, "run", "--resume", str(out / "plr"), "--quiet")
    assert code == 2 and err.count("\n") == 1 and f"{out / 'plr'} keeps its last checkpoint" in err, err
    assert (out / "plr" / "checkpoint.npz").read_bytes() == checkpoint and (out / "plr" / "config.json").exists()

    monkeypatch.setattr(ued, "train_seeds", lambda *a, **k: (_ for _ in ()).throw(MemoryError()))
    code, _, err = run_cli(capsys, *base, "--algo", "plr", "--out", str(tmp_path / "numpy"))
    assert code == 2 and "num_envs=8: the run does not fit in memory (MemoryError)" in err, err
    assert not (tmp_path / "numpy").exists()
    (tmp_path / "kept" / "data").mkdir(parents=True)  # a folder holding no run, with the user's files in it
    (tmp_path / "kept" / "data" / "x.txt").write_text("mine")
    assert run_cli(capsys, *base, "--algo", "plr", "--out", str(tmp_path / "kept"))[0] == 2
    assert [str(p.relative_to(tmp_path)) for p in sorted((tmp_path / "kept").rglob("*"))] == ["kept/data",
                                                                                            "kept/data/x.txt"]


def test_run_help_names_each_experiments_default_algorithms_from_the_registry(capsys, monkeypatch):
    from remidi.engine.algorithms import ALGORITHMS, PAPER_ALGORITHMS
    from remidi.experiments import all_experiments

    monkeypatch.setenv("COLUMNS", "2000")  # one line per option: no word broken at a hyphen
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    line = next(line for line in capsys.readouterr().out.splitlines() if line.strip().startswith("--algo"))
    assert "default: all" not in line
    for exp in all_experiments().values():
        default = ", ".join(exp.default_algorithms or exp.algorithms)
        group = next(part for part in line.split(" — ", 1)[1].split("; ") if exp.name in part.split(": ")[0].split(", "))
        assert group.split(": ", 1)[1].startswith(default), (exp.name, group)
        extra = [a for a in exp.algorithms if a not in (exp.default_algorithms or exp.algorithms)]
        assert not extra or f"(all adds {', '.join(extra)})" in group
    # a user's task: the paper's algorithms, and all adds every other registered one its mutator, builder and
    # solve criterion allow
    others = ", ".join(a for a in ALGORITHMS if a not in PAPER_ALGORITHMS)
    assert f"module:function: {', '.join(PAPER_ALGORITHMS)} (all adds {others} that the task can run)" in line


def test_resuming_a_finished_run_says_so_and_trains_nothing(tmp_path, capsys, finished_tabular):
    out = copy_of(finished_tabular, tmp_path / "both")
    for folder in (out, out / "mmr"):  # a several-algorithm run, one algorithm's run
        before = {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in out.rglob("*") if p.is_file()}
        code, stdout, err = run_cli(capsys, "run", "--resume", str(folder), "--quiet")
        assert code == 0 and err == "", err
        assert stdout == (f"{folder}: the run is finished (summary.json written); nothing to resume "
                          f"(its results: remidi table {folder})\n")
        assert {p: (p.read_bytes(), p.stat().st_mtime_ns) for p in out.rglob("*") if p.is_file()} == before


def test_printed_metrics_keep_one_value_column_for_long_names(capsys):
    from remidi.cli.experiments import _print_summaries

    long = "regret/LabyrinthFlipped_and_a_few_more_words/mean"  # longer than 32 characters
    _print_summaries({"plr": {"experiment": "tmaze", "preset": "smoke", "seeds": [0, 1], "metrics": {
        "solve_rate/mean": {"mean": 0.5, "std": 0.1, "per_seed": [0.4, 0.6]},
        long: {"mean": 12.25, "std": 1.0, "per_seed": [11.25, 13.25]},
        "x": {"mean": None, "std": None, "per_seed": [None, None]}}}}, "out")
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("  ")]
    assert len(rows) == 3
    ends = {len(row.split(" ± ")[0]) for row in rows}  # where each mean (or n/a) ends
    assert ends == {2 + len(long) + 1 + 10}, rows


def test_a_run_whose_rollouts_cannot_fit_is_refused_before_anything_is_written(tmp_path, capsys, monkeypatch):
    """The rollouts' observations alone (seeds × num_steps × num_envs × one observation and three
    floats) against the device's memory: a lower bound, checked with the rest of the input."""
    from remidi.experiments import running

    monkeypatch.setattr(running, "_device_memory", lambda: (64 * 2**20, "a 64 MiB test device"))
    argv = ["run", "lever", "--algo", "plr", "--seeds", "1", "--quiet", *LEVER_TINY, "--set", "num_envs=100000"]
    code, _, err = run_cli(capsys, *argv, "--out", str(tmp_path / "run"))
    # lever: a 65-float observation (260 bytes) and 12 bytes: 4 steps × 100000 envs × 272 bytes = 104 MiB
    assert code == 2 and err == ("remidi: error: num_envs=100000: the rollouts alone need 104 MiB (1 seed × num_steps "
                                 "4 × num_envs 100000 × 272 bytes), more than the 64 MiB of a 64 MiB test device; "
                                 "lower num_envs (--set num_envs=N), num_steps or the number of seeds\n"), err
    assert list(tmp_path.iterdir()) == []
