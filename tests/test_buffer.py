"""Tests for the PLR⊥ level buffer (remidi.engine.adversaries.level_buffer)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine.adversaries import level_buffer as B
from remidi.engine.adversaries.level_buffer import REPLAY_RULES
from remidi.errors import ConfigError


def make_level(a, b=None):
    """A toy level: an id ``a`` (i32[]) and a payload ``b`` (f32[3])."""
    b = jnp.full(3, a, jnp.float32) if b is None else b
    return {"a": jnp.asarray(a, jnp.int32), "b": jnp.asarray(b, jnp.float32)}


def make_levels(ids):
    """A batch of toy levels with leading dim ``[len(ids)]``."""
    ids = jnp.asarray(ids, jnp.int32)
    return {"a": ids, "b": jnp.repeat(ids[:, None].astype(jnp.float32), 3, axis=1)}


def config(**kw):
    kw.setdefault("capacity", 4)
    return B.BufferConfig(**kw)


def manual_state(cfg, scores, valid, last_seen, time, extra_names=()):
    """A buffer with the given per-slot scores/validity/time stamps; level ids = slot indices."""
    state = B.init_buffer(cfg, make_level(0), extra_names)
    return state.replace(
        levels=make_levels(np.arange(cfg.capacity)),
        scores=jnp.asarray(scores, jnp.float32),
        valid=jnp.asarray(valid, bool),
        last_seen=jnp.asarray(last_seen, jnp.int32),
        time=jnp.asarray(time, jnp.int32),
    )


# Scores [1, 3, 2, -] (slot 3 empty): ranks 3, 1, 2. Staleness at time 10 with last_seen
# [6, 9, 8, -] is [4, 1, 2] -> [4/7, 1/7, 2/7].
HAND_STATE = dict(scores=[1.0, 3.0, 2.0, 0.0], valid=[1, 1, 1, 0], last_seen=[6, 9, 8, 0], time=10)


# ----------------------------------------------------------------------------- replay weights


def test_rank_weights_beta_1_hand_computed():
    # h ∝ [1/3, 1, 1/2] = [2/11, 6/11, 3/11]; 0.7*h + 0.3*[4/7, 1/7, 2/7]
    state = manual_state(config(temperature=1.0, staleness_coef=0.3), **HAND_STATE)
    w = B.replay_weights(state, config(temperature=1.0, staleness_coef=0.3))
    np.testing.assert_allclose(w, [23 / 77, 327 / 770, 213 / 770, 0.0], rtol=1e-6)


def test_rank_weights_beta_half_hand_computed():
    # h ∝ [1/9, 1, 1/4] = [4/49, 36/49, 9/49]; 0.7*h + 0.3*[4/7, 1/7, 2/7]
    cfg = config(temperature=0.5, staleness_coef=0.3)
    w = B.replay_weights(manual_state(cfg, **HAND_STATE), cfg)
    np.testing.assert_allclose(w, [8 / 35, 39 / 70, 15 / 70, 0.0], rtol=1e-6)


def test_topk_weights_hand_computed():
    # top-2 = slots 1, 2 (scores 3, 2): h = softmax = [0, e/(1+e), 1/(1+e)]; 0.7*h + 0.3*[4/7, 1/7, 2/7]
    cfg = config(prioritization="topk", topk_k=2, staleness_coef=0.3)
    w = B.replay_weights(manual_state(cfg, **HAND_STATE), cfg)
    e = np.e
    np.testing.assert_allclose(w, [0.3 * 4 / 7, 0.7 * e / (1 + e) + 0.3 / 7, 0.7 / (1 + e) + 0.3 * 2 / 7, 0.0],
                               rtol=1e-6)


def test_topk_softmax_is_jaxueds_rule_at_temperature_one():
    """jaxued's LevelSampler ``topk`` (``jax.nn.softmax(scores, where=top-k mask)``; its call no
    longer runs on current JAX: ``softmax`` lost ``initial``), computed here in NumPy."""
    scores, valid = np.array([0.5, 3.0, -1.0, 2.0, 1.5, 0.0]), np.array([1, 1, 1, 1, 1, 0], bool)
    cfg = config(capacity=6, prioritization="topk", topk_k=3, staleness_coef=0.0)
    ours = B.replay_weights(manual_state(cfg, scores, valid, [0] * 6, 1), cfg)
    top = np.zeros(6, bool)
    top[np.argsort(-np.where(valid, scores, -np.inf))[:3]] = True  # slots 1, 3, 4
    want = np.where(top, np.exp(scores), 0.0) / np.exp(scores[top]).sum()
    np.testing.assert_allclose(ours, want, rtol=1e-6)


def test_topk_temperature_sharpens_the_softmax():
    # top-2 scores 3, 2 at β = 0.5: weights ∝ e^6, e^4
    cfg = config(prioritization="topk", topk_k=2, staleness_coef=0.0, temperature=0.5)
    w = B.replay_weights(manual_state(cfg, **HAND_STATE), cfg)
    e2 = np.e ** 2
    np.testing.assert_allclose(w, [0.0, e2 / (1 + e2), 1 / (1 + e2), 0.0], rtol=1e-6)


def test_topk_without_finite_scores_is_uniform_over_the_top_k():
    cfg = config(prioritization="topk", topk_k=2, staleness_coef=0.0)
    state = manual_state(cfg, [-np.inf, np.nan, -np.inf, 0.0], [1, 1, 1, 0], [0, 0, 0, 0], 1)
    np.testing.assert_allclose(B.replay_weights(state, cfg), [0.5, 0.5, 0.0, 0.0])


def test_topk_k_clipped_to_number_valid():
    cfg = config(prioritization="topk", topk_k=10, staleness_coef=0.0)
    w = B.replay_weights(manual_state(cfg, **HAND_STATE), cfg)
    z = np.e ** 1 + np.e ** 3 + np.e ** 2
    np.testing.assert_allclose(w, [np.e / z, np.e ** 3 / z, np.e ** 2 / z, 0.0], rtol=1e-6)


def test_rank_ties_broken_by_index():
    # scores [2, 2, 1, 2]: ranks 1, 2, 4, 3 -> h ∝ [1, 1/2, 1/4, 1/3] = [12, 6, 3, 4] / 25
    cfg = config(staleness_coef=0.0)
    state = manual_state(cfg, [2.0, 2.0, 1.0, 2.0], [1, 1, 1, 1], [0, 0, 0, 0], 0)
    np.testing.assert_allclose(B.replay_weights(state, cfg), [12 / 25, 6 / 25, 3 / 25, 4 / 25], rtol=1e-6)


def test_topk_ties_broken_by_index():
    cfg = config(prioritization="topk", topk_k=2, staleness_coef=0.0)
    state = manual_state(cfg, [2.0, 2.0, 1.0, 2.0], [1, 1, 1, 1], [0, 0, 0, 0], 0)
    np.testing.assert_allclose(B.replay_weights(state, cfg), [0.5, 0.5, 0.0, 0.0])


def test_staleness_all_zero_is_uniform_over_valid():
    cfg = config(staleness_coef=1.0)
    state = manual_state(cfg, [5.0, 1.0, 0.0, 3.0], [1, 1, 0, 1], [7, 7, 0, 7], 7)
    np.testing.assert_allclose(B.replay_weights(state, cfg), [1 / 3, 1 / 3, 0.0, 1 / 3], rtol=1e-6)


def test_empty_buffer_weights_are_zero():
    cfg = config()
    state = B.init_buffer(cfg, make_level(0))
    np.testing.assert_array_equal(B.replay_weights(state, cfg), np.zeros(4))
    assert not B.can_replay(state, cfg)


def test_can_replay_min_fill():
    cfg = config(capacity=10, min_fill=0.7)
    for n_valid in range(11):  # 7 suffice, not 8 from 0.7*10 = 7.000000000000001
        state = manual_state(cfg, np.ones(10), np.arange(10) < n_valid, np.zeros(10), 0)
        assert bool(B.can_replay(state, cfg)) == (n_valid >= 7)
    empty, one = config(min_fill=0.0), config(min_fill=0.0)
    assert not B.can_replay(manual_state(empty, np.ones(4), np.zeros(4, bool), np.zeros(4), 0), empty)  # at least one
    assert B.can_replay(manual_state(one, np.ones(4), np.arange(4) < 1, np.zeros(4), 0), one)


# ----------------------------------------------------------------------------- insertion


def test_insert_fills_first_empty_slot():
    cfg = config()
    state = manual_state(cfg, [1.0, 0.0, 2.0, 0.0], [1, 0, 1, 0], [0, 0, 0, 0], 3)
    state, inserted, idx = B.insert(state, cfg, make_level(42), -5.0)
    assert bool(inserted) and int(idx) == 1
    assert int(state.levels["a"][1]) == 42 and float(state.scores[1]) == -5.0
    assert int(state.last_seen[1]) == 3 and int(state.time) == 3  # insert stamps, no tick
    np.testing.assert_array_equal(state.valid, [1, 1, 1, 0])


def test_insert_when_full_replaces_lowest_weight_only_if_higher():
    cfg = config(staleness_coef=0.0)
    state = manual_state(cfg, [4.0, 1.0, 3.0, 2.0], [1, 1, 1, 1], [0, 0, 0, 0], 0)
    same, inserted, idx = B.insert(state, cfg, make_level(9), 1.0)  # equal, not higher
    assert not bool(inserted) and int(idx) == -1
    np.testing.assert_array_equal(same.scores, state.scores)
    np.testing.assert_array_equal(same.levels["a"], state.levels["a"])
    state, inserted, idx = B.insert(state, cfg, make_level(9), 1.5)
    assert bool(inserted) and int(idx) == 1
    assert int(state.levels["a"][1]) == 9 and float(state.scores[1]) == 1.5


def test_nan_scored_entry_ranks_last_and_is_replaceable():
    cfg = config(staleness_coef=0.0)
    state = manual_state(cfg, [4.0, 1.0, 3.0, 2.0], [1, 1, 1, 1], [0, 0, 0, 0], 0)
    state = B.update_scores(state, jnp.array([0]), jnp.array([jnp.nan]))
    # ranks 4, 3, 1, 2 -> h ∝ [1/4, 1/3, 1, 1/2] = [3, 4, 12, 6] / 25
    np.testing.assert_allclose(B.replay_weights(state, cfg), [3 / 25, 4 / 25, 12 / 25, 6 / 25], rtol=1e-6)
    state, inserted, idx = B.insert(state, cfg, make_level(9), -100.0)
    assert bool(inserted) and int(idx) == 0


def test_insert_when_full_victim_uses_staleness():
    # With heavy staleness weight, the lowest-weight entry is the freshest, not the lowest score.
    cfg = config(staleness_coef=0.9)
    state = manual_state(cfg, [1.0, 2.0, 3.0, 4.0], [1, 1, 1, 1], [0, 0, 0, 9], 10)
    weights = B.replay_weights(state, cfg)
    assert int(jnp.argmin(weights)) == 3
    _, inserted, _ = B.insert(state, cfg, make_level(7), 3.5)  # 3.5 < 4.0 of slot 3
    assert not bool(inserted)
    state, inserted, idx = B.insert(state, cfg, make_level(7), 4.5)
    assert bool(inserted) and int(idx) == 3


@pytest.mark.parametrize("bad", [-jnp.inf, jnp.nan])
def test_never_inserts_neg_inf_or_nan(bad):
    cfg = config()
    empty = B.init_buffer(cfg, make_level(0))
    state, inserted, idx = B.insert(empty, cfg, make_level(1), bad)
    assert not bool(inserted) and int(idx) == -1 and int(B.size(state)) == 0
    full = manual_state(cfg, [1.0, 1.0, 1.0, 1.0], [1, 1, 1, 1], [0, 0, 0, 0], 0)
    state, inserted, _ = B.insert(full, cfg, make_level(1), bad)
    assert not bool(inserted)
    np.testing.assert_array_equal(state.scores, full.scores)


def test_duplicate_check_updates_existing_entry():
    cfg = config(duplicate_check=True)
    state = B.init_buffer(cfg, make_level(0), extra_names=("max_return",))
    state, _, _ = B.insert(state, cfg, make_level(5), 1.0, {"max_return": 0.5})
    state, _, _ = B.insert(state, cfg, make_level(6), 2.0, {"max_return": 0.25})
    state = state.replace(time=jnp.asarray(4, jnp.int32))
    state, inserted, idx = B.insert(state, cfg, make_level(5), 3.0)
    assert not bool(inserted) and int(idx) == 0 and int(B.size(state)) == 2
    assert float(state.scores[0]) == 3.0 and int(state.last_seen[0]) == 4
    assert float(state.extras["max_return"][0]) == 0.5  # not given: unchanged
    # A level differing in one leaf only is not a duplicate.
    state, inserted, idx = B.insert(state, cfg, make_level(5, jnp.array([5.0, 5.0, 0.0])), 1.0)
    assert bool(inserted) and int(idx) == 2
    # A -inf duplicate changes nothing.
    same, inserted, idx = B.insert(state, cfg, make_level(6), -jnp.inf)
    assert not bool(inserted) and int(idx) == -1 and float(same.scores[1]) == 2.0


def test_keep_higher_keeps_a_duplicates_highest_score():
    """keep_higher (a reservoir's keys, GeneratorSequence): a duplicate raises its entry's score,
    never lowers it; a new level is inserted as without it."""
    cfg = config(duplicate_check=True)
    state = B.init_buffer(cfg, make_level(0))
    state, _, _ = B.insert(state, cfg, make_level(5), 0.9, keep_higher=True)
    lower, inserted, idx = B.insert(state, cfg, make_level(5), 0.2, keep_higher=True)
    assert not bool(inserted) and int(idx) == 0 and float(lower.scores[0]) == np.float32(0.9)
    higher, _, _ = B.insert(lower, cfg, make_level(5), 0.95, keep_higher=True)
    assert float(higher.scores[0]) == np.float32(0.95)
    assert float(B.insert(state, cfg, make_level(5), 0.2)[0].scores[0]) == np.float32(0.2)  # the default: replaced


def test_duplicate_keeps_running_max_of_max_extras_and_overwrites_others():
    cfg = config(duplicate_check=True)
    state = B.init_buffer(cfg, make_level(0), extra_names=("max_return", "last_return"))
    state, _, _ = B.insert(state, cfg, make_level(5), 1.0, {"max_return": 0.75, "last_return": 0.75})
    state, inserted, idx = B.insert(state, cfg, make_level(5), 2.0, {"max_return": 0.25, "last_return": 0.25})
    assert not bool(inserted) and int(idx) == 0
    assert float(state.extras["max_return"][0]) == 0.75  # the MaxMC record does not go down
    assert float(state.extras["last_return"][0]) == 0.25  # any other extra is overwritten
    state, _, _ = B.insert(state, cfg, make_level(5), 2.0, {"max_return": 0.875})
    assert float(state.extras["max_return"][0]) == 0.875
    # a new entry takes the given value, whatever its slot held before
    state, _, _ = B.insert(state, cfg, make_level(6), 1.0, {"max_return": -3.0})
    assert float(state.extras["max_return"][1]) == -3.0


def test_update_scores_keeps_running_max_over_every_occurrence():
    cfg = config()
    state = manual_state(cfg, **HAND_STATE, extra_names=("max_return", "last_return"))
    state = state.replace(extras={"max_return": jnp.array([5.0, 1.0, 2.0, 0.0]), "last_return": jnp.zeros(4)})
    state = B.update_scores(state, jnp.array([1, 1, 0, -1]), jnp.zeros(4),
                            {"max_return": jnp.array([4.0, 3.0, 1.0, 9.0]), "last_return": jnp.array([4.0, 3.0, 1.0, 9.0])})
    np.testing.assert_allclose(state.extras["max_return"], [5.0, 4.0, 2.0, 0.0])
    np.testing.assert_allclose(state.extras["last_return"], [1.0, 3.0, 0.0, 0.0])  # last occurrence wins


def test_without_duplicate_check_copies_are_inserted():
    cfg = config()
    state = B.init_buffer(cfg, make_level(0))
    state, inserted, idxs = B.insert_batch(state, cfg, make_levels([5, 5]), jnp.array([1.0, 2.0]))
    np.testing.assert_array_equal(inserted, [True, True])
    np.testing.assert_array_equal(idxs, [0, 1])


def test_insert_extras_new_entry_defaults_to_zero():
    cfg = config()
    state = B.init_buffer(cfg, make_level(0), extra_names=("max_return", "other"))
    state, _, _ = B.insert(state, cfg, make_level(1), 1.0, {"max_return": 0.75})
    assert float(state.extras["max_return"][0]) == 0.75 and float(state.extras["other"][0]) == 0.0
    with pytest.raises(ValueError, match="unknown buffer extras"):
        B.insert(state, cfg, make_level(1), 1.0, {"nope": 1.0})


def test_insert_batch_is_sequential_and_ticks_once():
    cfg = config(capacity=1, staleness_coef=0.0)
    state = B.init_buffer(cfg, make_level(0))
    state, inserted, idxs = B.insert_batch(state, cfg, make_levels([1, 2, 3]), jnp.array([1.0, 5.0, 3.0]))
    np.testing.assert_array_equal(inserted, [True, True, False])
    np.testing.assert_array_equal(idxs, [0, 0, -1])
    assert int(state.levels["a"][0]) == 2 and float(state.scores[0]) == 5.0
    assert int(state.time) == 1 and int(state.last_seen[0]) == 1


def test_insert_batch_duplicates_within_batch():
    cfg = config(duplicate_check=True)
    state = B.init_buffer(cfg, make_level(0))
    state, inserted, idxs = B.insert_batch(state, cfg, make_levels([3, 3, 4]), jnp.array([1.0, 2.0, 0.5]))
    np.testing.assert_array_equal(inserted, [True, False, True])
    np.testing.assert_array_equal(idxs, [0, 0, 1])
    np.testing.assert_allclose(state.scores[:2], [2.0, 0.5])


@pytest.mark.parametrize("prioritization", ["rank", "topk"])
def test_random_insertion_invariants(prioritization):
    cfg = config(capacity=6, prioritization=prioritization, topk_k=2, staleness_coef=0.0)
    rng = np.random.default_rng(0)
    state = B.init_buffer(cfg, make_level(0))
    rejected, next_id, prev_min = set(), 1, None
    for _ in range(25):
        n = 4
        ids = np.arange(next_id, next_id + n)
        next_id += n
        scores = rng.normal(size=n).astype(np.float32)
        scores[rng.random(n) < 0.2] = -np.inf
        scores[rng.random(n) < 0.1] = np.nan
        state, inserted, idxs = B.insert_batch(state, cfg, make_levels(ids), jnp.asarray(scores))
        inserted, idxs = np.asarray(inserted), np.asarray(idxs)
        rejected |= set(ids[~inserted].tolist())
        np.testing.assert_array_equal(idxs[~inserted], -1)
        valid = np.asarray(state.valid)
        stored = set(np.asarray(state.levels["a"])[valid].tolist())
        assert int(B.size(state)) == valid.sum() <= cfg.capacity
        assert not (stored & rejected)
        assert np.all(np.isfinite(np.asarray(state.scores)[valid]))
        weights = np.asarray(B.replay_weights(state, cfg))
        assert np.all(weights[~valid] == 0) and np.isclose(weights.sum(), 1.0, atol=1e-5)
        if valid.all():
            current_min = float(np.asarray(state.scores).min())
            assert prev_min is None or current_min >= prev_min
            prev_min = current_min
    assert prev_min is not None


# ----------------------------------------------------------------------------- sampling


N_DRAWS = 20000


def test_sampling_frequencies_match_weights_and_stamp_time():
    cfg = config(staleness_coef=0.3)
    state = manual_state(cfg, **HAND_STATE)
    weights = np.asarray(B.replay_weights(state, cfg))
    new, idxs, levels = B.sample_replay(state, cfg, jax.random.key(0), N_DRAWS)
    freq = np.bincount(np.asarray(idxs), minlength=cfg.capacity) / N_DRAWS
    np.testing.assert_allclose(freq, weights, atol=0.015)
    assert freq[3] == 0.0  # the empty slot is never sampled
    np.testing.assert_array_equal(levels["a"], idxs)  # level ids are slot indices
    assert int(new.time) == 11
    np.testing.assert_array_equal(new.last_seen, [11, 11, 11, 0])  # all valid slots were drawn


def test_sample_stamps_only_sampled_entries():
    cfg = config(prioritization="topk", topk_k=2, staleness_coef=0.0)
    state = manual_state(cfg, **HAND_STATE)
    new, idxs, _ = B.sample_replay(state, cfg, jax.random.key(2), 500)
    assert set(np.asarray(idxs).tolist()) == {1, 2}  # only the top 2
    np.testing.assert_array_equal(new.last_seen, [6, 11, 11, 0])


def test_sample_on_empty_buffer_does_not_fail():
    cfg = config(staleness_coef=0.3)
    state = B.init_buffer(cfg, make_level(0))
    new, idxs, _ = B.sample_replay(state, cfg, jax.random.key(0), N_DRAWS)
    assert np.all((np.asarray(idxs) >= 0) & (np.asarray(idxs) < 4))
    assert int(B.size(new)) == 0


def test_update_scores():
    cfg = config()
    state = manual_state(cfg, **HAND_STATE, extra_names=("max_return",))
    state = B.update_scores(
        state, jnp.array([2, 0, 2, -1]), jnp.array([7.0, 8.0, 9.0, 99.0]), {"max_return": jnp.array([1.0, 2.0, 3.0, 4.0])}
    )
    np.testing.assert_allclose(state.scores, [8.0, 3.0, 9.0, 0.0])  # last occurrence wins, -1 ignored
    np.testing.assert_allclose(state.extras["max_return"], [2.0, 0.0, 3.0, 0.0])
    np.testing.assert_array_equal(state.last_seen, HAND_STATE["last_seen"])
    assert int(state.time) == 10


# ----------------------------------------------------------------------------- jit / vmap / stacking


def _run_step(state, cfg, rng, ids, scores):
    """Insert a batch, sample, then update the sampled scores: one function touching every API."""
    state, inserted, _ = B.insert_batch(state, cfg, make_levels(ids), scores, {"max_return": scores})
    state, idxs, levels = B.sample_replay(state, cfg, rng, 3)
    state = B.update_scores(state, idxs, levels["a"].astype(jnp.float32))
    return state, inserted, idxs, B.replay_weights(state, cfg), B.can_replay(state, cfg), B.size(state)


def test_jit_and_vmap_over_seed_axis():
    cfg = config(duplicate_check=True, min_fill=0.5)
    seeds = 3
    state = B.stack_buffers([B.init_buffer(cfg, make_level(0), ("max_return",))] * seeds)
    rngs = jax.random.split(jax.random.key(0), seeds)
    ids = jnp.array([[1, 2, 3], [4, 4, 5], [6, 7, 8]])
    scores = jnp.array([[1.0, -jnp.inf, 2.0], [0.5, 0.7, 0.1], [3.0, 2.0, 1.0]])
    step = jax.jit(jax.vmap(_run_step, in_axes=(0, None, 0, 0, 0)), static_argnums=1)
    batched = step(state, cfg, rngs, ids, scores)
    for s in range(seeds):
        single = jax.jit(_run_step, static_argnums=1)(B.select_buffer(state, s), cfg, rngs[s], ids[s], scores[s])
        for got, want in zip(jax.tree.leaves(jax.tree.map(lambda x: x[s], batched)), jax.tree.leaves(single)):
            np.testing.assert_allclose(got, want, rtol=1e-6)
    np.testing.assert_array_equal(batched[1], [[True, False, True], [True, False, True], [True, True, True]])


def test_select_and_replace_with_traced_index():
    cfg = config()
    stacked = B.stack_buffers([B.init_buffer(cfg, make_level(0)) for _ in range(3)])

    @jax.jit
    def insert_into(stacked, k, level_id):
        active = B.select_buffer(stacked, k)
        active, _, _ = B.insert(active, cfg, make_level(level_id), 1.0)
        return B.replace_buffer(stacked, k, active)

    stacked = insert_into(stacked, jnp.int32(1), jnp.int32(9))
    np.testing.assert_array_equal(jax.vmap(B.size)(stacked), [0, 1, 0])
    levels, valid = B.valid_levels(B.select_buffer(stacked, 1))
    assert int(levels["a"][0]) == 9 and bool(valid[0])


# ----------------------------------------------------------------------------- config validation


@pytest.mark.parametrize(
    "field,value,message",
    [
        ("capacity", 0, r"^capacity: .*≥ 1"),
        ("capacity", 2.0, r"^capacity: "),
        ("prioritization", "softmax", rf"^prioritization: .*allowed: {', '.join(REPLAY_RULES)}$"),
        ("temperature", 0.0, r"^temperature: .*> 0"),
        ("temperature", -1.0, r"^temperature: "),
        ("topk_k", 0, r"^topk_k: .*≥ 1"),
        ("staleness_coef", 1.5, r"^staleness_coef: .*\[0, 1\]"),
        ("staleness_coef", float("nan"), r"^staleness_coef: "),
        ("replay_prob", -0.1, r"^replay_prob: .*\[0, 1\]"),
        ("min_fill", 2, r"^min_fill: .*\[0, 1\]"),
        ("duplicate_check", "yes", r"^duplicate_check: "),
    ],
)
def test_validate_buffer_config_errors(field, value, message):
    cfg = dataclasses.replace(B.BufferConfig(), **{field: value})
    with pytest.raises(ConfigError, match=message) as err:
        B.validate_buffer_config(cfg)
    assert "\n" not in str(err.value)
    with pytest.raises(ConfigError):
        B.init_buffer(cfg, make_level(0))


def test_validate_buffer_config_accepts_defaults_and_edges():
    B.validate_buffer_config(B.BufferConfig())
    B.validate_buffer_config(B.BufferConfig(capacity=1, staleness_coef=0, replay_prob=1, min_fill=1.0, topk_k=1))
