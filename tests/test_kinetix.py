"""Kinetix as a UED domain (needs the kinetix extra: skipped without it; `.ci/run` runs this file in
an environment of its own, `.ci/.venv-kinetix`): the task passes validation, sampled levels pass
Kinetix's no-op filter, the held-out levels load and `remidi evaluate` plays them, PLR⊥ and ReMiDi
write their outputs and resume, ACCEL's edits are valid levels, the entity observation follows
remidi's convention. Compiling Kinetix's sampler and physics costs minutes on 2 cores; the
persistent compilation cache (tests/conftest.py) keeps later runs of this file short."""

import json
import shutil

import pytest

pytest.importorskip("kinetix")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from test_cli import assert_resumes_to_the_uninterrupted_result  # noqa: E402

from remidi.cli import main  # noqa: E402
from remidi.engine.run.task_checks import validate_task  # noqa: E402
from remidi.envs import kinetix as K  # noqa: E402
from remidi.envs.kinetix_levels import level_files  # noqa: E402
from remidi.envs.kinetix_names import HELD_OUT  # noqa: E402
from remidi.envs.kinetix_obs import entity_observation  # noqa: E402

pytestmark = pytest.mark.slow  # compiles Kinetix's physics: `pytest -m "not slow"` skips it

NOOP = 8  # Kinetix's DISCRETE no-op: 2 · 4 motor bindings
TINY = ["--set", "num_updates=4", "--set", "eval_every=2", "--set", "checkpoint_every=2", "--set", "num_envs=4",
        "--set", "num_steps=16", "--set", "eval_attempts=1", "--set", "hidden_size=16", "--set", "buffer.capacity=8",
        "--set", "remidi.buffer_capacity=8", "--set", "remidi.steps_per_buffer=2", "--set", "buffer.min_fill=0.25"]


@pytest.fixture(scope="module")
def task():
    return K.kinetix_task("s")


@pytest.fixture(scope="module")
def levels(task):
    """16 sampled levels (leaves [16, ...])."""
    return jax.jit(jax.vmap(task.sample_level))(jax.random.split(jax.random.PRNGKey(0), 16))


def noop_returns(task, levels, steps: int) -> np.ndarray:
    """f32[L]: each level's first-episode return under the no-op over ``steps`` steps."""
    n = jax.tree.leaves(levels)[0].shape[0]

    @jax.jit
    def play(levels):
        keys = jax.random.split(jax.random.PRNGKey(1), n)
        _, state = jax.vmap(task.env.reset_to_level, (0, 0, None))(keys, levels, task.params)

        def step(carry, _):
            state, alive, ret = carry
            _, state, reward, done, _ = jax.vmap(task.env.step, (0, 0, 0, None))(
                keys, state, jnp.full((n,), NOOP), task.params)
            return (state, alive & ~done, ret + jnp.where(alive, reward, 0.0)), None

        (_, _, ret), _ = jax.lax.scan(step, (state, jnp.ones(n, bool), jnp.zeros(n)), None, steps)
        return ret

    return np.asarray(play(levels))


def test_the_task_passes_validation_and_names_its_held_out_levels(task):
    validate_task(task)
    assert task.num_actions == 11 and task.max_episode_steps == 256 and task.deterministic_reset
    for size in ("s", "m", "l"):  # the names the experiment knows without Kinetix are the package's files
        assert sorted(HELD_OUT[size]) == sorted(level_files(size))
    assert sorted(task.eval_sets) == sorted(f"s_{n}" for n in HELD_OUT["s"])
    tags = jax.eval_shape(task.level_tags, jax.tree.map(lambda x: x[0], task.eval_sets["s_h0_weak_thrust"]))
    assert set(tags) == {"has_motor", "has_thruster", "has_red", "shapes_2", "shapes_3"}
    assert K.shape_buckets(5) == [(2, 3), (4, 5)] and K.shape_buckets(12) == [(2, 3), (4, 6), (7, 12)]


def test_sampled_levels_are_not_solved_by_doing_nothing(task, levels):
    """Kinetix's filter draws each level from two candidates, down-weighting one the no-op solves
    within 64 steps 1000:1: over a whole episode the no-op solves few of them (a level both of
    whose candidates the no-op solves slips through, as in Kinetix); without it, about a quarter
    (measured: 15 of 64 within 64 steps)."""
    ret = noop_returns(task, levels, 64)
    assert (ret > 0.5).sum() <= 1, ret
    tags = jax.vmap(task.level_tags)(levels)
    assert bool(jnp.all(tags["has_motor"] | tags["has_thruster"]))  # Kinetix forces a control on every level


def test_the_return_says_whether_the_goal_was_reached(task):
    """The shaping of an episode is bounded by ±0.45, so a return > 0.5 is the goal (+1) and nothing else."""
    levels = jax.tree.map(lambda *xs: jnp.concatenate(xs), *task.eval_sets.values())
    ret = noop_returns(task, levels, 256)
    assert np.all(np.abs(ret - np.round(ret)) <= K.SHAPING_BOUND + 1e-5), ret


