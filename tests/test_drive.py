"""The controlled robot's kinematics other than diff, its motion noise (common.drive) and its
footprints: IR-SIM's omni, omni_angular and acker, cars, polygon and compound robots, in flatland step for
step as IR-SIM moves them, in the gym env's action space, and refused with one line where only a
differential drive will do."""

from __future__ import annotations

import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

from common.actions import ActionMapping
from common.drive import CHANNELS, Drive
from common.errors import ConfigError
from common.scenario import RobotProfile, Scenario
from tests.conftest import optional

STEPS = 200
# Kinematics mappings as IR-SIM reads them, the cars' with a wheelbase in their shape (the footprint
# ahead of the rear axle: a box and a circle), and finite accelerations so the windows bind.
ROBOTS = {
    "omni": {"kinematics": {"name": "omni"}, "shape": {"name": "rectangle", "length": 0.5, "width": 0.3},
             "vel_max": [1.0, 0.8], "vel_min": [-0.6, -0.8], "acce": [2.0, 3.0]},
    "omni_angular": {"kinematics": {"name": "omni_angular"}, "shape": {"name": "circle", "radius": 0.25},
                     "vel_max": [1.0, 0.8, 1.5], "vel_min": [-1.0, -0.8, -1.5], "acce": [2.0, 3.0, 4.0]},
    "acker": {"kinematics": {"name": "acker"}, "shape": {"name": "rectangle", "length": 1.0, "width": 0.6,
                                                        "wheelbase": 0.7},
              "vel_max": [1.5, 0.5], "vel_min": [-1.0, -0.5], "acce": [3.0, 2.0]},
    # A differential drive with a concave footprint (an arrowhead: pymunk collides its convex pieces).
    "polygon": {"kinematics": {"name": "diff"}, "shape": {"name": "polygon", "vertices": [
        [0.35, 0.0], [-0.2, 0.3], [-0.05, 0.0], [-0.2, -0.3]]}, "vel_min": [-1.0, -2.0], "vel_max": [1.5, 2.0]},
    # IR-SIM's compound shape: parts placed by their poses, one of them a circle off the centre line.
    "compound": {"kinematics": {"name": "diff"}, "shape": {"name": "compound", "parts": [
        {"name": "rectangle", "length": 0.8, "width": 0.3},
        {"name": "rectangle", "length": 0.3, "width": 0.6, "pose": [-0.25, 0.3, 0.5]},
        {"name": "circle", "radius": 0.2, "center": [0.1, 0.0], "pose": [0.4, -0.3, 0]}]},
        "vel_min": [-1.0, -2.0], "vel_max": [1.5, 2.0]},
    # IR-SIM's motion noise, drawn from the world's generator in IR-SIM's order: equal draws.
    "diff_noisy": {"kinematics": {"name": "diff", "noise": True, "alpha": [0.1, 0.0, 0.02, 0.3]},
                   "shape": {"name": "circle", "radius": 0.3}, "vel_min": [-1.0, -1.5], "vel_max": [1.5, 1.5]},
    "omni_angular_noisy": {"kinematics": {"name": "omni_angular", "noise": True},
                           "shape": {"name": "rectangle", "length": 0.6, "width": 0.4}},
    "acker_angular": {"kinematics": {"name": "acker", "mode": "angular", "wheelbase": 0.6, "noise": True},
                      "shape": {"name": "circle", "radius": 0.4, "wheelbase": 0.7},
                      "vel_max": [1.5, 0.8], "vel_min": [-1.0, -0.8]},
}


