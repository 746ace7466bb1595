"""``remidi.run_ued`` as a Python caller meets it: the configuration as a dict of its keys or as a
``UEDConfig``, the algorithms as a list or a comma-separated string, the seeds as a list or a
count, and every error and note in the caller's words (``algos``, ``seeds``, ``out``,
``config["key"]``), not the command line's (``--algo``, ``--seeds``, ``--out``, ``--set``).
Nothing trains: the run stops where everything is checked and training would start."""

import importlib.util
import json
import sys
from pathlib import Path

import pytest

from remidi import run_ued
from remidi.engine.algorithms import get_algorithm
from remidi.engine.config import UEDConfig
from remidi.engine.trackers import tracker_cost_note
from remidi.errors import COMMAND_LINE, PYTHON, ConfigError, a_type
from remidi.experiments import running
from remidi.experiments.custom import python_naming

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "bring_your_own_env.py"


@pytest.fixture(scope="module")
def task():
    """The worked example's task (a module of its own name: no other test imports it so)."""
    spec = importlib.util.spec_from_file_location("byo_python_api", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while it loads
    spec.loader.exec_module(module)
    return module.make_task()


@pytest.fixture
def checked(monkeypatch):
    """What run_experiment hands to training once everything is checked (training left out)."""
    seen = {}

    def validated_only(spec, config, out, notes, progress):
        seen.update(spec=spec, config=config, out=out, notes=notes)
        return {algo: {} for algo in spec.algos}

    monkeypatch.setattr(running, "_write_and_train", validated_only)
    return seen


def test_the_config_is_a_dict_of_its_keys_the_algorithms_a_comma_string_and_the_seeds_a_count(task, checked,
                                                                                              tmp_path):
    """Before: a dict raised TypeError from dataclasses, ``"plr,remidi"`` read as the algorithms
    ``p``, ``l``, ``r``, ... (``--algo: unknown value 'p'``)."""
    summaries = run_ued(task, {"num_updates": 20, "ppo": {"lr": 1e-3}, "remidi.num_buffers": 2}, "plr,remidi", 2,
                        tmp_path / "out", progress=False)
    assert summaries == {"plr": {}, "remidi": {}}
    spec, config = checked["spec"], checked["config"]
    assert spec.algos == ["plr", "remidi"] and spec.seeds == [0, 1]
    assert (config.num_updates, config.ppo.lr, config.remidi.num_buffers) == (20, 1e-3, 2)
    assert config.score == "perfect_regret" and config.num_steps == task.max_episode_steps  # the task's defaults
    note = next(line for line in checked["notes"] if line.startswith("defaults for this task"))
    assert note.endswith('; config["KEY"]=VALUE chooses another'), note
    scaled = next(line for line in checked["notes"] if line.startswith("num_updates 2500 → 20"))
    assert scaled.endswith("(set them in config to choose other values)"), scaled
    whole = UEDConfig(num_updates=20, eval_every=10)  # a whole UEDConfig: used as it is
    run_ued(task, whole, ["plr"], [3], tmp_path / "other", progress=False)
    assert checked["config"] == whole and checked["spec"].seeds == [3]


@pytest.mark.parametrize("config, algos, seeds, message", [
    ({"num_update": 20}, ["plr"], [0], "config: unknown key 'num_update'; allowed: num_updates, num_envs, "),
    ([("num_updates", 20)], ["plr"], [0], "config: must be a dict of UEDConfig keys (e.g. {'num_updates': 200, "
                                          "'ppo.lr': 3e-4}) or a UEDConfig, got [('num_updates', 20)]"),
    ({"num_updates": "many"}, ["plr"], [0], "num_updates: expected an integer, got 'many'"),
    ({}, "plr,remidy", [0], "algos: unknown value 'remidy'; allowed: dr, plr, minimax-return, remidi"),
    ({}, ["plr", "accel"], [0], "algos: accel cannot run on custom: accel edits levels, but this task has no level "
                                "mutator"),
    ({}, "plr,plr", [0], "algos: 'plr,plr' names an algorithm twice"),
    ({}, 7, [0], "algos: must be a list of algorithm names or a comma-separated string (e.g. ['plr', 'remidi'] or "
                 "'plr,remidi'), got 7"),
    ({}, ["plr"], [], "seeds: must be a non-empty list of integers in [0, 4294967295] or a number of seeds ≥ 1, "
                      "got []"),
    ({}, ["plr"], 0, "seeds: must be a number of seeds ≥ 1 or a list of seeds, got 0"),
    ({}, ["plr"], [0, "1"], "seeds: must be a non-empty list of integers"),
    ({}, ["plr"], [-1, 2], "seeds: every seed must be in [0, 4294967295] (a 32-bit random key), got -1..2"),
])
def test_bad_arguments_are_one_line_naming_the_python_argument(task, tmp_path, config, algos, seeds, message):
    """Before: ``--algo: ...``, ``--seeds: ...``, ``--set: unknown key``, ``; lower --seed or --seeds``."""
    out = tmp_path / "out"
    with pytest.raises(ConfigError) as err:
        run_ued(task, config, algos, seeds, out, progress=False)
    text = str(err.value)
    assert text.startswith(message) and "\n" not in text and "--" not in text, text
    assert not out.exists()


def test_the_run_folder_is_named_out_and_resuming_it_resume_true(task, tmp_path):
    """Before: ``--out: ... pass --resume OUT`` and ``--resume: OUT does not exist``."""
    taken = tmp_path / "taken"
    taken.mkdir()
    (taken / "config.json").write_text(json.dumps({}))
    with pytest.raises(ConfigError) as err:
        run_ued(task, {}, ["plr"], [0], taken, progress=False)
    assert str(err.value) == (f"out: {taken} already holds a run; choose another folder or pass out='{taken}', "
                              f"resume=True")
    with pytest.raises(ConfigError) as err:
        run_ued(task, {}, ["plr"], [0], tmp_path / "none", progress=False, resume=True)
    assert str(err.value) == f"out: {tmp_path / 'none'} does not exist"


def test_warnings_and_notes_name_the_setting_as_the_config_was_given(task, checked, tmp_path):
    """The short-rollout warning said before training and the tracker's cost note said as ReMiDi
    trains suggest ``config["num_steps"]=14`` for a dict, ``config.remidi.tracker_budget=8`` for a
    UEDConfig; the command line's stay ``--set KEY=VALUE``. Before: ``--set`` for every caller."""
    run_ued(task, {"num_steps": 4, "num_updates": 20}, ["plr"], [0], tmp_path / "out", progress=False)
    warning = next(line for line in checked["notes"] if line.startswith("warning: score perfect_regret"))
    assert f'config["num_steps"]={task.max_episode_steps} (or more) scores every level' in warning, warning
    assert "--set" not in warning
    whole = UEDConfig(num_updates=20, eval_every=10)
    cost = tracker_cost_note(task, whole, get_algorithm("remidi"), python_naming(whole))
    assert "config.remidi.tracker_budget=8 makes it 9×" in cost and "--set" not in cost, cost
    assert "--set remidi.tracker_budget=8 makes it 9×" in tracker_cost_note(task, whole, get_algorithm("remidi"))
    assert python_naming({}) is PYTHON and PYTHON.setting("ppo.lr", 3e-4) == 'config["ppo.lr"]=0.0003'
    assert COMMAND_LINE.setting("ppo.lr", 3e-4) == "--set ppo.lr=0.0003"


def test_a_task_that_is_no_uedtask_is_an_int_not_a_int(tmp_path):
    """Messages name a value's type with its article (they said "a int")."""
    with pytest.raises(ConfigError, match="^experiment: custom gives an int, not a remidi UEDTask$"):
        run_ued(3, {}, ["plr"], [0], tmp_path / "out", progress=False)
    assert [a_type(v) for v in (3, {}, object(), 1.0)] == ["an int", "a dict", "an object", "a float"]
