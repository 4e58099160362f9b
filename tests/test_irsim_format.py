"""Unit tests for the IR-SIM world reader (common/irsim_format.py)."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import optional
import yaml

from common.errors import ConfigError
from common.irsim_format import ReadCache, _spaced_points, _too_close, has_random_placement, parse_irsim
from common.polygons import is_simple_polygon
from common.scenario import BoxObstacle, CircleObstacle, PolygonObstacle, SegmentObstacle
from common.yaml_io import read_yaml_mapping
from common.world_file import WorldFile, read_world_file

ROBOT = "robot:\n  kinematics: {name: diff}\n"


def load(tmp_path: Path, text: str, seed: int | None = 0, name: str = "world.yaml"):
    """Write an IR-SIM YAML fixture and parse it."""
    path = tmp_path / name
    path.write_text(text)
    return parse_irsim(read_yaml_mapping(path), source=path, seed=seed)


def error(tmp_path: Path, text: str) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        load(tmp_path, text)
    return info.value


# -- defaults ------------------------------------------------------------------------------------


def test_defaults_mirror_irsim(tmp_path):
    scenario = load(tmp_path, ROBOT)
    assert scenario.start == (1.0, 1.0, 0.0)
    assert scenario.goal == (1.0, 9.0)
    assert scenario.goal_threshold == pytest.approx(0.1)
    assert scenario.obstacles == []
    assert scenario.kind == "irsim" and scenario.name == "world" and scenario.seed is None
    world = scenario.world
    assert (world.width, world.height, world.offset, world.step_time) == (10.0, 10.0, (0.0, 0.0), 0.1)
    assert world.walls is False and world.integrator == "euler"
    robot = scenario.robot
    assert robot.shape == "circle" and robot.radius == 1.0  # no shape key: IR-SIM's radius-1 circle
    assert (robot.v_min, robot.v_max, robot.w_low, robot.w_max) == (-1.0, 1.0, -1.0, 1.0)
    assert math.isinf(robot.accel_v) and math.isinf(robot.accel_w)
    lidar = scenario.lidar  # no sensor: IR-SIM's lidar2d defaults anyway
    assert (lidar.beams, lidar.range_min, lidar.range_max, lidar.noise_std) == (100, 0.0, 10.0, 0.0)
    assert lidar.angle_range == pytest.approx(math.pi) and lidar.offset == (0.0, 0.0, 0.0)


def test_circle_shape_default_radius_and_rectangle_robot(tmp_path):
    assert load(tmp_path, ROBOT + "  shape: {name: circle}\n").robot.radius == 0.2
    robot = load(tmp_path, ROBOT + "  shape: {name: rectangle, length: 0.6, width: 0.4}\n").robot
    assert (robot.shape, robot.length, robot.width) == ("box", 0.6, 0.4)
    robot = load(tmp_path, ROBOT + "  shape: {name: rectangle}\n").robot
    assert (robot.length, robot.width) == (1.0, 1.0)


def test_robot_fields(tmp_path):
    scenario = load(tmp_path, ROBOT + """\
  state: [2, 3]
  goal: [[7, 8, 0], [1, 1, 0]]
  goal_threshold: 0.4
  vel_min: [-0.5, -2]
  vel_max: [1.5, 2]
  acce: [0.5, .inf]
  color: g
  plot: {show_trail: true}
  description: robot.png
  behavior: {name: dash}
  arrive_mode: position
  angle_range: [-3.14159, 3.14159]
world: {width: 20, height: 15, offset: [-1, -2], step_time: 0.05, sample_time: 0.1, control_mode: keyboard,
        name: lab, plot: {no_axis: true}, status: None}
gui: {keyboard: {vel_max: [1, 1]}}
custom: {anything: [1, 2]}
""")
    assert scenario.start == (2.0, 3.0, 0.0)
    assert scenario.goal == (7.0, 8.0)
    assert scenario.goal_threshold == 0.4
    robot = scenario.robot
    assert (robot.v_min, robot.v_max, robot.w_low, robot.w_max) == (-0.5, 1.5, -2.0, 2.0)
    assert robot.accel_v == 0.5 and math.isinf(robot.accel_w)
    assert (scenario.world.width, scenario.world.height, scenario.world.offset) == (20.0, 15.0, (-1.0, -2.0))
    assert scenario.world.step_time == 0.05 and scenario.name == "lab"


def test_state_is_padded_and_truncated(tmp_path):
    assert load(tmp_path, ROBOT + "  state: [4]\n").start == (4.0, 0.0, 0.0)
    assert load(tmp_path, ROBOT + "  state: [4, 5, 0.5, 9, 9]\n").start == (4.0, 5.0, 0.5)


def test_list_and_mapping_robot_agree(tmp_path):
    body = "kinematics: {name: diff}\n    shape: {name: circle, radius: 0.3}\n    state: [2, 2, 1]\n"
    as_mapping = load(tmp_path, "robot:\n    " + body, name="a.yaml")
    as_list = load(tmp_path, "robot:\n  - " + body, name="a.yaml")
    assert as_mapping == as_list


def test_further_robots_are_obstacles_that_move_as_irsims_behaviour_says(tmp_path):
    scenario = load(tmp_path, """\
