"""Planning for the robot's own footprint: the discs that cover it, the poses and turns a grid
allows it, A* and RRT through gaps its bounding circle does not fit, and the pursuits driving a
rectangle through the ``passages`` kind."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.controllers import make_controller
from common.evaluation import run_episode
from common.generators import SUITES
from common.geometry import box_sdf, circle_sdf
from common.occupancy import OccupancyGrid, ScanMapper, inflate, scenario_grid
from common.planners import RRT, AStar, keep_clear, path_length, shortcut
from common.planners.footprint import SLACK, TURN_STEP, Footprint, FootprintGrid
from common.robots import robot_profile
from common.scenario import BoxObstacle, CircleObstacle, RobotProfile, Scenario, WorldSpec

WIDE = RobotProfile(shape="box", length=0.51, width=0.43, v_max=2.0, w_max=2.0)  # the fast rectangle
RESOLUTION = 0.05


def rectangle_points(robot: RobotProfile, x: float, y: float, yaw: float, spacing: float = 0.005) -> np.ndarray:
    """Points on the robot's rectangle at this pose: its perimeter every ``spacing`` metres and its centre."""
    half_l, half_w = 0.5 * robot.length, 0.5 * robot.width
    corners = np.array([(-half_l, -half_w), (half_l, -half_w), (half_l, half_w), (-half_l, half_w)])
    points = [np.zeros((1, 2))]
    for a, b in zip(corners, np.roll(corners, -1, axis=0)):
        n = int(math.ceil(np.hypot(*(b - a)) / spacing))
        points.append(a + (b - a) * np.linspace(0.0, 1.0, n, endpoint=False)[:, None])
    local = np.vstack(points)
    c, s = math.cos(yaw), math.sin(yaw)
    return np.column_stack([x + c * local[:, 0] - s * local[:, 1], y + s * local[:, 0] + c * local[:, 1]])


def true_clearance(scenario: Scenario, robot: RobotProfile, x: float, y: float, yaw: float) -> float:
    """The rectangle's distance to the nearest obstacle, measured on the obstacles' exact shapes."""
    points = rectangle_points(robot, x, y, yaw)
    least = math.inf
    for obstacle in scenario.obstacles:
        if isinstance(obstacle, CircleObstacle):
            least = min(least, float(circle_sdf(points, obstacle.x, obstacle.y, obstacle.radius).min()))
        else:
            least = min(least, float(box_sdf(points, obstacle.x, obstacle.y, obstacle.length, obstacle.width,
                                             obstacle.yaw).min()))
    return least


def driven_poses(path: np.ndarray, heading: float | None) -> list[tuple[float, float, float]]:
    """The poses a robot takes driving the path as planned: straight along each segment every
    centimetre, and turning on the spot at each vertex, headings a degree apart."""
    poses = []
    previous = heading
    for a, b in zip(path[:-1], path[1:]):
        yaw = math.atan2(b[1] - a[1], b[0] - a[0])
        if previous is not None:
            turn = math.remainder(yaw - previous, 2 * math.pi)
            poses += [(a[0], a[1], previous + turn * t) for t in np.linspace(0.0, 1.0, max(2, int(abs(turn) / 0.017)))]
        n = max(2, int(math.ceil(np.hypot(*(b - a)) / 0.01)))
        poses += [(*(a + (b - a) * t), yaw) for t in np.linspace(0.0, 1.0, n)]
        previous = yaw
    return poses


def gap_world(gap: float, robot: RobotProfile) -> Scenario:
    """A 6 x 4 m world cut by a wall of two boxes across x = 3, open ``gap`` metres wide about y = 2."""
    half = 0.5 * gap
    wall = [BoxObstacle(x=3.0, y=0.5 * (2.0 - half), length=0.2, width=2.0 - half, yaw=0.0),
            BoxObstacle(x=3.0, y=4.0 - 0.5 * (2.0 - half), length=0.2, width=2.0 - half, yaw=0.0)]
    return Scenario(world=WorldSpec(width=6.0, height=4.0, walls=False), robot=robot, obstacles=wall,
                    start=(1.0, 1.2, 0.0), goal=(5.0, 2.8))


def obstacle_cells(scenario: Scenario) -> OccupancyGrid:
    """Every cell an obstacle touches, and some beside (centres within half a diagonal of one): a
    map of the obstacles' returns marks fewer."""
    return scenario_grid(scenario, RESOLUTION, inflation=RESOLUTION * math.sqrt(0.5))


@pytest.mark.parametrize("robot", [WIDE, robot_profile("physics3d"), RobotProfile(shape="box", length=0.2, width=0.6),
                                   RobotProfile(shape="box", length=1.2, width=0.3)], ids=str)
