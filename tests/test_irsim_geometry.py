"""IR-SIM's object discs (common/irsim_geometry.py) against shapely, GEOS and IR-SIM, to the last bit.

Every comparison is ``==`` on floats: the point of the module is that a head-on social force takes
the sign of an angle made only of the centroid's last bits, so "close" would not be a pass.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from common import irsim_geometry as g
from tests.conftest import optional

shapely = optional("shapely")

ROUND_RADII = (0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.5, 0.75, 1.0, 1.5, 2.0, 2.5, 3.0, 5.0)
SPECIAL_THETAS = (0.0, math.pi, -math.pi, math.pi / 2, -math.pi / 2, math.pi / 4, 1e-17)


def transformed(outline: np.ndarray, x: float, y: float, theta: float) -> np.ndarray:
    """The ring as the centroid places it vertex by vertex (:func:`common.irsim_geometry.placed`)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([g.placed(outline, i, x, y, c, s) for i in range(len(outline))])


def circles(n: int, seed: int) -> list[tuple[float, float, float]]:
    """(radius, cx, cy): round and random radii, centred at the origin, off it, or shifted by a wheelbase."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        radius = ROUND_RADII[k % len(ROUND_RADII)] if k % 4 == 0 else float(rng.uniform(0.05, 5.0))
        kind = k % 3
        if kind == 0:
            cx = cy = 0.0
        elif kind == 1:
            cx, cy = (float(v) for v in rng.uniform(-2.0, 2.0, 2))
        else:  # IR-SIM's wheelbase circle: Point([center[0] + wheelbase / 2, center[1]])
            cx, cy = 0.0 + float(rng.uniform(0.1, 3.0)) / 2, 0.0
        out.append((radius, cx, cy))
    return out


def rectangles(n: int, seed: int) -> list[tuple[float, float, float | None]]:
    """(length, width, wheelbase or None)."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        length, width = (float(v) for v in rng.uniform(0.05, 5.0, 2))
        if k % 5 == 0:
            length, width = ROUND_RADII[k % len(ROUND_RADII)] * 2, ROUND_RADII[(k + 3) % len(ROUND_RADII)]
        out.append((length, width, float(rng.uniform(0.0, length)) if k % 3 == 0 else None))
    return out


def states(n: int, seed: int) -> list[tuple[float, float, float]]:
    """(x, y, theta) in [-50, 50]^2 x [-pi, pi], some with special headings."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        x, y, theta = float(rng.uniform(-50, 50)), float(rng.uniform(-50, 50)), float(rng.uniform(-math.pi, math.pi))
        if k % 10 == 0:
            theta = SPECIAL_THETAS[(k // 10) % len(SPECIAL_THETAS)]
        out.append((x, y, theta))
    return out


def shapely_circle(radius: float, cx: float, cy: float):
    return shapely.Point(cx, cy).buffer(radius)


def irsim_rectangle_vertices(length: float, width: float, wheelbase: float | None) -> list[tuple[float, float]]:
    """IR-SIM's RectangleGeometry.construct_original_geometry, verbatim."""
    if wheelbase is None:
        return [(-length / 2, -width / 2), (length / 2, -width / 2), (length / 2, width / 2), (-length / 2, width / 2)]
    start_x, start_y = -(length - wheelbase) / 2, -width / 2
    return [(start_x, start_y), (start_x + length, start_y), (start_x + length, start_y + width), (start_x, start_y + width)]


def our_rectangle(length: float, width: float, wheelbase: float | None) -> np.ndarray:
    return g.rectangle_outline(length, width) if wheelbase is None else g.rectangle_outline(length, width, wheelbase)


def ring_of(polygon) -> np.ndarray:
    return np.asarray(polygon.exterior.coords)


def assert_same_ring(ours: np.ndarray, theirs: np.ndarray, what: str) -> None:
    assert ours.shape == theirs.shape, what
    assert (ours == theirs).all(), f"{what}: {np.argwhere(ours != theirs)[:4].tolist()}"


