"""Multi-discrete actions (``MultiDiscrete(nvec)``: one choice per component) through the engine:
the MultiCategorical distribution against NumPy, the declaration of a task's action space and
what the task's check says of it (Kinetix's space read off the environment, the misleading
message fixed, a validation message naming the one leaf that differs), the exact trackers
replaying the agent's component actions on frozen levels, the belief model's coding of them,
and PPO learning a one-step task whose reward needs both components right."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import struct

from remidi.engine.core.distributions import CATEGORICAL, MultiCategorical, for_space, for_task
from remidi.engine.learner import Policy, Stepping, rollout
from remidi.engine.run.task_checks import validate_task
from remidi.engine.trackers.base import Frozen
from remidi.engine.trackers.exact import make_tracker
from remidi.envs.actions import Box, Discrete, MultiDiscrete, from_env_space
from remidi.envs.interface import UEDTask, UnderspecifiedEnv, one_step_discounted
from remidi.errors import ConfigError


def np_log_softmax(x):
    x = x - x.max(-1, keepdims=True)
    return x - np.log(np.exp(x).sum(-1, keepdims=True))


# ------------------------------------------------------------------ the distribution
def test_multicategorical_log_prob_entropy_and_mode_match_a_hand_computation():
    nvec = (3, 2, 4)
    dist = MultiCategorical(nvec)
    rng = np.random.default_rng(0)
    logits = rng.normal(size=(5, 9)).astype(np.float32) * 2
    action = np.stack([rng.integers(0, n, 5) for n in nvec], axis=-1)  # [5, 3]
    parts = [logits[:, 0:3], logits[:, 3:5], logits[:, 5:9]]
    logp = [np_log_softmax(p.astype(np.float64)) for p in parts]
    want_lp = sum(lp[np.arange(5), action[:, i]] for i, lp in enumerate(logp))
    want_h = sum(-(np.exp(lp) * lp).sum(-1) for lp in logp)
    # a batch with two leading axes: [2, 5, 9] -> [2, 5]; one program
    out, act = jnp.asarray(np.stack([logits, logits])), jnp.asarray(np.stack([action, action]), jnp.int32)
    log_prob, entropy, mode = jax.jit(lambda o, a: (dist.log_prob(o, a), dist.entropy(o), dist.mode(o)))(out, act)
    np.testing.assert_allclose(log_prob, np.stack([want_lp, want_lp]), rtol=1e-5)
    np.testing.assert_allclose(entropy[1], want_h, rtol=1e-5)
    np.testing.assert_array_equal(mode[0], np.stack([p.argmax(-1) for p in parts], axis=-1))
    assert dist.network_actions == 9 and not dist.continuous


def test_multicategorical_samples_follow_each_components_probabilities():
    """20000 draws of one row: each component's choice frequencies within 0.015 of its softmax
    (a binomial's standard deviation is at most 0.0036 here: four of them), every draw in range."""
    dist = MultiCategorical((3, 2, 4))
    logits = jnp.asarray([0.5, -1.0, 1.5, 2.0, 0.0, -0.5, 0.3, 1.2, 0.0], jnp.float32)
    draws = np.asarray(jax.jit(lambda k: dist.sample(k, jnp.broadcast_to(logits, (20000, 9))))(jax.random.PRNGKey(0)))
    assert draws.shape == (20000, 3) and draws.dtype == np.int32
    for i, part in enumerate(dist.split(np.asarray(logits))):
        probs = np.exp(np_log_softmax(part))
        freq = np.bincount(draws[:, i], minlength=len(probs)) / len(draws)
        np.testing.assert_allclose(freq, probs, atol=0.015)


def test_the_distribution_and_the_network_head_follow_the_declared_space():
    assert for_space(Discrete(5)).network_actions == 5 and for_space(Box(3)).continuous
    assert for_space(MultiDiscrete((3, 3, 2))) == MultiCategorical((3, 3, 2))
    assert for_task(False) is CATEGORICAL  # the earlier form: size-free
    from remidi.engine.config import UEDConfig
    from remidi.engine.setup import network_for

    net = network_for(UEDConfig(network="mlp"), dials_task())
    assert net.num_actions == 5 and not net.continuous  # Σ nvec logits


# ------------------------------------------------------------------ declaring and checking the space
class KinetixLikeSpace:
    """Kinetix's MultiDiscrete (kinetix/environment/spaces.py): ``n`` the total of choices,
    ``number_of_dims_per_distribution`` (i32[k]) per dimension, ``shape`` ``(k,)``, ``dtype`` ``jnp.int_``."""

    def __init__(self, counts):
        self.number_of_dims_per_distribution = jnp.asarray(counts, jnp.int32)
        self.n = int(sum(counts))
        self.shape = (len(counts),)
        self.dtype = jnp.int_


class JaxMARLMultiDiscrete:
    """JaxMARL's MultiDiscrete (jaxmarl/environments/spaces.py): ``num_categories`` per dimension."""

    def __init__(self, num_categories):
        self.num_categories = jnp.array(num_categories)
        self.shape = (len(num_categories),)
        self.dtype = jnp.int_


class JaxMARLDiscrete:
    """JaxMARL's Discrete: ``n``, ``shape`` ``()``, ``dtype``."""

    def __init__(self, num_categories, dtype=jnp.int32):
        self.n, self.shape, self.dtype = num_categories, (), dtype


class JaxMARLBox:
    """JaxMARL's Box: ``low``, ``high``, ``shape``, ``dtype``."""

    def __init__(self, low, high, shape, dtype=jnp.float32):
        self.low, self.high, self.shape, self.dtype = low, high, shape, dtype


@struct.dataclass
class Dials:
    a: jax.Array  # i32[]: the right choice of component 0 (of 3)
    b: jax.Array  # i32[]: the right choice of component 1 (of 2)


class DialsEnv(UnderspecifiedEnv):
    """One step: the observation shows (a, b) one-hot; reward 1 iff the action is (a, b)."""

    @property
    def default_params(self):
        return None

    def action_space(self, params):
        return KinetixLikeSpace((3, 2))

    def _obs(self, level):
        return jnp.concatenate([jax.nn.one_hot(level.a, 3), jax.nn.one_hot(level.b, 2)])

    def reset_env_to_level(self, rng, level, params):
        return self._obs(level), level

    def step_env(self, rng, state, action, params):
        right = (action[0] == state.a) & (action[1] == state.b)
        return self._obs(state), state, right.astype(jnp.float32), jnp.asarray(True), {}


ALL_DIALS = Dials(a=jnp.repeat(jnp.arange(3), 2), b=jnp.tile(jnp.arange(2), 3))


def dials_task(**actions):
    def sample(rng):
        k1, k2 = jax.random.split(rng)
        return Dials(a=jax.random.randint(k1, (), 0, 3), b=jax.random.randint(k2, (), 0, 2))

    one = lambda level: jnp.asarray(1.0)  # noqa: E731
    return UEDTask(env=DialsEnv(), params=None, sample_level=sample, max_episode_steps=1,
                   optimal_return=one, optimal_discounted_return=one_step_discounted(one),
                   eval_sets={"all": ALL_DIALS}, deterministic_reset=True,
                   **(actions or {"action_space": from_env_space(DialsEnv().action_space(None))}))


def test_spaces_are_read_off_the_environment_and_another_is_refused_in_one_line():
    from gymnax.environments import spaces

    assert from_env_space(KinetixLikeSpace((3, 3, 2, 2))) == MultiDiscrete((3, 3, 2, 2))  # not its n = 10
    assert from_env_space(spaces.Discrete(4)) == Discrete(4)
    assert from_env_space(spaces.Box(-1.0, 1.0, (2, 3))) == Box(6)
    with pytest.raises(ConfigError) as err:
        from_env_space(spaces.Dict({"a": spaces.Discrete(2)}))
    assert str(err.value).startswith("task.env.action_space: a Dict is not supported; allowed: Discrete(n), "
                                     "MultiDiscrete(nvec)") and "\n" not in str(err.value)
    task = dials_task()
    assert task.actions == MultiDiscrete((3, 2)) and task.num_actions is None
    validate_task(task)
    legacy = dials_task(num_actions=5)  # the shorthand still declares Discrete / Box
    assert legacy.actions == Discrete(5) and dials_task(num_actions=2, continuous=True).actions == Box(2)


@pytest.mark.parametrize("actions, message", [
    # the check once summed the choices ("must be the environment's 5 actions"): it names the space now
    ({"num_actions": 5}, "task.num_actions: must be the environment's MultiDiscrete((3, 2)) (its action_space), got "
                         "Discrete(5); declare action_space=MultiDiscrete((3, 2))"),
    ({"action_space": MultiDiscrete((3, 3))}, "task.action_space: must be the environment's MultiDiscrete((3, 2))"),
    ({"action_space": MultiDiscrete((3, 0))}, "task.action_space: MultiDiscrete((3, 0)): nvec must be a non-empty "
                                              "sequence of integers ≥ 1"),
    ({"action_space": MultiDiscrete((3, 2)), "num_actions": 5}, "task.num_actions: num_actions=5 disagrees with "
                                                                "action_space=MultiDiscrete((3, 2))"),
    ({"action_space": KinetixLikeSpace((3, 3))}, "task.action_space: must be the environment's MultiDiscrete((3, 2))"),
    ({"action_space": JaxMARLDiscrete(6)}, "task.action_space: must be the environment's MultiDiscrete((3, 2)) (its "
                                           "action_space), got Discrete(6)"),
    ({"action_space": {"a": 3}}, "task.action_space: a dict is not supported; allowed: Discrete(n), MultiDiscrete"),
])
def test_a_wrong_declaration_is_one_line_naming_the_space(actions, message):
    with pytest.raises(ConfigError) as err:
        validate_task(dials_task(**actions))
    assert str(err.value).startswith(message) and "\n" not in str(err.value), str(err.value)


def _gymnasium_spaces():
    from gymnasium import spaces

    return spaces


@pytest.mark.parametrize("make, ours", [
    (lambda: KinetixLikeSpace((3, 2)), MultiDiscrete((3, 2))),  # once refused: "must be one of remidi.envs.actions'"
    (lambda: JaxMARLMultiDiscrete([3, 2]), MultiDiscrete((3, 2))),
    (lambda: _gymnasium_spaces().MultiDiscrete([3, 2]), MultiDiscrete((3, 2))),
    (lambda: JaxMARLDiscrete(4), Discrete(4)),
    (lambda: _gymnasium_spaces().Discrete(4), Discrete(4)),  # XLand-MiniGrid's gymnasium wrapper's action space
    (lambda: __import__("gymnax").environments.spaces.Discrete(4), Discrete(4)),
    (lambda: JaxMARLBox(-1.0, 1.0, (2, 3)), Box(6)),
    (lambda: __import__("gymnax").environments.spaces.Box(-1.0, 1.0, (2,)), Box(2)),
])
def test_an_environments_own_space_is_a_tasks_action_space(make, ours):
    """gymnax's, Kinetix's, JaxMARL's and gymnasium's spaces (XLand-MiniGrid's is gymnasium's)
    given as ``action_space`` become this package's when the task is built; the task trains on it."""
    task = dials_task(action_space=make())
    assert task.action_space == ours and task.actions == ours
    if ours == MultiDiscrete((3, 2)):  # the dials environment's own space: the task passes its check
        validate_task(task)


def test_a_space_whose_choices_do_not_start_at_zero_is_refused_in_one_line():
    with pytest.raises(ConfigError) as err:
        validate_task(dials_task(action_space=_gymnasium_spaces().Discrete(6, start=1)))
    assert str(err.value).startswith("task.action_space: a Discrete whose choices start at 1 is not supported")


def test_expected_return_needs_discrete_actions():
    task = dataclasses.replace(dials_task(), expected_return=lambda level, probs: probs[0])
    with pytest.raises(ConfigError, match="^task.expected_return: reads a Discrete policy's action probabilities, "
                                          "but the actions are MultiDiscrete"):
        validate_task(task)


def test_a_level_mismatch_names_the_first_leaf_that_differs_and_counts_the_rest():
    """A level of 40 leaves whose reseed returns three of them wrong: the message names the first
    (its path, the sampled and the returned shape) and says how many more, not all 40 twice."""
    base = dials_task()
    wide = {f"w{i:02d}": jnp.zeros((4,), jnp.float32) for i in range(38)}

    def sample(rng):
        return {"dials": base.sample_level(rng), **wide}

    class WideEnv(DialsEnv):
        def reset_env_to_level(self, rng, level, params):
            return super().reset_env_to_level(rng, level["dials"], params)

    def reseed(rng, level):
        return {**level, "w03": jnp.zeros((5,)), "w07": jnp.zeros((4,), jnp.int32), "w09": jnp.zeros(())}

    task = dataclasses.replace(base, env=WideEnv(), sample_level=sample, eval_sets={}, reseed_level=reseed)
    with pytest.raises(ConfigError) as err:
        validate_task(task)
    assert str(err.value) == ("task.reseed_level: must return a level with the sampled level's shapes and dtypes; "
                              "['w03'] (float32[4] sampled, float32[5] here) and 2 more")
    batch = {"dials": ALL_DIALS, **{name: jnp.zeros((6, 4)) for name in wide}}
    batch["w05"] = jnp.zeros((6,))  # a leaf without the level's axis
    with pytest.raises(ConfigError) as err:
        validate_task(dataclasses.replace(task, reseed_level=None, eval_sets={"wide": batch}))
    assert str(err.value) == ("task.eval_sets: 'wide' must be a batch of levels, every leaf with the level's shape "
                              "after one leading axis of the same length ≥ 1; ['w05'] ([6, rank 1] expected, [6] here)")


# ------------------------------------------------------------------ the exact trackers replay the components
@struct.dataclass
class Gears:
    m: jax.Array  # i32[2]: how far each component's choice moves the position


class GearsEnv(UnderspecifiedEnv):
    """The position starts at 0 and moves by ``action * m`` (component-wise) each step; episodes
    last 8 steps. Two levels differing in ``m[1]`` look the same until a step's component 1 is not 0."""

    @property
    def default_params(self):
        return None

    def action_space(self, params):
        return KinetixLikeSpace((3, 2))

    def reset_env_to_level(self, rng, level, params):
        return jnp.zeros(2), (level, jnp.zeros(2), jnp.zeros((), jnp.int32))

    def step_env(self, rng, state, action, params):
        level, pos, t = state
        pos = pos + (action * level.m).astype(jnp.float32)
        return pos, (level, pos, t + 1), jnp.asarray(0.0), t + 1 >= 8, {}


def uniform_policy(n):
    def apply(variables, carry, obs, reset):
        return carry, (jnp.zeros((1, reset.shape[1], 5)), jnp.zeros((1, reset.shape[1])))

    return Policy(apply, {}, jnp.zeros(n))


@pytest.mark.parametrize("budget", [0, 1])  # the reference tracker, the candidate slots
def test_the_exact_tracker_replays_the_agents_component_actions(budget):
    n, steps = 16, 6
    played = Gears(m=jnp.tile(jnp.asarray([[1, 1]], jnp.int32), (n, 1)))
    dist = MultiCategorical((3, 2))

    @jax.jit
    def roll(frozen_m):  # one program for both frozen levels
        frozen = Frozen(levels=Gears(m=frozen_m[None]), valid=jnp.ones(1, bool), tracker=make_tracker("prefix", budget))
        return rollout(jax.random.PRNGKey(3), Stepping(GearsEnv(), None, budget > 0), uniform_policy(n), played,
                       steps, frozen, dist=dist)[0]

    def play(frozen_m):
        return jax.device_get(roll(jnp.asarray(frozen_m, jnp.int32)))

    same = play([1, 1])
    assert same.action.shape == (steps, n, 2) and same.indist.all()  # the same level: explained at every step
    other = play([1, 2])
    # distinguishable from the first step after one whose component 1 was not 0, not before
    still_same = np.cumprod(np.concatenate([np.ones((1, n), bool), other.action[:-1, :, 1] == 0]), axis=0) == 1
    np.testing.assert_array_equal(other.indist, still_same)
    assert other.indist[0].all() and not other.indist[-1].all()


# ------------------------------------------------------------------ the belief model codes the components
def test_the_belief_model_one_hot_codes_each_component():
    from remidi.engine.trackers import belief_model as bm

    obs = jnp.zeros((3,), jnp.int32)
    model = bm.BeliefModel(bm.coding_for(jax.eval_shape(lambda: obs)), num_actions=(3, 2), hidden=4)
    assert model.action_shape == (2,)
    np.testing.assert_array_equal(model.action_code(jnp.asarray([[2, 1], [0, 0]])),
                                  [[0, 0, 1, 0, 1], [1, 0, 0, 1, 0]])
    params = model.init(jax.random.PRNGKey(0))
    assert params["wx"].shape[0] == model.input_size
    t, n = 4, 3
    ll = bm.step_logliks(model, params, jnp.zeros((t, n, 3), jnp.int32), jnp.ones((t, n, 2), jnp.int32),
                         jnp.zeros((t, n), bool).at[0].set(True))
    assert ll.shape == (t, n) and np.isfinite(np.asarray(ll)).all()


# ------------------------------------------------------------------ PPO learns both components
@pytest.mark.slow
def test_ppo_learns_a_task_whose_reward_needs_both_components():
    """The dials task: chance solves 1/6 of episodes; DR with PPO solves nearly all after training."""
    from remidi.engine import train as tr
    from remidi.engine.config import UEDConfig
    from remidi.engine.core.ppo import PPOConfig
    from remidi.engine.run import driver, evaluation
    from remidi.engine.run.validation import validate_ued_config

    task = dials_task()
    cfg = UEDConfig(num_updates=40, num_envs=32, num_steps=2, network="mlp", hidden_size=32, eval_every=40,
                    eval_attempts=32, checkpoint_every=40,
                    ppo=PPOConfig(epochs=4, minibatches=2, lr=3e-3, anneal_lr=False, gamma=0.0, gae_lambda=0.0))
    validate_ued_config(cfg, "dr", task)
    setup = tr.make_setup(task, cfg, "dr")
    before = evaluation.evaluate(setup, tr.init_runner(setup, jax.random.PRNGKey(0)), jax.random.PRNGKey(1))
    assert abs(float(before["solve_rate/all"]) - 1 / 6) < 0.1  # chance: 6 equally likely answers
    hist = driver.train_seeds(task, cfg, "dr", [0], progress=False).history
    assert float(hist["solve_rate/all"][0, -1]) > 0.95


class CountingGears(GearsEnv):
    """:class:`GearsEnv` with integer observations (the belief model reads categories) and a reward
    for moving component 0 far enough."""

    def reset_env_to_level(self, rng, level, params):
        return jnp.zeros(2, jnp.int32), (level, jnp.zeros(2), jnp.zeros((), jnp.int32))

    def step_env(self, rng, state, action, params):
        pos, state, _, done, info = super().step_env(rng, state, action, params)
        return jnp.clip(pos, 0, 15).astype(jnp.int32), state, (pos[0] > 3).astype(jnp.float32), done, info


@pytest.mark.slow
@pytest.mark.parametrize("tracker", ["belief", "simulated"])
def test_remidi_runs_the_learned_trackers_on_component_actions(tracker):
    """ReMiDi over two buffers with a learned tracker: the models read the agent's component
    actions (recorded i32[..., 2] for the reference and the noise model) and the run stays finite."""
    from remidi.engine.config import BufferConfig, ReMiDiConfig, UEDConfig
    from remidi.engine.core.ppo import PPOConfig
    from remidi.engine.run import driver
    from remidi.engine.run.validation import validate_ued_config

    task = UEDTask(env=CountingGears(), params=None, max_episode_steps=8, deterministic_reset=True,
                   sample_level=lambda rng: Gears(m=jax.random.randint(rng, (2,), 0, 2)),
                   action_space=MultiDiscrete((3, 2)), eval_sets={"ones": Gears(m=jnp.ones((2, 2), jnp.int32))})
    cfg = UEDConfig(num_updates=4, num_envs=4, num_steps=8, network="mlp", hidden_size=8, eval_every=4,
                    eval_attempts=1, checkpoint_every=4, score="pvl", ppo=PPOConfig(epochs=1, minibatches=1),
                    buffer=BufferConfig(capacity=4, min_fill=0.25),
                    remidi=ReMiDiConfig(num_buffers=2, buffer_capacity=4, steps_per_buffer=2, tracker=tracker,
                                        belief_calibration=2, belief_reference=True))
    validate_ued_config(cfg, "remidi", task)
    result = driver.train_seeds(task, cfg, "remidi", [0], progress=False)
    assert result.runner.tracker.actions.shape[-1] == 2  # [seeds, R, T, N, components]
    assert np.isfinite(result.history["return/ones"]).all() and int(result.runner.adversary.active[0]) == 1
