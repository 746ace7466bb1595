"""``remidi status RUN_DIR ...``: where runs stand, read from their folders without loading a
model: finished (evaluated where ``evaluate.json`` is there) or the last checkpoint's update and
age; each part's updates, device and seconds per update; the time left at the last part's rate;
and the stalled updates (:func:`remidi.experiments.ued.stalled_updates`)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from remidi.engine.run.checkpoint import CHECKPOINT, HISTORY, load_history, read_meta, unreadable
from remidi.errors import ConfigError
from remidi.experiments.outputs import read_json_object
from remidi.runs import require_folder


def run_folders(folders: list[Path]) -> list[Path]:
    """Each folder that holds a ``config.json`` of one algorithm's run, in the order given (a
    several-algorithm run's folder: its algorithms' folders, by name)."""
    found = []
    for folder in map(Path, folders):
        require_folder("RUN_DIR", folder)
        config = folder / "config.json"
        subs = sorted(p.parent for p in folder.glob("*/config.json")) if folder.is_dir() else []
        if config.is_file() and "algo" in read_json_object(config, "RUN_DIR"):
            found.append(folder)
        elif subs:
            found.extend(subs)
        else:
            raise ConfigError(f"RUN_DIR: {folder} holds no run (no config.json written by remidi run)")
    return found


def _duration(seconds: float) -> str:
    """``45 s`` under a minute, ``12 min``, ``3 h 05 min``."""
    if seconds < 59.5:
        return f"{max(round(seconds), 0)} s"
    minutes = round(seconds / 60)
    return f"{minutes // 60} h {minutes % 60:02d} min" if minutes >= 60 else f"{minutes} min"


def _per_update(seconds: float) -> str:
    return f"{seconds:.1f}" if seconds >= 1 else f"{seconds:.2g}"


def steady_rate(part: dict) -> float | None:
    """Seconds per update of a part while it trained, compiling left out (``train_s /
    train_updates`` of its timed blocks, :class:`~remidi.engine.run.driver.PartClock`); None without."""
    if part.get("train_updates") and part.get("train_s") is not None:
        return part["train_s"] / part["train_updates"]
    return None


def _part(part: dict) -> str:
    first, last = part["updates"]
    code = part.get("code") or {}
    device = code.get("device") or "device not recorded"
    steady = steady_rate(part)
    if steady is not None:
        rate = f", {_per_update(steady)} s/update after compiling" + \
            (f" ({_duration(part['wall_s'])} in all)" if part.get("wall_s") else "")
    else:
        rate = f", {_per_update(part['wall_s'] / (last - first))} s/update with compiling" \
            if last > first and part.get("wall_s") else ""
    return f"{first}–{last} on {device}{rate}"


def _seeds(seeds: list[int]) -> str:
    return f"seeds {seeds[0]}–{seeds[-1]}" if seeds == list(range(seeds[0], seeds[-1] + 1)) and len(seeds) > 1 \
        else "seed" + ("s " if len(seeds) > 1 else " ") + ", ".join(map(str, seeds))


def _stalled_line(stalled: dict) -> str:
    if not stalled:
        return "stalled: none"
    return "stalled (trained on nothing while a frozen adversary rejected levels): " + "; ".join(
        f"seed {seed} updates " + ", ".join(f"{a}–{b}" for a, b in ranges) for seed, ranges in stalled.items())


def run_status(folder: Path, now: float | None = None) -> list[str]:
    """The lines ``remidi status`` prints for one algorithm's run folder."""
    from remidi.experiments.ued import stalled_updates

    config = read_json_object(folder / "config.json", "RUN_DIR")
    try:  # a config.json edited by hand: say which file, not a traceback
        seeds = [int(s) for s in config.get("seeds") or []]
        total = (config.get("config") or {}).get("num_updates")
        total = int(total) if total else None
    except (TypeError, ValueError, AttributeError) as err:
        raise ConfigError(f"RUN_DIR: {folder / 'config.json'} is not as remidi run writes it (seeds, "
                          f"config.num_updates: {type(err).__name__})") from None
    head = f"{folder}: {config.get('algo')} on {config.get('experiment')}, preset {config.get('preset')}, " \
           f"{_seeds(seeds) if seeds else 'no seeds'}"
    lines = [head]
    summary = folder / "summary.json"
    if summary.is_file():
        doc = read_json_object(summary, "RUN_DIR")
        evaluated = "" if not (folder / CHECKPOINT).is_file() else ", evaluated" if (folder / "evaluate.json").is_file() \
            else f", not evaluated (remidi evaluate {folder})"  # a UED run keeps its checkpoint to evaluate
        lines.append(f"  finished{f' ({total} updates)' if total else ''}{evaluated}")
        lines += [f"  part {_part(p)}" for p in doc.get("parts") or []]
        if "stalled_updates" in doc:
            lines.append("  " + _stalled_line(doc["stalled_updates"]))
        return lines
    ckpt = folder / CHECKPOINT
    if not ckpt.is_file():
        lines.append(f"  no checkpoint yet (remidi run --resume {folder} trains it from the start)")
        return lines
    meta = read_meta(ckpt, "RUN_DIR")
    try:
        done = int(meta["done"])
    except (KeyError, TypeError, ValueError):
        raise unreadable(ckpt, TypeError("its meta holds no update count"), "RUN_DIR") from None
    age = (now if now is not None else time.time()) - ckpt.stat().st_mtime
    share = f" of {total} ({100 * done // total} %)" if total else ""  # floored: 99 % until it is done
    lines.append(f"  checkpoint at update {done}{share}, written {_duration(age)} ago "
                 f"(remidi run --resume {folder} continues it)")
    parts = meta.get("parts") or []
    lines += [f"  part {_part(p)}" for p in parts]
    last = parts[-1] if parts else None
    if total and last:
        rate, how = steady_rate(last), "after compiling"
        if rate is None and last.get("wall_s") and last["updates"][1] > last["updates"][0]:
            rate, how = last["wall_s"] / (last["updates"][1] - last["updates"][0]), "with its compiling: an overestimate"
        device = (last.get("code") or {}).get("device") or "its device"
        if rate is not None:
            lines.append(f"  left: {total - done} updates, about {_duration(rate * (total - done))} at the last "
                         f"part's rate ({how}; on {device}; a resume compiles first)")
    try:
        history, _ = load_history(ckpt.with_name(HISTORY), meta)
    except ConfigError as err:  # its message is for --resume: say what it means here
        lines.append(f"  stalled: unknown ({str(err).removeprefix('--resume: ').split(';')[0]})")
        return lines
    if history and all("rejected" in block and "ppo/policy_loss" in block for block in history):
        stacked = {name: np.stack([np.asarray(block[name]) for block in history], axis=1)
                   for name in ("rejected", "ppo/policy_loss")}
        lines.append("  " + _stalled_line(stalled_updates(seeds, np.asarray(meta["steps"]), stacked)))
    return lines
