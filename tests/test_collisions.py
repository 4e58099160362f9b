"""Flatland collisions (IR-SIM 'stop' mode), sweeping, velocity limits and determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from common.conditions import Conditions
from common.kinematics import Pose2D, wrap_angle
from common.readings import Readings
from common.scenario import (
    BoxObstacle,
    CircleObstacle,
    LidarSpec,
    PolygonObstacle,
    RobotProfile,
    Scenario,
    SegmentObstacle,
    WorldSpec,
)
from flatland.world import World

DT = 0.1
RADIUS = 0.2  # RobotProfile's default footprint radius


def make_world(obstacles=(), start=(1.0, 5.0, 0.0), robot: RobotProfile | None = None, walls: bool = False,
               size: float = 20.0, lidar: LidarSpec | None = None, seed: int = 0) -> World:
    scenario = Scenario(
        world=WorldSpec(width=size, height=size, walls=walls, step_time=DT),
        robot=robot or RobotProfile(),
        lidar=lidar or LidarSpec(beams=8),
        start=start,
        obstacles=list(obstacles),
    )
    world = World(scenario, seed=seed)
    world.reset()
    return world


def drive_until_collision(world: World, v: float, w: float = 0.0, max_steps: int = 200) -> list[Readings]:
    """Readings of every step up to and including the first collided one (or max_steps)."""
    history = [world.readings]
    for _ in range(max_steps):
        history.append(world.step(v, w))
        if history[-1].collided:
            break
    return history


def along(pose, start) -> float:
    """Distance travelled from ``start`` along its heading."""
    return (pose[0] - start[0]) * math.cos(start[2]) + (pose[1] - start[1]) * math.sin(start[2])


def frame(start, a: float, c: float) -> tuple[float, float]:
    """World point ``a`` metres ahead of and ``c`` metres left of the pose ``start``."""
    x, y, yaw = start
    return x + a * math.cos(yaw) - c * math.sin(yaw), y + a * math.sin(yaw) + c * math.cos(yaw)


# --- stop mode --------------------------------------------------------------------------------


def test_head_on_circle_stops_at_the_touching_pose_and_stays():
    circle = CircleObstacle(x=4.0, y=5.0, radius=0.5)
    world = make_world([circle])
    history = drive_until_collision(world, v=1.0)
    hit, before = history[-1], history[-2]
    assert hit.collided and not before.collided
    contact = circle.radius + RADIUS
    gap_before = math.hypot(before.pose.x - circle.x, before.pose.y - circle.y)
    gap = math.hypot(hit.pose.x - circle.x, hit.pose.y - circle.y)
    assert gap_before >= contact
    assert contact - 1.0 * DT <= gap < contact  # touching, by at most one step's travel
    assert hit.pose.x < circle.x - circle.radius  # the centre never enters the obstacle
    for _ in range(10):
        later = world.step(1.0, 0.5)
        assert later.collided
        assert later.pose == hit.pose
        assert later.velocity == (0.0, 0.0)
        assert (later.odometry.v, later.odometry.w) == (0.0, 0.0)
    assert world.reset().collided is False
    assert world.readings.pose == world.scenario.start_pose


def test_a_robot_deep_inside_a_polygon_collides_at_its_first_move():
    """Far from every edge of a polygon it starts inside, the robot still touches it (its inside
    counts, not just its outline), as IR-SIM judges a start inside an obstacle."""
    square = PolygonObstacle(vertices=[(0.0, 2.0), (8.0, 2.0), (8.0, 8.0), (0.0, 8.0)])
    world = make_world([square], start=(4.0, 5.0, 0.0))
    assert world.step(0.5, 0.0).collided


@pytest.mark.parametrize("seed", range(3))
def test_the_clear_path_test_agrees_with_signed_distances(seed):
    """path_clear is True only when every obstacle (and a polygon's inside) lies at least
    ``radius`` from the segment, and False only when one is within it or a polygon's bounding box
    is near: moves it clears skip pymunk, so a wrong True would let a robot through an obstacle."""
    from common.geometry import box_sdf, circle_sdf, polygon_sdf, segments_distance
    from flatland.clearance import path_clear

    rng = np.random.default_rng(seed)
    triangle = PolygonObstacle(vertices=[(6.0, 6.0), (9.0, 6.5), (7.0, 9.0)])
    line = SegmentObstacle(points=[(1.0, 8.0), (3.0, 9.0), (4.0, 8.5)])
    circles = [CircleObstacle(x=x, y=y, radius=r) for x, y, r in rng.uniform([0, 0, 0.1], [10, 10, 0.8], (4, 3))]
    boxes = [BoxObstacle(x=x, y=y, length=a, width=b, yaw=t) for x, y, a, b, t in rng.uniform([0, 0, 0.2, 0.2, -3], [10, 10, 2, 1, 3], (4, 5))]
    world = make_world([*circles, *boxes, triangle, line], walls=True, size=10.0)
    lidar = world.lidar

    def nearest(points):
        return np.min([
            *(circle_sdf(points, c.x, c.y, c.radius) for c in circles),
            *(box_sdf(points, b.x, b.y, b.length, b.width, b.yaw) for b in boxes),
            polygon_sdf(points, np.array(triangle.vertices)),
            segments_distance(points, np.array(line.points[:-1]), np.array(line.points[1:])),
            segments_distance(points, lidar.segments[:4, :2], lidar.segments[:4, 2:]),
        ])

    step = 0.002
    for _ in range(1500):
        a = rng.uniform(-0.5, 10.5, 2)
        b = a + rng.uniform(-0.6, 0.6, 2) * (rng.random() < 0.8)  # a fifth of them: a point, not a segment
        radius = rng.uniform(0.05, 0.6)
        samples = a + np.linspace(0, 1, int(np.hypot(*(b - a)) / step) + 2)[:, None] * (b - a)
        sampled = nearest(samples)  # at most half a sample step above the segment's true distance
        clear = path_clear(a[0], a[1], b[0], b[1], radius, lidar.circles, lidar.boxes, lidar.segments, world._solids)
        if clear:
            assert sampled >= radius - 1e-9
        elif sampled > radius + step:
            # Only a polygon's bounding box may refuse a path that is in fact clear.
            x0, y0 = np.min(triangle.vertices, axis=0) - radius
            x1, y1 = np.max(triangle.vertices, axis=0) + radius
            assert max(x0, min(a[0], b[0])) <= min(x1, max(a[0], b[0])) and max(y0, min(a[1], b[1])) <= min(y1, max(a[1], b[1]))


def test_segment_gaps_to_boxes_and_segments_match_sampled_distances():
    """The two exact gaps path_clear is built on, against the distance of many points along the
    segment: crossing, grazing, parallel and apart, with long segments through small boxes."""
    from common.geometry import box_sdf, segments_distance
    from common.geometry import segment_box_gap, segments_gap

    rng = np.random.default_rng(0)
    for _ in range(2000):
        a, b = rng.uniform(-3, 3, 2), rng.uniform(-3, 3, 2)
        samples = a + np.linspace(0, 1, 4001)[:, None] * (b - a)
        slack = np.hypot(*(b - a)) / 4000
        x, y, length, width, yaw = rng.uniform([-1, -1, 0.1, 0.1, -3], [1, 1, 2, 2, 3])
        gap = segment_box_gap(*a, *b, x, y, math.cos(yaw), math.sin(yaw), length / 2, width / 2)
        sampled = max(box_sdf(samples, x, y, length, width, yaw).min(), 0.0)
        assert sampled - slack - 1e-9 <= gap <= sampled + 1e-9
        c, d = rng.uniform(-3, 3, 2), rng.uniform(-3, 3, 2)
        sampled = segments_distance(samples, c[None], d[None]).min()
        assert sampled - slack - 1e-9 <= segments_gap(*a, *b, *c, *d) <= sampled + 1e-9
    # A segment straight through a thin box, both ends well outside it, touches it.
    assert segment_box_gap(-1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.05, 3.0) == 0.0
    assert segments_gap(-1.0, 0.0, 1.0, 0.0, 0.0, -1.0, 0.0, 1.0) == 0.0


def test_hypot_excess_compares_with_a_reach_as_hypot_does_to_the_last_bit():
    """Decided by squares away from the edge; at the edge (a reach a few ulps either side of the
    distance, where the squares' rounding and hypot's disagree) hypot's own answer."""
    from common.geometry import hypot_excess

    rng = np.random.default_rng(0)
    checked = 0
    for dx, dy in rng.uniform(-20, 20, (3000, 2)):
        distance = math.hypot(dx, dy)
        reaches = [distance * (1 + f) for f in (-0.1, -1e-8, -1e-10, 1e-10, 1e-8, 0.1)]
        reach = distance
        for _ in range(4):
            reaches += [reach]
            reach = np.nextafter(reach, np.inf)
        reach = distance
        for _ in range(4):
            reach = np.nextafter(reach, -np.inf)
            reaches += [reach]
        for reach in reaches:
            assert np.sign(hypot_excess(dx, dy, reach)) == np.sign(distance - reach), (dx, dy, reach)
            checked += 1
    assert checked == 3000 * 14
    # Lengths whose squares underflow: the squares lose the bits, hypot does not.
    assert hypot_excess(2.7132e-162, 2.7132e-162, 3.7852e-162) > 0.0


def test_a_point_beyond_a_segments_bounds_is_beyond_the_segment_and_one_within_is_not_passed_over():
    from common.geometry import beyond_segment_bounds, segment_distance

    rng = np.random.default_rng(1)
    passed_over = 0
    for x, y, x1, y1, x2, y2, reach in rng.uniform([-5, -5, -3, -3, -3, -3, 0], [5, 5, 3, 3, 3, 3, 2], (5000, 7)):
        distance = segment_distance(x, y, x1, y1, x2, y2)
        if beyond_segment_bounds(x, y, x1, y1, x2, y2, reach):
            assert distance > reach
            passed_over += 1
        if distance <= reach:
            assert not beyond_segment_bounds(x, y, x1, y1, x2, y2, reach)
    assert 1000 < passed_over < 5000  # the test spares many, and is not everything
    # 0.5 m from an axis-aligned wall: beyond 0.49 m, not beyond 0.5 m; off its end diagonally, a
    # bounding box test cannot tell (it only ever errs toward computing the distance).
    for x, y in ((-0.5, 0.0), (10.5, 0.0), (5.0, 0.5), (5.0, -0.5)):
        assert not beyond_segment_bounds(x, y, 0.0, 0.0, 10.0, 0.0, 0.5)
        assert beyond_segment_bounds(x, y, 0.0, 0.0, 10.0, 0.0, 0.49)
    assert not beyond_segment_bounds(-0.3, 0.4, 0.0, 0.0, 10.0, 0.0, 0.49)


@pytest.mark.parametrize(("a", "b", "gap"), [
    ((0.0, 0.0, 0.0, 1.0, 1.0), (1.5, 0.0, 0.0, 1.0, 1.0), 0.5),  # side by side
    ((0.0, 0.0, 0.0, 1.0, 1.0), (0.5 + 0.3 + math.sqrt(0.5), 0.0, math.pi / 4, 1.0, 1.0), 0.3),  # a corner at a side
    ((0.0, 0.0, math.pi / 4, 1.0, 1.0), (0.0, 0.5 + 0.3 + math.sqrt(0.5), 0.0, 1.0, 1.0), 0.3),  # and the other way
    ((0.0, 0.0, 0.0, 1.0, 1.0), (1.2, 1.2, 0.0, 1.0, 1.0), 0.2 * math.sqrt(2.0)),  # corner to corner
    ((0.0, 0.0, 0.0, 1.0, 1.0), (0.9, 0.0, 0.0, 1.0, 1.0), -0.1),  # overlapping by 0.1 m
    ((0.0, 0.0, 0.0, 2.0, 2.0), (0.0, 0.0, 0.0, 0.5, 0.5), -1.25),  # one inside the other
])
def test_the_signed_gap_between_two_boxes(a, b, gap):
    from common.geometry import box_gap

    assert box_gap(a, b) == pytest.approx(gap, abs=1e-12)
    assert box_gap(b, a) == pytest.approx(gap, abs=1e-12)


def test_starting_in_contact_is_judged_after_the_first_move_as_in_irsim():
    """The start (1, 5) overlaps a circle at (1.62, 5) by 0.08 m; IR-SIM judges contact after a move."""
    circle = CircleObstacle(x=1.62, y=5.0, radius=0.5)
    facing = make_world([circle])
    assert not facing.readings.collided
    into = facing.step(1.0, 0.0)
    assert into.collided and into.pose.x == pytest.approx(1.1)
    away = make_world([circle], start=(1.0, 5.0, math.pi))
    out = away.step(1.0, 0.0)
    assert not out.collided and out.pose.x == pytest.approx(0.9)


@pytest.mark.parametrize("clearance, collides", [(0.01, False), (-0.01, True)])
def test_grazing_pass(clearance, collides):
    """Driving along y = 5 at v_max past a circle whose surface is ``clearance`` from the footprint."""
    circle = CircleObstacle(x=10.0, y=5.0 + RADIUS + 0.5 + clearance, radius=0.5)
    history = drive_until_collision(make_world([circle]), v=1.0, max_steps=150)
    assert history[-1].collided is collides
    if collides:
        assert abs(history[-1].pose.x - circle.x) < math.sqrt((RADIUS + 0.5) ** 2 - (RADIUS + 0.5 + clearance) ** 2)
    else:
        assert history[-1].pose.x > 15.0


def test_fast_grazing_overlap_is_detected():
    circle = CircleObstacle(x=10.0, y=5.24, radius=0.05)
    world = make_world([circle], start=(1.1, 5.0, 0.0), robot=RobotProfile(v_max=50.0))
    assert drive_until_collision(world, v=10.0, max_steps=15)[-1].collided


# --- tunnelling -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "obstacle, near_face",
    [
        (SegmentObstacle(points=[(5.05, 0.0), (5.05, 10.0)]), 5.05),
        (SegmentObstacle(points=[(4.93, 0.0), (4.93, 10.0)]), 4.93),
        (SegmentObstacle(points=[(6.51, 4.0), (6.51, 6.0)]), 6.51),
        (CircleObstacle(x=5.0, y=5.0, radius=0.03), 4.97),
        (BoxObstacle(x=5.5, y=5.0, length=0.02, width=3.0), 5.49),
    ],
    ids=["wall-5.05", "wall-4.93", "short-wall", "small-circle", "thin-box"],
)
def test_one_long_step_cannot_tunnel(obstacle, near_face):
    """5 m in one step (v = 50 m/s, dt = 0.1) across a thin obstacle: stopped where it first touches."""
    world = make_world([obstacle], start=(2.0, 5.0, 0.0), robot=RobotProfile(v_max=50.0))
    hit = world.step(50.0, 0.0)
    assert hit.collided
    assert hit.pose.x == pytest.approx(near_face - RADIUS, abs=1e-6)
    assert hit.pose.y == 5.0
    assert world.step(50.0, 0.0).pose == hit.pose


