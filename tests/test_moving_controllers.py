"""The scan tracker on synthetic scans, and the mover-aware controllers (dwa, orca) among people."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.controllers import make_controller
from common.controllers.base import LidarGeometry
from common.controllers.dwa import clearances
from common.controllers.tracking import Scene, ScanTracker, blobs
from common.controllers.velocity_obstacle import nearest_admissible, orca_half_planes
from common.evaluation import run_episode
from common.generators import generate
from common.motion.spec import Dash, Motion
from common.scenario import CircleObstacle, LidarSpec, Scenario
from tests.conftest import optional

STEP = 0.1  # s


def cast(geometry: LidarGeometry, pose: tuple[float, float, float], discs=(), walls=()) -> np.ndarray:
    """The ranges a lidar at ``pose`` reads among discs (x, y, r) and wall segments ((x, y), (x, y))."""
    angles = pose[2] + geometry.relative_angles
    direction = np.column_stack([np.cos(angles), np.sin(angles)])
    origin = np.array(pose[:2])
    ranges = np.full(len(angles), geometry.spec.range_max)
    for x, y, r in discs:
        to_centre = np.array([x, y]) - origin
        along = direction @ to_centre
        square = along**2 - (to_centre @ to_centre - r * r)
        t = np.where(square >= 0.0, along - np.sqrt(np.abs(square)), np.inf)
        ranges = np.minimum(ranges, np.where(t > 0.0, t, np.inf))
    for a, b in walls:
        a, edge = np.array(a, float), np.subtract(b, a)
        cross = direction[:, 0] * edge[1] - direction[:, 1] * edge[0]
        to_a = a - origin
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (to_a[0] * edge[1] - to_a[1] * edge[0]) / cross
            u = (to_a[0] * direction[:, 1] - to_a[1] * direction[:, 0]) / cross
        ranges = np.minimum(ranges, np.where((t > 0.0) & (u >= 0.0) & (u <= 1.0), t, np.inf))
    return ranges


def crossing_disc(beams: int, steps: int = 25):
    """A stationary lidar's scenes of a 0.25 m disc crossing 1.5 m in front of it at (0, 0.8) m/s."""
    geometry = LidarGeometry(LidarSpec(beams=beams))
    tracker = ScanTracker(geometry)
    velocity, start = np.array([0.0, 0.8]), np.array([1.5, -1.2])
    for k in range(steps):
        centre = start + velocity * k * STEP
        pose = (0.0, 0.0, 0.0)
        yield centre, velocity, tracker.update(cast(geometry, pose, [(*centre, 0.25)]), pose, k * STEP)


@pytest.mark.parametrize("beams, tolerance", [(36, 0.25), (360, 0.15)])
def test_a_disc_moving_at_a_known_velocity_is_tracked_at_that_velocity(beams, tolerance):
    scenes = list(crossing_disc(beams))
    assert all(len(scene.centres) == 0 for _, _, scene in scenes[:2])  # one scan carries no velocity
    for centre, velocity, scene in scenes[8:]:
        assert len(scene.centres) == 1
        assert np.hypot(*(scene.velocities[0] - velocity)) < tolerance
        assert np.hypot(*(scene.centres[0] - centre)) < 0.25
        assert len(scene.static) == 0  # its returns are the mover's, not obstacles where it was


def test_tracking_is_deterministic():
    first, second = list(crossing_disc(36)), list(crossing_disc(36))
    for (_, _, a), (_, _, b) in zip(first, second):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("drive", ["along", "turning"])
def test_a_wall_driven_past_is_no_mover(drive):
    # The robot drives 1 m from a wall at 1 m/s, or turns on the spot at 1 rad/s. At grazing angles
    # the hits lie further apart than a blob's gap: single-return fragments whose point slides
    # along the wall as the beams move, at up to the robot's speed or range x turn rate.
    geometry = LidarGeometry(LidarSpec())
    tracker = ScanTracker(geometry)
    walls = [((-20.0, 1.0), (20.0, 1.0)), ((-20.0, -3.0), (20.0, -3.0))]
    slid = 0.0
    for k in range(40):
        pose = (k * STEP, 0.0, 0.0) if drive == "along" else (0.0, 0.0, k * STEP)
        scene = tracker.update(cast(geometry, pose, walls=walls), pose, k * STEP)
        assert len(scene.centres) == 0, (k, scene.centres, scene.velocities)
        slid = max(slid, float(np.hypot(*tracker.tracks.velocity.T).max(initial=0.0)))
    # The filter did see fragments slide; only the evidence rule keeps them from being movers.
    assert slid > 0.5


def test_dwa_clearances_are_each_arc_point_s_gap_to_the_nearest_return_and_predicted_mover():
    rng = np.random.default_rng(3)
    points, times = rng.uniform(-3.0, 3.0, (9, 12, 2)), 0.1 * np.arange(1, 13)
    scene = Scene(static=rng.uniform(-4.0, 4.0, (360, 2)), centres=rng.uniform(-3.0, 3.0, (4, 2)),
                  velocities=rng.uniform(-1.0, 1.0, (4, 2)), radii=rng.uniform(0.2, 0.4, 4))
    static, movers = clearances(points, scene, times, 0.2)
    # By hand, every point against every return, and every mover moved to the point's time.
    to_returns = np.hypot(*(points[:, :, None, :] - scene.static).transpose(3, 0, 1, 2)).min(axis=2)
    ahead = scene.centres[None] + times[:, None, None] * scene.velocities[None]  # (T, K, 2)
    to_movers = (np.hypot(*(points[:, :, None, :] - ahead[None]).transpose(3, 0, 1, 2)) - scene.radii).min(axis=2)
    assert np.array_equal(static, to_returns - 0.2) and np.array_equal(movers, to_movers - 0.2)
    empty = Scene(np.empty((0, 2)), np.empty((0, 2)), np.empty((0, 2)), np.empty(0))
    assert np.isinf(clearances(points, empty, times, 0.2)).all()