robot:
  - kinematics: {name: diff}
    shape: {name: circle, radius: 0.3}
    state: [1, 1, 0]
  - kinematics: {name: omni}
    shape: {name: rectangle, length: 0.4, width: 0.2}
    state: [5, 5, 0.5]
    goal: [7, 6]
    behavior: {name: dash}
  - kinematics: {name: diff}
    shape: {name: circle, radius: 0.2}
    state: [3, 3, 0]
""")
    assert scenario.robot.radius == 0.3 and scenario.start == (1.0, 1.0, 0.0)
    box, still = scenario.obstacles
    assert isinstance(box, BoxObstacle) and (box.x, box.y, box.yaw, box.length) == (5.0, 5.0, 0.5, 0.4)
    motion = box.motion
    assert (motion.behavior.name, motion.kinematics, motion.goals, motion.role) == ("dash", "omni", [(7.0, 6.0)], "robot")
    assert still.motion is None  # no behaviour: IR-SIM leaves it where it is


def test_robot_number_expands_in_order(tmp_path):
    scenario = load(tmp_path, """\
robot:
  number: 3
  kinematics: {name: diff}
  shape: {name: circle, radius: 0.2}
  state: [[1, 1, 0], [3, 3, 0]]
""")
    assert scenario.start == (1.0, 1.0, 0.0)
    assert [(o.x, o.y) for o in scenario.obstacles] == [(3, 3), (3, 3)]  # padded with the last state


@pytest.mark.parametrize("spelling", ["name: lidar2d, ", "type: lidar2d, ", ""])
def test_sensor_named_by_name_type_or_nothing(tmp_path, spelling):
    lidar = load(tmp_path, ROBOT + f"  sensors: [{{{spelling}number: 36, range_max: 5}}]\n").lidar
    assert (lidar.beams, lidar.range_max) == (36, 5.0)


def test_first_lidar2d_sensor_is_used(tmp_path):
    lidar = load(tmp_path, ROBOT + """\
  sensors:
    - {type: contact2d}
    - {name: lidar2d, number: 20, angle_range: 7.0, range_min: 0.1, offset: [0.1, 0.05, 0.3], noise: true, std: 0.05}
    - {name: lidar2d, number: 50}
""").lidar
    assert lidar.beams == 20 and lidar.range_min == 0.1
    assert lidar.angle_range == pytest.approx(2 * math.pi)  # clipped to 2 pi, as IR-SIM does
    assert lidar.offset == (0.1, 0.05, 0.3) and lidar.noise_std == 0.05


@pytest.mark.parametrize("second, message", [("{name: lidar2d, nubmer: 10}", r"sensors\[1\]\.nubmer: unknown key"),
                                             ("{name: lidar2d, range_max: -5}", r"sensors\[1\]\.range_max: ")])
def test_every_lidar2d_is_checked_not_only_the_first(second, message, tmp_path):
    with pytest.raises(ConfigError, match=message):
        load(tmp_path, ROBOT + f"  sensors:\n    - {{name: lidar2d, number: 20}}\n    - {second}\n")


def test_lidar_noise_off_means_no_noise(tmp_path):
    assert load(tmp_path, ROBOT + "  sensors: [{std: 0.5}]\n").lidar.noise_std == 0.0


def test_single_beam_points_straight_ahead(tmp_path):
    lidar = load(tmp_path, ROBOT + "  sensors: [{number: 1, angle_range: 2.0, offset: [0, 0, 0.25]}]\n").lidar
    assert lidar.beam_angles() + lidar.offset[2] == pytest.approx([0.25])


# -- obstacles -----------------------------------------------------------------------------------


def test_a_circle_obstacle_stays_a_circle_where_irsim_places_it(tmp_path):
    (obstacle,) = load(tmp_path, ROBOT + """\
obstacle:
  - shape: {name: circle, radius: 0.5, center: [0.2, 0.1]}
    state: [3, 4, 0.7]
""").obstacles
    c, s = math.cos(0.7), math.sin(0.7)  # the body-frame centre turned by the state's yaw, then moved
    assert isinstance(obstacle, CircleObstacle) and obstacle.radius == 0.5
    assert (obstacle.x, obstacle.y) == pytest.approx((0.2 * c - 0.1 * s + 3, 0.2 * s + 0.1 * c + 4), abs=1e-12)


def test_obstacle_shapes_and_defaults(tmp_path):
    circle, box, polygon, line, default = load(tmp_path, ROBOT + """\
