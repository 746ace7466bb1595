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

Replay rule
    How scores become replay weights is a :class:`ReplayRule`, named by ``buffer.prioritization``
    (:data:`REPLAY_RULES`: ``rank``, ``topk``; :func:`register_replay_rule` adds one, e.g.
    ``examples/my_replay_rule.py``). The rule's weights are normalised over the valid entries and
    mixed with staleness: ``(1-ρ)·rule + ρ·staleness`` (:func:`replay_weights`).
"""

from __future__ import annotations

import math
from functools import partial
from dataclasses import dataclass
from typing import Any, Sequence

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


@partial(jax.jit, static_argnames=("config",))
def can_replay(state: BufferState, config: BufferConfig) -> jax.Array:
    """``bool[]``: the buffer holds enough valid entries to replay: ``max(1, ⌈min_fill·capacity⌉)``
    (a tolerance of 1e-9 absorbs float error: ``0.7 * 10`` counts as 7, not 8)."""
    return jnp.sum(state.valid, dtype=jnp.int32) >= max(1, math.ceil(config.min_fill * config.capacity - 1e-9))


# ---------------------------------------------------------------------------- replay weights
class ReplayRule:
    """How the scores of a buffer become its replay weights, before staleness is mixed in.

    One method: ``weights(state, config, ranks) -> f32[capacity]``, non-negative where valid (the
    buffer normalises them over the valid entries; all zero: uniform). ``ranks`` i32[capacity]:
    1 = the highest score among valid entries (ties by lower index, NaN like −inf, invalid
    entries after the valid ones). Subclasses are frozen dataclasses (static under jit)."""

    def weights(self, state: BufferState, config: BufferConfig, ranks: jax.Array) -> jax.Array:
        raise NotImplementedError


@dataclass(frozen=True)
class RankReplay(ReplayRule):
    """PLR's rank prioritisation: ``(1/rank)^(1/temperature)``."""

    def weights(self, state, config, ranks):
        return (1.0 / ranks.astype(jnp.float32)) ** (1.0 / config.temperature)


@dataclass(frozen=True)
class TopKReplay(ReplayRule):
    """A softmax of score/temperature over the ``topk_k`` best valid entries, zero elsewhere
    (``jaxued``'s ``topk`` at temperature 1); uniform over them if none has a finite score."""

    def weights(self, state, config, ranks):
        top = (ranks <= config.topk_k) & state.valid  # ranks of valid entries are 1..size: k clipped to size
        logits = jnp.where(jnp.isnan(state.scores), -jnp.inf, state.scores) / config.temperature
        peak = jnp.max(jnp.where(top, logits, -jnp.inf))
        return jnp.where(top, jnp.where(jnp.isfinite(peak), jnp.exp(logits - jnp.where(jnp.isfinite(peak), peak, 0.0)),
                                        1.0), 0.0)


#: every ``buffer.prioritization``, by name (:func:`register_replay_rule` adds to it)
REPLAY_RULES: dict[str, ReplayRule] = {"rank": RankReplay(), "topk": TopKReplay()}


def register_replay_rule(name: str, rule: ReplayRule) -> None:
    """Make ``rule`` the replay rule ``buffer.prioritization=name`` selects."""
    if not isinstance(rule, ReplayRule):
        raise TypeError(f"register_replay_rule: {rule!r} is no ReplayRule")
    hash(rule)  # static under jit: a frozen dataclass
    REPLAY_RULES[name] = rule


def _normalise(x: jax.Array, valid: jax.Array) -> jax.Array:
    """``x`` on the valid entries over its sum (uniform over them if the sum is 0; zeros if none is valid)."""
    x = jnp.where(valid, x, 0.0)
    total = jnp.sum(x)
    uniform = valid / jnp.maximum(jnp.sum(valid), 1)
    return jnp.where(total > 0, x / jnp.where(total > 0, total, 1.0), uniform)


def _weights(state: BufferState, config: BufferConfig) -> tuple[jax.Array, jax.Array]:
    """``(weights f32[capacity], ranks i32[capacity])``: the replay distribution
    ``(1-ρ)·rule + ρ·staleness`` (zero on invalid entries; sums to 1 if any is valid) and the
    ranks it was computed from (:class:`ReplayRule`)."""
    cap = state.scores.shape[0]
    index = jnp.arange(cap)
    # lexsort: the last key is primary -> valid first, then descending score, then ascending index
    order = jnp.lexsort((index, -jnp.where(jnp.isnan(state.scores), -jnp.inf, state.scores), ~state.valid))
    ranks = jnp.zeros(cap, jnp.int32).at[order].set(jnp.arange(1, cap + 1, dtype=jnp.int32))
    by_score = _normalise(REPLAY_RULES[config.prioritization].weights(state, config, ranks), state.valid)
    staleness = _normalise((state.time - state.last_seen).astype(jnp.float32), state.valid)
    rho = config.staleness_coef
    return (1.0 - rho) * by_score + rho * staleness, ranks


