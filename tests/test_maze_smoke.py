"""End-to-end `remidi run tmaze|blindfold` on a shortened smoke preset: the qualitative pattern of
the paper's Figures 6-7 (PLR⊥'s replay fills with the levels of irreducible regret; ReMiDi's later
buffers reject them), and every output a reader needs."""

import csv
import json

import numpy as np
import pytest

from remidi.cli import main
from remidi.envs.maze import HELD_OUT_NAMES

# the smoke preset, shortened further for the test suite
SHORT = ["--set", "num_updates=40", "--set", "eval_every=20", "--set", "checkpoint_every=20", "--set", "num_steps=32",
         "--set", "eval_attempts=1", "--set", "ppo.epochs=1", "--set", "remidi.steps_per_buffer=10"]


def run(out, experiment, algo, *more):
    argv = ["run", experiment, "--algo", algo, "--preset", "smoke", "--out", str(out), "--quiet", *SHORT, *more]
    assert main(argv) == 0
    for name in ("config.json", "metrics.csv", "summary.json", "training.png", "final.png", "checkpoint.npz"):
        assert (out / name).exists(), name
    summary = json.loads((out / "summary.json").read_text())
    with open(out / "metrics.csv") as fh:
        rows = list(csv.DictReader(fh))
    history = {}
    for r in rows:
        history.setdefault(r["metric"], {}).setdefault(int(r["step"]), []).append(float(r["value"]))
    return {k: v["mean"] for k, v in summary["metrics"].items()}, summary, history


def check_held_out_metrics(summary):
    metrics = summary["metrics"]
    rates = [metrics[f"solve_rate/{name}"]["per_seed"] for name in HELD_OUT_NAMES]
    assert all(0.0 <= x <= 1.0 for seed_rates in rates for x in seed_rates)
    np.testing.assert_allclose(metrics["solve_rate/mean"]["per_seed"], np.mean(rates, axis=0), atol=1e-6)
    assert list(metrics)[:11] == ["solve_rate/mean"] + [f"solve_rate/{n}" for n in HELD_OUT_NAMES]


@pytest.fixture(scope="module")
def tmaze_remidi(tmp_path_factory):
    # buffer 0 lasts 39 updates (nearly the first two blocks), long enough for PLR⊥'s preference to show
    # in it; buffers 1 and 2 follow. One run serves both the PLR⊥ and the ReMiDi checks: ReMiDi's
    # first stage is PLR⊥ (nothing frozen yet), and a second compiled program for `--algo plr`
    # would cost the suite about 30 s
    return run(tmp_path_factory.mktemp("tmaze") / "remidi", "tmaze", "remidi",
               "--set", "num_updates=80", "--set", "remidi.steps_per_buffer=39")


@pytest.mark.slow  # end-to-end run: `pytest -m "not slow"` skips it
def test_plr_stage_replay_fills_with_tmazes(tmaze_remidi):
    _, _, history = tmaze_remidi
    assert max(history["active_buffer"][20]) == 0  # the first block is all PLR⊥ ...
    assert max(history["rejected"][20]) == 0 and max(history["trained_fraction_masked"][20]) == 0  # ... unmasked
    # half of the generated levels are T-mazes; PLR⊥ replays them far more (updates 20-40: the
    # first buffer's replays, and any of buffer 1, which holds no T-mazes, only lower the share)
    assert np.mean(history["replay_fraction/tmaze"][40]) > 0.75
    assert np.mean(history["buffer_fraction/tmaze/b0"][40]) > 0.6  # and so does its buffer


@pytest.mark.slow  # end-to-end run: `pytest -m "not slow"` skips it
def test_remidi_later_buffers_hold_no_tmazes(tmaze_remidi):
    m, summary, history = tmaze_remidi
    assert m["active_buffer"] == 2
    assert m["buffer_fraction/tmaze/b0"] > 0.75  # the first buffer is PLR⊥: T-mazes
    assert m["buffer_fraction/tmaze/b1"] < 0.1 and m["buffer_fraction/tmaze/b2"] < 0.1
    assert m["replay_fraction/tmaze"] < 0.1
    assert min(history["rejected"][80]) > 0  # complete overlaps turned away
    check_held_out_metrics(summary)
    assert all(x < 0.1 for x in summary["metrics"]["buffer_fraction/tmaze/b1"]["per_seed"])


@pytest.mark.slow  # end-to-end run: `pytest -m "not slow"` skips it
def test_blindfold_remidi_rejects_blind_levels(tmp_path):
    m, summary, _ = run(tmp_path / "remidi", "blindfold", "remidi")
    assert m["buffer_fraction/blind/b0"] > 0.2  # PLR⊥'s buffer takes blind levels too
    assert m["buffer_fraction/blind/b1"] < 0.1 and m["buffer_fraction/blind/b2"] < 0.1
    assert m["replay_fraction/blind"] < 0.1 and m["rejected"] > 0
    check_held_out_metrics(summary)


@pytest.mark.parametrize("experiment, setting, needle", [
    ("tmaze", "maze.prob=2", "maze.prob: must be in [0, 1], got 2.0"),
    ("blindfold", "maze.num_walls=500", "maze.num_walls: must be an integer in [0, 167], got 500"),
    ("tmaze", "maze.size=9", "--set: unknown key 'maze.size'"),
])
def test_bad_maze_settings_are_one_line_errors(tmp_path, capsys, experiment, setting, needle):
    out = tmp_path / "run"
    assert main(["run", experiment, "--set", setting, "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1
    assert not out.exists()
