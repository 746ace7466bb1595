"""`remidi run --resume` on a damaged or mismatched run folder: one line naming the file and what
is wrong, exit 2, and nothing in the folder changed (never a traceback from numpy, zipfile, json
or flax)."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from remidi.cli import main
from test_cli import LEVER_TINY


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A checkpointed lever run (remidi, 2 seeds) and another run's (plr) checkpoint; both the
    configurations other tests compile, so their programs come from the compilation cache."""
    root = tmp_path_factory.mktemp("resume")
    for algo in ("remidi", "plr"):
        assert main(["run", "lever", "--algo", algo, "--seeds", "2", "--quiet", *LEVER_TINY,
                     "--out", str(root / algo)]) == 0
    return root


def _edit_config(key, value):
    def edit(folder):
        path = folder / "config.json"
        doc = json.loads(path.read_text())
        target = doc
        *parents, last = key.split(".")
        for part in parents:
            target = target[part]
        target[last] = value
        path.write_text(json.dumps(doc))
    return edit


def _truncate(name, keep=0.5):
    def edit(folder):
        data = (folder / name).read_bytes()
        (folder / name).write_bytes(data[:int(len(data) * keep)])
    return edit


def _positional(folder):
    """The checkpoint as remidi wrote it before arrays were named by tree path: leaf_0, leaf_1, ..."""
    path = folder / "checkpoint.npz"
    with np.load(path) as data:
        arrays = [data[name] for name in data.files if name != "meta"]
        meta = data["meta"]
    np.savez(path, meta=meta, **{f"leaf_{i}": a for i, a in enumerate(arrays)})


def _flip(folder):
    path = folder / "checkpoint.npz"
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x10
    path.write_bytes(bytes(data))


def _older_history(folder):
    """checkpoint.history.npz of an earlier checkpoint (the first block only) beside the last
    checkpoint.npz: what copying a folder while its run trains can give (the history sorts first)."""
    path = folder / "checkpoint.history.npz"
    with np.load(path) as saved:
        first = {key: saved[key] for key in saved.files if key.split("|")[0] in ("h0", "p0")}
    np.savez(path, **first)


DAMAGE = {
    "truncated config.json": (_truncate("config.json"), "config.json is not a readable run config"),
    "truncated checkpoint": (_truncate("checkpoint.npz"), "checkpoint.npz cannot be read"),
    "empty checkpoint": (_truncate("checkpoint.npz", 0.0), "checkpoint.npz cannot be read"),
    "random checkpoint": (lambda f: (f / "checkpoint.npz").write_bytes(bytes(range(256)) * 64),
                          "checkpoint.npz cannot be read"),
    "bit-flipped checkpoint": (_flip, "checkpoint.npz cannot be read"),
    "missing history": (lambda f: (f / "checkpoint.history.npz").unlink(), "checkpoint.history.npz is missing"),
    "another run's checkpoint": (None, "checkpoint.npz does not match the run's config.json"),
    "hidden_size edited": (_edit_config("config.hidden_size", 32),
                           "does not match the run's config.json (.learner.train_state."),
    "an older remidi's checkpoint": (_positional, "was written by an older remidi, which stored the state's arrays "
                                                  "by position"),
    "seeds edited": (_edit_config("seeds", [0, 1, 2]), "does not match the run's config.json"),
    "algo edited": (_edit_config("algo", "plr"), "does not match the run's config.json"),
    "config.json not an object": (lambda f: (f / "config.json").write_text("[1, 2]"),
                                  "config.json is not a readable run config"),
    # edits the state's shapes do not show: before, each resumed silently and the files misstated the run
    "seeds relabelled": (_edit_config("seeds", [5, 6]), "does not match the run's config.json (seeds: [5, 6] there"),
    "learning rate edited": (_edit_config("config.ppo.lr", 0.5), "(config.ppo.lr: 0.5 there"),
    "num_updates below the checkpoint": (_edit_config("config.num_updates", 10), "(config.num_updates: 10 there"),
    "history older than the checkpoint": (_older_history, "checkpoint.history.npz holds the metrics of 1 of the 4 blocks"),
}


