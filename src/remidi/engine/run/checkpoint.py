"""Checkpoints of a UED run: the runner (``checkpoint.npz``) and the metrics so far
(``checkpoint.history.npz``), written atomically, read back with one-line errors for damaged
files and files of another run.

Runner arrays are stored by tree path (``leaf:.train_state.params['params']...``), so a mismatch
names the differing part; positional checkpoints (``leaf_0``, ...) are refused. Older layouts
with one runner field per feature load through :data:`RENAMES`; an all-zero copy of a part now
left empty (:data:`UNUSED`) is read as this run's empty part."""

from __future__ import annotations

import json
import re
import zipfile
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from remidi.errors import ConfigError
from remidi.files import atomic_write, flat_keys, remove_temporaries

CHECKPOINT = "checkpoint.npz"
PREFIX = "leaf:"  # a runner array's name in checkpoint.npz: PREFIX + its tree path
HISTORY = "checkpoint.history.npz"  # the metrics logged up to the checkpoint, beside it

#: the runner's earlier layout (one field per feature) → this one (one state per component): a
#: stored leaf path starting with a key here is read as the value's path (``.rng`` kept)
RENAMES = {".train_state": ".learner.train_state", ".obs_stats": ".learner.obs_stats",
           ".frozen_params": ".learner.frozen_params", ".buffers": ".adversary.buffers",
           ".active": ".adversary.active", ".count": ".adversary.count", ".edit_next": ".adversary.edit_next",
           ".last_replayed": ".adversary.last_replayed", ".generator": ".adversary.generator",
           ".antagonist": ".adversary.antagonist", ".next_generators": ".adversary.next_generators",
           ".belief": ".tracker", ".update": ".updates_done"}


#: runner parts, by tree path, that older checkpoints store in full though the run never fills them
#: (DR's buffer, now slotless: ``no_buffers``); their all-zero leaves are read as this run's empty ones
UNUSED = (".adversary.buffers",)


def _unused(name: str, stored: np.ndarray, want) -> bool:
    """The stored leaf ``name`` is an older version's unfilled copy of an :data:`UNUSED` part that
    ``want`` leaves empty."""
    path = name[len(PREFIX):]
    return (any(path == p or path.startswith((p + ".", p + "[")) for p in UNUSED) and np.size(want) == 0
            and stored.dtype == want.dtype and not np.any(stored))


def current_name(path: str) -> str:
    """A runner leaf's tree path in this layout (renamed by :data:`RENAMES`, else unchanged)."""
    first = re.match(r"\.[A-Za-z_]+", path)
    if first is not None and first.group(0) in RENAMES:
        return RENAMES[first.group(0)] + path[first.end():]
    return path


def _named_leaves(tree) -> dict[str, object]:
    """``{PREFIX + tree path: leaf}`` in the tree's leaf order."""
    return {PREFIX + jax.tree_util.keystr(path): leaf for path, leaf in jax.tree_util.tree_leaves_with_path(tree)}


def save_checkpoint(path: Path, runner, meta: dict) -> None:
    """Write the runner's arrays (by tree path) and ``meta`` (JSON) to ``path`` atomically."""
    leaves = {name: np.asarray(x) for name, x in _named_leaves(jax.device_get(runner)).items()}
    text = json.dumps(meta, default=_plain)
    atomic_write(path, lambda fh: np.savez(fh, meta=np.asarray(text), **leaves), binary=True)


def _plain(value):
    """JSON for NumPy/JAX scalars and arrays in a meta (``tolist``), anything else by its text."""
    return value.tolist() if hasattr(value, "tolist") else str(value)


# what reading a damaged .npz can raise: a truncated, empty, random or bit-flipped file
_UNREADABLE = (OSError, ValueError, KeyError, EOFError, TypeError, zipfile.BadZipFile)


def unreadable(path: Path, err: Exception, flag: str = "--resume") -> ConfigError:
    """The one-line error for a checkpoint ``err`` kept from being read, starting with ``flag``."""
    detail = str(err).strip().splitlines()[0] if str(err).strip() else ""
    advice = f"; it is damaged: delete {CHECKPOINT} and {HISTORY} to train the run from the start" \
        if flag == "--resume" else ""
    return ConfigError(f"{flag}: {path} cannot be read ({type(err).__name__}{': ' + detail if detail else ''})"
                       f"{advice}")


