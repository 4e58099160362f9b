"""A scenario written as an IR-SIM world runs in IR-SIM as it runs in flatland, movers included."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from common.drive import channel_limits
from common.errors import ConfigError
from common.generators import generate
from common.irsim_export import fixed_routes, scenario_to_irsim
from common.irsim_format import parse_irsim
from common.motion.spec import Dash, Motion, Orca, Sfm
from common.scenario import CircleObstacle, FootprintPart, RobotProfile
from tests.conftest import optional


def test_movers_read_back_from_their_irsim_file(tmp_path):
    scenario = fixed_routes(generate("crowd", 2, 0.5, "eval", behavior="sfm"), count=8)
    back = parse_irsim(scenario_to_irsim(scenario), source=tmp_path / "w.yaml")
    ours, theirs = scenario.movers, back.movers
    assert [(p.x, p.y, p.radius) for p in ours] == [(p.x, p.y, p.radius) for p in theirs]
    for mine, read in zip(ours, theirs):
        assert read.motion.behavior == mine.motion.behavior and read.motion.vel_max == mine.motion.vel_max
        assert read.motion.route_from((read.x, read.y)) == mine.motion.route_from((mine.x, mine.y))


def test_a_wanderer_without_goals_reads_back_with_its_region(tmp_path):
    wanderer = CircleObstacle(x=5.0, y=5.0, radius=0.25, motion=Motion(wander=(1.0, 1.0, 9.0, 9.0)))
    scenario = generate("open", 0, 0.5).model_copy(update={"obstacles": [wanderer]})
    data = scenario_to_irsim(scenario)
    (person,) = parse_irsim(data, source=tmp_path / "w.yaml").movers
    assert person.motion.wander == (1.0, 1.0, 9.0, 9.0)
    x, y = person.motion.goals[0]  # its first goal, drawn in the region as the file is read
    assert 1.0 <= x <= 9.0 and 1.0 <= y <= 9.0


@pytest.mark.parametrize("robot", [
    RobotProfile(shape="box", length=0.5, width=0.3, v_min=-0.5, accel_v=2.0, accel_w=3.0),
    RobotProfile(kinematics="omni", lateral_max=0.7, accel_lateral=1.5, motion_noise=(0.1, 0.2)),
    RobotProfile(kinematics="omni_angular", shape="box", length=0.6, width=0.4, static=True),
    RobotProfile(kinematics="acker", shape="box", length=1.0, width=0.6, footprint_offset=0.35, steer_max=0.5,
                 axle_distance=0.7, steer_mode="angular", accel_steer=1.0),
    RobotProfile(kinematics="acker", radius=0.4, footprint_offset=0.2, motion_noise=(0.1, 0.0, 0.0, 0.2)),
    RobotProfile(shape="polygon", vertices=((0.3, 0.0), (-0.2, 0.25), (-0.05, 0.0), (-0.2, -0.25))),
    RobotProfile(shape="compound", parts=(FootprintPart(vertices=((-0.3, -0.1), (0.3, -0.1), (0.3, 0.1), (-0.3, 0.1))),
                                          FootprintPart(center=(-0.2, 0.15), radius=0.12))),
], ids=["diff box", "omni", "omni_angular", "car", "round car", "polygon", "compound"])
def test_the_robot_reads_back_from_its_irsim_file(robot, tmp_path):
    scenario = generate("sparse", 1).model_copy(update={"robot": robot})
    back = parse_irsim(scenario_to_irsim(scenario), source=tmp_path / "w.yaml").robot
    # IR-SIM has no wheels, and writes each minimum out where a profile may leave it to the maximum.
    apart = {"wheel_radius", "wheel_base", "w_min", "lateral_min", "steer_min"}
    assert back.model_dump(exclude=apart) == robot.model_dump(exclude=apart)
    assert channel_limits(back) == channel_limits(robot)


@pytest.mark.slow
def test_an_exported_crowd_moves_in_irsim_as_in_flatland(tmp_path):
    irsim = optional("irsim")
    import flatland

    path = tmp_path / "crowd.yaml"
    crowd = fixed_routes(generate("crowd", 2, 0.5, "eval", behavior="sfm"), count=8)
    path.write_text(yaml.safe_dump(scenario_to_irsim(crowd)))
    world, env = flatland.load_world(path), irsim.make(str(path), display=False, log_level="ERROR")
    world.reset()
    try:
        for k in range(100):
            ours = world.step(0.3, 0.2)
            env.step([0.3, 0.2])
            theirs = np.array([obj.state[:2, 0] for obj in env.objects if obj.role == "obstacle" and not obj.static])
            np.testing.assert_allclose(ours.movers.rows[:, :2], theirs, rtol=0, atol=1e-9, err_msg=f"step {k}")
    finally:
        env.end(0)


def test_what_irsim_cannot_say_is_one_line():
    def person(behavior, reacts=False, speed=1.0):
        return CircleObstacle(x=5.0, y=5.0, radius=0.2, motion=Motion(behavior=behavior, goals=[(6.0, 5.0)], group="g",
                                                                      vel_max=(speed, speed), reacts_to_robot=reacts))

    scenario = generate("open", 0)
    with pytest.raises(ConfigError, match="IR-SIM's ORCA group sees only its members"):
        scenario_to_irsim(scenario.model_copy(update={"obstacles": [person(Orca(), reacts=True)]}))
    alone = person(Orca())
    alone = alone.model_copy(update={"motion": alone.motion.model_copy(update={"group": None})})
    with pytest.raises(ConfigError, match="0.motion.group: IR-SIM runs ORCA as a group behaviour only"):
        scenario_to_irsim(scenario.model_copy(update={"obstacles": [alone]}))
    with pytest.raises(ConfigError, match="IR-SIM's group behaviour has one set of parameters"):
        scenario_to_irsim(scenario.model_copy(update={"obstacles": [person(Sfm(vmax=1.0)), person(Sfm(vmax=2.0))]}))
    driver = CircleObstacle(x=5.0, y=5.0, radius=0.2, motion=Motion(behavior=Dash(yield_distance=1.0), goals=[(6.0, 5.0)]))
    with pytest.raises(ConfigError, match="0.motion.behavior.yield_distance: IR-SIM's dash never yields"):
        scenario_to_irsim(scenario.model_copy(update={"obstacles": [driver]}))
    blind = driver.model_copy(update={"motion": driver.motion.model_copy(update={"reacts_to_robot": False})})
    assert "yield_distance" not in str(scenario_to_irsim(scenario.model_copy(update={"obstacles": [blind]})))
    # Dropped without a word, each parted IR-SIM's poses from flatland's by centimetres in 20 steps.
    noisy = scenario.model_copy(update={"robot": scenario.robot.model_copy(update={"encoder_noise": 0.2})})
    with pytest.raises(ConfigError, match="robot.encoder_noise: IR-SIM's robot has no wheel encoders; allowed: 0"):
        scenario_to_irsim(noisy)
    exact = scenario.model_copy(update={"world": scenario.world.model_copy(update={"integrator": "exact"})})
    with pytest.raises(ConfigError, match="world.integrator: IR-SIM moves its robot by Euler steps; allowed: euler"):
        scenario_to_irsim(exact)


@pytest.mark.parametrize("roles", ["all", "robot", "obstacle"])
def test_whom_a_mover_avoids_reads_back(roles, tmp_path):
    """target_roles: robot was written as nothing (all): IR-SIM's own moving files then ran, under
    --world irsim, with movers that avoided every object instead of the robot alone."""
    mover = CircleObstacle(x=5.0, y=5.0, radius=0.2, motion=Motion(goals=[(6.0, 5.0)], target_roles=roles))
    scenario = generate("open", 0).model_copy(update={"obstacles": [mover]})
    back = parse_irsim(scenario_to_irsim(scenario), source=tmp_path / "w.yaml")
    assert back.movers[0].motion.target_roles == roles