@pytest.mark.parametrize("case", list(DAMAGE))
def test_resume_of_a_damaged_run_is_one_line_and_changes_nothing(runs, tmp_path, capsys, case):
    folder = tmp_path / "run"
    shutil.copytree(runs / "remidi", folder)
    (folder / "summary.json").unlink()  # unfinished (killed after its last checkpoint): a finished run is not resumed
    damage, needle = DAMAGE[case]
    if damage is None:
        shutil.copy(runs / "plr" / "checkpoint.npz", folder / "checkpoint.npz")
    else:
        damage(folder)
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    capsys.readouterr()
    assert main(["run", "--resume", str(folder), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("remidi: error: --resume: ") and err.count("\n") == 1, err
    assert needle in err and str(folder) in err, err
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before


@pytest.mark.parametrize("text", ['{"experiment": "lever"', "[1, 2]"])
def test_resume_of_a_finished_run_with_a_damaged_summary_is_one_line(runs, tmp_path, capsys, text):
    """A finished run's summary.json is read back by --resume: damaged, one line that says how to
    write it again (before: a JSONDecodeError traceback)."""
    folder = tmp_path / "run"
    shutil.copytree(runs / "remidi", folder)
    (folder / "summary.json").write_text(text)
    capsys.readouterr()
    assert main(["run", "--resume", str(folder), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"remidi: error: --resume: {folder / 'summary.json'}") and err.count("\n") == 1, err
    assert "delete it, and --resume writes the run's outputs again" in err


def test_resume_of_a_folder_it_cannot_write_is_one_line_before_training(runs, tmp_path, capsys, monkeypatch):
    """A read-only run folder (its probe made to fail: no permission stops root's writes;
    test_evaluate tests files.writable on a real read-only folder): refused at once, before
    compiling; a finished run there is still read."""
    from remidi.experiments import resuming

    folder = tmp_path / "run"
    shutil.copytree(runs / "remidi", folder)
    monkeypatch.setattr(resuming, "writable", lambda path: Path(path) != folder)
    capsys.readouterr()
    assert main(["run", "--resume", str(folder), "--quiet"]) == 0  # finished: nothing to write
    (folder / "summary.json").unlink()
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    assert main(["run", "--resume", str(folder), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err == f"remidi: error: --resume: {folder} is not writable: the resumed run could not write its " \
                  f"checkpoints and results; resume a writable copy of it\n"
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before


def test_a_run_folder_another_process_writes_is_refused(runs, tmp_path, capsys):
    """While one process writes a run (its folder locked: flock on the folder, which conflicts
    across open descriptions as across processes), a --resume of it or a new run into it is one
    line, exit 2, and changes nothing; before, the second deleted the first's checkpoint
    temporaries (the first then failed) and their checkpoints could interleave."""
    from remidi.experiments.outputs import folder_lock

    folder = tmp_path / "run"
    shutil.copytree(runs / "remidi", folder)
    (folder / "summary.json").unlink()
    (folder / ".checkpoint.npz.inflight.tmp").write_bytes(b"the other process's write")
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    empty = tmp_path / "empty"
    empty.mkdir()
    capsys.readouterr()
    with folder_lock(folder, "--resume"), folder_lock(empty, "--out"):
        assert main(["run", "--resume", str(folder), "--quiet"]) == 2
        assert capsys.readouterr().err == (f"remidi: error: --resume: {folder} is in use by another remidi process "
                                           f"(a run writing there); wait for it to end, or write elsewhere\n")
        assert main(["run", "lever", "--algo", "remidi", "--seeds", "2", "--quiet", *LEVER_TINY,
                     "--out", str(empty)]) == 2
        assert f"--out: {empty} is in use by another remidi process" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before and not any(empty.iterdir())


def test_one_algorithm_of_a_several_algorithm_run_is_locked_with_the_whole_run(runs, tmp_path, capsys):
    """A resume of OUT/remidi while another process writes OUT (a run or resume of the whole
    several-algorithm run, which locks OUT) is refused too."""
    from remidi.experiments.outputs import folder_lock

    whole = tmp_path / "both"
    for algo in ("plr", "remidi"):
        shutil.copytree(runs / algo, whole / algo)
        _edit_config("algos", ["plr", "remidi"])(whole / algo)
    (whole / "remidi" / "summary.json").unlink()
    capsys.readouterr()
    with folder_lock(whole, "--resume"):
        assert main(["run", "--resume", str(whole / "remidi"), "--quiet"]) == 2
    assert f"--resume: {whole} is in use by another remidi process" in capsys.readouterr().err


def test_history_blocks_may_log_more_metrics_than_the_first(tmp_path):
    """Blocks trained by a version of remidi that added a metric log more than the earlier ones:
    read as they are; a block without one of block 0's metrics is a damaged file."""
    from remidi.engine.run.checkpoint import load_history
    from remidi.errors import ConfigError

    path = tmp_path / "checkpoint.history.npz"
    meta = {"done": 20, "steps": [10, 20], "num_blocks": 2}
    np.savez(path, **{"h0|a": np.zeros(2), "h1|a": np.ones(2), "h1|b": np.ones(2), "p0|r": np.zeros(2),
                      "p1|r": np.zeros(2)})
    history, _ = load_history(path, meta)
    assert [sorted(h) for h in history] == [["a"], ["a", "b"]]
    np.savez(path, **{"h0|a": np.zeros(2), "h0|b": np.zeros(2), "h1|a": np.ones(2), "p0|r": np.zeros(2),
                      "p1|r": np.zeros(2)})
    with pytest.raises(ConfigError, match="is damaged: block 1 lacks b"):
        load_history(path, meta)


def test_a_checkpoint_records_a_config_given_with_numpy_values(tmp_path):
    """Through the Python API a config may hold NumPy scalars: the checkpoint's record of the run
    takes them (before, json.dumps raised a TypeError at the first checkpoint)."""
    from remidi.engine.run.checkpoint import check_run, load_checkpoint, save_run

    run = {"algo": "plr", "seeds": [0], "config": {"ppo": {"lr": np.float32(3e-4)}, "shape": np.arange(2)}}
    save_run(tmp_path / "checkpoint.npz", {"w": np.zeros(2)}, 10, [10], [{"m": np.zeros(1)}], [{"r": np.zeros(1)}],
             run=run)
    _, meta = load_checkpoint(tmp_path / "checkpoint.npz", {"w": np.zeros(2)})
    assert meta["run"]["config"]["shape"] == [0, 1]
    check_run(tmp_path / "checkpoint.npz", meta, run)  # the same run: no error


def test_resume_removes_the_temporaries_a_killed_checkpoint_write_left(runs, tmp_path, capsys):
    """SIGKILL during an atomic checkpoint write leaves ``.checkpoint.npz.<random>.tmp``: the next
    resume deletes those (and only those) before it writes."""
    folder = tmp_path / "run"
    shutil.copytree(runs / "remidi", folder)
    (folder / "summary.json").unlink()  # unfinished (killed after its last checkpoint): a finished run is not resumed
    stale = [folder / ".checkpoint.npz.k1ll3d.tmp", folder / ".checkpoint.history.npz.x9.tmp",
             # and the outputs' (Ctrl-C exits at once, before a write renames or removes its temporary)
             folder / ".metrics.csv.a1b2.tmp", folder / ".summary.json.q.tmp", folder / ".training.png.4242.tmp.png"]
    for path in stale:
        path.write_bytes(b"\0" * 4096)
    (folder / ".notes.tmp").write_text("mine")
    assert main(["run", "--resume", str(folder), "--quiet"]) == 0
    assert not any(path.exists() for path in stale)
    assert (folder / ".notes.tmp").read_text() == "mine"
    # the checkpoint was the last update: this resume trained nothing and adds no part (before: [40, 40])
    parts = json.loads((folder / "summary.json").read_text())["parts"]
    assert [part["updates"] for part in parts] == [[0, 40]]
