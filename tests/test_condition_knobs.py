"""Condition knobs reach what they change: the robot and odometry knobs together on a plain
scenario, and a motor gain on both velocities the wheels deliver."""

from __future__ import annotations

import pytest

from common.conditions import Conditions
from common.robots import PROFILES
from common.scenario import Scenario, WorldSpec
from common.tiers import make_world

OPEN = Scenario(start=(2.0, 5.0, 0.0), goal=(9.0, 5.0), world=WorldSpec(width=12.0, height=10.0))


def test_odometry_noise_keeps_the_robot_knob_on_a_plain_scenario():
    robot = Conditions(robot="physics3d", odometry_noise=0.02).scenario(Scenario()).robot
    assert robot == PROFILES["physics3d"].model_copy(update={"encoder_noise": 0.02})


@pytest.mark.parametrize("knobs, expected", [
    ({"robot": "physics3d"}, PROFILES["physics3d"]),
    ({"odometry_noise": 0.03}, Scenario().robot.model_copy(update={"encoder_noise": 0.03})),
    ({"robot": "physics3d", "lidar_noise": 0.05}, PROFILES["physics3d"]),
])
def test_each_robot_and_noise_knob_changes_only_its_own_part(knobs, expected):
    scenario = Conditions(**knobs).scenario(Scenario())
    assert scenario.robot == expected
    assert scenario.lidar.noise_std == knobs.get("lidar_noise", Scenario().lidar.noise_std)


@pytest.mark.parametrize("gain", [0.5, 0.8])
def test_a_motor_gain_scales_both_the_linear_and_the_angular_velocity(gain):
    world = make_world("flatland", OPEN, conditions=Conditions(motor_scale=(gain, gain)))
    world.reset(seed=0)
    world.step(0.4, 0.6)
    assert world.velocity == pytest.approx((0.4 * gain, 0.6 * gain))
    world.step(0.2, -0.5)  # a turn the other way: the same gain, the sign kept
    assert world.velocity == pytest.approx((0.2 * gain, -0.5 * gain))
