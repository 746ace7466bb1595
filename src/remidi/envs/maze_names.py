"""The maze domain's names and sizes, in a module of their own: an experiment registers its
metrics by them without importing :mod:`remidi.envs.maze`, whose jaxued base imports gymnax
(every environment) and seaborn, seconds that a process which never builds a maze need not pay."""

TRAIN_SIZE = 13  # the training mazes' side
MAX_STEPS = 250  # an episode's steps at most
PREFAB_NAMES = ("SixteenRooms", "SixteenRooms2", "Labyrinth", "LabyrinthFlipped", "Labyrinth2",
                "StandardMaze", "StandardMaze2", "StandardMaze3")  # jaxued's held-out layouts
CORRIDORS = {"SmallCorridor": 13, "LargeCorridor": 19}  # the corridor mazes and their sides
HELD_OUT_NAMES = PREFAB_NAMES + tuple(CORRIDORS)
