"""The ``passages`` kind: every gap of every band 1.2 to 2 robot widths across (the robot's own
width, not its bounding circle's), room to turn between bands, the goal beyond them and reachable,
for round and rectangular robots alike."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.generators import generate
from common.robots import robot_profile
from common.scenario import BoxObstacle, RobotProfile, Scenario

GAP = (1.2, 2.0)  # robot widths, as the kind promises
TURN_MARGIN = 0.3  # m between bands beyond the bounding circle's diameter
ROBOTS = {
    "default circle": RobotProfile(),
    "small circle": RobotProfile(radius=0.1),
    "3D robot": robot_profile("physics3d"),
    "wide rectangle": RobotProfile(shape="box", length=0.51, width=0.43, v_max=2.0),
}
WIDTHS = {"default circle": 0.4, "small circle": 0.2, "3D robot": robot_profile("physics3d").width, "wide rectangle": 0.43}


def _local(scenario: Scenario) -> tuple[np.ndarray, np.ndarray, float]:
    """Unit vectors along the route (start to goal, an axis) and across it, and the world's extent across."""
    start, goal = np.array(scenario.start[:2]), np.array(scenario.goal)
    along = np.zeros(2)
    axis = int(np.argmax(np.abs(goal - start)))
    along[axis] = np.sign((goal - start)[axis])
    across = np.array([-along[1], along[0]])
    extent = scenario.world.height if axis == 0 else scenario.world.width
    return along, across, extent


def _intervals(scenario: Scenario, along: np.ndarray, across: np.ndarray):
    """Each obstacle as (u_low, u_high, v_low, v_high) in the route's frame, v from the wall at 0."""
    origin = np.array(scenario.world.offset) + np.where(across < 0, [scenario.world.width, scenario.world.height], 0)
    rows = []
    for obstacle in scenario.obstacles:
        centre = np.array([obstacle.x, obstacle.y]) - origin
        u, v = float(centre @ along), float(centre @ np.abs(across)) if across.sum() > 0 else float(centre @ across)
        if isinstance(obstacle, BoxObstacle):
            half_u, half_v = 0.5 * obstacle.length, 0.5 * obstacle.width  # boxes are yawed along the route
        else:
            half_u = half_v = obstacle.radius
        rows.append((u - half_u, u + half_u, v - half_v, v + half_v))
    return np.array(rows)


def _gaps(band: np.ndarray, extent: float) -> np.ndarray:
    """The free lengths along a band: wall to first obstacle, between obstacles, last to wall."""
    band = band[np.argsort(band[:, 2])]
    return np.concatenate([[band[0, 2]], band[1:, 2] - band[:-1, 3], [extent - band[-1, 3]]])


def _bands(rows: np.ndarray, strip: float) -> list[np.ndarray]:
    """The obstacles grouped into bands: a new band where a free strip at least ``strip`` deep
    runs across the route (within a band, the obstacles' spans along the route interleave)."""
    order = rows[np.argsort(rows[:, 0])]
    bands, reach = [[order[0]]], order[0, 1]
    for row in order[1:]:
        if row[0] - reach >= strip - 1e-9:
            bands.append([])
        bands[-1].append(row)
        reach = max(reach, row[1]) if len(bands[-1]) > 1 else row[1]
    return [np.array(band) for band in bands]


@pytest.mark.parametrize("name", list(ROBOTS))
@pytest.mark.parametrize("difficulty", [0.0, 1.0])
def test_every_gap_is_1_2_to_2_robot_widths_and_the_bands_leave_room_to_turn(name, difficulty):
    robot = ROBOTS[name]
    width, reach = WIDTHS[name], 2.0 * robot.bounding_radius
    for seed in range(15):
        scenario = generate("passages", seed, difficulty, "eval", template=Scenario(robot=robot))
        along, across, extent = _local(scenario)
        rows = _intervals(scenario, along, across)
        # Bands apart by less than the turning strip would merge here, into fewer than two.
        bands = _bands(rows, strip=reach + TURN_MARGIN)
        assert 2 <= len(bands) <= 4, f"seed {seed}: {len(bands)} bands"
        for band in bands:
            gaps = _gaps(band, extent)
            open_gaps = gaps[gaps > 1e-9]  # a shelf reaching a wall leaves no gap there
            assert open_gaps.min() >= GAP[0] * width - 1e-9, f"seed {seed}: a gap of {open_gaps.min():.3f} m"
            assert open_gaps.max() <= GAP[1] * width + 1e-9, f"seed {seed}: a gap of {open_gaps.max():.3f} m"
        u_start = float((np.array(scenario.start[:2]) - np.array(scenario.world.offset)) @ along)
        assert all(u_start < band[:, 0].min() for band in bands) or all(u_start > band[:, 1].max() for band in bands)


