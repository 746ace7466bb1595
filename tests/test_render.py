"""``remidi render``: held-out mazes, a run's level buffers and an episode, as PNG / GIF files;
every bad input is one line on stderr, exit 2, and writes nothing.

The run folder is built the way ``remidi run`` builds one (``write_run_config``, the driver's
``_init`` runner and ``save_checkpoint``), with its buffers filled by hand instead of by training:
a real training run compiles for close to a minute on a 2-core CPU.
"""

from __future__ import annotations

import shutil

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from PIL import Image

from remidi.runs import render, sheets
from remidi.cli import main

SEEDS = [0, 1]
NUM_BUFFERS, CAPACITY = 3, 6
TINY = {"num_updates": 20, "num_envs": 4, "num_steps": 8, "eval_every": 10, "checkpoint_every": 10,
        "eval_attempts": 1, "remidi.num_buffers": NUM_BUFFERS, "remidi.buffer_capacity": CAPACITY,
        "remidi.steps_per_buffer": 5}


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def snapshot(*folders):
    return {str(p): p.read_bytes() for folder in folders for p in sorted(folder.rglob("*")) if p.is_file()}


def level_pool(num_tmazes: int, num_mazes: int):
    """T-mazes (the generator's) and random 13×13 mazes (25 walls, built with NumPy: no compiling)."""
    from remidi.envs.maze import MazeLevel, tmaze_level

    rng = np.random.default_rng(1)
    levels = [tmaze_level(jax.random.PRNGKey(i)) for i in range(num_tmazes)]
    for _ in range(num_mazes):
        cells = rng.choice(13 * 13, 27, replace=False)
        walls = np.zeros(13 * 13, bool)
        walls[cells[:25]] = True
        (gy, gx), (ay, ax) = np.divmod(cells[25], 13), np.divmod(cells[26], 13)
        levels.append(MazeLevel.make(walls.reshape(13, 13), (gx, gy), (ax, ay), rng.integers(4)))
    return jax.tree.map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *levels)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """``{"maze": a tmaze/remidi run folder with a checkpoint, "lever": a lever run's folder}``.

    Buffers of seed s: buffer 0 full (CAPACITY levels), buffer 1 with 3 levels in scattered slots,
    buffer 2 empty; buffer 1 is the active one. Scores are distinct; seed 0's buffer 0 holds a
    T-maze at its best score."""
    from remidi.engine.run import driver
    from remidi.engine import train as tr
    from remidi.engine.run.checkpoint import CHECKPOINT, save_checkpoint
    from remidi.experiments import get_experiment
    from remidi.experiments.base import RunSpec, resolve_config
    from remidi.experiments.running import write_run_config
    from remidi.experiments.maze import task_factory

    root = tmp_path_factory.mktemp("render")
    exp = get_experiment("tmaze")
    config = resolve_config(exp, "smoke", TINY)
    exp.validate(config, "remidi")
    folder = root / "tmaze_run"
    folder.mkdir()
    write_run_config(folder, RunSpec(exp, ["remidi"], "smoke", SEEDS, argv=["run", "tmaze"]), "remidi", config)
    setup = tr.make_setup(task_factory("tmaze")(config), config, "remidi")
    runner = jax.device_get(driver._init(setup, jax.vmap(jax.random.PRNGKey)(jnp.asarray(SEEDS, jnp.uint32))))

    pool = level_pool(2, 2 * (CAPACITY + 3))
    tmazes, mazes = np.flatnonzero(pool.tmaze), np.flatnonzero(~pool.tmaze)
    # [S, K, C] index into the pool, valid flags and scores
    pick = np.zeros((len(SEEDS), NUM_BUFFERS, CAPACITY), int)
    valid = np.zeros_like(pick, bool)
    scores = np.zeros(pick.shape, np.float32)
    rng = np.random.default_rng(0)
    for s in range(len(SEEDS)):
        ordinary = iter(mazes[s * (CAPACITY + 3):])
        pick[s, 0] = [tmazes[s]] + [next(ordinary) for _ in range(CAPACITY - 1)]
        valid[s, 0] = True
        scores[s, 0] = [5.0] + list(rng.uniform(0, 1, CAPACITY - 1))
        for slot in (0, 2, 5):
            pick[s, 1, slot] = next(ordinary)
            valid[s, 1, slot] = True
        scores[s, 1] = rng.uniform(0, 1, CAPACITY)
    levels = jax.tree.map(
        lambda x: np.where(valid.reshape(valid.shape + (1,) * (x.ndim - 1)), x[pick], 0).astype(x.dtype), pool)
    runner = runner.replace(adversary=runner.adversary.replace(
        buffers=runner.adversary.buffers.replace(levels=levels, valid=valid,
                                                 scores=np.where(valid, scores, 0.0).astype(np.float32)),
        active=np.ones(len(SEEDS), np.int32)))
    save_checkpoint(folder / CHECKPOINT, runner, {"done": 20, "steps": [10, 20], "num_blocks": 2})

    lever = root / "lever_run"
    lever.mkdir()
    lexp = get_experiment("lever")
    write_run_config(lever, RunSpec(lexp, ["remidi"], "smoke", [0], argv=["run", "lever"]), "remidi",
                     resolve_config(lexp, "smoke", {}))
    (lever / CHECKPOINT).write_bytes(b"")
    return {"maze": folder, "lever": lever, "levels": levels, "scores": scores, "valid": valid}