obstacle:
  - shape: {name: circle}
    state: [5, 5]
  - shape: {name: Rectangle, length: 2, width: 0.5}
    state: [3, 7, 0.5]
  - shape: {name: polygon, vertices: [[0, 0], [1, 0], [0, 1]]}
  - shape: {name: linestring, vertices: [[0, 0], [0, 3]]}
    state: [7, 1, 1.5707963267948966]
  - {}
""").obstacles
    assert (circle.x, circle.y, circle.radius) == (5, 5, 0.2)
    assert isinstance(box, BoxObstacle) and (box.x, box.y, box.length, box.width, box.yaw) == (3, 7, 2, 0.5, 0.5)
    np.testing.assert_allclose(polygon.vertices, [[1, 1], [2, 1], [1, 2]])  # default state [1, 1, 0]
    assert isinstance(line, SegmentObstacle)
    np.testing.assert_allclose(line.points, [[7, 1], [4, 1]], atol=1e-12)
    assert (default.x, default.y, default.radius) == (1, 1, 1.0)  # no shape: IR-SIM's circle of radius 1


def test_unobstructed_flag(tmp_path):
    a, b = load(tmp_path, ROBOT + """\
obstacle:
  - {shape: {name: circle}, state: [5, 5, 0], unobstructed: true}
  - {shape: {name: circle}, state: [6, 5, 0]}
""").obstacles
    assert a.unobstructed and not b.unobstructed


def test_self_intersecting_polygon_becomes_its_envelope(tmp_path):
    shapely = optional("shapely")
    vertices = [[0, 0], [2, 2], [2, 0], [0, 2]]  # a bow tie
    (obstacle,) = load(tmp_path, ROBOT + f"obstacle: {{shape: {{name: polygon, vertices: {vertices}}}, state: [0, 0, 0]}}\n").obstacles
    envelope = shapely.envelope(shapely.make_valid(shapely.geometry.Polygon(vertices)))
    assert shapely.geometry.Polygon(obstacle.vertices).equals(envelope)


@pytest.mark.parametrize("vertices", [
    [[0, 0], [1, 0], [1, 1], [0, 1]],
    [[0, 0], [2, 0], [2, 2], [1, 0.5], [0, 2]],
    [[0, 0], [2, 2], [2, 0], [0, 2]],
    [[0, 0], [2, 0], [1, 0], [1, 1]],
    [[0, 0], [2, 0], [2, 2], [1, 0], [0, 2]],
    [[0, 0], [1, 1], [2, 2]],
])
def test_simple_polygon_check_agrees_with_shapely(vertices):
    shapely = optional("shapely")
    assert is_simple_polygon(np.asarray(vertices, float)) == shapely.geometry.Polygon(vertices).is_valid


def test_number_with_shared_and_listed_values(tmp_path):
    obstacles = load(tmp_path, ROBOT + """\
obstacle:
  - number: 3
    shape: [{name: rectangle, length: 1, width: 1}, {name: rectangle, length: 2, width: 1}]
    state: [[1, 1, 0], [2, 2, 0], [3, 3, 0], [4, 4, 0]]
    unobstructed: true
""").obstacles
    assert [(o.x, o.length, o.unobstructed) for o in obstacles] == [(1, 1, True), (2, 2, True), (3, 2, True)]


def test_random_distribution_is_seeded(tmp_path):
    text = ROBOT + """\
obstacle:
  - number: 6
    distribution: {name: random, range_low: [2, 3, -3], range_high: [8, 9, 3], min_distance: 1.5}
    shape: {name: rectangle, length: 0.3, width: 0.3}
