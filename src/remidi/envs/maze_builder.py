"""The maze's level-building MDP (:class:`MazeBuilder`): what a learned generator (PAIRED)
acts in, cell by cell."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from remidi.envs.builder import BuilderState, LevelBuilder
from remidi.envs.maze_levels import NUM_WALLS, VIEW, MazeLevel, tmaze_level
from remidi.envs.maze_names import TRAIN_SIZE


@struct.dataclass
class MazeDesign:
    """A maze being built: cells are indices ``y·size + x``; ``agent`` −1 until placed."""

    wall_map: jax.Array  # bool[H, W]
    goal: jax.Array  # i32[]
    agent: jax.Array  # i32[]
    agent_dir: jax.Array  # i32[]
    special: jax.Array  # bool[]: a T-maze (kind tmaze) or a blind level (kind blindfold)


class MazeBuilder(LevelBuilder):
    """The maze's level-building MDP; actions are cell indices ``y·size + x``. Steps, in order:

    1. the kind (``tmaze`` or ``blindfold`` tasks): ``a mod 2`` = 1 special, so a uniform generator
       matches the sampler's half;
    2. the goal's cell (default: cell 0);
    3. the agent's cell (none on the goal; unplaced: the first free cell);
    4. the direction ``a mod 4``;
    5. ``num_walls`` walls (none on the goal, the agent or a wall).

    A T-maze is :func:`tmaze_level` from the episode's key; its goal step picks the arm (another
    cell keeps the key's side), other steps change nothing. Every sampler level can be built
    (``tests/test_builder.py``)."""

    def __init__(self, kind: str = "tmaze", num_walls: int = NUM_WALLS, size: int = TRAIN_SIZE):
        self.kind, self.size, self.num_walls = kind, size, num_walls
        self.kind_steps = 1 if kind in ("tmaze", "blindfold") else 0
        self.num_steps = self.kind_steps + 3 + num_walls
        self.num_actions = size * size

    def empty(self, key) -> MazeDesign:
        return MazeDesign(wall_map=jnp.zeros((self.size, self.size), bool), goal=jnp.zeros((), jnp.int32),
                          agent=jnp.full((), -1, jnp.int32), agent_dir=jnp.zeros((), jnp.int32),
                          special=jnp.asarray(False))

    def place(self, design: MazeDesign, t, action) -> MazeDesign:
        cells = self.size * self.size
        on_grid = (action >= 0) & (action < cells)
        phase = t - self.kind_steps  # −1 the kind, 0 goal, 1 agent, 2 direction, 3… walls
        flat = design.wall_map.reshape(-1)
        occupied = flat[jnp.clip(action, 0, cells - 1)] | (action == design.goal) | (action == design.agent)
        kind = design.replace(special=action % 2 == 1)
        goal = design.replace(goal=jnp.where(on_grid & (action != design.agent), action, design.goal))
        agent = design.replace(agent=jnp.where(on_grid & (action != design.goal), action, design.agent))
        direction = design.replace(agent_dir=action % 4)
        wall = design.replace(wall_map=jnp.where(on_grid & ~occupied, flat.at[jnp.clip(action, 0, cells - 1)].set(True),
                                                 flat).reshape(self.size, self.size))
        index = jnp.clip(phase + 1, 0, 4)  # which of the five designs this step makes

        def pick(*options):
            out = options[0]
            for i, option in enumerate(options[1:], 1):
                out = jnp.where(index == i, option, out)
            return out

        return jax.tree.map(pick, kind, goal, agent, direction, wall)

    def show(self, design: MazeDesign) -> jax.Array:
        """f32[H, W, 4]: walls, goal, agent, and the kind (special) on every cell."""
        cells = jnp.arange(self.size * self.size).reshape(self.size, self.size)
        return jnp.stack([design.wall_map, cells == design.goal, cells == design.agent,
                          jnp.broadcast_to(design.special, cells.shape)], axis=-1).astype(jnp.float32)

    def built(self, state: BuilderState) -> MazeLevel:
        d = state.design
        flat = d.wall_map.reshape(-1)
        cells = jnp.arange(self.size * self.size)
        free = ~flat & (cells != d.goal)
        agent = jnp.where(d.agent >= 0, d.agent, jnp.argmax(free))
        xy = lambda i: jnp.stack([i % self.size, i // self.size])  # noqa: E731
        maze = MazeLevel.make(d.wall_map, xy(d.goal), xy(agent), d.agent_dir,
                              blind=d.special & (self.kind == "blindfold"))
        if self.kind != "tmaze":
            return maze
        tmaze = tmaze_level(state.key, self.size)
        c, arm = self.size // 2, min(VIEW - 1, self.size // 2)
        chosen = xy(d.goal)
        arm_end = (chosen[1] == c) & ((chosen[0] == c - arm) | (chosen[0] == c + arm))
        tmaze = tmaze.replace(goal_pos=jnp.where(arm_end, chosen, tmaze.goal_pos).astype(jnp.uint32))
        return jax.tree.map(lambda a, b: jnp.where(d.special, a, b), tmaze, maze)