def test_the_width_across_is_the_footprint_across_the_heading():
    assert [ROBOTS[name].width_across for name in WIDTHS] == pytest.approx(list(WIDTHS.values()))
    # The narrowest gaps are too narrow for a wide rectangle's bounding circle: what makes the kind
    # hard for planners that inflate by it.
    robot = ROBOTS["wide rectangle"]
    assert GAP[0] * robot.width_across < 2.0 * robot.bounding_radius


def test_a_robot_crosses_the_bands_to_the_goal_through_the_gaps():
    """A waypoint path straight across each band through a gap, turning in the strips between
    them, driven in flatland by the wide rectangle: no contact, and it arrives."""
    from flatland.world import World

    robot = ROBOTS["wide rectangle"]
    scenario = generate("passages", 4, 1.0, "eval", template=Scenario(robot=robot))
    along, across, extent = _local(scenario)
    rows = _intervals(scenario, along, across)
    bands = _bands(rows, strip=2 * robot.bounding_radius + TURN_MARGIN)
    origin = np.array(scenario.world.offset) + np.where(across < 0, [scenario.world.width, scenario.world.height], 0)
    frame = np.abs(across) if across.sum() > 0 else across

    def point(u: float, v: float) -> np.ndarray:
        return origin + u * along + v * frame

    goal_v = float((np.array(scenario.goal) - origin) @ frame)
    waypoints = []
    for band in bands:
        band = band[np.argsort(band[:, 2])]
        lows = np.concatenate([[0.0], band[:, 3]])
        centres = [low + 0.5 * gap for low, gap in zip(lows, _gaps(band, extent)) if gap > 1e-9]
        v = min(centres, key=lambda c: abs(c - goal_v))
        u_low, u_high = band[:, 0].min(), band[:, 1].max()
        waypoints += [point(u_low - 0.6, v), point(u_high + 0.6, v)]
    waypoints.append(np.array(scenario.goal))
    world = World(scenario)
    readings = world.reset()
    for target in waypoints:
        for _ in range(400):
            x, y, yaw = readings.pose
            bearing = math.atan2(target[1] - y, target[0] - x)
            error = math.remainder(bearing - yaw, 2 * math.pi)
            v = 0.0 if abs(error) > 0.05 else min(0.4, math.dist((x, y), target))
            readings = world.step(v, max(-1.0, min(1.0, 3.0 * error)))
            assert not readings.collided
            if math.dist(readings.pose[:2], target) < 0.05:
                break
    assert math.dist(readings.pose[:2], scenario.goal) < 0.1


def test_a_layout_the_robot_cannot_cross_is_redrawn_and_refused_in_the_end(monkeypatch):
    """The generator's own check on a fine grid (half the robot's width inflated): gaps drawn
    narrower than the robot never make a scenario."""
    from common import passages
    from common.errors import ConfigError

    monkeypatch.setattr(passages, "GAP", (0.6, 0.9))
    with pytest.raises(ConfigError, match="no reachable passages layout"):
        generate("passages", 0, 0.5, "eval")


def test_a_suite_is_laid_out_for_a_robot_its_layouts_may_not_fit():
    from common.curriculum.cli import _scenarios, build_parser
    from common.conditions import Conditions
    from common.generators import SUITES

    wide = ROBOTS["wide rectangle"]
    laid_out = list(SUITES["passages"].scenarios(2, robot=wide))
    assert all(scenario.robot == wide for scenario in laid_out)
    assert laid_out[0].obstacles != next(SUITES["passages"].scenarios(1)).obstacles
    # Other suites keep their one draw for a robot within the template's bounding circle, and lay
    # out their own for a wider one.
    small = robot_profile("physics3d")
    assert all(scenario.robot == RobotProfile() for scenario in SUITES["sparse"].scenarios(2, robot=small))
    assert all(scenario.robot == wide for scenario in SUITES["cluttered"].scenarios(2, robot=wide))
    # The CLI draws a passages suite for the robot of --env-kwargs.
    args = build_parser().parse_args(["eval", "--policy", "p.zip", "--suite", "passages", "--episodes", "2",
                                      "--world", "flatland", "--seed", "0"])
    conditions = Conditions.parse({"robot": {"shape": "box", "length": 0.51, "width": 0.43, "v_max": 2.0}})
    assert [s.obstacles for s in _scenarios(args, conditions=conditions)] == [s.obstacles for s in laid_out]
