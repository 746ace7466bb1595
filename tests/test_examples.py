"""examples/bring_your_own_env.py runs, writes its outputs and shows the pattern it is about."""

import importlib.util
import json
import math
import sys
from pathlib import Path

import pytest

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "bring_your_own_env.py"


def load_example():
    spec = importlib.util.spec_from_file_location("bring_your_own_env", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while it loads
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_bring_your_own_env_example(tmp_path, capsys):
    example = load_example()
    out = tmp_path / "byo"
    # in-process, so the suite's compilation cache (tests/conftest.py) applies
    assert example.main([str(out)]) == 0
    printed = capsys.readouterr().out
    assert "next:" in printed and str(out / "training.png") in printed
    assert (out / "config.json").exists() and (out / "training.png").stat().st_size > 10_000
    assert json.loads((out / "config.json").read_text())["config"]["num_updates"] == 200
    shares = {}
    for algo in ("plr", "remidi"):
        for name in ("metrics.csv", "summary.json", "checkpoint.npz", "checkpoint.history.npz"):
            assert (out / algo / name).exists(), (algo, name)
        summary = json.loads((out / algo / "summary.json").read_text())
        assert summary["seeds"] == [0, 1]
        m = {name: v["mean"] for name, v in summary["metrics"].items()}
        for name in ("solve_rate/visible", "solve_rate/hidden"):
            assert 0 <= m[name] <= 1, (algo, name)
        assert m["regret/visible/mean"] >= -1e-6
        # the hidden levels keep their regret: a guess at best (half the optimal return ≥ 0.425)
        assert m["regret/hidden/worst"] > 0.2
        shares[algo] = m["replay_fraction/hidden"]
    assert shares["plr"] > 0.5  # PLR⊥ replays mostly the levels it cannot learn
    # ReMiDi's second buffer rejects every hidden level (their rollouts are the frozen ones')
    assert shares["remidi"] is None or shares["remidi"] == 0 or math.isnan(shares["remidi"])


def test_bring_your_own_env_example_bad_input_is_one_line(tmp_path, capsys):
    example = load_example()
    assert example.main([str(tmp_path / "x"), "--updates", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("bring_your_own_env: error: remidi.num_buffers") and err.count("\n") == 1
    assert not (tmp_path / "x").exists()
