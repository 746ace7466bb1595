"""A pure-functional, jit-able PLR⊥ level buffer (robust prioritized level replay).

The buffer is a fixed-capacity table of levels with a score, a last-seen time stamp, a validity
flag and optional per-level extras. Every function is pure and jit-able with the
:class:`~remidi.engine.config.BufferConfig` static; no Python control flow depends on traced
values, so a :class:`BufferState` can be ``vmap``-ed over seeds and K of them stacked along a
leading axis and indexed with a traced integer (ReMiDi's sequence: :func:`stack_buffers`,
:func:`select_buffer`, :func:`replace_buffer`). The public functions are ``jax.jit``-wrapped
(``config``, ``n`` static): compiled once per config and shapes, inlined under an outer jit.

Empty slots
    ``valid = False``, score 0, ``last_seen = 0``, zero extras and level; never sampled, ignored.

Clock
    ``state.time`` counts the train steps that touched the buffer. :func:`sample_replay` (a
    replay step) and :func:`insert_batch` (fresh levels) advance it by one, then stamp every entry
    they touch (sampled, inserted, updated as a duplicate) with it: staleness ``time - last_seen``
    0. :func:`insert` (one level; stamps the current time) and :func:`update_scores` do not.

Extras
    Per-level extras (``extra_names`` of :func:`init_buffer`) are written by :func:`insert` and
    :func:`update_scores`. An extra whose name starts with ``max_`` (e.g. ``max_return``, MaxMC's
    record of the best return ever seen on a level) is a running maximum: when an existing entry
    is updated (a duplicate re-insertion or :func:`update_scores`) it keeps the element-wise
    maximum of its stored and new values (over every occurrence in one :func:`update_scores`
    call), so the record never goes down while the entry lives. Every other extra is overwritten
    by the new value. A new entry simply takes the given values.

Scores
    Higher is replayed more. A level scored ``-inf`` or NaN is never inserted (``+inf`` is); an
    entry later set to NaN by :func:`update_scores` ranks like ``-inf``.
"""

from __future__ import annotations

import math
from functools import partial
from typing import Any, Mapping, Sequence

import flax.struct
import jax
import jax.numpy as jnp

from remidi.engine.config import BufferConfig, validate_buffer_config

RUNNING_MAX_PREFIX = "max_"  # extras named max_* keep their maximum on updates (module docstring)

@flax.struct.dataclass
class BufferState:
    """The buffer's contents; a pytree whose leaves are all JAX arrays.

    Attributes:
        levels: level pytree, every leaf with leading dim ``[capacity]``.
        scores: ``f32[capacity]``.
        last_seen: ``i32[capacity]``, the clock value at which each entry was last inserted,
            updated as a duplicate, or sampled.
        valid: ``bool[capacity]``.
        extras: ``{name: f32[capacity]}`` per-level extras, e.g. ``{"max_return": ...}``.
        time: ``i32[]``, the buffer's clock.
    """

    levels: Any
    scores: jax.Array
    last_seen: jax.Array
    valid: jax.Array
    extras: dict
    time: jax.Array


def init_buffer(config: BufferConfig, example_level, extra_names: Sequence[str] = ()) -> BufferState:
    """An empty buffer whose levels have the structure, shapes and dtypes of ``example_level``.

    Validates ``config`` first. Every level leaf becomes zeros of shape ``[capacity, *leaf.shape]``;
    scores, ``last_seen``, extras and ``time`` start at 0 and ``valid`` at False.
    """
    validate_buffer_config(config)
    if isinstance(extra_names, str):
        raise TypeError(f"extra_names must be a sequence of names, not the string {extra_names!r}")
    cap = config.capacity

    def zeros_like_stacked(leaf):
        leaf = jnp.asarray(leaf)
        return jnp.zeros((cap, *leaf.shape), leaf.dtype)

    return BufferState(
        levels=jax.tree.map(zeros_like_stacked, example_level),
        scores=jnp.zeros(cap, jnp.float32),
        last_seen=jnp.zeros(cap, jnp.int32),
        valid=jnp.zeros(cap, bool),
        extras={name: jnp.zeros(cap, jnp.float32) for name in extra_names},
        time=jnp.zeros((), jnp.int32),
    )


def without_slots(state: BufferState) -> BufferState:
    """``state`` with none of its slots (every per-level leaf [0, ...]; the clock kept): the buffer
    of an adversary that keeps no level, the fields of a buffer without its storage."""
    cut = lambda x: x[:0]  # noqa: E731
    return state.replace(levels=jax.tree.map(cut, state.levels), scores=cut(state.scores),
                         last_seen=cut(state.last_seen), valid=cut(state.valid),
                         extras={name: cut(v) for name, v in state.extras.items()})