def test_a_blob_that_vanishes_is_dropped_after_a_few_steps():
    geometry = LidarGeometry(LidarSpec())
    tracker = ScanTracker(geometry)  # max_misses 3
    pose, disc = (0.0, 0.0, 0.0), [(1.5, 0.3, 0.25)]
    counts = []
    for k in range(10):
        tracker.update(cast(geometry, pose, disc if k < 5 else []), pose, k * STEP)
        counts.append(len(tracker.tracks.position))
    assert counts == [1, 1, 1, 1, 1, 1, 1, 1, 0, 0]  # unseen from step 5: kept for 3 misses, gone at the 4th


def test_blobs_are_runs_of_linked_hits_and_wrap_round_a_closed_scan():
    links = np.array([True, False, False, True, True, False, True, True])
    hit = np.array([True, True, False, True, True, True, True, True])
    # 0-1 linked; 3-4-5 linked; 6-7-0-1 linked across the seam (link 7 joins beam 7 to beam 0).
    assert [run.tolist() for run in blobs(links, hit)] == [[3, 4, 5], [6, 7, 0, 1]]


@pytest.mark.parametrize("side", [1.0, -1.0])
@pytest.mark.parametrize("mover_velocity", [(0.0, 0.0), (-0.5, 0.0)])
def test_orca_turns_the_velocity_out_of_the_obstacle_the_short_way(side, mover_velocity):
    # Heading at 1 m/s for a disc 2 m ahead, a little to one side: the velocity kept is the one
    # nearest the preferred that clears it for the horizon, passing on the side away from it.
    offset, radius, horizon = np.array([[2.0, 0.2 * side]]), 0.5, 2.0
    velocity = np.array([1.0, 0.0])
    points, directions = orca_half_planes(velocity, offset, np.array([mover_velocity]), np.array([radius]),
                                          np.array([horizon]), STEP, 1.0)
    angles = np.linspace(-math.pi, math.pi, 721)
    candidates = np.concatenate([s * np.column_stack([np.cos(angles), np.sin(angles)]) for s in (0.5, 0.75, 1.0)])
    chosen = nearest_admissible(velocity, points, directions, np.zeros(1, bool), candidates)
    assert chosen[1] * side < 0.0  # away from the obstacle's side
    times = np.linspace(0.0, horizon, 201)[:, None]
    relative = offset + times * (np.array(mover_velocity) - chosen)
    assert np.hypot(*relative.T).min() >= radius - 0.02
    assert np.hypot(*(chosen - velocity)) < 0.6  # the least change, not an about-turn


def person(start: tuple[float, float], goal: tuple[float, float], speed: float = 1.0) -> CircleObstacle:
    """A person walking straight from ``start`` to ``goal``, blind to the robot."""
    return CircleObstacle(x=start[0], y=start[1], radius=0.3,
                          motion=Motion(behavior=Dash(), goals=[goal], vel_max=(speed, speed), reacts_to_robot=False))


# The robot drives (1, 5) -> (9, 5); at full speed it reaches x = 5 after 4 s, when the person does y = 5.
CROSSINGS = {
    "from the right": Scenario(start=(1.0, 5.0, 0.0), goal=(9.0, 5.0), obstacles=[person((5.0, 1.0), (5.0, 9.0))]),
    "from the left": Scenario(start=(1.0, 5.0, 0.0), goal=(9.0, 5.0), obstacles=[person((5.0, 9.0), (5.0, 1.0))]),
    "head on": Scenario(start=(1.0, 5.0, 0.0), goal=(9.0, 5.0), obstacles=[person((8.5, 5.0), (0.5, 5.0), 0.8)]),
}


def smallest_gap(name: str, scenario: Scenario, **params) -> tuple[str, float]:
    """The outcome of an episode and the smallest gap between the robot and the person (m)."""
    log = []
    episode = run_episode(make_controller(name, params), scenario, max_steps=300, on_step=log.append)
    gap = min(math.dist(r.pose[:2], r.movers.rows[0, :2]) - scenario.robot.radius - 0.3 for r in log)
    return episode.outcome, gap


@pytest.mark.parametrize("case", list(CROSSINGS))
def test_go_to_goal_walks_into_the_person(case):
    assert smallest_gap("go_to_goal", CROSSINGS[case])[0] == "collision"


@pytest.mark.parametrize("name", ["dwa", "orca"])
@pytest.mark.parametrize("case", list(CROSSINGS))
def test_dwa_and_orca_let_the_person_pass(name, case):
    outcome, gap = smallest_gap(name, CROSSINGS[case])
    assert outcome == "success" and gap > 0.1


@pytest.mark.parametrize("name", ["dwa", "orca"])
def test_the_controllers_forget_their_tracks_and_map_every_episode(name):
    controller = make_controller(name)
    run_episode(controller, CROSSINGS["from the right"], max_steps=30)
    assert len(controller.tracker.history) and controller.planner.evidence is not None
    controller.reset()
    assert len(controller.tracker.tracks.position) == 0 and not controller.tracker.history
    assert controller.planner.evidence is None and controller.planner.previous is None


@pytest.mark.parametrize("name", ["dwa", "orca"])
def test_the_same_controllers_drive_the_3d_robot(name):
    optional("pybullet")
    episode = run_episode(make_controller(name), generate("cluttered", 0), tier="physics3d", max_steps=400)
    assert episode.outcome == "success"
