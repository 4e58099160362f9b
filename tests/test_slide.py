"""Movers that slide along walls (``static_contact: slide``): the geometry of one step, the
generated people who never enter walls or shelves, and IR-SIM's movers, which pass through."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.errors import ConfigError
from common.generators import SUITES, generate
from common.irsim_export import fixed_routes, passing, scenario_to_irsim
from common.geometry import box_distance, segment_distance
from common.motion.slide import CLEARANCE, slide_out
from common.motion.step import _touches_static
from common.motion.table import static_contacts
from common.scenario import Scenario
from flatland.world import World

NO_CIRCLES, NO_BOXES, NO_SEGMENTS = np.zeros((0, 3)), np.zeros((0, 6)), np.zeros((0, 4))
FLOOR = np.array([[0.0, 0.0, 4.0, 0.0]])  # a wall along y = 0


def test_a_step_into_a_wall_keeps_the_part_along_it():
    # From 0.25 m off the wall a step of (0.1, -0.1) would end 0.05 m into a 0.2 m body's reach.
    x, y = slide_out(1.1, 0.15, 0.2, 1.0, 0.25, NO_CIRCLES, NO_BOXES, FLOOR)
    assert x == pytest.approx(1.1, abs=1e-12)
    assert y == pytest.approx(0.2 + CLEARANCE, abs=1e-12)
    assert slide_out(1.1, 0.3, 0.2, 1.0, 0.4, NO_CIRCLES, NO_BOXES, FLOOR) == (1.1, 0.3)  # clear: untouched


def test_a_step_into_any_wall_post_or_shelf_slides_to_just_off_it():
    # Pushed out to exactly CLEARANCE, a body measured again read a rounding short about half the
    # time, and after the last pass its step was thrown away: people stood frozen at angled walls.
    rng = np.random.default_rng(0)
    r = 0.2
    for _ in range(600):
        angle = rng.uniform(-math.pi, math.pi)
        normal, along = np.array([math.cos(angle), math.sin(angle)]), np.array([-math.sin(angle), math.cos(angle)])
        centre = rng.uniform(2.0, 8.0, 2)  # each surface faces the body 1.5 m from here along the normal
        start = centre + normal * (1.5 + r + rng.uniform(0.001, 0.05))
        end = start - normal * rng.uniform(0.06, 0.15) + along * rng.uniform(-0.1, 0.1)  # 1 to 10 cm into reach
        wall = np.array([[*(centre + 1.5 * normal - 3 * along), *(centre + 1.5 * normal + 3 * along)]])
        post = np.array([[*centre, 1.5]])
        shelf = np.array([[*centre, *normal, 1.5, 0.05]])  # its end, 0.1 m wide, faces the body: a side or a corner
        for surfaces, gap in (((NO_CIRCLES, NO_BOXES, wall), lambda p: segment_distance(*p, *wall[0])),
                              ((post, NO_BOXES, NO_SEGMENTS), lambda p: math.dist(p, centre) - 1.5),
                              ((NO_CIRCLES, shelf, NO_SEGMENTS), lambda p: box_distance(*p, *centre, 3.0, 0.1, *normal))):
            x, y = slide_out(*end, r, *start, *surfaces)
            assert (x, y) != tuple(start)
            assert r < gap((x, y)) < r + 2 * CLEARANCE


def test_a_corner_pushes_out_of_both_walls_and_a_narrow_wedge_stops_the_step():
    walls = np.array([[0.0, 0.0, 4.0, 0.0], [0.0, 0.0, 0.0, 4.0]])
    x, y = slide_out(0.1, 0.12, 0.2, 0.3, 0.3, NO_CIRCLES, NO_BOXES, walls)
    assert (x, y) == pytest.approx((0.2 + CLEARANCE, 0.2 + CLEARANCE), abs=1e-12)
    wedge = np.array([[0.0, 0.0, 4.0, 0.0], [0.0, 0.0, 4.0, 2.0]])  # 27 degrees: pushes out of one lead into the other
    for to in [(0.8, 0.25), (0.7, 0.2), (1.0, 0.3)]:
        x, y = slide_out(*to, 0.2, 1.5, 0.5, NO_CIRCLES, NO_BOXES, wedge)
        assert min(segment_distance(x, y, *wall) for wall in wedge) >= 0.2


@pytest.mark.parametrize("yaw", [0.0, 0.7])
def test_a_centre_inside_a_box_leaves_by_the_nearer_side_and_a_post_pushes_radially(yaw):
    # Steps shorter than the radius never take a centre inside; a person placed there by a file does.
    c, s = math.cos(yaw), math.sin(yaw)
    box = np.array([[2.0, 1.5, c, s, 0.5, 0.3]])  # 1 x 0.6 m, centred (2, 1.5)
    u, v = 0.1, -0.2  # in the box's frame: 0.1 m from its long side, 0.4 m from its end
    x, y = 2.0 + c * u - s * v, 1.5 + s * u + c * v
    x, y = slide_out(x, y, 0.2, x, y, NO_CIRCLES, box, NO_SEGMENTS)
    assert c * (x - 2.0) + s * (y - 1.5) == pytest.approx(u, abs=1e-12)
    assert -s * (x - 2.0) + c * (y - 1.5) == pytest.approx(-(0.3 + 0.2 + CLEARANCE), abs=1e-12)
    post = np.array([[2.0, 1.5, 0.3]])
    x, y = slide_out(2.1, 1.1, 0.2, 2.1, 0.5, post, NO_BOXES, NO_SEGMENTS)
    assert math.hypot(x - 2.0, y - 1.5) == pytest.approx(0.5 + CLEARANCE)
    assert math.atan2(y - 1.5, x - 2.0) == pytest.approx(math.atan2(1.1 - 1.5, 2.1 - 2.0))


@pytest.mark.parametrize("suite", ["crowd", "warehouse_moving"])
def test_generated_people_never_enter_walls_shelves_or_crates(suite):
    # Before people slid, pushed sideways by the crowd they overlapped static geometry in 1.1%
    # (crowd) and 5.4% (warehouse_moving) of person-steps, the robot standing still: behind the
    # crossing corridors' walls and inside shelves' ends (40 scenarios each, 300 steps).
    overlapping = steps = 0
    for scenario in SUITES[suite].scenarios(12):
        circles, boxes, segments, rings, ring_index = static_contacts(scenario)
        world = World(scenario, seed=0)
        world.reset(seed=0)
        for _ in range(300):
            for x, y, theta, _, _, radius, length, _ in world.step(0.0, 0.0).movers.rows:
                if length == 0.0:  # a person (forklifts follow their aisles)
                    steps += 1
                    overlapping += _touches_static(0, x, y, theta, radius, 0.0, 0.0, circles, boxes, segments, rings,
                                                   ring_index)
    assert steps > 10_000
    assert overlapping == 0


def test_a_person_walking_into_a_wall_is_seen_standing():
    # Others (and the social figures) see the velocity it moved with, not the one it was given.
    person = {"type": "circle", "x": 5.0, "y": 9.6, "radius": 0.2, "motion": {"goals": [[5.0, 9.9]], "static_contact": "slide"}}
    world = World(Scenario.model_validate({"start": [1.0, 1.0, 0.0], "goal": [2.0, 1.0], "obstacles": [person]}), seed=0)
    world.reset(seed=0)
    for _ in range(10):
        row = world.step(0.0, 0.0).movers.rows[0]
    assert row[1] == pytest.approx(10.0 - 0.2 - CLEARANCE)
    assert abs(row[4]) < 1e-6


def test_slide_is_for_circles_and_irsim_refuses_it():
    cart = {"type": "box", "x": 5.0, "y": 5.0, "length": 1.0, "width": 0.5,
            "motion": {"goals": [[6.0, 6.0]], "static_contact": "slide"}}
    with pytest.raises(ValueError, match=r"obstacles\.0\.motion\.static_contact: slide keeps circle obstacles"):
        Scenario.model_validate({"obstacles": [cart]})
    runner = {"type": "circle", "x": 5.0, "y": 5.0, "radius": 0.2,
              "motion": {"goals": [[6.0, 6.0]], "static_contact": "slide", "kinematics": "diff", "vel_max": [2.5, 1.0]}}
    with pytest.raises(ValueError, match=r"obstacles\.0\.motion\.static_contact: slide needs a step shorter than "
                                         r"the radius 0\.2 m \(here 2\.5 m/s x 0\.1 s = 0\.25 m\)"):
        Scenario.model_validate({"obstacles": [runner]})  # a step past a thin wall's middle would leave on its far side
    crowd = generate("crowd", 2, 0.5, "eval", behavior="sfm")
    with pytest.raises(ConfigError, match=r"obstacles\.\d+\.motion\.static_contact: IR-SIM's movers pass through"):
        scenario_to_irsim(crowd)
    walkers = fixed_routes(crowd)  # a crowd IR-SIM can run: each person on its own route
    assert all(mover.motion.static_contact == "pass" for mover in walkers.movers)
    sliding = walkers.model_copy(update={"obstacles": [*walkers.static_obstacles, *(
        mover.model_copy(update={"motion": mover.motion.model_copy(update={"static_contact": "slide"})})
        for mover in walkers.movers)]})
    with pytest.raises(ConfigError, match="static_contact"):
        scenario_to_irsim(sliding)
    assert scenario_to_irsim(passing(sliding)) == scenario_to_irsim(walkers)
    assert passing(Scenario()) == Scenario()