FAST = RobotProfile(v_max=80.0, w_max=100.0)
FAST_BOX = RobotProfile(shape="box", length=0.6, width=0.2, v_max=80.0, w_max=100.0)


@pytest.mark.parametrize("robot", [FAST, FAST_BOX], ids=["circle", "box"])
def test_a_thin_wall_before_an_obstacle_stops_the_robot_at_the_wall(robot):
    """One 6 m step whose end pose overlaps a far box: the thin wall on the way is what it hits."""
    wall = SegmentObstacle(points=[(3.0, 0.0), (3.0, 10.0)])
    far = BoxObstacle(x=8.0, y=5.0, length=1.0, width=3.0)
    world = make_world([wall, far], start=(1.5, 5.0, 0.0), robot=robot)
    hit = world.step(60.0, 0.0)
    half = robot.radius if robot.shape == "circle" else robot.length / 2
    assert hit.collided and hit.pose.x <= 3.0 - half + 1e-6 and hit.pose.x > 3.0 - half - 0.02


@pytest.mark.parametrize("integrator", ["euler", "exact"])
@pytest.mark.parametrize("angle", np.radians(np.arange(0, 180, 15)))
@pytest.mark.parametrize("robot", [FAST, FAST_BOX], ids=["circle", "box"])
def test_a_thin_wall_at_any_angle_is_never_crossed(robot, angle, integrator):
    """A zero-thickness wall through (5, 5) at ``angle``; the robot drives at it from 2 m away at up
    to 40 m/s while turning: whatever the step, it never ends on the wall's far side."""
    direction = np.array([math.cos(angle), math.sin(angle)])
    wall = SegmentObstacle(points=[tuple(np.array([5.0, 5.0]) - 4 * direction), tuple(np.array([5.0, 5.0]) + 4 * direction)])
    normal = np.array([-direction[1], direction[0]])
    start = np.array([5.0, 5.0]) - 2.0 * normal
    heading = math.atan2(normal[1], normal[0])
    for v, w in [(40.0, 0.0), (25.0, 3.0), (10.0, -20.0)]:
        scenario = Scenario(world=WorldSpec(width=20, height=20, walls=False, step_time=DT, integrator=integrator),
                            robot=robot, lidar=LidarSpec(beams=8), start=(*start, heading), obstacles=[wall])
        world = World(scenario, seed=0)
        world.reset()
        for _ in range(5):
            readings = world.step(v, w)
            side = float(np.dot(np.array(readings.pose[:2]) - np.array([5.0, 5.0]), normal))
            assert side < 0, (v, w, readings.pose)  # the centre never crosses the line
            if readings.collided:
                break
        assert readings.collided or w != 0, (v, w)  # a tight turn may circle away from the wall


