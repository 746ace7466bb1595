"""The warning for a ReMiDi seed that trains on nothing: a frozen adversary explains every level the
block played and nothing was replayed (seed 1 of the results page's T-maze belief runs, whose
learned model explained every fresh level after the first buffer, trained on nothing for 1350
updates without a word). Pure functions over the driver's block metrics, and their wiring into
the UED experiments' training (the driver mocked: no program is compiled)."""

from __future__ import annotations

import numpy as np

from remidi.engine.config import UEDConfig
from remidi.experiments import ued
from remidi.experiments.base import RunContext

# one block of 150 updates of 32 envs, two seeds, as the T-maze belief run logged them (update 300)
ENVS, BLOCK = 32, 150
STALLED = {"rejected": np.array([4800.0, 4709.0]), "inserted": np.array([0.0, 91.0]),
           "replay": np.array([0.0, 0.0])}


def test_a_block_whose_every_level_was_explained_and_nothing_replayed_is_stalled():
    assert ued.stalled_seeds(STALLED, ENVS, BLOCK).tolist() == [True, False]  # 91 levels got in: it trains later
    replayed = {**STALLED, "replay": np.array([0.01, 0.0])}  # one update replayed: it trained
    assert ued.stalled_seeds(replayed, ENVS, BLOCK).tolist() == [False, False]
    rehearsed = {**STALLED, "rehearsal": np.array([0.1, 0.0])}  # remidi.rehearsal trained on a frozen buffer
    assert ued.stalled_seeds(rehearsed, ENVS, BLOCK).tolist() == [False, False]
    # PLR⊥ (no tracker: nothing is ever rejected) before its buffer fills replays nothing either
    assert ued.stalled_seeds({**STALLED, "rejected": np.zeros(2)}, ENVS, BLOCK).tolist() == [False, False]
    assert ued.stalled_seeds({"mean_return": np.zeros(2)}, ENVS, BLOCK).size == 0  # DR's, PAIRED's metrics


def test_the_warning_names_the_seed_and_updates_once_and_the_trackers_cause():
    check = ued.stall_warner([3, 4], "belief", ENVS, BLOCK)
    (line,) = check(300, STALLED)  # the first block of this invocation: a resume from update 150
    assert line.startswith("seed 3: in updates 151–300 a frozen adversary explained every level played and none "
                           "was replayed, so the agent trained on nothing: with remidi.tracker=belief"), line
    assert check(450, STALLED) == []  # once per seed
    assert check(600, {**STALLED, "rejected": np.array([4800.0, 4800.0])}) == [
        line.replace("seed 3", "seed 4").replace("151–300", "451–600")]
    last = ued.stall_warner([0], "prefix", ENVS, BLOCK)(1000, {k: v[:1] for k, v in STALLED.items()})
    assert "in updates 901–1000" in last[0] and "the frozen buffers explain every level drawn" in last[0]


def test_training_prints_it(monkeypatch, capsys):
    """make_train's block callback prints the warning whatever the experiment tracking."""
    from remidi.engine.driver import TrainResult

    def fake_train_seeds(task, cfg, algo, seeds, *, on_block=None, **kwargs):
        on_block(BLOCK, {k: v[:1] for k, v in STALLED.items()})
        history = {k: v[:1, None] for k, v in STALLED.items()}
        return TrainResult(np.array([BLOCK]), history, {"replay": np.zeros((1, BLOCK))}, None, [])

    monkeypatch.setattr(ued, "train_seeds", fake_train_seeds)
    monkeypatch.setattr(ued, "run_warnings", lambda *args: [])
    cfg = UEDConfig(num_envs=ENVS, eval_every=BLOCK, num_updates=BLOCK)
    train = ued.make_train(lambda c: None, ())
    train(RunContext(experiment="x", algo="remidi", preset="smoke", seeds=[7], config=cfg, out=None))
    assert "remidi: warning: seed 7: in updates 1–150 a frozen adversary explained every level" in capsys.readouterr().err