def _world_file(tmp_path, name: str) -> str:
    robot = {**ROBOTS[name], "state": [2.0, 2.0, 0.3, 0][:4 if "acker" in name else 3], "goal": [8, 8, 0],
             "sensors": [{"name": "lidar2d", "range_max": 5, "angle_range": 2 * math.pi, "number": 60}]}
    data = {"world": {"width": 10, "height": 10, "step_time": 0.1, "collision_mode": "stop"},
            "robot": [robot],
            "obstacle": [{"shape": {"name": "circle", "radius": 0.5}, "state": [5.0, 3.5, 0]},
                         {"shape": {"name": "rectangle", "length": 2.0, "width": 0.6}, "state": [4.0, 6.5, 0.4]},
                         {"shape": {"name": "polygon", "vertices": [[7, 2], [8.5, 2.5], [7.5, 4]]}, "state": [0, 0, 0]}]}
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def _commands(channels: int, seed: int) -> np.ndarray:
    """Random commands that drive mostly forward and now and then past the limits."""
    rng = np.random.default_rng(seed)
    commands = rng.uniform(-1.2, 1.2, (STEPS, channels))
    commands[:, 0] = rng.uniform(-0.3, 1.6, STEPS)
    return commands


@pytest.mark.parametrize("name", list(ROBOTS))
def test_each_kinematics_moves_and_collides_as_irsim_does(name, tmp_path):
    irsim = optional("irsim")
    import flatland

    path = _world_file(tmp_path, name)
    world = flatland.load_world(path, seed=0)
    assert world.scenario.robot.kinematics == ROBOTS[name]["kinematics"]["name"]
    env = irsim.make(path, display=False, log_level="ERROR", seed=0)
    collided = -1
    try:
        world.reset()
        for seed in range(20):  # until a run of commands ends in a collision
            for k, command in enumerate(_commands(len(CHANNELS[world.scenario.robot.kinematics]), seed)):
                ours = world.step(*command)
                env.step(command.reshape(-1, 1))
                theirs = np.asarray(env.get_robot_state()[:3, 0], dtype=float)
                np.testing.assert_allclose(ours.pose[:2], theirs[:2], rtol=0, atol=1e-9, err_msg=f"step {k}")
                assert math.isclose(math.remainder(ours.pose[2] - theirs[2], 2 * math.pi), 0.0, abs_tol=1e-9)
                assert ours.collided == bool(env.robot.collision_flag), f"collision flag, step {k}"
                close = np.abs(ours.lidar - env.get_lidar_scan()["ranges"]) <= 0.02
                assert close.mean() >= 0.95, f"step {k}: {close.mean():.0%} of beams within 2 cm"
                if ours.collided:
                    collided = k
                    break
            if collided >= 0:
                break
            world.reset()
            env.reset()
    finally:
        env.end(0)
    assert collided >= 0, "no run of commands collided: the contact was never compared"


@pytest.mark.parametrize("name", ["polygon", "compound", "acker"])
def test_each_footprint_covers_what_irsims_covers(name, tmp_path):
    """The footprint's outline in the body frame against IR-SIM's own geometry (its circles are
    polygons of 2 mm chords, hence the tolerance)."""
    irsim = optional("irsim")
    from shapely.geometry import Point, Polygon
    from shapely.ops import unary_union

    import flatland

    path = _world_file(tmp_path, name)
    robot = flatland.load_world(path, seed=0).scenario.robot
    ours = unary_union([Point(part.center).buffer(part.radius, quad_segs=64) if part.radius is not None
                        else Polygon(part.vertices) for part in robot.outline])
    env = irsim.make(path, display=False, log_level="ERROR", seed=0)
    try:
        theirs = env.robot.original_geometry
        assert ours.symmetric_difference(theirs).area <= 2e-3 * theirs.area
    finally:
        env.end(0)