def test_an_arc_is_swept_along_the_arc_not_its_chord():
    """With the exact integrator, v 10 m/s and w 20 rad/s turn 2 rad on a 0.5 m radius: the arc bulges
    to x = 5.5 (the footprint to 5.7) while the chord and end pose stay below x = 5.65."""
    wall = SegmentObstacle(points=[(5.68, 3.0), (5.68, 7.0)])
    scenario = Scenario(world=WorldSpec(width=20, height=20, walls=False, step_time=DT, integrator="exact"),
                        robot=FAST, lidar=LidarSpec(beams=8), start=(5.0, 5.0, 0.0), obstacles=[wall])
    world = World(scenario, seed=0)
    world.reset()
    assert not world.overlaps(Pose2D(5.0 + 0.5 * math.sin(2.0), 5.5 - 0.5 * math.cos(2.0), 2.0))  # the end pose
    readings = world.step(10.0, 20.0)
    assert readings.collided and readings.pose.x < 5.5


@pytest.mark.parametrize("w", [-100.0, -30.0, 30.0, 100.0])
def test_a_box_spinning_on_the_spot_next_to_a_wall_hits_it(w):
    """The box (0.6 × 0.2 m, across the wall) reaches 0.32 m from its centre with a corner; the wall
    is 0.25 m away. In one step at 30 rad/s it turns 3 rad to a pose clear of the wall again: only
    the corner's swing on the way touches it."""
    wall = SegmentObstacle(points=[(5.25, 3.0), (5.25, 7.0)])
    world = make_world([wall], start=(5.0, 5.0, math.pi / 2), robot=FAST_BOX)
    assert not world.overlaps(world.scenario.start_pose)
    assert not world.overlaps(Pose2D(5.0, 5.0, math.pi / 2 + w * DT))  # the end pose alone says "clear"
    readings = world.step(0.0, w)
    assert readings.collided
    # Halted where a corner first reached the wall: a fraction of the turn from the start.
    assert abs(wrap_angle(readings.pose.yaw - math.pi / 2)) < 0.7


