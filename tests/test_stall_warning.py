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
                     "(README, \"The learned belief tracker\")"), first
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
    monkeypatch.setattr(ued.jax, "process_index", lambda: process)
    cfg = UEDConfig(num_envs=ENVS, eval_every=BLOCK, num_updates=BLOCK)
    train = ued.make_train(lambda c: None, ())
    result = train(RunContext(experiment="x", algo="remidi", preset="smoke", seeds=[7], config=cfg, out=None))
    printed = "remidi: warning: seed 7: in updates 1–150 the agent trained on nothing" in capsys.readouterr().err
    assert printed == (process == 0)
    assert result.extra["stalled_updates"] == {"7": [[1, 150]]}  # summary.json keeps it, for every process