def test_motion_noise_moves_the_robot_where_the_command_alone_would_not_and_odometry_does_not_see_it():
    from flatland.world import World

    def drive(noise):
        robot = RobotProfile(v_max=1.0, w_max=1.0, motion_noise=noise)
        world = World(Scenario(robot=robot, start=(2.0, 2.0, 0.0), goal=(8.0, 8.0)), seed=4)
        world.reset()
        for _ in range(30):
            readings = world.step(0.8, 0.3)
        return readings

    quiet, noisy, again = drive(None), drive((0.1, 0.0, 0.0, 0.3)), drive((0.1, 0.0, 0.0, 0.3))
    assert noisy.pose == again.pose  # seeded
    assert math.dist(noisy.pose[:2], quiet.pose[:2]) > 0.05
    # The odometry integrates the command: without noise the pose itself, with it the noise-free path.
    assert np.allclose(quiet.odometry.pose, quiet.pose, atol=1e-9)
    assert np.allclose(noisy.odometry.pose, quiet.pose, atol=1e-9)


def test_a_static_robot_stays_where_it_is_whatever_it_is_commanded():
    from flatland.world import World

    world = World(Scenario(robot=RobotProfile(static=True), start=(2.0, 2.0, 0.5), goal=(8.0, 8.0)))
    world.reset()
    readings = world.step(1.0, 1.0)
    assert readings.pose == (2.0, 2.0, 0.5) and readings.velocity == (0.0, 0.0) and not readings.collided


def test_the_acceleration_window_and_the_limits_clip_each_channel_as_irsim_does():
    robot = RobotProfile(kinematics="omni_angular", v_min=-1.0, v_max=1.0, lateral_max=0.5, w_max=2.0,
                         accel_v=1.0, accel_lateral=10.0, accel_w=5.0)
    drive = Drive(robot, dt=0.1)
    # Forward reaches 0.1 of its 1.0 a step; lateral is capped at 0.5; w's window is 0.5 a step.
    assert drive.move((5.0, 5.0, -5.0))[0] == pytest.approx((0.1, 0.5, -0.5))
    assert drive.move((5.0, -5.0, 5.0))[0] == pytest.approx((0.2, -0.5, 0.0))
    # A window wholly above the limit (last 2.0, reach 1.0) leaves the limit, as NumPy's clip does
    # (raised to the window's low end, then lowered to the high end).
    drive = Drive(RobotProfile(kinematics="omni", lateral_max=0.2, accel_lateral=1.0), dt=1.0)
    drive.last = [0.0, 2.0]
    assert drive.move((0.0, -1.0))[0][1] == pytest.approx(0.2)


def test_a_car_turns_with_the_steering_angle_it_began_the_step_with():
    robot = RobotProfile(kinematics="acker", v_max=2.0, steer_max=0.5, axle_distance=2.0)
    drive = Drive(robot, dt=0.1)
    assert drive.move((1.0, 0.4))[0] == (1.0, 0.0, 0.0)  # wheels were straight
    assert drive.move((1.0, 0.0))[0][2] == pytest.approx(math.tan(0.4) / 2.0)
    angular = Drive(robot.model_copy(update={"steer_mode": "angular"}), dt=0.1)
    angular.move((1.0, 0.5))
    assert angular.steer == pytest.approx(0.05)  # a rate: 0.5 rad/s for 0.1 s


@pytest.mark.parametrize("v_min", [0.0, -0.5, -1.0])
def test_an_omni_robots_forward_action_spans_its_own_speed_range(v_min):
    """Mapped to [-v_max, v_max] and then clipped to v_min, the lower half of a[0] stood still
    for an omni robot that cannot back."""
    mapping = ActionMapping(RobotProfile(kinematics="omni", v_min=v_min, v_max=1.0, lateral_max=0.5))
    forward = [mapping.to_velocity(np.array([a, 0.0], dtype=np.float32))[0] for a in (-1.0, -0.5, 0.0, 1.0)]
    assert forward == pytest.approx([v_min, v_min + 0.25 * (1.0 - v_min), 0.5 * (v_min + 1.0), 1.0])
    assert mapping.to_velocity(np.array([0.3, -1.0], dtype=np.float32))[1] == -0.5  # lateral stays symmetric
    assert mapping.to_action(0.5 * (v_min + 1.0), 0.25) == pytest.approx([0.0, 0.5])