# --- box footprint ----------------------------------------------------------------------------

BOX_ROBOT = RobotProfile(shape="box", length=0.6, width=0.2)


@pytest.mark.parametrize("heading", [0.0, math.pi / 2, -2.5])
def test_box_robot_nose_on_into_a_diamond(heading):
    """A unit square turned 45 deg 4 m ahead: its vertex is at 4 - sqrt(2)/2; the robot's front face,
    0.3 m ahead of its centre, reaches it after travelling 4 - sqrt(2)/2 - 0.3 m."""
    start = (10.0, 10.0, heading)
    diamond = BoxObstacle(x=frame(start, 4.0, 0.0)[0], y=frame(start, 4.0, 0.0)[1], length=1.0, width=1.0,
                          yaw=heading + math.pi / 4)
    world = make_world([diamond], start=start, robot=BOX_ROBOT)
    history = drive_until_collision(world, v=1.0)
    reach = 4.0 - math.sqrt(0.5) - 0.5 * BOX_ROBOT.length
    assert history[-1].collided
    assert reach < along(history[-1].pose, start) <= reach + DT
    assert along(history[-2].pose, start) <= reach


@pytest.mark.parametrize("heading", [0.0, math.pi / 2])
@pytest.mark.parametrize("clearance, collides", [(0.02, False), (-0.02, True)])
def test_box_robot_side_pass_by_a_rotated_box(heading, clearance, collides):
    """A 1 x 0.4 box turned 30 deg whose lowest corner is ``clearance`` from the robot's side face
    (0.1 m from its centre line). A circle of the box's bounding radius (0.32 m) would always hit it."""
    yaw = math.radians(30.0)
    corner_below_centre = 0.5 * math.sin(yaw) + 0.2 * math.cos(yaw)
    start = (10.0, 10.0, heading)
    x, y = frame(start, 4.0, 0.5 * BOX_ROBOT.width + clearance + corner_below_centre)
    box = BoxObstacle(x=x, y=y, length=1.0, width=0.4, yaw=heading + yaw)
    history = drive_until_collision(make_world([box], start=start, robot=BOX_ROBOT), v=1.0, max_steps=70)
    assert history[-1].collided is collides
    round_robot = RobotProfile(shape="circle", radius=BOX_ROBOT.bounding_radius)
    assert drive_until_collision(make_world([box], start=start, robot=round_robot), v=1.0, max_steps=70)[-1].collided


