"""Conditions (common.conditions): each knob changes what it should, in each tier, deterministically."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pybullet as p
import pytest

import flatland  # noqa: F401
import physics3d  # noqa: F401
from common.conditions import Conditions
from common.errors import ConfigError
from common.robots import PROFILES
from common.scenario import LidarSpec, Scenario, SegmentObstacle, WorldSpec
from common.tiers import generator_template, make_world

OPEN = Scenario(start=(2.0, 5.0, 0.0), goal=(9.0, 5.0), world=WorldSpec(width=12.0, height=10.0))


def _xs(world, commands) -> list[float]:
    world.reset(seed=0)
    return [world.step(v, w).pose[0] for v, w in commands]


def test_action_delay_holds_each_command_back_by_whole_steps():
    commands = [(1.0, 0.0)] * 3 + [(0.0, 0.0)] * 3
    now = _xs(make_world("flatland", OPEN, conditions=Conditions(action_delay=0)), commands)
    late = _xs(make_world("flatland", OPEN, conditions=Conditions(action_delay=1)), commands)
    assert late[0] == 2.0  # the first step still carries the "stand still" the robot started with
    np.testing.assert_allclose(late[1:], now[:-1])


@pytest.mark.parametrize("tier", ["flatland", "physics3d"])
def test_an_action_delay_range_draws_whole_steps_per_episode_and_replays_under_a_seed(tier):
    world = make_world(tier, OPEN, conditions=Conditions(action_delay=(0, 2), odometry_noise=0.0))

    def delay(seed: int) -> int:
        world.reset(seed=seed)
        # The command moves the robot only once it has come through the pipeline.
        return next(step for step in range(4) if world.step(0.5, 0.0).velocity[0] > 0.1)

    delays = [delay(seed) for seed in range(12)]
    assert set(delays) == {0, 1, 2}
    assert [delay(seed) for seed in range(12)] == delays


@pytest.mark.parametrize("knob", ["action_delay", "motor_scale", "friction", "mass_scale"])
def test_a_range_runs_from_low_to_high(knob):
    with pytest.raises(ConfigError, match=rf"env_kwargs.{knob}: expected \[low, high\] with low <= high, got \[2(\.0)?, 1(\.0)?\]"):
        Conditions.parse({knob: [2, 1]})


def test_lidar_noise_has_the_asked_spread_and_replays_under_a_seed():
    wall = SegmentObstacle(points=[(4.0, 0.0), (4.0, 10.0)])
    scenario = OPEN.model_copy(update={"obstacles": [wall], "lidar": LidarSpec(beams=720, range_max=20.0)})
    clean = make_world("flatland", scenario, seed=1).reset().lidar
    noisy = make_world("flatland", scenario, seed=1, conditions=Conditions(lidar_noise=0.05)).reset().lidar
    hits = clean < 20.0
    error = (noisy - clean)[hits]
    assert abs(error.std() - 0.05) < 0.005 and abs(error.mean()) < 0.006  # 720 beams: ±10 % on sigma
    again = make_world("flatland", scenario, seed=1, conditions=Conditions(lidar_noise=0.05)).reset().lidar
    assert np.array_equal(noisy, again)


@pytest.mark.parametrize("tier", ["flatland", "physics3d"])
def test_lidar_beams_sets_the_scan_of_either_tier_and_keeps_the_noise(tier):
    conditions = Conditions(lidar_beams=180, lidar_noise=0.02)
    scenario = conditions.scenario(OPEN)
    assert (scenario.lidar.beams, scenario.lidar.noise_std) == (180, 0.02)
    world = make_world(tier, OPEN, seed=0, conditions=conditions)
    try:
        assert world.reset().lidar.shape == (180,)
    finally:
        getattr(world, "close", lambda: None)()


def test_motor_scale_draws_a_gain_per_episode_within_its_range():
    world = make_world("flatland", OPEN, conditions=Conditions(motor_scale=(0.5, 1.5)))
    gains = []
    for seed in range(8):
        world.reset(seed=seed)
        gains.append(world.step(1.0, 0.0).pose[0] - 2.0)  # 0.1 m a step at gain 1
    assert all(0.05 <= g <= 0.15 for g in gains) and len(set(np.round(gains, 9))) == 8
    world.reset(seed=3)
    assert world.step(1.0, 0.0).pose[0] - 2.0 == gains[3]


def test_first_order_dynamics_rehearse_the_3d_robots_response():
    robot = OPEN.model_copy(update={"robot": PROFILES["physics3d"]})
    world = make_world("flatland", robot, conditions=Conditions(dynamics="first_order"))
    world.reset(seed=0)
    speeds = [world.step(0.5, 0.0).velocity[0] for _ in range(3)] + [world.step(0.0, 0.0).velocity[0] for _ in range(3)]
    # Measured on the 3D robot: 0.254, 0.493, 0.501 up; 0.245, 0.008, 0.001 down.
    np.testing.assert_allclose(speeds, [0.25, 0.5, 0.5, 0.25, 0.0, 0.0], atol=0.01)
    turns = [world.step(0.5, 1.5).velocity for _ in range(3)]
    assert turns[0][1] < 0.1 and 0.6 < turns[1][1] < 0.9 and turns[2][1] == pytest.approx(1.5, abs=0.05)


def test_the_robot_knob_swaps_the_profile_and_noise_knobs_reach_the_scenario():
    env = gym.make("flatland/Nav-v0", world="sparse", robot="physics3d", odometry_noise=0.02, lidar_noise=0.03)
    env.reset(seed=0)
    scenario = env.unwrapped.scenario
    assert scenario.robot == PROFILES["physics3d"].model_copy(update={"encoder_noise": 0.02})
    assert scenario.lidar.noise_std == 0.03
    assert env.unwrapped.actions.v_max == 0.5  # actions map to the 3D robot's limits


def test_each_tier_refuses_the_other_tiers_knobs():
    with pytest.raises(ConfigError, match="friction: not a flatland knob"):
        gym.make("flatland/Nav-v0", friction=(0.8, 1.2))
    with pytest.raises(ConfigError, match="heading_source: not a flatland knob"):
        gym.make("flatland/Nav-v0", heading_source="gyro")
    with pytest.raises(ConfigError, match="dynamics: not a physics3d knob"):
        gym.make("physics3d/WarehouseNav-v0", world="open", dynamics="first_order")


def test_physics3d_defaults_are_the_realistic_ones():
    env = gym.make("physics3d/WarehouseNav-v0", world="open")
    conditions = env.unwrapped.conditions
    assert conditions.robot == "physics3d" and conditions.lidar_noise == 0.01 and conditions.odometry_noise == 0.01
    assert conditions.motor_scale == (0.95, 1.05) and conditions.friction == (0.8, 1.2) and conditions.mass_scale == (0.9, 1.1)
    world = env.unwrapped.world
    assert world.gyro_heading and world.imu.gyro_noise == 0.005 and world.conditions.gyro_bias == 0.0005
    assert gym.make("flatland/Nav-v0").unwrapped.conditions.lidar_noise is None  # flatland: ideal unless asked
    # A world built directly has its tier's defaults too: there is one table of them.
    bare = make_world("physics3d", OPEN)
    assert bare.conditions == conditions and bare.gyro_heading and bare.imu.accel_noise == 0.05
    assert bare.scenario.lidar.noise_std == 0.01 and bare.scenario.robot.encoder_noise == 0.01
    bare.close()
    env.close()


def test_physics3d_friction_and_mass_are_drawn_per_episode_and_replay():
    world = make_world("physics3d", OPEN, conditions=Conditions(friction=(0.5, 0.7), mass_scale=(1.5, 2.0)))
    robot = world.robot

    def dynamics(seed: int) -> tuple[float, float]:
        world.reset(seed=seed)
        mass = p.getDynamicsInfo(robot.id, -1, physicsClientId=world.client)[0]
        friction = p.getDynamicsInfo(robot.id, robot.wheels[0], physicsClientId=world.client)[1]
        return mass, friction

    draws = [dynamics(seed) for seed in range(4)]
    assert all(3.0 <= mass <= 4.0 and 0.5 <= mu <= 0.7 for mass, mu in draws)  # the URDF body is 2 kg
    assert len(set(draws)) == 4 and dynamics(2) == draws[2]
    world.close()


def test_a_heavier_slipperier_3d_robot_accelerates_less():
    plain = make_world("physics3d", OPEN, conditions=Conditions(motor_scale=(1, 1), friction=(1, 1), mass_scale=(1, 1)))
    heavy = make_world("physics3d", OPEN, conditions=Conditions(motor_scale=(1, 1), friction=(0.3, 0.3), mass_scale=(3, 3)))
    far = [_xs(world, [(0.5, 0.0)] * 5)[-1] for world in (plain, heavy)]
    assert far[1] < far[0] - 0.02


def test_the_heading_and_gyro_knobs_reach_the_3d_world():
    env = gym.make("physics3d/WarehouseNav-v0", world="open", heading_source="wheels", gyro_noise=0.02, gyro_bias=0.01)
    world = env.unwrapped.world
    assert not world.gyro_heading and world.imu.gyro_noise == 0.02 and world.conditions.gyro_bias == 0.01
    biases = [tuple(world.reset(seed=seed).imu and world.imu.bias) for seed in range(30)]
    assert len(set(biases)) == 30  # drawn per episode
    assert np.std(biases) == pytest.approx(0.01, rel=0.3)  # with the knob's σ: 90 draws
    env.close()


def test_each_tier_generates_around_its_own_template_and_an_unknown_tier_is_refused():
    from physics3d.robot import TEMPLATE

    assert generator_template("physics3d") is TEMPLATE and generator_template("flatland") == Scenario()
    assert gym.make("physics3d/WarehouseNav-v0").unwrapped.source.template.name == TEMPLATE.name
    with pytest.raises(ConfigError, match="unknown tier 'mars'; allowed: flatland, physics3d"):
        generator_template("mars")


def test_the_docs_table_lists_every_knob_with_its_physics3d_default():
    # The knob table in docs/envs.md is what users read: a new knob or a changed default must show there.
    import re

    import yaml

    from common.conditions import CONDITION_KEYS, TIER_DEFAULTS

    text = (Path(__file__).resolve().parents[1] / "docs/envs.md").read_text()
    section = text.split("## Conditions", 1)[1].split("\n## ", 1)[0]
    rows = {m.group(1): m.group(2).strip() for m in re.finditer(r"^\| `(\w+)` \|.*\| ([^|]+) \|$", section, re.M)}
    assert set(rows) == set(CONDITION_KEYS)
    for knob, default in TIER_DEFAULTS["physics3d"].items():
        documented = yaml.safe_load(rows[knob].strip("`"))
        assert documented == (list(default) if isinstance(default, tuple) else default), knob


def test_a_robot_that_does_not_fit_its_world_is_refused_in_one_line():
    from common.curriculum.cli import main

    with pytest.raises(ConfigError, match=r"robot: 1998 m across, it does not fit in the 10 x 10 m world"):
        Conditions(robot={"radius": 999}).scenario(Scenario())
    assert main(["compare", "--controllers", "go_to_goal", "--episodes", "1", "--env-kwargs", "robot:{radius: 999}"]) == 2


@pytest.mark.parametrize("knobs, field, got", [
    ({"lidar_beams": True}, "lidar_beams", "True"),  # was one beam
    ({"action_delay": True}, "action_delay", "True"),  # was a step of delay
    ({"lidar_noise": "0.5"}, "lidar_noise", "'0.5'"),
    ({"odometry_noise": False}, "odometry_noise", "False"),
    ({"motor_scale": [True, True]}, "motor_scale.0", "True"),
    ({"control_period": True}, "control_period", "True"),
    ({"robot_family": {"radius": [True, 0.3]}}, "robot_family.radius.0", "True"),
])
def test_a_knob_of_the_wrong_type_is_refused_not_read_as_a_number(knobs, field, got):
    with pytest.raises(ConfigError, match=rf"^c.yaml: env_kwargs.{field}: Input should be a valid (number|integer) \(got {got}\)$"):
        Conditions.parse(knobs, "c.yaml")
    # Whole numbers stay numbers where a real number belongs.
    assert Conditions.parse({"lidar_noise": 0, "motor_scale": [1, 2]}).motor_scale == (1.0, 2.0)
