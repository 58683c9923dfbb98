"""A tiny numpy rasteriser for the 2-D environments' ``rgb_array`` frames and for plan overlays (no pygame, no GL).

World coordinates live in the square [-1, 1]^2 with y pointing up; an image of shape [H, W, 3] uint8 covers that
square exactly, row 0 being y = +1. Every drawing function returns a new image and leaves its input untouched, so a
cached background can be drawn over many times.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

WORLD_LOW = -1.0
WORLD_HIGH = 1.0

Color = Sequence[int] | np.ndarray

WHITE = (255, 255, 255)
WALL_GRAY = (70, 70, 80)
GOAL_GREEN = (40, 170, 70)
AGENT_BLUE = (30, 90, 220)
PLAN_ORANGE = (240, 140, 20)


def blank_canvas(size: int = 256, color: Color = WHITE) -> np.ndarray:
    """Create a square image of one colour covering the world square [-1, 1]^2.

    :param size: side of the image in pixels.
    :param color: RGB fill colour, three ints in [0, 255].
    :return: image [size, size, 3] uint8.
    """
    if int(size) < 2:
        raise ValueError(f"size must be an int >= 2 pixels, got {size!r}")
    image = np.empty((int(size), int(size), 3), dtype=np.uint8)
    image[...] = _as_rgb(color)
    return image


def world_to_pixel(points: np.ndarray, image_shape: Sequence[int]) -> np.ndarray:
    """Map world points to fractional pixel coordinates (column, row) of an image.

    :param points: world coordinates [..., 2] (x, y).
    :param image_shape: shape of the target image; only the first two entries (H, W) are used.
    :return: pixel coordinates [..., 2] float64 (column, row); pixel (c, r) covers [c, c+1) x [r, r+1).
    """
    points = np.asarray(points, dtype=np.float64)
    height, width = int(image_shape[0]), int(image_shape[1])
    span = WORLD_HIGH - WORLD_LOW
    cols = (points[..., 0] - WORLD_LOW) / span * width
    rows = (WORLD_HIGH - points[..., 1]) / span * height
    return np.stack([cols, rows], axis=-1)


def pixel_centers(image_shape: Sequence[int]) -> np.ndarray:
    """World coordinates of the centre of every pixel.

    :param image_shape: shape of the image; only (H, W) are used.
    :return: world points [H, W, 2] (x, y).
    """
    height, width = int(image_shape[0]), int(image_shape[1])
    span = WORLD_HIGH - WORLD_LOW
    xs = WORLD_LOW + (np.arange(width) + 0.5) / width * span
    ys = WORLD_HIGH - (np.arange(height) + 0.5) / height * span
    grid_x, grid_y = np.meshgrid(xs, ys)  # [H, W] each
    return np.stack([grid_x, grid_y], axis=-1)


def fill_where(image: np.ndarray, predicate: Callable[[np.ndarray], np.ndarray], color: Color) -> np.ndarray:
    """Paint every pixel whose centre satisfies a vectorised predicate (how maze walls are drawn, exactly).

    :param image: image [H, W, 3] uint8.
    :param predicate: function of world points [H, W, 2] returning a bool mask [H, W].
    :param color: RGB colour.
    :return: a new image with the masked pixels painted.
    """
    out = _checked_copy(image)
    mask = np.asarray(predicate(pixel_centers(out.shape)), dtype=bool)
    if mask.shape != out.shape[:2]:
        raise ValueError(f"predicate must return a mask of shape {out.shape[:2]}, got {mask.shape}")
    out[mask] = _as_rgb(color)
    return out


def fill_box(image: np.ndarray, box: Sequence[float] | np.ndarray, color: Color) -> np.ndarray:
    """Paint an axis-aligned world box.

    :param image: image [H, W, 3] uint8.
    :param box: (xmin, ymin, xmax, ymax) in world coordinates.
    :param color: RGB colour.
    :return: a new image with the box painted (pixels whose centre lies in the closed box).
    """
    xmin, ymin, xmax, ymax = (float(v) for v in np.asarray(box, dtype=np.float64).reshape(4))

    def inside(points: np.ndarray) -> np.ndarray:
        x, y = points[..., 0], points[..., 1]
        return (x >= xmin) & (x <= xmax) & (y >= ymin) & (y <= ymax)

    return fill_where(image, inside, color)


def draw_disc(image: np.ndarray, center: Sequence[float] | np.ndarray, radius: float, color: Color) -> np.ndarray:
    """Paint a filled disc.

    :param image: image [H, W, 3] uint8.
    :param center: (x, y) in world coordinates.
    :param radius: radius in world units (at least one pixel is always painted).
    :param color: RGB colour.
    :return: a new image with the disc painted.
    """
    cx, cy = (float(v) for v in np.asarray(center, dtype=np.float64).reshape(2))
    pixel_size = (WORLD_HIGH - WORLD_LOW) / image.shape[0]
    radius = max(float(radius), 0.5 * pixel_size)

    def inside(points: np.ndarray) -> np.ndarray:
        return (points[..., 0] - cx) ** 2 + (points[..., 1] - cy) ** 2 <= radius**2

    out = fill_where(image, inside, color)
    # A disc smaller than a pixel may miss every pixel centre: paint the pixel under the centre regardless.
    return _paint_pixels(out, world_to_pixel(np.array([[cx, cy]]), out.shape), _as_rgb(color), thickness=1)


def draw_paths(
    image: np.ndarray,
    paths: np.ndarray,
    color: Color = PLAN_ORANGE,
    thickness: int = 1,
) -> np.ndarray:
    """Draw a batch of 2-D polylines (e.g. planned trajectories) over an image.

    :param image: image [H, W, 3] uint8, e.g. a frame from ``env.render()``.
    :param paths: world points [P, T, 2] (P paths of T points) or a single path [T, 2]; non-finite points and the
        segments touching them are skipped, parts outside the world square are clipped away.
    :param color: one RGB colour (3,) for all paths, or one per path [P, 3].
    :param thickness: line width in pixels (1 = one-pixel line).
    :return: a new image with the paths drawn.
    """
    out = _checked_copy(image)
    paths = np.asarray(paths, dtype=np.float64)
    if paths.ndim == 2:
        paths = paths[None]
    if paths.ndim != 3 or paths.shape[-1] != 2:
        raise ValueError(f"paths must have shape [P, T, 2] or [T, 2], got {paths.shape}")
    num_paths = paths.shape[0]
    colors = np.asarray(color)
    if colors.shape == (3,):
        colors = np.broadcast_to(colors, (num_paths, 3))
    if colors.shape != (num_paths, 3):
        raise ValueError(f"color must be one RGB triple or one per path [{num_paths}, 3], got shape {colors.shape}")
    colors = np.stack([_as_rgb(c) for c in colors]) if num_paths else np.zeros((0, 3), np.uint8)
    if thickness < 1:
        raise ValueError(f"thickness must be >= 1 pixel, got {thickness}")
    if num_paths == 0 or paths.shape[1] == 0:
        return out

    pixels = world_to_pixel(paths, out.shape)  # [P, T, 2] (column, row)
    if paths.shape[1] == 1:
        starts, ends = pixels, pixels  # single points: draw dots
    else:
        starts, ends = pixels[:, :-1], pixels[:, 1:]  # [P, T-1, 2] segments
    lengths = np.abs(ends - starts).max(axis=-1)  # [P, S] in pixels
    finite_lengths = lengths[np.isfinite(lengths)]
    # Sample every segment at the same count, enough for the longest one to leave no gaps (capped for sanity).
    num_samples = int(min(np.ceil(finite_lengths.max(initial=0.0)) + 1, 4 * max(out.shape[:2])))
    fractions = np.linspace(0.0, 1.0, max(num_samples, 1))  # [L]
    samples = starts[..., None, :] + fractions[:, None] * (ends - starts)[..., None, :]  # [P, S, L, 2]
    for path_index in range(num_paths):
        _paint_pixels(out, samples[path_index].reshape(-1, 2), colors[path_index], thickness)
    return out


def _paint_pixels(image: np.ndarray, pixel_points: np.ndarray, rgb: np.ndarray, thickness: int) -> np.ndarray:
    """Paint, in place, the pixels under fractional (column, row) points, dropping non-finite or outside ones."""
    height, width = image.shape[:2]
    pixel_points = pixel_points[np.isfinite(pixel_points).all(axis=-1)]
    cols = np.floor(pixel_points[:, 0]).astype(np.int64)
    rows = np.floor(pixel_points[:, 1]).astype(np.int64)
    half = (thickness - 1) // 2
    offsets = np.arange(-half, thickness - half)
    cols = (cols[:, None, None] + offsets[None, None, :]).repeat(thickness, axis=1).reshape(-1)
    rows = (rows[:, None, None] + offsets[None, :, None]).repeat(thickness, axis=2).reshape(-1)
    keep = (cols >= 0) & (cols < width) & (rows >= 0) & (rows < height)
    image[rows[keep], cols[keep]] = rgb
    return image


def _checked_copy(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[-1] != 3 or image.dtype != np.uint8:
        raise ValueError(f"image must be an [H, W, 3] uint8 array, got shape {image.shape} dtype {image.dtype}")
    return image.copy()


def _as_rgb(color: Color) -> np.ndarray:
    rgb = np.asarray(color)
    if rgb.shape != (3,) or not np.all((rgb >= 0) & (rgb <= 255)):
        raise ValueError(f"color must be three ints in [0, 255], got {color!r}")
    return rgb.astype(np.uint8)


__all__ = [
    "AGENT_BLUE",
    "GOAL_GREEN",
    "PLAN_ORANGE",
    "WALL_GRAY",
    "WHITE",
    "blank_canvas",
    "draw_disc",
    "draw_paths",
    "fill_box",
    "fill_where",
    "pixel_centers",
    "world_to_pixel",
]