def test_the_discs_cover_the_rectangle_and_stay_near_its_half_width(robot):
    footprint = Footprint.of(robot)
    inside = np.random.default_rng(0).uniform(-0.5, 0.5, (4000, 2)) * (robot.length, robot.width)
    corners = 0.5 * np.array([(1, 1), (1, -1), (-1, 1), (-1, -1)]) * (robot.length, robot.width)
    points = np.vstack([inside, corners])
    gaps = np.hypot(*(points[:, None] - footprint.centres[None]).transpose(2, 0, 1)) - footprint.radii[None]
    assert (gaps.min(axis=1) <= 1e-9).all(), "a point of the footprint lies outside every disc"
    assert footprint.radii.max() <= SLACK * 0.5 * min(robot.length, robot.width) + 1e-12
    assert not footprint.turns_freely


def test_a_circle_is_its_own_disc_and_turns_freely():
    footprint = Footprint.of(RobotProfile(radius=0.25))
    assert footprint.turns_freely and footprint.radii.tolist() == [0.25]


def test_a_rectangle_stands_in_a_gap_head_on_that_its_bounding_circle_does_not_fit():
    long = RobotProfile(shape="box", length=0.7, width=0.43)  # 0.82 m across its bounding circle
    scenario = gap_world(0.62, long)
    grid = FootprintGrid(obstacle_cells(scenario), Footprint.of(long))
    assert grid.pose_free(3.0, 2.0, 0.0)  # head-on through the gap
    assert not grid.pose_free(3.0, 2.0, 0.5 * math.pi)  # across it: 0.7 m in a 0.62 m gap
    assert not grid.turn_free(3.0, 2.0, 0.0, 0.5)  # turning there swings the corners into the wall
    inflated = OccupancyGrid(inflate(obstacle_cells(scenario).occupied, long.bounding_radius, RESOLUTION),
                             (0.0, 0.0), RESOLUTION)
    assert not inflated.is_free(3.0, 2.0)
    assert true_clearance(scenario, long, 3.0, 2.0, 0.0) > 0.0
    assert true_clearance(scenario, long, 3.0, 2.0, 0.5 * math.pi) < 0.0


@pytest.mark.parametrize("planner", [AStar(), RRT(seed=0, max_iterations=20000), RRT(seed=0, optimise=True)],
                         ids=["astar", "rrt", "rrt_star"])
def test_a_plan_threads_the_gap_and_every_pose_driven_along_it_clears_the_true_obstacles(planner):
    scenario = gap_world(1.5 * WIDE.width, WIDE)
    grid = FootprintGrid(obstacle_cells(scenario), Footprint.of(WIDE), margin=0.01)
    heading = 0.0
    path = planner.plan(grid, (*scenario.start[:2], heading), scenario.goal)
    assert path is not None
    path = shortcut(grid, path, heading)
    assert grid.path_free(path, heading)
    clearances = [true_clearance(scenario, WIDE, *pose) for pose in driven_poses(path, heading)]
    assert min(clearances) > 0.0
    # The bounding circle finds no way at all.
    inflated = OccupancyGrid(inflate(obstacle_cells(scenario).occupied, WIDE.bounding_radius, RESOLUTION),
                             (0.0, 0.0), RESOLUTION)
    assert AStar().plan(inflated, scenario.start[:2], scenario.goal) is None


def corridors_through_a_room(width: float, room: float, resolution: float = 0.025) -> OccupancyGrid:
    """Walls everywhere but a corridor ``width`` wide east along y = 1 into a square room ``room``
    across about (4, 1), and another leaving it north along x = 4."""
    cells = int(round(6.0 / resolution))
    rows, cols = np.indices((cells, cells))
    x, y = (cols + 0.5) * resolution, (rows + 0.5) * resolution
    east = (np.abs(y - 1.0) < 0.5 * width) & (x > 0.5) & (x < 4.0)
    north = (np.abs(x - 4.0) < 0.5 * width) & (y > 1.0) & (y < 5.5)
    square = (np.abs(x - 4.0) < 0.5 * room) & (np.abs(y - 1.0) < 0.5 * room)
    return OccupancyGrid(~(east | north | square), (0.0, 0.0), resolution)


@pytest.mark.parametrize("planner", [AStar(), RRT(seed=0), RRT(seed=0, optimise=True)], ids=["astar", "rrt", "rrt_star"])
def test_a_rectangle_that_cannot_turn_in_the_room_between_two_corridors_is_not_planned_through_it(planner):
    # It drives each corridor head-on (0.43 m in 0.52 m) and stands in the 0.6 m room facing
    # either way, but turning there takes 0.67 m (its bounding circle; 0.66 m at 45 degrees).
    cells = corridors_through_a_room(0.52, 0.6)
    wide = FootprintGrid(cells, Footprint.of(WIDE))
    assert wide.pose_free(4.0, 1.0, 0.0) and wide.pose_free(4.0, 1.0, 0.5 * math.pi)
    start, goal = (1.2, 1.0, 0.0), (4.0, 5.0)
    assert planner.plan(wide, start, goal) is None
    small = FootprintGrid(cells, Footprint.of(RobotProfile(shape="box", length=0.35, width=0.3)))
    path = planner.plan(small, start, goal)
    assert path is not None and small.path_free(shortcut(small, path, 0.0), 0.0)


