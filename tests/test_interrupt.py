"""Ctrl-C at any moment of `remidi run` (start-up, XLA compiling, training) exits cleanly: status
130, one line `remidi: interrupted...`, no traceback, no abort, no half-written file."""

import json
import signal
import subprocess
import sys
import time

import pytest
from conftest import subprocess_env
from test_cli import LEVER_TINY

# the `remidi` program with Python's default Ctrl-C handling (a test runner may start its
# children with SIGINT ignored, and then remidi leaves it ignored)
LAUNCH = ("import runpy, signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
          "sys.argv = ['remidi', *sys.argv[1:]]; runpy.run_module('remidi', run_name='__main__')")


def _started(path):
    return lambda: path.exists()


@pytest.mark.parametrize("when", [
    "start-up",  # 0.5 s in: Python imports JAX (a KeyboardInterrupt there used to be swallowed)
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
