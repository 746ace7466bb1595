"""The lever game and the command line start without jaxued's maze, gymnax and seaborn
(seconds of start-up), and jaxued's interface stays one class when its package is imported later."""

import subprocess
import sys

from conftest import subprocess_env

SCRIPT = """
import sys
from remidi.cli import main
from remidi.engine import driver  # noqa: F401
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
      issubclass(MazeEnv, UnderspecifiedEnv))
"""


def test_the_lever_game_starts_without_the_maze_stack_and_the_interface_stays_one_class():
    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=300,
                          env=subprocess_env(__name__))
    assert done.returncode == 0, done.stderr[-2000:]
    line = next(x for x in done.stdout.splitlines() if x.startswith("RESULT"))
    assert line == "RESULT [] True True True"
