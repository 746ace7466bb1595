"""End-to-end `remidi run lever --preset smoke`, one algorithm per test: the qualitative pattern
of the paper's Figure 8 at smoke size."""

import csv
import json

import pytest

from remidi.cli import main

pytestmark = pytest.mark.slow  # end-to-end runs: `pytest -m "not slow"` skips them

CHANCE = 1 / 64
MMR_HIDDEN = 20 * (1 - CHANCE)  # minimax regret on hidden levels (uniform lever choice)
BLIND_VISIBLE = 2 * (1 - CHANCE)  # regret on a visible level of a policy that ignores the answer


def check_hidden_regret(m):
    # no policy beats minimax regret on the hidden levels; the mean over them is the same for
    # every policy that cannot see the answer (which is why the solve rate there says nothing)
    assert m["regret/hidden/worst"] >= MMR_HIDDEN - 1e-3
    assert abs(m["regret/hidden/mean"] - MMR_HIDDEN) < 1e-3


def run(tmp_path, algo, *more):
    out = tmp_path / algo
    assert main(["run", "lever", "--algo", algo, "--preset", "smoke", "--out", str(out), "--quiet", *more]) == 0
    for name in ("config.json", "metrics.csv", "summary.json", "training.png", "checkpoint.npz"):
        assert (out / name).exists(), name
    metrics = json.loads((out / "summary.json").read_text())["metrics"]
    if algo not in ("remidi", "remidi-paired"):  # nothing is ever masked without frozen levels: at every logged step
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
    assert m["regret/visible/mean"] > 0.95 * BLIND_VISIBLE  # it never learns to read the answer
    check_hidden_regret(m)


# one seed where the pattern is a property of every run (and a second would cost the suite time)
def test_minimax_return_also_prefers_hidden_levels(tmp_path):
    m, _ = run(tmp_path, "minimax-return", "--seeds", "1")
    assert m["replay_fraction/hidden"] > 0.9
    check_hidden_regret(m)


def test_dr_trains_on_fresh_levels_only(tmp_path):
    m, metrics = run(tmp_path, "dr", "--seeds", "1")
    assert m["replay"] == 0
    assert not any(k.startswith(("buffer_size", "buffer_fraction")) for k in m)  # no buffer: nothing reported
    assert metrics["replay_fraction/hidden"]["mean"] is None  # nothing replayed: undefined, not 0
    check_hidden_regret(m)


def test_remidi_rejects_hidden_levels_and_learns_visible_ones(tmp_path, plr_visible):
    m, metrics = run(tmp_path, "remidi")
    assert m["active_buffer"] == 1
    assert m["buffer_fraction/hidden/b0"] > 0.9  # the first buffer is plain PLR: hidden levels
    assert m["buffer_fraction/hidden"] == 0  # the second never takes one: complete overlap
    assert m["replay_fraction/hidden"] == 0
    check_hidden_regret(m)
    assert m["solve_rate/visible"] > 0.2
    assert m["solve_rate/visible"] > 5 * plr_visible["solve_rate/visible"]
    assert m["regret/visible/mean"] < 0.85 * plr_visible["regret/visible/mean"]
    assert all(v > 0.1 for v in metrics["solve_rate/visible"]["per_seed"])


def test_paired_with_perfect_regret_generates_hidden_levels_and_fails_visible_ones(tmp_path):
    """PAIRED whose antagonist is the exact optimum (``paired.estimator=perfect``): hidden levels
    carry regret ≈ 20 against ≤ 2 for visible ones, so the generator learns to build hidden
    levels (half of the generator's first levels are hidden, by chance), and the protagonist,
    trained on what it generates, stays at chance on visible levels."""
    m, metrics = run(tmp_path, "paired", "--set", "paired.estimator=perfect")
    assert m["generated/hidden"] > 0.75
    assert min(metrics["generated/hidden"]["per_seed"]) > 0.7
    assert m["solve_rate/visible"] < 0.1
    assert m["paired/regret"] > 10  # the generator is paid for hidden levels
    with open(tmp_path / "paired" / "metrics.csv") as fh:
        first = [float(r["value"]) for r in csv.DictReader(fh) if r["metric"] == "generated/hidden" and r["step"] == "50"]
    assert max(first) < 0.7 < m["generated/hidden"]  # it learned to: early on the shares are near one half
    check_hidden_regret(m)


def test_remidi_over_paired_moves_later_generators_to_visible_levels(tmp_path):
    """ReMiDi over PAIRED (perfect regret): the first generator learns hidden levels as PAIRED's
    does; after the switch (update 100 of the smoke preset) a fresh generator is paid little for
    levels the first one's support explains (hidden levels all look alike), builds fewer hidden
    levels, and the protagonist learns the visible ones PAIRED's never does."""
    m, metrics = run(tmp_path, "remidi-paired", "--set", "paired.estimator=perfect")
    with open(tmp_path / "remidi-paired" / "metrics.csv") as fh:
        rows = [r for r in csv.DictReader(fh) if r["metric"] in ("generated/hidden", "rejected")]
    at = lambda metric, step: [float(r["value"]) for r in rows if r["metric"] == metric and r["step"] == str(step)]  # noqa: E731
    assert min(at("generated/hidden", 100)) > 0.6  # the first generator, as PAIRED's
    assert max(metrics["generated/hidden"]["per_seed"]) < 0.45  # the second one leaves hidden levels
    assert min(at("rejected", 150)) > 100  # levels the first support explains are rejected
    assert m["solve_rate/visible"] > 0.1
    check_hidden_regret(m)
