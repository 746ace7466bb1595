"""Kinetix's hand-made held-out levels, loaded once and cached as arrays.

Kinetix's loader rebuilds each JSON level eagerly, seconds per level (71 s for the s set, 341 s
for l on a loaded 2-core CPU), so stacked levels are cached in
``<cache>/kinetix-<version>-<train size>-<level size>.npz`` (``$REMIDI_KINETIX_CACHE``, else
``~/.cache/remidi/kinetix``; a file of other shapes is rebuilt)."""

from __future__ import annotations

import importlib.metadata
import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from kinetix.environment import create_empty_env, static_env_params_from_size

from remidi.envs.kinetix_names import HELD_OUT, SIZES, natural_key

def level_files(size: str) -> list[str]:
    """The held-out level files Kinetix ships for ``size`` (names without ``.json``), in natural order."""
    from kinetix.util.saving import BASE_DIR

    return sorted((f[:-5] for f in os.listdir(os.path.join(BASE_DIR, size)) if f.endswith(".json")), key=natural_key)


def cache_dir() -> Path:
    return Path(os.environ.get("REMIDI_KINETIX_CACHE") or Path.home() / ".cache" / "remidi" / "kinetix")


def _load_json(names: list[str], level_size: str, static):
    from kinetix.util.saving import load_evaluation_levels

    levels, _ = load_evaluation_levels([f"{level_size}/{n}" for n in names], static_env_params_override=static)
    return levels


def stacked_levels(train_size: str, level_size: str, static):
    """The held-out levels of ``level_size`` as one ``EnvState`` (leaves ``[L, ...]``) padded to ``static``."""
    names = list(HELD_OUT[level_size])
    example = jax.eval_shape(lambda: create_empty_env(static))
    leaves, treedef = jax.tree.flatten(example)
    version = importlib.metadata.version("kinetix-env")
    path = cache_dir() / f"kinetix-{version}-{train_size}-{level_size}.npz"
    if path.exists():
        with np.load(path) as saved:
            arrays = [saved[f"leaf_{i}"] for i in range(len(leaves))] if f"leaf_{len(leaves) - 1}" in saved else []
            stored = list(saved["names"]) if "names" in saved else []
        fits = stored == names and len(arrays) == len(leaves) and all(
            a.shape == (len(names),) + tuple(x.shape) and a.dtype == x.dtype for a, x in zip(arrays, leaves))
        if fits:
            return jax.tree.unflatten(treedef, [jnp.asarray(a) for a in arrays])
    levels = _load_json(names, level_size, static)
    levels = jax.tree.unflatten(treedef, [jnp.asarray(a, x.dtype) for a, x in zip(jax.tree.leaves(levels), leaves)])
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix(f".{os.getpid()}.tmp.npz")
    np.savez(partial, names=np.asarray(names), **{f"leaf_{i}": np.asarray(a) for i, a in enumerate(jax.tree.leaves(levels))})
    os.replace(partial, path)
    return levels


def held_out_sets(train_size: str, static=None) -> dict:
    """``{"<size>_<name>": level batch of one}``: the held-out levels of ``train_size`` and of every
    smaller size, padded to ``train_size``."""
    static = static if static is not None else static_env_params_from_size(train_size)
    sets = {}
    for level_size in SIZES[:SIZES.index(train_size) + 1]:
        levels = stacked_levels(train_size, level_size, static)
        for i, name in enumerate(HELD_OUT[level_size]):
            sets[f"{level_size}_{name}"] = jax.tree.map(lambda x: x[i:i + 1], levels)
    return sets