# --- walls and unobstructed obstacles ---------------------------------------------------------


@pytest.mark.parametrize("heading, wall_distance", [(0.0, 4.97), (math.pi / 2, 5.04), (math.pi, 5.03), (-math.pi / 2, 4.96)])
def test_boundary_walls_collide(heading, wall_distance):
    start = (5.03, 4.96, heading)
    world = make_world(start=start, walls=True, size=10.0)
    history = drive_until_collision(world, v=1.0)
    assert history[-1].collided
    travelled = along(history[-1].pose, start)
    assert wall_distance - RADIUS < travelled <= wall_distance - RADIUS + DT


def test_walls_off_means_no_boundary():
    world = make_world(start=(9.0, 5.0, 0.0), walls=False, size=10.0)
    history = drive_until_collision(world, v=1.0, max_steps=30)
    assert not history[-1].collided
    assert history[-1].pose.x > 11.0


def test_unobstructed_obstacles_do_not_collide():
    ghosts = [CircleObstacle(x=4.0, y=5.0, radius=0.5, unobstructed=True),
              SegmentObstacle(points=[(6.0, 0.0), (6.0, 10.0)], unobstructed=True),
              BoxObstacle(x=8.0, y=5.0, length=1.0, width=1.0, yaw=0.3, unobstructed=True)]
    world = make_world(ghosts)
    assert not world.overlaps((4.0, 5.0, 0.0))
    history = drive_until_collision(world, v=1.0, max_steps=100)
    assert not history[-1].collided
    assert history[-1].pose.x > 10.0


