"""`remidi evaluate`: CVaR on hand-known values, perfect mazes against an independent search,
and the whole command on a tiny lever run (keys, files, one-line errors)."""

import csv
import json
import shutil
from pathlib import Path

import jax
import numpy as np
import pytest
from test_cli import LEVER_TINY
from test_maze_env import brute_force_steps

from remidi.cli import main
from remidi.engine.core.distributions import ACTIONS
from remidi.envs import maze as M
from remidi.envs.perfect_mazes import perfect_maze_walls, perfect_mazes
from remidi.runs.evaluate import cvar


def test_cvar_is_the_mean_of_the_worst_share():
    rates = np.array([1.0, 0.0, 0.5, 0.25] + [1.0] * 96)  # 100 levels
    assert cvar(rates, 0.01) == 0.0  # the worst level
    assert cvar(rates, 0.04) == pytest.approx((0 + 0.25 + 0.5 + 1.0) / 4)
    assert cvar(rates, 0.1) == pytest.approx((0 + 0.25 + 0.5 + 7 * 1.0) / 10)
    assert cvar(rates, 1.0) == pytest.approx(rates.mean())
    assert cvar(np.array([0.3, 0.7]), 0.01) == 0.3  # at least one level


def test_cvar_ranks_on_one_set_of_rollouts_and_scores_on_another():
    rank = np.array([0.0, 0.5, 1.0, 0.25])
    score = np.array([0.5, 1.0, 0.0, 0.75])
    assert cvar(score, 0.25, rank_by=rank) == 0.5  # the level ranked worst, scored by the other set
    assert cvar(score, 0.5, rank_by=rank) == pytest.approx((0.5 + 0.75) / 2)
    assert cvar(score, 1.0, rank_by=rank) == pytest.approx(score.mean())


def test_independent_ranking_removes_the_bias_of_ranking_on_the_scored_rollouts():
    """Every level solved with probability 0.5, 4 episodes each: ranked and scored on the same
    episodes, the worst 10% look hopeless (the unlucky draws); ranked on other episodes, their
    score is what the agent really does on them."""
    rng = np.random.default_rng(0)
    first, second = (rng.binomial(4, 0.5, size=2000) / 4 for _ in range(2))
    assert cvar(first, 0.1) < 0.1  # biased: the lowest of 2000 noisy estimates
    assert cvar(second, 0.1, rank_by=first) == pytest.approx(0.5, abs=0.05)


