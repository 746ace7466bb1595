"""``remidi solve``: solve a game file exactly and report MMR, the BLP rounds, policy and regret."""

from __future__ import annotations

import json
import os

import numpy as np

from remidi.solvers import onestep, sequence_form
from remidi.solvers.gamefile import load_game
from remidi.solvers.onestep import OneStepGame
from remidi.solvers.sequence_form import TreeGame


def _clean(x: float) -> float:
    """A float rounded to 10 decimals, without negative zero."""
    return round(float(x), 10) + 0.0


def _by_level(names: tuple[str, ...], values: np.ndarray) -> dict[str, float]:
    """{level name: value} from values [L]."""
    return {n: _clean(v) for n, v in zip(names, values)}


def _policy_table(game: OneStepGame | TreeGame, policy) -> dict[str, dict[str, float]]:
    """{observation or AOH text: {action: probability}} from a solver's policy."""
    if isinstance(game, OneStepGame):
        return {
            obs: {a: _clean(p) for a, p in zip(game.actions, row)}
            for obs, row in zip(game.observation_names, policy)
        }
    return {
        " ".join(aoh): {a: _clean(p) for a, p in probs.items()} for aoh, probs in policy.items()
    }


def summarise(game: OneStepGame | TreeGame, progress=None) -> dict:
    """JSON-ready summary of the BLP solution (whose first round is the MMR solution).

    Keys: format, actions, mmr_value, adversary (round 1, {level: prob}), rounds
    ([{value, support, adversary, unique}]; ``unique``: whether the policy the round freezes is
    the only optimal one, see :class:`~remidi.solvers.results.Round`), policy ({observation/AOH:
    {action: prob}}), regret, optimal_return and support_round ({level: 1-based round whose
    support holds it}).
    """
    solver = onestep if isinstance(game, OneStepGame) else sequence_form
    result = solver.solve_blp(game, progress=progress)
    names = game.level_names
    rounds = [
        {"value": _clean(r.value), "support": list(r.support),
         "adversary": {n: _clean(p) for n, p in r.adversary.items()},
         "unique": bool(r.unique)}
        for r in result.rounds
    ]
    return {
        "format": "one-step" if isinstance(game, OneStepGame) else "multi-step",
        "actions": list(game.actions),
        "mmr_value": _clean(result.mmr_value),
        "adversary": rounds[0]["adversary"],
        "rounds": rounds,
        "policy": _policy_table(game, result.policy),
        "regret": _by_level(names, result.regret),
        "optimal_return": _by_level(names, result.optimal_return),
        "support_round": {n: i + 1 for i, r in enumerate(result.rounds) for n in r.support},
    }


def _num(x: float) -> str:
    """A number for the text report."""
    return f"{x:.6g}"


def _table(rows: list[list[str]], indent: str = "  ") -> list[str]:
    """Left-aligned columns separated by two spaces."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return [indent + "  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]


def format_text(summary: dict, source: str) -> str:
    """Readable report of :func:`summarise`'s output."""
    levels = list(summary["regret"])
    lines = [
        f"{source}: {summary['format']} game, {len(levels)} levels, actions "
        f"{', '.join(summary['actions'])}",
        "",
        f"minimax regret value: {_num(summary['mmr_value'])}",
        "",
        "BLP refinement (maximal-support equilibrium adversary per round):",
    ]
    lines += _table([["round", "value", "frozen policy unique", "adversary support (probability)"]] + [
        [str(i + 1), _num(r["value"]), "yes" if r["unique"] else "no",
         ", ".join(f"{n} ({_num(p)})" for n, p in r["adversary"].items())]
        for i, r in enumerate(summary["rounds"])
    ])
    ambiguous = [str(i + 1) for i, r in enumerate(summary["rounds"]) if not r["unique"]]
    if ambiguous:
        lines += [f"  The BLP policy is not unique: round(s) {', '.join(ambiguous)} froze one of several optimal",
                  "  policies; later rounds, the policy and the regrets below can depend on that choice."]
    else:
        lines.append("  The BLP policy is unique: every round froze the only optimal policy.")
    key = "observation" if summary["format"] == "one-step" else "history"
    lines += ["", "BLP policy (probability of each action):"]
    lines += _table([[key] + summary["actions"]] + [
        [obs] + [_num(probs[a]) if a in probs else "-" for a in summary["actions"]]
        for obs, probs in summary["policy"].items()
    ])
    if summary["format"] == "multi-step":
        lines.append("  (histories the policy never reaches are omitted)")
    lines += ["", "per level:"]
    lines += _table([["level", "optimal return", "regret", "round"]] + [
        [n, _num(summary["optimal_return"][n]), _num(summary["regret"][n]),
         str(summary["support_round"][n])]
        for n in levels
    ])
    return "\n".join(lines)


def solve_command(path: str, as_json: bool, log=None) -> str:
    """Text (or, with ``as_json``, JSON) report for a game file; raises GameFileError. ``log``
    (a function of one line) hears each BLP round as it is solved."""
    game = load_game(path)

    def progress(value, support, covered, total):
        if log is not None:
            log(f"BLP round: value {value:.6g}, support {support} level(s), "
                f"{covered}/{total} levels covered")

    summary = summarise(game, progress)
    if as_json:
        return json.dumps(summary, indent=2)
    return format_text(summary, os.path.basename(path))
