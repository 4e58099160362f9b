"""Occupancy grid maps (IR-SIM's ``world.obstacle_map``): an image, or a generator spec, as a grid
of cells over the world rectangle, read as IR-SIM reads it.

An image's grey level becomes an occupancy of 100 (black) to 0 (white), its rows the y axis from
the top (IR-SIM's ``fliplr(grid.T)``), every ``downsample``-th cell kept; the grid spans the world,
so a cell is width / columns by height / rows; a cell above ``threshold`` (IR-SIM's 50) is an
obstacle. A generator spec (IR-SIM's ``perlin``, its ``resolution`` in m per cell) is built by
IR-SIM's own generator, so it needs the ``irsim`` extra.

Flatland's lidar walks the grid of :func:`occupancy` cell by cell; its contacts meet
:func:`boundary_cells`, the occupied cells with a free neighbour, as boxes: a footprint coming
from free space enters the occupied region through one of them. Both see what IR-SIM's map (the
boundary of the union of occupied cells) shows.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import Field, model_validator

from common.errors import ConfigError, quote
from common.fields import Frozen

MAX_CELLS = 4096 * 4096  # an image this many pixels is refused before it is decoded
OCCUPIED_ABOVE = 50.0  # IR-SIM's OCCUPANCY_THRESHOLD


class GridMap(Frozen):
    """Where a grid map comes from: ``image`` (a path; dark is occupied) or ``generator`` (IR-SIM's
    spec as (key, value) pairs, e.g. perlin with its resolution and seed), every ``downsample``-th
    cell kept."""

    image: str | None = None
    generator: tuple[tuple[str, str | float | int | bool], ...] | None = None
    downsample: Annotated[int, Field(ge=1, le=64)] = 1

    @model_validator(mode="after")
    def _one_source(self) -> "GridMap":
        if (self.image is None) == (self.generator is None):
            raise ValueError("a grid map comes from an image or a generator; allowed: one of image, generator")
        return self


def _image_occupancy(path: str) -> np.ndarray:
    """IR-SIM's ImageGridGenerator: 0-100 occupancy, indexed [x, y] with y up."""
    import matplotlib.image as mpimg
    from PIL import Image

    with Image.open(path) as image:  # the header only: a huge image is refused undecoded
        if image.width * image.height > MAX_CELLS:
            raise ConfigError(None, "world.obstacle_map", f"{image.width} x {image.height} pixels; allowed: at most "
                              f"{MAX_CELLS:,} pixels")
    grid = mpimg.imread(path)
    if grid.ndim > 2:
        grid = np.dot(grid[..., :3], [0.2989, 0.5870, 0.1140])
    if np.issubdtype(grid.dtype, np.integer):
        grid = grid.astype(np.float64) / np.iinfo(grid.dtype).max
    elif grid.max() > 1.0:
        grid = grid.astype(np.float64) / grid.max()
    return np.fliplr((100 * (1 - grid.astype(np.float64))).T)


def _generated_occupancy(spec: dict, width: float, height: float) -> np.ndarray:
    try:
        from irsim.world.map import build_grid_from_generator
    except ImportError:
        raise ConfigError(None, "world.obstacle_map", f"the {quote(spec.get('name'))} generator is IR-SIM's; allowed: "
                          "an image, or install the irsim extra (pip install 'nav-curriculum[irsim]')") from None
    try:
        return np.asarray(build_grid_from_generator(spec, world_width=width, world_height=height), dtype=np.float64)
    except (ValueError, TypeError) as exc:
        raise ConfigError(None, "world.obstacle_map", f"{exc}".splitlines()[0]) from None


@functools.lru_cache(maxsize=16)
def occupancy(grid: GridMap, width: float, height: float) -> np.ndarray:
    """The occupied cells (bool, indexed [x, y]) of ``grid`` over a world ``width`` × ``height``."""
    if grid.image is not None:
        levels = _image_occupancy(grid.image)
    else:
        levels = _generated_occupancy(dict(grid.generator or ()), width, height)
    occupied = levels[::grid.downsample, ::grid.downsample] > OCCUPIED_ABOVE
    occupied.setflags(write=False)
    return occupied


def boundary_cells(grid: GridMap, width: float, height: float, offset: tuple[float, float]) -> np.ndarray:
    """The occupied cells with a free neighbour (left, right, below, above; beyond the map counts
    as occupied) as rows x, y, cell width, cell height (centres, in the world frame)."""
    occupied = occupancy(grid, width, height)
    padded = np.pad(occupied, 1, constant_values=True)
    free_beside = ~(padded[:-2, 1:-1] & padded[2:, 1:-1] & padded[1:-1, :-2] & padded[1:-1, 2:])
    i, j = np.nonzero(occupied & free_beside)
    cell_x, cell_y = width / occupied.shape[0], height / occupied.shape[1]
    return np.column_stack([offset[0] + (i + 0.5) * cell_x, offset[1] + (j + 0.5) * cell_y,
                            np.full(len(i), cell_x), np.full(len(i), cell_y)])


def resolve_image(name: str, folder: Path | None) -> str:
    """An image path as IR-SIM finds it: as given, beside the world file, or among the maps IR-SIM
    ships (``cave.png``, ``hm3d_1.png``, ...) when it is installed."""
    for candidate in (Path(name), *(() if folder is None else (folder / name,))):
        if candidate.is_file():
            return str(candidate.resolve())
    try:
        import irsim
    except ImportError:
        irsim = None
    if irsim is not None:
        for found in sorted((Path(irsim.__file__).parent / "world" / "map").rglob(Path(name).name)):
            return str(found)
    raise ConfigError(None, "world.obstacle_map", f"image {quote(name)} not found (as given, beside the world file"
                      f"{', or among IR-SIM’s maps' if irsim is not None else ''}); allowed: an image path")
