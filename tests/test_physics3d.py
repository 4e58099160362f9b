"""The 3D tier: URDF, wheel tracking, sensors against geometry, collisions, twin worlds with
flatland, the env's checkers and determinism, and the GUI under Xvfb. DIRECT mode except the GUI test."""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pybullet as p
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import physics3d  # noqa: F401  (registers the env)
from common.curriculum.bench import camera_fps, physics3d_and_bare, physics3d_bench_scenario, physics3d_steps_per_s
from common.curriculum.cli import main
from common.conditions import Conditions
from common.controllers import make_controller
from common.errors import ConfigError
from common.curriculum.policy_file import save_policy
from common.evaluation import run_episode
from common.generators import generate
from common.kinematics import wrap_angle
from tests.conftest import missing
from tests.rollouts import rollout, same
from common.scenario import (BoxObstacle, CircleObstacle, LidarSpec, PolygonObstacle, RobotProfile, Scenario,
                             SegmentObstacle)
from common.tiers import make_world
from flatland.world import World as FlatWorld
from physics3d.robot import (ROBOT_COLLISION_GROUP, ROBOT_PROFILE, TEMPLATE, URDF_PATH, WHEEL_BASE, WHEEL_RADIUS,
                             Robot)
from physics3d.sensors import GRAVITY, Lidar
from physics3d.warehouse import Tag
from physics3d.world import World

OPEN = TEMPLATE.model_copy(update={"start": (5.0, 5.0, 0.0), "goal": (9.0, 9.0)})
# The robot as built: no sensor noise and none of physics3d's per-episode imperfections. The tests
# of the world's physics and sensors start from it and add the one knob they measure.
AS_BUILT = dict(lidar_noise=0.0, odometry_noise=0.0, motor_scale=(1.0, 1.0), friction=(1.0, 1.0),
                mass_scale=(1.0, 1.0), heading_source="wheels", gyro_noise=0.0, gyro_bias=0.0, accel_noise=0.0)


def as_built(**knobs) -> Conditions:
    return Conditions(**{**AS_BUILT, **knobs})


def scenario(**update) -> Scenario:
    return OPEN.model_copy(update=update)


# --- URDF and wheels ---------------------------------------------------------------------------

def test_urdf_loads_with_the_tutorials_dimensions():
    client = p.connect(p.DIRECT)
    try:
        robot = Robot(client, OPEN.start_pose)
        assert p.getDynamicsInfo(robot.id, -1, physicsClientId=client)[0] == pytest.approx(2.0)
        ys = []
        for joint in robot.wheels:
            info = p.getJointInfo(robot.id, joint, physicsClientId=client)
            assert info[2] == p.JOINT_REVOLUTE and info[8] > info[9]  # continuous: no limits (lower > upper)
            assert p.getDynamicsInfo(robot.id, joint, physicsClientId=client)[0] == pytest.approx(0.1)
            shape = p.getCollisionShapeData(robot.id, joint, physicsClientId=client)[0]
            assert shape[2] == p.GEOM_CYLINDER and shape[3][1] == pytest.approx(WHEEL_RADIUS)
            ys.append(info[14][1])
        assert abs(ys[0] - ys[1]) == pytest.approx(WHEEL_BASE)
        names = {p.getJointInfo(robot.id, j, physicsClientId=client)[12].decode()
                 for j in range(p.getNumJoints(robot.id, physicsClientId=client))}
        assert {"caster_wheel", "lidar_link", "camera_link"} <= names
    finally:
        p.disconnect(client)
    assert URDF_PATH.exists() and ROBOT_PROFILE.shape == "box" and ROBOT_PROFILE.v_max == 0.5


@pytest.mark.parametrize("v, w", [(0.5, 0.0), (0.3, 0.5), (0.2, 1.5), (0.0, -1.5), (0.5, 1.5)])
def test_wheels_track_the_commanded_velocity_within_five_percent(v, w):
    world = World(OPEN, conditions=as_built())
    world.reset(seed=0)
    for _ in range(10):  # accelerate
        world.step(v, w)
    measured = np.array([world.step(v, w).velocity for _ in range(10)]).mean(axis=0)
    for commanded, actual in zip((v, w), measured):
        assert actual == pytest.approx(commanded, rel=0.05, abs=0.005)


def test_commands_are_clipped_to_the_profile_limits():
    world = World(OPEN, conditions=as_built())
    world.reset()
    for _ in range(15):
        readings = world.step(3.0, -9.0)
    assert readings.velocity[0] == pytest.approx(0.5, rel=0.05)
    assert readings.velocity[1] == pytest.approx(-1.5, rel=0.05)


# --- lidar -------------------------------------------------------------------------------------

