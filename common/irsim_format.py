"""Read an IR-SIM world YAML (the 2.x schema) as a project :class:`Scenario`.

The goal is parity with IR-SIM: the same start, limits, lidar, obstacle geometry and moving
objects, so that ``flatland`` reproduces IR-SIM's poses, scans and movers. Facts about IR-SIM
(defaults, key names, fan-out, random placement, behaviours) follow IR-SIM 2.12.

Mapping, and where it deliberately differs from IR-SIM:

* The first robot (after expanding ``number``) is the controlled one, driven by IR-SIM's
  ``diff``, ``omni``, ``omni_angular`` or ``acker`` kinematics (:mod:`common.drive`; a car's
  ``wheelbase`` puts its footprint ahead of its rear axle, as in IR-SIM). Further robots, and every obstacle, are obstacles at their initial
  state; those IR-SIM moves (kinematics ``diff`` or ``omni`` and a ``behavior`` or a group's
  ``group_behavior``) carry a :class:`~common.motion.spec.Motion` read by
  :mod:`common.irsim_motion`, and move as IR-SIM moves them. The collision modes ``stop``,
  ``unobstructed`` and ``unobstructed_obstacles`` are IR-SIM's.
* IR-SIM builds circles as 64-gons (a buffered point); here they stay circles, read by an exact
  ray-circle test and collided with as circles, which is what keeps IR-SIM's typical worlds of
  many small circles fast. A 64-gon's edges lie inside its circle by at most r (1 - cos(pi / 64)),
  0.12 % of r (0.6 mm for r = 0.5 m), so ranges head-on and contact distances differ by that
  much; a beam grazing the rim differs more (tests/test_irsim_parity.py bounds both). Polygons,
  rectangles and lines match IR-SIM to rounding.
* Without a lidar2d sensor the scenario still gets a lidar with IR-SIM's lidar2d defaults,
  because every project scenario carries one.
* Random placement (``distribution: random``), random shapes and wandering goals use
  ``np.random.default_rng(seed)`` with IR-SIM's draw order (robot groups, then obstacle groups;
  per group states, goals, then each object's shape and its first wandering goal), so the result
  equals ``irsim.make(path, seed=seed)``; :func:`parse_irsim_drawing` hands the generator on.
* Keys IR-SIM knows but flatland does not need (colours, plots, contact-mode physics, ...) are
  accepted and ignored; unknown keys and values that would move something in a way flatland
  cannot model are a :class:`ConfigError`.
"""

from __future__ import annotations

import math
import numbers
import operator
from pathlib import Path
from typing import Any, Callable, Hashable, NamedTuple

import numpy as np
from pydantic import ValidationError

from common.drive import CHANNELS as DRIVE_CHANNELS, DEFAULT_NOISE
from common.errors import ConfigError, did_you_mean, quote
from common.grid_maps import GridMap, check_generator, occupied_boxes, resolve_image
from common.irsim_values import (
    Entry,
    Value,
    boolean,
    build_model,
    check_keys,
    fail,
    fit3,
    join,
    mapping_of,
    number_list,
    ordered_bounds,
    point_list,
    real,
    string,
    value_of,
    values_of,
    whole,
)
from common.irsim_motion import moves, needs_tracking, read_motion
from common.kernel_cache import kernel
from common.motion.spec import Motion
from common.polygons import is_simple_polygon
from common.scenario import (
    MAX_OBSTACLES,
    NOISE_SIZES,
    BoxObstacle,
    CircleObstacle,
    LidarSpec,
    PolygonObstacle,
    RobotProfile,
    Scenario,
    SegmentObstacle,
    WorldSpec,
    pydantic_error,
)

TOP_KEYS = ("world", "robot", "obstacle", "gui", "custom")
WORLD_KEYS = (
    "name", "height", "width", "step_time", "sample_time", "offset", "step_mode", "control_mode",
    "collision_mode", "gravity", "friction", "restitution", "drive_tau", "obstacle_map", "mdownsample",
    "fog_map", "fog_map_resolution", "plot", "status",
)
COLLISION_MODES = ("stop", "unobstructed", "unobstructed_obstacles")  # IR-SIM's reactive and contact: not modelled
OBJECT_KEYS = (
    "shape", "kinematics", "state", "velocity", "goal", "role", "color", "static", "mass", "friction",
    "inertia", "restitution", "vel_min", "vel_max", "acce", "angle_range", "behavior", "group_behavior",
    "goal_threshold", "sensors", "arrive_mode", "description", "group", "group_name", "state_dim",
    "vel_dim", "unobstructed", "fov", "fov_radius", "name", "plot", "number", "distribution",
)
KINEMATICS_NAMES = ("diff", "omni", "omni_angular", "acker", "static")
KINEMATICS_KEYS = ("name", "noise", "alpha", "tau", "mode", "wheelbase")
DIFF_KINEMATICS_KEYS = ("name", "noise", "alpha", "tau")
SENSOR_TYPES = ("lidar2d", "fmcw_lidar2d", "contact2d")
LIDAR_KEYS = (
    "name", "type", "range_min", "range_max", "angle_range", "number", "scan_time", "noise", "std",
    "angle_std", "offset", "alpha", "has_velocity", "color", "plot",
)
_RANDOM_POLYGON_KEYS = (
    "random_shape", "is_convex", "center_range", "avg_radius_range", "irregularity_range",
    "spikeyness_range", "num_vertices_range",
)
SHAPE_KEYS = {
    "circle": ("name", "radius", "center", "random_shape", "radius_range", "wheelbase"),
    "rectangle": ("name", "length", "width", "wheelbase"),
    "polygon": ("name", "vertices", *_RANDOM_POLYGON_KEYS),
    "linestring": ("name", "vertices", *_RANDOM_POLYGON_KEYS),
    "compound": ("name", "parts"),
}
PART_SHAPES = ("circle", "rectangle", "polygon")  # IR-SIM's compound parts (fixed shapes: no random ones here)
PART_KEYS = {name: (*(key for key in SHAPE_KEYS[name] if key not in (*_RANDOM_POLYGON_KEYS, "radius_range")), "pose")
             for name in PART_SHAPES}
