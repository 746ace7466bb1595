"""``remidi render``: pictures of maze levels, of what the adversary chose, and of the agent playing.

* :func:`render_maze`: a held-out maze (corridor mazes: one tile per goal placement) as a PNG with
  a colour key, at least :data:`~remidi.runs.sheets.MIN_SIDE` pixels on its short side.
* :func:`render_buffers`: the top-K levels of every buffer in a maze run's checkpoint, one row per
  buffer (the active one marked), tiles captioned with score and tags, as a PNG.
* :func:`render_episode`: the checkpoint's agent playing one episode on a held-out maze, as a GIF
  of the maze (the 5×5 view highlighted) beside the agent's observation (:data:`EPISODE_KEY`).

Drawing: :mod:`remidi.runs.sheets`. Every bad input raises :class:`~remidi.errors.RemidiError`
(one line) before anything is written."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from remidi.errors import RemidiError, one_of
from remidi.runs import require_folder
from remidi.runs.sheets import (ACTION_NAMES, BACKGROUND, CAPTION, DEFAULT_TILE, DEFAULT_TOP, EPISODE_KEY,
                                EPISODE_STEPS, HEADER, KEY, MAX_COLUMNS, MAZE_EXPERIMENTS, MAZE_KEY, MIN_FRAME_WIDTH,
                                PAD, TILE_RANGE, UNSEEN, _draw_key, _render_levels, _renderer, _save_gif, _save_png,
                                _sheet, _text, key_height, readable_tile)


# ----------------------------------------------------------------------------------- checks
def _check_tile(tile: int) -> int:
    lo, hi = TILE_RANGE
    if not isinstance(tile, int) or not lo <= tile <= hi:
        raise RemidiError(f"--tile: must be an integer in [{lo}, {hi}] (pixels per cell), got {tile}")
    return tile


def _check_out(out, default: Path, suffix: str) -> Path:
    """The output file: ``out`` or ``default``; its folder must exist and its name end in ``suffix``."""
    path = Path(out) if out is not None else default
    if path.suffix.lower() != suffix:
        raise RemidiError(f"--out: {path} must be a {suffix} file name")
    if path.is_dir():
        raise RemidiError(f"--out: {path} is a folder; give a {suffix} file name")
    if not path.parent.is_dir():
        raise RemidiError(f"--out: folder {path.parent} does not exist")
    return path


def _check_maze_name(name: str, flag: str):
    from remidi.envs.maze import HELD_OUT_NAMES, held_out_sets

    if name not in HELD_OUT_NAMES:
        raise one_of(flag, name, HELD_OUT_NAMES)
    return held_out_sets()[name]


# --------------------------------------------------------------------------------- render maze
def render_maze(name: str, out=None, tile: int = DEFAULT_TILE) -> Path:
    """Draw held-out maze ``name`` (every goal placement of a corridor maze) as a titled PNG with a
    colour key, tiles captioned with their goal; ``tile`` pixels per cell, or more where the picture
    would be too small (:func:`readable_tile`)."""
    _check_tile(tile)
    size, levels = _check_maze_name(name, "maze")
    path = _check_out(out, Path(f"{name}.png"), ".png")
    goals = np.asarray(levels.goal_pos)  # [n, 2]
    n = goals.shape[0]
    nrows = math.ceil(n / MAX_COLUMNS)
    ncols = math.ceil(n / nrows)
    tiles = _render_levels(levels, size, readable_tile(tile, nrows, ncols, size + 2, MAZE_KEY))
    rows = [{"tiles": [], "captions": []} for _ in range(nrows)]
    for i in range(n):  # column-major: a corridor's top dead ends on the first row, bottom ones below
        rows[i % nrows]["tiles"].append(tiles[i])
        rows[i % nrows]["captions"].append(f"{f'#{i} ' if n > 1 else ''}goal ({goals[i][0]}, {goals[i][1]})")
    what = f", {n} goal placements (--goal-index 0..{n - 1})" if n > 1 else ""
    canvas = _sheet(f"{name} ({size}x{size}){what}", rows, ncols, tiles.shape[1], row_header=False, key=MAZE_KEY)
    _save_png(path, canvas)
    return path


# ------------------------------------------------------------------------------- run folders
@dataclass
class _Run:
    folder: Path
    experiment: str
    algo: str
    seeds: list[int]
    config: Any
    setup: Any = None


def _load_run(run_dir) -> _Run:
    """The run in ``run_dir`` (config.json), which must be a maze experiment's."""
    from remidi.experiments import saved_experiment
    from remidi.experiments.resuming import saved_run

    folder = Path(run_dir)
    require_folder("RUN_DIR", folder)
    if not (folder / "config.json").is_file():
        subs = sorted(p.name for p in folder.iterdir() if (p / "config.json").is_file())
        hint = f"; it holds a several-algorithm run, pass one of its sub-folders: {', '.join(subs)}" if subs else ""
        raise RemidiError(f"RUN_DIR: {folder} holds no run (no config.json){hint}")
    try:
        with open(folder / "config.json") as fh:
            experiment = json.load(fh)["experiment"]
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise RemidiError(f"RUN_DIR: {folder / 'config.json'} is not a run's config.json ({err})") from None
    if experiment not in MAZE_EXPERIMENTS:
        raise RemidiError(f"RUN_DIR: {folder} is a {experiment!r} run; render buffers/episode needs a maze run "
                          f"(experiments: {', '.join(MAZE_EXPERIMENTS)})")
    _, algo, _, seeds, config = saved_run(saved_experiment, folder, flag="RUN_DIR")
    return _Run(folder=folder, experiment=experiment, algo=algo, seeds=list(seeds), config=config)