@jax.jit
def size(state: BufferState) -> jax.Array:
    """Number of valid entries, ``i32[]``."""
    return jnp.sum(state.valid, dtype=jnp.int32)


def min_replay_size(config: BufferConfig) -> int:
    """Smallest number of valid entries that allows replay: ``max(1, ceil(min_fill·capacity))``.

    A tolerance of 1e-9 absorbs float error (``0.7 * 10`` counts as 7, not 8).
    """
    return max(1, math.ceil(config.min_fill * config.capacity - 1e-9))


@partial(jax.jit, static_argnames=("config",))
def can_replay(state: BufferState, config: BufferConfig) -> jax.Array:
    """``bool[]``: the buffer holds at least :func:`min_replay_size` valid entries."""
    return size(state) >= min_replay_size(config)


def _effective_scores(state: BufferState) -> jax.Array:
    """``f32[capacity]`` scores with NaN read as ``-inf``."""
    return jnp.where(jnp.isnan(state.scores), -jnp.inf, state.scores)


def _ranks(state: BufferState) -> jax.Array:
    """``i32[capacity]``: rank 1 = highest score among valid entries, ties by lower index.

    Valid entries get ranks ``1..size``; invalid entries get the ranks after those. NaN scores
    rank like ``-inf``.
    """
    cap = state.scores.shape[0]
    index = jnp.arange(cap)
    # lexsort: last key is primary -> valid first, then descending score, then ascending index.
    order = jnp.lexsort((index, -_effective_scores(state), ~state.valid))
    return jnp.zeros(cap, jnp.int32).at[order].set(jnp.arange(1, cap + 1, dtype=jnp.int32))


def _normalise_over_valid(x: jax.Array, valid: jax.Array) -> jax.Array:
    """``x`` restricted to valid entries, divided by its sum; uniform over valid if the sum is 0.

    All zeros when nothing is valid.
    """
    x = jnp.where(valid, x, 0.0)
    total = jnp.sum(x)
    uniform = valid / jnp.maximum(jnp.sum(valid), 1)
    return jnp.where(total > 0, x / jnp.where(total > 0, total, 1.0), uniform)


def _score_weights(state: BufferState, config: BufferConfig, ranks: jax.Array) -> jax.Array:
    """:func:`score_weights` given the :func:`_ranks` of ``state``."""
    if config.prioritization == "rank":
        raw = (1.0 / ranks.astype(jnp.float32)) ** (1.0 / config.temperature)
    else:  # "topk": ranks of valid entries are 1..size, so this is the k best, k clipped to size
        top = (ranks <= config.topk_k) & state.valid
        logits = _effective_scores(state) / config.temperature
        peak = jnp.max(jnp.where(top, logits, -jnp.inf))
        # a softmax over the top k (exp(-inf) = 0); uniform over them if none has a finite score
        raw = jnp.where(top, jnp.where(jnp.isfinite(peak), jnp.exp(logits - jnp.where(jnp.isfinite(peak), peak, 0.0)),
                                       1.0), 0.0)
    return _normalise_over_valid(raw, state.valid)


@partial(jax.jit, static_argnames=("config",))
def score_weights(state: BufferState, config: BufferConfig) -> jax.Array:
    """``f32[capacity]`` score part of the replay distribution (sums to 1 over valid entries)."""
    return _score_weights(state, config, _ranks(state))


@jax.jit
def staleness_weights(state: BufferState) -> jax.Array:
    """``f32[capacity]`` ∝ ``time - last_seen`` over valid entries (uniform over valid if all 0)."""
    staleness = (state.time - state.last_seen).astype(jnp.float32)
    return _normalise_over_valid(staleness, state.valid)


def _replay_weights(state: BufferState, config: BufferConfig, ranks: jax.Array) -> jax.Array:
    """:func:`replay_weights` given the :func:`_ranks` of ``state``."""
    rho = config.staleness_coef
    return (1.0 - rho) * _score_weights(state, config, ranks) + rho * staleness_weights(state)


@partial(jax.jit, static_argnames=("config",))
def replay_weights(state: BufferState, config: BufferConfig) -> jax.Array:
    """``f32[capacity]`` replay distribution ``(1-ρ)·score + ρ·staleness``.

    Zero on invalid entries; sums to 1 when any entry is valid, all zeros otherwise.
    """
    return _replay_weights(state, config, _ranks(state))


def _tick(state: BufferState) -> BufferState:
    """Advance the clock by one."""
    return state.replace(time=state.time + 1)