OBSTACLE_SHAPES = ("circle", "rectangle", "polygon", "linestring")
ROBOT_SHAPES = ("circle", "rectangle", "polygon", "compound")  # the footprints RobotProfile can express
# ``non_overlapping`` is accepted and, as IR-SIM's factory does, ignored (IR-SIM reads it only as an
# argument of its env's random_obstacle_position, never from a file).
DISTRIBUTION_KEYS = ("name", "range_low", "range_high", "min_distance", "radius", "center", "3d", "non_overlapping")
# What one file may cost (IR-SIM has no caps): a shared file must be answered quickly, whatever it holds.
MAX_OBJECTS = MAX_OBSTACLES + 1  # robots and obstacles, after ``number`` fan-out, across the file
MAX_VERTICES = 1000  # per polygon
MAX_TOTAL_VERTICES = 20_000  # across the file (simplicity checks cost the square of a polygon's vertices)
MAX_PLACEMENT_CHECKS = 10_000_000  # candidate-to-placed distance checks of random placement, across the file
MAX_BEAMS = 4096
_MARGIN = 0.5  # IR-SIM keeps default random and circle placements this far inside the world


class _Shape(NamedTuple):
    """A body-frame outline: ``circle`` (points = [centre], radius), ``rectangle`` (points =
    [centre], length, width), ``polygon`` or ``linestring`` (points = vertices)."""

    kind: str
    points: np.ndarray
    radius: float = 0.0
    length: float = 0.0
    width: float = 0.0
    parts: tuple[dict, ...] = ()  # a compound's, as FootprintPart fields in the body frame




class ReadCache:
    """Reads of an IR-SIM file's values, reused while the same value objects come back: a group's
    objects share one shape or kinematics mapping, and the seeds of one file share all but what
    they draw (:class:`common.world_file.WorldFile` keeps one cache per file, so a new layout
    re-reads only its draws). Keyed by identity, which assumes the parsed YAML is not changed
    between parses; it holds the values, so an id reused after one is gone cannot match."""

    MAX_ENTRIES = 4096  # random shapes bring new objects every parse; past this, start afresh

    def __init__(self) -> None:
        self._done: dict[tuple, tuple[tuple, Any]] = {}

    def once(self, what: Hashable, values: tuple, read: Callable[[], Any]) -> Any:
        """``read()``, a function of ``values`` only (paths aside, which only errors name), done
        once for the same value objects. An error is not kept: it is raised again next time."""
        key = (what, *map(id, values))
        held, result = self._done.get(key, (None, None))
        if held is None or not all(map(operator.is_, held, values)):
            if len(self._done) >= self.MAX_ENTRIES:
                self._done.clear()
            result = read()
            self._done[key] = (values, result)
        return result


class _Draws:
    """The file's random generator, what placing and shaping its objects may still cost, and the
    reads already done."""

    def __init__(self, seed: int | None, reads: ReadCache) -> None:
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.reads = reads
        self._left = {"objects": MAX_OBJECTS, "vertices": MAX_TOTAL_VERTICES, "checks": MAX_PLACEMENT_CHECKS}

    def left(self, what: str) -> int:
        """What is left of the budget for ``what``."""
        return self._left[what]

    def spend(self, what: str, amount: int, path: str, advice: str) -> None:
        """Take ``amount`` of ``what`` from the budget, or fail naming ``path``."""
        self._left[what] -= amount
        if self._left[what] < 0:
            raise fail(path, f"the file needs more than {_LIMITS[what]} in all; allowed: {advice}")


_LIMITS = {"objects": f"{MAX_OBJECTS:,} objects", "vertices": f"{MAX_TOTAL_VERTICES:,} polygon vertices",
           "checks": f"{MAX_PLACEMENT_CHECKS:,} random-placement spacing checks"}


# -- world ---------------------------------------------------------------------------------------


def _world(value: Any, path: str) -> tuple[WorldSpec, str | None]:
    """The world block as a WorldSpec (no walls, Euler steps) and its name, if given."""
    world = mapping_of({} if value is None else value, path)
    check_keys(world, WORLD_KEYS, path)
    at = lambda key: join(path, key)  # noqa: E731
    fields = {
        "width": Value(real(world.get("width", 10), at("width"), 0, strict=True), at("width")),
        "height": Value(real(world.get("height", 10), at("height"), 0, strict=True), at("height")),
        "offset": Value(tuple(number_list(world.get("offset", [0, 0]), at("offset"), size=2)), at("offset")),
        "step_time": Value(real(world.get("step_time", 0.1), at("step_time"), 0, strict=True), at("step_time")),
        "walls": Value(False, path),  # IR-SIM's world rectangle only frames the plot
        "integrator": Value("euler", path),
    }
    if world.get("sample_time") is not None:
        real(world["sample_time"], at("sample_time"), 0, strict=True)
    fields["collision_mode"] = Value(string(world.get("collision_mode", "stop"), at("collision_mode"), COLLISION_MODES),
                                     at("collision_mode"))
    string(world.get("step_mode", "internal"), at("step_mode"), ("internal", "external"))
    string(world.get("control_mode", "auto"), at("control_mode"), ("auto", "keyboard"))
    if world.get("mdownsample") is not None:
        whole(world["mdownsample"], at("mdownsample"), 1, 64)
    name = world.get("name")
    if name is not None:
        string(name, at("name"))
    return build_model(WorldSpec, path, fields), name


def _grid_map(value: Any, path: str, source: str | Path | None, world: WorldSpec) -> GridMap | None:
    """IR-SIM's ``obstacle_map`` (an image path, or a generator spec mapping) and ``mdownsample``,
    read now, so that a map that cannot be read is refused with the file."""
    grid = _grid_source(value, path, source, world)
    if grid is not None:
        try:
            occupied_boxes(grid, world.width, world.height, world.offset)  # the map's cells, and its bodies bounded
        except ConfigError as exc:
            raise fail(join(path, "obstacle_map"), exc.problem) from None
    return grid


