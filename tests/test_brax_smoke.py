"""End-to-end `remidi run brax-hopper --algo remidi` at a tiny size: every output, the continuous
agent, observation statistics kept across resume, and ReMiDi's pattern (the first buffer, plain
PLR⊥, takes type B levels; the second rejects every one of them). One compiled program serves
the whole file (compiling Brax physics costs about a minute on 2 cores)."""

import csv
import json

import numpy as np
import pytest

from remidi.cli import main

pytestmark = pytest.mark.slow  # end-to-end run: `pytest -m "not slow"` skips it

TINY = ["--set", "num_updates=24", "--set", "num_envs=16", "--set", "num_steps=25", "--set", "hidden_size=16",
        "--set", "lstm_size=16", "--set", "ppo.minibatches=2", "--set", "ppo.epochs=2", "--set", "eval_every=8",
        "--set", "checkpoint_every=8", "--set", "eval_attempts=1", "--set", "buffer.capacity=32",
        "--set", "remidi.buffer_capacity=32", "--set", "remidi.steps_per_buffer=8", "--set", "buffer.min_fill=0.5",
        "--set", "brax.reference_return=250", "--set", "brax.reference_discounted_return=200"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("brax") / "remidi"
    argv = ["run", "brax-hopper", "--algo", "remidi", "--preset", "smoke", "--seeds", "1", "--out", str(out),
            "--quiet", *TINY]
    assert main(argv) == 0
    return out


def test_outputs_and_summary(run):
    for name in ("config.json", "metrics.csv", "summary.json", "training.png", "checkpoint.npz"):
        assert (run / name).exists(), name
    config = json.loads((run / "config.json").read_text())
    assert config["config"]["network"] == "mlp_lstm" and config["config"]["normalize_obs"] is True
    assert config["config"]["reward_scale"] == 0.1 and config["config"]["brax"]["reference_return"] == 250
    metrics = json.loads((run / "summary.json").read_text())["metrics"]
    assert list(metrics)[:3] == ["return/undisturbed", "replay_fraction/type_b", "buffer_fraction/type_b"]
    ret = metrics["return/undisturbed"]["mean"]
    # hopper earns 1 per healthy step: a 100-step episode of an untrained agent lies between 0 and ~300
    assert 0 < ret < 400
    np.testing.assert_allclose(metrics["regret/undisturbed/mean"]["mean"], 250 - ret, rtol=1e-4)


def test_remidi_second_buffer_rejects_type_b_levels(run):
    m = {k: v["mean"] for k, v in json.loads((run / "summary.json").read_text())["metrics"].items()}
    assert m["active_buffer"] == 1
    assert m["buffer_fraction/type_b/b0"] > 0.3  # the first buffer is plain PLR⊥: type B levels in it
    assert m["buffer_fraction/type_b/b1"] == 0 and m["buffer_fraction/type_b"] == 0
    assert m["replay_fraction/type_b"] == 0
    with open(run / "metrics.csv") as fh:
        rows = [r for r in csv.DictReader(fh)]
    rejected = sum(float(r["value"]) for r in rows if r["metric"] == "rejected")
    assert rejected > 0  # complete overlaps with the frozen type B levels: never inserted