@partial(jax.jit, static_argnames=("config",))
def replay_weights(state: BufferState, config: BufferConfig) -> jax.Array:
    """``f32[capacity]`` replay distribution ``(1-ρ)·rule + ρ·staleness``: zero on invalid
    entries, summing to 1 when any entry is valid, all zeros otherwise."""
    return _weights(state, config)[0]


# ---------------------------------------------------------------------------- replay
@partial(jax.jit, static_argnames=("config", "n"))
def sample_replay(state: BufferState, config: BufferConfig, rng: jax.Array, n: int):
    """``n`` entries drawn with replacement from :func:`replay_weights` (``n`` static); the clock
    advances by one and stamps them. Meaningful only when :func:`can_replay` (an empty buffer
    gives arbitrary invalid entries, so it can be traced inside ``lax.cond``/``vmap``).

    Returns ``(state, idxs i32[n], levels)``, every level leaf of leading dim ``[n]``."""
    weights = _weights(state, config)[0]
    cap = state.scores.shape[0]
    probs = jnp.where(jnp.any(state.valid), weights, 1.0 / cap)
    idxs = jax.random.choice(rng, cap, (n,), replace=True, p=probs).astype(jnp.int32)
    time = state.time + 1
    state = state.replace(time=time, last_seen=state.last_seen.at[idxs].set(time))
    return state, idxs, jax.tree.map(lambda x: x[idxs], state.levels)


def get_levels(state: BufferState, idxs: jax.Array):
    """The levels at ``idxs`` (``i32[n]`` or a scalar), leaves of leading dim ``[n]``."""
    return jax.tree.map(lambda x: x[idxs], state.levels)


def _known_extras(state: BufferState, extras) -> dict:
    """``extras`` as a dict; ValueError for a name the buffer does not track."""
    extras = dict(extras or {})
    unknown = sorted(set(extras) - set(state.extras))
    if unknown:
        raise ValueError(f"unknown buffer extras {unknown}; tracked: {sorted(state.extras)}")
    return extras


@jax.jit
def update_scores(state: BufferState, idxs: jax.Array, scores: jax.Array, extras=None) -> BufferState:
    """The scores ``f32[n]`` (and the given extras ``{name: f32[n]}``) of the entries ``idxs``
    ``i32[n]`` after they were replayed. A negative index (the ``-1`` of a rejected insertion) is
    ignored; of a repeated index the last occurrence wins, except for ``max_*`` extras, which
    keep the maximum of the stored value and every given one. The clock and ``last_seen`` stay
    (:func:`sample_replay` stamped them)."""
    extras = _known_extras(state, extras)
    idxs = jnp.asarray(idxs, jnp.int32)
    n, cap = idxs.shape[0], state.scores.shape[0]
    later = jnp.arange(n)[None, :] > jnp.arange(n)[:, None]
    last = ~jnp.any(later & (idxs[:, None] == idxs[None, :]), axis=1)  # idxs[i] does not occur again later
    target = jnp.where(last & (idxs >= 0), idxs, cap)  # cap: dropped
    every = jnp.where(idxs >= 0, idxs, cap)  # every occurrence, for running maxima
    new_extras = dict(state.extras)
    for name, values in extras.items():
        column = state.extras[name]
        values = jnp.asarray(values, column.dtype)
        new_extras[name] = (column.at[every].max(values, mode="drop") if name.startswith(RUNNING_MAX_PREFIX)
                            else column.at[target].set(values, mode="drop"))
    return state.replace(scores=state.scores.at[target].set(jnp.asarray(scores, jnp.float32), mode="drop"),
                         extras=new_extras)