@pytest.mark.parametrize("size", [7, 21, 51])
def test_perfect_mazes_are_trees_and_their_optimum_matches_a_search(size):
    rng = np.random.default_rng(size)
    walls = perfect_maze_walls(rng, size)
    open_cells = {(x, y) for y, x in zip(*np.nonzero(~walls))}
    edges = sum(1 for x, y in open_cells for dx, dy in ((1, 0), (0, 1)) if (x + dx, y + dy) in open_cells)
    assert edges == len(open_cells) - 1  # a tree ...
    seen, stack = {next(iter(open_cells))}, [next(iter(open_cells))]
    while stack:  # ... that is connected: one path between any two open cells
        x, y = stack.pop()
        for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            if (x + dx, y + dy) in open_cells and (x + dx, y + dy) not in seen:
                seen.add((x + dx, y + dy))
                stack.append((x + dx, y + dy))
    assert seen == open_cells and len(open_cells) >= ((size - 1) // 2) ** 2
    levels = perfect_mazes(size, 6, seed=3)
    assert levels.wall_map.shape == (6, size, size)
    again = perfect_mazes(size, 6, seed=3)
    np.testing.assert_array_equal(np.asarray(levels.wall_map), np.asarray(again.wall_map))  # deterministic
    got = np.asarray(jax.jit(jax.vmap(M.optimal_return))(levels))
    for i in range(6):
        n = brute_force_steps(np.asarray(levels.wall_map[i]), np.asarray(levels.goal_pos[i]).tolist(),
                              np.asarray(levels.agent_pos[i]).tolist(), int(levels.agent_dir[i]))
        assert np.isfinite(n)  # a perfect maze connects every open cell
        want = 1 - 0.9 * n / M.MAX_STEPS if n <= M.MAX_STEPS else 0.0
        np.testing.assert_allclose(got[i], want, rtol=1e-6)


@pytest.fixture(scope="module")
def lever_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("evaluate") / "run"
    assert main(["run", "lever", "--algo", "plr,remidi", "--seeds", "2", "--quiet", *LEVER_TINY, "--out", str(out)]) == 0
    return out


def test_evaluate_a_several_algorithm_run(lever_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(lever_run, run)
    capsys.readouterr()
    assert main(["evaluate", str(run), "--attempts", "3", "--cvar-levels", "40", "--cvar-attempts", "2"]) == 0
    doc = json.loads((run / "evaluate.json").read_text())
    assert doc["args"]["cvar_levels"] == 40 and set(doc["algorithms"]) == {"plr", "remidi"}
    for algo, entry in doc["algorithms"].items():
        assert entry["seeds"] == [0, 1] and entry["update"] == entry["num_updates"] == 40
        assert entry["cvar_levels_used"] == 40
        m = entry["metrics"]
        for name in ("solve_rate/visible", "solve_rate/hidden", "solve_rate/mean", "return/visible",
                     "cvar/solve_rate/10%", "cvar/solve_rate/100%", "cvar/return/10%"):
            assert name in m, (algo, name)
        assert "cvar/solve_rate/1%" not in m and "cvar/return/1%" not in m  # 1% of 40 levels: less than one
        for s in range(2):
            # ranked and scored on independent episodes, so the worst 10% may score above the mean
            worst = [m[f"cvar/solve_rate/{a}"]["per_seed"][s] for a in ("10%", "100%")]
            assert all(0 <= w <= 1 for w in worst)
        assert {"generator/solve_rate/hidden", "generator/solve_rate/not-hidden"} <= set(m)
        assert not any(name.startswith("perfect") for name in m)  # only maze runs get perfect mazes
    with open(run / "evaluate.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["algo"] for r in rows} == {"plr", "remidi"} and {r["seed"] for r in rows} == {"0", "1"}
    assert (run / "evaluate.png").stat().st_size > 5_000
    out, err = capsys.readouterr()
    assert "wrote" in out
    assert "CVaR at 1% left out: of 40 levels that share is less than one level" in err and "--cvar-levels 100" in err


def test_evaluate_with_the_most_likely_action_writes_its_own_files(lever_run, tmp_path):
    """--action mode plays the deterministic policy: its files sit beside the sampled evaluation's,
    the policy it scores has no entropy, and its evaluation-set metrics do not depend on the seed
    that draws the episodes (the lever's levels and steps are deterministic)."""
    run = tmp_path / "run"
    shutil.copytree(lever_run, run)
    small = ["--attempts", "2", "--cvar-levels", "8", "--cvar-attempts", "1"]
    assert main(["evaluate", str(run), *small]) == 0
    sampled = (run / "evaluate.json").read_bytes()
    docs = []
    for seed in ("0", "7"):
        assert main(["evaluate", str(run), *small, "--action", "mode", "--seed", seed]) == 0
        docs.append(json.loads((run / "evaluate-mode.json").read_text()))
        assert (run / "evaluate-mode.csv").is_file() and (run / "evaluate-mode.png").is_file()
    assert (run / "evaluate.json").read_bytes() == sampled  # the sampled evaluation is left as it was
    assert docs[0]["args"]["action"] == "mode" and json.loads(sampled)["args"]["action"] == "sample"
    assert docs[0]["code"]["device"] == "cpu: cpu" and "commit" in docs[0]["code"]  # what it ran on
    for algo in ("plr", "remidi"):
        first, again = (d["algorithms"][algo]["metrics"] for d in docs)
        assert first["entropy/visible"]["per_seed"] == [0.0, 0.0]
        for name in ("solve_rate/visible", "solve_rate/hidden", "regret/visible/mean"):
            assert first[name]["per_seed"] == again[name]["per_seed"], (algo, name)


@pytest.mark.parametrize("argv, needle", [
    (["--attempts", "0"], "--attempts: must be an integer ≥ 1, got 0"),
    (["--perfect-sizes", "20"], "--perfect-sizes: each must be an odd integer"),
    (["--perfect-sizes", "x"], "--perfect-sizes: must be comma-separated odd integers"),
    (["--seed", "-1"], "--seed: must be an integer in"),
    (["--action", "mean"], f"--action: unknown value 'mean'; allowed: {', '.join(ACTIONS)}"),
])
def test_bad_evaluate_arguments_are_one_line(lever_run, capsys, argv, needle):
    assert main(["evaluate", str(lever_run), *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err
    assert not (lever_run / "evaluate.json").exists()


def test_a_run_that_cannot_be_written_is_refused_before_evaluating(lever_run, tmp_path, capsys, monkeypatch):
    import remidi.runs.evaluate as ev

    run = tmp_path / "run"
    shutil.copytree(lever_run, run)
    before = sorted(p.relative_to(run) for p in run.rglob("*"))
    monkeypatch.setattr(ev, "writable", lambda folder: Path(folder) != run)

    def no_evaluation(*args, **kwargs):
        raise AssertionError("evaluated a run whose results could not be written")

    monkeypatch.setattr(ev, "_load", no_evaluation)
    assert main(["evaluate", str(run)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{run} is not writable" in err
    assert sorted(p.relative_to(run) for p in run.rglob("*")) == before


def _read_only_folder(tmp_path):
    """A folder no file can be made in, for this process: a read-only tmpfs mounted on it (root,
    where mounting is allowed) or its write bits taken away (anyone else); None if neither is possible."""
    import os
    import subprocess

    folder = tmp_path / "ro"
    folder.mkdir()
    if os.geteuid() != 0:
        folder.chmod(0o555)
        return folder
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "ro", "tmpfs", str(folder)], capture_output=True).returncode:
        return None
    return folder


def test_writable_says_no_where_no_file_can_be_made(tmp_path):
    import os
    import subprocess

    from remidi.files import writable

    assert writable(tmp_path)
    folder = _read_only_folder(tmp_path)
    if folder is None:
        pytest.skip("root without permission to mount: no read-only folder can be made here")
    try:
        assert not writable(folder)
        assert list(folder.iterdir()) == []  # the probe leaves nothing behind
    finally:
        if os.geteuid() == 0:
            subprocess.run(["umount", str(folder)], check=False)


def test_a_folder_that_is_no_ued_run_is_one_line(tmp_path, capsys):
    assert main(["evaluate", str(tmp_path)]) == 2
    assert "holds no run" in capsys.readouterr().err
    from remidi.experiments import get_experiment
    from remidi.experiments.base import RunSpec, resolve_config
    from remidi.experiments.running import write_run_config

    exp = get_experiment("tabular-shared")  # a run's folder as the CLI writes it (evaluate reads its config first)
    (tmp_path / "tab").mkdir()
    write_run_config(tmp_path / "tab", RunSpec(exp, ["mmr"], "smoke", [0], argv=["run", "tabular-shared"]), "mmr",
                     resolve_config(exp, "smoke", {"iterations": 20}))
    assert main(["evaluate", str(tmp_path / "tab")]) == 2
    assert "evaluate needs a UED run" in capsys.readouterr().err


def test_cvar_levels_leave_out_levels_no_agent_can_solve():
    from remidi.runs.evaluate import _solvable_levels

    task = M.maze_task("maze", 0.5, 60)  # 60 walls: many goals cut off
    drawn = jax.jit(jax.vmap(task.sample_level))(jax.random.split(jax.random.PRNGKey(0), 32))
    assert (np.asarray(jax.jit(jax.vmap(M.optimal_return))(drawn)) <= 0).any()  # the generator makes some
    levels = _solvable_levels(task, 32, seed=0)
    assert levels.wall_map.shape[0] == 32
    assert (np.asarray(jax.jit(jax.vmap(M.optimal_return))(levels)) > 0).all()


def test_evaluate_png_is_titled_with_the_experiment_and_the_run(tmp_path, monkeypatch):
    from remidi.runs import evaluate
    from remidi.experiments import plots

    titles = []
    monkeypatch.setattr(plots, "plot_bars", lambda path, title, *args, **kwargs: titles.append(title))
    entry = {"update": 300, "seeds": [0, 1], "metrics": {"solve_rate/visible": {"per_seed": [0.5, 1.0]}}}
    doc = {"run": "/work/runs/lever/20261124-2338", "experiment": "lever", "args": {},
           "algorithms": {"plr": entry, "remidi": entry}}
    evaluate._plot(tmp_path / "evaluate.png", doc)
    assert titles == ["lever: solve rate of lever/20261124-2338's final checkpoint, update 300"]
    # a run evaluated before it finished says so (before: "final checkpoint" for update 300 of 600)
    unfinished = {**entry, "num_updates": 600}
    evaluate._plot(tmp_path / "evaluate.png", {**doc, "algorithms": {"plr": unfinished, "remidi": unfinished}})
    assert titles[1] == "lever: solve rate of lever/20261124-2338's last checkpoint (unfinished), update 300"


def test_cvar_is_reported_from_the_mean_down_and_only_where_its_share_holds_a_level():
    """cvar/<kind>/<α> in the order 100%, 10%, 1% (the mean, then further into the tail); 1% of 50
    levels is half a level, so 1% is left out (it would be the single worst level); of 100, it is one."""
    from types import SimpleNamespace

    from remidi.runs.evaluate import _summarise, cvar_shares

    setup = SimpleNamespace(task=SimpleNamespace(solved=None))
    for n, labels in ((50, ["100%", "10%"]), (100, ["100%", "10%", "1%"]), (9, ["100%"])):
        score = np.linspace(0.0, 1.0, 2 * n).reshape(2, n)
        raw = {"cvar_raw/score/solve_rate": score, "cvar_raw/rank/solve_rate": score}
        out = _summarise(raw, setup, {})
        assert [name for name in out if name.startswith("cvar/")] == [f"cvar/solve_rate/{a}" for a in labels], n
        assert [label for _, label in cvar_shares(n)] == labels
    np.testing.assert_allclose(out["cvar/solve_rate/100%"], score.mean(axis=1))


def test_generator_metrics_by_tag_are_the_scoring_rollouts_means_over_that_kind():
    """generator/<kind>/<tag>: by hand on fixed per-level values (2 seeds, 4 levels, two tagged)."""
    from types import SimpleNamespace

    from remidi.runs.evaluate import _summarise

    score = np.array([[1.0, 0.0, 1.0, 1.0], [0.0, 0.5, 0.25, 0.75]])
    rank = np.zeros_like(score)
    raw = {"cvar_raw/score/solve_rate": score, "cvar_raw/rank/solve_rate": rank,
           "cvar_raw/score/return": score * 10, "cvar_raw/rank/return": rank}
    tags = {"hidden": np.array([True, True, False, False]), "never": np.zeros(4, bool)}
    out = _summarise(raw, SimpleNamespace(task=SimpleNamespace(solved=None)), {}, tags)
    np.testing.assert_allclose(out["generator/solve_rate/hidden"], [0.5, 0.25])
    np.testing.assert_allclose(out["generator/solve_rate/not-hidden"], [1.0, 0.5])
    np.testing.assert_allclose(out["generator/return/hidden"], [5.0, 2.5])
    np.testing.assert_allclose(out["generator/solve_rate/not-never"], [0.75, 0.375])
    assert "generator/solve_rate/never" not in out  # no level of that kind: no number