def _ray_box(ox: float, oy: float, angle: float, box: BoxObstacle) -> float:
    """Analytic distance along a ray to an oriented box (slab method), inf on a miss."""
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    rx, ry = ox - box.x, oy - box.y
    px, py = c * rx + s * ry, -s * rx + c * ry
    dx, dy = c * math.cos(angle) + s * math.sin(angle), -s * math.cos(angle) + c * math.sin(angle)
    near, far = -math.inf, math.inf
    for pos, d, half in ((px, dx, 0.5 * box.length), (py, dy, 0.5 * box.width)):
        if abs(d) < 1e-12:
            if abs(pos) > half:
                return math.inf
            continue
        t1, t2 = (-half - pos) / d, (half - pos) / d
        near, far = max(near, min(t1, t2)), min(far, max(t1, t2))
    return near if near <= far and near > 0 else math.inf


BOXES = [BoxObstacle(x=7.0, y=5.2, length=0.6, width=1.5), BoxObstacle(x=4.0, y=7.5, length=2.0, width=0.4, yaw=0.3),
         BoxObstacle(x=2.5, y=3.0, length=0.8, width=0.8, yaw=-0.7)]


@pytest.mark.parametrize("yaw, offset", [(0.0, (0.0, 0.0, 0.0)), (0.4, (0.1, -0.05, 0.2))])
def test_lidar_ranges_match_analytic_distances_to_placed_boxes(yaw, offset):
    lidar = LidarSpec(beams=36, range_max=5.0, offset=offset)
    unwalled = OPEN.world.model_copy(update={"walls": False})
    world = World(scenario(obstacles=BOXES, lidar=lidar, start=(5.0, 5.0, yaw), world=unwalled), conditions=as_built())
    readings = world.reset()
    x, y, heading = readings.pose
    c, s = math.cos(heading), math.sin(heading)
    ox, oy = x + c * offset[0] - s * offset[1], y + s * offset[0] + c * offset[1]
    angles = heading + lidar.beam_angles() + offset[2]
    expected = [min(min(_ray_box(ox, oy, a, box) for box in BOXES), lidar.range_max) for a in angles]
    assert readings.lidar.shape == (36,)
    np.testing.assert_allclose(readings.lidar, expected, atol=2e-3)
    assert (np.array(expected) < lidar.range_max).sum() >= 8  # the boxes are in view


def test_lidar_skips_the_robots_own_links_and_clips_with_noise():
    world = World(scenario(obstacles=BOXES[:1]), conditions=as_built())
    world.reset()
    spec = LidarSpec(beams=36, range_min=0.3, range_max=2.5, noise_std=0.05)
    # A scan plane through the middle of the body: every ray starts inside the robot's links.
    inside = Lidar(spec, world.client, 0.0, np.random.default_rng(0), ROBOT_COLLISION_GROUP)
    x, y, yaw = world.pose()
    ranges = inside.scan(x, y, world.robot.link_pose()[0][2], yaw)
    assert ranges.min() >= 0.3 and ranges.max() <= 2.5
    hits = ranges < 2.5
    assert hits.sum() >= 3  # the box 1.7 m ahead
    assert np.abs(ranges[hits] - 1.7).max() < 0.5


def test_lidar_noise_has_the_specified_spread():
    spec = LidarSpec(beams=36, range_max=5.0, noise_std=0.02)
    quiet, noisy = (World(scenario(obstacles=BOXES, lidar=spec), conditions=as_built(lidar_noise=n)) for n in (0.0, 0.02))
    truth = quiet.reset().lidar
    errors = np.concatenate([noisy.reset(seed=k).lidar - truth for k in range(20)])
    errors = errors[np.abs(errors) > 0]
    assert np.std(errors) == pytest.approx(0.02, rel=0.15)
    assert abs(np.mean(errors)) < 0.005


# --- camera and IMU ----------------------------------------------------------------------------

def test_camera_images_have_their_shapes_and_depth_in_metres():
    box = BoxObstacle(x=6.0, y=5.0, length=0.5, width=3.0, height=1.5)  # near face 0.75 m ahead of the centre
    world = World(scenario(obstacles=[box]), conditions=as_built(), camera=True)
    camera = world.reset().camera
    rgb, depth, segmentation = camera["rgb"], camera["depth"], camera["segmentation"]
    assert rgb.shape == (240, 320, 3) and rgb.dtype == np.uint8
    assert depth.shape == (240, 320) and depth.dtype == np.float32
    assert segmentation.shape == (240, 320)
    assert world.camera.near <= depth.min() and depth.max() <= world.camera.far
    assert not rgb.flags.writeable  # a snapshot
    # The camera sits 0.25 m behind the body's centre, pitched 0.3 rad down: its optical axis
    # meets the box's face 1 m ahead of it, 1 / cos(0.3) m along the axis.
    assert depth[120, 160] == pytest.approx(1.0 / math.cos(0.3), abs=0.03)
    tags = world.warehouse.tags
    assert tags[segmentation[120, 160]].kind == "obstacle"
    assert segmentation[235, 160] == world.robot.id  # the robot's own body, below and ahead of the camera


