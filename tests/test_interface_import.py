"""Two checks on a fresh single-device process (one subprocess serves both: each start costs
seconds):

* the lever game and the command line start without jaxued's maze, gymnax and seaborn (seconds of
  start-up), and jaxued's interface stays one class when its package is imported later;
* regression, initialising many seeds must not hang. With jaxlib 0.10.2 on CPU, several *batched*
  QR decompositions in one program (orthogonal initialisers under ``vmap`` over seeds) sometimes
  never finish; the driver initialises seeds one after another with ``lax.map``. In a subprocess,
  a hang fails the test (its timeout) instead of stalling the suite.
"""

import subprocess
import sys

import pytest

from conftest import subprocess_env

SCRIPT = """
import sys
from remidi.cli import main
from remidi.engine.run import driver  # noqa: F401
from remidi.experiments import get_experiment
from remidi.experiments.base import resolve_config
main(["list", "lever"])
exp = get_experiment("lever")
task = exp.make_task(resolve_config(exp, "smoke", {}))
heavy = sorted(m for m in ("gymnax", "seaborn", "jaxued.environments", "remidi.envs.maze") if m in sys.modules)
import jaxued.environments
from jaxued.environments.maze import Maze
from remidi.envs.interface import UnderspecifiedEnv
from remidi.envs.maze import MazeEnv
print("RESULT", heavy, jaxued.environments.UnderspecifiedEnv is UnderspecifiedEnv, issubclass(Maze, UnderspecifiedEnv),
      issubclass(MazeEnv, UnderspecifiedEnv), flush=True)

import jax, jax.numpy as jnp
from remidi.engine import train as tr
from remidi.envs.lever import lever_task
from remidi.experiments.lever import paper_config
setup = tr.make_setup(lever_task(64), paper_config(), "dr")
runner = driver._init(setup, jax.vmap(jax.random.PRNGKey)(jnp.arange(8, dtype=jnp.uint32)))
jax.block_until_ready(runner)
print("initialised", runner.learner.train_state.step.shape)
"""


@pytest.fixture(scope="module")
def fresh_process():
    """``(exit status or None if it hung, stdout, stderr)``: each test reads its own part, so a
    hang or crash of the seed initialisation leaves the import check its verdict."""
    try:
        done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=300,
                              env=subprocess_env(__name__))
        return done.returncode, done.stdout, done.stderr
    except subprocess.TimeoutExpired as err:  # its captured output is bytes
        return None, (err.stdout or b"").decode(), (err.stderr or b"").decode()


def test_the_lever_game_starts_without_the_maze_stack_and_the_interface_stays_one_class(fresh_process):
    _, stdout, stderr = fresh_process
    lines = [x for x in stdout.splitlines() if x.startswith("RESULT")]
    assert lines, stderr[-2000:]
    assert lines[0] == "RESULT [] True True True"


def test_initialising_eight_seeds_finishes(fresh_process):
    status, stdout, stderr = fresh_process
    assert status == 0, "hung (killed after 300 s)" if status is None else stderr[-2000:]
    assert "initialised (8,)" in stdout