def _check_seed(run: _Run, seed) -> int:
    """The index of ``seed`` (default: the run's first) among the run's seeds."""
    if seed is None:
        return 0
    if seed not in run.seeds:
        raise one_of("--seed", seed, run.seeds)
    return run.seeds.index(seed)


def _check_checkpoint(run: _Run) -> Path:
    from remidi.engine.run.driver import CHECKPOINT

    path = run.folder / CHECKPOINT
    if not path.is_file():
        raise RemidiError(f"RUN_DIR: {run.folder} has no {CHECKPOINT} (the run wrote no checkpoint yet)")
    return path


def _load_runner(run: _Run, path: Path):
    """``(runner, meta)`` from the checkpoint; the runner's leaves have the seeds axis first."""
    from remidi.engine.run import driver
    from remidi.engine import train as tr
    from remidi.experiments.maze import task_factory

    task = task_factory(run.experiment)(run.config)
    run.setup = tr.make_setup(task, run.config, run.algo)
    return driver.load_run_state(run.setup, run.seeds, path, flag="RUN_DIR")


def _open_run(run_dir, seed, out, default_name: str, suffix: str):
    """Check everything about a run-folder command, then load the checkpoint: ``(run, seed index,
    seed, output path, runner, checkpoint meta)``; ``default_name`` may use ``{seed}``."""
    run = _load_run(run_dir)
    s = _check_seed(run, seed)
    seed = run.seeds[s]
    path = _check_out(out, run.folder / default_name.format(seed=seed), suffix)
    runner, meta = _load_runner(run, _check_checkpoint(run))
    return run, s, seed, path, runner, meta


# ------------------------------------------------------------------------------ render buffers
def render_buffers(run_dir, top: int = DEFAULT_TOP, seed: int | None = None, out=None,
                   tile: int = DEFAULT_TILE) -> Path:
    """Draw the ``top`` highest-scored levels of each buffer of seed ``seed`` (default: the first)
    in the run's checkpoint, one row per buffer, as a PNG."""
    import jax

    from remidi.envs.maze import TRAIN_SIZE

    _check_tile(tile)
    if not isinstance(top, int) or top < 1:
        raise RemidiError(f"--top: must be an integer ≥ 1, got {top}")
    run, s, seed, path, runner, meta = _open_run(run_dir, seed, out, "buffers_seed{seed}.png", ".png")
    if np.asarray(runner.adversary.buffers.valid).shape[-1] == 0:  # DR: buffers without a slot
        raise RemidiError(f"RUN_DIR: {run.folder} is a {run.setup.algo.name} run, which keeps no level buffers (fresh "
                          f"levels every update); render episode shows its agent")

    buffers = jax.tree.map(lambda x: np.asarray(x[s]), runner.adversary.buffers)  # leaves [K, C, ...]
    levels = getattr(buffers.levels, "level", buffers.levels)  # blindfold-noisy: the maze of a SeededLevel
    active = int(np.asarray(runner.adversary.active)[s])
    valid, scores = buffers.valid, buffers.scores.astype(float)
    num_buffers, capacity = valid.shape
    columns = min(top, capacity)
    picks = []  # (buffer, slot) in drawing order
    for k in range(num_buffers):
        ranked = np.where(valid[k] & ~np.isnan(scores[k]), scores[k], -np.inf)
        slots = [int(i) for i in np.argsort(-ranked, kind="stable") if valid[k, i]][:columns]
        picks.append(slots)
    flat = [(k, i) for k, slots in enumerate(picks) for i in slots]
    if flat:
        ks, idx = np.asarray([k for k, _ in flat]), np.asarray([i for _, i in flat])
        tiles = _render_levels(jax.tree.map(lambda x: x[ks, idx], levels), TRAIN_SIZE, tile)
    tile_px = (TRAIN_SIZE + 2) * tile
    rows, n = [], 0
    for k, slots in enumerate(picks):
        tmaze = np.asarray(levels.tmaze[k]) & valid[k]
        blind = np.asarray(levels.blind[k]) & valid[k]
        state = ("active" if k == active else "frozen" if k < active else "not used yet") \
            if run.setup.algo.buffer_sequence else "active"
        label = f"buffer {k} ({state}): {int(valid[k].sum())}/{capacity} levels"
        if run.experiment == "tmaze":
            label += f", {int(tmaze.sum())} T-mazes"
        else:
            label += f", {int(blind.sum())} blind"
        label += f"; top {len(slots)} by score" if slots else "; empty"
        captions = []
        for i in slots:
            tags = [tag for tag, on in (("T-maze", levels.tmaze[k, i]), ("blind", levels.blind[k, i]))
                    if on]
            captions.append(" ".join([f"{scores[k, i]:.3f}", *tags]))
        rows.append({"tiles": tiles[n:n + len(slots)] if slots else [], "captions": captions, "label": label,
                     "active": k == active})
        n += len(slots)
    title = (f"{run.experiment} / {run.algo}, seed {seed}: level buffers at update {meta.get('done', '?')} "
             f"(active: buffer {active})")
    _save_png(path, _sheet(title, rows, columns, tile_px, row_header=True, key=KEY))
    return path