def test_imu_reads_gravity_at_rest_with_the_specified_noise():
    world = World(OPEN, seed=0, conditions=as_built(accel_noise=0.1, gyro_noise=0.02))
    world.reset(seed=0)
    imu = [world.step(0.0, 0.0).imu for _ in range(300)]
    accel = np.array([r.linear_acceleration for r in imu])
    gyro = np.array([r.angular_velocity for r in imu])
    np.testing.assert_allclose(accel.mean(axis=0), (0.0, 0.0, GRAVITY), atol=0.03)
    np.testing.assert_allclose(gyro.mean(axis=0), 0.0, atol=0.006)
    np.testing.assert_allclose(accel.std(axis=0), 0.1, rtol=0.2)
    np.testing.assert_allclose(gyro.std(axis=0), 0.02, rtol=0.2)


def test_imu_measures_turn_rate_and_centripetal_acceleration():
    world = World(OPEN, conditions=as_built())
    world.reset()
    for _ in range(15):
        world.step(0.4, 1.0)
    imu = [world.step(0.4, 1.0).imu for _ in range(10)]
    assert np.mean([r.angular_velocity[2] for r in imu]) == pytest.approx(1.0, rel=0.05)
    # Centripetal v·w toward the turn's centre, body +y (the IMU sits at the centre of mass, 4 cm
    # behind the axle, which adds w²·0.04 along x only), and gravity up.
    assert np.mean([r.linear_acceleration[1] for r in imu]) == pytest.approx(0.4, rel=0.1)
    assert np.mean([r.linear_acceleration[2] for r in imu]) == pytest.approx(GRAVITY, abs=0.05)


# --- odometry and collisions -------------------------------------------------------------------

def _curving_drive(encoder_noise: float, seed: int, **world) -> list:
    """The readings of 4.8 m of curving drive on an empty floor."""
    world = World(OPEN, conditions=as_built(odometry_noise=encoder_noise, **world))
    readings = [world.reset(seed=seed)]
    readings += [world.step(0.4, 0.6 * math.sin(0.05 * k)) for k in range(120)]
    world.close()
    return readings


def _odometry_error(noise: float, seed: int) -> float:
    end = _curving_drive(noise, seed)[-1]
    return math.dist(end.pose[:2], end.odometry.pose[:2])


def test_odometry_drift_grows_with_encoder_noise():
    drift = {noise: np.mean([_odometry_error(noise, seed) for seed in range(3)]) for noise in (0.0, 0.05, 0.2)}
    assert drift[0.0] < 0.05  # 4.8 m driven: what wheel slip alone leaves
    assert drift[0.0] < drift[0.05] < drift[0.2]


def _heading_error(heading_source: str, seed: int, **imu) -> float:
    end = _curving_drive(0.05, seed, heading_source=heading_source, **imu)[-1]
    return abs(wrap_angle(end.pose.yaw - end.odometry.pose.yaw))


def test_gyro_heading_holds_where_wheel_heading_drifts():
    wheels = np.mean([_heading_error("wheels", seed) for seed in range(3)])
    perfect = np.mean([_heading_error("gyro", seed, gyro_noise=0.0, gyro_bias=0.0) for seed in range(3)])
    noisy = [_heading_error("gyro", seed, gyro_noise=0.02, gyro_bias=0.002) for seed in range(3)]
    assert wheels > 0.05  # 5% encoder noise over 4.8 m turns the estimate by degrees
    assert perfect < 1e-6  # a perfect gyro integrated over each period is the true turn
    assert 0.0 < np.mean(noisy) < wheels / 3  # a noisy, biased gyro still holds the heading better
    assert _heading_error("gyro", 1, gyro_noise=0.02, gyro_bias=0.002) == noisy[1]


def test_the_heading_source_changes_no_other_draw():
    runs = [_curving_drive(0.05, 0, heading_source=source, gyro_bias=0.01) for source in ("wheels", "gyro")]
    for wheels, gyro in zip(*runs):
        np.testing.assert_array_equal(wheels.lidar, gyro.lidar)
        assert wheels.imu == gyro.imu and wheels.odometry.v == gyro.odometry.v
    assert runs[0][-1].odometry.pose != runs[1][-1].odometry.pose