def test_circle_outline_is_shapelys_point_buffer():
    for radius, cx, cy in circles(3000, seed=1):
        assert_same_ring(g.circle_outline(radius, cx, cy), ring_of(shapely_circle(radius, cx, cy)), f"r={radius!r} c=({cx!r}, {cy!r})")
    # The default centre is IR-SIM's [0, 0]; the axis vertices are exact (GEOS snaps sin(pi) and cos(pi/2) to 0).
    ring = g.circle_outline(0.3)
    assert_same_ring(ring, ring_of(shapely.Point(0, 0).buffer(0.3)), "origin")
    assert ring[16, 0] == ring[48, 0] == ring[32, 1] == 0.0 and ring[0, 0] == 0.3


def test_rectangle_outline_is_irsims_polygon():
    for length, width, wheelbase in rectangles(2000, seed=2):
        theirs = ring_of(shapely.Polygon(irsim_rectangle_vertices(length, width, wheelbase)))
        assert_same_ring(our_rectangle(length, width, wheelbase), theirs, f"{length!r} x {width!r} wb={wheelbase!r}")
    # Wheelbase 0 is the no-wheelbase rectangle to the bit.
    assert_same_ring(g.rectangle_outline(1.3, 0.7, 0.0), ring_of(shapely.Polygon(irsim_rectangle_vertices(1.3, 0.7, None))), "wb=0")


def test_centroid_is_geos_centroid_of_transformed_circles_and_rectangles():
    for (radius, cx, cy), (x, y, theta) in zip(circles(3000, seed=3), states(3000, seed=4)):
        outline = g.circle_outline(radius, cx, cy)
        for ring in (outline, transformed(outline, x, y, theta)):
            c = shapely.Polygon(ring).centroid
            assert g.centroid(ring) == (c.x, c.y), (radius, cx, cy, x, y, theta)
        # Placed as it is read: the same bits as the placed ring's.
        assert g.centroid(outline, x, y, theta) == (c.x, c.y), (radius, cx, cy, x, y, theta)
    for (length, width, wheelbase), (x, y, theta) in zip(rectangles(3000, seed=5), states(3000, seed=6)):
        outline = our_rectangle(length, width, wheelbase)
        c = shapely.Polygon(transformed(outline, x, y, theta)).centroid
        assert g.centroid(transformed(outline, x, y, theta)) == g.centroid(outline, x, y, theta) == (c.x, c.y), \
            (length, width, wheelbase, x, y, theta)
    # The ulps are real: the origin circle's centroid is not the origin, and ours is GEOS's.
    c = shapely.Point(0, 0).buffer(1.0).centroid
    assert (c.x, c.y) != (0.0, 0.0) and g.centroid(g.circle_outline(1.0)) == (c.x, c.y)


def test_centroid_of_a_ring_without_area_is_geos_line_or_point_centroid():
    for (length, width), (x, y, theta) in zip([(1.0, 0.0), (0.0, 2.5), (0.0, 0.0), (3.7, 0.0)] * 25, states(100, seed=7)):
        ring = transformed(g.rectangle_outline(length, width), x, y, theta)
        c = shapely.Polygon(ring).centroid
        assert g.centroid(ring) == g.centroid(g.rectangle_outline(length, width), x, y, theta) == (c.x, c.y), \
            (length, width, x, y, theta)


def test_bounding_radius_is_geos_minimum_bounding_radius():
    for (radius, cx, cy), (x, y, theta) in zip(circles(1500, seed=8), states(1500, seed=9)):
        original = g.circle_outline(radius, cx, cy)
        for ring in (original, transformed(original, x, y, theta)):
            assert g.bounding_radius(ring) == shapely.minimum_bounding_radius(shapely.Polygon(ring)), (radius, cx, cy, x, y, theta)
    for (length, width, wheelbase), (x, y, theta) in zip(rectangles(1500, seed=10), states(1500, seed=11)):
        original = our_rectangle(length, width, wheelbase)
        for ring in (original, transformed(original, x, y, theta)):
            assert g.bounding_radius(ring) == shapely.minimum_bounding_radius(shapely.Polygon(ring)), (length, width, x, y, theta)
    # Not the radius itself: IR-SIM's 0.2 m robot is 0.20000000000000004 m to GEOS.
    assert g.bounding_radius(g.circle_outline(0.2)) == shapely.minimum_bounding_radius(shapely.Point(0, 0).buffer(0.2)) != 0.2


