"""Movers in flatland: routes, behaviours, sensing, contact and the collision modes.

Each test builds a small scenario whose outcome is known by hand: a mover on a patrol passes its
waypoints at its speed, the lidar sees it, touching it is a collision (who moved into whom told
apart), and each collision mode halts what IR-SIM's halts.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.errors import ConfigError
from common.motion.spec import Dash, Motion, Orca, Sfm
from common.scenario import (BoxObstacle, CircleObstacle, LidarSpec, RobotProfile, Scenario, SegmentObstacle, WorldSpec,
                             scenario_from_mapping)
from flatland.world import World


def person(x: float, y: float, goals, speed: float = 1.0, **motion) -> CircleObstacle:
    return CircleObstacle(x=x, y=y, radius=0.25, motion=Motion(behavior=motion.pop("behavior", Dash()), goals=goals,
                                                               vel_max=(speed, speed), **motion))


def world_of(*obstacles, start=(1.0, 1.0, 0.0), mode="stop", **scenario) -> World:
    spec = WorldSpec(collision_mode=mode)
    return World(Scenario(world=spec, start=start, goal=(9.0, 1.0), obstacles=list(obstacles), **scenario), seed=0)


def positions(world: World, steps: int, command=(0.0, 0.0)) -> np.ndarray:
    world.reset()
    return np.array([world.step(*command).movers.rows[0, :2] for _ in range(steps)])


def test_a_dash_mover_moves_its_speed_once_a_step_until_it_arrives():
    world = world_of(person(2.0, 5.0, [(5.0, 5.0)], speed=1.0))
    path = positions(world, 40)
    steps = np.hypot(*np.diff(path, axis=0).T)
    np.testing.assert_allclose(steps[:25], 0.1, atol=1e-12)  # 1 m/s for 0.1 s: advanced once per step
    np.testing.assert_allclose(path[-1], (5.0, 5.0), atol=0.1)  # within its goal threshold, it stops
    assert np.all(steps[-5:] == 0.0)


@pytest.mark.parametrize("kinematics", ["diff", "omni"])
def test_an_rvo_mover_of_a_project_scenario_walks_to_its_goal(kinematics):
    """Stepped in Python (IR-SIM's rvo), it indexed an IR-SIM world's polygons, which a project
    world has none of: every command on the file ended in an IndexError."""
    from common.motion.spec import Rvo

    world = world_of(person(5.0, 3.0, [(5.0, 5.5)], speed=0.5, behavior=Rvo(), kinematics=kinematics))
    path = positions(world, 80)
    assert np.hypot(*(path[-1] - (5.0, 5.5))) < 0.2 < np.hypot(*(path[0] - (5.0, 5.5)))


@pytest.mark.parametrize(("route", "visits"), [
    ("once", [(4, 5), (4, 8)]),
    ("loop", [(4, 5), (4, 8), (4, 5), (4, 8)]),
    ("back_and_forth", [(4, 5), (4, 8), (4, 5), (2, 5), (4, 5)]),
])
def test_a_patrol_visits_its_waypoints_in_order(route, visits):
    world = world_of(person(2.0, 5.0, [(4.0, 5.0), (4.0, 8.0)], speed=1.0, route=route, goal_threshold=0.05))
    path = positions(world, 250)
    reached = []
    for x, y in path:
        near = [v for v in [(4, 5), (4, 8), (2, 5)] if math.hypot(x - v[0], y - v[1]) < 0.06]
        if near and (not reached or reached[-1] != near[0]):
            reached.append(near[0])
    assert reached[:len(visits)] == visits
    if route == "once":
        assert reached == visits


@pytest.mark.parametrize("goals", [[(6.0, 5.0)], []], ids=["a-first-goal", "goals-drawn-from-the-start"])
def test_a_wanderer_draws_its_goals_from_the_episode_seed(goals):
    # Without goals its first is drawn at reset (before, its route was empty: every step crashed).
    region = (1.0, 1.0, 9.0, 9.0)
    world = world_of(person(5.0, 5.0, goals, wander=region, goal_threshold=0.2))

    def drive(seed: int) -> np.ndarray:
        world.reset(seed=seed)
        return np.array([world.step(0.0, 0.0).movers.rows[0, :2] for _ in range(300)])

    first, again, other = drive(3), drive(3), drive(4)
    assert np.array_equal(first, again)
    assert not np.array_equal(first, other)
    assert np.hypot(*(first.max(axis=0) - first.min(axis=0))) > 3.0  # it went on to new goals
    assert np.all((first >= 1.0 - 1e-9) & (first <= 9.0 + 1e-9))


def test_the_lidar_sees_a_mover_coming():
    # A person walks at the robot along the x axis; the beam straight ahead (37 beams all round
    # have one) shortens by 0.1 m a step.
    world = world_of(person(4.0, 1.0, [(1.5, 1.0)], speed=1.0), lidar=LidarSpec(beams=37))
    scenario = world.scenario
    ahead = int(np.argmin(np.abs(scenario.lidar.beam_angles())))
    world.reset()
    ranges = [world.step(0.0, 0.0).lidar[ahead] for _ in range(5)]
    np.testing.assert_allclose(np.diff(ranges), -0.1, atol=1e-9)
    np.testing.assert_allclose(ranges[0], 4.0 - 0.1 - 1.0 - 0.25, atol=1e-9)


def test_a_mover_walking_into_the_robot_is_its_collision():
    world = world_of(person(3.0, 1.0, [(0.5, 1.0)], speed=1.0), mode="unobstructed_obstacles")
    world.reset()
    for _ in range(30):
        readings = world.step(0.0, 0.0)
        if readings.collided:
            break
    assert readings.contact.kind == "mover" and readings.contact.by == "mover" and readings.contact.mover == 0


def test_the_robot_driving_into_a_standing_mover_is_its_collision():
    standing = CircleObstacle(x=3.0, y=1.0, radius=0.25, motion=Motion(goals=[(3.0, 1.0)]))
    world = world_of(standing)
    world.reset()
    for _ in range(30):
        readings = world.step(1.0, 0.0)
        if readings.collided:
            break
    assert readings.contact == ("mover", 0, "robot")
    assert readings.pose.x == pytest.approx(3.0 - 0.45, abs=0.1)


def test_who_moved_into_whom_is_judged_at_the_robots_outline_turning_and_sideways_included():
    from common.readings import mover_fault

    disc, box = RobotProfile(radius=0.2), RobotProfile(shape="box", length=1.2, width=0.4)
    # A forklift turning in place at the end of its patrol: its centre still, its end sweeping
    # into a robot that stands still (a tie of two zero speeds once blamed the robot).
    turning = np.array([2.0, 1.0, 0.5, 0.0, 0.0, 0.58, 1.0, 0.6])
    assert mover_fault((1.0, 1.0, 0.0), (0.0, 0.0, 0.0), turning, disc) == "mover"
    # The reverse: a long robot turning in place sweeps its front end into a person standing beside it.
    standing = np.array([1.5, 1.5, 0.0, 0.0, 0.0, 0.25, 0.0, 0.0])
    assert mover_fault((1.0, 1.0, 0.0), (0.0, 0.0, 1.0), standing, box) == "robot"
    assert mover_fault((1.0, 1.0, 0.0), (0.0, 0.0, -1.0), standing, box) == "mover"  # turning away from it
    # An omnidirectional robot sliding left at 1 m/s into a person creeping toward it at 0.1 m/s.
    creeping = np.array([1.0, 2.0, 0.0, 0.0, -0.1, 0.25, 0.0, 0.0])
    assert mover_fault((1.0, 1.0, 0.0), (0.0, 1.0, 0.0), creeping, disc) == "robot"
    assert mover_fault((1.0, 1.0, 0.0), (0.0, 0.0, 0.0), creeping, disc) == "mover"


def test_an_omnidirectional_robot_sliding_into_a_person_is_its_collision():
    # The world passes the robot's sideways speed on to the judgement (a person creeping towards it).
    creeping = CircleObstacle(x=5.0, y=6.0, radius=0.25, motion=Motion(goals=[(5.0, 4.0)], vel_max=(0.1, 0.1)))
    world = World(Scenario(robot=RobotProfile(kinematics="omni"), start=(5.0, 5.0, 0.0), goal=(9.0, 1.0),
                           obstacles=[creeping]), seed=0)
    world.reset()
    for _ in range(30):
        readings = world.step(0.0, 1.0)  # forward 0, left 1 m/s
        if readings.collided:
            break
    assert readings.contact == ("mover", 0, "robot")


def test_in_stop_mode_a_mover_halts_on_touching_a_wall_and_otherwise_passes_through():
    wall = SegmentObstacle(points=[(5.0, 3.0), (5.0, 7.0)])

    def end(mode: str) -> float:
        world = world_of(wall, person(3.0, 5.0, [(7.0, 5.0)]), mode=mode)
        return positions(world, 60)[-1, 0]

    assert end("stop") == pytest.approx(5.0 - 0.25, abs=0.1)
    assert end("unobstructed") == pytest.approx(7.0, abs=0.1)
    assert end("unobstructed_obstacles") == pytest.approx(7.0, abs=0.1)  # an obstacle's role passes on


def test_in_stop_mode_movers_that_meet_halt_and_otherwise_pass_through_each_other():
    def ends(mode: str) -> np.ndarray:
        world = world_of(person(3.0, 5.0, [(7.0, 5.0)]), person(7.0, 5.0, [(3.0, 5.0)]), mode=mode)
        world.reset()
        for _ in range(60):
            rows = world.step(0.0, 0.0).movers.rows
        return rows[:, 0]

    np.testing.assert_allclose(ends("stop"), [5.0 - 0.25, 5.0 + 0.25], atol=0.1)  # face to face, halted
    np.testing.assert_allclose(ends("unobstructed"), [7.0, 3.0], atol=0.1)
    # A forklift's side brushing a person standing beside its path: its long box touches, not its centre.
    forklift = BoxObstacle(x=2.0, y=5.0, length=2.0, width=0.5,
                           motion=Motion(behavior=Dash(), goals=[(7.0, 5.0)], vel_max=(1.0, 1.0)))
    world = world_of(forklift, person(5.0, 5.45, [(5.0, 5.45)], speed=0.0))
    world.reset()
    for _ in range(50):
        rows = world.step(0.0, 0.0).movers.rows
    assert 5.0 - 1.0 - 0.25 <= rows[0, 0] <= 5.0 - 1.0  # its front halts as it reaches the person


def test_unobstructed_obstacles_halts_movers_whose_role_is_robot():
    wall = SegmentObstacle(points=[(5.0, 3.0), (5.0, 7.0)])
    world = world_of(wall, person(3.0, 5.0, [(7.0, 5.0)], role="robot"), mode="unobstructed_obstacles")
    assert positions(world, 60)[-1, 0] == pytest.approx(5.0 - 0.25, abs=0.1)


def test_the_robot_passes_through_things_when_unobstructed_and_says_it_touched():
    world = world_of(BoxObstacle(x=3.0, y=1.0, length=0.5, width=1.0), mode="unobstructed")
    world.reset()
    readings = [world.step(1.0, 0.0) for _ in range(40)]
    assert readings[-1].pose.x == pytest.approx(5.0, abs=1e-9)  # straight through
    assert any(r.collided for r in readings) and not readings[-1].collided


def test_a_forklift_turns_round_at_the_ends_of_its_aisle():
    motion = Motion(behavior=Dash(angle_tolerance=0.05), goals=[(7.0, 5.0)], route="back_and_forth", kinematics="diff",
                    vel_max=(1.0, 1.5), vel_min=(0.0, -1.5), goal_threshold=0.2, label="forklift")
    world = world_of(BoxObstacle(x=3.0, y=5.0, length=1.0, width=0.6, motion=motion), mode="unobstructed_obstacles")
    world.reset()
    rows = np.array([world.step(0.0, 0.0).movers.rows[0] for _ in range(200)])
    assert rows[:, 0].max() > 6.7 and rows[40:, 0].min() < 3.3  # there and back again
    assert np.all(np.abs(rows[:, 1] - 5.0) < 0.4)  # along its aisle, arcing round at its ends (IR-SIM's dash)
    assert np.all(rows[:, 3] * np.cos(rows[:, 2]) + rows[:, 4] * np.sin(rows[:, 2]) >= -1e-9)  # never reversing


@pytest.mark.parametrize("sees", [True, False])
def test_a_driver_who_sees_the_robot_in_the_lane_stops_short_of_it_and_a_blind_one_does_not(sees):
    def forklift(start_y: float) -> BoxObstacle:
        motion = Motion(behavior=Dash(yield_distance=1.0), goals=[(9.0, start_y)], kinematics="diff",
                        vel_max=(1.0, 1.5), vel_min=(0.0, -1.5), reacts_to_robot=sees, label="forklift")
        return BoxObstacle(x=1.0, y=start_y, length=1.0, width=0.6, motion=motion)

    world = world_of(forklift(5.0), forklift(5.8), start=(5.0, 5.0, 0.0), mode="unobstructed_obstacles")
    world.reset()
    steps = [world.step(0.0, 0.0) for _ in range(100)]
    front = np.array([r.movers.rows[:, 0] for r in steps]) + 0.5
    if sees:  # the lane's forklift waits, its front about a metre short of the robot (0.2 m radius)
        assert 5.0 - 0.2 - 1.3 <= front[-1, 0] <= 5.0 - 0.2 - 0.8
        assert np.all(front[-50:, 0] == front[-1, 0]) and not any(r.collided for r in steps)
    else:
        assert any(r.contact.by == "mover" for r in steps if r.collided)
    assert front[-1, 1] - 0.5 == pytest.approx(9.0, abs=0.15)  # the one beside the lane (0.8 m off) drives past


@pytest.mark.parametrize("behavior", [Orca(neighbor_dist=4.0, time_horizon=2.0), Sfm(vmax=1.0, force_factor_social=10.0,
                                                                                   safety_radius=0.3, lambda_importance=1.0)])
def test_people_who_see_the_robot_go_round_it_and_blind_ones_walk_into_it(behavior):
    def crash(reacting: bool) -> bool:
        walker = person(1.0, 5.0, [(9.0, 5.0)], behavior=behavior, group="people", reacts_to_robot=reacting)
        world = world_of(walker, start=(5.0, 5.0, 0.0), mode="unobstructed_obstacles")
        world.reset()
        return any(world.step(0.0, 0.0).collided for _ in range(120))

    assert not crash(True) and crash(False)


@pytest.mark.parametrize(("motion", "message"), [
    ({"goals": [[float("nan"), 1.0]]}, "obstacles.0.motion.goals.0.0: Input should be a finite number"),
    ({"goals": [[12.0, 1.0]]}, "obstacles.0.motion.goals.0: (12, 1) lies outside the world"),
    ({"goals": [[2.0, 1.0]], "vel_max": [11.0, 1.0]},
     "obstacles.0.motion.vel_max.0: Input should be less than or equal to 10"),
    ({"goals": [[2.0, 1.0]], "vel_min": [1.0, 0.0], "vel_max": [0.5, 1.0]}, "vel_min [1.0, 0.0] exceeds vel_max"),
    ({}, "a motion needs goals or a wander region"),
    ({"wander": [5.0, 5.0, 11.0, 9.0]}, "obstacles.0.motion.wander: [5.0, 5.0, 11.0, 9.0] reaches outside the world"),
    ({"goals": [[2.0, 1.0]], "behavior": {"name": "teleport"}},
     "obstacles.0.motion.behavior.name: 'teleport'; allowed: dash, rvo, orca, sfm"),
    # RVO's candidates are a 0.05 m/s grid over the limits: 1e6 asked for petabytes at the first step.
    ({"goals": [[2.0, 1.0]], "behavior": {"name": "rvo", "vxmax": 1e6}},
     "obstacles.0.motion.behavior.vxmax: Input should be less than or equal to 10"),
    ({"goals": [[2.0, 1.0]], "behavior": {"name": "rvo", "acce": 21.0}},
     "obstacles.0.motion.behavior.acce: Input should be less than or equal to 20"),
])
def test_bad_motions_are_one_line_errors_naming_the_field(motion, message):
    data = {"obstacles": [{"type": "circle", "x": 5.0, "y": 5.0, "radius": 0.3, "motion": motion}]}
    with pytest.raises(ConfigError) as error:
        scenario_from_mapping(data, "world.yaml")
    text = str(error.value)
    assert message in text and "\n" not in text and text.startswith("world.yaml: ")


def test_too_many_movers_and_mixed_groups_are_refused():
    walker = {"type": "circle", "x": 5.0, "y": 5.0, "radius": 0.1, "motion": {"goals": [[5.0, 6.0]]}}
    with pytest.raises(ConfigError, match="501 moving obstacles; allowed: at most 500"):
        scenario_from_mapping({"obstacles": [walker] * 501})
    orca = {**walker, "motion": {"goals": [[5.0, 6.0]], "behavior": {"name": "orca"}, "group": "g"}}
    sfm = {**walker, "motion": {"goals": [[5.0, 6.0]], "behavior": {"name": "sfm"}, "group": "g"}}
    with pytest.raises(ConfigError, match="the movers of group 'g' differ"):
        scenario_from_mapping({"obstacles": [orca, sfm]})


@pytest.mark.parametrize(("kind", "options"), [("crowd", {"behavior": "sfm"}), ("crowd", {"behavior": "orca"}),
                                               ("warehouse_moving", {})])
def test_a_reset_starts_the_same_episode_again_from_the_same_start_and_a_new_one_from_another(kind, options):
    # Movers who see the robot: a social-force crowd, an ORCA one, forklifts (boxes) and people.
    from common.generators import generate
    from common.motion.movers import Movers

    crowd = generate(kind, 0, 1.0, "eval", reacting=True, **options)

    def episode(movers: Movers, pose) -> np.ndarray:
        """What the first readings see (states, the lidar's circles and boxes), then the movers' poses each step."""
        rng = np.random.default_rng(0)  # the wanderers' next goals
        movers.reset(pose, rng)
        seen = [movers.states().rows.ravel(), *(rows.copy().ravel() for rows in movers.visible())]
        for k in range(60):
            movers.finish((pose[0] + 0.02 * k, pose[1], pose[2]), 0.2, 0.0, False, rng)
            seen.append(movers.states().rows[:, :3].ravel())
        return np.concatenate(seen)

    here, there = (1.0, 1.0, 0.0), (5.0, 5.0, 0.0)
    movers = Movers(crowd)
    first = episode(movers, here)
    assert np.array_equal(episode(movers, here), first)  # the same start again
    elsewhere = episode(movers, there)
    assert np.array_equal(elsewhere, episode(Movers(crowd), there))
    assert not np.array_equal(elsewhere, first)
    assert np.array_equal(episode(movers, here), first)


def test_a_project_file_moves_its_wanderers_as_its_scenario_does_in_any_world(tmp_path):
    # The movers draw from a stream of their own: loaded from its file or built from its scenario,
    # and whatever else the world draws from the seed (its sensors' noise here), a seed moves the
    # wanderers alike. (An IR-SIM file's draw from the generator its parse drew from, as IR-SIM's.)
    import flatland

    scenario = world_of(person(5.0, 5.0, [(6.0, 5.0)], wander=(1.0, 1.0, 9.0, 9.0), goal_threshold=0.2)).scenario
    scenario = scenario.model_copy(update={"lidar": scenario.lidar.model_copy(update={"noise_std": 0.05})})
    path = tmp_path / "wanderer.yaml"
    path.write_text(scenario.to_yaml())

    def path_of(world) -> np.ndarray:
        world.reset()
        return np.array([world.step(0.0, 0.0).movers.rows[0, :2] for _ in range(200)])

    assert np.array_equal(path_of(flatland.load_world(path, seed=3)), path_of(World(scenario, seed=3)))


def test_a_crowds_social_force_sums_every_pair_within_reach_in_the_batched_order():
    # The group's plan passes over pairs beyond reach before computing them: the sums must be
    # those of every pair, each pushing both ways, in IR-SIM's batched order, to the bit.
    from common.generators import generate
    from common.motion.movers import Movers
    from common.motion.sfm import NEIGHBOR_THRESHOLD, pair_force
    from common.motion.table import OVX, OVY, OX, OY, ROW

    movers = Movers(generate("crowd", 0, 1.0, "eval", reacting=True, behavior="sfm"))
    movers.reset((1.0, 1.0, 0.0), np.random.default_rng(0))
    t = movers.table
    members = movers._members[0]
    states = [t.objects[t.I[m, ROW], [OX, OY, OVX, OVY]] for m in members]
    reach = t.params[members[0], NEIGHBOR_THRESHOLD]
    distances = [math.dist(a[:2], b[:2]) for k, a in enumerate(states) for b in states[k + 1:]]
    assert sum(0.5 * reach < d <= reach for d in distances) >= 10 and sum(d > reach for d in distances) >= 10
    for a, m in enumerate(members):
        expected = np.zeros(2)
        for c, other in enumerate(members):
            if c != a:
                first, second = (a, c) if a < c else (c, a)
                fx, fy, counts = pair_force(*states[first], *states[second], t.params[members[first]], False)
                if counts:
                    expected += (fx, fy) if a < c else (-fx, -fy)
        assert tuple(movers._neighbors[a, :2]) == tuple(expected), f"member {a}"
