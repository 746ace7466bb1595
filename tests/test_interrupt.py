"""Ctrl-C at any moment of `remidi run` (start-up, XLA compiling, training) exits cleanly: status
130, one line `remidi: interrupted...`, no traceback, no abort, no half-written file. SIGTERM (a
scheduler's pre-emption notice) checkpoints the block under way and exits 143; the resumed run
ends where an uninterrupted one does."""

import json
import signal
from pathlib import Path
import subprocess
import sys
import time

import pytest
from conftest import subprocess_env
from test_cli import LEVER_TINY

pytestmark = pytest.mark.usefixtures("no_png")  # no test here reads a plot

# the `remidi` program with Python's default Ctrl-C handling (a test runner may start its
# children with SIGINT ignored, and then remidi leaves it ignored)
LAUNCH = ("import runpy, signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
          "sys.argv = ['remidi', *sys.argv[1:]]; runpy.run_module('remidi', run_name='__main__')")


def _started(path):
    return lambda: path.exists()


@pytest.mark.parametrize("when", [
    "start-up",  # 0.5 s in: Python imports JAX (a KeyboardInterrupt there must not be swallowed)
    "compiling",  # just after config.json is written: tracing and compiling the first programs
    pytest.param("training", marks=pytest.mark.slow),  # after the first checkpoint: blocks running
])
def test_ctrl_c_exits_130_with_one_line(tmp_path, when):
    out = tmp_path / "run"
    # ReMiDi on 2 seeds: tests/test_cli.py's programs, from the suite's compilation cache when they are there
    argv = ["run", "lever", "--algo", "remidi", "--seeds", "2", "--quiet", *LEVER_TINY, "--out", str(out)]
    # the suite's compilation cache (tests/conftest.py) for "training" only: faster to the first block
    env = subprocess_env(__name__, cache=when == "training")
    proc = subprocess.Popen([sys.executable, "-c", LAUNCH, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)
    ready = {"start-up": lambda: True, "compiling": _started(out / "config.json"),
             "training": _started(out / "checkpoint.npz")}[when]
    start = time.monotonic()
    time.sleep(0.5)
    while not ready() and proc.poll() is None and time.monotonic() - start < 240:
        time.sleep(0.02)
    assert proc.poll() is None, f"the run ended before the interrupt ({when})"
    proc.send_signal(signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    assert proc.returncode == 130, err
    assert err.startswith("remidi: interrupted") and err.count("\n") == 1, err
    assert "Traceback" not in err and "Exception ignored" not in err
    if when != "start-up":
        assert f"continue with: remidi run --resume {out}" in err
        assert json.loads((out / "config.json").read_text())["algo"] == "remidi"  # complete, never half-written
    if when == "training":
        import numpy as np

        with np.load(out / "checkpoint.npz") as saved:  # the last checkpoint is whole
            assert json.loads(str(saved["meta"]))["done"] >= 10
        assert not (out / "summary.json").exists()


def _tiny(out, *more):
    return ["run", "lever", "--algo", "remidi", "--seeds", "2", "--quiet", *LEVER_TINY, *more, "--out", str(out)]


def _same_results(a, b):
    assert (a / "metrics.csv").read_text() == (b / "metrics.csv").read_text()
    assert json.loads((a / "summary.json").read_text())["metrics"] == json.loads((b / "summary.json").read_text())["metrics"]


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """The uninterrupted run the resumed ones must equal, trained once for this file's tests
    (``checkpoint_every`` only decides when the driver saves: the same programs, the same metrics)."""
    from remidi.cli import main

    out = tmp_path_factory.mktemp("uninterrupted") / "full"
    assert main(_tiny(out)) == 0
    return out


def _checkpoint_done(folder):
    import numpy as np

    with np.load(folder / "checkpoint.npz") as saved:
        return json.loads(str(saved["meta"]))["done"]


def test_sigterm_while_training_checkpoints_the_block_and_exits_143(tmp_path, capsys, monkeypatch, uninterrupted):
    """SIGTERM's request (remidi.preemption, what the command line's handler records) during a
    block: that block is checkpointed although checkpoint_every has not come (update 20 of
    checkpoint_every=40), one line names the update and the resume command, status 143; the
    resumed run's metrics.csv and summary equal the uninterrupted run's."""
    from remidi import preemption
    from remidi.cli import main
    from remidi.experiments import ued

    every = ("--set", "checkpoint_every=40")
    real = ued.train_seeds

    def notified(*args, on_block=None, **kwargs):
        def at(done, metrics):
            if done == 10:  # the signal lands while the next block runs
                preemption.request()
        return real(*args, **kwargs, on_block=at)

    monkeypatch.setattr(ued, "train_seeds", notified)
    capsys.readouterr()
    cut = tmp_path / "cut"
    assert main(_tiny(cut, *every)) == 143
    err = capsys.readouterr().err
    assert err == f"remidi: terminated (SIGTERM), checkpoint of update 20 written; continue with: remidi run --resume {cut}\n"
    assert _checkpoint_done(cut) == 20 and not (cut / "summary.json").exists()
    monkeypatch.setattr(ued, "train_seeds", real)
    assert main(["run", "--resume", str(cut), "--quiet"]) == 0
    _same_results(cut, uninterrupted)


def test_sigterm_while_the_first_block_runs_keeps_that_block(tmp_path, capsys, monkeypatch, uninterrupted):
    """Python runs the SIGTERM handler only when XLA's call returns, so a signal that comes while
    the first block of a run (or of a resumed run) computes is handled as the driver's wait for
    that block returns. The handler must then only record it (request() True: no exit at once)
    and the block is checkpointed: before, the run exited there and lost the block (a resumed
    maze run lost ten minutes of training)."""
    from remidi import preemption
    from remidi.cli import main
    from remidi.engine.run import driver

    real, answers = driver._to_host, []

    def waited(tree):  # the first call waits for the first block: the handler runs as it returns
        out = real(tree)
        if not answers:
            answers.append(preemption.request())
        return out

    monkeypatch.setattr(driver, "_to_host", waited)
    cut = tmp_path / "cut"
    assert main(_tiny(cut, "--set", "checkpoint_every=40")) == 143
    assert answers == [True]
    assert capsys.readouterr().err.startswith("remidi: terminated (SIGTERM), checkpoint of update 10 written")
    assert _checkpoint_done(cut) == 10
    monkeypatch.setattr(driver, "_to_host", real)
    assert main(["run", "--resume", str(cut), "--quiet"]) == 0
    _same_results(cut, uninterrupted)


def test_sigterm_as_an_algorithm_finishes_stops_before_the_next(tmp_path, capsys, monkeypatch):
    """SIGTERM during the last block of the first of two algorithms: that one finishes and writes
    its results, the second does not start (no block, no checkpoint); status 143, and the resume
    trains the second."""
    from remidi import preemption
    from remidi.cli import main
    from remidi.experiments import ued

    real = ued.train_seeds

    def notified(*args, on_block=None, **kwargs):
        def at(done, metrics):
            if done == 40:
                preemption.request()
        return real(*args, **kwargs, on_block=at)

    monkeypatch.setattr(ued, "train_seeds", notified)
    out = tmp_path / "two"
    argv = ["run", "lever", "--algo", "plr,remidi", "--seeds", "2", "--quiet", *LEVER_TINY, "--out", str(out)]
    assert main(argv) == 143
    assert capsys.readouterr().err == f"remidi: terminated (SIGTERM); continue with: remidi run --resume {out}\n"
    assert (out / "plr" / "summary.json").exists() and not (out / "remidi" / "checkpoint.npz").exists()
    monkeypatch.setattr(ued, "train_seeds", real)
    assert main(["run", "--resume", str(out), "--quiet"]) == 0
    assert (out / "remidi" / "summary.json").exists()
    assert capsys.readouterr().err.startswith(f"remidi: note: {out / 'remidi'} has no checkpoint yet")


@pytest.mark.parametrize("algos", ["remidi", "plr,remidi"])
def test_a_run_stopped_while_it_plots_is_plotted_when_resumed(tmp_path, capsys, monkeypatch, algos):
    """Ctrl-C (or SIGTERM, which exits at once after training) while the plots are drawn: the
    last algorithm's summary.json, which marks a run finished, is not written yet, so --resume
    trains nothing more and draws the plots (a several-algorithm run's comparison plots too).
    Before, summary.json came first: the folder kept no plot, and --resume called it finished."""
    from remidi.cli import main
    from remidi.experiments import plots

    out = tmp_path / "run"
    real, drawn, saved = plots._save, [], []  # (this file's plots are not rendered: no_png)

    def stopped(fig, path):  # the first plot of one algorithm's run; a several-algorithm run's comparison
        if not drawn and (algos == "remidi" or Path(path).parent == out):
            drawn.append(path)
            raise KeyboardInterrupt
        saved.append(path)
        real(fig, path)

    monkeypatch.setattr(plots, "_save", stopped)
    argv = ["run", "lever", "--algo", algos, "--seeds", "2", "--quiet", *LEVER_TINY, "--out", str(out)]
    assert main(argv) == 130
    last = out / "remidi" if "," in algos else out
    assert drawn and not (last / "summary.json").exists() and (last / "checkpoint.npz").exists()
    capsys.readouterr()
    assert main(["run", "--resume", str(out), "--quiet"]) == 0
    assert (last / "summary.json").exists() and drawn[0] in saved
    assert main(["run", "--resume", str(out), "--quiet"]) == 0  # now finished
    assert "the run is finished" in capsys.readouterr().out


@pytest.mark.slow
def test_sigterm_to_the_program_then_resume_gives_the_uninterrupted_result(tmp_path, uninterrupted):
    """The real signal: `remidi run` in a subprocess gets SIGTERM once its first checkpoint is
    written; it exits 143 with one line and the resume hint (having checkpointed the block under
    way, or at once if training had ended), and `--resume` finishes it to the uninterrupted result."""
    from remidi.cli import main

    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-c", LAUNCH, *_tiny(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=subprocess_env(__name__))
    start = time.monotonic()
    while not (out / "checkpoint.npz").exists() and proc.poll() is None and time.monotonic() - start < 240:
        time.sleep(0.02)
    assert proc.poll() is None, "the run ended before the signal"
    proc.send_signal(signal.SIGTERM)
    try:
        _, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    assert proc.returncode == 143, err
    assert err.startswith("remidi: terminated (SIGTERM)") and err.count("\n") == 1, err
    assert err.endswith(f"continue with: remidi run --resume {out}\n") and "Traceback" not in err
    if "checkpoint of update" in err:  # the usual case: the block under way was checkpointed
        assert f"checkpoint of update {_checkpoint_done(out)} written" in err
    assert main(["run", "--resume", str(out), "--quiet"]) == 0
    _same_results(out, uninterrupted)


def test_sigterm_before_training_exits_143_at_once(tmp_path):
    """Before a block has run (start-up: importing JAX) nothing newer than the last checkpoint
    exists: SIGTERM exits at once, status 143, one line."""
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-c", LAUNCH, *_tiny(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=subprocess_env(__name__, cache=False))
    time.sleep(0.5)
    assert proc.poll() is None
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert err.startswith("remidi: terminated (SIGTERM)") and err.count("\n") == 1 and "checkpoint" not in err, err