def test_transformed_is_irsims_geometry_transform_of_irsims_shapes():
    geometry_handler = optional("irsim.lib.handler.geometry_handler")
    util = optional("irsim.util.util")
    make = geometry_handler.GeometryFactory.create_geometry
    for k, ((radius, cx, cy), (x, y, theta)) in enumerate(zip(circles(600, seed=12), states(600, seed=13))):
        # IR-SIM's own circle construction, with a centre offset or a wheelbase shift.
        if k % 3 == 2:
            wheelbase = 2 * cx
            handler, ours = make("circle", radius=radius, wheelbase=wheelbase), g.circle_outline(radius, 0.0 + wheelbase / 2, 0.0)
        else:
            handler, ours = make("circle", radius=radius, center=[cx, cy]), g.circle_outline(radius, cx, cy)
        assert_same_ring(ours, ring_of(handler._original_geometry), f"circle {k}")
        assert_same_ring(transformed(ours, x, y, theta), ring_of(handler.step(np.array([[x], [y], [theta]]))), f"circle {k} moved")
    for k, ((length, width, wheelbase), (x, y, theta)) in enumerate(zip(rectangles(600, seed=14), states(600, seed=15))):
        handler = make("rectangle", length=length, width=width, wheelbase=wheelbase)
        ours = our_rectangle(length, width, wheelbase)
        assert_same_ring(ours, ring_of(handler._original_geometry), f"rectangle {k}")
        moved = util.geometry_transform(handler._original_geometry, np.array([x, y, theta]))
        assert_same_ring(transformed(ours, x, y, theta), ring_of(moved), f"rectangle {k} moved")


WORLD = """\
world: {height: 10, width: 10, step_time: 0.1}
robot:
  - kinematics: {name: diff}
    shape: {name: circle, radius: 0.2}
    state: [1, 1, 0.3]
    goal: [9, 9, 0]
    behavior: {name: dash}
obstacle:
  - shape: {name: circle, radius: 0.5}
    state: [5, 5, 0]
  - shape: {name: circle, radius: 0.3, center: [0.2, -0.1]}
    state: [2.5, 7.5, 1.0]
  - shape: {name: circle, radius: 0.35, wheelbase: 0.5}
    state: [7.5, 2.5, -2.0]
  - kinematics: {name: omni}
    shape: {name: circle, radius: 0.25}
    state: [2, 8, 0]
    goal: [8, 3, 0]
    behavior: {name: dash}
  - shape: {name: rectangle, length: 1.0, width: 0.6}
    state: [3, 7, 0.5]
  - shape: {name: rectangle, length: 1.3, width: 0.7, wheelbase: 0.9}
    state: [6, 8, 2.5]
  - kinematics: {name: diff}
    shape: {name: rectangle, length: 0.5, width: 0.3}
    state: [8, 8, -2.5]
    goal: [1, 2, 0]
    behavior: {name: dash}
"""
# Each object's shape, in the world's order (robot first): ours computes its disc from these and its state.
SHAPES = [("circle", 0.2, 0.0, 0.0), ("circle", 0.5, 0.0, 0.0), ("circle", 0.3, 0.2, -0.1), ("circle", 0.35, 0.5 / 2, 0.0),
          ("circle", 0.25, 0.0, 0.0), ("rectangle", 1.0, 0.6, None), ("rectangle", 1.3, 0.7, 0.9),
          ("rectangle", 0.5, 0.3, None)]