# ------------------------------------------------------------------------------ render episode
@dataclass
class Episode:
    path: Path
    maze: str
    goal_index: int
    seed: int
    steps: int
    episode_return: float
    solved: bool

    def line(self) -> str:
        goal = f" goal #{self.goal_index}" if self.goal_index is not None else ""
        return (f"wrote {self.path} ({self.maze}{goal}, seed {self.seed}: {self.steps} steps, "
                f"return {self.episode_return:.3f}, {'solved' if self.solved else 'not solved'})")


def _play(env, net, params, level, rng, steps: int):
    """One episode (at most ``steps`` actions) of ``net`` on ``level``, as host arrays: inner states
    and observations [steps + 1] (the first the start), actions, rewards and dones [steps]."""
    import jax
    import jax.numpy as jnp

    def play(params, level, rng):
        k_reset, k_steps = jax.random.split(rng)
        obs, state = env.reset_to_level(k_reset, level, env.default_params)

        def step(carry, key):
            state, obs, reset, hidden = carry
            k_act, k_env = jax.random.split(key)
            obs_in = jax.tree.map(lambda x: x[None, None], obs)
            hidden, (logits, _) = net.apply({"params": params}, hidden, obs_in, reset[None, None])
            action = jax.random.categorical(k_act, logits[0, 0])
            obs, state, reward, done, _ = env.step(k_env, state, action, env.default_params)
            return (state, obs, jnp.asarray(False), hidden), (state.inner, obs, action, reward, done)

        carry = (state, obs, jnp.asarray(True), net.initialize_carry(1))
        _, (inner, observations, actions, rewards, dones) = jax.lax.scan(step, carry, jax.random.split(k_steps, steps))
        first = jax.tree.map(lambda x: jnp.asarray(x)[None], (state.inner, obs))
        inner = jax.tree.map(lambda a, b: jnp.concatenate([a, b]), first[0], inner)
        observations = jax.tree.map(lambda a, b: jnp.concatenate([a, b.astype(a.dtype)]), first[1], observations)
        return inner, observations, actions, rewards, dones

    return jax.tree.map(np.asarray, jax.jit(play)(params, level, rng))


