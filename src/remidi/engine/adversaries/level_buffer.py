"""A pure-functional, jit-able PLR⊥ level buffer.

A fixed-capacity table of levels, each with a score, a last-seen stamp, a validity flag and
optional extras. No Python control flow depends on traced values, so a :class:`BufferState` can
be ``vmap``-ed over seeds, and K of them stacked and indexed with a traced integer
(:func:`stack_buffers`, :func:`select_buffer`, :func:`replace_buffer`). Public functions are
``jax.jit``-wrapped with ``config`` and ``n`` static.

Empty slots
    ``valid = False``, all zeros; never sampled.

Clock
    ``state.time`` counts the train steps that touched the buffer. :func:`sample_replay` and
    :func:`insert_batch` advance it by one, then stamp every entry they touch (staleness 0).
    :func:`insert` (stamps the current time) and :func:`update_scores` do not advance it.

Extras
    Written by :func:`insert` and :func:`update_scores`. An extra named ``max_*`` (MaxMC's
    ``max_return``) is a running maximum: updating an existing entry keeps the maximum of the
    stored and every new value, so the record never goes down while the entry lives. Other
    extras are overwritten; a new entry takes the given values.

Scores
    Higher is replayed more. ``-inf`` or NaN is never inserted (``+inf`` is); an entry later set
    to NaN ranks like ``-inf``.

Replay rule
    A :class:`ReplayRule` named by ``buffer.prioritization`` (:data:`REPLAY_RULES`) turns scores
    into weights, normalised over valid entries and mixed ``(1-ρ)·rule + ρ·staleness``."""

from __future__ import annotations

import math
from functools import partial
from dataclasses import dataclass
from typing import Any, Sequence

import flax.struct
import jax
import jax.numpy as jnp

from remidi.engine.config import BufferConfig, _check_unit_interval, _is_int, _is_real
from remidi.errors import ConfigError, one_of

RUNNING_MAX_PREFIX = "max_"  # extras named max_* keep their maximum on updates (module docstring)


@flax.struct.dataclass
class BufferState:
    """The buffer's contents (all leaves JAX arrays).

    Attributes:
        levels: level pytree, leaves ``[capacity, ...]``.
        scores: ``f32[capacity]``.
        last_seen: ``i32[capacity]``, the clock when each entry was last inserted, updated or sampled.
        valid: ``bool[capacity]``.
        extras: ``{name: f32[capacity]}``.
        time: ``i32[]``, the clock."""

    levels: Any
    scores: jax.Array
    last_seen: jax.Array
    valid: jax.Array
    extras: dict
    time: jax.Array


def init_buffer(config: BufferConfig, example_level, extra_names: Sequence[str] = ()) -> BufferState:
    """An empty buffer for levels shaped like ``example_level`` (leaves ``[capacity, *leaf.shape]``).

    Validates ``config``; everything starts at 0 / False."""
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
    """``state`` with zero slots (leaves [0, ...], clock kept): the buffer of an adversary that keeps
    no level."""
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
    """How a buffer's scores become replay weights, before staleness is mixed in.

    ``weights(state, config, ranks) -> f32[capacity]``, non-negative where valid (normalised by the
    buffer; all zero: uniform). ``ranks`` i32[capacity]: 1 = best valid score (ties by lower index,
    NaN like −inf, invalid last). Subclasses are frozen dataclasses (static under jit)."""

    def weights(self, state: BufferState, config: BufferConfig, ranks: jax.Array) -> jax.Array:
        raise NotImplementedError


@dataclass(frozen=True)
class RankReplay(ReplayRule):
    """PLR's rank prioritisation: ``(1/rank)^(1/temperature)``."""

    def weights(self, state, config, ranks):
        return (1.0 / ranks.astype(jnp.float32)) ** (1.0 / config.temperature)


@dataclass(frozen=True)
class TopKReplay(ReplayRule):
    """Softmax of score/temperature over the ``topk_k`` best valid entries, zero elsewhere; uniform
    over them if none has a finite score."""

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