def _grid_source(value: Any, path: str, source: str | Path | None, world_spec: WorldSpec) -> GridMap | None:
    world = {} if value is None else value
    item = world.get("obstacle_map")
    if item is None:
        return None
    at = join(path, "obstacle_map")
    downsample = whole(world.get("mdownsample", 1), join(path, "mdownsample"), 1, 64)
    if isinstance(item, dict) and item.get("name") == "image":
        if "path" not in item:
            raise fail(join(at, "path"), "missing; IR-SIM's image generator reads the image at path")
        item = item.get("path")
    if isinstance(item, str):
        folder = None if source is None else Path(source).resolve().parent
        try:
            return GridMap(image=resolve_image(item, folder), downsample=downsample)
        except ConfigError as exc:
            raise fail(at, exc.problem) from None
    spec = mapping_of(item, at)
    for key, entry in spec.items():
        if not isinstance(entry, (str, int, float, bool)):
            raise fail(join(at, str(key)), f"expected a number, a string or true/false (got {quote(entry)})")
    string(spec.get("name"), join(at, "name"))
    try:
        check_generator(spec, world_spec.width, world_spec.height, at)
    except ConfigError as exc:
        raise fail(exc.field, exc.problem) from None
    return GridMap(generator=tuple(sorted((str(k), v) for k, v in spec.items())), downsample=downsample)


# -- objects: fan-out and placement --------------------------------------------------------------


def _groups(value: Any, path: str) -> list[tuple[dict, str]]:
    """A robot or obstacle block (a mapping or a list of mappings) as (group, path) pairs."""
    if value is None:
        return []
    if isinstance(value, dict):
        return [(value, path)]
    if not isinstance(value, list):
        raise fail(path, f"expected a mapping or a list of mappings (got {quote(value)})")
    return [(mapping_of(group, f"{path}[{i}]"), f"{path}[{i}]") for i, group in enumerate(value)]


def _fan_out(value: Any, number: int, path: str) -> list[Value]:
    """IR-SIM's per-object spread: a scalar, mapping or number list is shared; any other list holds
    one entry per object, padded with its last entry or truncated."""
    if number == 0:
        return []
    # A list holding any number is a (possibly malformed) vector, so validation names its bad entry.
    if not isinstance(value, list) or not value or any(isinstance(v, numbers.Real) for v in value):
        return [Value(value, path)] * number
    items = [Value(v, f"{path}[{i}]") for i, v in enumerate(value[:number])]
    return items + [items[-1]] * (number - len(items))


def _sensor_fan_out(value: Any, number: int, path: str) -> list[Value]:
    """Sensors are shared when given as a list of mappings, else one list per object."""
    if not isinstance(value, list) or all(isinstance(v, dict) for v in value):
        return [Value(value, path)] * number
    return _fan_out(value, number, path)


def _random_points(draws: _Draws, low: list[float], high: list[float], number: int,
                   min_distance: float, path: str) -> tuple[list[list[float]], list[list[float]]]:
    """IR-SIM's rejection sampling of a group's states, then of its goals: up to 1000 draws per
    point for an xy spacing of ``min_distance`` within each set; when all fail the last draw is
    kept. Spacing checks count against the file's budget, so an impossible spacing is an error
    within a fraction of a second rather than minutes of draws."""
    if number == 0:
        return [], []
    left = draws.left("checks")
    points, checks = _spaced_points(draws.rng, np.asarray(low[:3], dtype=float), np.asarray(high[:3], dtype=float),
                                    number, min_distance, left)
    draws.spend("checks", checks, path, "a smaller min_distance, fewer objects or a wider range")
    states, goals = points.tolist()
    return states, goals


@kernel(inline="always")
def _too_close(dx: float, dy: float, min_distance: float) -> bool:
    """IR-SIM's spacing rule to the last bit: ``np.linalg.norm`` of the xy difference, i.e. the
    square root of the sum of squares (not ``hypot``, which rounds differently and is slower)."""
    return math.sqrt(dx * dx + dy * dy) < min_distance


@kernel
def _spaced_points(rng, low: np.ndarray, high: np.ndarray, number: int, min_distance: float,
                   budget: int) -> tuple[np.ndarray, int]:
    """Two sets of ``number`` points (states, then goals) and how many spacing checks they took;
    stops once the checks pass ``budget``. (One call for both: passing a Generator to a compiled
    function costs 25 µs.)

    Each candidate is IR-SIM's ``rng.uniform(low, high)``: low + (high - low) * random() per axis,
    the same draws bit for bit (numba shares NumPy's generator).
    """
    span = high - low
    sets = np.zeros((2, number, 3))
    checks = 0
    for points in sets:
        for i in range(number):
            for _ in range(1 if i == 0 else 1000):
                for axis in range(3):
                    points[i, axis] = low[axis] + span[axis] * rng.random()
                checks += i
                if checks > budget:
                    return sets, checks
                fits = True
                for j in range(i):
                    if _too_close(points[i, 0] - points[j, 0], points[i, 1] - points[j, 1], min_distance):
                        fits = False
                        break
                if fits:
                    break  # accepted; when all 1000 fail, the last draw is kept
    return sets, checks


