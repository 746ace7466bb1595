"""gymnax environments as UED tasks (remidi.envs.gymnax) and the cartpole/acrobot/pendulum
experiments: the adapter steps exactly as gymnax does, levels stay in their ranges, the held-out
grid's return tells a balancing policy from a random one, ACCEL and the CLI run on it, and the
perfect-regret score is refused in one line."""

import csv
import dataclasses
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.cli import main
from remidi.engine.adversaries.scores import SCORES
from remidi.engine.run.evaluation import first_episode_return
from remidi.engine.learner import Policy, Stepping, rollout
from remidi.engine.run.validation import validate_ued_config
from remidi.envs.gymnax import SEED, gymnax_task
from remidi.errors import ConfigError
from remidi.experiments.gymnax import DOMAINS, domain_task, grid_points, paper_config

R = dataclasses.replace
CARTPOLE = DOMAINS["cartpole"]


def rollout_pair(name, max_steps, num_steps, action):
    """Step the domain's adapter and gymnax's own ``step_env`` (on the params the adapter builds
    from the level, op by op) side by side from the same start, with the same keys and actions;
    returns the two lists of ``(obs, reward, done, gymnax state)``."""
    task = domain_task(name, max_steps)
    env, gym = task.env, task.env.gymnax_env
    level = task.sample_level(jax.random.PRNGKey(3))
    params = env.params_for(level, task.params)
    obs, state = env.reset_to_level(jax.random.PRNGKey(99), level, task.params)  # the key is ignored
    g_obs, g_state = gym.reset_env(jax.random.wrap_key_data(level[SEED], impl="threefry2x32"), params)
    ours, theirs = [(obs, 0.0, False, state.env_state)], [(g_obs, 0.0, False, g_state)]
    for t in range(num_steps):
        key = jax.random.PRNGKey(t)
        a = action(jax.random.fold_in(key, 1))
        obs, state, reward, done, _ = env.step_env(key, state, a, task.params)
        g_obs, g_state, g_reward, terminated, _ = gym.step_env(key, g_state, a, params)
        ours.append((obs, reward, done, state.env_state))
        theirs.append((g_obs, g_reward, terminated | gym.is_truncated(g_state, params), g_state))
    return ours, theirs


@pytest.mark.parametrize("name, action", [
    ("cartpole", lambda k: jax.random.randint(k, (), 0, 2)),
    ("acrobot", lambda k: jax.random.randint(k, (), 0, 3)),
    ("pendulum", lambda k: 3.0 * jax.random.normal(k, (1,))),  # beyond the torque limit: gymnax clips
])
def test_the_adapter_steps_bit_for_bit_as_gymnax_and_ends_where_gymnax_does(name, action):
    ours, theirs = rollout_pair(name, max_steps=30, num_steps=40, action=action)
    for t, (a, b) in enumerate(zip(ours, theirs)):
        for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
            np.testing.assert_array_equal(np.asarray(x), np.asarray(y), err_msg=f"{name}, step {t}")
    dones = [bool(d) for _, _, d, _ in ours]
    assert any(dones[:31]), name  # the episode ends (at the latest at the time limit, step 30)


def test_cartpole_level_writes_its_fields_and_recomputes_the_derived_ones():
    task = domain_task("cartpole", 0)
    level = task.sample_level(jax.random.PRNGKey(0))
    p = task.env.params_for(level, task.params)
    assert (p.gravity, p.masspole, p.length) == (level["gravity"], level["masspole"], level["length"])
    np.testing.assert_allclose(p.total_mass, p.masscart + level["masspole"])
    np.testing.assert_allclose(p.polemass_length, level["masspole"] * level["length"])
    assert task.max_episode_steps == 500 and not task.continuous and task.num_actions == 2
    pendulum = domain_task("pendulum", 0)
    assert pendulum.continuous and pendulum.num_actions == 1 and pendulum.max_episode_steps == 200