def test_accel_edits_are_valid_levels_of_the_same_shapes(task, levels):
    level = jax.tree.map(lambda x: x[0], levels)
    edited = jax.jit(task.mutate_level, static_argnums=2)(jax.random.PRNGKey(3), level, 5)
    assert jax.tree.structure(edited) == jax.tree.structure(level)
    assert all(a.shape == b.shape and a.dtype == b.dtype for a, b in zip(jax.tree.leaves(edited), jax.tree.leaves(level)))
    assert any(bool(jnp.any(a != b)) for a, b in zip(jax.tree.leaves(edited), jax.tree.leaves(level)))
    for roles, active in ((edited.polygon_shape_roles, edited.polygon.active), (edited.circle_shape_roles, edited.circle.active)):
        assert roles.shape == active.shape
    green = jnp.sum((edited.polygon_shape_roles == 1) & edited.polygon.active) + jnp.sum(
        (edited.circle_shape_roles == 1) & edited.circle.active)
    blue = jnp.sum((edited.polygon_shape_roles == 2) & edited.polygon.active) + jnp.sum(
        (edited.circle_shape_roles == 2) & edited.circle.active)
    assert green >= 1 and blue >= 1  # still a task: a shape to move and a goal
    obs, _ = task.env.reset_to_level(jax.random.PRNGKey(0), edited, task.params)
    assert obs.shape == (140,) and bool(jnp.all(jnp.isfinite(obs)))


def test_the_entity_observation_follows_the_convention():
    from kinetix.environment import EnvParams, ObservationType, make_kinetix_env, static_env_params_from_size
    from kinetix.environment import ActionType

    static = static_env_params_from_size("s")
    env = make_kinetix_env(ActionType.DISCRETE, ObservationType.SYMBOLIC_ENTITY, None, EnvParams(), static,
                           auto_reset=False)
    level = jax.tree.map(lambda x: x[0], K.held_out_sets("s", static)["s_h2_one_wheel_car"])
    raw, _ = env.reset(jax.random.PRNGKey(0), EnvParams(), override_reset_state=level)
    obs = entity_observation(raw)
    assert set(obs) == {"entities"} and set(obs["entities"]) == {"polygons", "circles", "joints", "thrusters"}
    shapes = static.num_polygons + static.num_circles  # 7
    widths = {"polygons": 27 + 2 * shapes, "circles": 19 + 2 * shapes, "joints": 22 + 2 * shapes,
              "thrusters": 8 + shapes}
    rows = {"polygons": 5, "circles": 2, "joints": 2, "thrusters": 1}
    for name, group in obs["entities"].items():
        assert set(group) == {"features", "mask"}
        assert group["features"].shape == (rows[name], widths[name]) and group["features"].dtype == jnp.float32
        assert group["mask"].shape == (rows[name],) and group["mask"].dtype == jnp.bool_
    np.testing.assert_array_equal(obs["entities"]["polygons"]["mask"], raw.polygon_mask)
    np.testing.assert_array_equal(obs["entities"]["joints"]["features"][:, :22], raw.joints)
    links = np.asarray(obs["entities"]["joints"]["features"][:, 22:]).reshape(2, 2, shapes)
    np.testing.assert_array_equal(links.argmax(-1), raw.joint_indexes)  # a→b, then b→a
    thruster = np.asarray(obs["entities"]["thrusters"]["features"][:, 8:])
    np.testing.assert_array_equal(thruster.argmax(-1), raw.thruster_indexes)
    touching = np.asarray(obs["entities"]["polygons"]["features"][:, 27 + shapes:])
    np.testing.assert_array_equal(touching, np.asarray(raw.attention_mask[3][:5], np.float32))
    batched = jax.vmap(entity_observation)(jax.tree.map(lambda x: jnp.stack([x, x]), raw))  # a batch: a leading axis
    assert batched["entities"]["circles"]["features"].shape == (2, 2, widths["circles"])


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("kinetix") / "run"
    assert main(["run", "kinetix-s", "--algo", "plr,remidi", "--seeds", "1", "--quiet", *TINY, "--out", str(out)]) == 0
    return out


def test_plr_and_remidi_write_their_outputs(run):
    assert (run / "training.png").exists()
    for algo in ("plr", "remidi"):
        for name in ("config.json", "metrics.csv", "summary.json", "checkpoint.npz"):
            assert (run / algo / name).exists(), (algo, name)
        assert json.loads((run / algo / "config.json").read_text())["experiment"] == "kinetix-s"
        metrics = json.loads((run / algo / "summary.json").read_text())["metrics"]
        assert 0 <= metrics["solve_rate/mean"]["mean"] <= 1 and "solve_rate/s_h0_weak_thrust" in metrics
        assert "replay_fraction/has_thruster" in metrics


def test_evaluate_plays_the_held_out_levels(run, tmp_path):
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    assert main(["evaluate", str(copy), "--attempts", "1", "--cvar-levels", "4", "--cvar-attempts", "1"]) == 0
    doc = json.loads((copy / "evaluate.json").read_text())
    for algo in ("plr", "remidi"):
        m = doc["algorithms"][algo]["metrics"]
        assert all(f"solve_rate/s_{n}" in m for n in HELD_OUT["s"]) and "cvar/solve_rate/10%" in m


@pytest.mark.usefixtures("no_png")
def test_an_interrupted_run_resumes_to_the_uninterrupted_result(run, tmp_path, monkeypatch):
    assert_resumes_to_the_uninterrupted_result(
        monkeypatch, ["run", "kinetix-s", "--algo", "remidi", "--seeds", "1", "--quiet", *TINY], tmp_path, at=2)