def test_the_gyro_bias_is_drawn_per_episode_and_turns_the_estimate_at_rest():
    world = World(OPEN, conditions=as_built(gyro_bias=0.05, heading_source="gyro"))

    def drift(seed: int) -> tuple[float, float]:
        start = world.reset(seed=seed).odometry.pose.yaw
        readings = [world.step(0.0, 0.0) for _ in range(20)]
        rates = [r.imu.angular_velocity[2] for r in readings]
        return wrap_angle(readings[-1].odometry.pose.yaw - start), float(np.mean(rates))

    draws = [drift(seed) for seed in range(4)]
    for turned, rate in draws:
        assert turned == pytest.approx(rate * 2.0, abs=1e-3)  # 2 s standing still: the bias, integrated
    assert len({round(rate, 6) for _, rate in draws}) == 4 and drift(1) == draws[1]
    world.close()


def test_an_unknown_heading_source_is_refused():
    with pytest.raises(ConfigError, match="heading_source: Input should be 'wheels' or 'gyro'"):
        World(OPEN, conditions=Conditions.parse({"heading_source": "compass"}))


def test_a_graze_that_separates_within_the_control_period_is_a_collision():
    """The robot's side grazes a pillar 0.19 m off its path (0.01 m of overlap), is deflected and
    clear again before the period ends: a contact at any of the 48 sub-steps counts."""
    scenario = TEMPLATE.model_copy(update={"start": (1.0, 5.0, 0.0), "goal": (9.0, 5.0),
                                           "obstacles": [CircleObstacle(x=1.5, y=5.19, radius=0.1)]})
    world = World(scenario, conditions=as_built(control_period=0.2))
    collided = [world.step(0.5, 0.0).collided for _ in range(4)]
    assert collided == [False, False, False, True]
    assert world.touching() == []  # separated by the period's end: its last sub-step alone says "clear"



def _poll_everything(world: World, speed: float, turn_rate: float) -> tuple[list[int], int]:
    """The reference for contact polling: every body but the floor, from the first sub-step."""
    return sorted(body for body, tag in world.warehouse.tags.items() if tag.kind not in ("robot", "floor")), 0


def _near_misses(polling, monkeypatch) -> list[list[bool]]:
    """Per drive, the collided flags of its control periods, contacts polled by ``polling``: six
    0.2 s periods past a pillar that the robot's side overlaps by 1-20 mm, four 0.1 s periods
    head-on at a box from starts 1 cm apart (contact begins at every phase of a period), and six
    turning hard beside a box."""
    monkeypatch.setattr(World, "_bodies_near", polling)
    drives = [(start, CircleObstacle(x=1.5, y=5.21 - overlap, radius=0.1), 0.2, 6, 0.5, 0.0)
              for start in np.linspace(0.9, 1.05, 4) for overlap in (0.001, 0.009, 0.02)]
    drives += [(start, BoxObstacle(x=2.0, y=5.0, length=0.2, width=1.0), 0.1, 4, 0.5, 0.0)
               for start in np.linspace(1.55, 1.65, 11)]
    # Creeping while turning hard: the corners sweep into a box beside the robot far faster than it drives.
    drives += [(1.0, BoxObstacle(x=1.0 + 0.02 * k, y=5.21, length=0.3, width=0.1), 0.1, 6, 0.02, 1.5) for k in range(6)]
    runs = []
    for start, obstacle, period, steps, v, w in drives:
        world = World(TEMPLATE.model_copy(update={"start": (float(start), 5.0, 0.0), "goal": (9.0, 5.0),
                                                  "obstacles": [obstacle]}), conditions=as_built(control_period=period))
        runs.append([world.step(v, w).collided for _ in range(steps)])
        world.close()
    return runs


def test_contacts_polled_near_bodies_only_are_seen_in_the_same_period(monkeypatch):
    """Polling only the bodies within reach, from the first sub-step that could close the gap,
    sees every contact in the period that polling everything at every sub-step sees it: grazes
    that separate before the period ends, and contacts that begin at any phase of a period."""
    fast = _near_misses(World._bodies_near, monkeypatch)
    reference = _near_misses(_poll_everything, monkeypatch)
    assert fast == reference
    assert sum(any(run) for run in reference) >= 15  # the drives do touch
    assert len({run.index(True) for run in reference[12:23] if any(run)}) >= 2  # head-on: in different periods
    assert sum(any(run) for run in reference[23:]) >= 3  # the corners do sweep into the box
def test_driving_into_a_box_is_a_collision_and_the_floor_is_not():
    box = BoxObstacle(x=7.0, y=5.0, length=1.0, width=1.0)
    world = World(scenario(obstacles=[box]), conditions=as_built())
    world.reset()
    for step in range(60):
        readings = world.step(0.5, 0.0)
        if readings.collided:
            break
    # 1.35 m from the body's front to the box at 0.05 m per step.
    assert readings.collided and 25 <= step <= 28
    assert [world.warehouse.tags[body] for body in world.touching()] == [Tag("obstacle", 0)]
    assert readings.pose.x == pytest.approx(7.0 - 0.5 - 0.15, abs=0.01)


