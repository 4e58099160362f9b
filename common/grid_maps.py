"""Occupancy grid maps (IR-SIM's ``world.obstacle_map``): an image, or a generator spec, as a grid
of cells over the world rectangle, read as IR-SIM reads it.

An image's grey level becomes an occupancy of 100 (black) to 0 (white), its rows the y axis from
the top (IR-SIM's ``fliplr(grid.T)``), every ``downsample``-th cell kept; the grid spans the world,
so a cell is width / columns by height / rows; a cell above ``threshold`` (IR-SIM's 50) is an
obstacle. A generator spec is this project's ``maze`` (:func:`maze_occupancy`) or IR-SIM's
(``perlin``, its ``resolution`` in m per cell), built by IR-SIM's own generator, so it needs the
``irsim`` extra.

Flatland's lidar walks the grid of :func:`occupancy` cell by cell; its contacts meet the occupied
cells merged into boxes (:func:`occupied_boxes`), whose union is theirs. Both see what IR-SIM's
map (the boundary of the union of occupied cells) shows.
"""

from __future__ import annotations

import functools
import io
from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import Field, model_validator

from common.errors import ConfigError, quote
from common.fields import MAX_LENGTH, Frozen
from common.files import read_bytes, regular_file
from common.irsim_package import import_irsim, quiet_stdout
from common.params import is_real

MAX_CELLS = 4096 * 4096  # an image this many pixels is refused before it is decoded
MAX_SIDE = 8192  # pixels along either side: boxes are merged column by column, in Python
# Boxes of occupied cells: each is a body in flatland's world (IR-SIM's own maps make at most
# 14,236); a 1024 x 1024 checkerboard, 2 KB of PNG, would have made 524,288 and minutes of building.
MAX_BOXES = 65_536
# A generated grid's cells: IR-SIM's Perlin noise holds several float arrays of this size at once.
MAX_GENERATED_CELLS = 2048 * 2048
MAX_IMAGE_BYTES = 64 * 1024 * 1024
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
        keys = [key for key, _ in self.generator or ()]
        if twice := sorted({key for key in keys if keys.count(key) > 1}):
            raise ValueError(f"generator: {', '.join(map(quote, twice))} given twice; allowed: each key once")
        return self


def _image_occupancy(path: str) -> np.ndarray:
    """IR-SIM's ImageGridGenerator: 0-100 occupancy, indexed [x, y] with y up."""
    import matplotlib.image as mpimg
    from PIL import Image, UnidentifiedImageError

    # Read once, bounded, from a regular file only: PIL opening a FIFO waited for a writer forever.
    data = read_bytes(path, MAX_IMAGE_BYTES, "an image file")
    try:
        with Image.open(io.BytesIO(data)) as image:  # the header only: a huge image is refused undecoded
            width, height = image.size
        too_large = width * height > MAX_CELLS or max(width, height) > MAX_SIDE
        grid = None if too_large else mpimg.imread(io.BytesIO(data), format=Path(path).suffix.lstrip(".") or None)
    # SyntaxError: PIL's PNG reader, forced by the name, meeting another format (a JPEG named .png).
    except (UnidentifiedImageError, Image.DecompressionBombError, OSError, ValueError, SyntaxError) as exc:
        # PIL refuses a header of more pixels than its own cap before ours can (a bomb).
        why = str(exc).split(",")[0] if isinstance(exc, Image.DecompressionBombError) else "unreadable image data"
        raise ConfigError(path, "world.obstacle_map", f"{why}; allowed: a PNG or another image of at most "
                          f"{MAX_CELLS:,} pixels") from None
    if too_large:
        raise ConfigError(path, "world.obstacle_map", f"{width} x {height} pixels; allowed: at most {MAX_CELLS:,} pixels, "
                          f"{MAX_SIDE:,} along either side")
    if grid.ndim > 2:
        grid = np.dot(grid[..., :3], [0.2989, 0.5870, 0.1140])
    if np.issubdtype(grid.dtype, np.integer):
        grid = grid.astype(np.float64) / np.iinfo(grid.dtype).max
    elif grid.max() > 1.0:
        grid = grid.astype(np.float64) / grid.max()
    return np.fliplr((100 * (1 - grid.astype(np.float64))).T)


def write_occupancy_image(occupied: np.ndarray, path: str | Path) -> Path:
    """An 8-bit grey PNG that :func:`_image_occupancy` (IR-SIM's reading) reads back as ``occupied``
    (bool, indexed [x, y]): black where occupied, white where free."""
    from PIL import Image

    grey = 1.0 - np.fliplr(np.asarray(occupied, dtype=np.float64)).T  # the inverse of the reading's fliplr and .T
    Image.fromarray(np.round(255 * grey).astype(np.uint8), mode="L").save(path)
    return Path(path)


