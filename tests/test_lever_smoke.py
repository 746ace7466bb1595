"""End-to-end `remidi run lever --preset smoke`, one algorithm per test: the qualitative pattern
of the paper's Figure 8 at smoke size."""

import csv
import json

import pytest

from remidi.cli import main

CHANCE = 1 / 64


def run(tmp_path, algo):
    out = tmp_path / algo
    assert main(["run", "lever", "--algo", algo, "--preset", "smoke", "--out", str(out), "--quiet"]) == 0
    for name in ("config.json", "metrics.csv", "summary.json", "training.png", "checkpoint.npz"):
        assert (out / name).exists(), name
    metrics = json.loads((out / "summary.json").read_text())["metrics"]
    if algo != "remidi":  # nothing is ever masked without frozen buffers: at every logged step
        with open(out / "metrics.csv") as fh:
            masked = [float(r["value"]) for r in csv.DictReader(fh) if r["metric"] == "trained_fraction_masked"]
        assert masked and all(v == 0 for v in masked)
    return {k: v["mean"] for k, v in metrics.items()}, metrics


@pytest.fixture(scope="module")
def plr_visible(tmp_path_factory):
    m, _ = run(tmp_path_factory.mktemp("plr"), "plr")
    return m


def test_plr_replays_hidden_levels_and_fails_visible_ones(plr_visible):
    m = plr_visible
    assert m["replay_fraction/hidden"] > 0.9
    assert m["buffer_fraction/hidden"] > 0.9
    assert m["solve_rate/visible"] < 0.1
    assert m["solve_rate/hidden"] < 3 * CHANCE


def test_minimax_return_also_prefers_hidden_levels(tmp_path):
    m, _ = run(tmp_path, "minimax-return")
    assert m["replay_fraction/hidden"] > 0.9
    assert m["solve_rate/hidden"] < 3 * CHANCE


def test_dr_trains_on_fresh_levels_only(tmp_path):
    m, metrics = run(tmp_path, "dr")
    assert m["replay"] == 0 and m["buffer_size"] == 0
    assert metrics["replay_fraction/hidden"]["mean"] is None  # nothing replayed: undefined, not 0
    assert m["solve_rate/hidden"] < 3 * CHANCE


def test_remidi_rejects_hidden_levels_and_learns_visible_ones(tmp_path, plr_visible):
    m, metrics = run(tmp_path, "remidi")
    assert m["active_buffer"] == 1
    assert m["buffer_fraction/hidden/b0"] > 0.9  # the first buffer is plain PLR: hidden levels
    assert m["buffer_fraction/hidden"] == 0  # the second never takes one: complete overlap
    assert m["replay_fraction/hidden"] == 0
    assert m["solve_rate/hidden"] < 3 * CHANCE
    assert m["solve_rate/visible"] > 0.2
    assert m["solve_rate/visible"] > 5 * plr_visible["solve_rate/visible"]
    assert all(v > 0.1 for v in metrics["solve_rate/visible"]["per_seed"])
