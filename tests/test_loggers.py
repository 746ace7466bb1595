"""`remidi run --log wandb,tensorboard`, fully offline: what each backend receives, a resumed run
continuing the same tracked run without logging a step twice, and one-line errors when a package
is missing (before anything is written)."""

import glob
import importlib.util
import json
import struct

import numpy as np
import pytest
from test_cli import LEVER_TINY

from remidi.cli import main
from remidi import loggers


def tensorboard_steps(logdir) -> dict[str, list[int]]:
    """tag → steps, read from every event file in ``logdir`` (TFRecord framing, Event protos)."""
    from tensorboardX.proto import event_pb2

    tags: dict[str, list[int]] = {}
    for path in sorted(glob.glob(f"{logdir}/events.out.tfevents.*")):
        data, i = open(path, "rb").read(), 0
        while i < len(data):
            (n,) = struct.unpack("<Q", data[i:i + 8])
            event = event_pb2.Event()
            event.ParseFromString(data[i + 12:i + 12 + n])
            i += 12 + n + 4
            for value in event.summary.value:
                tags.setdefault(value.tag, []).append(event.step)
    return {tag: sorted(steps) for tag, steps in tags.items()}  # each part of a resumed run has a file of its own


def wandb_bytes(folder, run_id) -> bytes:
    """Every offline W&B transaction log of run ``run_id`` under ``folder/wandb``, concatenated."""
    return b"".join(open(p, "rb").read() for p in sorted(glob.glob(f"{folder}/wandb/offline-run-*/run-{run_id}.wandb")))


@pytest.fixture
def offline(monkeypatch):
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_SILENT", "true")


def test_both_loggers_offline_and_a_resume_continues_the_same_runs(tmp_path, capsys, offline, monkeypatch):
    from remidi.experiments import ued

    out = tmp_path / "run"
    argv = ["run", "lever", "--algo", "plr", "--seeds", "2", "--quiet", *LEVER_TINY, "--out", str(out),
            "--log", "wandb,tensorboard"]
    real = ued.train_seeds

    def stop_after_20(*args, on_block=None, **kwargs):
        def block(done, metrics):
            on_block(done, metrics)
            if done == 20:
                raise KeyboardInterrupt
        return real(*args, **kwargs, on_block=block)

    monkeypatch.setattr(ued, "train_seeds", stop_after_20)
    assert main(argv) == 130
    monkeypatch.setattr(ued, "train_seeds", real)
    state = json.loads((out / "tracking.json").read_text())
    assert state["last_step"] == 20 and not state.get("finished")
    assert json.loads((out / "config.json").read_text())["log"] == ["wandb", "tensorboard"]
    capsys.readouterr()
    assert main(["run", "--resume", str(out), "--quiet"]) == 0
    state = json.loads((out / "tracking.json").read_text())
    assert state["last_step"] == 40 and state["finished"]
    # TensorBoard: per seed, every metric of metrics.csv at every step exactly once, across both parts
    for seed in (0, 1):
        tags = tensorboard_steps(out / "tensorboard" / f"seed_{seed}")
        assert tags["solve_rate/visible"] == [10, 20, 30, 40] and tags["replay"] == [10, 20, 30, 40]
        assert any(tag.startswith("config") for tag in tags) and any(tag.startswith("summary") for tag in tags)
    assert "plots/training" in tensorboard_steps(out / "tensorboard" / "seed_0")
    # W&B: one run (the same id before and after the resume), per-seed metrics, config, summary, plots
    logged = wandb_bytes(out, state["wandb_id"])
    assert len(glob.glob(f"{out}/wandb/offline-run-*/run-{state['wandb_id']}.wandb")) == 2  # two parts, one id
    for needle in (b"seed_0/solve_rate/visible", b"seed_1/regret/hidden/worst", b"topk_k", b"final/solve_rate/visible"):
        assert needle in logged, needle
    assert glob.glob(f"{out}/wandb/offline-run-*/files/media/images/plots/training*.png")
    with open(out / "metrics.csv") as fh:
        metrics = {line.split(",")[2] for line in list(fh)[1:]}
    assert all(f"seed_0/{m}".encode() in logged for m in metrics if m != "replay_fraction/hidden")


def test_missing_package_or_login_is_one_line_before_writing(tmp_path, capsys, monkeypatch):
    find = importlib.util.find_spec
    monkeypatch.setattr(loggers.importlib.util, "find_spec", lambda name: None if name == "wandb" else find(name))
    out = tmp_path / "never"
    assert main(["run", "lever", "--log", "wandb", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and 'wandb needs the wandb package: pip install "remidi[wandb]"' in err
    assert not out.exists()
    monkeypatch.setattr(loggers.importlib.util, "find_spec", find)
    monkeypatch.delenv("WANDB_MODE", raising=False)
    monkeypatch.delenv("WANDB_API_KEY", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))  # no ~/.netrc
    assert main(["run", "lever", "--log", "wandb", "--out", str(out)]) == 2
    assert "WANDB_MODE=offline" in capsys.readouterr().err and not out.exists()
    for text, needle in (("mlflow", f"--log: unknown value 'mlflow'; allowed: {', '.join(loggers.BACKENDS)}"),
                         ("wandb,", "has an empty name")):
        assert main(["run", "lever", "--log", text, "--out", str(out)]) == 2
        assert needle in capsys.readouterr().err and not out.exists()


def test_a_part_resumed_within_the_same_second_keeps_the_parts_before(tmp_path):
    """tensorboardX names event files by the second: without a suffix of its own, a resume opened
    in the same second as the part before overwrote that part's file (steps 10, 20 lost)."""
    from remidi.loggers import RunLogger

    for steps in ((10, 20), (30, 40)):  # two parts, well within one second
        run_logger = RunLogger(["tensorboard"], tmp_path, "run", {"config": {}}, [0])
        for step in steps:
            run_logger.log(step, {"loss": np.array([1.0])})
        run_logger.close()
    assert tensorboard_steps(tmp_path / "tensorboard" / "seed_0")["loss"] == [10, 20, 30, 40]