def validate_buffer_config(config: BufferConfig) -> None:
    """Raise :class:`~remidi.errors.ConfigError` (one line, naming the field) if invalid."""
    if not (_is_int(config.capacity) and config.capacity >= 1):
        raise ConfigError(f"capacity: must be an integer ≥ 1, got {config.capacity!r}")
    if config.prioritization not in REPLAY_RULES:
        raise one_of("prioritization", config.prioritization, REPLAY_RULES)
    if not (_is_real(config.temperature) and config.temperature > 0 and math.isfinite(config.temperature)):
        raise ConfigError(f"temperature: must be a finite number > 0, got {config.temperature!r}")
    if not (_is_int(config.topk_k) and config.topk_k >= 1):
        raise ConfigError(f"topk_k: must be an integer ≥ 1, got {config.topk_k!r}")
    _check_unit_interval("staleness_coef", config.staleness_coef)
    _check_unit_interval("replay_prob", config.replay_prob)
    _check_unit_interval("min_fill", config.min_fill)
    if not isinstance(config.duplicate_check, bool):
        raise ConfigError(f"duplicate_check: must be true or false, got {config.duplicate_check!r}")


def _normalise(x: jax.Array, valid: jax.Array) -> jax.Array:
    """``x`` on valid entries over its sum (uniform if the sum is 0; zeros if none is valid)."""
    x = jnp.where(valid, x, 0.0)
    total = jnp.sum(x)
    uniform = valid / jnp.maximum(jnp.sum(valid), 1)
    return jnp.where(total > 0, x / jnp.where(total > 0, total, 1.0), uniform)


def _weights(state: BufferState, config: BufferConfig) -> tuple[jax.Array, jax.Array]:
    """``(weights f32[capacity], ranks i32[capacity])``: :func:`replay_weights` and its ranks."""
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
    """``f32[capacity]``: ``(1-ρ)·rule + ρ·staleness``, zero on invalid entries, sums to 1 if any is valid."""
    return _weights(state, config)[0]


# ---------------------------------------------------------------------------- replay
@partial(jax.jit, static_argnames=("config", "n"))
def sample_replay(state: BufferState, config: BufferConfig, rng: jax.Array, n: int):
    """``(state, idxs i32[n], levels [n, ...])``: ``n`` draws with replacement from :func:`replay_weights`.

    Advances the clock and stamps them. Meaningful only when :func:`can_replay`; an empty buffer
    gives arbitrary entries rather than failing, so it traces inside ``lax.cond``/``vmap``."""
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
    """Set the scores ``f32[n]`` (and extras ``{name: f32[n]}``) of replayed entries ``idxs`` i32[n].

    A negative index (a rejected insertion's ``-1``) is ignored; of a repeated index the last wins,
    except ``max_*`` extras (maximum of all). Clock and ``last_seen`` unchanged."""
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
    """:func:`insert` as a ``lax.scan`` body: ``(state, (inserted bool[], idx i32[]))``."""
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
    """``(state, inserted bool[], idx i32[])``: try to insert one level (``score`` f32[]).

    ``extras`` ``{name: f32[]}``. Stamped with the current time (no tick). In order:

      * ``-inf`` or NaN is never written;
      * with ``duplicate_check``, an equal valid entry is updated instead: its score (``keep_higher``:
        the higher), given extras (``max_*``: maximum) and ``last_seen``; ``inserted = False``;
      * else the first empty slot;
      * if full, it replaces the entry of lowest replay weight (ties: lowest-ranked) only if its
        score is strictly higher.

    Missing extras are 0 on a new entry, kept on a duplicate. ``idx`` -1 if nothing was written."""
    state, (inserted, idx) = _insert(config, keep_higher, state, (level, score, extras))
    return state, inserted, idx


@partial(jax.jit, static_argnames=("config", "keep_higher"))
def insert_batch(state: BufferState, config: BufferConfig, levels, scores, extras=None, keep_higher: bool = False):
    """Tick the clock, then :func:`insert` ``n`` levels (leaves [n, ...]) in order (later see earlier).

    ``scores`` f32[n], ``extras`` ``{name: f32[n]}`` -> ``(state, inserted bool[n], idxs i32[n])``."""
    scores = jnp.asarray(scores, jnp.float32)
    state, (inserted, idxs) = jax.lax.scan(partial(_insert, config, keep_higher), state.replace(time=state.time + 1),
                                           (levels, scores, _known_extras(state, extras)))
    return state, inserted, idxs


# ---------------------------------------------------------------------------- K buffers
def valid_levels(state: BufferState):
    """``(levels [capacity, ...], valid bool[capacity])``."""
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
