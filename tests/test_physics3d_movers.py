"""Movers in the 3D tier: moved by the shared code as flatland moves them, seen by the lidar and the
camera (each class its own segmentation label), and a contact with one told apart from a static one."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from common.conditions import Conditions
from common.errors import ConfigError
from common.generators import generate
from common.motion.movers import Movers, mover_generator
from common.motion.spec import Dash, Motion
from common.scenario import BoxObstacle, CircleObstacle, WorldSpec
from flatland.world import World as FlatWorld
from physics3d.movers import MovingBodies
from physics3d.robot import TEMPLATE
from physics3d.warehouse import SEGMENTATION_CLASSES
from physics3d.world import World

AS_BUILT = Conditions(lidar_noise=0.0, odometry_noise=0.0, motor_scale=(1.0, 1.0), friction=(1.0, 1.0),
                      mass_scale=(1.0, 1.0), heading_source="wheels", gyro_noise=0.0, gyro_bias=0.0, accel_noise=0.0)


def person(x: float, y: float, goal, speed: float = 1.0) -> CircleObstacle:
    return CircleObstacle(x=x, y=y, radius=0.25, height=1.7, motion=Motion(behavior=Dash(), goals=[goal],
                                                                          vel_max=(speed, speed)))


def forklift(x: float, y: float, goal) -> BoxObstacle:
    return BoxObstacle(x=x, y=y, length=1.0, width=0.6, height=2.0,
                       motion=Motion(behavior=Dash(), goals=[goal], vel_max=(0.5, 0.5), label="forklift"))


def world_of(*obstacles, **kwargs) -> World:
    """The 3D robot at (5, 5) facing +x among ``obstacles``, a beam every degree (the default 36
    beams, 10 degrees apart, pass either side of a person 4 m ahead)."""
    scenario = TEMPLATE.model_copy(update={"start": (5.0, 5.0, 0.0), "goal": (9.0, 9.0), "obstacles": list(obstacles),
                                           "lidar": TEMPLATE.lidar.model_copy(update={"beams": 360})})
    return World(scenario, conditions=AS_BUILT, **kwargs)


@pytest.mark.parametrize("suite", ["crowd_unaware", "warehouse_moving_unaware"])
def test_movers_blind_to_the_robot_move_in_3d_exactly_as_in_flatland(suite):
    # People wandering (their next goals drawn from the episode seed) and forklifts on patrol: with
    # the same commands both tiers move every one of them to the same bits, step for step, whatever
    # the 3D tier draws besides (its sensors' noise, the per-episode imperfections).
    kind = "crowd" if suite == "crowd_unaware" else "warehouse_moving"
    scenario = generate(kind, 4, 0.6, "eval", reacting=False)
    flat, solid = FlatWorld(scenario, seed=1, conditions=Conditions(robot="physics3d")), World(scenario, seed=1)
    first = flat.reset(seed=11).movers.rows, solid.reset(seed=11).movers.rows
    assert np.array_equal(*first)
    for _ in range(120):
        ours, theirs = flat.step(0.0, 0.4).movers.rows, solid.step(0.0, 0.4).movers.rows
        assert np.array_equal(ours[:, :3], theirs[:, :3])
        bodies = [p.getBasePositionAndOrientation(body, physicsClientId=solid.client) for body in solid.movers.bodies]
        np.testing.assert_allclose([(x, y, p.getEulerFromQuaternion(q)[2]) for (x, y, _), q in bodies], theirs[:, :3],
                                   atol=1e-9)  # and the bodies the sensors see are there
    assert np.hypot(*(ours[:, :2] - first[0][:, :2]).T).max() > 3.0  # they went somewhere


def test_a_wanderer_without_goals_draws_its_first_alike_in_both_tiers():
    # Its first goal is drawn at reset from the movers' stream, which both tiers seed alike.
    wanderer = CircleObstacle(x=2.0, y=2.0, radius=0.25, height=1.7,
                              motion=Motion(behavior=Dash(), wander=(1.0, 1.0, 4.0, 9.0), vel_max=(1.0, 1.0)))
    scenario = world_of(wanderer).scenario
    flat, solid = FlatWorld(scenario, seed=1, conditions=Conditions(robot="physics3d")), World(scenario, seed=1)
    ours, theirs = flat.reset(seed=7).movers.rows, solid.reset(seed=7).movers.rows
    for _ in range(100):
        ours, theirs = flat.step(0.0, 0.0).movers.rows, solid.step(0.0, 0.0).movers.rows
        assert np.array_equal(ours[:, :3], theirs[:, :3])
    assert math.dist(ours[0, :2], (2.0, 2.0)) > 1.0


def test_movers_that_see_the_robot_move_by_the_shared_code_from_its_3d_path(monkeypatch):
    # The 3D robot slips and sways, so its path is not flatland's; given its path, the movers that
    # react to it (people under the social force, yielding drivers) move as common.motion moves them.
    scenario = generate("warehouse_moving", 2, 0.6, "eval")
    inputs = []
    finish = MovingBodies.finish
    monkeypatch.setattr(MovingBodies, "finish", lambda self, pose, v, w, rng: (
        inputs.append((tuple(pose), v, w)), finish(self, pose, v, w, rng)))
    world = World(scenario, seed=0)
    start = world.reset(seed=5)
    seen = [world.step(0.6, 0.1 * math.sin(0.1 * k)).movers.rows for k in range(80)]
    replay, rng = Movers(world.scenario), mover_generator(5)  # the scenario as the 3D tier runs it: its robot
    replay.reset(start.pose, rng)
    for (pose, v, w), rows in zip(inputs, seen):
        replay.finish(pose, v, w, False, rng)
        assert np.array_equal(replay.states().rows, rows)
    assert len(inputs) == 80


def test_the_lidar_sees_a_person_coming():
    world = world_of(person(9.0, 5.0, (5.5, 5.0)))
    ahead = world.lidar.spec.beams // 2  # beams from -pi: the middle one looks half a degree left of ahead
    ranges = [world.reset().lidar[ahead]] + [world.step(0.0, 0.0).lidar[ahead] for _ in range(10)]
    np.testing.assert_allclose(np.diff(ranges), -0.1, atol=0.01)  # 1 m/s for 0.1 s a period
    assert ranges[0] == pytest.approx(9.0 - 0.25 - 5.0 - world.lidar.spec.offset[0], abs=0.03)


def test_the_camera_labels_people_and_forklifts_as_themselves():
    world = world_of(person(6.5, 5.3, (6.5, 5.3)), forklift(6.5, 4.4, (6.5, 4.4)), camera=True)
    segmentation = world.reset().camera["segmentation"]
    classes = world.warehouse.classes(segmentation)
    names = {SEGMENTATION_CLASSES[c] for c in np.unique(classes)}
    assert {"person", "forklift", "floor", "robot"} <= names
    person_column = np.flatnonzero((classes == SEGMENTATION_CLASSES.index("person")).any(axis=0))
    forklift_column = np.flatnonzero((classes == SEGMENTATION_CLASSES.index("forklift")).any(axis=0))
    assert person_column.mean() < forklift_column.mean()  # the person on the left (+y), the forklift right


def test_a_person_walking_into_the_robot_is_its_collision_and_the_persons_doing():
    world = world_of(person(7.0, 5.0, (4.0, 5.0)))
    world.reset()
    contacts = [world.step(0.0, 0.0).contact for _ in range(30)]
    assert next(c for c in contacts if c is not None) == ("mover", 0, "mover")


def test_driving_into_a_standing_forklift_is_the_robots_doing_and_into_a_box_static():
    world = world_of(forklift(7.0, 5.0, (7.0, 5.0)))
    world.reset()
    contacts = [world.step(0.5, 0.0).contact for _ in range(40)]
    assert next(c for c in contacts if c is not None) == ("mover", 0, "robot")
    world = world_of(BoxObstacle(x=7.0, y=5.0, length=1.0, width=0.6), person(2.0, 2.0, (2.0, 2.0)))
    world.reset()
    contacts = [world.step(0.5, 0.0).contact for _ in range(40)]
    assert next(c for c in contacts if c is not None) == ("static", -1, "robot")


def test_the_same_seed_gives_the_same_3d_episode_among_movers():
    scenario = generate("crowd", 1, 0.6, "eval")
    world = World(scenario, seed=0)

    def episode() -> np.ndarray:
        world.reset(seed=3)
        return np.array([np.concatenate([world.step(0.3, 0.2).movers.rows.ravel(), world.readings.lidar])
                         for _ in range(40)])

    assert np.array_equal(episode(), episode())


def test_a_collision_mode_the_3d_tier_does_not_model_is_one_line():
    scenario = TEMPLATE.model_copy(update={"world": WorldSpec(collision_mode="unobstructed")})
    with pytest.raises(ConfigError, match=r"world.collision_mode: 'unobstructed' is not modelled in the 3D tier"):
        World(scenario)