@partial(jax.jit, static_argnames=("config", "n"))
def sample_replay(state: BufferState, config: BufferConfig, rng: jax.Array, n: int):
    """Sample ``n`` entries with replacement from :func:`replay_weights` (``n`` static).

    Advances the clock by one and sets ``last_seen`` of the sampled entries to the new time.
    Only meaningful when :func:`can_replay`; on an empty buffer it returns arbitrary (invalid)
    entries without failing, so it may be traced inside ``lax.cond``/``vmap``.

    Returns:
        ``(state, idxs i32[n], levels)`` with every level leaf of leading dim ``[n]``.
    """
    weights = replay_weights(state, config)
    cap = state.scores.shape[0]
    probs = jnp.where(jnp.any(state.valid), weights, 1.0 / cap)
    idxs = jax.random.choice(rng, cap, (n,), replace=True, p=probs).astype(jnp.int32)
    state = _tick(state)
    state = state.replace(last_seen=state.last_seen.at[idxs].set(state.time))
    return state, idxs, get_levels(state, idxs)


def get_levels(state: BufferState, idxs: jax.Array):
    """The levels at ``idxs`` (``i32[n]`` or a scalar), leaves of leading dim ``[n]``."""
    return jax.tree.map(lambda x: x[idxs], state.levels)


def _is_running_max(name: str) -> bool:
    return name.startswith(RUNNING_MAX_PREFIX)


def _check_extra_names(state: BufferState, extras: Mapping[str, Any] | None) -> dict:
    """``extras`` as a dict, raising ``ValueError`` on a name the buffer does not track."""
    extras = dict(extras or {})
    unknown = sorted(set(extras) - set(state.extras))
    if unknown:
        raise ValueError(f"unknown buffer extras {unknown}; tracked: {sorted(state.extras)}")
    return extras


def _last_occurrence(idxs: jax.Array) -> jax.Array:
    """``bool[n]``: whether ``idxs[i]`` does not occur again at a later position."""
    n = idxs.shape[0]
    later = jnp.arange(n)[None, :] > jnp.arange(n)[:, None]
    return ~jnp.any(later & (idxs[:, None] == idxs[None, :]), axis=1)


@jax.jit
def update_scores(state: BufferState, idxs: jax.Array, scores: jax.Array, extras=None) -> BufferState:
    """Set the scores (and given extras) of entries ``idxs`` after they were replayed.

    Args:
        idxs: ``i32[n]`` entry indices; negative indices (e.g. the ``-1`` of a rejected
            insertion) are ignored, and for a repeated index the last occurrence wins.
        scores: ``f32[n]``.
        extras: optional ``{name: f32[n]}``; extras not given are left unchanged, ``max_*``
            extras keep the maximum of the stored value and every given one.

    Does not move the clock or change ``last_seen`` (:func:`sample_replay` already stamped).
    """
    extras = _check_extra_names(state, extras)
    idxs = jnp.asarray(idxs, jnp.int32)
    cap = state.scores.shape[0]
    target = jnp.where(_last_occurrence(idxs) & (idxs >= 0), idxs, cap)  # cap: dropped
    every = jnp.where(idxs >= 0, idxs, cap)  # every occurrence, for running maxima

    def scatter(arr, values):
        return arr.at[target].set(jnp.asarray(values, arr.dtype), mode="drop")

    def update_extra(name, arr):
        if name not in extras:
            return arr
        if _is_running_max(name):
            return arr.at[every].max(jnp.asarray(extras[name], arr.dtype), mode="drop")
        return scatter(arr, extras[name])

    new_extras = {k: update_extra(k, v) for k, v in state.extras.items()}
    return state.replace(scores=scatter(state.scores, scores), extras=new_extras)


def _find_duplicate(state: BufferState, level) -> tuple[jax.Array, jax.Array]:
    """``(found bool[], idx i32[])``: the first valid entry whose leaves all equal ``level``'s."""
    def leaf_equal(stored, new):
        eq = stored == jnp.asarray(new, stored.dtype)
        return jnp.all(eq.reshape(eq.shape[0], -1), axis=1)

    equal = jax.tree.reduce(jnp.logical_and, jax.tree.map(leaf_equal, state.levels, level))
    match = equal & state.valid
    return jnp.any(match), jnp.argmax(match).astype(jnp.int32)


def _lowest_weight_index(state: BufferState, config: BufferConfig) -> jax.Array:
    """``i32[]``: the valid entry with the lowest replay weight; ties go to the worst rank."""
    ranks = _ranks(state)
    weights = _replay_weights(state, config, ranks)
    lowest = jnp.min(jnp.where(state.valid, weights, jnp.inf))
    candidates = state.valid & (weights <= lowest)
    return jnp.argmax(jnp.where(candidates, ranks, 0)).astype(jnp.int32)


