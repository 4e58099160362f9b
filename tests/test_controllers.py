"""Classical controllers on hand-built flatland worlds, generated suites, and the registry's checks."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import pytest

from common.controllers import CONTROLLERS, Controller, controller_parameters, make_controller
from common.errors import ConfigError
from common.generators import generate
from common.kinematics import Pose2D
from common.readings import Odometry
from common.scenario import CircleObstacle, RobotProfile, Scenario, WorldSpec
from flatland.world import World

AVOIDERS = ["reactive", "potential_field", "pid_blend"]


class Episode(NamedTuple):
    outcome: str  # "success", "collision" or "timeout"
    steps: int
    commands: list[tuple[float, float]]
    poses: list[Pose2D]


def rollout(controller: Controller, scenario: Scenario, max_steps: int = 500) -> Episode:
    """Drive ``scenario`` with ``controller`` until the goal (within goal_threshold), a collision or max_steps."""
    controller.bind(scenario.robot, scenario.lidar)
    controller.reset()
    world = World(scenario, seed=0)
    readings = world.reset()
    commands, poses = [], [readings.pose]
    for step in range(1, max_steps + 1):
        command = controller.act(readings, scenario.goal)
        commands.append(command)
        readings = world.step(*command)
        poses.append(readings.pose)
        if math.dist(readings.pose[:2], scenario.goal) < scenario.goal_threshold:
            return Episode("success", step, commands, poses)
        if readings.collided:
            return Episode("collision", step, commands, poses)
    return Episode("timeout", max_steps, commands, poses)


def single_circle(y: float = 5.0) -> Scenario:
    """Start (2, 5) facing +x, goal (8, 5), a 0.5 m circle at (5, y) across the route."""
    return Scenario(start=(2.0, 5.0, 0.0), goal=(8.0, 5.0), obstacles=[CircleObstacle(x=5.0, y=y, radius=0.5)])


@pytest.mark.parametrize("name", list(CONTROLLERS))
def test_straight_approach_reaches_the_goal(name):
    episode = rollout(make_controller(name), Scenario(start=(1.0, 5.0, 0.0), goal=(9.0, 5.0)), max_steps=300)
    assert episode.outcome == "success"
    assert all(abs(pose.y - 5.0) < 0.05 for pose in episode.poses)  # straight, no weaving


@pytest.mark.parametrize("name", list(CONTROLLERS))
def test_goal_behind_turns_toward_it_without_driving_away(name):
    # The goal is behind and a little to the left: turn left (w > 0) on the spot, then go.
    scenario = Scenario(start=(5.0, 5.0, 0.0), goal=(2.0, 5.5))
    episode = rollout(make_controller(name), scenario, max_steps=300)
    v, w = episode.commands[0]
    assert w > 0.0 and v == pytest.approx(0.0, abs=1e-9)
    start_distance = math.dist(scenario.start[:2], scenario.goal)
    assert max(math.dist(pose[:2], scenario.goal) for pose in episode.poses) <= start_distance + 0.05
    assert episode.outcome == "success"


@pytest.mark.parametrize("name", list(CONTROLLERS))
def test_commands_respect_the_forward_only_limits(name):
    robot = RobotProfile(v_max=0.4, w_max=0.6)
    episode = rollout(make_controller(name), single_circle(5.15).model_copy(update={"robot": robot}))
    v, w = np.array(episode.commands).T
    assert v.min() >= 0.0 and v.max() <= 0.4 and np.abs(w).max() <= 0.6
    # A robot that cannot stand (v_min 0.2) nor turn right faster than 0.3 rad/s: the world drove
    # its limits, not the command, and dwa weighed arcs the robot could not take.
    robot = RobotProfile(v_max=0.6, v_min=0.2, w_max=1.0, w_min=-0.3, accel_v=2.0, accel_w=5.0)
    episode = rollout(make_controller(name), single_circle(5.15).model_copy(update={"robot": robot}), max_steps=60)
    v, w = np.array(episode.commands).T
    assert v.min() >= 0.2 and v.max() <= 0.6 and w.min() >= -0.3 and w.max() <= 1.0


def test_go_to_goal_drives_into_an_obstacle_dead_ahead():
    # The tutorial's point: it knows only the goal.
    assert rollout(make_controller("go_to_goal"), single_circle()).outcome == "collision"


@pytest.mark.parametrize("name", AVOIDERS)
@pytest.mark.parametrize("y, away", [(5.15, -1.0), (4.85, 1.0)])
def test_avoiders_turn_away_and_go_round_a_circle_dead_ahead(name, y, away):
    # The circle sits slightly left (y = 5.15) or right of the route: the first real turn goes the other way.
    episode = rollout(make_controller(name), single_circle(y))
    first_turn = next(w for _, w in episode.commands if abs(w) > 0.1)
    assert math.copysign(1.0, first_turn) == away
    assert episode.outcome == "success"
    passing = [pose.y for pose in episode.poses if abs(pose.x - 5.0) < 0.1]
    assert passing and all((py - y) * away > 0.7 for py in passing)  # round the side it turned to
    clearance = min(math.dist(pose[:2], (5.0, y)) for pose in episode.poses) - 0.5 - 0.2
    assert clearance > 0.05


@pytest.mark.parametrize("name", AVOIDERS)
def test_avoiders_go_round_a_circle_exactly_on_the_route(name):
    assert rollout(make_controller(name), single_circle(5.0)).outcome == "success"


def test_reactive_turns_a_slower_robot_at_its_own_limit():
    robot = RobotProfile(w_max=0.5)
    episode = rollout(make_controller("reactive"), single_circle(5.15).model_copy(update={"robot": robot}))
    avoiding = [(v, w) for v, w in episode.commands if v == pytest.approx(0.1)]
    assert avoiding and {abs(w) for _, w in avoiding} == {0.5}


def test_potential_field_is_stuck_in_traps_but_navigates_sparse_worlds():
    # The tutorial's local minimum: in a U or between twin obstacles the forces cancel. Stuck means
    # neither arriving nor colliding: it halts (or dithers) in front of the obstacle.
    stuck = sum(rollout(make_controller("potential_field"), generate("trap", seed), 400).outcome == "timeout"
                for seed in range(10))
    reached = sum(rollout(make_controller("potential_field"), generate("sparse", seed)).outcome == "success"
                  for seed in range(10))
    assert stuck >= 8
    assert reached >= 8


def test_potential_field_halts_in_front_of_a_trap():
    episode = rollout(make_controller("potential_field"), generate("trap", 0), 400)
    assert episode.outcome == "timeout"
    # Not wandering off either: it ends up between start and goal, short of the goal.
    scenario = generate("trap", 0)
    final = episode.poses[-1]
    assert math.dist(final[:2], scenario.goal) < math.dist(scenario.start[:2], scenario.goal)
    assert math.dist(final[:2], scenario.goal) > 1.0


def test_pid_infers_its_step_time_from_the_readings():
    # A world stepping 0.05 s, not the default 0.1 s, so a step time taken for granted shows.
    scenario = single_circle(5.15).model_copy(update={"world": WorldSpec(step_time=0.05)})
    given = rollout(make_controller("pid_blend", {"step_time": 0.05}), scenario)
    inferred = rollout(make_controller("pid_blend"), scenario)
    np.testing.assert_allclose(np.array(inferred.commands), np.array(given.commands), atol=1e-9)
    assumed = rollout(make_controller("pid_blend", {"step_time": 0.1}), scenario)
    n = min(len(assumed.commands), len(given.commands))
    assert not np.allclose(np.array(assumed.commands[:n]), np.array(given.commands[:n]))


def test_pid_integral_is_bounded_and_reset():
    # Turning to a goal behind, unsaturated: the integral grows past 0.02 within 40 steps unless clamped.
    controller = make_controller("pid_blend", {"integral_limit": 0.02})
    rollout(controller, Scenario(start=(5.0, 5.0, 0.0), goal=(2.0, 5.5)), max_steps=40)
    assert abs(controller._integral) == pytest.approx(0.02)
    controller.reset()
    assert controller._integral == 0.0


@pytest.mark.parametrize("name", list(CONTROLLERS))
def test_controllers_read_the_odometry_not_the_true_pose(name):
    scenario = Scenario(start=(5.0, 5.0, 0.0), goal=(8.0, 5.0))
    controller = make_controller(name)
    controller.bind(scenario.robot, scenario.lidar)
    controller.reset()
    readings = World(scenario).reset()
    # The true pose says the goal is straight ahead; the odometry says the robot already stands on it.
    fooled = readings._replace(odometry=Odometry(Pose2D(8.0, 5.0, 0.0), 0.0, 0.0))
    assert controller.act(fooled, scenario.goal) == (0.0, 0.0)


def test_every_parameter_has_a_default_and_round_trips():
    for name, cls in CONTROLLERS.items():
        parameters = controller_parameters(cls)
        assert parameters, name
        defaults = {key: default for key, (_, default) in parameters.items()}
        controller = make_controller(name, defaults)
        assert isinstance(controller, cls) and controller.name == name
        for key, default in defaults.items():
            assert getattr(controller, key) == default


def test_integer_values_are_accepted_for_float_parameters():
    controller = make_controller("go_to_goal", {"k_angular": 3})
    assert controller.k_angular == 3.0 and isinstance(controller.k_angular, float)


@pytest.mark.parametrize("name, params, field, problem", [
    ("teleport", None, "controllers.teleport", "unknown controller; allowed: go_to_goal, reactive"),
    ("reactive", {"clearence": 0.4}, "controllers.reactive.clearence", "unknown parameter; allowed: k_linear"),
    ("pid_blend", {"kp": "fast"}, "controllers.pid_blend.kp", "got 'fast'; allowed: a finite number"),
    ("pid_blend", {"kp": True}, "controllers.pid_blend.kp", "allowed: a finite number"),
    ("pid_blend", {"step_time": [0.1]}, "controllers.pid_blend.step_time", "allowed: a finite number or null"),
    ("potential_field", {"k_rep": float("nan")}, "controllers.potential_field.k_rep", "allowed: a finite number"),
    ("go_to_goal", {"turn_in_place": "yes"}, "controllers.go_to_goal.turn_in_place", "allowed: true/false"),
    ("go_to_goal", [0.5], "controllers.go_to_goal", "expected a mapping of parameters"),
])
def test_bad_parameters_are_one_line_config_errors(name, params, field, problem):
    with pytest.raises(ConfigError) as caught:
        make_controller(name, params, source="run.yaml")
    error = caught.value
    assert error.source == "run.yaml" and error.field == field and problem in error.problem
    assert "\n" not in str(error) and str(error).startswith(f"run.yaml: {field}: ")



@pytest.mark.parametrize("name", list(CONTROLLERS))
@pytest.mark.parametrize("threshold", [0.1, 0.5])
def test_every_controller_drives_into_the_scenarios_goal_radius(name, threshold):
    from common.evaluation import run_episode

    # The goal off the start's heading: the controller must turn, then close in on it.
    scenario = Scenario(start=(1.0, 2.0, 0.0), goal=(8.0, 7.0), goal_threshold=threshold)
    episode = run_episode(make_controller(name), scenario, max_steps=400)
    assert episode.outcome == "success", (name, episode)


def test_dwa_weighs_only_arcs_the_robot_can_drive():
    """Its window ran over [0, v_max] x [-w_max, w_max]: with v_min above 0 it chose a turn on the
    spot, which the robot drove as a step forward (into the wall it faced)."""
    robot = RobotProfile(v_max=0.6, v_min=0.2, w_max=1.0, w_min=-0.3, accel_v=2.0, accel_w=5.0)
    scenario = single_circle().model_copy(update={"robot": robot})
    dwa = make_controller("dwa")
    dwa.bind(robot, scenario.lidar)
    dwa.reset()
    v, w = dwa.window(World(scenario, seed=0).reset())
    assert v.min() == pytest.approx(0.2) and v.max() <= 0.6 and w.min() == pytest.approx(-0.3) and w.max() <= 1.0