def _read(path: Path, flag: str, names=()) -> tuple[dict, list[str], dict[str, np.ndarray]]:
    """``(meta, stored array names, {name: array} for those of ``names``)``; ConfigError if unreadable."""
    try:
        with np.load(path) as data:
            meta = json.loads(str(data["meta"]))
            stored = [name for name in data.files if name != "meta"]
            arrays = {name: np.asarray(data[name]) for name in names if name in data.files}
        if not isinstance(meta, dict):
            raise TypeError(f"its meta is a {type(meta).__name__}")
    except _UNREADABLE as err:
        raise unreadable(path, err, flag) from None
    return meta, stored, arrays


def read_meta(path: Path, flag: str = "--resume") -> dict:
    """A checkpoint's ``meta`` (``done``, ``steps``, ``parts``, ...) without its arrays."""
    return _read(path, flag)[0]


def load_checkpoint(path: Path, template, flag: str = "--resume"):
    """``(runner, meta)``: a runner of ``template``'s structure restored from ``path``.

    ConfigError (one line, starting with ``flag``) when unreadable, or when structure, shapes or
    dtypes differ (another run's checkpoint, or an edited config.json)."""
    wanted = _named_leaves(template)
    meta, stored, leaves = _read(path, flag, wanted)
    renamed = {PREFIX + current_name(name[len(PREFIX):]): name for name in stored if name.startswith(PREFIX)}
    if any(new != old for new, old in renamed.items()):  # the earlier layout: read under this one's names
        _, _, old = _read(path, flag, [renamed[name] for name in wanted if name in renamed])
        stored, leaves = list(renamed), {new: old[name] for new, name in renamed.items() if name in old}
    positional = any(name.startswith("leaf_") for name in stored)
    if positional:
        raise ConfigError(f"{flag}: {path} was written by an older remidi, which stored the state's arrays by "
                          f"position; this version reads them by name: continue the run with the version that "
                          f"wrote it, or delete {CHECKPOINT} and {HISTORY} to train it from the start")
    missing = [name for name in wanted if name not in leaves]
    extra = [name for name in stored if name not in wanted]
    mismatch = None
    if missing or extra:
        mismatch = (f"it lacks {missing[0][len(PREFIX):]}" if missing else
                    f"it holds {extra[0][len(PREFIX):]}, which this run's state does not have")
    else:
        for name, want in wanted.items():
            leaf = leaves[name]
            if leaf.shape != want.shape and _unused(name, leaf, want):  # DR's unfilled buffer, stored in full
                leaves[name] = np.asarray(want)
                continue
            if leaf.shape != want.shape or leaf.dtype != want.dtype:
                mismatch = (f"{name[len(PREFIX):]} is {leaf.dtype}{list(leaf.shape)}, this run's state needs "
                            f"{want.dtype}{list(want.shape)}")
                break
    if mismatch is not None:
        raise ConfigError(f"{flag}: {path} does not match the run's config.json ({mismatch}): was config.json "
                          f"edited (seeds, algo, network sizes) or the checkpoint copied from another run?")
    treedef = jax.tree.structure(template)
    return jax.tree.unflatten(treedef, [jnp.asarray(leaves[name]) for name in wanted]), meta


def remove_stale_temporaries(ckpt: Path) -> list[Path]:
    """Delete the temporaries a killed write left beside ``ckpt`` (before a run writes); returns them."""
    return remove_temporaries(ckpt.parent, (ckpt.name, HISTORY))


