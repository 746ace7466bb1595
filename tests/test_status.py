"""`remidi status`: where runs stand, read from their folders (hand-written run folders: no
training, no compiling)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from remidi.cli import main
from remidi.engine.run.checkpoint import CHECKPOINT, save_run
from remidi.errors import ConfigError
from remidi.runs.status import run_folders, run_status

NAN = float("nan")


def _config(folder, seeds=(0, 1), num_updates=1500):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "config.json").write_text(json.dumps({"experiment": "tmaze", "algo": "remidi", "preset": "cpu",
                                                    "seeds": list(seeds), "config": {"num_updates": num_updates}}))
    return folder


def _unfinished(folder, seeds=(0, 1), parts=None, **meta):
    """Two blocks of 150 updates trained on a CPU in 600 s; the second seed trained on nothing in the
    second block while every level it played was explained (4800 of 32 × 150)."""
    _config(folder, seeds)
    history = [{"rejected": np.array([0.0, 0.0]), "ppo/policy_loss": np.array([0.1, 0.2])},
               {"rejected": np.array([100.0, 4800.0]), "ppo/policy_loss": np.array([0.1, NAN])}]
    per_step = [{"replay": np.zeros((2, 150))}] * 2
    parts = [{"updates": [0, 300], "wall_s": 600.0, "code": {"device": "cpu: test"}}] if parts is None else parts
    save_run(folder / CHECKPOINT, {"x": np.zeros(2)}, 300, [150, 300], history, per_step, parts or None)
    return folder


def test_an_unfinished_run_shows_its_checkpoint_parts_time_left_and_stalled_seeds(tmp_path):
    folder = _unfinished(tmp_path / "run")
    os.utime(folder / CHECKPOINT, (1000.0, 1000.0))
    lines = run_status(folder, now=1000.0 + 600)
    assert lines == [
        f"{folder}: remidi on tmaze, preset cpu, seeds 0–1",
        f"  checkpoint at update 300 of 1500 (20 %), written 10 min ago (remidi run --resume {folder} continues it)",
        "  part 0–300 on cpu: test, 2.0 s/update with compiling",
        "  left: 1200 updates, about 40 min at the last part's rate (with its compiling: an overestimate; on cpu: "
        "test; a resume compiles first)",
        "  stalled (trained on nothing while a frozen adversary rejected levels): seed 1 updates 151–300",
    ]


def test_the_time_left_leaves_compiling_out_and_a_fresh_checkpoint_is_seconds_old(tmp_path):
    """A part that timed its blocks after the first (driver.PartClock: 90 s of compiling, then 3
    blocks of 100 updates in 6 s) gives the rate after compiling, 0.02 s/update: 1200 updates
    left take about 24 s, not the 6 min its whole wall time per update would say; a checkpoint
    written 5 s ago says so (not "1 min")."""
    parts = [{"updates": [0, 400], "wall_s": 96.0, "train_s": 6.0, "train_updates": 300, "code": {"device": "cpu: t"}}]
    folder = _unfinished(tmp_path / "run", parts=parts)
    os.utime(folder / CHECKPOINT, (1000.0, 1000.0))
    lines = run_status(folder, now=1005.0)
    assert lines[1].endswith("written 5 s ago (remidi run --resume " + f"{folder} continues it)")
    assert lines[2] == "  part 0–400 on cpu: t, 0.02 s/update after compiling (2 min in all)"
    assert lines[3] == ("  left: 1200 updates, about 24 s at the last part's rate (after compiling; on cpu: t; a "
                        "resume compiles first)")


def test_parts_rates_from_the_last_part_and_seeds_that_are_not_a_range(tmp_path):
    parts = [{"updates": [0, 150], "wall_s": 3000.0, "code": None},  # an older part: device unknown
             {"updates": [150, 300], "wall_s": 1500.0, "code": {"device": "gpu: H100"}}]
    lines = run_status(_unfinished(tmp_path / "run", seeds=(2, 5), parts=parts))
    assert lines[0].endswith("preset cpu, seeds 2, 5")
    assert lines[2:5] == ["  part 0–150 on device not recorded, 20.0 s/update with compiling",
                          "  part 150–300 on gpu: H100, 10.0 s/update with compiling",
                          "  left: 1200 updates, about 3 h 20 min at the last part's rate (with its compiling: an "
                          "overestimate; on gpu: H100; a resume compiles first)"]
    assert lines[5].endswith("seed 5 updates 151–300")
    older = run_status(_unfinished(tmp_path / "old", parts=[]))  # a checkpoint from before parts were recorded
    assert older[2].startswith("  stalled") and len(older) == 3
    no_time = [{"updates": [0, 300], "code": None}]  # no wall time: no rate, no time left
    assert run_status(_unfinished(tmp_path / "no-time", parts=no_time))[2:4] == [
        "  part 0–300 on device not recorded", "  stalled (trained on nothing while a frozen adversary rejected "
                                               "levels): seed 1 updates 151–300"]


@pytest.mark.parametrize("damage", ["truncated", "npy", "meta-list", "no-done"])
def test_a_damaged_checkpoint_is_one_line(tmp_path, capsys, damage):
    folder = _unfinished(tmp_path / "run")
    ckpt = folder / CHECKPOINT
    if damage == "truncated":
        ckpt.write_bytes(ckpt.read_bytes()[:40])
    elif damage == "npy":
        with open(ckpt, "wb") as fh:
            np.save(fh, np.zeros(3))
    else:
        with open(ckpt, "wb") as fh:
            np.savez(fh, meta=np.asarray("[1]" if damage == "meta-list" else '{"steps": [150]}'))
    assert main(["status", str(folder)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"remidi: error: RUN_DIR: {ckpt} cannot be read (") and err.count("\n") == 1, err


def test_a_hand_edited_config_is_one_line(tmp_path, capsys):
    folder = _config(tmp_path / "run")
    (folder / "config.json").write_text(json.dumps({"algo": "remidi", "seeds": None, "config": "x"}))
    assert main(["status", str(folder)]) == 2
    assert "is not as remidi run writes it" in capsys.readouterr().err


def test_a_checkpoint_without_its_metrics_still_shows_where_it_stands(tmp_path):
    folder = _unfinished(tmp_path / "run")
    (folder / "checkpoint.history.npz").unlink()
    lines = run_status(folder)
    assert lines[1].startswith("  checkpoint at update 300 of 1500 (20 %)")
    assert lines[-1] == f"  stalled: unknown ({folder / 'checkpoint.history.npz'} is missing (the metrics logged " \
                        f"before the checkpoint))"


def test_a_finished_run_says_whether_it_was_evaluated(tmp_path):
    folder = _config(tmp_path / "run", seeds=(3,))
    (folder / CHECKPOINT).write_bytes(b"")  # a UED run keeps its checkpoint (remidi evaluate reads it)
    (folder / "summary.json").write_text(json.dumps({
        "parts": [{"updates": [0, 750], "wall_s": 450.0, "code": {"device": "gpu: H100"}},
                  {"updates": [750, 1500], "wall_s": 7500.0, "code": None}],
        "stalled_updates": {"3": [[151, 1500]]}}))
    assert run_status(folder) == [
        f"{folder}: remidi on tmaze, preset cpu, seed 3",
        f"  finished (1500 updates), not evaluated (remidi evaluate {folder})",
        "  part 0–750 on gpu: H100, 0.6 s/update with compiling",
        "  part 750–1500 on device not recorded, 10.0 s/update with compiling",
        "  stalled (trained on nothing while a frozen adversary rejected levels): seed 3 updates 151–1500"]
    (folder / "evaluate.json").write_text("{}")
    assert run_status(folder)[1] == "  finished (1500 updates), evaluated"
    (folder / CHECKPOINT).unlink()  # the tabular games: no checkpoint, nothing to evaluate
    assert run_status(folder)[1] == "  finished (1500 updates)"


def test_folders_of_several_algorithms_no_checkpoint_and_no_run(tmp_path, capsys):
    both = tmp_path / "both"
    _unfinished(both / "plr")
    _config(both / "remidi")
    assert run_folders([both]) == [both / "plr", both / "remidi"]
    assert run_status(both / "remidi")[1] == f"  no checkpoint yet (remidi run --resume {both / 'remidi'} trains it " \
                                              f"from the start)"
    assert main(["status", str(both)]) == 0
    out = capsys.readouterr().out
    assert "checkpoint at update 300 of 1500" in out and "no checkpoint yet" in out
    (tmp_path / "empty").mkdir()
    with pytest.raises(ConfigError, match=r"^RUN_DIR: .*empty holds no run"):
        run_folders([tmp_path / "empty"])
    assert main(["status", str(tmp_path / "empty")]) == 2
    assert "holds no run" in capsys.readouterr().err


def test_a_part_times_the_blocks_after_its_first_of_the_same_length():
    """driver.PartClock: the first block (it compiles) and a block of another length (a short last
    block compiles again) are left out of ``train_s``; a part with one block records no rate."""
    from remidi.engine.run.driver import PartClock

    clock = PartClock(100)
    assert "train_s" not in clock.record(100)
    for length, seconds in ((40, 50.0), (40, 1.0), (40, 1.25), (20, 9.0)):
        clock.block(length, seconds)
    part = clock.record(240)
    assert part["updates"] == [100, 240] and part["train_s"] == 2.25 and part["train_updates"] == 80
    assert part["code"] is not None and part["wall_s"] >= 0
