"""The candidate tracker steps only its live slots (engine/trackers/exact.py, CandidateTracker.step):
where no env's first observation matches a frozen level a rollout steps the envs alone, and
otherwise the batch of slots is the smallest size of the ladder that holds the live ones (over
every seed of the program), whatever the slots per env. Counted by the environment itself (a
callback in its step runs once per level stepped), on the lever game, whose one-step episodes
restart every step, so the live slots are the same at every step (the matches of the first
observation)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine.learner import Policy, Stepping, rollout
from remidi.engine.core.seeds import SEED_BATCH
from remidi.engine.trackers.base import Frozen
from remidi.engine.trackers.exact import make_tracker, slot_ladder
from remidi.envs.lever import LeverGame, LeverLevel

LEVERS, ENVS, STEPS, SLOTS = 8, 4, 5, 16
STEPPED = []  # the levels stepped by CountingLever, per call


class CountingLever(LeverGame):
    """The lever game, its step counted (``STEPPED``)."""

    def step_env(self, rng, state, action, params):
        # under vmap the callback sees the batch (or one level at a time): count its entries
        jax.debug.callback(lambda done: STEPPED.append(np.size(done)), state.done)
        return super().step_env(rng, state, action, params)


ENV = CountingLever(LEVERS)


def levels(correct, visible):
    return LeverLevel(correct=jnp.asarray(correct, jnp.int32), visible=jnp.asarray(visible, bool))


# the agents' levels: two hidden (one observation: "hidden"), two visible ones of levers 0 and 1
AGENTS = levels([0, 3, 0, 1], [False, False, True, True])
# frozen: three hidden levels and a visible lever 0 (7 slots live: 3 + 3 + 1 + 0), the rest visible levers 4..7
MATCHING = levels([1, 2, 5, 0] + [4 + i % 4 for i in range(8)], [False, False, False, True] + [True] * 8)
# frozen: only visible levers 4..7, which no agent's first observation shows
NOTHING = levels([4 + i % 4 for i in range(12)], [True] * 12)


def uniform(variables, carry, obs, reset):
    n = reset.shape[1]
    return carry, (jnp.zeros((1, n, LEVERS)), jnp.zeros((1, n)))


def play(rng, frozen_levels):
    """A rollout of the uniform policy on AGENTS with the candidate tracker (SLOTS slots per env)."""
    frozen = None
    if frozen_levels is not None:
        frozen = Frozen(levels=frozen_levels, valid=jnp.ones(12, bool), tracker=make_tracker("prefix", SLOTS))
    policy = Policy(uniform, {}, jnp.zeros(ENVS))
    return rollout(rng, Stepping(ENV, ENV.default_params, True), policy, AGENTS, STEPS, frozen)[0]


def counted(fn, *args):
    """``(fn(*args), levels stepped)``, ``fn`` compiled first."""
    compiled = jax.jit(fn).lower(*args).compile()
    STEPPED.clear()
    out = jax.block_until_ready(compiled(*args))
    jax.effects_barrier()
    return out, sum(STEPPED)


def test_the_ladder_of_slot_batches():
    assert slot_ladder(32, 64) == (0, 4, 32, 256, 2048)  # 2048 / 8, / 8, / 8: down to 32 / 8
    assert slot_ladder(ENVS, SLOTS) == (0, 1, 8, 64)
    assert slot_ladder(4, 8) == (0, 1, 4, 32)
    assert slot_ladder(1, 1) == (0, 1)
    assert slot_ladder(16, 20) == (0, 2, 5, 40, 320)  # 320/8 = 40, ⌈40/8⌉ = 5, then the floor 16 // 8


@pytest.fixture(scope="module")
def runs():
    key = jax.random.PRNGKey(0)
    return {name: counted(play, key, frozen) for name, frozen in
            (("none", None), ("nothing", NOTHING), ("matching", MATCHING))}


def test_where_nothing_matches_only_the_envs_are_stepped(runs):
    (plr, plr_steps), (remidi, remidi_steps) = runs["none"], runs["nothing"]
    assert plr_steps == remidi_steps == ENVS * STEPS  # not ENVS · (1 + SLOTS) per step
    assert not remidi.indist.any()
    for field in ("obs", "action", "reward", "done", "log_prob"):  # the same rollout as without a tracker
        np.testing.assert_array_equal(getattr(remidi, field), getattr(plr, field), err_msg=field)


def test_the_slots_stepped_are_the_live_ones_rounded_up_the_ladder(runs):
    traj, steps = runs["matching"]
    # 7 live slots every step (each episode is one step and restarts with its first observation's
    # matches): the batch of 8, against 4 · 16 slots stepped before
    assert steps == STEPS * (ENVS + 8)
    np.testing.assert_array_equal(traj.indist, np.broadcast_to([True, True, True, False], (STEPS, ENVS)))


def test_over_seeds_every_seed_steps_the_batch_its_busiest_seed_needs(runs):
    """Under the seed vmap the batch size is one for all seeds (a branch, not a select of every
    size): the largest any seed needs; each seed's rollout is its own."""
    keys = jnp.stack([jax.random.PRNGKey(0)] * 2)
    frozen = jax.tree.map(lambda a, b: jnp.stack([a, b]), NOTHING, MATCHING)
    both, steps = counted(jax.vmap(play, axis_name=SEED_BATCH), keys, frozen)
    assert steps == 2 * STEPS * (ENVS + 8)
    for seed, name in enumerate(("nothing", "matching")):
        for field in ("obs", "action", "indist", "done"):
            np.testing.assert_array_equal(getattr(both, field)[seed], getattr(runs[name][0], field),
                                          err_msg=f"{name} {field}")