# --- velocity limits --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "robot, command, applied",
    [
        (RobotProfile(v_max=1.0, w_max=1.5), (5.0, -5.0), (1.0, -1.5)),
        (RobotProfile(v_max=1.0, w_max=1.5), (-1.0, 5.0), (0.0, 1.5)),
        (RobotProfile(v_max=1.0, w_max=1.5), (0.4, 0.3), (0.4, 0.3)),
        (RobotProfile(v_min=-0.5, w_max=1.5, w_min=-0.5), (-3.0, -3.0), (-0.5, -0.5)),
    ],
)
def test_velocity_clipping(robot, command, applied):
    world = make_world(start=(5.0, 5.0, 0.0), robot=robot)
    readings = world.step(*command)
    assert readings.velocity == pytest.approx(applied)
    assert_allclose(readings.pose, (5.0 + applied[0] * DT, 5.0, applied[1] * DT), atol=1e-12)  # Euler step


def test_acceleration_window():
    robot = RobotProfile(v_max=1.0, w_max=1.0, accel_v=0.5, accel_w=2.0)
    world = make_world(start=(5.0, 5.0, 0.0), robot=robot)
    speeds = np.array([world.step(1.0, 1.0).velocity for _ in range(25)])
    assert_allclose(speeds[:, 0], np.minimum(0.05 * np.arange(1, 26), 1.0), atol=1e-12)
    assert_allclose(speeds[:, 1], np.minimum(0.2 * np.arange(1, 26), 1.0), atol=1e-12)
    slowing = np.array([world.step(0.0, -1.0).velocity for _ in range(3)])
    assert_allclose(slowing, [(0.95, 0.8), (0.90, 0.6), (0.85, 0.4)], atol=1e-12)