def _placements(group: dict, number: int, path: str, draws: _Draws,
                world: WorldSpec) -> tuple[list[Value], list[Value]]:
    """States and goals of a group's objects, by its ``distribution``."""
    dist_path = join(path, "distribution")
    distribution = mapping_of(group.get("distribution") or {"name": "manual"}, dist_path)
    check_keys(distribution, DISTRIBUTION_KEYS, dist_path)
    if "name" not in distribution:
        raise fail(join(dist_path, "name"), "missing; allowed: manual, random, circle")
    name = string(distribution["name"], join(dist_path, "name"), ("manual", "random", "circle"))
    if distribution.get("3d"):
        raise fail(join(dist_path, "3d"), "3D placement is not supported (IR-SIM neither); allowed: false")
    (x0, y0), width, height = world.offset, world.width, world.height
    at = lambda key: join(dist_path, key)  # noqa: E731
    if name == "manual":
        state = group.get("state")
        goal = group.get("goal")
        return (_fan_out([1, 1, 0] if state is None else state, number, join(path, "state")),
                _fan_out([1, 9, 0] if goal is None else goal, number, join(path, "goal")))
    if name == "random":
        default_low = [x0 + _MARGIN, y0 + _MARGIN, -math.pi]
        default_high = [x0 + width - _MARGIN, y0 + height - _MARGIN, math.pi]
        low = number_list(distribution.get("range_low", default_low), at("range_low"), min_size=3)
        high = number_list(distribution.get("range_high", default_high), at("range_high"), min_size=3)
        ordered_bounds(low[:3], high[:3], at("range_high"))
        spacing = real(distribution.get("min_distance", 1.0), at("min_distance"))
        states, goals = _random_points(draws, low, high, number, spacing, at("min_distance"))
        return [Value(s, dist_path) for s in states], [Value(g, dist_path) for g in goals]
    radius = real(distribution.get("radius", min(width, height) / 2 - _MARGIN), at("radius"))
    cx, cy = number_list(distribution.get("center", [x0 + width / 2, y0 + height / 2]), at("center"), min_size=2)[:2]
    states, goals = [], []
    for i in range(number):
        # Evenly spaced on the circle, facing the centre, each goal diametrically opposite.
        theta = 2 * math.pi * i / number
        dx, dy = radius * math.cos(theta), radius * math.sin(theta)
        states.append(Value([cx + dx, cy + dy, theta - math.pi], dist_path))
        goals.append(Value([cx - dx, cy - dy, theta - math.pi], dist_path))
    return states, goals


def _expand(group: dict, path: str, draws: _Draws, world: WorldSpec) -> list[Entry]:
    """One entry per object of a group, every key resolved to that object's value."""
    check_keys(group, OBJECT_KEYS, path)
    number = whole(group.get("number", 1), join(path, "number"), 0, MAX_OBJECTS)
    draws.spend("objects", number, join(path, "number"), "fewer objects")
    states, goals = _placements(group, number, path, draws, world)
    entries: list[Entry] = [{"state": states[i], "goal": goals[i]} for i in range(number)]
    for key, value in group.items():
        if key in ("number", "distribution", "state", "goal"):
            continue
        spread = _sensor_fan_out if key == "sensors" else _fan_out
        for entry, item in zip(entries, spread(value, number, join(path, key))):
            entry[key] = item
    return entries


def _state(entry: Entry) -> tuple[float, float, float]:
    state = entry["state"]
    return fit3(number_list(state.value, state.path))


def _goal(entry: Entry) -> tuple[float, float]:
    goal = entry["goal"]
    value = goal.value
    if isinstance(value, list) and value and isinstance(value[0], list):
        # A list of goals is visited in order; the scenario's goal is the first one.
        goal = Value(value[0], f"{goal.path}[0]")
    x, y = number_list(goal.value, goal.path, min_size=2)[:2]
    return x, y


# -- shapes ----------------------------------------------------------------------------------------


def _shape(item: Value, draws: _Draws, allowed: tuple[str, ...]) -> _Shape:
    """An IR-SIM ``shape`` mapping as a body-frame outline; draws random shapes from the file's generator.

    A group's objects share one shape mapping: a fixed shape is read once per :class:`ReadCache`
    (once per file, across its seeds, in a :class:`~common.world_file.WorldFile`).
    """
    if isinstance(item.value, dict) and item.value.get("random_shape"):
        return _read_shape(item, draws, allowed)
    shape = draws.reads.once(("shape", allowed), (item.value,), lambda: _read_shape(item, draws, allowed))
    if shape.kind in ("polygon", "linestring"):  # every object's vertices count, shared or not
        draws.spend("vertices", len(shape.points), join(item.path, "vertices"), "fewer or simpler polygons")
    for part in shape.parts:
        draws.spend("vertices", len(part.get("vertices", ())), join(item.path, "parts"), "fewer or simpler parts")
    return shape


def _read_shape(item: Value, draws: _Draws, allowed: tuple[str, ...]) -> _Shape:
    if item.value is None:
        # IR-SIM's fallback for an object without a shape (it logs a warning).
        return _Shape("circle", np.zeros((1, 2)), radius=1.0)
    shape = mapping_of(item.value, item.path)
    at = lambda key: join(item.path, key)  # noqa: E731
    name = string(shape.get("name", "circle"), at("name")).lower()
    if name not in allowed:
        raise fail(at("name"), f"unsupported shape {quote(name)}; allowed: {', '.join(allowed)}")
    check_keys(shape, SHAPE_KEYS[name], item.path)
    if name == "compound":
        return _Shape("compound", np.zeros((0, 2)), parts=_compound_parts(Value(shape.get("parts"), at("parts")), draws))
    # An Ackermann wheelbase moves the outline forward by half of it, as in IR-SIM.
    shift = 0.5 * real(shape["wheelbase"], at("wheelbase"), 0) if shape.get("wheelbase") is not None else 0.0
    random_shape = shape.get("random_shape") is not None and boolean(shape["random_shape"], at("random_shape"))
    if name == "circle":
        center = np.array([number_list(shape.get("center", [0, 0]), at("center"), size=2)]) + [shift, 0.0]
        if random_shape:
            low, high = number_list(shape.get("radius_range", [0.1, 1.0]), at("radius_range"), size=2)
            ordered_bounds([low], [high], at("radius_range"))
            radius = float(draws.rng.uniform(low, high))
            if radius <= 0:
                raise fail(at("radius_range"), f"must give radii > 0 (drew {radius:g})")
        else:
            radius = real(shape.get("radius", 0.2), at("radius"), 0, strict=True)
        return _Shape("circle", center, radius=radius)
    if name == "rectangle":
        length = real(shape.get("length", 1.0), at("length"), 0, strict=True)
        width = real(shape.get("width", 1.0), at("width"), 0, strict=True)
        return _Shape("rectangle", np.array([[shift, 0.0]]), length=length, width=width)
    if "vertices" in shape or name == "linestring":
        # IR-SIM requires a linestring's vertices even when it draws a random one instead.
        vertices = point_list(shape.get("vertices"), at("vertices"), 3 if name == "polygon" else 2)
    else:
        vertices = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])  # IR-SIM's default square
    if random_shape:
        vertices = _random_polygon(shape, item.path, draws, default_convex=name == "linestring")
    return _Shape(name, vertices)


