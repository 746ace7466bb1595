"""The line a run ends with for each buffer sequence (experiments/remidi_account.remidi_account and
remidi_line): the fresh levels it rejected out of those it evaluated, the masked share of the
steps it trained on and its frozen buffers' solve rates, or, where it rejected and masked
nothing, that it was the algorithm it refines (at the cost ratio to that algorithm's run of the
same invocation). Checked against hand computations on constructed histories, then on tiny runs
where rejection happens (the worked example's hidden signposts) and where it cannot (one buffer)."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from remidi.experiments.base import RunResult
from remidi.experiments.remidi_account import remidi_account, remidi_line

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "bring_your_own_env.py"


def result(**history):
    """Two seeds, blocks of 10 and 20 updates (ending at 10 and 30)."""
    return RunResult(steps=np.array([10, 30]), history={k: np.asarray(v, float) for k, v in history.items()})


BLOCKS = dict(replay=[[0.5, 0.75], [0.5, 1.0]], rejected=[[0, 6], [1, 0]],
              trained_fraction_masked=[[0.0, 0.3], [0.0, 0.0]], active_buffer=[[0, 1], [0, 1]],
              **{"buffer_solve_rate/b0": [[np.nan, 0.5], [np.nan, 0.7]], "buffer_solve_rate/b1": [[0.2, 0.1], [0.3, 0.4]]})


def test_the_counts_are_the_blocks_sums_by_hand():
    did = remidi_account("remidi", result(**BLOCKS), num_envs=4)
    # fresh: 10·4·(1 − 0.5) + 20·4·(1 − 0.75) = 20 + 20 = 40; seed 1: 20 + 0 = 20
    assert did["fresh_levels"] == [40, 20] and did["rejected"] == [6, 1]
    # trained updates (PLR⊥ trains on replays): 10·0.5 + 20·0.75 = 20 and 25; masked: 20·0.3 = 6 of 20
    assert did["masked_share"] == pytest.approx([0.3, 0.0])
    assert did["frozen_solve_rate"] == {"b0": pytest.approx([0.5, 0.7])}  # b1 is active at the end: not frozen
    assert did["base"] == "plr"
    line = remidi_line("remidi", {"remidi_did": did}, {})
    assert line == ("what remidi did (2 seeds): rejected 7 of 60 fresh levels (11.7%), masked 15.0% of the steps it "
                    "trained on, the frozen buffers solve 0.60 (b0)")
    # rehearsal: an update that rehearses is neither fresh nor a replay, and trains
    rehearsed = remidi_account("remidi", result(**BLOCKS, rehearsal=[[0.5, 0.25], [0.0, 0.0]]), num_envs=4)
    assert rehearsed["fresh_levels"] == [0, 20] and rehearsed["masked_share"][0] == pytest.approx(6 / 30)
    # SFL trains on every update: 6 masked of 30 updates
    assert remidi_account("remidi-sfl", result(**BLOCKS), num_envs=4)["masked_share"] == pytest.approx([0.2, 0.0])
    assert remidi_account("plr", result(**BLOCKS), num_envs=4) is None  # no buffer sequence: nothing said


def test_a_run_that_rejected_and_masked_nothing_says_it_was_plr_at_its_cost():
    quiet = {**BLOCKS, "rejected": [[0, 0], [0, 0]], "trained_fraction_masked": [[0, 0], [0, 0]]}
    did = remidi_account("remidi", result(**quiet), num_envs=4)
    part = {"updates": [0, 30], "wall_s": 0, "train_s": 9.0, "train_updates": 20}
    remidi = {"remidi_did": did, "wall_s": 40.0, "parts": [part]}
    plr = {"wall_s": 20.0, "parts": [{**part, "train_s": 3.0}]}  # steady rates: 0.45 s and 0.15 s per update
    assert remidi_line("remidi", remidi, {"plr": plr, "remidi": remidi}) == (
        "what remidi did (2 seeds): rejected 0 of 60 fresh levels, masked no step, the frozen buffers solve 0.60 (b0): "
        "this run was PLR⊥ at 3.0× its cost")
    assert remidi_line("remidi", remidi, {"remidi": remidi}).endswith(": this run was PLR⊥")  # no PLR⊥ run beside it
    untimed = {"wall_s": 10.0, "parts": [{"updates": [0, 30]}]}  # one block: wall time over updates
    assert remidi_line("remidi", {**remidi, "parts": [{"updates": [0, 30]}]}, {"plr": untimed}).endswith(" at 4.0× its cost")


@pytest.fixture(scope="module")
def task():
    spec = importlib.util.spec_from_file_location("byo_remidi_account", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module.make_task()


TINY = {"num_updates": 40, "num_envs": 8, "eval_every": 20, "eval_attempts": 1, "hidden_size": 32, "ppo.epochs": 1,
        "ppo.minibatches": 1}


@pytest.mark.slow  # two tiny runs of PLR⊥ and ReMiDi: compiles for about a minute
def test_tiny_runs_end_with_what_remidi_did(task, tmp_path, capsys):
    from remidi import run_ued

    capsys.readouterr()
    run_ued(task, TINY, ["plr", "remidi"], 1, tmp_path / "hidden", progress=False)
    # hidden signposts: the second buffer rejects fresh levels its first one explains
    (line,) = [line for line in capsys.readouterr().err.splitlines() if line.startswith("remidi: what remidi did")]
    did = [int(n.replace(",", "")) for n in line.split(": rejected ")[1].split(" fresh")[0].split(" of ")]
    assert 0 < did[0] < did[1] and "× PLR⊥'s cost" in line and "the frozen buffers solve" in line, line
    run_ued(task, {**TINY, "remidi.num_buffers": 1}, ["plr", "remidi"], 1, tmp_path / "one", progress=False)
    (line,) = [line for line in capsys.readouterr().err.splitlines() if line.startswith("remidi: what remidi did")]
    assert ", masked no step: this run was PLR⊥ at " in line and line.endswith("× its cost"), line  # nothing frozen