def sheet_size(rows: int, columns: int, tile: int, size: int = 13, row_header: bool = False):
    """(width, height) of a render sheet (see remidi.runs.render's module docstring): a buffer sheet
    (``row_header``) with the buffers' colour key, a maze sheet with the mazes'."""
    tile_px = (size + 2) * tile
    row_h = (sheets.ROW_HEADER if row_header else 0) + sheets.CAPTION + tile_px + sheets.PAD
    width = sheets.PAD + columns * (tile_px + sheets.PAD)
    key = sheets.key_height(width, sheets.KEY if row_header else sheets.MAZE_KEY)
    return width, sheets.HEADER + key + rows * row_h + sheets.PAD


def maze_tile(rows: int, columns: int, tile: int, size: int) -> int:
    """The pixels per cell of a maze sheet asked for ``tile``: the least from ``tile`` on whose
    sheet is at least MIN_SIDE pixels on its short side."""
    while min(sheet_size(rows, columns, tile, size)) < sheets.MIN_SIDE:
        tile += 1
    return tile


# ------------------------------------------------------------------------------------- maze
@pytest.mark.parametrize("name, rows, columns, size, tile", [
    ("SmallCorridor", 2, 5, 13, 4),  # 10 goal placements; 4 pixels per cell would be too small to read
    ("LargeCorridor", 2, 8, 19, 16),  # 16; the default cells are large enough
    ("SixteenRooms", 1, 1, 13, 16),
    ("SixteenRooms", 1, 1, 13, 50),  # larger than needed: as asked
])
def test_render_maze_writes_the_grid_of_goal_placements(tmp_path, capsys, monkeypatch, name, rows, columns, size,
                                                         tile):
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(capsys, "render", "maze", name, "--tile", tile)
    assert code == 0, err
    assert out == f"wrote {name}.png\n"
    with Image.open(tmp_path / f"{name}.png") as img:
        assert img.format == "PNG"
        assert img.size == sheet_size(rows, columns, maze_tile(rows, columns, tile, size), size)
        assert min(img.size) >= sheets.MIN_SIDE


def test_render_maze_tiles_are_the_renderers_under_one_title_and_a_key(tmp_path):
    """The tiles are jaxued's renderer's, at the least readable size; the sheet says the maze's
    name once (its title: a tile is captioned with its goal), and its key shows every colour the
    tiles use (wall, floor, goal, agent, the agent's view) with its name."""
    from jaxued.environments.maze.renderer import MazeRenderer

    from remidi.envs.maze import MazeEnv, held_out_sets

    path = render.render_maze("SmallCorridor", out=tmp_path / "c.png", tile=3)
    img = np.asarray(Image.open(path).convert("RGB"))
    _, levels = held_out_sets()["SmallCorridor"]
    env = MazeEnv(13)
    tile = maze_tile(2, 5, 3, 13)
    tile_px = 15 * tile
    # goal placement #3 is the second row (bottom dead ends), second column
    want = np.asarray(MazeRenderer(env.maze, tile).render_level(jax.tree.map(lambda x: x[3], levels),
                                                                env.default_params))
    head = sheets.HEADER + sheets.key_height(img.shape[1], sheets.MAZE_KEY)
    top = head + (sheets.CAPTION + tile_px + sheets.PAD) + sheets.CAPTION
    left = sheets.PAD + (tile_px + sheets.PAD)
    np.testing.assert_array_equal(img[top:top + tile_px, left:left + tile_px], want)
    key = img[sheets.HEADER:head].reshape(-1, 3)
    for colour, _ in sheets.MAZE_KEY:
        assert (key == colour).all(axis=1).sum() >= (sheets.SWATCH - 2) ** 2, colour
    names = " ".join(label for _, label in sheets.MAZE_KEY)
    assert all(word in names for word in ("wall", "floor", "goal", "agent", "view"))
    assert "active buffer" not in names


def test_render_maze_names_a_single_maze_once(tmp_path, monkeypatch):
    """A maze of one goal placement: the title names it, the tile's caption gives its goal."""
    captions = []
    real = render._sheet
    monkeypatch.setattr(render, "_sheet", lambda title, rows, *a, **k: captions.append(
        (title, [c for row in rows for c in row["captions"]])) or real(title, rows, *a, **k))
    render.render_maze("SixteenRooms", out=tmp_path / "s.png")
    ((title, tiles),) = captions
    assert title == "SixteenRooms (13x13)" and tiles == ["goal (11, 11)"]


