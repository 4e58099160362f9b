"""Build a scenario's static world in a PyBullet client: floor, boundary walls and obstacles.

Every obstacle is extruded to its ``height``: circles become cylinders, boxes boxes, polygons
prisms (a non-convex polygon is split into convex pieces, since Bullet collides convex shapes),
segments thin boxes. The footprints are those flatland collides with, so one scenario gives
twin worlds. Each body is tagged, so a segmentation image or a contact names what it hit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple, Sequence

import numpy as np
import pybullet as p

from flatland.polygons import convex_pieces
from common.scenario import BoxObstacle, CircleObstacle, Obstacle, PolygonObstacle, Scenario, SegmentObstacle

WALL_HEIGHT = 1.0  # m
WALL_THICKNESS = 0.1  # m, outside the world rectangle: the inner faces are flatland's boundary lines
SEGMENT_THICKNESS = 0.02  # m: a segment has no thickness in 2D; a lidar reads 1 cm short of it here
FLOOR_MARGIN = 1.0  # m of floor beyond the world rectangle
# Rubber on concrete. Bullet multiplies the two bodies' coefficients: with the tyres' 1.0 the grip
# is 1.0 (PyBullet's default 0.5 let the wheels spin at every start).
FLOOR_FRICTION = 1.0
_COLOURS = {
    "floor": (0.85, 0.85, 0.82, 1.0),
    "wall": (0.65, 0.67, 0.72, 1.0),
    "shelf": (0.80, 0.45, 0.15, 1.0),
    "crate": (0.72, 0.56, 0.36, 1.0),
    "pillar": (0.95, 0.80, 0.15, 1.0),
    "polygon": (0.45, 0.60, 0.45, 1.0),
    "segment": (0.40, 0.40, 0.45, 1.0),
    # Movers, by their label: people in purple, forklifts in red (apart from the orange shelving, the
    # yellow pillars and the blue robot), carts and the rest in greys and violets.
    "person": (0.60, 0.25, 0.80, 1.0),
    "forklift": (0.85, 0.12, 0.10, 1.0),
    "cart": (0.55, 0.55, 0.60, 1.0),
    "robot": (0.30, 0.70, 0.70, 1.0),
    "obstacle": (0.60, 0.30, 0.60, 1.0),
}
_SHELF_HEIGHT = 1.0  # m: boxes at least this tall are drawn as shelving, lower ones as crates
_GHOST_ALPHA = 0.35  # unobstructed obstacles: seen by the camera only, translucent


class Tag(NamedTuple):
    """What a body is: ``floor``, ``wall``, ``obstacle`` or ``mover`` (with its index in
    ``scenario.obstacles``; a mover also with its label: ``person``, ``forklift``, ...), or ``robot``."""

    kind: str
    index: int | None = None
    label: str | None = None


# The classes of :meth:`Warehouse.classes`, by index: what each pixel of a segmentation image shows.
SEGMENTATION_CLASSES = ("nothing", "floor", "wall", "obstacle", "robot", "person", "forklift", "cart", "moving robot",
                        "moving obstacle")
_MOVER_CLASSES = {"robot": "moving robot", "obstacle": "moving obstacle"}  # labels that name a static class too


@dataclass
class Warehouse:
    """The bodies of a built world; ``tags`` maps every body id to what it is."""

    floor: int
    tags: dict[int, Tag] = field(default_factory=dict)

    def bodies(self, kind: str) -> list[int]:
        """The ids of the bodies of one kind, in creation order."""
        return [body for body, tag in self.tags.items() if tag.kind == kind]

    def classes(self, segmentation: np.ndarray) -> np.ndarray:
        """A segmentation image of body ids as indices into :data:`SEGMENTATION_CLASSES`: a mover
        is its label (a person, a forklift), anything else its kind; pixels on nothing 0."""
        table = np.zeros(max(self.tags, default=0) + 2, dtype=np.uint8)  # the last entry: anything untagged
        for body, tag in self.tags.items():
            name = _MOVER_CLASSES.get(tag.label, tag.label) if tag.kind == "mover" else tag.kind
            table[body] = SEGMENTATION_CLASSES.index(name)
        return table[np.where((segmentation >= 0) & (segmentation < len(table) - 1), segmentation, -1)]


def build(scenario: Scenario, client: int) -> Warehouse:
    """Add the scenario's floor, walls (if ``world.walls``) and obstacles to ``client``."""
    world = scenario.world
    x0, y0 = world.offset
    centre = (x0 + 0.5 * world.width, y0 + 0.5 * world.height)
    half = (0.5 * world.width + FLOOR_MARGIN, 0.5 * world.height + FLOOR_MARGIN, 0.05)
    if world.walls:
        floor = _box(client, (centre[0], centre[1], -0.05), half, 0.0, _COLOURS["floor"])
    else:
        # Nothing keeps the robot in a world without walls (IR-SIM's): it drove off the floor's edge
        # and fell for the rest of the episode. Its floor collides as an endless plane at z = 0, as
        # flatland's has no edge; it is drawn as the walled floor is.
        plane = p.createCollisionShape(p.GEOM_PLANE, collisionFramePosition=(0.0, 0.0, 0.05), physicsClientId=client)
        visual = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=_COLOURS["floor"], physicsClientId=client)
        floor = _body(client, plane, visual, (centre[0], centre[1], -0.05), 0.0)
    p.changeDynamics(floor, -1, lateralFriction=FLOOR_FRICTION, physicsClientId=client)
    warehouse = Warehouse(floor, {floor: Tag("floor")})
    if world.walls:
        for body in _walls(client, x0, y0, world.width, world.height):
            warehouse.tags[body] = Tag("wall")
    for index, obstacle in enumerate(scenario.obstacles):
        motion = getattr(obstacle, "motion", None)
        for body in _obstacle(client, obstacle, None if motion is None else motion.label):
            warehouse.tags[body] = Tag("obstacle", index) if motion is None else Tag("mover", index, motion.label)
    return warehouse


