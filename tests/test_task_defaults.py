"""An import-path task's run starts from defaults chosen from what the task provides
(experiments/custom.task_defaults): the score, the rollout length and how often to evaluate, said
in one line; nothing trains here."""

import dataclasses
import importlib.util
import sys
from pathlib import Path

import pytest

from remidi.engine.config import UEDConfig
from remidi.experiments.base import resolve_config
from remidi.experiments.custom import task_defaults, task_experiment

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "bring_your_own_env.py"


@pytest.fixture(scope="module")
def task():
    spec = importlib.util.spec_from_file_location("corridor_defaults_example", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module.make_task()  # optimal and discounted optimal returns, solved, episodes of 14 steps


@pytest.mark.parametrize("change, score, discounted", [
    ({}, "perfect_regret", True),
    ({"optimal_discounted_return": None}, "perfect_regret", False),  # an undiscounted optimum only
    ({"optimal_return": None, "optimal_discounted_return": None}, "learnability", True),  # solved, no optimum
    ({"optimal_return": None, "optimal_discounted_return": None, "solved": None}, "pvl", True),  # neither
])
def test_the_score_comes_from_what_the_task_provides(task, change, score, discounted):
    config, why = task_defaults(dataclasses.replace(task, **change))
    assert (config.score, config.discounted_regret) == (score, discounted)
    assert config.num_steps == task.max_episode_steps == 14  # an episode ends inside a rollout
    assert config.eval_every == UEDConfig().num_updates // 20 == 125
    assert ("discounted_regret" in why) == (not discounted) and set(why) >= {"score", "num_steps", "eval_every"}


def test_a_long_episode_is_rolled_out_256_steps_at_most(task):
    config, why = task_defaults(dataclasses.replace(task, max_episode_steps=1000))
    assert config.num_steps == 256 and "1000" in why["num_steps"]


def test_a_short_run_evaluates_every_ten_updates_and_the_defaults_are_said_in_one_line(task):
    exp = task_experiment("mine", lambda: task)
    notes = []
    cfg = resolve_config(exp, "default", {"num_updates": 30}, notes)
    assert cfg.eval_every == 10  # not 125 × 30 / 2500 → 1: three evaluations, not thirty
    assert notes[0] == ("defaults for this task: score perfect_regret (the task gives its optimal return); "
                        "num_steps 14 (the task's episode bound); eval_every 10 (20 evaluations per run, at least 10 "
                        "updates apart); --set KEY=VALUE chooses another")
    assert notes[1].startswith("num_updates 2500 → 30, so scaled eval_every 125 → 10, ")
    assert resolve_config(exp, "default", {"num_updates": 7}).eval_every == 7  # shorter than the floor: one block
    assert resolve_config(exp, "default", {"num_updates": 5000}).eval_every == 250  # still 20 evaluations
    notes = []
    resolve_config(exp, "default", {"score": "pvl", "num_steps": 8, "eval_every": 5}, notes)
    assert notes == []  # every default set by hand: nothing to say
    for algo in ("plr", "remidi"):
        exp.validate(resolve_config(exp, "default", {}), algo)
    # a configuration given in Python is used as it is
    given = task_experiment("given", lambda: task, UEDConfig(eval_every=50))
    assert given.config_factory() == UEDConfig(eval_every=50) and given.config_note is None


def test_the_exact_trackers_cost_is_said_with_the_option_that_lowers_it():
    """engine/trackers.tracker_cost_note: ReMiDi with a frozen adversary and at least 8 slots per env
    (or the reference tracker) is said, naming remidi.tracker_budget and tracker_overflow; PLR⊥, a
    single buffer, a learned tracker or few slots are not."""
    from types import SimpleNamespace

    from remidi.engine.algorithms import get_algorithm
    from remidi.engine.config import ReMiDiConfig
    from remidi.engine.trackers import tracker_cost_note

    def note(deterministic=True, **remidi):
        cfg = UEDConfig(remidi=ReMiDiConfig(**{"num_buffers": 2, "buffer_capacity": 512, **remidi}))
        return tracker_cost_note(SimpleNamespace(deterministic_reset=deterministic), cfg, get_algorithm("remidi"))

    line = note()
    assert line.startswith("ReMiDi's exact tracker steps up to 64 frozen levels (remidi.tracker_budget=64) beside "
                           "each rollout env once an adversary is frozen: a rollout steps this environment up to 65× ")
    assert "--set remidi.tracker_budget=8 makes it 9×" in line and "tracker_overflow" in line and "\n" not in line
    assert "up to 9×" in note(tracker_budget=8) and "remidi.buffer_capacity" in note(tracker_budget=8)
    assert note(tracker_budget=4) is None  # 5 environment steps per env step: not said
    assert note(buffer_capacity=4) is None  # 4 frozen levels: the candidate tracker follows 4 at most
    reference = note(tracker_budget=0)
    assert "every frozen level (512: the reference tracker)" in reference and "up to 513×" in reference
    assert "remidi.tracker=belief" in note(deterministic=False)  # no slots where the reset draws its start
    assert note(tracker="belief") is None and note(num_buffers=1) is None
    cfg = UEDConfig(remidi=ReMiDiConfig(num_buffers=2))
    assert tracker_cost_note(SimpleNamespace(deterministic_reset=True), cfg, get_algorithm("plr")) is None
