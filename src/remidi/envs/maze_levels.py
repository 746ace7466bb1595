"""The maze domain's levels (:class:`MazeLevel`) and where they come from: random training
mazes, T-mazes, ACCEL's edits, and the held-out mazes (jaxued's prefabs and the corridor mazes).
The environment that plays them is :mod:`remidi.envs.maze`."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from jaxued.environments.maze.env import DIR_TO_VEC

from remidi.envs.maze_names import CORRIDORS, PREFAB_NAMES, TRAIN_SIZE

NUM_WALLS = 25
VIEW = 5
RIGHT, UP = 0, 3


@struct.dataclass
class MazeLevel:
    """One maze level. Positions are ``(x, y)``; ``wall_map[y, x]``; directions 0 right, 1 down,
    2 left, 3 up. Field names and dtypes follow ``jaxued``'s ``Level`` (without its width and
    height: the wall map's shape is the level's size)."""

    wall_map: jax.Array  # bool[H, W]
    goal_pos: jax.Array  # u32[2]
    agent_pos: jax.Array  # u32[2]
    agent_dir: jax.Array  # u8[]
    tmaze: jax.Array  # bool[]: a T-maze (hidden goal, one move decides)
    blind: jax.Array  # bool[]: observations are all zeros

    @classmethod
    def make(cls, wall_map, goal_pos, agent_pos, agent_dir, tmaze=False, blind=False) -> "MazeLevel":
        """A level with canonical dtypes (so every level has the same pytree type)."""
        return cls(wall_map=jnp.asarray(wall_map, bool), goal_pos=jnp.asarray(goal_pos, jnp.uint32).reshape(2),
                   agent_pos=jnp.asarray(agent_pos, jnp.uint32).reshape(2),
                   agent_dir=jnp.asarray(agent_dir, jnp.uint8).reshape(()),
                   tmaze=jnp.asarray(tmaze, bool), blind=jnp.asarray(blind, bool))


def from_jaxued(level) -> MazeLevel:
    """An ordinary :class:`MazeLevel` from a ``jaxued`` ``Level``."""
    return MazeLevel.make(level.wall_map, level.goal_pos, level.agent_pos, level.agent_dir)

# ------------------------------------------------------------------------------------ levels
def random_maze(rng, size: int = TRAIN_SIZE, num_walls: int = NUM_WALLS) -> MazeLevel:
    """The UED standard random maze: ``num_walls`` wall cells drawn i.i.d. (with replacement, as
    ``jaxued``'s generator does), then the agent (random direction) and the goal on free cells."""
    from jaxued.environments.maze import make_level_generator

    return from_jaxued(make_level_generator(size, size, num_walls)(rng))


def view_window(pos, direction: int, view: int = VIEW, size: int = TRAIN_SIZE) -> np.ndarray:
    """bool[size, size]: the cells inside the agent's view from ``pos`` (x, y) facing ``direction``
    (the same window ``jaxued``'s partial observation slices, clipped to the grid)."""
    fwd = np.asarray(DIR_TO_VEC)[direction].astype(int)
    pos = np.asarray(pos, int)
    side = (fwd == 0) * (view // 2)
    corners = np.stack([pos, pos + fwd * (view - 1), pos + side, pos - side])
    lo, hi = corners.min(0), corners.max(0)
    ys, xs = np.mgrid[0:size, 0:size]
    return (xs >= lo[0]) & (xs <= hi[0]) & (ys >= lo[1]) & (ys <= hi[1])


@functools.lru_cache(maxsize=None)
def _tmaze_layout(size: int, view: int):
    """(open bool[size, size], visible bool[size, size]) of the T-maze: junction at the centre,
    arms and stem ``view − 1`` long; ``visible`` = every cell seen from the junction."""
    c = size // 2
    arm = min(view - 1, c)
    open_ = np.zeros((size, size), bool)
    open_[c, c - arm:c + arm + 1] = True  # the top bar of the T
    open_[c:c + arm + 1, c] = True  # the stem
    visible = np.zeros((size, size), bool)
    for d in range(4):
        visible |= view_window((c, c), d, view, size)
    return open_, visible


def tmaze_level(rng, size: int = TRAIN_SIZE, view: int = VIEW) -> MazeLevel:
    """A T-maze: agent at the junction facing up, hidden goal at the end of a random arm, every
    never-seen cell a wall with probability 1/2."""
    open_, visible = _tmaze_layout(size, view)
    k_side, k_walls = jax.random.split(rng)
    c = size // 2
    arm = min(view - 1, c)
    noise = jax.random.bernoulli(k_walls, 0.5, (size, size))
    wall_map = jnp.where(visible, ~open_, noise)
    goal_x = jnp.where(jax.random.bernoulli(k_side), c + arm, c - arm)
    return MazeLevel.make(wall_map, jnp.stack([goal_x, jnp.asarray(c)]), (c, c), UP, tmaze=True)


def mutate_maze(rng, level: MazeLevel, num_edits: int, view: int = VIEW) -> MazeLevel:
    """ACCEL's maze editor (minimax's and jaxued's ``move_goal_flip_walls``): ``num_edits`` edits.

    Each, with equal odds: nothing, flip one wall (never the agent's or goal's cell), or move the
    goal to a free cell. The agent never moves. Flags are kept, and a T-maze's edits flip only
    cells invisible from the junction and never move the goal, so an edited T-maze plays exactly
    like the original and ReMiDi over ACCEL rejects it."""
    size = level.wall_map.shape[0]
    cells = jnp.arange(size * size)
    _, visible = _tmaze_layout(size, view)
    visible = jnp.asarray(visible.reshape(-1))

    def index(pos):
        return (pos[1] * size + pos[0]).astype(jnp.int32)

    def edit(lv: MazeLevel, key):
        k_kind, k_flip, k_goal = jax.random.split(key, 3)
        walls = lv.wall_map.reshape(-1)
        occupied = (cells == index(lv.agent_pos)) | (cells == index(lv.goal_pos))
        flippable = ~occupied & ~(lv.tmaze & visible)
        flip = jax.random.choice(k_flip, cells, p=flippable / jnp.maximum(flippable.sum(), 1))
        flipped = walls.at[flip].set(~walls[flip])
        free = ~walls & ~occupied
        goal = jax.random.choice(k_goal, cells, p=free / jnp.maximum(free.sum(), 1))
        kind = jax.random.randint(k_kind, (), 0, 3)  # 0 nothing, 1 flip a wall, 2 move the goal
        move_goal = (kind == 2) & ~lv.tmaze & jnp.any(free)
        do_flip = (kind == 1) & jnp.any(flippable)
        new_goal = jnp.stack([goal % size, goal // size]).astype(jnp.uint32)
        return lv.replace(wall_map=jnp.where(do_flip, flipped, walls).reshape(size, size),
                          goal_pos=jnp.where(move_goal, new_goal, lv.goal_pos)), None

    return jax.lax.scan(edit, level, jax.random.split(rng, num_edits))[0]


def prefab_level(name: str) -> MazeLevel:
    """A ``jaxued`` prefab maze (``jaxued.environments.maze.level.prefabs``), loaded at run time."""
    from jaxued.environments.maze.level import Level, prefabs

    return from_jaxued(Level.from_str(prefabs[name]))


def corridor_levels(size: int) -> MazeLevel:
    """The corridor maze of odd side ``size``, one level per goal placement (leading dim: dead ends),
    so a solve rate over the batch is the expected one under a uniform goal.

    A ring corridor along the border; the middle row a wall except at its ends; each even interior
    column holds two dead ends towards the middle row. The agent starts at the middle row's left
    end facing its wall (as DCD's and minimax's); the goal is at a dead end's inner end."""
    assert size % 2 == 1 and size >= 5, size
    mid = size // 2
    walls = np.ones((size, size), bool)
    walls[0, :] = walls[-1, :] = walls[:, 0] = walls[:, -1] = False  # the ring
    columns = list(range(2, size - 2, 2))
    for x in columns:
        walls[1:mid, x] = False  # from the top border to the middle
        walls[mid + 1:size - 1, x] = False  # from the bottom border to the middle
    goals = [(x, y) for x in columns for y in (mid - 1, mid + 1)]
    return _stack([MazeLevel.make(walls, goal, (0, mid), RIGHT) for goal in goals])


def _stack(levels):
    """One batch (leaves [L, ...]) from a list of levels."""
    return jax.tree.map(lambda *xs: jnp.stack(xs), *levels)


def held_out_sets() -> dict[str, tuple[int, MazeLevel]]:
    """name → (grid size, level batch) for the ten held-out test mazes."""
    sets = {name: (TRAIN_SIZE, _stack([prefab_level(name)])) for name in PREFAB_NAMES}
    for name, size in CORRIDORS.items():
        sets[name] = (size, corridor_levels(size))
    return sets