# ---------------------------------------------------------------------------------- buffers
def test_render_buffers_one_row_per_buffer_active_marked(runs, capsys):
    folder = runs["maze"]
    code, out, err = run_cli(capsys, "render", "buffers", folder, "--tile", 4, "--top", 4)
    assert code == 0, err
    path = folder / "buffers_seed0.png"
    assert out == f"wrote {path}\n"
    img = np.asarray(Image.open(path).convert("RGB"))
    assert (img.shape[1], img.shape[0]) == sheet_size(NUM_BUFFERS, 4, 4, row_header=True)
    tile_px = 15 * 4
    row_h = sheets.ROW_HEADER + sheets.CAPTION + tile_px + sheets.PAD
    head = sheets.HEADER + sheets.key_height(img.shape[1])
    band = lambda k: img[head + k * row_h + 1, -3]  # noqa: E731 (right end of row k's header band)
    assert tuple(band(1)) == sheets.ACTIVE_BAND  # buffer 1 is the active one
    assert tuple(band(0)) == tuple(band(2)) == sheets.BACKGROUND

    # the colour key under the title: a swatch of every colour the sheet uses, with its name
    assert sheets.key_height(img.shape[1]) >= sheets.KEY_ROW
    key = img[sheets.HEADER:head].reshape(-1, 3)
    for colour, _ in sheets.KEY:
        assert (key == colour).all(axis=1).sum() >= (sheets.SWATCH - 2) ** 2, colour
    assert {label for _, label in sheets.KEY} >= {"wall", "floor", "goal", "active buffer"}

    def tile(k, c):
        top = head + k * row_h + sheets.ROW_HEADER + sheets.CAPTION
        left = sheets.PAD + c * (tile_px + sheets.PAD)
        return img[top:top + tile_px, left:left + tile_px]

    # buffer 0: the best level (the T-maze, score 5) first; buffer 1: 3 levels; buffer 2: empty
    best = jax.tree.map(lambda x: x[0, 0, 0], runs["levels"])
    np.testing.assert_array_equal(tile(0, 0), sheets._render_levels(jax.tree.map(lambda x: x[None], best), 13, 4)[0])
    assert (tile(1, 2) != 255).any() and (tile(1, 3) == 255).all()
    assert (tile(2, 0) == 255).all()


def test_render_buffers_other_seed_top_beyond_capacity_and_out(runs, tmp_path, capsys):
    out = tmp_path / "b.png"
    code, stdout, err = run_cli(capsys, "render", "buffers", runs["maze"], "--seed", 1, "--top", 50, "--tile", 2,
                                "--out", out)
    assert code == 0, err
    assert stdout == f"wrote {out}\n"
    with Image.open(out) as img:
        assert img.size == sheet_size(NUM_BUFFERS, CAPACITY, 2, row_header=True)


# ---------------------------------------------------------------------------------- episode
def test_render_episode_writes_an_animated_gif(runs, capsys):
    folder = runs["maze"]
    code, out, err = run_cli(capsys, "render", "episode", folder, "--maze", "LargeCorridor", "--seed", 1,
                             "--goal-index", 3, "--attempt-seed", 2, "--tile", 3)
    assert code == 0, err
    path = folder / "episode_LargeCorridor_seed1.gif"
    assert out.startswith(f"wrote {path} (LargeCorridor goal #3, seed 1: ") and out.count("\n") == 1
    assert "return " in out and "solved" in out
    with Image.open(path) as img:
        assert img.format == "GIF"
        assert 1 < img.n_frames <= 251
        assert img.size[0] >= (19 + 2) * 3 + 5 * 2 * 3


# ----------------------------------------------------------------------------------- errors
ALLOWED_MAZES = "allowed: SixteenRooms, SixteenRooms2, Labyrinth, LabyrinthFlipped, Labyrinth2"


