"""The flatland lidar against analytic ranges, and the Readings snapshot it ends up in."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from common.scenario import (
    BoxObstacle,
    CircleObstacle,
    LidarSpec,
    PolygonObstacle,
    Scenario,
    SegmentObstacle,
    WorldSpec,
)
from flatland.lidar import Lidar
from flatland.world import World

RANGE_MAX = 20.0


def fan(half_angle: float, **kwargs) -> LidarSpec:
    """Three beams: -half_angle, straight ahead, +half_angle."""
    return LidarSpec(beams=3, angle_range=2.0 * half_angle, range_max=RANGE_MAX, **kwargs)


def make_lidar(spec: LidarSpec, circles=(), boxes=(), segments=(), seed: int = 0) -> Lidar:
    return Lidar(spec, np.array(circles, dtype=float), np.array(boxes, dtype=float),
                 np.array(segments, dtype=float), np.random.default_rng(seed))


def box_row(x: float, y: float, length: float, width: float, yaw: float = 0.0) -> tuple[float, ...]:
    return (x, y, math.cos(yaw), math.sin(yaw), 0.5 * length, 0.5 * width)


def make_world(obstacles=(), start=(2.0, 3.0, 0.0), walls: bool = False, seed: int = 0, **lidar) -> World:
    lidar.setdefault("range_max", RANGE_MAX)
    scenario = Scenario(world=WorldSpec(width=10.0, height=10.0, walls=walls), start=start,
                        obstacles=list(obstacles), lidar=LidarSpec(**lidar))
    world = World(scenario, seed=seed)
    world.reset()
    return world


def scan(world: World) -> np.ndarray:
    return world.readings.lidar


# --- single primitives --------------------------------------------------------------------------


@pytest.mark.parametrize("mount_x", [0.0, 0.15])
def test_circle_straight_ahead(mount_x):
    lidar = make_lidar(fan(0.1, offset=(mount_x, 0.0, 0.0)), circles=[(6.0, 1.0, 0.5)])
    ranges = lidar.scan(1.0, 1.0, 0.0)
    assert ranges[1] == pytest.approx(6.0 - 0.5 - 1.0 - mount_x, abs=1e-12)
    # The side beams hit the circle obliquely: solve |o + t d - c| = r for the nearer root.
    for angle, got in ((-0.1, ranges[0]), (0.1, ranges[2])):
        b = (mount_x - 5.0) * math.cos(angle)  # (o - c) . d with o - c = (mount_x - 5, 0)
        c = (5.0 - mount_x) ** 2 - 0.25
        assert got == pytest.approx(-b - math.sqrt(b * b - c), abs=1e-12)


def test_axis_aligned_box():
    lidar = make_lidar(fan(math.atan2(0.4, 3.0)), boxes=[box_row(4.0, 0.0, 2.0, 1.0)])
    ranges = lidar.scan(0.0, 0.0, 0.0)
    slant = math.hypot(3.0, 0.4)  # side beams reach the near face x = 3 at y = +-0.4
    assert_allclose(ranges, (slant, 3.0, slant), atol=1e-12)


def test_rotated_box():
    """A 2 x 1 box at (5, 0) turned 30 deg: the ray along +x through its centre enters through a long
    side (local y = +-0.5) at (w/2) / sin 30 = 1 m before the centre, as (w/2)/sin 30 < (l/2)/cos 30."""
    yaw = math.radians(30.0)
    assert 0.5 / math.sin(yaw) < 1.0 / math.cos(yaw)
    lidar = make_lidar(fan(0.01), boxes=[box_row(5.0, 0.0, 2.0, 1.0, yaw)])
    assert lidar.scan(0.0, 0.0, 0.0)[1] == pytest.approx(4.0, abs=1e-12)
    # From above, facing -y through the centre: a short side (local x = +-1) would be (l/2)/sin 30 = 2 m
    # before the centre, a long side (w/2)/cos 30 = 0.577 m: the ray enters through the long side.
    assert lidar.scan(5.0, 3.0, -math.pi / 2)[1] == pytest.approx(3.0 - 0.5 / math.cos(yaw), abs=1e-12)


def test_box_obstacle_through_the_world_matches():
    box = BoxObstacle(x=7.0, y=3.0, length=2.0, width=1.0, yaw=math.radians(30.0))
    world = make_world([box], start=(2.0, 3.0, 0.0), beams=3, angle_range=0.2)
    assert scan(world)[1] == pytest.approx(7.0 - 1.0 - 2.0, abs=1e-12)


def test_boundary_walls_in_an_empty_world():
    # Beams at -pi, -pi/2, 0, pi/2, pi (IR-SIM's layout) from (2, 3) facing +x in the 10 x 10 world.
    world = make_world(walls=True, start=(2.0, 3.0, 0.0), beams=5, repeat_end_beam=True)
    assert_allclose(scan(world), (2.0, 3.0, 8.0, 7.0, 2.0), atol=1e-12)


def test_no_walls_means_misses():
    world = make_world(walls=False, beams=5)
    assert_array_equal(scan(world), RANGE_MAX)


def test_walls_beyond_range_read_range_max():
    world = make_world(walls=True, start=(2.0, 3.0, 0.0), beams=5, range_max=5.0, repeat_end_beam=True)
    assert_allclose(scan(world), (2.0, 3.0, 5.0, 5.0, 2.0), atol=1e-12)


def test_concave_polygon():
    """A U open towards the robot: the middle beam goes down the notch to the inner wall x = 7,
    the side beams hit the outer face x = 5 (at y = 5 +- 0.75)."""
    u_shape = PolygonObstacle(vertices=[(5, 4), (8, 4), (8, 6), (5, 6), (5, 5.5), (7, 5.5), (7, 4.5), (5, 4.5)])
    half = math.atan2(0.75, 4.0)
    world = make_world([u_shape], start=(1.0, 5.0, 0.0), beams=3, angle_range=2.0 * half)
    slant = math.hypot(4.0, 0.75)
    assert_allclose(scan(world), (slant, 6.0, slant), atol=1e-12)


def test_segment_polyline_is_seen_from_both_sides():
    wall = SegmentObstacle(points=[(4.0, 2.0), (4.0, 6.0), (8.0, 6.0)])
    cases = [((1.0, 5.0, 0.0), 3.0),  # first piece, from the left
             ((9.0, 5.0, math.pi), 5.0),  # first piece, from the right (zero thickness, no inside)
             ((6.0, 3.0, math.pi / 2), 3.0),  # second piece, from below
             ((2.0, 7.0, 0.0), RANGE_MAX)]  # above the polyline's end: a miss
    for start, expected in cases:
        world = make_world([wall], start=start, beams=3, angle_range=0.2)
        assert scan(world)[1] == pytest.approx(expected, abs=1e-12), start


# --- mounting, beam layout, clipping ------------------------------------------------------------


def test_mounting_offset_shifts_and_rotates_the_sensor():
    # Robot at (2, 3) facing +y; sensor 0.3 ahead, 0.1 to the left, turned -90 deg: it sits at (1.9, 3.3)
    # and looks along +x, straight at a circle centred on y = 3.3.
    spec = fan(0.05, offset=(0.3, 0.1, -math.pi / 2))
    lidar = make_lidar(spec, circles=[(6.0, 3.3, 0.5)])
    assert_allclose(lidar.origin(2.0, 3.0, math.pi / 2), (1.9, 3.3), atol=1e-12)
    assert lidar.scan(2.0, 3.0, math.pi / 2)[1] == pytest.approx(6.0 - 0.5 - 1.9, abs=1e-12)
    # Without the mount yaw the middle beam looks along +y and misses.
    unturned = make_lidar(fan(0.05, offset=(0.3, 0.1, 0.0)), circles=[(6.0, 3.3, 0.5)])
    assert unturned.scan(2.0, 3.0, math.pi / 2)[1] == RANGE_MAX


@pytest.mark.parametrize("angle_range, beams, repeat", [(math.pi / 2, 7, False), (math.radians(270.0), 28, False),
                                                         (2.0 * math.pi, 36, True), (2.0 * math.pi, 36, False)])
def test_beam_angles_follow_linspace_around_the_heading(angle_range, beams, repeat):
    spec = LidarSpec(beams=beams, angle_range=angle_range, range_max=1000.0, offset=(0.0, 0.0, 0.2),
                     repeat_end_beam=repeat)
    if angle_range < 2.0 * math.pi or repeat:
        expected_relative = np.linspace(-angle_range / 2, angle_range / 2, beams)
    else:  # a full circle: evenly spaced, centred on the heading
        expected_relative = np.linspace(-math.pi, math.pi, beams, endpoint=False) + math.pi / beams
    assert_allclose(spec.beam_angles(), expected_relative, atol=0)
    # A long wall x = 10 seen from the origin with heading 0.1 (robot) + 0.2 (mount): the range of the
    # beam at world angle a is 10 / cos(a); the layout is not symmetric about the wall's normal, so a
    # reversed order, a missing heading or another spacing would read differently.
    lidar = make_lidar(spec, segments=[(10.0, -1e4, 10.0, 1e4)])
    world_angles = 0.3 + expected_relative
    cosines = np.cos(world_angles)
    distance = np.divide(10.0, cosines, out=np.full(beams, np.inf), where=cosines > 0.0)
    assert_allclose(lidar.scan(0.0, 0.0, 0.1), np.minimum(distance, 1000.0), rtol=1e-9)


def test_obstacles_behind_or_beside_the_fan_are_missed():
    lidar = make_lidar(fan(0.3), circles=[(-3.0, 0.0, 1.0), (0.0, 4.0, 1.0)], boxes=[box_row(0.0, -4.0, 1.0, 1.0)])
    assert_array_equal(lidar.scan(0.0, 0.0, 0.0), RANGE_MAX)


def test_obstacle_beyond_range_max_reads_range_max():
    lidar = make_lidar(fan(0.1).model_copy(update={"range_max": 3.0}), circles=[(5.0, 0.0, 1.0)])
    assert_array_equal(lidar.scan(0.0, 0.0, 0.0), 3.0)


def test_range_min_clips_near_returns():
    spec = fan(0.1, range_min=0.3)
    lidar = make_lidar(spec, circles=[(1.6, 0.0, 0.5)])  # the surface is 0.1 m ahead
    ranges = lidar.scan(1.0, 0.0, 0.0)
    assert ranges[1] == pytest.approx(0.3)
    assert np.all(ranges >= 0.3)


@pytest.mark.parametrize("offset", [0.0, 0.5, -1.2])
def test_sensor_inside_a_circle_reads_the_exit_distance(offset):
    lidar = make_lidar(LidarSpec(beams=5, range_max=RANGE_MAX, repeat_end_beam=True), circles=[(3.0, 3.0, 2.0)])
    ranges = lidar.scan(3.0 + offset, 3.0, 0.0)  # beams at -pi, -pi/2, 0, pi/2, pi
    side = math.sqrt(4.0 - offset**2)
    assert_allclose(ranges, (2.0 + offset, side, 2.0 - offset, side, 2.0 + offset), atol=1e-12)


def test_sensor_inside_a_box_reads_the_exit_distance():
    lidar = make_lidar(LidarSpec(beams=5, range_max=RANGE_MAX, repeat_end_beam=True), boxes=[box_row(3.0, 3.0, 4.0, 2.0)])
    assert_allclose(lidar.scan(3.5, 3.0, 0.0), (2.5, 1.0, 1.5, 1.0, 2.5), atol=1e-12)


def test_unobstructed_obstacles_are_invisible():
    hidden = [CircleObstacle(x=5.0, y=3.0, radius=0.5, unobstructed=True),
              BoxObstacle(x=2.0, y=6.0, length=1.0, width=1.0, unobstructed=True)]
    world = make_world(hidden, walls=True, start=(2.0, 3.0, 0.0), beams=5, repeat_end_beam=True)
    assert_allclose(scan(world), (2.0, 3.0, 8.0, 7.0, 2.0), atol=1e-12)
    visible = [obstacle.model_copy(update={"unobstructed": False}) for obstacle in hidden]
    seen = scan(make_world(visible, walls=True, start=(2.0, 3.0, 0.0), beams=5, repeat_end_beam=True))
    assert_allclose(seen[2:4], (2.5, 2.5), atol=1e-12)


# --- movers: circles and boxes handed over each scan ---------------------------------------------


def _movers_fan() -> Lidar:
    # Beams at -pi, -pi/2, 0, pi/2, pi; a wall 9 m to the right.
    return make_lidar(LidarSpec(beams=5, range_max=RANGE_MAX, repeat_end_beam=True), segments=[(-9.0, -9.0, 9.0, -9.0)])


def test_movers_are_seen_where_their_tables_say_now_each_scan():
    # The movers rewrite the same two arrays in place every step: each scan reads them afresh.
    lidar = _movers_fan()
    circles, boxes = np.array([[3.0, 0.0, 0.5]]), np.array([box_row(0.0, 4.0, 1.0, 1.0)])
    assert_allclose(lidar.scan(0.0, 0.0, 0.0, circles, boxes), (RANGE_MAX, 9.0, 2.5, 3.5, RANGE_MAX), atol=1e-12)
    circles[0, 0], boxes[0, 1] = 6.0, 2.0
    assert_allclose(lidar.scan(0.0, 0.0, 0.0, circles, boxes), (RANGE_MAX, 9.0, 5.5, 1.5, RANGE_MAX), atol=1e-12)


def test_movers_tables_of_any_layout_scan_as_their_float_c_order_copies():
    lidar = _movers_fan()
    wide = np.zeros((2, 6))
    wide[:, :3] = [[3.0, 0.0, 0.5], [0.0, -2.0, 0.25]]
    circles = wide[:, :3]  # a strided view: not what the compiled scan may read directly
    boxes = np.asfortranarray([box_row(0.0, 4.0, 1.0, 1.0), box_row(-5.0, 0.0, 2.0, 2.0)])
    expected = lidar.scan(0.0, 0.0, 0.0, np.ascontiguousarray(circles), np.ascontiguousarray(boxes))
    assert_array_equal(lidar.scan(0.0, 0.0, 0.0, circles, boxes), expected)
    assert_allclose(expected, (4.0, 1.75, 2.5, 3.5, 4.0), atol=1e-12)
    wide[0, 0] = 6.0  # moved through the view: a copy kept from the last scan would not see it
    assert lidar.scan(0.0, 0.0, 0.0, circles, boxes)[2] == pytest.approx(5.5)


# --- noise -------------------------------------------------------------------------------------


NOISY = LidarSpec(beams=360, range_max=10.0, noise_std=0.05)
HALF_PLANE_WALL = [(3.0, -1e4, 3.0, 1e4)]  # the line x = 3: beams looking +x hit it, the others miss


def clean_and_noisy(seed: int, scans: int) -> tuple[np.ndarray, np.ndarray]:
    clean = make_lidar(NOISY.model_copy(update={"noise_std": 0.0}), segments=HALF_PLANE_WALL).scan(0.0, 0.0, 0.0)
    noisy = make_lidar(NOISY, segments=HALF_PLANE_WALL, seed=seed)
    return clean, np.array([noisy.scan(0.0, 0.0, 0.0) for _ in range(scans)])


def test_noise_std_on_hits_and_none_on_misses():
    clean, noisy = clean_and_noisy(seed=3, scans=200)
    hits = clean < 9.0  # well inside range_max, so clipping at range_max cannot bias the spread
    misses = clean == NOISY.range_max
    assert hits.sum() > 100 and misses.sum() > 100
    errors = (noisy - clean)[:, hits]
    assert abs(errors.mean()) < 0.002
    assert errors.std() == pytest.approx(0.05, rel=0.03)
    assert_array_equal(noisy[:, misses], NOISY.range_max)


def test_same_seed_same_noisy_scan():
    _, first = clean_and_noisy(seed=11, scans=3)
    _, second = clean_and_noisy(seed=11, scans=3)
    _, other = clean_and_noisy(seed=12, scans=3)
    assert_array_equal(first, second)
    assert not np.array_equal(first, other)
    assert not np.array_equal(first[0], first[1])  # fresh noise each scan


def test_noise_never_leaves_the_clip_range():
    spec = LidarSpec(beams=64, range_min=0.2, range_max=3.0, noise_std=0.5)
    lidar = make_lidar(spec, circles=[(0.0, 0.0, 2.9)], seed=5)  # sensor inside: every beam hits at 2.9
    ranges = np.array([lidar.scan(0.0, 0.0, 0.0) for _ in range(50)])
    assert ranges.min() >= 0.2 and ranges.max() <= 3.0


# --- Readings --------------------------------------------------------------------------------


def test_readings_lidar_is_a_read_only_snapshot():
    world = make_world([CircleObstacle(x=5.0, y=3.0, radius=0.5)], walls=True, beams=8, noise_std=0.01)
    first = world.readings
    before = first.lidar.copy()
    assert not first.lidar.flags.writeable
    with pytest.raises(ValueError):
        first.lidar[0] = 0.0
    second = world.step(1.0, 0.5)
    world.step(1.0, 0.5)
    assert second.lidar is not first.lidar
    assert not np.shares_memory(second.lidar, first.lidar)
    assert_array_equal(first.lidar, before)
    assert not np.array_equal(second.lidar, before)
    with pytest.raises(AttributeError):
        first.lidar = before  # frozen dataclass


# --- brute force reference ---------------------------------------------------------------------


def reference_scan(ox: float, oy: float, angles: np.ndarray, circles, boxes, segments, range_max: float) -> np.ndarray:
    """Every beam against every primitive, boxes as their four edges (no culling, no slab test)."""
    edges = [tuple(s) for s in segments]
    for x, y, c, s, hl, hw in boxes:
        corners = [(x + c * lx - s * ly, y + s * lx + c * ly) for lx, ly in ((hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw))]
        edges += [corners[i] + corners[(i + 1) % 4] for i in range(4)]
    out = np.full(len(angles), range_max)
    for k, angle in enumerate(angles):
        d = np.array([math.cos(angle), math.sin(angle)])
        hits = []
        for cx, cy, r in circles:
            f = np.array([ox - cx, oy - cy])
            b, c = f @ d, f @ f - r * r
            if b * b - c >= 0.0:
                hits += [-b - math.sqrt(b * b - c), -b + math.sqrt(b * b - c)]
        for x1, y1, x2, y2 in edges:
            e = np.array([x2 - x1, y2 - y1])
            denom = d[0] * e[1] - d[1] * e[0]
            if denom != 0.0:
                wx, wy = x1 - ox, y1 - oy
                u = (wx * d[1] - wy * d[0]) / denom
                if 0.0 <= u <= 1.0:
                    hits.append((wx * e[1] - wy * e[0]) / denom)
        hits = [t for t in hits if t > 1e-9]
        out[k] = min([range_max] + hits)
    return out


@pytest.mark.parametrize("seed", range(12))
def test_random_scenes_match_a_brute_force_caster(seed):
    """Random primitives, poses, mounts and fans (full circle and partial, wrapping past +-pi)."""
    rng = np.random.default_rng(seed)
    circles = np.column_stack([rng.uniform(0, 10, (6, 2)), rng.uniform(0.1, 1.0, 6)])
    boxes = np.array([box_row(*rng.uniform(0, 10, 2), *rng.uniform(0.2, 2.0, 2), rng.uniform(-math.pi, math.pi))
                      for _ in range(5)])
    segments = rng.uniform(0, 10, (5, 4))
    for _ in range(10):
        spec = LidarSpec(beams=int(rng.integers(2, 200)), angle_range=float(rng.choice([2 * math.pi, rng.uniform(0.1, 6.2)])),
                         range_max=float(rng.uniform(1.0, 12.0)), offset=(*rng.uniform(-0.3, 0.3, 2), rng.uniform(-3, 3)))
        lidar = make_lidar(spec, circles, boxes, segments)
        x, y, yaw = *rng.uniform(0, 10, 2), rng.uniform(-4, 4)
        ox, oy = lidar.origin(x, y, yaw)
        angles = yaw + spec.offset[2] + spec.beam_angles()
        expected = reference_scan(ox, oy, angles, circles, boxes, segments, spec.range_max)
        assert_allclose(lidar.scan(x, y, yaw), expected, atol=1e-9)


def test_a_full_circle_reads_every_direction_once_and_irsim_files_keep_their_layout():
    import math

    from common.generators import generate

    angles = LidarSpec(beams=36).beam_angles()
    np.testing.assert_allclose(np.diff(angles), 2 * math.pi / 36)
    assert angles[0] == pytest.approx(-math.pi + math.pi / 36) and angles[-1] == pytest.approx(math.pi - math.pi / 36)
    wrapped = np.round(np.mod(angles, 2 * math.pi), 9)
    assert len(set(wrapped)) == 36  # no direction read twice
    assert np.array_equal(generate("sparse", 0).lidar.beam_angles(), angles)  # the templates' lidar
    # IR-SIM's own layout: both ends of the range, so its 360° scan repeats the ±π beam.
    irsim = LidarSpec(beams=36, repeat_end_beam=True).beam_angles()
    np.testing.assert_allclose(irsim, np.linspace(-math.pi, math.pi, 36))
    # Arcs short of a full circle keep both ends whichever layout.
    np.testing.assert_allclose(LidarSpec(beams=5, angle_range=math.pi).beam_angles(), np.linspace(-math.pi / 2, math.pi / 2, 5))
