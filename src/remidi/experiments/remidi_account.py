"""What a buffer sequence (ReMiDi over PLR⊥, ACCEL, SFL, ...) did over a run, said in one line at
its end (:func:`remidi_line`): rejected fresh levels, masked share, frozen solve rates, cost."""

from __future__ import annotations

import numpy as np

from remidi.experiments.base import RunResult

# how the end-of-run line names the algorithm a buffer sequence refines
BASE_NAMES = {"plr": "PLR⊥", "accel": "ACCEL", "sfl": "SFL"}


def remidi_account(algo_name: str, result: RunResult, num_envs: int | None) -> dict | None:
    """What a buffer sequence did over the whole run, per seed, from ``result.history``
    ({name: f[S, T]}, blocks ending at ``result.steps`` i[T]):

    * ``fresh_levels``: levels neither replayed nor rehearsed, ``length × num_envs × (1 − replay −
      rehearsal)`` per block;
    * ``rejected``: those a frozen level explained completely;
    * ``masked_share``: the share of trained steps a frozen level explained (``trained_fraction_masked``
      summed over trained updates, divided by their number; NaN without one);
    * ``frozen_solve_rate`` {buffer: f[S]}: ``buffer_solve_rate/b<i>`` of the buffers frozen at the end.

    None for a non-sequence algorithm or a history without those metrics."""
    from remidi.engine.algorithms import ALGORITHMS

    algo = ALGORITHMS.get(algo_name)
    history = result.history
    if algo is None or not algo.buffer_sequence or not num_envs or not all(
            name in history for name in ("rejected", "replay", "trained_fraction_masked")):
        return None
    steps = np.asarray(result.steps, float)
    lengths = np.diff(np.concatenate([[0.0], steps]))  # f[T]
    replay = np.asarray(history["replay"], float)
    rehearsal = np.asarray(history.get("rehearsal", np.zeros_like(replay)), float)
    fresh = (lengths * num_envs * (1.0 - replay - rehearsal)).sum(axis=1)
    rejected = np.asarray(history["rejected"], float).sum(axis=1)
    trains_on_replay = algo.replays and not algo.trains_on_fresh
    trained = (lengths * (replay + rehearsal)).sum(axis=1) if trains_on_replay else np.full(len(replay), lengths.sum())
    masked = (lengths * np.asarray(history["trained_fraction_masked"], float)).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(trained > 0, masked / trained, np.nan)
    final = result.final_metrics()
    active = np.asarray(history["active_buffer"], float)[:, -1] if "active_buffer" in history else None
    solve = {name.split("/", 1)[1]: [float(v) for v in np.asarray(final[name], float)]
             for name in sorted(final, key=lambda n: (len(n), n)) if name.startswith("buffer_solve_rate/b")
             and active is not None and int(name.rsplit("b", 1)[1]) < np.min(active)}  # frozen on every seed
    return {"fresh_levels": [int(round(v)) for v in fresh], "rejected": [int(round(v)) for v in rejected],
            "masked_share": [float(v) for v in share], "base": _base_algorithm(algo),
            **({"frozen_solve_rate": solve} if solve else {})}


def _base_algorithm(algo) -> str | None:
    """The registered algorithm ``algo`` (a buffer sequence) refines: the one with its adversary as
    a single buffer and its score (``remidi`` → ``plr``); None where none is registered."""
    from dataclasses import replace as replaced

    from remidi.engine.algorithms import ALGORITHMS
    from remidi.errors import ConfigError

    try:
        single = replaced(algo.adversary, buffer_sequence=False)
    except (TypeError, ConfigError):  # no such field, or no single-buffer form (PAIRED's sequence)
        return None
    return next((name for name, other in ALGORITHMS.items() if other.adversary == single and other.score == algo.score),
                None)


def _cost_per_update(summary: dict) -> float | None:
    """Seconds per update this invocation trained: the steady rate after the first block where
    recorded, else wall time over updates; None where neither is known."""
    parts = summary.get("parts") or []
    last = parts[-1] if parts and isinstance(parts[-1], dict) else {}
    if last.get("train_updates"):
        return last["train_s"] / last["train_updates"]
    updates = (last["updates"][1] - last["updates"][0]) if last.get("updates") else None
    return summary["wall_s"] / updates if updates and summary.get("wall_s") else None


def remidi_line(algo: str, summary: dict, summaries: dict[str, dict]) -> str | None:
    """The line a run says at its end of what buffer sequence ``algo`` did (:func:`remidi_account`)
    over every seed; where nothing was rejected or masked, that it ran as its base algorithm, with
    the cost ratio to that algorithm's run in ``summaries`` where there is one."""
    did = summary["remidi_did"]
    fresh, rejected = sum(did["fresh_levels"]), sum(did["rejected"])
    shares = [s for s in did["masked_share"] if isinstance(s, (int, float)) and s == s]  # NaN, null: none trained
    masked = float(np.mean(shares)) if shares else 0.0
    seeds = len(did["fresh_levels"])
    who = f"what {algo} did{f' ({seeds} seeds)' if seeds > 1 else ''}"
    base = did.get("base")
    ratio = None
    if base in summaries and base != algo:
        mine, theirs = _cost_per_update(summary), _cost_per_update(summaries[base])
        ratio = mine / theirs if mine and theirs else None
    solve = did.get("frozen_solve_rate") or {}
    solved = (", the frozen buffers solve " + ", ".join(f"{np.nanmean(v):.2f} ({name})" for name, v in solve.items())
              if solve else "")
    if rejected == 0 and masked == 0:
        same = f": this run was {BASE_NAMES.get(base, base)}" if base else ""
        cost = f" at {ratio:.1f}× its cost" if base and ratio is not None else ""
        return f"{who}: rejected 0 of {fresh:,} fresh levels, masked no step{solved}{same}{cost}"
    part = f" ({rejected / fresh:.1%})" if fresh else ""
    steps = f"masked {masked:.1%} of the steps it trained on" if masked > 0 else "masked no step"
    cost = f"; {ratio:.1f}× {BASE_NAMES.get(base, base)}'s cost" if base and ratio is not None else ""
    return f"{who}: rejected {rejected:,} of {fresh:,} fresh levels{part}, {steps}{solved}{cost}"