def test_a_motor_gain_above_one_cannot_lift_the_acceleration_window_past_the_limit():
    # The window is centred on the speed the wheels delivered (1.2 m/s with a 1.2 gain), whose low
    # end then lies above v_max: the limit wins, so the command stays 1 m/s and the robot 1.2 m/s.
    scenario = Scenario(world=WorldSpec(width=40.0, height=40.0, step_time=DT), lidar=LidarSpec(beams=8),
                        robot=RobotProfile(v_max=1.0, accel_v=0.5), start=(1.0, 20.0, 0.0))
    world = World(scenario, conditions=Conditions(motor_scale=(1.2, 1.2)))
    world.reset(seed=0)
    speeds = [world.step(1.0, 0.0).velocity[0] for _ in range(40)]
    assert speeds[-1] == pytest.approx(1.2) and max(speeds) == pytest.approx(1.2)


def test_acceleration_window_moves_the_robot_by_the_applied_speed():
    world = make_world(start=(5.0, 5.0, 0.0), robot=RobotProfile(accel_v=0.5))
    xs = [world.step(1.0, 0.0).pose.x for _ in range(3)]
    assert_allclose(np.diff([5.0] + xs), [0.005, 0.010, 0.015], atol=1e-12)


# --- determinism ------------------------------------------------------------------------------


NOISY_SCENARIO_KW = dict(
    obstacles=[CircleObstacle(x=3.0, y=7.0, radius=0.6), BoxObstacle(x=7.0, y=4.0, length=1.5, width=0.8, yaw=0.4),
               SegmentObstacle(points=[(2.0, 2.0), (4.0, 3.0)])],
    start=(5.0, 5.0, 0.3),
    robot=RobotProfile(encoder_noise=0.05),
    lidar=LidarSpec(beams=90, range_max=6.0, noise_std=0.02),
    walls=True,
    size=10.0,
)


def replay(world: World, seed: int, commands: np.ndarray) -> list[Readings]:
    return [world.reset(seed=seed)] + [world.step(v, w) for v, w in commands]


def assert_same_readings(first: list[Readings], second: list[Readings]) -> None:
    assert len(first) == len(second)
    for a, b in zip(first, second):
        assert a.pose == b.pose
        assert a.velocity == b.velocity
        assert a.odometry == b.odometry
        assert a.collided == b.collided
        assert a.time == b.time
        assert_array_equal(a.lidar, b.lidar)
        assert a.contact == b.contact
        assert (a.movers is None) == (b.movers is None)
        if a.movers is not None:
            assert_array_equal(a.movers.rows, b.movers.rows)


def test_same_scenario_and_seed_give_identical_readings():
    commands = np.random.default_rng(99).uniform((-0.5, -2.0), (1.5, 2.0), size=(100, 2))
    world = make_world(**NOISY_SCENARIO_KW, seed=7)
    first = replay(world, 7, commands)
    assert_same_readings(first, replay(make_world(**NOISY_SCENARIO_KW, seed=7), 7, commands))
    assert_same_readings(first, replay(world, 7, commands))  # a reset with the seed replays too
    # The noise is really there: another seed changes both the scan and the odometry.
    other = replay(make_world(**NOISY_SCENARIO_KW, seed=8), 8, commands)
    assert not np.array_equal(first[1].lidar, other[1].lidar)
    assert first[-1].odometry != other[-1].odometry


# --- a world reused across scenarios ---------------------------------------------------------


def _space_shapes(world: World) -> list[tuple]:
    """Each static shape of the world's space (all but the robot) as its type and bounding box, sorted."""
    return sorted((type(shape).__name__, *(round(v, 9) for v in shape.cache_bb()))
                  for shape in world.space.shapes if shape.body is world.space.static_body)


def _episode(world: World, actions: np.ndarray) -> list[Readings]:
    world.reset(seed=3)
    return [world.step(v, w) for v, w in actions]