def _compound_parts(item: Value, draws: _Draws) -> tuple[dict, ...]:
    """IR-SIM's compound parts, each placed by its ``pose`` in the body frame: rectangles become
    polygons (their corners), circles keep their centre and radius."""
    if not isinstance(item.value, list) or not item.value:
        raise fail(item.path, f"expected a non-empty list of part shapes (got {quote(item.value)})")
    parts = []
    for index, part in enumerate(item.value):
        path = f"{item.path}[{index}]"
        name = string(mapping_of(part, path).get("name"), join(path, "name")).lower()
        if name not in PART_SHAPES:
            raise fail(join(path, "name"), f"unsupported part {quote(name)}; allowed: {', '.join(PART_SHAPES)}")
        check_keys(part, PART_KEYS[name], path)
        pose = fit3(number_list(part.get("pose", [0, 0, 0]), join(path, "pose"), size=3))
        shape = _read_shape(Value({key: value for key, value in part.items() if key != "pose"}, path), draws, PART_SHAPES)
        if shape.kind == "circle":
            parts.append({"center": _transform_point(shape.points[0], pose), "radius": shape.radius})
            continue
        if shape.kind == "rectangle":
            half_length, half_width = 0.5 * shape.length, 0.5 * shape.width
            corners = [(shape.points[0, 0] + sx * half_length, sy * half_width)
                       for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        else:
            corners = _polygon_ring(shape.points, join(path, "vertices"))
        parts.append({"vertices": tuple(_transform_point(np.asarray(corner), pose) for corner in corners)})
    return tuple(parts)


def _random_polygon(shape: dict, path: str, draws: _Draws, default_convex: bool) -> np.ndarray:
    """A random star-shaped polygon, drawn in IR-SIM's order: centre, mean radius, irregularity,
    spikiness, vertex count, angle steps, start angle, then one radius per vertex."""
    at = lambda key: join(path, key)  # noqa: E731
    convex = boolean(shape.get("is_convex", default_convex), at("is_convex"))
    center_range = number_list(shape.get("center_range", [0, 0, 0, 0]), at("center_range"), size=4)
    radius_range = number_list(shape.get("avg_radius_range", [0.1, 1]), at("avg_radius_range"), size=2)
    irregularity_range = number_list(shape.get("irregularity_range", [0, 1]), at("irregularity_range"), size=2)
    spike_default = [0, 0] if convex else [0, 1]
    spike_range = number_list(shape.get("spikeyness_range", spike_default), at("spikeyness_range"), size=2)
    ordered_bounds(center_range[0:2], center_range[2:], at("center_range"))
    ordered_bounds(radius_range[:1], radius_range[1:], at("avg_radius_range"))
    ordered_bounds(irregularity_range[:1], irregularity_range[1:], at("irregularity_range"))
    ordered_bounds(spike_range[:1], spike_range[1:], at("spikeyness_range"))
    count_range = shape.get("num_vertices_range", [4, 10])
    if not isinstance(count_range, list) or len(count_range) != 2:
        raise fail(at("num_vertices_range"), f"expected a list of 2 integers (got {quote(count_range)})")
    low_count = whole(count_range[0], at("num_vertices_range") + "[0]", 3, MAX_VERTICES - 1)
    high_count = whole(count_range[1], at("num_vertices_range") + "[1]", low_count + 1, MAX_VERTICES)
    rng = draws.rng
    center = rng.uniform(low=center_range[0:2], high=center_range[2:], size=(1, 2))[0]
    avg_radius = float(rng.uniform(low=radius_range[0], high=radius_range[1], size=(1,))[0])
    irregularity = float(rng.uniform(low=irregularity_range[0], high=irregularity_range[1], size=(1,))[0])
    spikiness = float(rng.uniform(low=spike_range[0], high=spike_range[1], size=(1,))[0])
    count = int(rng.integers(low=low_count, high=high_count, size=(1,))[0])
    draws.spend("vertices", count, at("num_vertices_range"), "fewer or simpler polygons")
    if not (0 <= irregularity <= 1 and 0 <= spikiness <= 1) or avg_radius <= 0:
        raise fail(path, "random polygon ranges must give irregularity and spikeyness in [0, 1] and radii > 0")
    spread = irregularity * 2 * math.pi / count
    steps = [float(rng.uniform(2 * math.pi / count - spread, 2 * math.pi / count + spread)) for _ in range(count)]
    scale = sum(steps) / (2 * math.pi)
    angle = float(rng.uniform(0, 2 * math.pi))
    vertices = []
    for step in steps:
        radius = min(max(float(rng.normal(avg_radius, spikiness * avg_radius)), 0.0), 2 * avg_radius)
        vertices.append((center[0] + radius * math.cos(angle), center[1] + radius * math.sin(angle)))
        angle += step / scale
    return np.array(vertices)


def _transform(points: np.ndarray, state: tuple[float, float, float]) -> np.ndarray:
    """Body frame to world frame, as IR-SIM's geometry transform: rotate by theta, then translate."""
    x, y, theta = state
    c, s = np.cos(theta), np.sin(theta)
    return np.column_stack((points[:, 0] * c - points[:, 1] * s + x, points[:, 0] * s + points[:, 1] * c + y))


def _polygon_ring(vertices: np.ndarray, path: str) -> np.ndarray:
    """A polygon's ring without a repeated closing vertex; an invalid one becomes its bounding box,
    as IR-SIM replaces it by the envelope of its repaired form."""
    if len(vertices) > 3 and np.array_equal(vertices[0], vertices[-1]):
        vertices = vertices[:-1]
    if is_simple_polygon(vertices):
        return vertices
    (x0, y0), (x1, y1) = vertices.min(axis=0), vertices.max(axis=0)
    if x1 - x0 <= 0 or y1 - y0 <= 0:
        raise fail(path, "the polygon has no area; allowed: at least 3 vertices not on one line")
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])


