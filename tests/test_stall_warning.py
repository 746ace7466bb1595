"""The warning for a ReMiDi seed that trains on nothing because a frozen adversary explains the
levels it plays (seed 1 of the results page's T-maze belief runs: its learned model explained
almost every fresh level after the first buffer, its active buffer never reached the replay
minimum, and it trained on nothing for 1350 updates without a word). Pure functions over the
driver's block metrics, and their wiring into the UED experiments' training (the driver mocked:
no program is compiled). That ``ppo/*`` is NaN on an update that does not train, or whose every
step was masked, is the engine's (tests/test_ued_engine.py, tests/test_ppo.py)."""

from __future__ import annotations

import numpy as np
import pytest

from remidi.engine.config import UEDConfig
from remidi.experiments import ued
from remidi.experiments.base import RunContext

# one block of 150 updates of 32 envs, four seeds, as every algorithm logs them (DR's and PLR⊥'s
# `rejected` is 0: nothing is frozen); `ppo/policy_loss` is the block's mean over the updates
# that trained, NaN if none did
ENVS, BLOCK = 32, 150
NAN = float("nan")
BLOCK_METRICS = {"rejected": np.array([4800.0, 4709.0, 0.0, 2400.0]),
                 "inserted": np.array([0.0, 91.0, 5.0, 2400.0]),
                 "replay": np.array([0.0, 0.0, 0.0, 0.8]),
                 "ppo/policy_loss": np.array([NAN, NAN, NAN, 0.01])}


def test_a_block_that_trained_on_nothing_while_levels_were_rejected_is_stalled():
    # seed 0: every level explained; seed 1: some got in, too few to replay (blindfold-noisy's
    # belief seeds in their second block); seed 2: PLR⊥ filling its buffer (nothing frozen);
    # seed 3: ReMiDi rejecting half and training on replays
    assert ued.stalled_seeds(BLOCK_METRICS).tolist() == [True, True, False, False]
    assert ued.stalled_seeds({"rejected": np.zeros(2)}).size == 0  # a learner without PPO's metrics


def test_the_warning_names_the_seed_updates_and_counts_once_and_the_belief_hint():
    check = ued.stall_warner([3, 4, 5, 6], "belief", ENVS, BLOCK)
    first, second = check(300, BLOCK_METRICS)  # the first block of this invocation: a resume from update 150
    assert first == ("seed 3: in updates 151–300 the agent trained on nothing: a frozen adversary explained 4800 of "
                     "the 4800 levels played; with remidi.tracker=belief the frozen models may explain too much "
                     "(docs/belief.md, \"The learned belief tracker\")"), first
    assert second.startswith("seed 4: in updates 151–300 the agent trained on nothing: a frozen adversary explained "
                             "4709 of the 4800 levels played;"), second
    assert check(450, BLOCK_METRICS) == []  # once per seed
    one = {k: v[:1] for k, v in BLOCK_METRICS.items()}
    (exact,) = ued.stall_warner([0], "prefix", ENVS, BLOCK)(150, one)
    assert exact == "seed 0: in updates 1–150 the agent trained on nothing: a frozen adversary explained 4800 of the " \
                    "4800 levels played"
    (last,) = ued.stall_warner([0], "per_step", ENVS, BLOCK)(1000, one)  # a short last block: updates 901–1000
    assert last.startswith("seed 0: in updates 901–1000") and "of the 3200 levels played" in last


def test_the_stalled_updates_of_a_whole_run_merge_following_blocks():
    steps = np.array([150, 300, 450, 600])
    history = {"rejected": np.array([[0.0, 4800, 4800, 4700], [4800, 10, 4800, 0]]),
               "ppo/policy_loss": np.array([[0.1, NAN, NAN, NAN], [NAN, 0.2, NAN, NAN]])}
    assert ued.stalled_updates([0, 1], steps, history) == {"0": [[151, 600]], "1": [[1, 150], [301, 450]]}
    assert ued.stalled_updates([0, 1], steps, {"rejected": history["rejected"]}) == {}