def maze_occupancy(seed: int, width: float, height: float, resolution: float, passage: float,
                   loops: float) -> np.ndarray:
    """A maze drawn from ``seed`` (0-100 occupancy, indexed [x, y]): rooms ``passage`` m wide on a
    lattice, walls one cell thick between them, a spanning tree of doors carved by a randomised
    depth-first walk (every room reachable from every other), then a ``loops`` fraction of the
    remaining walls between rooms opened, so that there are other ways round."""
    rng = np.random.default_rng(seed)
    nx, ny = max(1, round(width / resolution)), max(1, round(height / resolution))
    pitch = max(2, round(passage / resolution)) + 1  # a room's cells and one wall
    rooms_x, rooms_y = max(1, (nx - 1) // pitch), max(1, (ny - 1) // pitch)
    occupied = np.ones((nx, ny), dtype=bool)
    for a in range(rooms_x):
        for b in range(rooms_y):
            occupied[1 + a * pitch:(a + 1) * pitch, 1 + b * pitch:(b + 1) * pitch] = False

    def open_between(a: int, b: int, c: int, d: int) -> None:
        if a == c:  # the wall above or below: a horizontal run of cells
            wall = max(b, d) * pitch
            occupied[1 + a * pitch:(a + 1) * pitch, wall] = False
        else:
            wall = max(a, c) * pitch
            occupied[wall, 1 + b * pitch:(b + 1) * pitch] = False

    seen = np.zeros((rooms_x, rooms_y), dtype=bool)
    stack, seen[0, 0] = [(0, 0)], True
    closed = []
    while stack:
        a, b = stack[-1]
        unseen = [(c, d) for c, d in ((a - 1, b), (a + 1, b), (a, b - 1), (a, b + 1))
                  if 0 <= c < rooms_x and 0 <= d < rooms_y and not seen[c, d]]
        if not unseen:
            stack.pop()
            continue
        c, d = unseen[rng.integers(len(unseen))]
        open_between(a, b, c, d)
        seen[c, d] = True
        stack.append((c, d))
    for a in range(rooms_x):
        for b in range(rooms_y):
            for c, d in ((a + 1, b), (a, b + 1)):
                if c < rooms_x and d < rooms_y:
                    closed.append((a, b, c, d))
    for a, b, c, d in closed:
        if rng.random() < loops:
            open_between(a, b, c, d)
    return np.where(occupied, 100.0, 0.0)


def maze_rooms(width: float, height: float, resolution: float, passage: float,
               offset: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """The centres (x, y) of the rooms of :func:`maze_occupancy`'s lattice."""
    nx, ny = max(1, round(width / resolution)), max(1, round(height / resolution))
    pitch = max(2, round(passage / resolution)) + 1
    rooms_x, rooms_y = max(1, (nx - 1) // pitch), max(1, (ny - 1) // pitch)
    a, b = np.meshgrid(np.arange(rooms_x), np.arange(rooms_y), indexing="ij")
    middle = 1 + 0.5 * (pitch - 1)  # cells from a room's wall to its centre
    return np.column_stack([offset[0] + (a.ravel() * pitch + middle) * resolution,
                            offset[1] + (b.ravel() * pitch + middle) * resolution])


# This project's own generators (the others are IR-SIM's): name -> builder of the spec's keys.
OWN_GENERATORS = {"maze": maze_occupancy}

# Each generator's keys: (what is allowed, the check). IR-SIM's own checks come after its work,
# or never (a fill of 5 indexed out of its array; a resolution of 1e-5 asked for terabytes).
# Bounded above as well: 1e-320 m cells or a 1e308 m passage overflowed the cell counts, and a
# Perlin complexity of 1e300 made NaN noise (an empty map, silently).
_LENGTH = (f"a length from 0.001 to {MAX_LENGTH:g} m", lambda v: is_real(v) and 0.001 <= v <= MAX_LENGTH)
_SCALE = ("a number above 0, at most 1000", lambda v: is_real(v) and 0.0 < v <= 1000.0)
_FRACTION = ("a number from 0 to 1", lambda v: is_real(v) and 0.0 <= v <= 1.0)
_SEED = ("a whole number from 0, or null", lambda v: v is None or (_is_whole(v) and v >= 0))
GENERATOR_KEYS: dict[str, dict[str, tuple[str, object]]] = {
    "maze": {"resolution": _LENGTH, "passage": _LENGTH, "loops": _FRACTION, "seed": _SEED},
    "perlin": {"resolution": _LENGTH, "complexity": _SCALE, "fill": _FRACTION, "attenuation": _SCALE,
               "fractal": ("a whole number from 1 to 16", lambda v: _is_whole(v) and 1 <= v <= 16), "seed": _SEED},
}
_REQUIRED = {"maze": ("resolution", "passage", "loops", "seed"), "perlin": ("resolution",)}


def _is_whole(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def check_generator(spec: dict, width: float, height: float, field: str = "generator") -> None:
    """A one-line error for a generator spec that names no known generator, a key it does not
    take, a value out of its range, or more than :data:`MAX_GENERATED_CELLS` cells over the world:
    checked before anything is built. The spec's keys are named under ``field``."""
    name = spec.get("name")
    if name not in GENERATOR_KEYS:
        raise ConfigError(None, f"{field}.name", f"got {quote(name)}; allowed: {', '.join(GENERATOR_KEYS)}")
    keys = GENERATOR_KEYS[name]
    for key, value in spec.items():
        if key == "name":
            continue
        if key not in keys:
            raise ConfigError(None, f"{field}.{key}", f"unknown key of the {name} generator; allowed: "
                              f"{', '.join(keys)}")
        allowed, ok = keys[key]
        if not ok(value):
            raise ConfigError(None, f"{field}.{key}", f"got {quote(value)}; allowed: {allowed}")
    for key in _REQUIRED[name]:
        if key not in spec:
            raise ConfigError(None, f"{field}.{key}", f"missing; the {name} generator needs "
                              f"{', '.join(_REQUIRED[name])}")
    resolution = spec["resolution"]
    cells = max(1, round(width / resolution)) * max(1, round(height / resolution))
    if cells > MAX_GENERATED_CELLS:
        raise ConfigError(None, f"{field}.resolution", f"{resolution:g} m makes {cells:,} cells over the "
                          f"{width:g} x {height:g} m world; allowed: at most {MAX_GENERATED_CELLS:,} cells")
    octaves = spec.get("fractal", 1)  # Perlin noise is computed over every cell once per octave
    if cells * octaves > MAX_GENERATED_CELLS:
        raise ConfigError(None, f"{field}.fractal", f"{octaves} octaves over {cells:,} cells; allowed: at most "
                          f"{MAX_GENERATED_CELLS:,} cells times octaves")


def _generated_occupancy(spec: dict, width: float, height: float) -> np.ndarray:
    check_generator(spec, width, height)
    if spec["name"] in OWN_GENERATORS:
        keys = {k: v for k, v in spec.items() if k != "name"}
        return OWN_GENERATORS[spec["name"]](width=width, height=height, **keys)
    if import_irsim() is None:
        raise ConfigError(None, "world.obstacle_map", f"the {quote(spec.get('name'))} generator is IR-SIM's; allowed: "
                          "an image, or install the irsim extra (pip install 'nav-curriculum[irsim]')")
    with quiet_stdout():  # IR-SIM's map module probes GUI backends on import, printing a line for each
        from irsim.world.map import build_grid_from_generator
    return np.asarray(build_grid_from_generator(spec, world_width=width, world_height=height), dtype=np.float64)


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


@functools.lru_cache(maxsize=16)
def occupied_boxes(grid: GridMap, width: float, height: float, offset: tuple[float, float]) -> np.ndarray:
    """The occupied cells merged into axis-aligned boxes that cover exactly them, as rows x, y
    (centre), width, height in the world frame: each column's runs of occupied cells, and runs
    alike in neighbouring columns joined (a maze's wall is one box, not a box per cell)."""
    occupied = occupancy(grid, width, height)
    cell_x, cell_y = width / occupied.shape[0], height / occupied.shape[1]
    boxes: list[tuple[float, float, float, float]] = []
    open_runs: dict[tuple[int, int], int] = {}  # (first row, end row) of a run -> the column it began in
    for i in range(occupied.shape[0] + 1):
        runs = set()
        if i < occupied.shape[0]:
            column = np.concatenate([[False], occupied[i], [False]])
            edges = np.flatnonzero(column[1:] != column[:-1])
            runs = set(zip(edges[::2].tolist(), edges[1::2].tolist()))
        for run in [run for run in open_runs if run not in runs]:
            first = open_runs.pop(run)
            boxes.append((offset[0] + 0.5 * (first + i) * cell_x, offset[1] + 0.5 * (run[0] + run[1]) * cell_y,
                          (i - first) * cell_x, (run[1] - run[0]) * cell_y))
        for run in runs:
            open_runs.setdefault(run, i)
        if len(boxes) + len(open_runs) > MAX_BOXES:
            raise ConfigError(None, "world.obstacle_map", f"more than {MAX_BOXES:,} boxes of occupied cells; allowed: at "
                              f"most {MAX_BOXES:,} (a coarser map, or downsample)")
    table = np.array(boxes, dtype=float).reshape(-1, 4)
    table.setflags(write=False)
    return table


def resolve_image(name: str, folder: Path | None) -> str:
    """An image path as IR-SIM finds it: as given, beside the world file, or among the maps IR-SIM
    ships (``cave.png``, ``hm3d_1.png``, ...) when it is installed."""
    for candidate in (Path(name), *(() if folder is None else (folder / name,))):
        try:
            found = candidate.exists()
        except OSError as error:  # a name too long for the file system
            raise ConfigError(None, "world.obstacle_map", f"image {quote(name)}: {error.strerror or error}; "
                              "allowed: an image path") from None
        if found:  # a FIFO or a directory by that name is refused, not passed over
            return str(regular_file(candidate, "an image file").resolve())
    irsim = import_irsim()
    if irsim is not None:
        for found in sorted((Path(irsim.__file__).parent / "world" / "map").rglob(Path(name).name)):
            return str(found)
    raise ConfigError(None, "world.obstacle_map", f"image {quote(name)} not found (as given, beside the world file"
                      f"{', or among IR-SIM’s maps' if irsim is not None else ''}); allowed: an image path")