def test_sampled_and_edited_levels_stay_in_their_ranges():
    task = domain_task("cartpole", 0)
    levels = jax.vmap(task.sample_level)(jax.random.split(jax.random.PRNGKey(0), 2000))
    edited = jax.vmap(lambda k, lv: task.mutate_level(k, lv, 3))(jax.random.split(jax.random.PRNGKey(1), 2000), levels)
    for name, (lo, hi) in CARTPOLE.level.items():
        for batch in (levels, edited):
            assert lo <= float(batch[name].min()) and float(batch[name].max()) <= hi, name
        assert float(levels[name].min()) < lo + 0.05 * (hi - lo) and float(levels[name].max()) > hi - 0.05 * (hi - lo)
        moved = np.abs(np.asarray(edited[name] - levels[name]))
        assert moved.max() <= 3 * 0.1 * (hi - lo) + 1e-5, name  # 3 edits of a tenth of the range at most
        assert (moved > 0).mean() > 0.3, name
    np.testing.assert_array_equal(edited[SEED], levels[SEED])  # an edit keeps the start seed
    assert len(np.unique(np.asarray(levels[SEED]), axis=0)) == 2000
    tags = jax.vmap(task.level_tags)(levels)
    assert set(tags) == {"gravity_high", "masspole_high", "length_high"}
    np.testing.assert_array_equal(tags["gravity_high"], levels["gravity"] > 10.0)


def test_the_grid_holds_every_point_with_the_same_seeds():
    task = domain_task("cartpole", 0)
    assert tuple(task.eval_sets) == grid_points("cartpole") and len(task.eval_sets) == 9
    point = task.eval_sets["gravity=9.8_length=0.25"]
    np.testing.assert_array_equal(point["gravity"], np.full(4, 9.8, np.float32))
    np.testing.assert_array_equal(point["length"], np.full(4, 0.25, np.float32))
    np.testing.assert_array_equal(point["masspole"], np.full(4, 0.1, np.float32))  # gymnax's default
    seeds = np.asarray(point[SEED])
    assert len(np.unique(seeds, axis=0)) == 4
    for levels in task.eval_sets.values():
        np.testing.assert_array_equal(levels[SEED], seeds)


def hand_policy(gain):
    """A linear cart-pole controller (``gain`` 0: uniformly random actions) as a network's apply."""

    def apply(variables, carry, obs, reset):
        x, x_dot, theta, theta_dot = obs[..., 0], obs[..., 1], obs[..., 2], obs[..., 3]
        push = gain * (theta + 0.5 * theta_dot + 0.05 * x + 0.1 * x_dot)
        return carry, (jnp.stack([-push, push], -1), jnp.zeros(obs.shape[:2]))

    return apply


def test_the_grid_return_tells_a_balancing_policy_from_a_random_one():
    """The evaluation's own measure (first-episode return of a rollout over the grid's levels,
    as engine.evaluation.level_returns computes it), per grid point."""
    task = domain_task("cartpole", 200)
    levels = jax.tree.map(lambda *xs: jnp.concatenate(xs), *task.eval_sets.values())  # 9 points × 4 seeds
    n = len(levels["gravity"])
    means = {}
    for gain in (100.0, 0.0):
        traj, _ = rollout(jax.random.PRNGKey(0), Stepping(task.env, task.params, True),
                          Policy(hand_policy(gain), {}, jnp.zeros(n)), levels, task.max_episode_steps)
        means[gain] = np.asarray(first_episode_return(traj.reward, traj.done)).reshape(9, 4).mean(axis=1)
    np.testing.assert_array_equal(means[100.0], 200.0)  # balances every level for the whole episode
    assert means[0.0].max() < 80 and means[0.0].mean() < 40  # random actions drop the pole within steps


def test_perfect_regret_is_refused_in_one_line_and_the_other_scores_are_valid():
    cfg = paper_config()
    task = domain_task("cartpole", 0)
    with pytest.raises(ConfigError) as err:
        validate_ued_config(R(cfg, score="perfect_regret"), "plr", task)
    message = str(err.value)
    assert "\n" not in message and message.startswith("score: perfect_regret needs the environment's optimal return")
    # CartPole has a solve criterion but no optimum: every registered score that needs none is allowed
    allowed = [name for name, score in SCORES.items() if not score.needs_optimum]
    assert "perfect_regret" not in allowed and message.endswith(f"allowed: {', '.join(allowed)}")
    for score in allowed:
        validate_ued_config(R(cfg, score=score), "plr", task)
    no_solve = gymnax_task("CartPole-v1", {"gravity": (5.0, 15.0)})
    with pytest.raises(ConfigError, match="score: learnability needs a solve criterion"):
        validate_ued_config(R(cfg, score="learnability"), "plr", no_solve)