@pytest.mark.parametrize("process", [0, 1])
def test_training_prints_it_in_the_first_process(monkeypatch, capsys, process):
    """make_train's block callback prints the warning whatever the experiment tracking, once
    across processes (each gets every seed's metrics), and the run's summary lists the stalled
    updates."""
    from remidi.engine.run.driver import TrainResult

    def fake_train_seeds(task, cfg, algo, seeds, *, on_block=None, **kwargs):
        metrics = {k: v[:1] for k, v in BLOCK_METRICS.items()}
        on_block(BLOCK, metrics)
        return TrainResult(np.array([BLOCK]), {k: v[:, None] for k, v in metrics.items()},
                           {"replay": np.zeros((1, BLOCK))}, None, [])

    monkeypatch.setattr(ued, "train_seeds", fake_train_seeds)
    monkeypatch.setattr(ued, "run_warnings", lambda *args: [])
    monkeypatch.setattr(ued, "tracker_cost_note", lambda *args: None)
    monkeypatch.setattr(ued.jax, "process_index", lambda: process)
    cfg = UEDConfig(num_envs=ENVS, eval_every=BLOCK, num_updates=BLOCK)
    train = ued.make_train(lambda c: None, ())
    result = train(RunContext(experiment="x", algo="remidi", preset="smoke", seeds=[7], config=cfg, out=None))
    printed = "remidi: warning: seed 7: in updates 1–150 the agent trained on nothing" in capsys.readouterr().err
    assert printed == (process == 0)
    assert result.extra["stalled_updates"] == {"7": [[1, 150]]}  # summary.json keeps it, for every process


# ------------------------------------------------------------------ a learned tracker that cannot separate
def test_a_learned_tracker_whose_audit_explains_nearly_everything_is_reported():
    """The last audit's numbers of the results page's runs (docs/results/data, per seed): the
    T-maze belief runs (explained 1.00 and 0.91, agreement with the exact tracker 0.53 and 0.59)
    and blindfold-noisy's (0.94, agreement 0.06) cannot separate the adversaries; the lever-noisy
    belief runs (0.44, agreement 0.56), the simulated model's T-maze runs (0.54, agreement 1.00) and
    a deterministic task whose fresh levels almost all overlap (0.95 explained, agreement 0.97)
    can. A seed with no audit yet (NaN: nothing frozen) says nothing."""
    final = {"belief/explained": np.array([1.0, 0.91, 0.94, 0.44, 0.54, 0.95, NAN]),
             "belief/agreement": np.array([0.53, 0.59, 0.06, 0.56, 1.0, 0.97, NAN])}
    line = ued.separation_warning([10, 11, 12, 13, 14, 15, 16], final)
    assert line.startswith("the learned tracker cannot separate the adversaries: ")
    assert "1.00 on seed 10, 0.91 on seed 11, 0.94 on seed 12 of the steps" in line
    assert all(f"seed {s}" not in line for s in (13, 14, 15, 16)) and "\n" not in line
    quiet = {k: v[3:] for k, v in final.items()}
    assert ued.separation_warning([13, 14, 15, 16], quiet) is None
    assert ued.separation_warning([0], {"solve_rate/visible": np.array([0.5])}) is None  # no learned tracker


@pytest.mark.parametrize("explained, warned", [(0.97, True), (0.45, False)])
def test_training_prints_the_separation_warning_once_the_run_ends(monkeypatch, capsys, explained, warned):
    from remidi.engine.run.driver import TrainResult

    def fake_train_seeds(task, cfg, algo, seeds, *, on_block=None, **kwargs):
        history = {"belief/explained": np.array([[NAN, explained]]), "belief/agreement": np.array([[NAN, 0.5]])}
        return TrainResult(np.array([BLOCK, 2 * BLOCK]), history, {"replay": np.zeros((1, 2 * BLOCK))}, None, [])

    monkeypatch.setattr(ued, "train_seeds", fake_train_seeds)
    monkeypatch.setattr(ued, "run_warnings", lambda *args: [])
    monkeypatch.setattr(ued, "tracker_cost_note", lambda *args: None)
    cfg = UEDConfig(num_envs=ENVS, eval_every=BLOCK, num_updates=2 * BLOCK)
    ued.make_train(lambda c: None, ())(RunContext(experiment="x", algo="remidi", preset="smoke", seeds=[3],
                                                  config=cfg, out=None))
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "cannot separate" in line]
    assert lines == ([f"remidi: warning: the learned tracker cannot separate the adversaries: at the last audit its "
                      f"frozen models explain {explained:.2f} on seed 3 of the steps of fresh generator levels "
                      f"(belief/explained; the exact tracker judges 0.50 of them alike), so a later adversary's "
                      f"levels are rejected or masked as an earlier one's whatever they hold (docs/belief.md, \"The "
                      f"learned belief tracker\")"] if warned else [])