def test_a_rectangle_is_measured_against_the_cells_beside_it_not_its_discs():
    """Beside the rectangle's long side the discs stick out 1.6 cm; the rectangle itself decides,
    keeping half a cell's diagonal from an occupied cell's centre (its obstacle may reach the corner)."""
    footprint = Footprint.of(WIDE)
    for offset, free in ((0.05, True), (0.02, False)):
        occupied = np.zeros((40, 40), dtype=bool)
        occupied[20, 20] = True  # centre (1.025, 1.025)
        grid = FootprintGrid(OccupancyGrid(occupied, (0.0, 0.0), RESOLUTION), footprint)
        y = 1.025 - 0.5 * WIDE.width - offset
        assert grid.clearance(1.025, y, 0.0) < 0.0  # the discs alone would refuse both
        assert grid.pose_free(1.025, y, 0.0) is free, offset


def test_what_lies_off_the_grid_counts_as_occupied():
    grid = FootprintGrid(OccupancyGrid(np.zeros((40, 40), dtype=bool), (0.0, 0.0), RESOLUTION), Footprint.of(WIDE))
    assert grid.pose_free(1.0, 1.0, 0.0)
    assert not grid.pose_free(0.27, 1.0, 0.0)  # its back 1.5 cm off the grid
    assert grid.clearance(0.5, 1.0, 0.5 * math.pi) < 0.5 - 0.5 * WIDE.width  # the edge is 0.5 m away


def test_a_turn_is_checked_at_headings_a_few_degrees_apart():
    # A post just off the rectangle's corner sweep: clear at both ends of a 90 degree turn, hit in the middle.
    robot = RobotProfile(shape="box", length=0.6, width=0.2)
    post = CircleObstacle(x=0.25, y=0.25, radius=0.05)
    scenario = Scenario(world=WorldSpec(width=2.0, height=2.0, offset=(-1.0, -1.0), walls=False), robot=robot,
                        obstacles=[post], start=(0.0, 0.0, 0.0), goal=(0.8, 0.8))
    grid = FootprintGrid(scenario_grid(scenario, 0.01, inflation=0.01 * math.sqrt(0.5)), Footprint.of(robot))
    assert grid.pose_free(0.0, 0.0, 0.0) and grid.pose_free(0.0, 0.0, 0.5 * math.pi)
    assert not grid.turn_free(0.0, 0.0, 0.0, 0.5 * math.pi)
    assert TURN_STEP <= math.radians(20)


def two_gaps(robot: RobotProfile) -> Scenario:
    """An 8 x 6 m world cut by a wall across x = 4: a gap two robot widths across on the straight
    line from the start to the goal, and one 2 m wide 3 m off it."""
    narrow = 2.0 * robot.width_across

    def wall(y0: float, y1: float) -> BoxObstacle:
        return BoxObstacle(x=4.0, y=0.5 * (y0 + y1), length=0.2, width=y1 - y0, yaw=0.0)

    return Scenario(world=WorldSpec(width=8.0, height=6.0, walls=False), robot=robot,
                    obstacles=[wall(0.0, 1.5 - 0.5 * narrow), wall(1.5 + 0.5 * narrow, 3.5), wall(5.5, 6.0)],
                    start=(1.0, 1.5, 0.0), goal=(7.0, 1.5))


@pytest.mark.parametrize("seed", range(3))
def test_rrt_pursuit_plans_the_shorter_of_two_gaps_whatever_its_seed(seed):
    """Its planner refines the route over its whole budget (informed RRT*): plain RRT returned the
    first route its tree found, most seeds through the wide gap (8.6-11.6 m), another each replan."""
    robot = robot_profile("physics3d")
    scenario = two_gaps(robot)
    grid = FootprintGrid(obstacle_cells(scenario), Footprint.of(robot), margin=0.02)
    pursuit = make_controller("rrt_pursuit", {"seed": seed})
    pursuit.reset()
    for _ in range(2):  # a replan, on fresh samples, agrees
        path = pursuit.planner.plan(grid, scenario.start, scenario.goal)
        assert path is not None and grid.path_free(path, 0.0)
        assert path_length(path) < 6.1  # the straight 6 m through the narrow gap


