"""The warning for a ReMiDi seed that trains on nothing because a frozen adversary explains the
levels it plays (seed 1 of the results page's T-maze belief runs: its learned model explained
almost every fresh level after the first buffer, its active buffer never reached the replay
minimum, and it trained on nothing for 1350 updates without a word). Pure functions over the
driver's block metrics, and their wiring into the UED experiments' training (the driver mocked:
no program is compiled)."""

from __future__ import annotations

import numpy as np

from remidi.engine.config import UEDConfig
from remidi.experiments import ued
from remidi.experiments.base import RunContext

# one block of 150 updates of 32 envs, three seeds; as every algorithm logs them (DR's and
# PLR⊥'s `rejected` is 0: nothing is frozen)
ENVS, BLOCK = 32, 150
BLOCK_METRICS = {"rejected": np.array([4800.0, 4709.0, 0.0]), "inserted": np.array([0.0, 91.0, 5.0]),
                 "replay": np.array([0.0, 0.0, 0.0])}


def test_a_replay_algorithm_that_replayed_nothing_while_levels_were_rejected_is_stalled():
    # seed 0: every level explained; seed 1: some got in, too few to replay (blindfold-noisy's
    # belief seeds in their second block); seed 2: PLR⊥ filling its buffer (nothing frozen)
    assert ued.stalled_seeds(BLOCK_METRICS, ENVS, BLOCK, trains_on_fresh=False).tolist() == [True, True, False]
    replayed = {**BLOCK_METRICS, "replay": np.array([0.01, 0.0, 0.0])}  # one update replayed: it trained
    assert ued.stalled_seeds(replayed, ENVS, BLOCK, False).tolist() == [False, True, False]
    rehearsed = {**BLOCK_METRICS, "rehearsal": np.array([0.1, 0.0, 0.0])}  # remidi.rehearsal trained on a frozen buffer
    assert ued.stalled_seeds(rehearsed, ENVS, BLOCK, False).tolist() == [False, True, False]


def test_an_algorithm_that_trains_on_every_rollout_is_stalled_only_when_every_level_was_masked():
    assert ued.stalled_seeds(BLOCK_METRICS, ENVS, BLOCK, trains_on_fresh=True).tolist() == [True, False, False]
    # a short last block (updates 901–1000 of 1000): every level of its 100 updates
    last = {k: v[:1] for k, v in BLOCK_METRICS.items()} | {"rejected": np.array([ENVS * 100.0])}
    assert ued.stall_warner([0], "prefix", ENVS, BLOCK, trains_on_fresh=True)(1000, last)


def test_the_warning_names_the_seed_updates_and_counts_once_and_the_belief_hint():
    check = ued.stall_warner([3, 4, 5], "belief", ENVS, BLOCK, trains_on_fresh=False)
    first, second = check(300, BLOCK_METRICS)  # the first block of this invocation: a resume from update 150
    assert first.startswith("seed 3: in updates 151–300 the agent trained on nothing: a frozen adversary explained "
                            "4800 of the 4800 levels played, 0 entered the active buffer and none was replayed; "
                            "with remidi.tracker=belief the frozen models may explain too much"), first
    assert second.startswith("seed 4: in updates 151–300 the agent trained on nothing: a frozen adversary explained "
                             "4709 of the 4800 levels played, 91 entered"), second
    assert check(450, BLOCK_METRICS) == []  # once per seed
    exact = ued.stall_warner([0], "prefix", ENVS, BLOCK, False)(150, {k: v[:1] for k, v in BLOCK_METRICS.items()})
    assert exact[0].endswith("none was replayed") and "updates 1–150" in exact[0]


def test_training_prints_it(monkeypatch, capsys):
    """make_train's block callback prints the warning whatever the experiment tracking."""
    from remidi.engine.driver import TrainResult

    def fake_train_seeds(task, cfg, algo, seeds, *, on_block=None, **kwargs):
        metrics = {k: v[:1] for k, v in BLOCK_METRICS.items()}
        on_block(BLOCK, metrics)
        return TrainResult(np.array([BLOCK]), {k: v[:, None] for k, v in metrics.items()},
                           {"replay": np.zeros((1, BLOCK))}, None, [])

    monkeypatch.setattr(ued, "train_seeds", fake_train_seeds)
    monkeypatch.setattr(ued, "run_warnings", lambda *args: [])
    cfg = UEDConfig(num_envs=ENVS, eval_every=BLOCK, num_updates=BLOCK)
    train = ued.make_train(lambda c: None, ())
    train(RunContext(experiment="x", algo="remidi", preset="smoke", seeds=[7], config=cfg, out=None))
    assert "remidi: warning: seed 7: in updates 1–150 the agent trained on nothing" in capsys.readouterr().err
