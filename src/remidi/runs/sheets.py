"""How ``remidi render`` draws: tiles (``jaxued``'s
:class:`~jaxued.environments.maze.renderer.MazeRenderer`), captions, colour keys and the sheets
holding them (NumPy and Pillow), written atomically as PNG or GIF.

Geometry, so tests can check it: a sheet is ``HEADER`` pixels of title, its colour key
(:data:`KEY` or :data:`MAZE_KEY`, :func:`key_height` pixels, ``KEY_ROW`` per line), then rows; a
row is a ``ROW_HEADER`` band (buffer sheets only), a ``CAPTION`` band and tiles, then ``PAD``;
tiles are ``(size + 2) · tile`` pixels square with ``PAD`` between and around (:func:`sheet_size`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

HEADER = 22  # sheet title band, pixels
ROW_HEADER = 16  # per-row header band of a buffer sheet
CAPTION = 14  # caption band above each tile
PAD = 4  # gap between and around tiles
MAX_COLUMNS = 8  # tiles per row of a maze sheet
DEFAULT_TILE = 16
TILE_RANGE = (2, 64)
DEFAULT_TOP = 8
MIN_SIDE = 600  # pixels: a maze sheet's short side is at least this (as far as TILE_RANGE allows), to be read
EPISODE_STEPS = 250
MAZE_EXPERIMENTS = ("tmaze", "blindfold", "blindfold-noisy")

BACKGROUND = (255, 255, 255)
TEXT = (0, 0, 0)
ACTIVE_BAND = (255, 214, 90)  # header band of the active buffer
ACTIVE_FRAME = (230, 140, 0)  # frame around the active buffer's tiles
UNSEEN = (24, 28, 70)  # a cell of the agent's view that it cannot see
KEY_ROW = 14  # one line of the colour key
SWATCH = 10  # a colour key's swatch, pixels square
# the colour key of a buffer sheet: jaxued's MazeRenderer's colours, then the active buffer's marks
KEY = (((100, 100, 100), "wall"), ((0, 0, 0), "floor"), ((0, 255, 0), "goal"),
       ((255, 0, 0), "agent (pointing where it faces)"),
       ((76, 76, 76), "its 5x5 view (cells lightened 30%)"), (ACTIVE_BAND, "active buffer"))
MAZE_KEY = KEY[:-1]  # a maze sheet's: the renderer's colours
EPISODE_KEY = MAZE_KEY + ((UNSEEN, "in its view: cells it cannot see"),)  # an episode frame's
MIN_FRAME_WIDTH = 320  # pixels: an episode frame is at least this wide, so its captions fit
FRAME_MS = 150
LAST_FRAME_MS = 2000
# the maze's seven actions; 3–6 change nothing in a maze (jaxued names the last one "done", which a
# caption would read as "the episode ended": called "no-op" here)
ACTION_NAMES = ("turn left", "turn right", "forward", "no-op (pickup)", "no-op (drop)", "no-op (toggle)",
                "no-op (done)")


def _font(size: int = 11):
    from PIL import ImageFont

    return ImageFont.load_default(size=size)


def _text(canvas: np.ndarray, xy: tuple[int, int], width: int, height: int, text: str,
          fill=TEXT, background=None) -> None:
    """Draw ``text`` into the ``width × height`` box at ``xy`` of ``canvas`` (u8[H, W, 3]), clipped to it."""
    from PIL import Image, ImageDraw

    x, y = xy
    box = canvas[y:y + height, x:x + width]
    if background is not None:
        box[...] = background
    img = Image.fromarray(box)
    ImageDraw.Draw(img).text((2, max(0, (height - 12) // 2)), text, fill=fill, font=_font())
    canvas[y:y + height, x:x + width] = np.asarray(img)


def _renderer(size: int, tile: int):
    from jaxued.environments.maze.renderer import MazeRenderer

    from remidi.envs.maze import MazeEnv

    env = MazeEnv(size)
    return env, MazeRenderer(env.maze, tile)


def _render_levels(levels, size: int, tile: int) -> np.ndarray:
    """u8[N, P, P, 3]: every level of the batch ``levels`` (leaves [N, ...]) as a tile."""
    import jax

    env, renderer = _renderer(size, tile)
    return np.asarray(jax.vmap(renderer.render_level, in_axes=(0, None))(levels, env.default_params))


def _key_lines(width: int, key=KEY) -> list[list[tuple[int, tuple, str]]]:
    """``key`` ((colour, label) pairs) laid out in lines that fit ``width`` pixels:
    ``[(x, colour, label)]`` per line (an entry wider than the sheet gets a line of its own, clipped)."""
    lines, x = [[]], PAD
    for colour, label in key:
        w = SWATCH + 4 + int(_font().getlength(label)) + 12
        if lines[-1] and x + w > width:
            lines.append([])
            x = PAD
        lines[-1].append((x, colour, label))
        x += w
    return lines


def key_height(width: int, key=KEY) -> int:
    """Pixels of the colour key ``key`` (default: a buffer sheet's) of a sheet ``width`` pixels wide."""
    return KEY_ROW * len(_key_lines(width, key))


def _draw_key(canvas: np.ndarray, top: int, key=KEY) -> None:
    for i, line in enumerate(_key_lines(canvas.shape[1], key)):
        y = top + i * KEY_ROW
        for x, colour, label in line:
            s = (KEY_ROW - SWATCH) // 2
            canvas[y + s:y + s + SWATCH, x:x + SWATCH] = (128, 128, 128)  # a grey edge: black floor on white
            canvas[y + s + 1:y + s + SWATCH - 1, x + 1:x + SWATCH - 1] = colour
            right = min(canvas.shape[1], x + SWATCH + 2 + int(_font().getlength(label)) + 8)
            _text(canvas, (x + SWATCH + 2, y), max(0, right - x - SWATCH - 2), KEY_ROW, label)


def sheet_size(rows: int, columns: int, tile_px: int, row_header: bool, key=None) -> tuple[int, int]:
    """``(width, height)`` in pixels of a sheet of ``rows`` rows of ``columns`` tiles ``tile_px``
    pixels square, with a header band per row or not, and the colour key ``key`` (None: none)."""
    width = PAD + columns * (tile_px + PAD)
    row_h = (ROW_HEADER if row_header else 0) + CAPTION + tile_px + PAD
    return width, HEADER + (key_height(width, key) if key else 0) + rows * row_h + PAD


def readable_tile(tile: int, rows: int, columns: int, cells: int, key=None) -> int:
    """Pixels per cell for ``rows`` × ``columns`` mazes of ``cells`` a side (border included):
    ``tile``, or more (up to ``TILE_RANGE``'s end) where the short side would be under :data:`MIN_SIDE`."""
    while tile < TILE_RANGE[1] and min(sheet_size(rows, columns, cells * tile, False, key)) < MIN_SIDE:
        tile += 1
    return tile


def _sheet(title: str, rows: list[dict], columns: int, tile_px: int, row_header: bool,
           key=None) -> np.ndarray:
    """Assemble a sheet. ``rows``: ``{"tiles": u8[n, P, P, 3] (n ≤ columns), "captions": [str],
    "label": str, "active": bool}``; ``key``: the colour key under the title ((colour, label)
    pairs; None: none)."""
    row_h = (ROW_HEADER if row_header else 0) + CAPTION + tile_px + PAD
    width, height = sheet_size(len(rows), columns, tile_px, row_header, key)
    head = HEADER + (key_height(width, key) if key else 0)
    canvas = np.full((height, width, 3), BACKGROUND, np.uint8)
    _text(canvas, (0, 0), width, HEADER, title)
    if key:
        _draw_key(canvas, HEADER, key)
    for r, row in enumerate(rows):
        top = head + r * row_h
        if row_header:
            _text(canvas, (0, top), width, ROW_HEADER, row.get("label", ""),
                  background=ACTIVE_BAND if row.get("active") else None)
            top += ROW_HEADER
        if row.get("active"):  # a frame around the row's tiles, drawn in the gaps
            canvas[top:top + CAPTION + tile_px + PAD, :PAD // 2 or 1] = ACTIVE_FRAME
            canvas[top:top + CAPTION + tile_px + PAD, width - (PAD // 2 or 1):] = ACTIVE_FRAME
            canvas[top + CAPTION + tile_px + PAD // 2:top + CAPTION + tile_px + PAD, :] = ACTIVE_FRAME
        for c, (image, caption) in enumerate(zip(row["tiles"], row["captions"])):
            left = PAD + c * (tile_px + PAD)
            _text(canvas, (left, top), tile_px, CAPTION, caption)
            canvas[top + CAPTION:top + CAPTION + tile_px, left:left + tile_px] = image
    return canvas


def _save_png(path: Path, canvas: np.ndarray) -> None:
    from PIL import Image

    from remidi.experiments.outputs import atomic_write

    image = Image.fromarray(canvas)
    atomic_write(path, lambda fh: image.save(fh, format="PNG"), binary=True)


def _save_gif(path: Path, frames: list[np.ndarray]) -> None:
    from PIL import Image

    from remidi.experiments.outputs import atomic_write

    images = [Image.fromarray(f) for f in frames]
    durations = [FRAME_MS] * (len(images) - 1) + [LAST_FRAME_MS]
    atomic_write(path, lambda fh: images[0].save(fh, format="GIF", save_all=True, append_images=images[1:],
                                                 duration=durations, loop=0), binary=True)
