"""The route on the static map (common.route): through the gaps the robot fits, around those it
does not; read by the ``lidar51_route`` layout and the ``route_progress`` reward, and given to a
policy by the evaluator as the env gives it in training."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import flatland  # noqa: F401
from common.evaluation import start_agent
from common.kinematics import Pose2D
from common.observations import make_layout
from common.readings import Imu, Odometry, Readings
from common.route import Route
from common.scenario import BoxObstacle, LidarSpec, Scenario

ROBOT = {"shape": "box", "length": 0.3, "width": 0.24}  # the 3D robot's footprint: 0.24 m across


def _fence(gap: float, gap_at: float = 7.0, yaw: float = 0.0) -> Scenario:
    """A world 10 x 10 m cut by a fence at x = 5 with one gap of ``gap`` metres centred at
    y = ``gap_at``; start (heading ``yaw``) and goal either side of it at y = 1."""
    low, high = gap_at - 0.5 * gap, gap_at + 0.5 * gap
    fence = [BoxObstacle(x=5.0, y=0.5 * low, length=0.2, width=low)]
    if high < 10.0:
        fence.append(BoxObstacle(x=5.0, y=0.5 * (high + 10.0), length=0.2, width=10.0 - high))
    return Scenario(world={"width": 10.0, "height": 10.0}, robot=ROBOT, start=(1.0, 1.0, yaw), goal=(9.0, 1.0),
                    obstacles=fence)


def test_the_route_goes_through_a_gap_the_robot_fits_and_its_cost_falls_along_it():
    route = Route(_fence(1.2 * 0.24), goal_radius=0.1)
    # The straight line is 8 m; the route climbs to the gap at y = 7 and back: at least 2 x hypot(4, 6).
    assert 2 * math.hypot(4.0, 6.0) <= route.distance(1.0, 1.0) < 1.15 * 2 * math.hypot(4.0, 6.0)
    x, y, costs = 1.0, 1.0, []
    for _ in range(100):
        costs.append(route.distance(x, y))
        x, y = route.ahead(x, y, 0.25)
        if (x, y) == route.goal:
            break
    assert (x, y) == route.goal
    assert all(later < earlier for earlier, later in zip(costs, costs[1:]))
    # Through a gap's middle, not along its edge: where the route meets a fence 0.6 m wide.
    wide = Route(_fence(0.6), goal_radius=0.1)
    x, y = 1.0, 1.0
    while x < 5.0:
        x, y = wide.ahead(x, y, 0.05)
    assert abs(y - 7.0) < 0.1  # at the edge of its open cells it would pass 0.19 m off the middle


def test_a_gap_narrower_than_the_robot_is_closed_and_an_unreachable_goal_reads_its_distance():
    route = Route(_fence(0.8 * 0.24), goal_radius=0.1)
    assert not math.isfinite(route.field[route.grid.cell_of(1.0, 1.0)])
    assert route.distance(1.0, 1.0) == pytest.approx(8.0)
    assert route.ahead(1.0, 1.0, 1.0) == route.goal  # nothing to follow: the goal itself


def _readings(x: float, y: float, yaw: float) -> Readings:
    pose = Pose2D(x, y, yaw)
    return Readings(pose=pose, velocity=(0.0, 0.0), odometry=Odometry(pose, 0.0, 0.0), lidar=np.full(36, 5.0),
                    imu=Imu((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)), collided=False, time=0.0)


def test_lidar51_route_reads_the_route_point_ahead_in_the_robots_frame_or_the_goal_without_one():
    scenario = _fence(0.6)
    layout = make_layout("lidar51_route", scenario.robot, LidarSpec())
    assert layout.space.shape == (51,) and layout.reads_route
    readings = _readings(1.0, 1.0, 0.5 * math.pi)  # facing +y, the goal to its right
    without = layout(readings, scenario.goal)
    assert without[49:] == pytest.approx([0.0, -1.0], abs=1e-6)  # 8 m to the right, clipped to 1
    np.testing.assert_array_equal(without[:49], make_layout("lidar49_robot", scenario.robot, LidarSpec())(
        readings, scenario.goal))
    route = Route(scenario, 0.1)
    layout.follow(route)
    ahead = route.ahead(1.0, 1.0, 1.0)
    obs = layout(readings, scenario.goal)
    # The route climbs toward the gap: mostly ahead (+y is forward), a little right (+x).
    assert obs[49] == pytest.approx(ahead[1] - 1.0, abs=1e-6) and obs[50] == pytest.approx(-(ahead[0] - 1.0), abs=1e-6)
    assert obs[49] > 0.5 and obs[50] < 0.0  # not at the goal, 8 m to its right
    layout.reset()  # a new episode forgets the last one's route
    np.testing.assert_array_equal(layout(readings, scenario.goal), without)


def test_the_env_plans_each_episodes_route_and_pays_route_progress_by_it():
    # Heading down and right: closer to the goal, farther from the gap at y = 7 the route takes.
    env = gym.make("flatland/Nav-v0", world=_fence(0.6, yaw=-0.25 * math.pi), observation="lidar51_route",
                   reward={"route_progress": 1.0, "progress": 0.0}, goal_threshold=0.1).unwrapped
    obs, _ = env.reset(seed=0)
    route = env._route
    assert route is not None and route.goal == (9.0, 1.0)
    x, y, yaw = env.readings.odometry.pose
    ahead = route.ahead(x, y, 1.0)
    assert obs[49] == pytest.approx(math.cos(yaw) * (ahead[0] - x) + math.sin(yaw) * (ahead[1] - y), abs=1e-5)
    before = route.distance(x, y)
    _, reward, _, _, info = env.step(np.array([1.0, 0.0], dtype=np.float32))  # full speed ahead
    after = route.distance(*env.readings.pose[:2])
    assert reward == pytest.approx(before - after) and reward < -0.03
    assert info["distance"] < math.dist((1.0, 1.0), (9.0, 1.0)) - 0.03  # what ``progress`` would have paid for
    env.reset(seed=1)
    assert env._route is route  # the same world's route is planned once


class _Follower:
    name, reads_route = "follower", True

    def __init__(self) -> None:
        self.calls: list[str] = []

    def bind(self, robot, lidar, goal_threshold) -> None:
        self.calls.append("bind")

    def reset(self) -> None:
        self.calls.append("reset")

    def follow(self, route: Route) -> None:
        self.calls.append("follow")
        self.route = route


def test_the_evaluator_gives_an_agent_that_reads_a_route_the_route_the_env_trains_with():
    scenario = _fence(0.6)
    agent = _Follower()
    start_agent(agent, scenario, 0.1)
    assert agent.calls == ["bind", "reset", "follow"]
    trained = Route(scenario, 0.1)
    np.testing.assert_array_equal(agent.route.field, trained.field)
    agent.reads_route = False
    agent.calls.clear()
    start_agent(agent, scenario, 0.1)
    assert agent.calls == ["bind", "reset"]


def test_the_boundary_walls_close_and_cost_as_obstacles_do():
    walled = Scenario(world={"width": 10.0, "height": 4.0}, robot=ROBOT, start=(0.5, 0.15, 0.0), goal=(9.5, 0.15))
    route = Route(walled, goal_radius=0.1)
    x, y = 0.5, 0.15
    while x < 5.0:
        x, y = route.ahead(x, y, 0.05)
    assert y > 0.22  # away from the wall along the way (within a width of it a cell costs more)
    assert not math.isfinite(route.field[route.grid.cell_of(5.0, 0.05)])  # 5 cm from the wall: the robot does not fit
    # A centre a little inside the closed margin (odometry, a graze) still reads the route beside it.
    assert math.dist(route.ahead(5.0, 0.08, 1.0), (5.0, 0.08)) < 1.1
    assert route.distance(5.0, 0.08) == pytest.approx(route.distance(5.0, 0.15), abs=0.1)
    open_world = Route(walled.model_copy(update={"world": walled.world.model_copy(update={"walls": False})}), 0.1)
    assert math.isfinite(open_world.field[open_world.grid.cell_of(5.0, 0.05)])


def test_the_cost_to_go_between_cell_centres_is_interpolated_not_stepped():
    steps = np.arange(0.0, 0.1, 0.001)  # four cells of 0.024 m, in the open along a straight route
    for goal, line in (((9.5, 2.0), lambda t: (3.0 + t, 2.0)), ((5.0, 3.5), lambda t: (5.0, 1.0 + t))):
        walled = Scenario(world={"width": 10.0, "height": 4.0}, robot=ROBOT, start=(0.5, 2.0, 0.0), goal=goal)
        route = Route(walled, goal_radius=0.1)
        costs = np.array([route.distance(*line(t)) for t in steps])
        assert np.all(np.diff(costs) < 0.0)  # nearer the goal at every millimetre, within a cell as across cells
        np.testing.assert_allclose(np.diff(costs), -0.001, rtol=0.05)