def test_discs_are_irsims_object_centroids_and_radii(tmp_path):
    irsim = optional("irsim")
    path = tmp_path / "world.yaml"
    path.write_text(WORLD)
    env = irsim.make(str(path), headless=True, log_level="ERROR", seed=0)
    try:
        assert len(env.objects) == len(SHAPES)
        start = [np.asarray(obj.state, dtype=float)[:3, 0].tolist() for obj in env.objects]
        for step in range(12):
            for k, (obj, (name, a, b, c)) in enumerate(zip(env.objects, SHAPES)):
                x, y, theta = np.asarray(obj.state, dtype=float)[:3, 0].tolist()
                if name == "circle":
                    disc = g.circle_disc(b, c, a, x, y, theta)
                else:
                    disc = g.rectangle_disc(a, b, x, y, theta) if c is None else g.rectangle_disc(a, b, x, y, theta, c)
                centroid = np.asarray(obj.centroid, dtype=float).reshape(-1)
                assert disc == (centroid[0], centroid[1], obj.radius), f"object {k} ({name}) at step {step}"
                assert disc[2] + 0.1 == obj.radius_extend  # the disc radius the behaviours use
            env.step()
        moved = [k for k, obj in enumerate(env.objects) if np.asarray(obj.state, dtype=float)[:3, 0].tolist() != start[k]]
        assert moved == [0, 4, 7]  # the robot and both moving obstacles
    finally:
        env.end(0)


def test_compiled_functions_give_the_python_bits():
    kernels = {
        "circle_outline": numba.njit(lambda r, cx, cy: g.circle_outline(r, cx, cy)),
        "circle_outline_origin": numba.njit(lambda r: g.circle_outline(r)),
        "rectangle_outline": numba.njit(lambda length, width: g.rectangle_outline(length, width)),
        "rectangle_outline_wheelbase": numba.njit(lambda length, width, wb: g.rectangle_outline(length, width, wb)),
        "centroid": numba.njit(lambda ring: g.centroid(ring)),
        "centroid_placed": numba.njit(lambda ring, x, y, theta: g.centroid(ring, x, y, theta)),
        "bounding_radius": numba.njit(lambda ring: g.bounding_radius(ring)),
        "circle_disc": numba.njit(lambda cx, cy, r, x, y, theta: g.circle_disc(cx, cy, r, x, y, theta)),
        "rectangle_disc": numba.njit(lambda length, width, x, y, theta, wb: g.rectangle_disc(length, width, x, y, theta, wb)),
    }
    for (radius, cx, cy), (length, width, wheelbase), (x, y, theta) in zip(circles(150, 16), rectangles(150, 17), states(150, 18)):
        wb = 0.0 if wheelbase is None else wheelbase
        circle, rectangle = g.circle_outline(radius, cx, cy), g.rectangle_outline(length, width, wb)
        moved = transformed(circle, x, y, theta)
        assert_same_ring(kernels["circle_outline"](radius, cx, cy), circle, "circle_outline")
        assert_same_ring(kernels["circle_outline_origin"](radius), g.circle_outline(radius), "circle_outline at the origin")
        assert_same_ring(kernels["rectangle_outline"](length, width), g.rectangle_outline(length, width), "rectangle_outline")
        assert_same_ring(kernels["rectangle_outline_wheelbase"](length, width, wb), rectangle, "rectangle_outline")
        for ring in (circle, moved, rectangle, transformed(rectangle, x, y, theta)):
            assert kernels["centroid"](ring) == g.centroid(ring)
            assert kernels["centroid_placed"](ring, x, y, theta) == g.centroid(ring, x, y, theta)
            assert kernels["bounding_radius"](ring) == g.bounding_radius(ring)
        assert kernels["circle_disc"](cx, cy, radius, x, y, theta) == g.circle_disc(cx, cy, radius, x, y, theta)
        assert kernels["rectangle_disc"](length, width, x, y, theta, wb) == g.rectangle_disc(length, width, x, y, theta, wb)

