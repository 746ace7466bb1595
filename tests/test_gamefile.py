"""Game files and the ``remidi solve`` report: example files, JSON/text output, malformed files."""

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from remidi.errors import GameFileError
from remidi.solvers.gamefile import load_game
from remidi.solvers.onestep import OneStepGame
from remidi.solvers.report import solve_command
from remidi.solvers.sequence_form import TreeGame

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

ONE_STEP = {
    "actions": ["A", "B"],
    "levels": [
        {"name": "theta1", "observation": "h1", "rewards": [-0.1, 0.1]},
        {"name": "theta2", "observation": "h1", "rewards": [0.7, -0.7]},
        {"name": "theta3", "observation": "h3", "rewards": [-0.7, 0.7]},
    ],
}


def bet(obs):
    return {"observation": obs, "children": {"a1": {"reward": 1}, "a2": {"reward": -1}}}


TREE = {
    "actions": ["a1", "a2"],
    "levels": [
        {"name": "p", "tree": {"observation": "s0", "children": {"a1": {"chance": [
            {"prob": 0.5, "node": bet("sA")}, {"prob": 0.5, "node": bet("sB")}]}}}},
        {"name": "q", "tree": {"observation": "s0", "children": {"a1": bet("sA")}}},
    ],
}


# ---------------------------------------------------------------- valid files and the report


def test_examples_load_as_the_right_kind():
    shared = load_game(str(EXAMPLES / "tabular_shared.json"))
    assert isinstance(shared, OneStepGame)
    assert shared.level_names == tuple(f"theta{i}" for i in range(1, 7))
    assert shared.observation_names == ("h1", "h3", "h5")
    assert shared.rewards[4] == pytest.approx([-1, 1])
    distinct = load_game(str(EXAMPLES / "tabular_distinct.json"))
    assert len(distinct.observation_names) == 6
    assert isinstance(load_game(str(EXAMPLES / "lottery.json")), TreeGame)


def test_json_report_of_the_shared_game():
    report = json.loads(solve_command(str(EXAMPLES / "tabular_shared.json"), as_json=True))
    assert report["mmr_value"] == 1.0
    assert report["rounds"][0] == {"value": 1.0, "support": ["theta5", "theta6"],
                                   "adversary": {"theta5": 0.5, "theta6": 0.5}, "unique": True}
    assert report["rounds"][1]["value"] == 0.175
    assert report["rounds"][1]["support"] == ["theta1", "theta2", "theta3", "theta4"]
    assert report["policy"]["h1"] == {"A": 0.875, "B": 0.125}
    assert report["regret"] == {"theta1": 0.175, "theta2": 0.175, "theta3": 0.175,
                                "theta4": 0.175, "theta5": 1.0, "theta6": 1.0}
    assert report["optimal_return"]["theta2"] == 0.7
    assert report["adversary"] == {"theta5": 0.5, "theta6": 0.5}


def test_json_report_of_the_lottery_uses_history_strings():
    report = json.loads(solve_command(str(EXAMPLES / "lottery.json"), as_json=True))
    assert report["mmr_value"] == 2.0
    assert report["policy"]["s0 a1 sA"] == {"a1": 1.0, "a2": 0.0}
    assert report["policy"]["s0 a1 sB"] == {"a1": 0.0, "a2": 1.0}
    assert report["regret"] == {"thetaA": 2.0, "thetaB": 2.0}
    # the equilibrium adversaries are every P(thetaA) in [0.01, 0.99] (test_solver_sequence_form)
    adversary = report["adversary"]
    assert set(adversary) == {"thetaA", "thetaB"} and adversary["thetaA"] + adversary["thetaB"] == pytest.approx(1.0)
    assert 0.01 <= adversary["thetaA"] <= 0.99
    assert report["rounds"][0]["unique"] is True


AMBIGUOUS = {"actions": ["a1", "a2", "a3"], "levels": [
    {"name": "x", "observation": "o", "rewards": [1, 0, 0]},
    {"name": "y", "observation": "o", "rewards": [0, 1, 1]},
    {"name": "z", "observation": "o", "rewards": [0, 0, 0.2]},
]}


