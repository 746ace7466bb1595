"""Checkpoints of a UED run: the runner (``checkpoint.npz``) and the metrics logged so far
(``checkpoint.history.npz``), written atomically, read back with one-line errors for every way
a file can be damaged or belong to another run.

The runner's arrays are stored by their tree path (``leaf:.train_state.params['params']...``,
``jax.tree_util.keystr``), so a checkpoint names what it holds and a mismatch names the part of
the state that differs. Checkpoints of remidi before this format stored arrays by position
(``leaf_0``, ``leaf_1``, ...); they are refused with a one-line error saying so.

The runner holds one state per component (``.learner``, ``.adversary``, ``.tracker``). A
checkpoint of the earlier layout, one runner field per feature (``.train_state``, ``.buffers``,
``.belief``, ...), loads through one rename, :data:`RENAMES` (:func:`current_name`). A part of
the state that earlier versions allocated and this one leaves empty (:data:`UNUSED`: DR's level
buffer, which it never fills) is read as this run's empty part where the checkpoint holds it
unfilled (every value zero)."""

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


#: parts of the runner, by tree path, that earlier versions allocated in full for runs that never
#: fill them: DR's adversary held one empty buffer of ``buffer.capacity`` levels (a checkpoint of
#: a maze run's 4000 levels: most of its size); it now holds the buffer without a slot
#: (``engine/adversaries/base.py``, ``no_buffers``). Such a checkpoint's unfilled (all-zero) leaves
#: there are read as this run's empty ones.
UNUSED = (".adversary.buffers",)


def _unused(name: str, stored: np.ndarray, want) -> bool:
    """The stored leaf ``name`` (``PREFIX`` + tree path) is an earlier version's unfilled copy of
    a part :data:`UNUSED` that this run's state ``want`` leaves empty (no element)."""
    path = name[len(PREFIX):]
    return (any(path == p or path.startswith((p + ".", p + "[")) for p in UNUSED) and np.size(want) == 0
            and stored.dtype == want.dtype and not np.any(stored))


def current_name(path: str) -> str:
    """A runner leaf's tree path (``jax.tree_util.keystr``) in this layout: one of the earlier
    layout renamed by :data:`RENAMES`, any other unchanged."""
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
    """JSON for what ``json`` does not know in a meta: NumPy and JAX scalars and arrays (a config
    given through the Python API with ``np.float32`` values), anything else by its text."""
    return value.tolist() if hasattr(value, "tolist") else str(value)


# what reading a damaged .npz can raise: a truncated, empty, random or bit-flipped file
_UNREADABLE = (OSError, ValueError, KeyError, EOFError, TypeError, zipfile.BadZipFile)


def unreadable(path: Path, err: Exception, flag: str = "--resume") -> ConfigError:
    """The one-line error for a checkpoint file that ``err`` (one of :data:`_UNREADABLE`) kept from
    being read, starting with ``flag`` (with ``--resume``: how to start the run again)."""
    detail = str(err).strip().splitlines()[0] if str(err).strip() else ""
    advice = f"; it is damaged: delete {CHECKPOINT} and {HISTORY} to train the run from the start" \
        if flag == "--resume" else ""
    return ConfigError(f"{flag}: {path} cannot be read ({type(err).__name__}{': ' + detail if detail else ''})"
                       f"{advice}")


def _read(path: Path, flag: str, names=()) -> tuple[dict, list[str], dict[str, np.ndarray]]:
    """``(meta, the names of the stored arrays, {name: array} for those of ``names`` stored)`` from a
    checkpoint file; ConfigError (:func:`unreadable`) when it cannot be read or its meta is no dict."""
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
    """The ``meta`` a checkpoint was saved with (``done``, ``steps``, ``parts``, ...), without reading
    its arrays; ConfigError (one line, starting with ``flag``) when the file cannot be read."""
    return _read(path, flag)[0]


def load_checkpoint(path: Path, template, flag: str = "--resume"):
    """Restore a runner with the structure of ``template`` from ``path``; returns ``(runner, meta)``.

    Raises ConfigError (one line, starting with ``flag`` and naming the file) when the file cannot
    be read, or when it does not hold a runner of ``template``'s structure, shapes and dtypes (a
    checkpoint of another run, or a config.json edited since: seeds, algorithm or network sizes)."""
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
    """Delete the hidden temporary files a killed checkpoint write left beside ``ckpt``
    (:func:`remidi.files.remove_temporaries`). Called when a run starts or resumes, before it
    writes; returns what was removed."""
    return remove_temporaries(ckpt.parent, (ckpt.name, HISTORY))


def load_history(path: Path, meta: dict):
    """The metrics a checkpoint's run logged so far (``checkpoint.history.npz``): ``(history,
    per_step)``, lists of per-block dicts. ConfigError (one line) when missing or unreadable."""
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
    """ConfigError (one line) when the run a checkpoint was written for (``meta["run"]``: its
    algorithm, seeds and config, :func:`save_run`) differs from ``run``, the one config.json
    describes now: an edited config.json would otherwise resume silently wherever the state's
    shapes still match (relabelled seeds, a learning rate, ``num_updates``, dr for plr). Keys
    only one side has are not compared (a version of remidi that added a config key reads an
    older run with its default); checkpoints written before runs were recorded are not checked."""
    if run is None or not isinstance(meta.get("run"), dict):
        return
    was, now = flat_keys(meta["run"]), flat_keys(json.loads(json.dumps(run, default=_plain)))
    for key in was:
        if key in now and was[key] != now[key]:
            raise ConfigError(f"--resume: {path} does not match the run's config.json ({key}: {now[key]!r} there, "
                              f"{was[key]!r} when the checkpoint was written): was config.json edited? Put it back, "
                              f"or start a new run")


def save_run(ckpt: Path, runner, done, steps, history, per_step, parts=None, run: dict | None = None) -> None:
    """Write a run's state at ``done`` updates: the metrics logged so far (``steps``, ``history``
    and ``per_step``, lists of per-block dicts) to :data:`HISTORY`, then the runner to ``ckpt``
    (its meta also holds ``parts``, the run's parts so far: :func:`remidi.engine.run.driver.drive`,
    and ``run``, the algorithm, seeds and config it trains: :func:`check_run`)."""
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
    """Every block's metrics (``{name: f[S]}``, in block order) that a ``checkpoint.history.npz``
    holds, read without its checkpoint (an unfinished run whose checkpoint stayed elsewhere);
    ConfigError (one line) when it cannot be read or a block is missing."""
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