def test_walls_bound_the_world():
    world = World(scenario(start=(9.0, 5.0, 0.0), goal=(1.0, 1.0)), conditions=as_built())
    world.reset()
    collided = [world.step(0.5, 0.0).collided for _ in range(30)]
    assert any(collided) and world.warehouse.tags[world.touching()[0]].kind == "wall"
    assert world.pose().x == pytest.approx(10.0 - 0.15, abs=0.01)


# --- twin worlds -------------------------------------------------------------------------------

MIXED = scenario(
    start=(5.0, 5.0, 0.3),
    obstacles=[
        CircleObstacle(x=7.0, y=6.0, radius=0.4, height=1.0),
        BoxObstacle(x=3.0, y=3.5, length=1.2, width=0.5, yaw=0.6),
        PolygonObstacle(vertices=[(2.0, 6.0), (4.0, 6.0), (4.0, 7.0), (3.0, 7.0), (3.0, 8.5), (2.0, 8.5)]),  # an L
        SegmentObstacle(points=[(6.0, 2.0), (8.0, 2.5), (8.5, 4.0)]),
    ])


@pytest.mark.parametrize("twin", [MIXED, generate("warehouse", 0, 1.0, "eval", TEMPLATE)], ids=["mixed", "warehouse"])
def test_the_same_scenario_gives_matching_lidar_scans_in_both_tiers(twin):
    world = World(twin, conditions=as_built())
    rng = np.random.default_rng(0)
    poses = [twin.start]
    while len(poses) < 4:  # free poses: clear of every obstacle by the robot's radius
        x, y = rng.uniform(1.0, 9.0, 2)
        if twin.signed_distance(np.array([[x, y]]))[0] > 0.3:
            poses.append((float(x), float(y), float(rng.uniform(-math.pi, math.pi))))
    for pose in poses:
        placed = twin.model_copy(update={"start": pose})
        world.load(placed)
        scan3d = world.reset().lidar
        flat = FlatWorld(placed.model_copy(update={"start": tuple(world.pose())}))
        difference = np.abs(scan3d - flat.reset().lidar)
        # A 3D segment is a 2 cm thick box: its face is 1 cm nearer than the 2D line, more for a
        # beam that meets it obliquely. Everything else agrees to the millimetre.
        assert np.median(difference) < 1e-3 and difference.max() < 0.03


IRSIM_WORLD = """\
world: {height: 10, width: 10, step_time: 0.1}
robot: {kinematics: {name: diff}, shape: {name: circle, radius: 0.2}, state: [1, 1, 0.5], goal: [9, 9, 0],
        sensors: [{name: lidar2d, number: 72, range_max: 6, angle_range: 6.283}]}
obstacle:
  - {shape: {name: polygon, vertices: [[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]]}, state: [2, 2.5, 0]}
  - {shape: {name: linestring, vertices: [[0, 0], [1, 1], [2, 0.5]]}, state: [5, 1, 0]}
  - {number: 4, distribution: {name: circle, radius: 3, center: [5, 5]}, shape: {name: polygon, random_shape: true}}
"""


def test_an_irsim_world_file_is_extruded_to_the_same_layout(tmp_path):
    path = tmp_path / "world.yaml"
    path.write_text(IRSIM_WORLD)
    env = make(world=str(path), lidar_noise=0.0)  # noiseless, to compare scans with flatland
    env.reset(seed=0)
    world = env.unwrapped.world
    # IR-SIM's random polygons are not convex: each becomes several convex prisms.
    assert len(world.warehouse.bodies("obstacle")) > len(world.scenario.obstacles)
    flat = FlatWorld(world.scenario.model_copy(update={"start": tuple(world.pose())}))
    difference = np.abs(world.reset().lidar - flat.reset().lidar)
    assert world.readings.lidar.shape == (72,) and np.median(difference) < 1e-3 and difference.max() < 0.03
    env.close()


def test_every_obstacle_is_built_to_its_height_and_tagged():
    twin = generate("warehouse", 0, 1.0, "eval", TEMPLATE)
    world = World(twin)
    obstacles = world.warehouse.bodies("obstacle")
    assert len(twin.obstacles) == 31 and len(obstacles) == 31
    assert len(world.warehouse.bodies("wall")) == 4
    for body in obstacles:
        obstacle = twin.obstacles[world.warehouse.tags[body].index]
        low, high = p.getAABB(body, physicsClientId=world.client)
        assert high[2] == pytest.approx(obstacle.height, abs=0.05)
        assert low[2] == pytest.approx(0.0, abs=0.05)


# --- world API, tiers and evaluation -----------------------------------------------------------