def test_report_says_whether_the_blp_policy_is_unique(tmp_path):
    path = tmp_path / "ambiguous.json"
    path.write_text(json.dumps(AMBIGUOUS))
    assert [r["unique"] for r in json.loads(solve_command(str(path), as_json=True))["rounds"]] == [False, True]
    assert "The BLP policy is not unique: round(s) 1 froze" in solve_command(str(path), as_json=False)
    shared = solve_command(str(EXAMPLES / "tabular_shared.json"), as_json=False)
    assert "The BLP policy is unique" in shared


def test_text_report_shows_rounds_policy_and_regret():
    text = solve_command(str(EXAMPLES / "tabular_shared.json"), as_json=False)
    assert "minimax regret value: 1" in text
    assert "0.175" in text and "0.875" in text
    assert "theta5 (0.5), theta6 (0.5)" in text
    lottery = solve_command(str(EXAMPLES / "lottery.json"), as_json=False)
    assert "s0 a1 sA" in lottery and "minimax regret value: 2" in lottery


def test_tree_file_round_trips(tmp_path):
    path = tmp_path / "tree.json"
    path.write_text(json.dumps(TREE))
    game = load_game(str(path))
    assert isinstance(game, TreeGame) and game.level_names == ("p", "q")
    assert json.loads(solve_command(str(path), as_json=True))["format"] == "multi-step"


# ---------------------------------------------------------------- malformed files


def error_for(path: Path) -> str:
    """The message of the GameFileError raised by ``solve_command``; checks it is one line."""
    with pytest.raises(GameFileError) as info:
        solve_command(str(path), as_json=False)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(str(path) + ": ")
    return message


def write(tmp_path: Path, data) -> Path:
    path = tmp_path / "game.json"
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return path


def edited(base: dict, edit) -> dict:
    data = copy.deepcopy(base)
    edit(data)
    return data


def test_unreadable_file(tmp_path):
    assert "cannot read file" in error_for(tmp_path / "missing.json")
    assert "cannot read file" in error_for(tmp_path)


def test_invalid_json(tmp_path):
    assert "invalid JSON at line 1" in error_for(write(tmp_path, '{"actions": ['))


def test_top_level_not_an_object(tmp_path):
    assert "top level: expected a JSON object" in error_for(write(tmp_path, "[1, 2]"))


@pytest.mark.parametrize("field", ["actions", "levels"])
def test_missing_top_level_field(tmp_path, field):
    data = edited(ONE_STEP, lambda d: d.pop(field))
    assert f"missing field '{field}'" in error_for(write(tmp_path, data))


def test_missing_level_fields(tmp_path):
    no_name = edited(ONE_STEP, lambda d: d["levels"][1].pop("name"))
    assert "levels[1]: missing field 'name'" in error_for(write(tmp_path, no_name))
    no_rewards = edited(ONE_STEP, lambda d: d["levels"][2].pop("rewards"))
    assert "level 'theta3': missing field 'rewards'" in error_for(write(tmp_path, no_rewards))
    neither = edited(ONE_STEP, lambda d: d["levels"][0].pop("rewards") and
                     d["levels"][0].pop("observation"))
    assert "level 'theta1': needs either" in error_for(write(tmp_path, neither))


def test_wrong_reward_list_length(tmp_path):
    data = edited(ONE_STEP, lambda d: d["levels"][2].update(rewards=[1, 2, 3]))
    path = write(tmp_path, data)
    assert error_for(path) == (
        f"{path}: level 'theta3': expected 2 rewards (one per action), got 3")


@pytest.mark.parametrize("bad", ['"x"', "true", "null", "NaN", "Infinity", "1e999", "[1]"])
def test_non_numeric_rewards(tmp_path, bad):
    text = json.dumps(ONE_STEP).replace("[0.7, -0.7]", f"[0.7, {bad}]")
    message = error_for(write(tmp_path, text))
    assert "level 'theta2': rewards[1] must be a finite number" in message