@pytest.mark.parametrize("kinematics, size", [("omni", 2), ("omni_angular", 3), ("acker", 2)])
def test_the_env_takes_one_action_per_channel_of_the_robots_kinematics(kinematics, size):
    import flatland  # noqa: F401

    scenario = Scenario(robot=RobotProfile(kinematics=kinematics, v_min=-1.0), start=(2.0, 5.0, 0.0), goal=(8.0, 5.0))
    env = gym.make("flatland/Nav-v0", world=scenario)
    assert env.action_space.shape == (size,)
    env.reset(seed=0)
    sideways = np.zeros(size, dtype=np.float32)
    sideways[1] = 1.0  # omni: full speed to the left; a car: full steering, driving at half speed
    for _ in range(5):
        env.step(sideways)
    x, y, yaw = env.unwrapped.world.pose
    if kinematics == "acker":
        assert x > 2.0 and y > 5.0 and yaw > 0.0  # forward on a left turn
    else:
        assert abs(x - 2.0) < 1e-9 and y == pytest.approx(5.5) and yaw == 0.0
    with pytest.raises(ValueError, match=f"shape \\({size},\\)"):
        env.step(np.zeros(size + 1, dtype=np.float32))


def test_controllers_policies_curricula_and_the_3d_tier_refuse_another_drive_in_one_line(tmp_path):
    from common.controllers import make_controller
    from common.curriculum.schema import load_curriculum
    from common.generators import generate
    from common.scenario import LidarSpec
    from flatland.world import World as FlatWorld
    from physics3d.world import World

    omni = RobotProfile(kinematics="omni")
    with pytest.raises(ConfigError, match="robot.kinematics: the potential_field controller drives a differential"):
        make_controller("potential_field").bind(omni, LidarSpec())
    with pytest.raises(ConfigError, match="robot.kinematics: the 3D robot is a differential drive, not 'omni'"):
        World(Scenario(robot=omni))
    (tmp_path / "omni.yaml").write_text("robot: {kinematics: omni}\nstart: [1, 1, 0]\ngoal: [9, 9]\n")
    with pytest.raises(ConfigError, match=r"^\S*omni\.yaml: robot\.kinematics: the 3D robot is a differential drive"):
        gym.make("physics3d/WarehouseNav-v0", world=str(tmp_path / "omni.yaml"))  # the env names the user's file
    with pytest.raises(ConfigError, match="robot.motion_noise: IR-SIM's kinematic stand-in is not modelled"):
        World(Scenario(robot=RobotProfile(motion_noise=(0.1, 0, 0, 0.1))))
    compound = RobotProfile(shape="compound", parts=({"radius": 0.2}, {"center": (-0.2, 0.0), "radius": 0.15}))
    with pytest.raises(ConfigError, match="robot.shape: the 3D robot's body is the URDF's box"):
        World(Scenario(robot=compound))
    with pytest.raises(ConfigError, match="robot.shape: a compound robot among movers is not modelled"):
        FlatWorld(generate("crowd", 1, 0.5).model_copy(update={"robot": compound}))
    from common.motion.spec import Motion
    with pytest.raises(ConfigError, match="robot.shape: a compound robot among movers is not modelled"):
        # The robot's own IR-SIM behaviour alone makes it a mover among movers.
        FlatWorld(Scenario(robot=compound, robot_motion=Motion(goals=[(8.0, 8.0)], role="robot")))
    curriculum = yaml.safe_load((Path(__file__).resolve().parents[1] / "curricula" / "stage1_2d.yaml").read_text())
    curriculum["stages"][0]["env_kwargs"]["robot"] = {"kinematics": "omni"}
    path = tmp_path / "omni.yaml"
    path.write_text(yaml.safe_dump(curriculum))
    with pytest.raises(ConfigError) as error:
        load_curriculum(path)
    assert "robot.kinematics: a curriculum stage drives a differential drive" in str(error.value)
    assert "\n" not in str(error.value)
