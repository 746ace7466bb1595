"""End-to-end `remidi run lever --preset smoke`, one algorithm per test: the qualitative pattern
of the paper's Figure 8 at smoke size."""

import csv
import json

import numpy as np
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


def history(out):
    """metric → step → per-seed values, from a run's metrics.csv."""
    h = {}
    with open(out / "metrics.csv") as fh:
        for r in csv.DictReader(fh):
            h.setdefault(r["metric"], {}).setdefault(int(r["step"]), []).append(float(r["value"]))
    return h


# One ReMiDi run serves the PLR⊥ checks too, and one ReMiDi-over-PAIRED run PAIRED's (as in
# tests/test_maze_smoke.py): until the switch at update 100 nothing is frozen, so ReMiDi's first
# stage is PLR⊥ and ReMiDi over PAIRED's is PAIRED; two more compiled end-to-end programs would
# cost the suite about 40 s. The results page compares PLR⊥ and PAIRED themselves with ReMiDi at the
# paper preset (10 seeds each).
@pytest.fixture(scope="module")
def remidi_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("remidi")
    m, metrics = run(out, "remidi")
    return m, metrics, history(out / "remidi")


@pytest.fixture(scope="module")
def remidi_paired_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("remidi-paired")
    m, metrics = run(out, "remidi-paired", "--set", "paired.estimator=perfect")
    return m, metrics, history(out / "remidi-paired")


def test_plr_stage_replays_hidden_levels_and_fails_visible_ones(remidi_run):
    _, _, h = remidi_run
    assert max(h["active_buffer"][50]) == 0 and max(h["trained_fraction_masked"][50]) == 0  # PLR⊥ until update 100
    assert min(h["replay_fraction/hidden"][100]) > 0.9  # updates 50-100: replays of buffer 0
    assert min(h["buffer_fraction/hidden"][50]) > 0.9
    assert max(h["solve_rate/visible"][100]) < 0.1
    assert min(h["regret/visible/mean"][100]) > 0.95 * BLIND_VISIBLE  # it never learns to read the answer
    assert min(h["regret/hidden/worst"][100]) >= MMR_HIDDEN - 1e-3


# one seed where the pattern is a property of every run (and a second would cost the suite time)
def test_minimax_return_also_prefers_hidden_levels(tmp_path):
    m, _ = run(tmp_path, "minimax-return", "--seeds", "1")
    assert m["replay_fraction/hidden"] > 0.9
    check_hidden_regret(m)


def test_dr_trains_on_fresh_levels_only(tmp_path):
    # 50 updates (the CLI scales the keys measured in updates): nothing checked depends on its length
    m, metrics = run(tmp_path, "dr", "--seeds", "1", "--set", "num_updates=50")
    assert m["replay"] == 0
    assert not any(k.startswith(("buffer_size", "buffer_fraction")) for k in m)  # no buffer: nothing reported
    assert metrics["replay_fraction/hidden"]["mean"] is None  # nothing replayed: undefined, not 0
    check_hidden_regret(m)


def test_remidi_rejects_hidden_levels_and_learns_visible_ones(remidi_run):
    m, metrics, h = remidi_run
    assert m["active_buffer"] == 1
    assert m["buffer_fraction/hidden/b0"] > 0.9  # the first buffer is plain PLR: hidden levels
    assert m["buffer_fraction/hidden"] == 0  # the second never takes one: complete overlap
    assert m["replay_fraction/hidden"] == 0
    check_hidden_regret(m)
    assert m["solve_rate/visible"] > 0.2
    assert m["solve_rate/visible"] > 5 * np.mean(h["solve_rate/visible"][100])  # against its PLR⊥ stage
    assert m["regret/visible/mean"] < 0.85 * np.mean(h["regret/visible/mean"][100])
    assert all(v > 0.1 for v in metrics["solve_rate/visible"]["per_seed"])


def test_paired_stage_with_perfect_regret_generates_hidden_levels_and_fails_visible_ones(remidi_paired_run):
    """PAIRED whose antagonist is the exact optimum (``paired.estimator=perfect``; the first
    generator of ReMiDi over PAIRED, updates 0-100): hidden levels carry regret ≈ 20 against ≤ 2
    for visible ones, so the generator learns to build hidden levels (half of its first levels
    are hidden, by chance), and the protagonist, trained on what it generates, stays at chance on
    visible levels."""
    _, _, h = remidi_paired_run
    assert max(h["active_buffer"][50]) == 0 and max(h["trained_fraction_masked"][50]) == 0  # PAIRED until update 100
    early, late = h["generated/hidden"][50], h["generated/hidden"][100]  # updates 0-50, 50-100
    assert min(late) > 0.6 and min(late) > max(early)  # it learned to
    assert max(h["solve_rate/visible"][100]) < 0.1
    assert min(h["paired/regret"][100]) > 10  # the generator is paid for hidden levels


def test_remidi_over_paired_moves_later_generators_to_visible_levels(remidi_paired_run):
    """ReMiDi over PAIRED (perfect regret): the first generator learns hidden levels as PAIRED's
    does; after the switch (update 100 of the smoke preset) a fresh generator is paid little for
    levels the first one's support explains (hidden levels all look alike), builds fewer hidden
    levels, and the protagonist learns the visible ones PAIRED's never does."""
    m, metrics, h = remidi_paired_run
    assert min(h["generated/hidden"][100]) > 0.6  # the first generator, as PAIRED's
    assert max(metrics["generated/hidden"]["per_seed"]) < 0.45  # the second one leaves hidden levels
    assert min(h["rejected"][150]) > 100  # levels the first support explains are rejected
    assert m["solve_rate/visible"] > 0.1
    check_hidden_regret(m)