def test_control_period_sets_the_substeps_and_time():
    world = World(OPEN, conditions=Conditions(control_period=0.05))
    world.reset()
    assert world.substeps == 12
    assert world.step(0.3, 0.0).time == pytest.approx(0.05)
    assert World(OPEN).substeps == 24


def test_reset_restores_the_start_and_same_seed_replays_the_world():
    noisy = scenario(obstacles=BOXES)
    world = World(noisy, conditions=Conditions(lidar_noise=0.05, odometry_noise=0.05))

    def episode(seed: int) -> list:
        out = [world.reset(seed=seed)]
        return out + [world.step(0.5, 0.8 * math.sin(0.1 * k)) for k in range(60)]

    first, again, other = episode(1), episode(1), episode(2)
    assert first[0].pose == pytest.approx(noisy.start, abs=2e-3) and first[0].time == 0.0
    for a, b in zip(first, again, strict=True):
        assert a.pose == b.pose and a.odometry == b.odometry and np.array_equal(a.lidar, b.lidar) and a.imu == b.imu
    assert not np.array_equal(first[10].lidar, other[10].lidar)


def test_make_world_and_a_controller_reach_the_goal_in_3d():
    world = make_world("physics3d", OPEN, seed=0)
    assert isinstance(world, World)
    episode = run_episode(make_controller("pid_blend"), OPEN, tier="physics3d", seed=0, max_steps=200)
    assert episode.outcome == "success"