"""
    first, again, other = (load(tmp_path, text, seed=s) for s in (4, 4, 5))
    assert first == again and first != other and first.seed == 4
    xy = np.array([(o.x, o.y) for o in first.obstacles])
    assert np.all((xy >= [2, 3]) & (xy <= [8, 9]))
    gaps = np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1))[np.triu_indices(6, 1)]
    assert gaps.min() >= 1.5
    # IR-SIM's factory ignores non_overlapping (its env's reset API reads it): the same layout.
    ignored = text.replace("min_distance: 1.5}", "min_distance: 1.5, non_overlapping: true}")
    assert "non_overlapping" in ignored and load(tmp_path, ignored, seed=4) == first


def test_spacing_decisions_match_irsims_rule():
    """The compiled sampler keeps a candidate exactly when IR-SIM's random_uniform does: the
    np.linalg.norm of its xy difference to every placed point is at least min_distance, decided
    bit for bit even within rounding of min_distance (where hypot, say, decides differently)."""
    irsim_random = optional("irsim.util.random")
    low, high = np.array([0.0, 0.0, 0.0]), np.array([1.0, 1.0, 0.0])
    for seed, number, spacing in ((0, 12, 0.25), (1, 30, 0.12), (2, 8, 0.0), (3, 6, 2.0)):
        irsim_random.set_seed(seed)
        theirs = [irsim_random.random_uniform(low, high, (3, number), spacing).T.tolist() for _ in ("states", "goals")]
        ours, _ = _spaced_points(np.random.default_rng(seed), low, high, number, spacing, 10**9)
        assert ours.tolist() == theirs
    rng = np.random.default_rng(0)
    for spacing in (0.25, 1.0, 1.2, 0.6, 3.7):
        angles = rng.uniform(0, 2 * np.pi, 2000)
        for dx, dy in zip(spacing * np.cos(angles), spacing * np.sin(angles)):
            for x in (np.nextafter(dx, -np.inf), dx, np.nextafter(dx, np.inf)):
                # As IR-SIM computes it: np.linalg.norm(diffs, axis=0) of a (2, n) array.
                assert _too_close(x, dy, spacing) == (np.linalg.norm(np.array([[x], [dy]]), axis=0)[0] < spacing)


def test_a_world_files_seeds_share_the_reads_of_its_fixed_parts(tmp_path):
    path = tmp_path / "world.yaml"
    path.write_text(ROBOT + "  sensors: [{name: lidar2d, number: 36}]\n"
                    "obstacle:\n  - {number: 5, distribution: {name: random}, shape: {name: circle, radius: 0.2}}\n")
    file = WorldFile(path)
    one, two = file.scenario(1), file.scenario(2)
    assert one.obstacles != two.obstacles
    assert one.robot is two.robot and one.lidar is two.lidar and one.world is two.world
    assert one == parse_irsim(read_yaml_mapping(path), source=path, seed=1)  # as a parse without the cache


@pytest.mark.parametrize("key, value, read", [
    ("vel_max", [2, 1], lambda s: s.robot.v_max), ("vel_min", [0.5, -1], lambda s: s.robot.v_min),
    ("acce", [3, 4], lambda s: s.robot.accel_v), ("shape", {"name": "circle", "radius": 0.3}, lambda s: s.robot.radius),
    ("sensors", [{"name": "lidar2d", "number": 12}], lambda s: s.lidar.beams),
])
def test_the_read_cache_rereads_a_value_that_changed(key, value, read):
    """A new value object for any field a cached read depends on is read afresh (the rest of the
    file's objects unchanged, so only that field's key can tell the two apart)."""
    data = yaml.safe_load(ROBOT + "  shape: {name: circle, radius: 0.2}\n  vel_max: [1, 1]\n")
    reads = ReadCache()
    before = read(parse_irsim(data, seed=1, reads=reads))
    changed = {**data, "robot": {**data["robot"], key: value}}
    after = parse_irsim(changed, seed=1, reads=reads)
    assert read(after) != before and after == parse_irsim(changed, seed=1)
    assert read(parse_irsim(data, seed=1, reads=reads)) == before


def test_the_read_cache_follows_drawn_shapes_and_stays_bounded(monkeypatch):
    data = yaml.safe_load(ROBOT + "  shape: {name: circle, random_shape: true, radius_range: [0.1, 0.5]}\n")
    reads = ReadCache()
    radii = {parse_irsim(data, seed=seed, reads=reads).robot.radius for seed in range(5)}
    assert len(radii) == 5  # a drawn footprint is a new robot every seed, cache or not
    monkeypatch.setattr(ReadCache, "MAX_ENTRIES", 6)
    reads = ReadCache()
    for seed in range(40):
        assert parse_irsim(data, seed=seed, reads=reads) == parse_irsim(data, seed=seed)
        assert len(reads._done) <= 6


def test_random_robot_uses_world_margins(tmp_path):
    # IR-SIM draws within 0.5 m of the world's edges: 200 draws stay inside and come near both ends.
    text = ROBOT + "  distribution: {name: random}\nworld: {width: 4, height: 3, offset: [10, 20]}\n"
    starts = np.array([load(tmp_path, text, seed=seed).start for seed in range(200)])
    x, y, theta = starts.T
    assert 10.5 <= x.min() < 10.6 and 13.4 < x.max() <= 13.5 and 20.5 <= y.min() < 20.6 and 22.4 < y.max() <= 22.5
    assert np.all(np.abs(theta) <= math.pi)
    scenario = load(tmp_path, text)
    assert scenario.goal != scenario.start[:2]
    # A circle placement's default radius keeps the same margin: 3 / 2 - 0.5 about the world's centre.
    circle = load(tmp_path, ROBOT + "  distribution: {name: circle}\nworld: {width: 4, height: 3, offset: [10, 20]}\n")
    assert circle.start[:2] == pytest.approx((13.0, 21.5))


def test_circle_distribution(tmp_path):
    scenario = load(tmp_path, ROBOT + "  number: 4\n  shape: {name: circle}\n  distribution: {name: circle, radius: 2, center: [5, 5]}\n")
    assert scenario.start == pytest.approx((7.0, 5.0, -math.pi))
    assert scenario.goal == pytest.approx((3.0, 5.0))
    np.testing.assert_allclose([(o.x, o.y) for o in scenario.obstacles], [[5, 7], [3, 5], [5, 3]], atol=1e-12)


def test_random_shapes(tmp_path):
    text = ROBOT + """\