def _transform_point(point: np.ndarray, state: tuple[float, float, float]) -> tuple[float, float]:
    """One point by :func:`_transform`, to the last bit (the same cosine, the same operations)."""
    x, y, theta = state
    px, py = float(point[0]), float(point[1])
    if px == 0.0 and py == 0.0:
        return x, y  # a centred shape: the rotation adds zeros (the sign of a zero x or y aside)
    c, s = float(np.cos(theta)), float(np.sin(theta))
    return px * c - py * s + x, px * s + py * c + y


def _obstacle(shape: _Shape, state: tuple[float, float, float], unobstructed: bool, shape_path: str,
              motion: Motion | None = None) -> Any:
    """A shape placed at a state as a project obstacle (circles and rectangles may move)."""
    if shape.kind == "circle":
        x, y = _transform_point(shape.points[0], state)
        return CircleObstacle(x=x, y=y, radius=shape.radius, yaw=state[2], unobstructed=unobstructed, motion=motion)
    if shape.kind == "rectangle":
        x, y = _transform_point(shape.points[0], state)
        return BoxObstacle(x=x, y=y, length=shape.length, width=shape.width, yaw=state[2], unobstructed=unobstructed,
                           motion=motion)
    if shape.kind == "polygon":
        ring = _polygon_ring(shape.points, join(shape_path, "vertices"))
        return PolygonObstacle(vertices=[tuple(p) for p in _transform(ring, state)], unobstructed=unobstructed)
    return SegmentObstacle(points=[tuple(p) for p in _transform(shape.points, state)], unobstructed=unobstructed)


# -- robots, sensors, obstacles ---------------------------------------------------------------------


def _kinematics_name(entry: Entry, path: str) -> str | None:
    """The validated kinematics name of an object (None: passive, i.e. static)."""
    item = value_of(entry, "kinematics", None, path)
    if item.value is None:
        return None
    kinematics = mapping_of(item.value, item.path)
    check_keys(kinematics, KINEMATICS_KEYS, item.path)
    if "name" not in kinematics:
        return None
    name_path = join(item.path, "name")
    return string(string(kinematics["name"], name_path).lower(), name_path, KINEMATICS_NAMES)


def _check_drive(entry: Entry, path: str) -> None:
    """The controlled robot must be driven by one of IR-SIM's kinematics and move."""
    item = value_of(entry, "kinematics", None, path)
    allowed = f"allowed: {{name: {' | '.join(DRIVE_CHANNELS)}}}"
    if item.value is None:
        raise fail(item.path, f"missing (IR-SIM would make the robot static); {allowed}")
    kinematics = mapping_of(item.value, item.path)
    name = kinematics.get("name")
    if not isinstance(name, str) or name.lower() not in DRIVE_CHANNELS:
        raise fail(item.path, f"unsupported kinematics {quote(name)} for the controlled robot; {allowed}")
    check_keys(kinematics, KINEMATICS_KEYS if name.lower() == "acker" else DIFF_KINEMATICS_KEYS, item.path)
    if name.lower() == "acker":
        string(kinematics.get("mode", "steer"), join(item.path, "mode"), ("steer", "angular"))
    size = len(DRIVE_CHANNELS[name.lower()])
    velocity = value_of(entry, "velocity", [0] * size, path)
    if any(v != 0 for v in number_list(velocity.value, velocity.path, size=size)):
        raise fail(velocity.path, f"the robot starts at rest; allowed: {[0] * size}")
    state = value_of(entry, "state", [0, 0, 0], path)
    if name.lower() == "acker" and isinstance(state.value, list) and len(state.value) > 3 and state.value[3] != 0:
        raise fail(state.path, "a car starts with its wheels straight; allowed: a steering angle (state[3]) of 0")


# IR-SIM's names of each kinematics' command channels (vel_min, vel_max, acce), as RobotProfile's.
_CHANNEL_FIELDS = {"v": ("v_min", "v_max", "accel_v"), "w": ("w_min", "w_max", "accel_w"),
                   "lateral": ("lateral_min", "lateral_max", "accel_lateral"),
                   "steer": ("steer_min", "steer_max", "accel_steer")}