@partial(jax.jit, static_argnames=("config", "keep_higher"))
def insert(state: BufferState, config: BufferConfig, level, score, extras=None, keep_higher: bool = False):
    """Try to insert one level; stamps a written entry with the current time (no clock tick).

    Rules, in order:
      * a score of ``-inf`` or NaN is never written (not even into an empty slot);
      * with ``duplicate_check``, a level equal (all leaves) to a valid entry updates that entry's
        score (``keep_higher``: to the higher of the two), given extras (``max_*`` extras keep
        their maximum) and ``last_seen`` instead (``inserted = False``, ``idx`` = that entry);
      * if there is an empty slot the level goes into the first one;
      * if full, it replaces the entry of lowest replay weight (ties: lowest-ranked), only if its
        score is strictly higher than that entry's score.

    Args:
        level: one level (no leading capacity axis).
        score: ``f32[]``.
        extras: optional ``{name: f32[]}``; on a new entry missing extras are 0, on a duplicate
            update they are left unchanged.

    Returns:
        ``(state, inserted bool[], idx i32[])``; ``idx`` is the written entry, or ``-1`` if
        nothing was written.
    """
    extras = _check_extra_names(state, extras)
    score = jnp.asarray(score, jnp.float32)
    cap = state.scores.shape[0]
    acceptable = ~jnp.isnan(score) & (score > -jnp.inf)

    if config.duplicate_check:
        is_duplicate, duplicate_idx = _find_duplicate(state, level)
    else:
        is_duplicate, duplicate_idx = jnp.zeros((), bool), jnp.zeros((), jnp.int32)

    full = size(state) >= cap
    victim = _lowest_weight_index(state, config)
    new_idx = jnp.where(full, victim, jnp.argmin(state.valid)).astype(jnp.int32)
    room = ~full | (score > _effective_scores(state)[victim])

    inserted = acceptable & ~is_duplicate & room
    updated = acceptable & is_duplicate
    written = inserted | updated
    idx = jnp.where(written, jnp.where(is_duplicate, duplicate_idx, new_idx), -1).astype(jnp.int32)
    target = jnp.where(written, idx, cap)  # cap: out of bounds, dropped

    def scatter(arr, value):
        return arr.at[target].set(jnp.asarray(value, arr.dtype), mode="drop")

    def new_extra(name, column):
        stored = column[duplicate_idx]
        if name not in extras:
            return jnp.where(updated, stored, 0.0)
        given = jnp.asarray(extras[name], column.dtype)
        if _is_running_max(name):
            return jnp.where(updated, jnp.maximum(stored, given), given)
        return given

    if keep_higher:
        score = jnp.where(updated, jnp.maximum(state.scores[duplicate_idx], score), score)
    state = state.replace(
        levels=jax.tree.map(scatter, state.levels, level),
        scores=scatter(state.scores, score),
        last_seen=scatter(state.last_seen, state.time),
        valid=scatter(state.valid, True),
        extras={k: scatter(v, new_extra(k, v)) for k, v in state.extras.items()},
    )
    return state, inserted, idx


@partial(jax.jit, static_argnames=("config", "keep_higher"))
def insert_batch(state: BufferState, config: BufferConfig, levels, scores, extras=None, keep_higher: bool = False):
    """Advance the clock by one, then :func:`insert` the ``n`` levels one after another.

    Later insertions see earlier ones (``lax.scan``); ``keep_higher``: as in :func:`insert`.

    Args:
        levels: level pytree with leaves of leading dim ``[n]``.
        scores: ``f32[n]``.
        extras: optional ``{name: f32[n]}``.

    Returns:
        ``(state, inserted bool[n], idxs i32[n])`` (``-1`` where nothing was written).
    """
    extras = _check_extra_names(state, extras)

    def step(carry, item):
        level, score, extra = item
        carry, inserted, idx = insert(carry, config, level, score, extra, keep_higher)
        return carry, (inserted, idx)

    scores = jnp.asarray(scores, jnp.float32)
    state, (inserted, idxs) = jax.lax.scan(step, _tick(state), (levels, scores, extras))
    return state, inserted, idxs


def valid_levels(state: BufferState):
    """``(levels [capacity, ...], valid bool[capacity])``: every stored level and whether it is one."""
    return state.levels, state.valid


def stack_buffers(states: Sequence[BufferState]) -> BufferState:
    """Stack K buffers of identical structure along a new leading axis ``[K, ...]``."""
    return jax.tree.map(lambda *xs: jnp.stack(xs), *states)


def select_buffer(stacked: BufferState, k) -> BufferState:
    """Buffer ``k`` (an int or a traced ``i32[]``) of a stack made by :func:`stack_buffers`."""
    return jax.tree.map(lambda x: x[k], stacked)


def replace_buffer(stacked: BufferState, k, state: BufferState) -> BufferState:
    """The stack with buffer ``k`` (an int or a traced ``i32[]``) replaced by ``state``."""
    return jax.tree.map(lambda xs, x: xs.at[k].set(x), stacked, state)
