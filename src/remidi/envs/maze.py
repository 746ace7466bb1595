"""The maze domain (paper §6.3): MiniGrid-style mazes, T-mazes, blindfolded mazes, held-out mazes.

The environment is ``jaxued``'s :class:`~jaxued.environments.Maze` (the UED reference
implementation), wrapped by :class:`MazeEnv`, which adds two kinds of level the ReMiDi paper
needs. On an ordinary level :class:`MazeEnv` *is* ``jaxued``'s ``Maze`` (observations, rewards
and dones agree step for step, see ``tests/test_maze_env.py``):

* a ``size × size`` grid (13 for training), walls, a goal and an agent with a direction;
* actions ``0`` left, ``1`` right, ``2`` forward (``3..6`` do nothing), so 7 discrete actions;
* an egocentric 5×5 view (object, colour, state channels, divided by 10) plus the direction;
* reward ``1 − 0.9·(t+1)/T`` on the step ``t`` (0-based) that moves into the goal, which ends
  the episode; ``T = 250`` steps at most.

Level kinds (flags of :class:`MazeLevel`):

* **T-maze** (``tmaze``): the agent stands at the junction of a T facing its top wall; the goal
  sits at the end of the left or the right arm and is drawn as an empty cell, so it cannot be
  seen. The first action that changes the agent's position ends the episode with ``+1`` if it
  moved towards the goal (the Manhattan distance to the goal fell) and ``−1`` otherwise (the
  other arm, or the stem). Every cell the agent can never see from the junction is a wall with
  probability 1/2, so T-mazes are distinct levels that all play identically. Optimal return 1
  (discounted: ``γ``, a turn, then the move); any policy that cannot see the goal has regret ≥ 1
  on one of the two sides.
* **Blind** (``blind``): an ordinary maze whose observations are all zeros (image and direction).

Optimal return (:func:`optimal_return`): an exact shortest path over (position, direction)
states, see its docstring for the convention.

Held-out test mazes (:func:`held_out_sets`): eight ``jaxued`` prefabs, loaded from
``jaxued.environments.maze.level.prefabs`` at run time, and the two corridor mazes of
:func:`corridor_levels`. Each is played at its own size (LargeCorridor is 19×19) by the same
network, since the observation is always the 5×5 view.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct
from jaxued.environments.maze import Maze
from jaxued.environments.maze.env import DIR_TO_VEC, EnvParams, Observation, make_maze_map

from remidi.envs.builder import BuilderState, LevelBuilder
from remidi.envs.interface import UEDTask, UnderspecifiedEnv
from remidi.envs.maze_names import CORRIDORS, HELD_OUT_NAMES, PREFAB_NAMES, TRAIN_SIZE

__all__ = [
    "MazeLevel", "MazeState", "MazeEnv", "MAX_STEPS", "TRAIN_SIZE", "NUM_WALLS", "PREFAB_NAMES", "HELD_OUT_NAMES",
    "random_maze", "tmaze_level", "prefab_level", "corridor_levels", "held_out_sets", "cost_to_go", "shortest_path_steps",
    "optimal_return", "optimal_discounted_return", "maze_task", "from_jaxued", "mutate_maze",
]

MAX_STEPS = 250
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


@struct.dataclass
class MazeState:
    inner: object  # jaxued's EnvState (agent_pos, agent_dir, goal_pos, wall_map, maze_map, time, terminal)
    tmaze: jax.Array  # bool[]
    blind: jax.Array  # bool[]


class MazeEnv(UnderspecifiedEnv):
    """``jaxued``'s ``Maze`` (normalised observations, time-penalised reward) plus T-mazes and
    blindfolds. ``size``: the grid side this instance plays (levels must be ``size × size``)."""

    def __init__(self, size: int = TRAIN_SIZE, view: int = VIEW):
        self.size = size
        self.view = view
        self.maze = Maze(max_height=size, max_width=size, agent_view_size=view, normalize_obs=True)

    def __hash__(self):
        return hash((MazeEnv, self.size, self.view))

    def __eq__(self, other):
        return isinstance(other, MazeEnv) and (self.size, self.view) == (other.size, other.view)

    @property
    def default_params(self) -> EnvParams:
        return EnvParams(max_steps_in_episode=MAX_STEPS)

    def action_space(self, params):
        return self.maze.action_space(params)

    def _canonical(self, inner):
        # jaxued's state mixes Python scalars and u8/i32 directions; fix one type for scan carries
        return inner.replace(agent_pos=inner.agent_pos.astype(jnp.uint32), agent_dir=jnp.asarray(inner.agent_dir, jnp.uint8),
                             time=jnp.asarray(inner.time, jnp.int32), terminal=jnp.asarray(inner.terminal, bool))

    def _observe(self, state: MazeState) -> Observation:
        obs = self.maze.get_obs(state.inner)
        return Observation(image=jnp.where(state.blind, 0.0, obs.image),
                           agent_dir=jnp.where(state.blind, 0, obs.agent_dir).astype(jnp.uint8))

    def reset_env_to_level(self, rng, level: MazeLevel, params):
        inner = self.maze.init_state_from_level(level)
        # a T-maze's goal is drawn as an empty cell
        hidden = make_maze_map(level, self.view - 1, ignore_goal=True)
        inner = self._canonical(inner.replace(maze_map=jnp.where(level.tmaze, hidden, inner.maze_map)))
        state = MazeState(inner=inner, tmaze=level.tmaze, blind=level.blind)
        return self._observe(state), state

    def step_env(self, rng, state: MazeState, action, params):
        _, inner, reward, done, info = self.maze.step_env(rng, state.inner, action, params)
        inner = self._canonical(inner)
        old, new = state.inner.agent_pos.astype(jnp.int32), inner.agent_pos.astype(jnp.int32)
        goal = state.inner.goal_pos.astype(jnp.int32)
        moved = jnp.any(new != old)
        towards = jnp.sum(jnp.abs(new - goal)) < jnp.sum(jnp.abs(old - goal))
        reward = jnp.where(state.tmaze, jnp.where(moved, jnp.where(towards, 1.0, -1.0), 0.0), reward)
        done = jnp.where(state.tmaze, moved | done, done)
        state = state.replace(inner=inner.replace(terminal=done))
        return self._observe(state), state, reward.astype(jnp.float32), done, info


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
    """ACCEL's maze editor (minimax's and jaxued's ``move_goal_flip_walls``): ``num_edits`` edits,
    each drawing one of three kinds with equal odds: nothing (a no-op), flipping one wall cell
    (adding or removing a wall; never on the agent's or the goal's cell) or moving the goal to a
    free cell other than the agent's. The agent never moves, so at most ``num_edits`` wall cells
    change and the goal always stands on a free cell.

    A T-maze stays a T-maze and a blind level stays blind (the flags are kept): an edit of a level
    whose regret is irreducible is again one. A T-maze's edits flip only cells the agent cannot
    see from the junction and never move the goal (a goal move is a no-op there), so an edited
    T-maze plays exactly like the original (same observations, same one-move outcome): ReMiDi
    over ACCEL rejects it.
    """
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
    """The corridor maze of side ``size`` (odd), one level per goal placement (leading dim = number
    of dead ends); the goal is drawn uniformly per episode, so a solve rate over the batch is the
    expected solve rate.

    Layout: a ring corridor along the border; the middle row is a wall except at its two ends;
    every even interior column holds two dead-end corridors, one running from the top border down
    towards the middle row and one from the bottom border up towards it; every other cell is a
    wall. The agent starts at the left end of the middle row facing right, into the middle row's
    wall (as DCD's and minimax's corridors do); the goal sits at the inner end of one dead end (the
    cell next to the middle row).
    """
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


# ----------------------------------------------------------------------------- optimal return
def cost_to_go(level: MazeLevel) -> jax.Array:
    """f32[4, H, W]: from each state (facing ``d``, at ``(x, y)`` → index ``[d, y, x]``), the fewest
    actions after which the agent receives the goal reward (the last one is the forward move into
    the goal); ``inf`` where the goal is unreachable, and on walls. Exact: a shortest path over
    (position, direction) states — turn left, turn right, or forward (blocked by walls and the
    grid's edge) — as the fixed point of the Bellman equation, iterated until nothing changes
    (jit-able, vmappable)."""
    h, w = level.wall_map.shape
    is_goal = (jnp.arange(h)[:, None] == level.goal_pos[1]) & (jnp.arange(w)[None, :] == level.goal_pos[0])
    # the goal cell counts as reached (0); walls can never be stood on (inf)
    fixed = jnp.broadcast_to(jnp.where(is_goal, 0.0, jnp.inf), (4, h, w))
    pinned = jnp.broadcast_to(level.wall_map | is_goal, (4, h, w))

    def ahead(cost_d, d):
        """cost_d f32[H, W] of the cell in front of each cell when facing d (inf past the edge)."""
        padded = jnp.pad(cost_d, 1, constant_values=jnp.inf)
        dx, dy = [(1, 0), (0, 1), (-1, 0), (0, -1)][d]
        return padded[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]

    def relax(cost):
        forward = jnp.stack([ahead(cost[d], d) for d in range(4)])
        turn = jnp.minimum(jnp.roll(cost, 1, axis=0), jnp.roll(cost, -1, axis=0))  # now facing d∓1
        return jnp.where(pinned, fixed, jnp.minimum(cost, 1.0 + jnp.minimum(turn, forward)))

    _, cost = jax.lax.while_loop(lambda c: jnp.any(c[0] != c[1]), lambda c: (c[1], relax(c[1])),
                                 (fixed, relax(fixed)))
    return cost


def shortest_path_steps(level: MazeLevel) -> jax.Array:
    """f32[]: the fewest actions from the level's start to the goal reward (:func:`cost_to_go`)."""
    cost = cost_to_go(level)
    return cost[level.agent_dir.astype(jnp.int32), level.agent_pos[1], level.agent_pos[0]]


def optimal_return(level: MazeLevel, max_steps: int = MAX_STEPS) -> jax.Array:
    """f32[]: the best return achievable on ``level``.

    Convention: an ordinary (or blind) maze's goal reached with the ``n``-th action pays
    ``1 − 0.9·n/T`` (the reward the environment gives at step ``t = n − 1``), so the optimal
    return is that value for ``n`` = :func:`shortest_path_steps`, and ``0`` when the goal is
    unreachable or ``n > T``. (``jaxued``'s ``MazeSolved.optimal_value`` uses ``n + 1``, one step
    too many.) A T-maze's optimal return is ``1``: an agent that could see the goal would turn
    towards it and step into its arm. Blindness does not change the level's optimum.
    """
    return optimal_discounted_return(level, 1.0, max_steps)


def optimal_discounted_return(level: MazeLevel, gamma: float, max_steps: int = MAX_STEPS) -> jax.Array:
    """f32[]: the best discounted return E[Σ_t γ^t r_t] on ``level`` (t = 0 at the first action).

    The goal reached with the ``n``-th action pays ``1 − 0.9·n/T`` at ``t = n − 1``, so the
    optimum is ``γ^(n−1)·(1 − 0.9·n/T)`` for ``n`` = :func:`shortest_path_steps` (a shorter path
    is both discounted less and paid more, so the shortest path is optimal for every γ), and
    ``0`` when the goal is unreachable or ``n > T``. A T-maze's agent faces the top wall, so the
    best it can do is a turn, then the move into the goal arm, paid ``1`` at ``t = 1``: its optimum
    is ``γ``. ``gamma = 1`` gives :func:`optimal_return`.
    """
    n = shortest_path_steps(level)
    reachable = n <= max_steps
    steps = jnp.where(reachable, n, 1.0)
    maze = jnp.where(reachable, jnp.power(jnp.float32(gamma), steps - 1.0) * (1.0 - 0.9 * steps / max_steps), 0.0)
    return jnp.where(level.tmaze, jnp.float32(gamma), maze).astype(jnp.float32)


# ------------------------------------------------------------------------------ the generator's MDP
@struct.dataclass
class MazeDesign:
    """A maze being built: cells are indices ``y·size + x``; ``agent`` −1 until placed."""

    wall_map: jax.Array  # bool[H, W]
    goal: jax.Array  # i32[]
    agent: jax.Array  # i32[]
    agent_dir: jax.Array  # i32[]
    special: jax.Array  # bool[]: a T-maze (kind tmaze) or a blind level (kind blindfold)


class MazeBuilder(LevelBuilder):
    """The maze's level-building MDP. Actions are cell indices ``y·size + x`` (``size²`` of
    them); the steps, in order:

    1. the level's kind, where the task has special levels (``kind`` ``tmaze`` or ``blindfold``):
       action ``a`` with ``a mod 2`` = 0 an ordinary maze, 1 a T-maze (a blind maze): a generator
       acting uniformly makes each kind half of the time, as the task's sampler does;
    2. the goal's cell (default: cell 0);
    3. the agent's cell; on the goal's cell it changes nothing; an agent never placed stands on
       the first cell that is neither the goal nor a wall;
    4. the agent's direction: ``a mod 4`` (right, down, left, up);
    5. ``num_walls`` wall placements (the sampler's 25): a wall on the goal, the agent or a wall
       changes nothing.

    A T-maze is the task's T-maze (:func:`tmaze_level`, its never-seen cells drawn from the
    episode's key); the goal step picks its goal arm (the cell of one of the two arm ends; any
    other cell keeps the side drawn from the key) and the other steps change nothing. Every level
    the task's sampler produces can be built (``tests/test_builder.py``)."""

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


# -------------------------------------------------------------------------------------- tasks
KINDS = ("maze", "tmaze", "blindfold")


@functools.lru_cache(maxsize=None)
def maze_task(kind: str = "tmaze", prob: float = 0.5, num_walls: int = NUM_WALLS) -> UEDTask:
    """The maze domain as a UED task. Cached: the same arguments give the same task (and reuse its
    compiled train steps).

    ``kind``: ``"tmaze"`` (each generated level is a T-maze with probability ``prob``, tag
    ``tmaze``), ``"blindfold"`` (each is blind with probability ``prob``, tag ``blind``) or
    ``"maze"`` (ordinary mazes only). Evaluation sets: the ten held-out mazes.
    """
    if kind not in KINDS:
        raise ValueError(f"maze kind must be one of {KINDS}, got {kind!r}")
    env = MazeEnv(TRAIN_SIZE)

    def generator(walls: int):
        def sample_level(rng):
            k_kind, k_maze, k_t = jax.random.split(rng, 3)
            special = jax.random.bernoulli(k_kind, prob) if kind != "maze" else jnp.asarray(False)
            maze = random_maze(k_maze, TRAIN_SIZE, walls)
            if kind == "tmaze":
                t = tmaze_level(k_t, TRAIN_SIZE)
                return jax.tree.map(lambda a, b: jnp.where(special, a, b), t, maze)
            return maze.replace(blind=special)

        return sample_level

    tag = {"tmaze": "tmaze", "blindfold": "blind"}.get(kind)  # the level flag it reports
    sets = held_out_sets()
    envs = {size: (env if size == TRAIN_SIZE else MazeEnv(size)) for size, _ in sets.values()}
    return UEDTask(
        env=env,
        params=env.default_params,
        sample_level=generator(num_walls),
        num_actions=env.action_space(env.default_params).n,
        max_episode_steps=MAX_STEPS,
        optimal_return=optimal_return,
        optimal_discounted_return=optimal_discounted_return,
        eval_sets={name: levels for name, (_, levels) in sets.items()},
        eval_envs={name: envs[size] for name, (size, _) in sets.items() if size != TRAIN_SIZE},
        level_tags=(lambda level: {tag: getattr(level, tag)}) if tag else (lambda level: {}),
        mutate_level=mutate_maze,
        easy_level=generator(0),  # ACCEL's easy start: no walls (T-mazes and blind levels as generated)
        level_builder=MazeBuilder(kind, num_walls),
        deterministic_reset=True,
    )