def test_cli_compare_and_eval_run_in_3d(tmp_path, capsys):
    from stable_baselines3 import PPO

    assert main(["compare", "--world", "physics3d", "--suite", "open", "--episodes", "1", "--controllers", "pid_blend",
                 "--max-steps", "60", "--out", str(tmp_path / "compare"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["pid_blend"]["episodes"] == 1
    untrained = PPO("MlpPolicy", make(world=OPEN), n_steps=64, batch_size=64, device="cpu")
    manifest = {"algorithm": "ppo", "observation": "lidar43", "goal_distance_scale": 10.0}
    policy = save_policy(untrained, tmp_path / "p.zip", manifest)
    assert main(["eval", "--world", "physics3d", "--policy", str(policy), "--suite", "open", "--episodes", "2",
                 "--max-steps", "30", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["episodes"] == 2


def test_bench_measures_the_env_the_bare_loop_and_the_camera(monkeypatch):
    bench = physics3d_bench_scenario()
    assert bench.robot == ROBOT_PROFILE and len(bench.obstacles) == 31
    assert physics3d_steps_per_s(bench, steps=100) > 0
    events: list[tuple[str, int]] = []  # worlds made and reset, in order: the env's, then the bare loop's
    make, reset = World.__init__, World.reset

    def made(self, *args, **kwargs):
        make(self, *args, **kwargs)
        events.append(("made", id(self)))

    def counted(self, *args, **kwargs):
        events.append(("reset", id(self)))
        return reset(self, *args, **kwargs)

    monkeypatch.setattr(World, "__init__", made)
    monkeypatch.setattr(World, "reset", counted)
    env_rate, bare_rate = physics3d_and_bare(bench, steps=300, chunk=30)
    assert env_rate > 0 and bare_rate > 0
    # The bare loop is made once the env has warmed up and starts its episode, and replays every
    # reset the env makes from then on; it raises if its robot did not end where the env's did
    # (so it does with the env's friction draws left out of the replay).
    (_, env_world), (_, bare_world) = [event for event in events if event[0] == "made"]
    timed = events[events.index(("made", bare_world)):]
    bare, env = timed.count(("reset", bare_world)), timed.count(("reset", env_world))
    assert bare >= 2 and env == bare
    assert camera_fps(bench, frames=3) > 0


def test_a_world_disconnects_its_client_on_close():
    world = World(OPEN)
    client = world.client
    world.close()
    assert not p.isConnected(client)


# --- env ---------------------------------------------------------------------------------------

def make(**kwargs):
    return gym.make("physics3d/WarehouseNav-v0", **kwargs)


@pytest.mark.parametrize("kwargs", [{"observation": "lidar43"}, {"observation": "nav7"}, {"observation": "lidar43_log"},
                                    {"observation": "lidar43", "camera": True}],
                         ids=["lidar43", "nav7", "lidar43_log", "camera"])
def test_env_passes_gymnasium_and_sb3_checkers(kwargs):
    env = make(**kwargs)
    # The render check opens every render mode, and "human" is the GUI: tested under Xvfb below.
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=False)
    env.close()


def test_camera_observation_is_a_dict_of_state_and_images():
    env = make(world=OPEN, camera=True)
    observation, _ = env.reset(seed=0)
    assert set(observation) == {"state", "rgb", "depth"}
    assert observation["rgb"].shape == (240, 320, 3) and observation["depth"].shape == (240, 320, 1)
    assert env.observation_space.contains(observation)
    env.close()


@pytest.mark.parametrize("world", ["warehouse", scenario(obstacles=BOXES, lidar=LidarSpec(noise_std=0.05))],
                         ids=["generated", "fixed"])
def test_env_same_seed_same_episodes(world):
    env = make(world=world)
    assert same(rollout(env, 3, steps=150), rollout(env, 3, steps=150))
    assert not same(rollout(env, 3, steps=150), rollout(env, 4, steps=150))
    env.close()


def test_env_keeps_one_physics_client_across_scenarios():
    env = make(world="warehouse")
    env.reset(seed=0)
    client, first = env.unwrapped.world.client, env.unwrapped.scenario
    env.reset()
    assert env.unwrapped.scenario is not first and env.unwrapped.world.client == client
    env.close()


def test_rgb_array_render_is_a_chase_camera_frame():
    env = make(world=OPEN, render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (360, 480, 3) and frame.dtype == np.uint8 and frame.std() > 10
    env.close()


def test_the_chase_camera_stays_inside_the_walls_and_sees_the_robot():
    """`crowd`'s seed 1 starts the robot with its back to a wall: the camera behind it was outside the
    walls, and its frame showed the wall alone."""
    env = make(world="crowd", render_mode="rgb_array")
    env.reset(seed=1)
    frame = env.render().astype(int)
    env.close()
    robot_blue = (frame[..., 2] > 150) & (frame[..., 0] < 80) & (frame[..., 1] < 80)
    assert robot_blue.sum() > 500, f"{robot_blue.sum()} pixels of the robot's blue body in the frame"


def test_gui_refuses_to_open_without_a_display(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    if not sys.platform.startswith("linux"):
        pytest.skip("the display check is Linux's")
    with pytest.raises(RuntimeError, match="DISPLAY"):
        World(OPEN, gui=True)


def test_gui_refuses_a_display_that_does_not_answer():
    """A stale DISPLAY (over ssh): PyBullet's GUI ended the whole process with exit code 1."""
    if not sys.platform.startswith("linux"):
        pytest.skip("the display check is Linux's")
    script = ("from physics3d.world import World\nfrom common.scenario import Scenario\n"
              "try:\n    World(Scenario(), gui=True)\nexcept RuntimeError as error:\n    print(error)")
    result = subprocess.run([sys.executable, "-c", script], env={**os.environ, "DISPLAY": ":987"},
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-1000:]
    assert "cannot open the X display ':987' (DISPLAY); try xvfb-run" in result.stdout


def test_a_closed_world_refuses_reset_and_step_in_one_line():
    world = World(OPEN)
    world.close()
    for call in (world.reset, lambda: world.step(0.1, 0.0)):
        with pytest.raises(RuntimeError, match=r"on a closed physics3d World; make a new one"):
            call()


def test_a_robot_mapping_changes_the_3d_robot_and_a_robot_profile_is_taken_whole():
    """A mapping's unset fields came from the 2D default: {v_max: 0.3} made a 0.2 m circle turning
    at 1 rad/s, which no 3D body is, while the URDF box drove."""
    from common.robots import PROFILES

    env = gym.make("physics3d/WarehouseNav-v0", robot={"v_max": 0.3})
    # The 3D robot (the odometry_noise condition its encoders'), slower.
    assert env.unwrapped.scenario.robot == PROFILES["physics3d"].model_copy(update={"v_max": 0.3, "encoder_noise": 0.01})
    assert env.action_space.shape == (2,) and env.unwrapped.actions.w_max == 1.5
    env.close()
    whole = RobotProfile(radius=0.25)  # a profile from Python: every field as given, defaults too
    env = gym.make("physics3d/WarehouseNav-v0", robot=whole)
    assert env.unwrapped.scenario.robot == whole.model_copy(update={"encoder_noise": 0.01})
    env.close()
    import flatland  # noqa: F401  (registers its env)

    env = gym.make("flatland/Nav-v0", robot={"v_max": 0.3})  # flatland's robot is the default one
    assert env.unwrapped.scenario.robot == RobotProfile(v_max=0.3)


@pytest.mark.parametrize("robot, expected", [
    ({"v_max": 3.0}, "robot.v_max: 3 m/s; allowed in the 3D tier: at most 2"),
    ({"v_max": 2.0, "w_max": 2.5}, "robot.w_max: 2.5 rad/s at v_max 2 m/s; allowed in the 3D tier: v_max x w_max at most 4"),
])
def test_limits_the_urdf_robot_cannot_follow_are_refused(robot, expected, capsys):
    """At 3 m/s, or 2 m/s at 2.5 rad/s, its wheels slip and it spins (-9 rad/s) whatever it is told."""
    with pytest.raises(ConfigError, match=re.escape(expected)):
        gym.make("physics3d/WarehouseNav-v0", robot=robot)
    assert main(["eval", "--world", "physics3d", "--policy", str(Path(__file__).parents[1] / "curricula" / "policies" / "stage1_2d_ppo.zip"),
                 "--episodes", "1", "--env-kwargs", f"robot:{robot}"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and expected in err, (out, err)  # refused before the announcement
    gym.make("physics3d/WarehouseNav-v0", robot={"v_max": 2.0, "w_max": 2.0}).close()  # it follows these


def test_render_fps_is_the_env_s_own_rate():
    """A recorder wrote 10 frames a second whatever the control period."""
    env = gym.make("physics3d/WarehouseNav-v0", control_period=0.05)
    assert env.metadata["render_fps"] == 20.0 and type(env.unwrapped).metadata["render_fps"] == 10
    env.close()


_GUI_SMOKE = textwrap.dedent("""
    import gymnasium as gym, physics3d
    env = gym.make("physics3d/WarehouseNav-v0", render_mode="human", control_period=0.025)
    env.reset(seed=0)
    for _ in range(25):
        env.step(env.action_space.sample())
    assert env.unwrapped._overlay.frames == 26
    env.close()
    from common.generators import generate
    from physics3d.robot import TEMPLATE
    crowd = generate("crowd", 0, 0.6, "eval", TEMPLATE)  # a second GUI window, among people
    env = gym.make("physics3d/WarehouseNav-v0", world=crowd, render_mode="human")
    env.reset(seed=0)
    start = env.unwrapped.readings.movers.rows[:, :2].copy()
    for _ in range(10):
        env.step(env.action_space.sample())
    assert abs(env.unwrapped.readings.movers.rows[:, :2] - start).max() > 0.3
    env.close()
    print("gui ok")
""")


@pytest.mark.slow
def test_human_render_opens_the_gui_under_xvfb():
    if shutil.which("Xvfb") is None:
        missing("Xvfb")
    read, write = os.pipe()
    server = subprocess.Popen(["Xvfb", "-displayfd", str(write), "-screen", "0", "1024x768x24", "-nolisten", "tcp"],
                              pass_fds=(write,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(write)
    try:
        with os.fdopen(read) as pipe:
            display = pipe.readline().strip()
        assert display, "Xvfb did not report a display"
        env = {**os.environ, "DISPLAY": f":{display}"}
        result = subprocess.run([sys.executable, "-c", _GUI_SMOKE], env=env, capture_output=True, text=True, timeout=120)
        assert result.returncode == 0 and "gui ok" in result.stdout, result.stderr[-2000:]
    finally:
        server.terminate()
        server.wait(timeout=10)


@pytest.mark.parametrize("kwargs, expected", [
    ({"camera": "false"}, "camera: got 'false'; allowed: true or false"),  # a non-empty string: the camera was on
    ({"resample": "no"}, "resample: got 'no'; allowed: true or false"),
    ({"world": {"warehouse": 3, "maze": 1}}, "world: the physics3d tier does not build the 'maze' kind"),  # at make,
    ({"template": "x"}, "template: got 'x'; allowed: a Scenario"),  # not after the resets that drew it
])
def test_arguments_the_3d_env_would_misread_are_refused_at_make(kwargs, expected):
    with pytest.raises(ConfigError) as error:
        gym.make("physics3d/WarehouseNav-v0", **kwargs)
    assert str(error.value).startswith(expected), str(error.value)


def test_importing_the_tier_prints_nothing():
    """PyBullet printed its build time on stderr: a line in front of every 3D command's own output
    and of its one-line errors."""
    result = subprocess.run([sys.executable, "-c", "import physics3d"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and result.stdout == "" and result.stderr == ""


def test_a_robot_leaving_a_world_without_walls_drives_on_the_floor():
    """The floor ended a metre past the world: in a world without walls (IR-SIM's) the robot drove
    off its edge and fell for the rest of the episode, the env stepping on as if nothing happened."""
    from common.scenario import Scenario, WorldSpec

    env = gym.make("physics3d/WarehouseNav-v0", world=Scenario(world=WorldSpec(walls=False), start=(9.0, 5.0, 0.0),
                                                                goal=(5.0, 5.0)))
    env.reset(seed=0)
    world = env.unwrapped.world
    height = p.getBasePositionAndOrientation(world.robot.id, physicsClientId=world.client)[0][2]
    for _ in range(150):  # about 7 m beyond the world's edge
        env.step(np.array([1.0, 0.0], dtype=np.float32))
    (x, _, z), _ = p.getBasePositionAndOrientation(world.robot.id, physicsClientId=world.client)
    assert x > 15.0 and abs(z - height) < 0.01
    env.close()
