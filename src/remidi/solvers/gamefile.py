"""Reading and validating game files (formats documented in ``examples/README.md``).

Two JSON formats share the top level ``{"actions": [...], "levels": [...]}``:

* one-step: every level is ``{"name", "observation", "rewards"}`` -> :class:`OneStepGame`;
* multi-step: every level is ``{"name", "tree"}`` -> :class:`TreeGame`.

Every problem raises :class:`~remidi.errors.GameFileError` with one line naming the file, the
place (level and, inside a tree, a path such as ``tree.children.a1.chance[0].node``) and the issue.
"""

from __future__ import annotations

import json
import math
from typing import Any

from remidi.errors import GameFileError
from remidi.solvers.onestep import OneStepGame
from remidi.solvers.sequence_form import (
    Chance, Decision, Node, Terminal, TreeGame, build_sequence_form,
)

#: Allowed deviation of a chance node's probabilities from summing to 1.
PROB_SUM_TOL = 1e-6

_TOP_KEYS = ("actions", "levels", "description")
_ONESTEP_KEYS = ("name", "observation", "rewards")
_TREE_KEYS = ("name", "tree")


class _Invalid(Exception):
    """A validation failure inside the file; the message lacks the file name."""


def _is_number(value: Any) -> bool:
    """True for finite JSON numbers (booleans excluded)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _show(value: Any) -> str:
    """A file value as short JSON text for messages."""
    text = json.dumps(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _object(value: Any, where: str, allowed: tuple[str, ...], required: tuple[str, ...]) -> dict:
    """Check that ``value`` is an object with only ``allowed`` keys and all ``required`` ones."""
    if not isinstance(value, dict):
        raise _Invalid(f"{where}: expected a JSON object, got {type(value).__name__}")
    for key in value:
        if key not in allowed:
            raise _Invalid(f"{where}: unknown field {key!r} (allowed: {', '.join(allowed)})")
    for key in required:
        if key not in value:
            raise _Invalid(f"{where}: missing field {key!r}")
    return value


def _name(value: Any, where: str, spaces: bool) -> str:
    """A non-empty string; without whitespace unless ``spaces`` (AOHs are space-joined)."""
    if not isinstance(value, str) or not value:
        raise _Invalid(f"{where}: expected a non-empty string, got {_show(value)}")
    if not spaces and any(ch.isspace() for ch in value):
        raise _Invalid(f"{where}: name {value!r} must not contain whitespace")
    return value


def _actions(data: dict) -> tuple[str, ...]:
    """The top-level action names [A]: a non-empty list of distinct names."""
    actions = data["actions"]
    if not isinstance(actions, list) or not actions:
        raise _Invalid("'actions': expected a non-empty list of action names")
    names = tuple(_name(a, f"actions[{i}]", spaces=False) for i, a in enumerate(actions))
    if len(set(names)) != len(names):
        raise _Invalid(f"'actions': duplicate action name in {list(names)}")
    return names


def _levels(data: dict) -> list[tuple[str, dict]]:
    """(name, object) per level; rejects an empty list and duplicate names."""
    levels = data["levels"]
    if not isinstance(levels, list):
        raise _Invalid(f"'levels': expected a list, got {type(levels).__name__}")
    if not levels:
        raise _Invalid("'levels' is empty: need at least one level")
    seen: dict[str, int] = {}
    named = []
    for i, level in enumerate(levels):
        level = _object(level, f"levels[{i}]", _ONESTEP_KEYS + _TREE_KEYS[1:], ("name",))
        name = _name(level["name"], f"levels[{i}].name", spaces=True)
        if name in seen:
            raise _Invalid(f"duplicate level name {name!r} (levels[{seen[name]}] and levels[{i}])")
        seen[name] = i
        named.append((name, level))
    return named


def _is_tree_level(name: str, level: dict) -> bool:
    """Whether a level is multi-step (has 'tree') rather than one-step."""
    has_tree = "tree" in level
    has_step = "rewards" in level or "observation" in level
    if has_tree == has_step:
        raise _Invalid(
            f"level {name!r}: needs either 'observation' and 'rewards' (one-step) or 'tree' "
            "(multi-step), not both or neither"
        )
    return has_tree


def _rewards(values: Any, where: str, count: int) -> list[float]:
    """A list of ``count`` finite rewards."""
    if not isinstance(values, list):
        raise _Invalid(f"{where}: 'rewards' must be a list of numbers")
    if len(values) != count:
        raise _Invalid(f"{where}: expected {count} rewards (one per action), got {len(values)}")
    for i, value in enumerate(values):
        if not _is_number(value):
            raise _Invalid(f"{where}: rewards[{i}] must be a finite number, got {_show(value)}")
    return [float(v) for v in values]


def _one_step(actions: tuple[str, ...], levels: list[tuple[str, dict]]) -> OneStepGame:
    """Build a one-step game from validated levels."""
    observations, rewards = [], []
    for name, level in levels:
        where = f"level {name!r}"
        _object(level, where, _ONESTEP_KEYS, _ONESTEP_KEYS)
        observations.append(_name(level["observation"], f"{where}: 'observation'", spaces=True))
        rewards.append(_rewards(level["rewards"], where, len(actions)))
    return OneStepGame(actions, tuple(n for n, _ in levels), tuple(observations), rewards)


def _chance(value: Any, where: str, actions: tuple[str, ...]) -> Chance:
    """A chance node: non-empty list of {prob, node} with probabilities >= 0 summing to 1."""
    if not isinstance(value, list) or not value:
        raise _Invalid(f"{where}.chance: expected a non-empty list of outcomes")
    outcomes = []
    for i, item in enumerate(value):
        here = f"{where}.chance[{i}]"
        item = _object(item, here, ("prob", "node"), ("prob", "node"))
        prob = item["prob"]
        if not _is_number(prob):
            raise _Invalid(f"{here}.prob: must be a finite number, got {_show(prob)}")
        if prob < 0:
            raise _Invalid(f"{here}.prob: negative probability {prob}")
        outcomes.append((float(prob), _node(item["node"], f"{here}.node", actions)))
    total = sum(p for p, _ in outcomes)
    if abs(total - 1.0) > PROB_SUM_TOL:
        raise _Invalid(f"{where}.chance: probabilities sum to {total:g}, expected 1")
    return Chance(tuple(outcomes))


def _decision(value: dict, where: str, actions: tuple[str, ...]) -> Decision:
    """A decision node: observation name and a non-empty {action: node} map over known actions."""
    observation = _name(value["observation"], f"{where}.observation", spaces=False)
    children = value["children"]
    if not isinstance(children, dict) or not children:
        raise _Invalid(f"{where}.children: expected a non-empty object {{action: node}}")
    for action in children:
        if action not in actions:
            raise _Invalid(
                f"{where}.children: unknown action {action!r} (actions: {', '.join(actions)})"
            )
    return Decision(observation, {
        a: _node(children[a], f"{where}.children.{a}", actions) for a in actions if a in children
    })


def _node(value: Any, where: str, actions: tuple[str, ...]) -> Node:
    """One tree node: exactly one of {"reward"}, {"chance"}, {"observation", "children"}."""
    if not isinstance(value, dict):
        raise _Invalid(f"{where}: expected a node object, got {type(value).__name__}")
    if "reward" in value:
        _object(value, where, ("reward",), ("reward",))
        if not _is_number(value["reward"]):
            raise _Invalid(f"{where}.reward: must be a finite number, got {_show(value['reward'])}")
        return Terminal(float(value["reward"]))
    if "chance" in value:
        _object(value, where, ("chance",), ("chance",))
        return _chance(value["chance"], where, actions)
    if "observation" in value or "children" in value:
        _object(value, where, ("observation", "children"), ("observation", "children"))
        return _decision(value, where, actions)
    raise _Invalid(
        f"{where}: a node needs 'reward', 'chance' or 'observation'+'children', got keys "
        f"{sorted(value)}"
    )


def _tree_game(actions: tuple[str, ...], levels: list[tuple[str, dict]]) -> TreeGame:
    """Build a multi-step game from validated levels; checks information-set consistency."""
    trees = []
    for name, level in levels:
        _object(level, f"level {name!r}", _TREE_KEYS, _TREE_KEYS)
        trees.append(_node(level["tree"], f"level {name!r}: tree", actions))
    game = TreeGame(actions, tuple(n for n, _ in levels), tuple(trees))
    try:
        build_sequence_form(game)
    except ValueError as err:
        raise _Invalid(str(err)) from None
    return game


def parse_game(data: Any, source: str = "<game>") -> OneStepGame | TreeGame:
    """Validate decoded JSON and build the game; ``source`` prefixes error messages."""
    try:
        data = _object(data, "top level", _TOP_KEYS, ("actions", "levels"))
        if not isinstance(data.get("description", ""), str):
            raise _Invalid("'description': expected a string")
        actions, levels = _actions(data), _levels(data)
        kinds = {_is_tree_level(name, level) for name, level in levels}
        if len(kinds) > 1:
            raise _Invalid("levels mix one-step ('rewards') and multi-step ('tree') formats")
        return _tree_game(actions, levels) if kinds.pop() else _one_step(actions, levels)
    except _Invalid as err:
        raise GameFileError(f"{source}: {err}") from None
    except RecursionError:
        raise GameFileError(f"{source}: tree nested too deeply") from None


def load_game(path: str) -> OneStepGame | TreeGame:
    """Read a game file; one-step or multi-step is detected from the levels' fields."""
    try:
        with open(path, encoding="utf-8") as handle:
            data = json.load(handle)
    except OSError as err:
        raise GameFileError(f"{path}: cannot read file ({err.strerror or err})") from None
    except UnicodeDecodeError:
        raise GameFileError(f"{path}: not a UTF-8 text file") from None
    except json.JSONDecodeError as err:
        raise GameFileError(
            f"{path}: invalid JSON at line {err.lineno} column {err.colno}: {err.msg}"
        ) from None
    except RecursionError:
        raise GameFileError(f"{path}: JSON nested too deeply") from None
    return parse_game(data, path)