def _robot_profile(entry: Entry, shape: _Shape, path: str) -> RobotProfile:
    """Footprint, kinematics, velocity limits and acceleration limits of the controlled robot."""
    if shape.kind != "polygon" and np.any(shape.points[:, 1] != 0):
        raise fail(join(path, "shape.center"), "a footprint off the robot's heading line is not supported; "
                   "allowed: a centre [x, 0]")
    kinematics = value_of(entry, "kinematics", None, path)
    name = kinematics.value["name"].lower()
    channels = DRIVE_CHANNELS[name]
    size = len(channels)
    vel_min = value_of(entry, "vel_min", [-1] * size, path)
    vel_max = value_of(entry, "vel_max", [1] * size, path)
    acce = value_of(entry, "acce", [math.inf] * size, path)
    lows = number_list(vel_min.value, vel_min.path, size=size, allow_inf=True)
    highs = number_list(vel_max.value, vel_max.path, size=size, allow_inf=True)
    accelerations = number_list(acce.value, acce.path, size=size, allow_inf=True)
    shape_path = value_of(entry, "shape", None, path).path
    fields = {"kinematics": Value(name, join(kinematics.path, "name"))}
    if shape.kind not in ("polygon", "compound"):
        fields["footprint_offset"] = Value(float(shape.points[0, 0]), shape_path)
    static = value_of(entry, "static", False, path)
    if boolean(static.value, static.path):
        fields["static"] = Value(True, static.path)
    settings = kinematics.value
    if boolean(settings.get("noise", False), join(kinematics.path, "noise")):
        alpha = settings.get("alpha")
        fields["motion_noise"] = Value(DEFAULT_NOISE[name] if alpha is None else tuple(
            number_list(alpha, join(kinematics.path, "alpha"), min_size=NOISE_SIZES[name])), join(kinematics.path, "alpha"))
    for channel, low, high, acceleration in zip(channels, lows, highs, accelerations):
        if low > high:
            raise fail(vel_min.path, f"{channel} minimum {low:g} exceeds vel_max's {high:g}; allowed: at most vel_max")
        low_field, high_field, acceleration_field = _CHANNEL_FIELDS[channel]
        fields.update({low_field: Value(low, vel_min.path), high_field: Value(high, vel_max.path),
                       acceleration_field: Value(acceleration, acce.path)})
    if name == "acker":
        # The wheelbase under kinematics wins over the shape's, as in IR-SIM (default 1).
        outline = value_of(entry, "shape", None, path).value or {}
        wheelbase = settings.get("wheelbase", outline.get("wheelbase") if isinstance(outline, dict) else None)
        fields["axle_distance"] = Value(1.0 if wheelbase is None else real(wheelbase, join(kinematics.path, "wheelbase"),
                                                                            0, strict=True), kinematics.path)
        fields["steer_mode"] = Value(settings.get("mode", "steer"), join(kinematics.path, "mode"))
    if shape.kind == "circle":
        fields.update(shape=Value("circle", shape_path), radius=Value(shape.radius, shape_path))
    elif shape.kind == "polygon":
        fields.update(shape=Value("polygon", shape_path),
                      vertices=Value(tuple(map(tuple, shape.points.tolist())), join(shape_path, "vertices")))
    elif shape.kind == "compound":
        fields.update(shape=Value("compound", shape_path), parts=Value(shape.parts, join(shape_path, "parts")))
    else:
        fields.update(shape=Value("box", shape_path), length=Value(shape.length, shape_path),
                      width=Value(shape.width, shape_path))
    return build_model(RobotProfile, path, fields)


def _lidar(entry: Entry, path: str) -> LidarSpec:
    """The first lidar2d sensor as a LidarSpec (IR-SIM's lidar2d defaults when there is none).
    Every lidar2d is read and checked as IR-SIM builds each: only the first was, and a second one
    with a misspelt key or a negative range loaded without a word."""
    item = value_of(entry, "sensors", [], path)
    if not isinstance(item.value, list):
        raise fail(item.path, f"expected a list of sensor mappings (got {quote(item.value)})")
    lidars = []
    for i, candidate in enumerate(item.value):
        candidate_path = f"{item.path}[{i}]"
        mapping_of(candidate, candidate_path)
        key = "name" if "name" in candidate else "type"
        if string(candidate.get(key, "lidar2d"), join(candidate_path, key), SENSOR_TYPES) == "lidar2d":
            lidars.append(_lidar_spec(candidate, candidate_path))
    return lidars[0] if lidars else _lidar_spec({}, item.path)


def _lidar_spec(sensor: dict, sensor_path: str) -> LidarSpec:
    """One lidar2d sensor's mapping as a LidarSpec."""
    check_keys(sensor, LIDAR_KEYS, sensor_path)
    at = lambda key: join(sensor_path, key)  # noqa: E731
    number = whole(sensor.get("number", 100), at("number"), 1, MAX_BEAMS)
    angle_range = min(real(sensor.get("angle_range", math.pi), at("angle_range"), 0, strict=True), 2 * math.pi)
    offset = fit3(number_list(sensor.get("offset", [0, 0, 0]), at("offset"), min_size=2))
    noisy = boolean(sensor.get("noise", False), at("noise"))
    std = real(sensor.get("std", 0.2), at("std"), 0)
    fields = {
        "beams": Value(number, at("number")),
        "range_min": Value(real(sensor.get("range_min", 0), at("range_min"), 0), at("range_min")),
        "range_max": Value(real(sensor.get("range_max", 10), at("range_max"), 0, strict=True), at("range_max")),
        "angle_range": Value(angle_range, at("angle_range")),
        "offset": Value(offset, at("offset")),
        "noise_std": Value(std if noisy else 0.0, at("std")),
        "repeat_end_beam": Value(True, sensor_path),  # IR-SIM's linspace layout, for parity
    }
    return build_model(LidarSpec, sensor_path, fields)


def _object(entry: Entry, path: str, draws: _Draws, role: str) -> Any:
    """Any object other than the controlled robot: an obstacle at its initial state, moving as
    IR-SIM moves it if it has kinematics and a behaviour."""
    if "kinematics" in entry:  # most obstacles have none, which needs no reading
        draws.reads.once("kinematics", values_of(entry, ("kinematics",)), lambda: _kinematics_name(entry, path))
    item = value_of(entry, "shape", None, path)
    shape = _shape(item, draws, OBSTACLE_SHAPES)
    flag = entry.get("unobstructed")
    unobstructed = flag is not None and flag.value is not None and boolean(flag.value, flag.path)
    state = _state(entry)
    motion = None
    if moves(entry, path):
        if shape.kind not in ("circle", "rectangle"):
            raise fail(join(item.path, "name"), f"a moving {shape.kind} is not supported; allowed: circle, rectangle")
        if np.any(shape.points != 0):
            raise fail(item.path, "a moving shape off its centre is not supported; allowed: a centred circle or rectangle")
        motion = read_motion(entry, path, draws.rng, path, role)
    try:
        return _obstacle(shape, state, unobstructed, item.path, motion)
    except ValidationError as exc:
        error = pydantic_error(None, exc)
        # Where the obstacle stands comes from its state (or the distribution that drew it), its size from its shape.
        placed = error.field in ("x", "y", "yaw")
        raise fail(value_of(entry, "state", None, path).path if placed else item.path, error.problem) from None