def test_non_numeric_tree_reward(tmp_path):
    def edit(d):
        d["levels"][1]["tree"]["children"]["a1"]["children"]["a2"]["reward"] = False
    message = error_for(write(tmp_path, edited(TREE, edit)))
    assert ("level 'q': tree.children.a1.children.a2.reward: must be a finite number, got false"
            in message)


def test_empty_level_list(tmp_path):
    assert "'levels' is empty" in error_for(write(tmp_path, {"actions": ["A"], "levels": []}))


def test_bad_actions(tmp_path):
    assert "'actions': expected a non-empty list" in error_for(
        write(tmp_path, edited(ONE_STEP, lambda d: d.update(actions=[]))))
    assert "duplicate action name" in error_for(
        write(tmp_path, edited(ONE_STEP, lambda d: d.update(actions=["A", "A"]))))
    assert "must not contain whitespace" in error_for(
        write(tmp_path, edited(ONE_STEP, lambda d: d.update(actions=["A", "go left"]))))


def test_duplicate_level_names(tmp_path):
    data = edited(ONE_STEP, lambda d: d["levels"][2].update(name="theta1"))
    assert "duplicate level name 'theta1' (levels[0] and levels[2])" in error_for(
        write(tmp_path, data))


def test_unknown_field(tmp_path):
    data = edited(ONE_STEP, lambda d: d["levels"][0].update(reward=[1, 2]))
    assert "unknown field 'reward'" in error_for(write(tmp_path, data))


def test_mixed_formats(tmp_path):
    data = edited(ONE_STEP, lambda d: d["levels"].append({"name": "t", "tree": {"reward": 1}}))
    assert "levels mix one-step" in error_for(write(tmp_path, data))


def test_unknown_action_in_tree(tmp_path):
    data = edited(TREE, lambda d: d["levels"][1]["tree"]["children"].update(a2={"reward": 0},
                                                                             a3={"reward": 0}))
    assert "level 'q': tree.children: unknown action 'a3' (actions: a1, a2)" in error_for(
        write(tmp_path, data))


def test_node_without_a_kind(tmp_path):
    data = edited(TREE, lambda d: d["levels"][1].update(tree={"obs": "s0"}))
    assert "level 'q': tree: a node needs" in error_for(write(tmp_path, data))


def test_negative_chance_probability(tmp_path):
    def edit(d):
        chance = d["levels"][0]["tree"]["children"]["a1"]["chance"]
        chance[0]["prob"], chance[1]["prob"] = -0.5, 1.5
    message = error_for(write(tmp_path, edited(TREE, edit)))
    assert "level 'p': tree.children.a1.chance[0].prob: negative probability -0.5" in message


def test_chance_probabilities_not_summing_to_one(tmp_path):
    def edit(d):
        d["levels"][0]["tree"]["children"]["a1"]["chance"][0]["prob"] = 0.4
    message = error_for(write(tmp_path, edited(TREE, edit)))
    assert "tree.children.a1.chance: probabilities sum to 0.9, expected 1" in message


def test_inconsistent_actions_within_an_information_set(tmp_path):
    data = edited(TREE, lambda d: d["levels"][1]["tree"]["children"]["a1"]["children"].pop("a2"))
    message = error_for(write(tmp_path, data))
    assert "information set 's0 a1 sA'" in message
    assert "level 'q'" in message and "level 'p'" in message


def test_onestep_game_checks_shapes():
    with pytest.raises(ValueError):
        OneStepGame(("A", "B"), ("x",), ("h",), np.zeros((1, 3)))


def test_remidi_solve_reports_each_blp_round_on_stderr(capsys):
    from pathlib import Path

    from remidi.cli import main

    game = Path(__file__).resolve().parent.parent / "examples" / "tabular_shared.json"
    assert main(["solve", str(game), "--json"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["mmr_value"] == pytest.approx(1.0)  # stdout: only the report
    assert err.splitlines() == ["remidi: BLP round: value 1, support 2 level(s), 2/6 levels covered",
                                "remidi: BLP round: value 0.175, support 4 level(s), 6/6 levels covered"]