def test_the_adapter_refuses_unknown_fields_and_empty_ranges_in_one_line():
    for kwargs, match in (({"level": {"gravty": (1.0, 2.0)}}, "level field 'gravty' is not a params field"),
                          ({"level": {"gravity": (2.0, 1.0)}}, "low must be ≤ high"),
                          ({"level": {"gravity": (1.0, 2.0)}, "eval_grid": {"length": (0.5,)}},
                           "eval_grid field 'length' is not a level field"),
                          ({"level": {"max_steps_in_episode": (100, 500)}}, "cannot vary by level"),
                          ({"level": {"gravity": 9.8}}, r"level field gravity must be a \(low, high\) pair"),
                          ({"level": {"gravity": (1.0, 2.0)}, "eval_grid": {"gravity": 9.8}},
                           "eval_grid field gravity must be a non-empty list of numbers")):
        with pytest.raises(ConfigError, match=match) as err:
            gymnax_task("CartPole-v1", **kwargs)
        assert "\n" not in str(err.value)
    # Acrobot's torque noise comes from the step's key: the level no longer decides the episode
    with pytest.raises(ConfigError, match="torque_noise_max > 0 draws noise from the step's key"):
        gymnax_task("Acrobot-v1", {"link_mass_1": (0.5, 1.5)}, params={"torque_noise_max": 0.1})
    # an integer field would be drawn as a float: MemoryChain's episode end (time == memory_length) never came
    with pytest.raises(ConfigError, match=r"level field memory_length is int32\[\] in MemoryChain-bsuite's params"):
        gymnax_task("MemoryChain-bsuite", {"memory_length": (2, 10)})
    with pytest.raises(ConfigError, match=r"level field available_torque is float32\[3\] in Acrobot-v1's params"):
        gymnax_task("Acrobot-v1", {"available_torque": (0.5, 1.5)})  # one float per level field, not an array
    # ranges and grids as any one-dimensional sequence of numbers (arrays, ranges)
    task = gymnax_task("CartPole-v1", {"gravity": np.array([5.0, 15.0])}, eval_grid={"gravity": np.linspace(5, 15, 3)})
    assert len(task.eval_sets) == 3
    gymnax_task("CartPole-v1", {"gravity": (5, 15)}, eval_grid={"gravity": range(5, 16, 5)})
    with pytest.raises(ConfigError, match="gymnax: cannot make 'NoSuchEnv-v0'"):
        gymnax_task("NoSuchEnv-v0", {"gravity": (1.0, 2.0)})


TINY = ["--seeds", "1", "--quiet", "--set", "gymnax.max_steps=32", "--set", "num_steps=32", "--set", "num_envs=4",
        "--set", "num_updates=6", "--set", "eval_every=2", "--set", "checkpoint_every=2", "--set", "eval_attempts=1",
        "--set", "hidden_size=16", "--set", "ppo.epochs=1", "--set", "ppo.minibatches=1",
        "--set", "buffer.capacity=8", "--set", "buffer.min_fill=0.25", "--set", "buffer.replay_prob=0.8"]


def test_cartpole_experiment_with_accel_through_the_cli(tmp_path):
    """``remidi run cartpole --algo accel`` at a tiny size: it edits replayed levels, and logs the
    return per grid point and their mean."""
    out = tmp_path / "accel"
    assert main(["run", "cartpole", "--algo", "accel", "--preset", "smoke", "--out", str(out), *TINY]) == 0
    m = {k: v["mean"] for k, v in json.loads((out / "summary.json").read_text())["metrics"].items()}
    points = [m[f"return/{p}"] for p in grid_points("cartpole")]
    assert m["return/mean"] == pytest.approx(np.mean(points), rel=1e-6)
    assert all(0 < r <= 32 for r in points) and 0 <= m["solve_rate/mean"] <= 1
    assert {"replay_fraction/gravity_high", "buffer_fraction/length_high"} <= set(m)
    with open(out / "metrics.csv") as fh:
        edits = [float(r["value"]) for r in csv.DictReader(fh) if r["metric"] == "edit"]
    assert edits and max(edits) > 0  # ACCEL edited replayed levels


