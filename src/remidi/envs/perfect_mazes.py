"""Perfect mazes (exactly one path between any two open cells) of any odd side, carved by a
randomised depth-first search: ``remidi evaluate``'s larger mazes, beyond the 13×13 training
size."""

from __future__ import annotations

import numpy as np


def perfect_maze_walls(rng: np.random.Generator, size: int) -> np.ndarray:
    """bool[size, size] walls of a perfect maze (odd ``size`` ≥ 5): a randomised depth-first search
    over the odd-coordinate rooms, so open cells form a tree."""
    walls = np.ones((size, size), bool)
    rooms = [(x, y) for y in range(1, size - 1, 2) for x in range(1, size - 1, 2)]
    start = rooms[rng.integers(len(rooms))]
    walls[start[1], start[0]] = False
    stack = [start]
    while stack:
        x, y = stack[-1]
        options = [(x + dx, y + dy) for dx, dy in ((2, 0), (-2, 0), (0, 2), (0, -2))
                   if 0 < x + dx < size - 1 and 0 < y + dy < size - 1 and walls[y + dy, x + dx]]
        if not options:
            stack.pop()
            continue
        nx, ny = options[rng.integers(len(options))]
        walls[(y + ny) // 2, (x + nx) // 2] = False
        walls[ny, nx] = False
        stack.append((nx, ny))
    return walls


def perfect_mazes(size: int, count: int, seed: int):
    """``count`` perfect mazes of side ``size`` as one :class:`~remidi.envs.maze.MazeLevel` batch,
    deterministic in ``seed``; agent and goal on two random open cells."""
    from remidi.envs.maze_levels import MazeLevel, _stack

    rng = np.random.default_rng([seed, size])
    levels = []
    for _ in range(count):
        walls = perfect_maze_walls(rng, size)
        ys, xs = np.nonzero(~walls)
        agent, goal = rng.choice(len(xs), size=2, replace=False)
        levels.append(MazeLevel.make(walls, (xs[goal], ys[goal]), (xs[agent], ys[agent]), rng.integers(4)))
    return _stack(levels)