def _walls(client: int, x0: float, y0: float, width: float, height: float) -> list[int]:
    t, h = WALL_THICKNESS, 0.5 * WALL_HEIGHT
    colour = _COLOURS["wall"]
    return [
        _box(client, (x0 + 0.5 * width, y0 - 0.5 * t, h), (0.5 * width + t, 0.5 * t, h), 0.0, colour),
        _box(client, (x0 + 0.5 * width, y0 + height + 0.5 * t, h), (0.5 * width + t, 0.5 * t, h), 0.0, colour),
        _box(client, (x0 - 0.5 * t, y0 + 0.5 * height, h), (0.5 * t, 0.5 * height, h), 0.0, colour),
        _box(client, (x0 + width + 0.5 * t, y0 + 0.5 * height, h), (0.5 * t, 0.5 * height, h), 0.0, colour),
    ]


def _obstacle(client: int, obstacle: Obstacle, label: str | None = None) -> list[int]:
    """The bodies of one obstacle (several for a segment polyline or a non-convex polygon); a mover's
    (``label``: what it is) in its label's colour, where it starts."""
    solid = not obstacle.unobstructed
    h = obstacle.height
    if isinstance(obstacle, CircleObstacle):
        r, colour = obstacle.radius, _shade(_COLOURS[label or "pillar"], solid)
        collision = p.createCollisionShape(p.GEOM_CYLINDER, radius=r, height=h, physicsClientId=client) if solid else -1
        visual = p.createVisualShape(p.GEOM_CYLINDER, radius=r, length=h, rgbaColor=colour, physicsClientId=client)
        return [_body(client, collision, visual, (obstacle.x, obstacle.y, 0.5 * h), 0.0)]
    if isinstance(obstacle, BoxObstacle):
        colour = _shade(_COLOURS[label or ("shelf" if h >= _SHELF_HEIGHT else "crate")], solid)
        return [_box(client, (obstacle.x, obstacle.y, 0.5 * h), (0.5 * obstacle.length, 0.5 * obstacle.width, 0.5 * h),
                     obstacle.yaw, colour, solid)]
    if isinstance(obstacle, PolygonObstacle):
        colour = _shade(_COLOURS["polygon"], solid)
        return [_prism(client, piece, h, colour, solid) for piece in convex_pieces(np.asarray(obstacle.vertices, float))]
    assert isinstance(obstacle, SegmentObstacle)
    colour = _shade(_COLOURS["segment"], solid)
    points = np.asarray(obstacle.points, dtype=float)
    bodies = []
    for a, b in zip(points[:-1], points[1:]):
        (mx, my), (dx, dy) = 0.5 * (a + b), b - a
        half = (0.5 * math.hypot(dx, dy), 0.5 * SEGMENT_THICKNESS, 0.5 * h)
        bodies.append(_box(client, (mx, my, 0.5 * h), half, math.atan2(dy, dx), colour, solid))
    return bodies


def _shade(colour: tuple[float, ...], solid: bool) -> tuple[float, ...]:
    return colour if solid else (*colour[:3], _GHOST_ALPHA)


def _body(client: int, collision: int, visual: int, position: Sequence[float], yaw: float) -> int:
    # A static rigid body (maximal coordinates), not a fixed-base multibody: with the warehouse's
    # 36 bodies as multibodies, every physics step was about a third slower.
    return p.createMultiBody(0.0, collision, visual, position, p.getQuaternionFromEuler((0.0, 0.0, yaw)),
                             useMaximalCoordinates=True, physicsClientId=client)


def _box(client: int, position: Sequence[float], half_extents: Sequence[float], yaw: float,
         colour: tuple[float, ...], solid: bool = True) -> int:
    collision = p.createCollisionShape(p.GEOM_BOX, halfExtents=half_extents, physicsClientId=client) if solid else -1
    visual = p.createVisualShape(p.GEOM_BOX, halfExtents=half_extents, rgbaColor=colour, physicsClientId=client)
    return _body(client, collision, visual, position, yaw)


def _prism(client: int, polygon: np.ndarray, height: float, colour: tuple[float, ...], solid: bool) -> int:
    """A convex polygon extruded from the floor to ``height``, as one static body."""
    centre = polygon.mean(axis=0)
    ring = polygon - centre  # counter-clockwise, as convex_pieces returns it
    k = len(ring)
    vertices = [(x, y, z) for z in (0.0, height) for x, y in ring]
    triangles = [(0, i + 1, i) for i in range(1, k - 1)] + [(k, k + i, k + i + 1) for i in range(1, k - 1)]
    for i in range(k):
        j = (i + 1) % k
        triangles += [(i, j, k + j), (i, k + j, k + i)]  # outward: right of each counter-clockwise edge
    indices = [index for triangle in triangles for index in triangle]
    # A mesh given by its vertices alone collides as their convex hull: the prism itself.
    collision = p.createCollisionShape(p.GEOM_MESH, vertices=vertices, physicsClientId=client) if solid else -1
    visual = p.createVisualShape(p.GEOM_MESH, vertices=vertices, indices=indices, rgbaColor=colour,
                                 physicsClientId=client)
    return _body(client, collision, visual, (centre[0], centre[1], 0.0), 0.0)