def test_a_loaded_world_drives_each_scenario_as_a_new_world_would():
    # The env reuses one World across generated scenarios, reshaping its pymunk shapes in place.
    from common.generators import generate

    polygon_world = Scenario(start=(2.0, 2.0, 0.8), goal=(8.0, 8.0), obstacles=[
        PolygonObstacle(vertices=[(4, 3), (6, 3), (6, 6), (5, 4.5), (4, 6)]),
        SegmentObstacle(points=[(3, 6), (3, 8), (5, 9)]),
        CircleObstacle(x=7, y=4, radius=0.5)])
    scenarios = [generate("warehouse", 0), generate("cluttered", 1), polygon_world, generate("sparse", 2),
                 generate("warehouse", 3), generate("open", 4)]
    rng = np.random.default_rng(0)
    reused = World(scenarios[0])
    collisions = 0
    for scenario in scenarios:
        actions = np.column_stack([rng.uniform(0.5, 1.0, 120), rng.uniform(-1.0, 1.0, 120)])
        assert reused.load(scenario)
        loaded, fresh = _episode(reused, actions), _episode(World(scenario), actions)
        for mine, theirs in zip(loaded, fresh):
            assert mine.pose == theirs.pose and mine.collided == theirs.collided
            assert_array_equal(mine.lidar, theirs.lidar)
        collisions += loaded[-1].collided
        # The pymunk space itself holds the same shapes where a new world's does (no stale ones).
        assert _space_shapes(reused) == _space_shapes(World(scenario))
    assert collisions >= 4  # most episodes end against an obstacle the load moved there


def test_a_world_loads_only_scenarios_of_its_own_robot_lidar_and_world():
    world = make_world()
    other = world.scenario.model_copy(update={"robot": RobotProfile(radius=0.3)})
    before = world.scenario
    assert not world.load(other) and world.scenario is before  # refused, and nothing changed
    assert world.load(before.model_copy(update={"obstacles": [CircleObstacle(x=3, y=3, radius=1)]}))
    assert len(world.scenario.obstacles) == 1


# --- the compiled step ------------------------------------------------------------------------


def _drive_through_crashes(world: World, commands: np.ndarray) -> list[Readings]:
    """Readings of a seeded drive that starts over after each crash."""
    readings = [world.reset(seed=5)]
    for v, w in commands:
        readings.append(world.step(v, w))
        if readings[-1].collided:
            readings.append(world.reset())
    return readings


def _drive_counting_compiled(world: World, commands: np.ndarray) -> tuple[list[Readings], int]:
    """:func:`_drive_through_crashes`, and how many of its steps the compiled path took (the
    robot's own, or with the movers' step after it)."""
    taken = 0
    compiled_step = world._free_step

    def counting(*arguments):
        nonlocal taken
        result = compiled_step(*arguments)
        taken += result is not None
        return result

    world._free_step = counting
    return _drive_through_crashes(world, commands), taken


@pytest.mark.slow
@pytest.mark.parametrize("variant", ["euler", "exact", "box_robot", "mounted_noisy_lidar", "among_movers"])
def test_the_compiled_step_drives_exactly_as_the_python_step(variant):
    # flatland.free_step does a clear move in one kernel (among movers, their step and the scan
    # too); it must give the Python path's bits.
    from common.generators import generate

    scenario = generate("cluttered", 4)
    if variant == "among_movers":  # people who walk into the robot: contacts with movers too
        scenario = generate("crowd", 0, 1.0, reacting=False)
    if variant == "exact":
        scenario = scenario.model_copy(update={"world": scenario.world.model_copy(update={"integrator": "exact"})})
    elif variant == "box_robot":
        scenario = scenario.model_copy(update={"robot": RobotProfile(shape="box", length=0.4, width=0.3)})
    elif variant == "mounted_noisy_lidar":
        lidar = scenario.lidar.model_copy(update={"offset": (0.1, -0.05, 0.3), "range_min": 0.05, "noise_std": 0.02})
        scenario = scenario.model_copy(update={"lidar": lidar})
    commands = np.random.default_rng(1).uniform((0.0, -1.0), (1.0, 1.0), size=(400, 2))
    compiled, taken = _drive_counting_compiled(World(scenario, seed=5), commands)
    python = World(scenario, seed=5)
    python._compiled = False
    assert_same_readings(compiled, _drive_through_crashes(python, commands))
    assert taken > 200  # the compiled path really drove most of it
    assert any(readings.collided for readings in compiled)  # and handed the contacts to the sweep


def test_encoder_noise_keeps_the_step_in_python_to_keep_the_draw_order():
    robot = RobotProfile(encoder_noise=0.05)
    assert not make_world(robot=robot)._compiled and make_world()._compiled