def test_pendulum_experiment_trains_its_continuous_agent_through_the_cli(tmp_path):
    out = tmp_path / "dr"
    assert main(["run", "pendulum", "--algo", "dr", "--preset", "smoke", "--out", str(out), *TINY]) == 0
    m = {k: v["mean"] for k, v in json.loads((out / "summary.json").read_text())["metrics"].items()}
    assert -16.3 * 32 <= m["return/mean"] < 0  # at most about 16.3 lost per step (angle π, speed 8, torque 2)
    assert json.loads((out / "config.json").read_text())["config"]["reward_scale"] == 0.1


EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "gymnax_cartpole.py"


def test_the_cartpole_example_is_a_task_in_ten_lines_that_the_cli_runs(monkeypatch, capsys, tmp_path):
    source = EXAMPLE.read_text()
    code = [line for line in source[source.index("\nfrom remidi"):].splitlines() if line.strip()]
    assert len(code) <= 10  # the user's code, blank lines aside: the import and make_task
    monkeypatch.syspath_prepend(str(EXAMPLE.parent.parent))
    from remidi.experiments.custom import import_experiment

    exp = import_experiment("examples.gymnax_cartpole:make_task")
    task = exp.make_task(exp.config_factory())
    assert len(task.eval_sets) == 9 and task.optimal_return is None and task.deterministic_reset
    # no optimum, episodes of 500 steps outlasting a rollout of 256: the default score is pvl, which scores a
    # truncated rollout by its bootstrapped value (experiments/custom.task_defaults)
    assert exp.config_factory().score == "pvl"
    # perfect regret needs an optimum: refused before anything is written, in one line
    assert main(["run", "examples.gymnax_cartpole:make_task", "--out", str(tmp_path / "x"), "--quiet",
                 "--set", "score=perfect_regret"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("remidi: error: score: perfect_regret needs the environment's optimal return")
    assert "\n" not in err and not (tmp_path / "x").exists()


def test_all_algorithms_of_a_gymnax_experiment_are_those_its_task_supports():
    """A gymnax task has no level-building MDP: `--algo all` leaves the learned generators out
    (it was refused by validation), while the maze and lever experiments keep them."""
    from remidi.experiments import get_experiment
    from remidi.experiments.base import parse_algos

    every = parse_algos(get_experiment("cartpole"), "all")
    assert "accel" in every and "paired" not in every and "remidi-paired" not in every
    assert "paired" in parse_algos(get_experiment("lever"), "all")
    # naming one says why it is left out, not that the name is unknown
    allowed = ", ".join(every)
    with pytest.raises(ConfigError, match=r"^--algo: remidi-paired cannot run on cartpole: cartpole's task has no "
                                          rf"level-building MDP \(UEDTask.level_builder\).*; allowed: {allowed}"):
        parse_algos(get_experiment("cartpole"), "dr,remidi-paired")
    with pytest.raises(ConfigError, match="^--algo: unknown value 'pared'"):
        parse_algos(get_experiment("cartpole"), "pared")


def test_solve_thresholds_follow_the_episode_limit():
    """Pendulum's threshold is a cost per step (−200 at gymnax's 200 steps); Acrobot's "up within
    100 steps" becomes "up within the episode" when episodes are shorter: a failed episode (−1 per
    step, −50 over 50 steps) would otherwise count as solved."""
    np.testing.assert_array_equal(np.asarray(domain_task("pendulum", 100).solved(jnp.array([-150.0, -90.0]))),
                                  [False, True])
    assert bool(domain_task("pendulum").solved(jnp.array([-190.0]))[0])
    np.testing.assert_array_equal(np.asarray(domain_task("acrobot", 50).solved(jnp.array([-50.0, -49.0]))),
                                  [False, True])
    np.testing.assert_array_equal(np.asarray(domain_task("acrobot", 500).solved(jnp.array([-101.0, -100.0]))),
                                  [False, True])