@pytest.mark.parametrize("optimise", [False, True])
def test_rrt_plans_from_a_heading_that_keeps_no_margin_where_another_does(optimise):
    """A robot standing closer than the margin to a return facing its way (as a follower ends up
    in a tight gap) may still face another: checking the turn from its own heading refused every
    edge, and the pursuit stood still for the rest of the episode."""
    robot = robot_profile("physics3d")
    occupied = np.zeros((80, 80), dtype=bool)
    occupied[40, 44] = True  # its centre 0.075 m ahead of the robot at (2, 2) facing +x, 0.105 m beside it facing +y
    grid = FootprintGrid(OccupancyGrid(occupied, (0.0, 0.0), RESOLUTION), Footprint.of(robot), margin=0.05)
    assert not grid.pose_free(2.0, 2.0, 0.0) and grid.pose_free(2.0, 2.0, 0.5 * math.pi)
    path = RRT(seed=0, optimise=optimise).plan(grid, (2.0, 2.0, 0.0), (2.0, 3.5))
    assert path is not None and grid.path_free(path)


def test_keep_clear_moves_a_path_off_a_post_and_keeps_it_free():
    scenario = Scenario(world=WorldSpec(width=6.0, height=4.0, walls=False), robot=WIDE,
                        obstacles=[CircleObstacle(x=3.0, y=2.4, radius=0.075)], start=(0.5, 2.0, 0.0), goal=(5.5, 2.0))
    grid = FootprintGrid(obstacle_cells(scenario), Footprint.of(WIDE), margin=0.01)
    straight = np.array([scenario.start[:2], scenario.goal])
    assert grid.path_free(straight)
    before = min(grid.clearance(x, y, 0.0) for x, y in zip(np.linspace(0.5, 5.5, 101), np.full(101, 2.0)))
    moved = keep_clear(grid, straight, 0.3)
    assert grid.path_free(moved)
    assert (moved[0] == straight[0]).all() and (moved[-1] == straight[-1]).all()
    after = min(true_clearance(scenario, WIDE, *pose) for pose in driven_poses(moved, None))
    assert after > before + 0.1
    assert path_length(moved) < path_length(straight) + 0.5


def test_the_mapper_names_the_cells_it_marks():
    mapper = ScanMapper((0.0, 0.0, 2.0, 2.0), 0.5)
    points = np.array([(0.1, 0.1), (1.9, 0.6), (2.2, 0.6), (5.0, 5.0)])
    rows, cols, keep = mapper.cells_of(points)
    assert rows.tolist() == [0, 1, 1, 3] and cols.tolist() == [0, 3, 3, 3] and keep.tolist() == [True, True, True, False]
    mapper.add_points(points)
    assert mapper.hits[1, 3] == 2 and mapper.hits.sum() == 3


@pytest.mark.parametrize("name", ["astar_pursuit", "rrt_pursuit"])
def test_the_pursuits_drive_a_fast_rectangle_through_passages(name):
    """Three held-out ``passages`` layouts for the 0.51 x 0.43 m robot at 2 m/s: gaps down to 0.52 m,
    its bounding circle 0.67 m across."""
    template = Scenario(robot=WIDE)
    scenarios = list(SUITES["passages"].scenarios(3, 0, template=template))
    for seed, scenario in enumerate(scenarios):
        result = run_episode(make_controller(name), scenario.model_copy(update={"goal_threshold": 0.1}), "flatland",
                             seed=seed, max_steps=500)
        assert result.outcome == "success", (scenario.name, result.outcome)


def test_an_astar_plan_ends_where_the_footprint_can_drive_its_last_step():
    # The lattice checks the footprint into the goal cell's centre; the exact goal put in its place
    # bent the last step, unchecked, into boxes beside it (in five of these plans).
    ended_at_a_centre = 0
    for seed in range(100, 200):
        rng = np.random.default_rng(seed)
        occupied = np.zeros((80, 80), bool)
        for _ in range(20):
            row, col = rng.integers(0, 80, 2)
            occupied[row:row + rng.integers(1, 6), col:col + rng.integers(1, 6)] = True
        grid = FootprintGrid(OccupancyGrid(occupied, (0.0, 0.0), RESOLUTION), Footprint.of(WIDE))
        start = (rng.uniform(0.5, 3.5), rng.uniform(0.5, 3.5), rng.uniform(-math.pi, math.pi))
        goal = (rng.uniform(0.5, 3.5), rng.uniform(0.5, 3.5))
        path = AStar().plan(grid, start, goal)
        if path is None or len(path) < 4:
            continue
        assert grid.path_free(path[-3:]), seed  # the turn onto the last step (from a lattice step), and the step
        assert math.dist(path[-1], goal) <= RESOLUTION / math.sqrt(2)  # the goal, or its cell's centre
        ended_at_a_centre += math.dist(path[-1], goal) > 0.0
    assert ended_at_a_centre > 0  # the case arose