# ---------------------------------------------------------------------------- insertion
def _insert(config: BufferConfig, keep_higher: bool, state: BufferState, item):
    """:func:`insert` of ``item = (level, score, extras)`` (a ``lax.scan`` body): ``(state,
    (inserted bool[], idx i32[]))``."""
    level, score, extras = item
    extras = _known_extras(state, extras)
    score = jnp.asarray(score, jnp.float32)
    cap = state.scores.shape[0]
    acceptable = ~jnp.isnan(score) & (score > -jnp.inf)
    if config.duplicate_check:  # the first valid entry whose leaves all equal the level's
        equal = state.valid
        for stored, new in zip(jax.tree.leaves(state.levels), jax.tree.leaves(level)):
            eq = stored == jnp.asarray(new, stored.dtype)
            equal = equal & jnp.all(eq.reshape(eq.shape[0], -1), axis=1)
        is_duplicate, duplicate_idx = jnp.any(equal), jnp.argmax(equal).astype(jnp.int32)
    else:
        is_duplicate, duplicate_idx = jnp.zeros((), bool), jnp.zeros((), jnp.int32)
    full = jnp.sum(state.valid, dtype=jnp.int32) >= cap
    # the victim of a full buffer: the valid entry of lowest replay weight, ties to the worst rank
    weights, ranks = _weights(state, config)
    lowest = jnp.min(jnp.where(state.valid, weights, jnp.inf))
    victim = jnp.argmax(jnp.where(state.valid & (weights <= lowest), ranks, 0)).astype(jnp.int32)
    new_idx = jnp.where(full, victim, jnp.argmin(state.valid)).astype(jnp.int32)
    room = ~full | (score > jnp.where(jnp.isnan(state.scores), -jnp.inf, state.scores)[victim])

    inserted = acceptable & ~is_duplicate & room
    updated = acceptable & is_duplicate
    written = inserted | updated
    idx = jnp.where(written, jnp.where(is_duplicate, duplicate_idx, new_idx), -1).astype(jnp.int32)
    target = jnp.where(written, idx, cap)  # cap: out of bounds, dropped
    new_extras = {}
    for name, column in state.extras.items():
        stored = column[duplicate_idx]
        if name not in extras:
            value = jnp.where(updated, stored, 0.0)
        elif name.startswith(RUNNING_MAX_PREFIX):
            value = jnp.where(updated, jnp.maximum(stored, jnp.asarray(extras[name], column.dtype)),
                              jnp.asarray(extras[name], column.dtype))
        else:
            value = jnp.asarray(extras[name], column.dtype)
        new_extras[name] = column.at[target].set(jnp.asarray(value, column.dtype), mode="drop")
    if keep_higher:
        score = jnp.where(updated, jnp.maximum(state.scores[duplicate_idx], score), score)
    state = state.replace(
        levels=jax.tree.map(lambda arr, x: arr.at[target].set(jnp.asarray(x, arr.dtype), mode="drop"),
                            state.levels, level),
        scores=state.scores.at[target].set(score, mode="drop"),
        last_seen=state.last_seen.at[target].set(state.time, mode="drop"),
        valid=state.valid.at[target].set(True, mode="drop"),
        extras=new_extras,
    )
    return state, (inserted, idx)


@partial(jax.jit, static_argnames=("config", "keep_higher"))
def insert(state: BufferState, config: BufferConfig, level, score, extras=None, keep_higher: bool = False):
    """Try to insert one level (no leading capacity axis) with ``score`` f32[] and ``extras``
    ``{name: f32[]}``; a written entry is stamped with the current time (no clock tick). In order:

      * a score of ``-inf`` or NaN is never written (not even into an empty slot);
      * with ``duplicate_check``, a level equal (all leaves) to a valid entry updates that entry's
        score (``keep_higher``: to the higher of the two), given extras (``max_*``: their
        maximum) and ``last_seen`` instead (``inserted = False``, ``idx`` = that entry);
      * into the first empty slot if there is one;
      * if full, it replaces the entry of lowest replay weight (ties: lowest-ranked), only if its
        score is strictly higher than that entry's.

    On a new entry missing extras are 0, on a duplicate update they are kept. Returns
    ``(state, inserted bool[], idx i32[])``, ``idx`` -1 if nothing was written."""
    state, (inserted, idx) = _insert(config, keep_higher, state, (level, score, extras))
    return state, inserted, idx


@partial(jax.jit, static_argnames=("config", "keep_higher"))
def insert_batch(state: BufferState, config: BufferConfig, levels, scores, extras=None, keep_higher: bool = False):
    """Advance the clock by one, then :func:`insert` the ``n`` levels (leaves [n, ...]) with
    ``scores`` f32[n] and ``extras`` ``{name: f32[n]}`` one after another (``lax.scan``: later
    insertions see earlier ones). Returns ``(state, inserted bool[n], idxs i32[n])``."""
    scores = jnp.asarray(scores, jnp.float32)
    state, (inserted, idxs) = jax.lax.scan(partial(_insert, config, keep_higher), state.replace(time=state.time + 1),
                                           (levels, scores, _known_extras(state, extras)))
    return state, inserted, idxs


# ---------------------------------------------------------------------------- K buffers
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