obstacle:
  - {number: 2, shape: {name: circle, random_shape: true, radius_range: [0.3, 0.4]}, state: [[2, 2], [5, 5]]}
  - {shape: {name: polygon, random_shape: true, avg_radius_range: [0.5, 0.6]}, state: [5, 2, 0]}
"""
    a, b, polygon = load(tmp_path, text, seed=1).obstacles
    for obstacle, centre in ((a, (2, 2)), (b, (5, 5))):
        assert (obstacle.x, obstacle.y) == centre and 0.3 <= obstacle.radius <= 0.4
    assert 4 <= len(polygon.vertices) < 10
    assert load(tmp_path, text, seed=1) == load(tmp_path, text, seed=1) != load(tmp_path, text, seed=2)


def test_has_random_placement():
    robot = {"kinematics": {"name": "diff"}}
    assert not has_random_placement({"robot": robot, "obstacle": [{"shape": {"name": "circle"}}]})
    assert has_random_placement({"robot": robot, "obstacle": [{"distribution": {"name": "random"}}]})
    assert has_random_placement({"robot": [{**robot, "distribution": {"name": "random"}}]})
    assert has_random_placement({"obstacle": {"shape": [{"name": "circle"}, {"name": "polygon", "random_shape": True}]}})
    assert has_random_placement({"irsim": {"obstacle": {"shape": {"name": "circle", "random_shape": True}}}})
    assert not has_random_placement({"obstacle": {"distribution": {"name": "circle"}}})
    assert not has_random_placement({"obstacle": "garbage", "robot": [3]})


def test_irsim_wrapper_and_world_file_entry_points(tmp_path):
    text = "irsim:\n  robot:\n    kinematics: {name: diff}\n    state: [2, 3, 0]\n  obstacle:\n    distribution: {name: random}\nother_simulator: {anything: 1}\n"
    path = tmp_path / "shared.yaml"
    path.write_text(text)
    scenario = read_world_file(path, seed=3)
    assert scenario.start == (2.0, 3.0, 0.0) and len(scenario.obstacles) == 1
    assert WorldFile(path).random


# -- errors --------------------------------------------------------------------------------------


ERRORS = [
    ("robots: {}\n", "robots", "unknown key (did you mean 'robot'?); allowed: world, robot, obstacle, gui, custom"),
    (ROBOT + "world: {size: 3}\n", "world.size", "unknown key; allowed: name, height"),
    (ROBOT + "world: {collision_mode: reactive}\n", "world.collision_mode", "allowed: stop"),
    (ROBOT + "world: {width: -1}\n", "world.width", "must be > 0"),
    (ROBOT + "world: {step_time: fast}\n", "world.step_time", "expected a number"),
    (ROBOT + "world: {obstacle_map: no-such-map.png}\n", "world.obstacle_map", "image 'no-such-map.png' not found"),
    (ROBOT + "world: {obstacle_map: {name: perlin, resolution: [1]}}\n", "world.obstacle_map.resolution", "expected a number"),
    (ROBOT + "world: {mdownsample: 0}\n", "world.mdownsample", "must be >= 1"),
    ("robot: {shape: {name: circle}}\n", "robot.kinematics", "allowed: {name: diff | omni"),
    ("robot: [{kinematics: {name: tank}}]\n", "robot[0].kinematics", "allowed: {name: diff | omni | omni_angular | acker}"),
    ("robot: {kinematics: {name: acker, mode: drift}}\n", "robot.kinematics.mode", "allowed: steer, angular"),
    ("robot: {kinematics: {name: acker}, state: [1, 1, 0, 0.3]}\n", "robot.state", "steering angle (state[3]) of 0"),
    ("robot: {kinematics: {name: omni_angular}, vel_max: [1, 1]}\n", "robot.vel_max", "expected a list of 3 numbers"),
    ("robot: {kinematics: {name: omni}, velocity: [0, 1]}\n", "robot.velocity", "allowed: [0, 0]"),
    ("robot: {kinematics: {name: diff, noise: true, alpha: [0.1, 0.2]}}\n", "robot.kinematics.alpha", "at least 4 numbers"),
    ("robot: {kinematics: {name: diff, noise: perhaps}}\n", "robot.kinematics.noise", "expected true or false"),
    ("robot: {kinematics: {name: diff, mode: steer}}\n", "robot.kinematics.mode", "unknown key"),
    (ROBOT + "  static: maybe\n", "robot.static", "expected true or false"),
    (ROBOT + "  velocity: [1, 0]\n", "robot.velocity", "allowed: [0, 0]"),
    (ROBOT + "  shape: {name: compound, shapes: []}\n", "robot.shape.shapes", "unknown key; allowed: name, parts"),
    (ROBOT + "  shape: {name: compound, parts: []}\n", "robot.shape.parts", "a non-empty list of part shapes"),
    (ROBOT + "  shape: {name: compound, parts: [{name: linestring}]}\n", "robot.shape.parts[0].name",
     "allowed: circle, rectangle, polygon"),
    (ROBOT + "  shape: {name: compound, parts: [{name: circle, pose: [1, x, 0]}]}\n", "robot.shape.parts[0].pose[1]",
     "expected a number"),
    (ROBOT + "  shape: {name: compound, parts: [{name: circle, random_shape: true}]}\n",
     "robot.shape.parts[0].random_shape", "unknown key"),
    (ROBOT + "  shape: {name: hexagon}\n", "robot.shape.name", "allowed: circle, rectangle, polygon, compound"),
    (ROBOT + "  shape: {name: polygon, vertices: [[0, 0], [1, 1], [1, 0], [0, 1]]}\n", "robot", "crosses itself"),
    (ROBOT + "  shape: {name: circle, center: [0.1, 0.2]}\n", "robot.shape.center", "allowed: a centre [x, 0]"),
    (ROBOT + "  shape: {name: circle, size: 1}\n", "robot.shape.size", "unknown key"),
    (ROBOT + "  colour: red\n", "robot.colour", "unknown key (did you mean 'color'?); allowed: shape, kinematics"),
    (ROBOT + "  state: here\n", "robot.state", "expected a list"),
    (ROBOT + "  state: [1, x, 0]\n", "robot.state[1]", "expected a number"),
    (ROBOT + "  goal: []\n", "robot.goal", "expected a list"),
    (ROBOT + "  goal_threshold: -1\n", "robot.goal_threshold", "must be > 0"),
    (ROBOT + "  vel_max: [0, 1]\n", "robot.vel_max", "greater than 0"),
    (ROBOT + "  vel_max: [1]\n", "robot.vel_max", "expected a list of 2 numbers"),
    (ROBOT + "  vel_min: [2, -1]\n", "robot.vel_min", "exceeds vel_max"),
    (ROBOT + "  acce: [0, 1]\n", "robot.acce", "greater than 0"),
    (ROBOT + "  sensors: {name: lidar2d}\n", "robot.sensors", "expected a list"),
    (ROBOT + "  sensors: [{name: camera}]\n", "robot.sensors[0].name", "allowed: lidar2d, fmcw_lidar2d, contact2d"),
    (ROBOT + "  sensors: [{beams: 3}]\n", "robot.sensors[0].beams", "unknown key"),
    (ROBOT + "  sensors: [{number: 0}]\n", "robot.sensors[0].number", "must be >= 1 and <= 4096"),
    (ROBOT + "  sensors: [{range_min: 5, range_max: 2}]\n", "robot.sensors[0]", "range_min"),
    (ROBOT + "  sensors: [{noise: yes please}]\n", "robot.sensors[0].noise", "expected true or false"),
    ("robot: []\n", "robot", "no robot"),
    ("world: {sample_time: 0.1}\n", "robot", "no robot"),  # IR-SIM's empty world, not a scenario's unknown key
    ("robot: {number: 0, kinematics: {name: diff}}\n", "robot", "no robot"),
    ("robot: 3\n", "robot", "expected a mapping or a list"),
    (ROBOT + "obstacle: [3]\n", "obstacle[0]", "expected a mapping"),
    (ROBOT + "obstacle: [{}, {}, {shape: {name: circle, radius: -1}}]\n", "obstacle[2].shape.radius", "must be > 0"),
    (ROBOT + "obstacle: [{shape: {name: circle, radius: big}}]\n", "obstacle[0].shape.radius", "expected a number"),
    (ROBOT + "obstacle: [{shape: {name: circle, radius: true}}]\n", "obstacle[0].shape.radius", "expected a number"),
    (ROBOT + "obstacle: [{shape: {name: triangle}}]\n", "obstacle[0].shape.name", "allowed: circle, rectangle, polygon, linestring"),
    (ROBOT + "obstacle: [{shape: {name: compound, parts: []}}]\n", "obstacle[0].shape.name", "allowed: circle"),
    (ROBOT + "obstacle: [{shape: {type: circle}}]\n", "obstacle[0].shape.type", "unknown key"),
    (ROBOT + "obstacle: [{number: 2, shape: [{name: circle}, {name: rectangle, width: 0}]}]\n", "obstacle[0].shape[1].width", "must be > 0"),
    (ROBOT + "obstacle: [{shape: {name: polygon, vertices: [[0, 0], [1, 1]]}}]\n", "obstacle[0].shape.vertices", "at least 3"),
    (ROBOT + "obstacle: [{shape: {name: polygon, vertices: [[0, 0], [1, 0], [2, 0]]}}]\n", "obstacle[0].shape.vertices", "no area"),
    (ROBOT + "obstacle: [{shape: {name: linestring}}]\n", "obstacle[0].shape.vertices", "at least 2"),
    (ROBOT + "obstacle: [{shape: {name: linestring, vertices: [[0, 0], [1]]}}]\n", "obstacle[0].shape.vertices[1]", "2 numbers"),
    (ROBOT + "obstacle: {number: -2}\n", "obstacle.number", "must be >= 0 and <= 2001"),
    (ROBOT + "obstacle: {number: 2.5}\n", "obstacle.number", "expected an integer"),
    (ROBOT + "obstacle: {distribution: {name: uniform}}\n", "obstacle.distribution.name", "allowed: manual, random, circle"),
    (ROBOT + "obstacle: {distribution: {range_low: [0, 0, 0]}}\n", "obstacle.distribution.name", "missing"),
    (ROBOT + "obstacle: {distribution: {name: random, range_low: [0, 0]}}\n", "obstacle.distribution.range_low", "at least 3"),
    (ROBOT + "obstacle: {distribution: {name: random, spread: 1}}\n", "obstacle.distribution.spread", "unknown key"),
    (ROBOT + "obstacle: {unobstructed: maybe}\n", "obstacle.unobstructed", "expected true or false"),
    (ROBOT + "obstacle: {kinematics: {name: teleport}}\n", "obstacle.kinematics.name", "allowed: diff, omni"),
    # An element out of range is named by its key and index (as IR-SIM paths are written), not its model's or its shape's.
    (ROBOT + "  state: [20000, 1, 0]\n", "robot.state[0]", "less than or equal to 10000 (got 20000.0)"),
    (ROBOT + "  sensors: [{offset: [5000, 0, 0]}]\n", "robot.sensors[0].offset[0]", "less than or equal to 1000"),
    ("world: {offset: [20000, 0]}\n" + ROBOT, "world.offset[0]", "less than or equal to 10000"),
    (ROBOT + "obstacle: [{shape: {name: circle, radius: 0.2}, state: [20000, 5, 0]}]\n", "obstacle[0].state",
     "less than or equal to 10000"),
    (ROBOT + "obstacle: {number: 2, distribution: {name: random, range_high: [50000, 50000, 0]}}\n",
     "obstacle.distribution", "less than or equal to 10000"),
    ("irsim: 3\n", "irsim", "expected a mapping"),
    ("irsim: {robot: {kinematics: {name: diff}}, extra: 1}\n", "irsim.extra", "unknown key"),
    # A behaviour's parameters were read by pydantic alone: true as 1, "0.7" as 0.7.
    (ROBOT + "obstacle: [{shape: {name: circle, radius: 0.3}, kinematics: {name: omni}, state: [5, 5, 0], "
             "goal: [6, 6, 0], behavior: {name: sfm, vmax: true}}]\n", "obstacle[0].behavior.vmax", "got true; allowed: a number"),
    (ROBOT + "obstacle: [{shape: {name: circle, radius: 0.3}, kinematics: {name: omni}, state: [5, 5, 0], "
             "goal: [6, 6, 0], behavior: {name: rvo, vxmax: '0.7'}}]\n", "obstacle[0].behavior.vxmax",
     "got '0.7' (quoted); allowed: a number"),
]


@pytest.mark.parametrize(("text", "field", "problem"), ERRORS, ids=[e[1] + ":" + e[2][:20] for e in ERRORS])
def test_malformed_input_names_the_field(tmp_path, text, field, problem):
    exc = error(tmp_path, text)
    assert exc.field == field, str(exc)
    assert problem in exc.problem, str(exc)
    message = str(exc)
    assert "\n" not in message and message.startswith(str(tmp_path / "world.yaml") + ": " + field + ": ")


def test_top_level_must_be_a_mapping():
    with pytest.raises(ConfigError, match="expected a YAML mapping"):
        parse_irsim([1, 2], source="x.yaml")


RICH = yaml.safe_load("""\
world: {height: 10, width: 10, step_time: 0.1, offset: [0, 0], collision_mode: stop}
robot:
  - kinematics: {name: diff}
    shape: {name: rectangle, length: 0.4, width: 0.3}
    state: [1, 1, 0]
    goal: [9, 9, 0]
    vel_min: [-1, -1]
    vel_max: [1, 1]
    acce: [1, 1]
    goal_threshold: 0.2
    sensors: [{name: lidar2d, number: 10, range_min: 0, range_max: 5, angle_range: 3, offset: [0, 0, 0], noise: false, std: 0.1}]
  - {kinematics: {name: diff}, number: 2, shape: {name: circle, radius: 0.2}, state: [[3, 3, 0], [4, 4, 0]]}