def _view_panel(image: np.ndarray, atlas: np.ndarray) -> np.ndarray:
    """u8[5·v, 5·v, 3]: the agent's observation (f32[5, 5, 3], ``image[x, y]``, values ÷ 10) in the
    renderer's tiles, the agent at the bottom centre facing up, unseen cells dark blue."""
    objects = np.rint(image[..., 0] * 10).astype(int).T  # [row, col]
    view, v = objects.shape[0], atlas.shape[1]
    # atlas: 0 empty, 1 wall, 2 goal, 3..6 agent facing right, down, left, up
    kind = np.select([objects == 2, objects == 8, objects == 0], [1, 2, -1], 0)
    kind[-1, view // 2] = 6
    panel = np.zeros((view * v, view * v, 3), np.uint8)
    for r in range(view):
        for c in range(view):
            cell = panel[r * v:(r + 1) * v, c * v:(c + 1) * v]
            if kind[r, c] < 0:
                cell[...] = UNSEEN
            else:
                cell[...] = atlas[kind[r, c]]
    if objects[-1, view // 2] == 0:  # blindfolded: the agent's own cell is unseen too; draw it anyway
        cell = panel[(view - 1) * v:, (view // 2) * v:(view // 2 + 1) * v]
        arrow = np.any(atlas[6] != atlas[0], axis=-1)
        cell[...] = np.where(arrow[..., None], atlas[6], UNSEEN)
    return panel


def render_episode(run_dir, maze: str, seed: int | None = None, attempt_seed: int = 0, goal_index: int | None = None,
                   out=None, tile: int = DEFAULT_TILE) -> Episode:
    """Save as a GIF one episode of the checkpoint's agent (seed ``seed``, default the first) on
    held-out maze ``maze`` (goal placement ``goal_index``); ``attempt_seed`` seeds the actions."""
    import jax
    from jaxued.environments.maze.renderer import MazeRenderer

    _check_tile(tile)
    size, levels = _check_maze_name(maze, "--maze")
    count = jax.tree.leaves(levels)[0].shape[0]
    if goal_index is not None and not (isinstance(goal_index, int) and 0 <= goal_index < count):
        allowed = f"an integer in [0, {count - 1}]" if count > 1 else "0 (this maze has one goal placement)"
        raise RemidiError(f"--goal-index: must be {allowed} for {maze}, got {goal_index}")
    if not isinstance(attempt_seed, int) or attempt_seed < 0:
        raise RemidiError(f"--attempt-seed: must be an integer ≥ 0, got {attempt_seed}")
    run, s, seed, path, runner, _ = _open_run(run_dir, seed, out, f"episode_{maze}_seed{{seed}}.gif", ".gif")

    index = goal_index or 0
    level = jax.tree.map(lambda x: x[index], levels)
    params = jax.tree.map(lambda x: x[s], runner.learner.train_state.params)
    env, renderer = _renderer(size, tile)
    inner, observations, actions, rewards, dones = _play(env, run.setup.net, params, level,
                                                         jax.random.PRNGKey(attempt_seed), EPISODE_STEPS)
    steps = int(np.argmax(dones)) + 1 if dones.any() else EPISODE_STEPS
    episode_return = float(rewards[:steps].sum())
    solved = bool(run.setup.task.solved(np.float32(episode_return)))

    states = jax.tree.map(lambda x: x[:steps + 1], inner)
    boards = np.asarray(jax.vmap(renderer.render_state, in_axes=(0, None))(states, env.default_params))
    view_tile = 2 * tile
    atlas = np.asarray(MazeRenderer(env.maze, view_tile)._atlas)
    board_px = boards.shape[1]
    view_px = env.view * view_tile
    width = max(PAD + board_px + 2 * PAD + view_px + PAD, MIN_FRAME_WIDTH)  # room for the captions
    body = max(board_px, CAPTION + view_px)
    head = HEADER + key_height(width, EPISODE_KEY)  # the title, then the colour key
    height = head + body + PAD + CAPTION + PAD
    goal = f" goal #{index}" if count > 1 else ""
    title = f"{maze}{goal}: {run.experiment} / {run.algo}, seed {seed}, attempt seed {attempt_seed}"
    blank = np.full((height, width, 3), BACKGROUND, np.uint8)  # what every frame shares: title and key
    _text(blank, (0, 0), width, HEADER, title)
    _draw_key(blank, HEADER, EPISODE_KEY)
    frames, total = [], 0.0
    for t in range(steps + 1):
        canvas = blank.copy()
        canvas[head:head + board_px, PAD:PAD + board_px] = boards[t]
        left = PAD + board_px + 2 * PAD
        _text(canvas, (left, head), view_px + PAD, CAPTION, "agent's view")
        canvas[head + CAPTION:head + CAPTION + view_px, left:left + view_px] = \
            _view_panel(observations.image[t], atlas)
        if t == 0:
            caption = f"step 0/{EPISODE_STEPS}: start"
        else:
            total += float(rewards[t - 1])
            caption = (f"step {t}/{EPISODE_STEPS}: {ACTION_NAMES[int(actions[t - 1])]}, "
                       f"reward {float(rewards[t - 1]):+.3f}, return {total:+.3f}")
        if t == steps:
            caption = (f"end after {steps} steps: return {episode_return:+.3f}, "
                       f"{'solved' if solved else 'not solved'}")
        _text(canvas, (0, head + body + PAD), width, CAPTION, caption)
        frames.append(canvas)
    _save_gif(path, frames)
    return Episode(path=path, maze=maze, goal_index=index if count > 1 else None, seed=seed, steps=steps,
                   episode_return=episode_return, solved=solved)