@pytest.mark.parametrize("argv, needle", [
    (["render", "maze", "Nope"], f"maze: unknown value 'Nope'; {ALLOWED_MAZES}"),
    (["render", "maze", "SmallCorridor", "--out", "{tmp}/missing/x.png"], "--out: folder"),
    (["render", "maze", "SmallCorridor", "--out", "{tmp}/x.gif"], "--out: {tmp}/x.gif must be a .png file name"),
    (["render", "maze", "SmallCorridor", "--tile", "0"], "--tile: must be an integer in [2, 64]"),
    (["render", "buffers", "{tmp}"], "holds no run (no config.json)"),
    (["render", "buffers", "{tmp}/nowhere"], "{tmp}/nowhere does not exist"),
    (["render", "buffers", "{nockpt}"], "has no checkpoint.npz"),
    (["render", "buffers", "{maze}", "--seed", "7"], "--seed: unknown value 7; allowed: 0, 1"),
    (["render", "buffers", "{maze}", "--top", "0"], "--top: must be an integer ≥ 1"),
    (["render", "buffers", "{maze}", "--out", "{tmp}/missing/b.png"], "--out: folder"),
    (["render", "buffers", "{lever}"], "is a 'lever' run; render buffers/episode needs a maze run"),
    (["render", "episode", "{lever}", "--maze", "SmallCorridor"], "is a 'lever' run"),
    (["render", "episode", "{maze}", "--maze", "Nope"], f"--maze: unknown value 'Nope'; {ALLOWED_MAZES}"),
    (["render", "episode", "{maze}", "--maze", "SmallCorridor", "--goal-index", "10"],
     "--goal-index: must be an integer in [0, 9] for SmallCorridor"),
    (["render", "episode", "{maze}", "--maze", "Labyrinth", "--goal-index", "1"], "--goal-index: must be 0"),
    (["render", "episode", "{maze}", "--maze", "Labyrinth", "--seed", "3"], "--seed: unknown value 3"),
    (["render", "episode", "{maze}", "--maze", "Labyrinth", "--attempt-seed", "-1"], "--attempt-seed"),
    (["render", "episode", "{maze}", "--maze", "Labyrinth", "--out", "{tmp}/e.png"], "must be a .gif file name"),
    (["render", "episode", "{maze}"], "the following arguments are required: --maze"),
    (["render", "episode", "{nockpt}", "--maze", "Labyrinth"], "has no checkpoint.npz"),
    (["render"], "remidi render: say what to draw"),
])
def test_bad_input_is_one_line_exit_2_and_writes_nothing(runs, tmp_path, capsys, monkeypatch, argv, needle):
    nockpt = tmp_path / "no_checkpoint"
    nockpt.mkdir()
    shutil.copy(runs["maze"] / "config.json", nockpt / "config.json")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    names = {"tmp": tmp_path, "maze": runs["maze"], "lever": runs["lever"], "nockpt": nockpt}
    argv = [a.format(**names) for a in argv]
    before = snapshot(tmp_path, runs["maze"], runs["lever"])
    code, out, err = run_cli(capsys, *argv)
    assert code == 2
    assert err.startswith("remidi: error: ") and err.count("\n") == 1, err
    assert needle.format(**names) in err
    assert out == ""
    assert snapshot(tmp_path, runs["maze"], runs["lever"]) == before


def test_render_buffers_of_a_dr_run_says_dr_keeps_none(tmp_path, capsys):
    """DR keeps no level (its state's buffer has no slot): render buffers says so in one line
    instead of drawing an empty buffer."""
    from remidi.engine.run import driver
    from remidi.engine import train as tr
    from remidi.engine.run.checkpoint import CHECKPOINT, save_checkpoint
    from remidi.experiments import get_experiment
    from remidi.experiments.base import RunSpec, resolve_config
    from remidi.experiments.running import write_run_config
    from remidi.experiments.maze import task_factory

    exp = get_experiment("tmaze")
    config = resolve_config(exp, "smoke", TINY)
    folder = tmp_path / "dr_run"
    folder.mkdir()
    write_run_config(folder, RunSpec(exp, ["dr"], "smoke", SEEDS, argv=["run", "tmaze"]), "dr", config)
    setup = tr.make_setup(task_factory("tmaze")(config), config, "dr")
    runner = jax.device_get(driver._init(setup, jax.vmap(jax.random.PRNGKey)(jnp.asarray(SEEDS, jnp.uint32))))
    save_checkpoint(folder / CHECKPOINT, runner, {"done": 20, "steps": [10, 20], "num_blocks": 2})
    code, out, err = run_cli(capsys, "render", "buffers", folder)
    assert code == 2 and out == "" and err == (f"remidi: error: RUN_DIR: {folder} is a dr run, which keeps no level "
                                               f"buffers (fresh levels every update); render episode shows its agent\n")
    assert not list(folder.glob("*.png"))


def test_a_several_algorithm_folder_names_its_runs(runs, tmp_path, capsys):
    (tmp_path / "both" / "remidi").mkdir(parents=True)
    shutil.copy(runs["maze"] / "config.json", tmp_path / "both" / "remidi" / "config.json")
    code, _, err = run_cli(capsys, "render", "buffers", tmp_path / "both")
    assert code == 2 and "pass one of its sub-folders: remidi" in err


def test_help(capsys):
    for sub in (["render"], ["render", "maze"], ["render", "buffers"], ["render", "episode"]):
        with pytest.raises(SystemExit) as exc:
            main([*sub, "--help"])
        assert exc.value.code == 0
        assert "usage: remidi render" in capsys.readouterr().out

