"""Robots as a condition: a robot drawn per episode from a family (seeded, within its ranges),
each scenario generated for its robot, and the ``lidar49_robot`` layout that shows the policy
which robot it drives."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import flatland  # noqa: F401
from common.conditions import Conditions
from common.errors import ConfigError
from common.observations import make_layout, robot_entries
from common.robots import RobotFamily
from common.scenario import LidarSpec, RobotProfile


def test_a_family_draws_seeded_robots_within_its_ranges_of_both_shapes():
    family = RobotFamily()
    robots = [family.draw(np.random.default_rng([7, k])) for k in range(200)]
    again = [family.draw(np.random.default_rng([7, k])) for k in range(200)]
    assert robots == again
    circles = [r for r in robots if r.shape == "circle"]
    boxes = [r for r in robots if r.shape == "box"]
    assert 60 < len(circles) < 140 and len(circles) + len(boxes) == 200
    assert all(0.1 <= r.radius <= 0.3 for r in circles)
    assert all(0.2 <= r.length <= 0.55 and 0.2 <= r.width <= 0.45 for r in boxes)
    assert all(0.5 <= r.v_max <= 2.0 and 1.0 <= r.w_max <= 3.0 for r in robots)
    # The draws span their ranges, not one corner of them.
    assert np.ptp([r.v_max for r in robots]) > 1.2 and np.ptp([r.radius for r in circles]) > 0.15
    base = RobotProfile(accel_v=2.0, wheel_base=0.3)
    assert all(r.accel_v == 2.0 and r.wheel_base == 0.3 for r in (family.draw(np.random.default_rng(k), base)
                                                                   for k in range(5)))


@pytest.mark.parametrize(("value", "message"), [
    ({"radius": [0.3, 0.1]}, "robot_family: radius: [0.3, 0.1]; allowed: [low, high] with low <= high"),
    ({"v_max": [0.5, 50]}, "robot_family.v_max.1: Input should be less than or equal to 10"),
    ({"radius": [0.0, 0.2]}, "robot_family.radius.0: Input should be greater than 0"),
    ({"shapes": ["triangle"]}, "robot_family.shapes.0: Input should be 'circle' or 'box'"),
    ({"legs": 4}, "robot_family.legs: unknown key"),
])
def test_a_family_out_of_range_is_one_line_naming_the_field(value, message):
    with pytest.raises(ConfigError) as error:
        Conditions.parse({"robot_family": value})
    assert message in str(error.value) and "\n" not in str(error.value)


def test_a_family_and_a_robot_together_or_a_fixed_world_are_refused():
    with pytest.raises(ConfigError, match="robot and robot_family both choose the robot"):
        Conditions.parse({"robot_family": True, "robot": "physics3d"})
    with pytest.raises(ConfigError, match="robot_family: robots drawn per episode need worlds generated for them"):
        gym.make("flatland/Nav-v0", world="curricula/../README.md", robot_family=True)
    with pytest.raises(ConfigError, match="robot_family: not a physics3d knob"):
        Conditions.parse({"robot_family": True}).for_tier("physics3d")


def test_each_episode_drives_a_drawn_robot_in_a_world_laid_out_for_it_and_sees_it():
    from common.generators import generate

    def episodes(seed: int):
        env = gym.make("flatland/Nav-v0", world="passages", observation="lidar49_robot", robot_family=True)
        out = []
        for k in range(12):
            obs, info = env.reset(seed=seed + k)
            out.append((env.unwrapped.scenario, obs))
        return out

    first, again = episodes(3), episodes(3)
    robots = [scenario.robot for scenario, _ in first]
    assert robots == [scenario.robot for scenario, _ in again]
    assert len({(r.shape, r.v_max) for r in robots}) == len(robots)  # a new robot every episode
    assert {r.shape for r in robots} == {"circle", "box"}
    for scenario, obs in first:
        np.testing.assert_array_equal(obs[43:], robot_entries(scenario.robot))
        # The world was generated for this robot: the generator with it as the template draws it again.
        assert generate("passages", scenario.seed, 0.5, "train", scenario.model_copy()).obstacles == scenario.obstacles


def test_the_robot_entries_scale_its_size_limits_and_shape():
    box = RobotProfile(shape="box", length=0.51, width=0.43, v_max=2.0, w_max=1.5)
    assert make_layout("lidar49_robot", box, LidarSpec()).space.shape == (49,)
    assert robot_entries(box) == pytest.approx([box.bounding_radius / 0.5, 0.43, 0.51, 1.0, 0.5, 1.0])
    circle = RobotProfile(radius=0.1, v_max=0.5, w_max=3.0)
    assert robot_entries(circle) == pytest.approx([0.2, 0.2, 0.2, 0.25, 1.0, 0.0])


def test_a_robot_on_the_command_line_drives_instead_of_a_policys_family_and_the_other_way_round():
    from types import SimpleNamespace

    from common.curriculum.cli import _conditions

    family_policy = SimpleNamespace(trained_conditions={"robot_family": True, "lidar_beams": 360})
    args = SimpleNamespace(env_kwargs=[("robot", "physics3d")], world="flatland")
    given = _conditions(args, [family_policy]).given()
    assert given["robot"] == "physics3d" and "robot_family" not in given and given["lidar_beams"] == 360
    one_robot_policy = SimpleNamespace(trained_conditions={"robot": "physics3d"})
    args = SimpleNamespace(env_kwargs=[("robot_family", True)], world="flatland")
    given = _conditions(args, [one_robot_policy]).given()
    assert "robot" not in given and given["robot_family"]["shapes"] == ["circle", "box"]


def test_a_beam_runs_inside_the_footprint_as_far_as_its_edge():
    import math

    from common.robots import footprint_reach

    lidar = LidarSpec(beams=8)  # full circle: beams at ±22.5°, ±67.5°, ±112.5°, ±157.5°
    angles = np.abs(lidar.beam_angles())
    box = RobotProfile(shape="box", length=0.51, width=0.43)
    expected = np.minimum(0.255 / np.abs(np.cos(angles)), 0.215 / np.abs(np.sin(angles)))
    np.testing.assert_allclose(footprint_reach(box, lidar), expected)
    np.testing.assert_allclose(footprint_reach(RobotProfile(radius=0.25), lidar), 0.25)
    # A lidar mounted 0.1 m ahead: nearer the front edge, farther from the back.
    ahead = LidarSpec(beams=2, angle_range=math.pi, offset=(0.1, 0.0, 0.0))  # beams at -90° and +90°
    forward = LidarSpec(beams=1, offset=(0.1, 0.0, 0.0))
    backward = LidarSpec(beams=1, offset=(0.1, 0.0, math.pi))
    assert footprint_reach(box, forward)[0] == pytest.approx(0.155)
    assert footprint_reach(box, backward)[0] == pytest.approx(0.355)
    np.testing.assert_allclose(footprint_reach(box, ahead), 0.215)


def test_lidar49_robot_reads_the_clearance_from_the_footprint_not_the_range():
    """A box 0.51 x 0.43 m with a wall 5 cm off its left side and 0.5 m ahead of its front: the
    left sector reads log(2) / log(101) (5 cm of clearance), the front one log(11) / log(101)."""
    import math

    from common.kinematics import Pose2D
    from common.readings import Imu, Odometry, Readings

    box = RobotProfile(shape="box", length=0.51, width=0.43)
    lidar = LidarSpec(beams=360)
    angles = lidar.beam_angles()
    # Ranges to the two walls: y = 0.215 + 0.05 on the left, x = 0.255 + 0.5 ahead.
    with np.errstate(divide="ignore"):
        left = np.where(np.sin(angles) > 0, 0.265 / np.sin(angles), np.inf)
        front = np.where(np.cos(angles) > 0, 0.755 / np.cos(angles), np.inf)
    ranges = np.minimum(np.minimum(left, front), lidar.range_max)
    pose = Pose2D(0.0, 0.0, 0.0)
    readings = Readings(pose=pose, velocity=(0.0, 0.0), odometry=Odometry(pose, 0.0, 0.0), lidar=ranges,
                        imu=Imu((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)), collided=False, time=0.0)
    obs = make_layout("lidar49_robot", box, lidar)(readings, (5.0, 0.0))
    sectors = obs[6:42]
    scale = math.log(5.0 / 0.05 + 1.0)
    assert sectors[27] == pytest.approx(math.log(2.0) / scale, abs=2e-3)  # the sector about +90°
    assert sectors[18] == pytest.approx(math.log(11.0) / scale, abs=2e-3)  # the sector about 0°
    # On lidar43_log's scale the same left wall lies inside the bounding circle: it reads 0.
    assert make_layout("lidar43_log", box, lidar)(readings, (5.0, 0.0))[6 + 27] == 0.0


def test_the_clearance_term_prices_closeness_from_the_footprint():
    from common.rewards import StepContext, clearance

    ctx = StepContext(distance=2.0, prev_distance=2.0, heading_error=0.0, v=0.5, w=0.0, min_range=0.3,
                      collided=False, reached=False, clearance=0.05)
    assert clearance(ctx, threshold=0.3) == pytest.approx(0.25)
    assert clearance(ctx._replace(clearance=0.4), threshold=0.3) == 0.0
    env = gym.make("flatland/Nav-v0", world="passages", observation="lidar49_robot", robot_family=True,
                   reward={"progress": 10.0, "clearance": {"weight": -1.0, "threshold": 10.0}})
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(2, dtype=np.float32))
    unwrapped = env.unwrapped
    from common.robots import footprint_reach

    least = float((unwrapped._readings.lidar - footprint_reach(unwrapped.scenario.robot, unwrapped.scenario.lidar)).min())
    assert info["reward_terms"]["clearance"] == pytest.approx(-(10.0 - least))


def test_progress_per_stride_pays_each_robot_by_its_own_full_speed_step():
    from common.rewards import StepContext, progress

    ctx = StepContext(distance=2.0, prev_distance=2.1, heading_error=0.0, v=0.5, w=0.0, min_range=1.0,
                      collided=False, reached=False, stride=0.05)
    assert progress(ctx, per_stride=True) == pytest.approx(2.0)
    assert progress(ctx) == pytest.approx(0.1)  # metres, as before, unless asked
    env = gym.make("flatland/Nav-v0", world="passages", observation="lidar49_robot", robot_family=True,
                   reward={"progress": {"weight": 1.0, "per_stride": True}})
    strides = set()
    for seed in range(4):
        _, info = env.reset(seed=seed)
        before = info["distance"]
        _, _, _, _, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
        unwrapped = env.unwrapped
        stride = unwrapped.scenario.robot.v_max * unwrapped.world.period
        strides.add(round(stride, 6))
        assert info["reward_terms"]["progress"] == pytest.approx((before - info["distance"]) / stride)
    assert len(strides) == 4  # each episode's own robot, not the first one's
