"""The maze domain's names and sizes, importable without :mod:`remidi.envs.maze` (whose jaxued
base imports gymnax and seaborn: seconds of start-up)."""

TRAIN_SIZE = 13  # the training mazes' side
MAX_STEPS = 250  # an episode's steps at most
PREFAB_NAMES = ("SixteenRooms", "SixteenRooms2", "Labyrinth", "LabyrinthFlipped", "Labyrinth2",
                "StandardMaze", "StandardMaze2", "StandardMaze3")  # jaxued's held-out layouts
CORRIDORS = {"SmallCorridor": 13, "LargeCorridor": 19}  # the corridor mazes and their sides
HELD_OUT_NAMES = PREFAB_NAMES + tuple(CORRIDORS)