obstacle:
  - {shape: {name: circle, radius: 0.5, center: [0, 0]}, state: [5, 5, 0], unobstructed: false}
  - {shape: {name: rectangle, length: 1, width: 2}, state: [7, 7, 1]}
  - {shape: {name: polygon, vertices: [[0, 0], [1, 0], [0, 1]]}, state: [2, 8, 0]}
  - {shape: {name: linestring, vertices: [[0, 0], [1, 1]]}, state: [8, 2, 0]}
  - number: 3
    distribution: {name: random, range_low: [0, 0, 0], range_high: [10, 10, 3], min_distance: 1}
    shape: {name: circle, random_shape: true, radius_range: [0.1, 0.5]}
  - {number: 2, distribution: {name: circle, radius: 3, center: [5, 5]}, shape: {name: polygon, random_shape: true}}
""")


def _leaves(node, path=()):
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _leaves(value, (*path, key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from _leaves(value, (*path, i))
    yield path


def _replaced(data, path, value):
    data = copy.deepcopy(data)
    if not path:
        return value
    node = data
    for part in path[:-1]:
        node = node[part]
    node[path[-1]] = value
    return data


def test_rich_world_parses():
    scenario = parse_irsim(copy.deepcopy(RICH), "rich.yaml")
    assert len(scenario.obstacles) == 2 + 4 + 3 + 2 and scenario.robot.shape == "box"


@pytest.mark.parametrize("bad", ["x", -1, 0, None, [], {}, [1], True, float("nan"), 1e9])
def test_any_corrupted_value_gives_config_error_or_scenario(bad):
    """Whatever a single value is replaced with, the parser returns a scenario or a one-line ConfigError."""
    for path in _leaves(RICH):
        data = _replaced(RICH, path, bad)
        try:
            parse_irsim(data, "rich.yaml")
        except ConfigError as exc:
            assert "\n" not in str(exc)


def test_round_trip_through_irsim_export():
    from common.irsim_export import scenario_to_irsim
    from common.scenario import CircleObstacle, LidarSpec, RobotProfile, Scenario

    scenario = Scenario(
        robot=RobotProfile(shape="box", length=0.4, width=0.3, v_min=-0.5, v_max=1.2, w_max=2.0, accel_v=1.0, accel_w=3.0),
        lidar=LidarSpec(beams=72, range_max=6.0, angle_range=4.0, offset=(0.1, 0.0, 0.2), noise_std=0.01),
        start=(2.0, 3.0, 0.5), goal=(8.0, 7.0), goal_threshold=0.25,
        obstacles=[CircleObstacle(x=5, y=5, radius=0.4), BoxObstacle(x=3, y=7, length=1, width=0.5, yaw=0.3),
                   PolygonObstacle(vertices=[(6, 1), (7, 1), (6.5, 2)]), SegmentObstacle(points=[(1, 8), (2, 9)])],
    )
    back = parse_irsim(yaml.safe_load(yaml.safe_dump(scenario_to_irsim(scenario))), "exported.yaml")
    assert (back.robot, back.lidar, back.start, back.goal, back.goal_threshold) == (
        scenario.robot.model_copy(update={"w_min": -2.0}), scenario.lidar.model_copy(update={"repeat_end_beam": True}),
        scenario.start, scenario.goal, 0.25)
    # A full circle of evenly spaced beams leaves as IR-SIM's layout of the same directions.
    full = Scenario(lidar=LidarSpec(beams=36))
    exported = parse_irsim(yaml.safe_load(yaml.safe_dump(scenario_to_irsim(full))), "exported.yaml").lidar
    np.testing.assert_allclose(exported.beam_angles(), full.lidar.beam_angles(), atol=1e-12)
    assert back.world.walls is False and len(back.obstacles) == 5  # the walls come back as a linestring
    circle, box, polygon, segment, walls = back.obstacles
    assert (circle, box, polygon, segment) == tuple(scenario.obstacles)
    assert isinstance(walls, SegmentObstacle) and len(walls.points) == 5