def load_history(path: Path, meta: dict):
    """``(history, per_step)``: per-block metric dicts of ``checkpoint.history.npz``; ConfigError if
    missing, unreadable or incomplete."""
    if not all(key in meta for key in ("done", "steps", "num_blocks")):
        raise unreadable(path.with_name(CHECKPOINT), KeyError("its meta lacks done, steps or num_blocks"))
    if not path.exists():
        raise ConfigError(f"--resume: {path} is missing (the metrics logged before the checkpoint); restore it, or "
                          f"delete {path.with_name(CHECKPOINT)} to train the run from the start")
    try:
        with np.load(path) as saved:
            history, per_step = _unstack(saved, "h", len(meta["steps"])), _unstack(saved, "p", meta["num_blocks"])
    except _UNREADABLE as err:
        raise unreadable(path, err) from None
    for blocks in (history, per_step):  # every block the checkpoint counts
        held = sum(1 for block in blocks if block)
        if held < len(blocks):
            raise ConfigError(f"--resume: {path} holds the metrics of {held} of the {len(blocks)} blocks "
                              f"{path.with_name(CHECKPOINT)} needs: an older copy (was the folder copied while the "
                              f"run trained, or written by two processes?); restore the pair, or delete both to "
                              f"train the run from the start")
        lacking = next(((i, k) for i, block in enumerate(blocks) for k in blocks[0] if k not in block), None)
        if lacking is not None:  # (a later block may log more: a version of remidi that added a metric)
            raise ConfigError(f"--resume: {path} is damaged: block {lacking[0]} lacks {lacking[1]}, which block 0 "
                              f"logged; restore it, or delete it and {path.with_name(CHECKPOINT)} to train the run "
                              f"from the start")
    return history, per_step


def check_run(path: Path, meta: dict, run: dict | None) -> None:
    """ConfigError when ``meta["run"]`` (algorithm, seeds, config) differs from ``run``.

    Why: an edited config.json would otherwise resume silently wherever shapes still match. Keys on
    one side only are skipped (added config keys); checkpoints without a recorded run are not checked."""
    if run is None or not isinstance(meta.get("run"), dict):
        return
    was, now = flat_keys(meta["run"]), flat_keys(json.loads(json.dumps(run, default=_plain)))
    for key in was:
        if key in now and was[key] != now[key]:
            raise ConfigError(f"--resume: {path} does not match the run's config.json ({key}: {now[key]!r} there, "
                              f"{was[key]!r} when the checkpoint was written): was config.json edited? Put it back, "
                              f"or start a new run")


def save_run(ckpt: Path, runner, done, steps, history, per_step, parts=None, run: dict | None = None) -> None:
    """Write the run at ``done`` updates: metrics to :data:`HISTORY` first, then the runner to ``ckpt``.

    The runner is last because it marks the history complete. Its meta holds ``parts`` and ``run``
    (:func:`check_run`)."""
    arrays = {}
    for i, h in enumerate(history):
        arrays.update({f"h{i}|{k}": v for k, v in h.items()})
    for i, p in enumerate(per_step):
        arrays.update({f"p{i}|{k}": v for k, v in p.items()})
    atomic_write(ckpt.with_name(HISTORY), lambda fh: np.savez(fh, **arrays), binary=True)
    # the runner checkpoint is written last: it is what marks the history as complete
    meta = {"done": done, "steps": steps, "num_blocks": len(per_step)}
    if parts is not None:
        meta["parts"] = parts
    if run is not None:
        meta["run"] = run
    save_checkpoint(ckpt, runner, meta)


def history_blocks(path: Path) -> list[dict[str, np.ndarray]]:
    """Every block's metrics (``{name: f[S]}``) of a history file read alone; ConfigError if unreadable
    or a block is missing."""
    try:
        with np.load(path) as saved:
            count = 1 + max((int(k.split("|", 1)[0][1:]) for k in saved.files if k.startswith("h")), default=-1)
            blocks = _unstack(saved, "h", count)
    except _UNREADABLE as err:
        raise unreadable(path, err) from None
    if not blocks or not all(blocks):
        raise ConfigError(f"{path} lacks blocks: it holds {sum(map(bool, blocks))} of {len(blocks)}")
    return blocks


def _unstack(saved, prefix: str, count: int) -> list[dict[str, np.ndarray]]:
    out = [dict() for _ in range(count)]
    for key in saved.files:
        head, name = key.split("|", 1)
        if head[0] == prefix and int(head[1:]) < count:
            out[int(head[1:])][name] = saved[key]
    return out