_DRIVE_KEYS = ("kinematics", "static", "velocity", "state")
_PROFILE_KEYS = ("kinematics", "static", "vel_min", "vel_max", "acce")  # and the footprint read, which is keyed on its shape


def _parse(data: dict, source: str | Path | None, draws: _Draws) -> Scenario:
    prefix = ""
    if "irsim" in data:
        # IR-SIM reads only the ``irsim`` block of a file shared with another simulator.
        data, prefix = mapping_of(data["irsim"], "irsim"), "irsim."
    for key in data:
        if key not in TOP_KEYS:
            raise fail(f"{prefix}{key}", f"unknown key{did_you_mean(key, TOP_KEYS)}; allowed: {', '.join(TOP_KEYS)}")
    reads = draws.reads
    world, name = reads.once("world", (data.get("world"),), lambda: _world(data.get("world"), f"{prefix}world"))
    grid_map = reads.once("grid map", (data.get("world"),),
                          lambda: _grid_map(data.get("world"), f"{prefix}world", source, world))
    obstacles: list[Any] = []
    robot = robot_motion = None
    for group, path in _groups(data.get("robot"), f"{prefix}robot"):
        for entry in _expand(group, path, draws, world):
            # Objects are made in IR-SIM's order, so random radii and wandering goals draw as IR-SIM's do.
            if robot is None:
                reads.once("drive", values_of(entry, _DRIVE_KEYS), lambda: _check_drive(entry, path))
                shape = _shape(value_of(entry, "shape", None, path), draws, ROBOT_SHAPES)
                robot = (entry, path, shape)
                if needs_tracking(entry, path):
                    robot_motion = read_motion(entry, path, draws.rng, path, "robot")
            else:
                obstacles.append(_object(entry, path, draws, "robot"))
    if robot is None:
        raise fail(f"{prefix}robot", "no robot defined; allowed: at least one robot with kinematics "
                   f"{{name: {' | '.join(DRIVE_CHANNELS)}}}")
    for group, path in _groups(data.get("obstacle"), f"{prefix}obstacle"):
        for entry in _expand(group, path, draws, world):
            obstacles.append(_object(entry, path, draws, "obstacle"))
    entry, path, shape = robot
    threshold = value_of(entry, "goal_threshold", 0.1, path)
    fields = {
        "name": Value(name or (Path(source).stem if source is not None else "irsim"), f"{prefix}world.name"),
        "world": Value(world, f"{prefix}world"),
        "robot": Value(reads.once("robot", (*values_of(entry, _PROFILE_KEYS), shape),
                                  lambda: _robot_profile(entry, shape, path)), path),
        "lidar": Value(reads.once("lidar", values_of(entry, ("sensors",)), lambda: _lidar(entry, path)),
                       join(path, "sensors")),
        "start": Value(_state(entry), join(path, "state")),
        "goal": Value(_goal(entry), join(path, "goal")),
        "goal_threshold": Value(real(threshold.value, threshold.path, 0, strict=True), threshold.path),
        "obstacles": Value(obstacles, f"{prefix}obstacle"),
        "kind": Value("irsim", prefix or "world"),
        "seed": Value(draws.seed if reads.once("random", (data,), lambda: has_random_placement(data)) else None,
                      prefix or "world"),
        "robot_motion": Value(robot_motion, path),
        "grid_map": Value(grid_map, f"{prefix}world.obstacle_map"),
    }
    return build_model(Scenario, prefix.rstrip("."), fields)


def parse_irsim(data: dict, source: str | Path | None = None, seed: int | None = 0,
                reads: ReadCache | None = None) -> Scenario:
    """A validated :class:`Scenario` from a parsed IR-SIM world YAML mapping.

    ``seed`` drives random placements, shapes and wandering goals. The start may touch an obstacle
    (IR-SIM allows it), so only types and values are checked, not geometry. Every problem is a
    one-line :class:`ConfigError` naming the field, e.g. ``obstacle[2].shape.radius: must be > 0
    (got -1)``. ``reads``: a :class:`ReadCache` kept between parses of the same, unchanged ``data``.
    """
    return parse_irsim_drawing(data, source, seed, reads)[0]


def parse_irsim_drawing(data: dict, source: str | Path | None = None, seed: int | None = 0,
                        reads: ReadCache | None = None) -> tuple[Scenario, np.random.Generator]:
    """:func:`parse_irsim`, and the file's generator where the parse left it: what IR-SIM draws
    from next (a wanderer's next goal), as ``irsim.make(path, seed=seed)`` leaves it."""
    try:
        if not isinstance(data, dict):
            raise fail(None, f"expected a YAML mapping at the top level (got {type(data).__name__})")
        draws = _Draws(seed, ReadCache() if reads is None else reads)
        return _parse(data, source, draws), draws.rng
    except ConfigError as exc:
        raise (exc.with_source(source) if source is not None else exc) from None


def has_random_placement(data: dict) -> bool:
    """Whether any robot or obstacle uses ``distribution: random``, a ``random_shape`` or a
    wandering behaviour (whose first goal is drawn with the layout)."""
    if isinstance(data, dict) and isinstance(data.get("irsim"), dict):
        data = data["irsim"]
    if not isinstance(data, dict):
        return False
    for section in ("robot", "obstacle"):
        groups = data.get(section)
        for group in groups if isinstance(groups, list) else [groups]:
            if not isinstance(group, dict):
                continue
            distribution = group.get("distribution")
            if isinstance(distribution, dict) and distribution.get("name") == "random":
                return True
            shapes = group.get("shape")
            shapes = shapes if isinstance(shapes, list) else [shapes]
            if any(isinstance(shape, dict) and shape.get("random_shape") for shape in shapes):
                return True
            behaviors = [group.get("behavior"), group.get("group_behavior")]
            behaviors = [b for item in behaviors for b in (item if isinstance(item, list) else [item])]
            if any(isinstance(b, dict) and b.get("wander") for b in behaviors):
                return True
    return False
