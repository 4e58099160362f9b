"""The moving generator kinds: seeded, scaled by difficulty, reachable, and crowds that behave."""

from __future__ import annotations

import numpy as np
import pytest

from common.errors import ConfigError
from common.generators import SUITES, generate, get_suite
from common.moving_kinds import CLEAR_OF_ROBOT, crowd_size
from common.occupancy import goal_reachable
from flatland.world import World


@pytest.mark.parametrize("kind", ["crowd", "warehouse_moving"])
def test_layouts_are_seeded_valid_and_reachable(kind):
    for seed in range(40):
        scenario = generate(kind, seed, 0.5, "eval")
        assert scenario == generate(kind, seed, 0.5, "eval")
        scenario.check()  # start and goal in the world and clear of every obstacle's start
        assert goal_reachable(scenario), seed
        assert scenario.world.collision_mode == "unobstructed_obstacles"
        start = np.array(scenario.start[:2])
        for mover in scenario.movers:
            assert np.hypot(mover.x - start[0], mover.y - start[1]) >= CLEAR_OF_ROBOT, seed
    assert generate(kind, 1, 0.5, "train") != generate(kind, 1, 0.5, "eval")


def test_difficulty_sets_the_crowd_its_speed_and_who_sees_the_robot():
    assert crowd_size(0.5) == (12, pytest.approx(1.2))
    blind, fastest = {}, {}
    for difficulty in (0.0, 0.5, 0.75, 1.0):
        scenario = generate("crowd", 3, difficulty)
        people = scenario.movers
        assert len(people) == crowd_size(difficulty)[0]
        speeds = [max(p.motion.vel_max) for p in people]
        assert 0.5 <= min(speeds) and max(speeds) <= crowd_size(difficulty)[1] + 1e-9
        blind[difficulty] = np.mean([not p.motion.reacts_to_robot for p in people])
        fastest[difficulty] = max(speeds)
    # Nobody blind up to 0.5, then a growing share (each of the 16 at 0.75 with probability 0.5), all at 1.
    assert blind[0.0] == blind[0.5] == 0.0 and 0.25 <= blind[0.75] <= 0.75 and blind[1.0] == 1.0
    assert fastest[0.0] == 0.5 and fastest[1.0] > 1.5  # walkers up to 1.9 m/s at 1


def test_the_crowd_suites_are_twelve_people_seeing_the_robot_or_not():
    seeing, blind = next(get_suite("crowd").scenarios(count=1)), next(get_suite("crowd_unaware").scenarios(count=1))
    assert len(seeing.movers) == len(blind.movers) == 12
    assert all(p.motion.reacts_to_robot for p in seeing.movers) and not any(p.motion.reacts_to_robot for p in blind.movers)
    assert [(p.x, p.y) for p in seeing.movers] == [(p.x, p.y) for p in blind.movers]  # the same crowds
    assert {SUITES["warehouse_moving"].kind, SUITES["crowd_unaware"].kind} == {"warehouse_moving", "crowd"}


def test_a_warehouse_has_forklifts_on_patrol_and_people_crossing():
    scenario = generate("warehouse_moving", 5, 0.5)
    labels = sorted(m.motion.label for m in scenario.movers)
    assert labels == ["forklift"] * 2 + ["person"] * 4
    for forklift in (m for m in scenario.movers if m.motion.label == "forklift"):
        assert forklift.motion.route == "back_and_forth" and forklift.motion.behavior.yield_distance > 0.0


@pytest.mark.parametrize("suite, seeing", [("warehouse_moving", 1.0), ("warehouse_moving_unaware", 0.0)])
def test_the_warehouse_suites_have_drivers_and_people_who_see_the_robot_or_not(suite, seeing):
    movers = [m for s in get_suite(suite).scenarios(count=10) for m in s.movers]
    assert {m.motion.label for m in movers} == {"forklift", "person"}
    assert np.mean([m.motion.reacts_to_robot for m in movers]) == seeing
    blind_share = np.mean([not m.motion.reacts_to_robot for s in (generate("warehouse_moving", seed, 0.75)
                                                                   for seed in range(40)) for m in s.movers])
    assert 0.3 < blind_share < 0.7  # half of them at difficulty 0.75


def test_options_are_checked():
    with pytest.raises(ConfigError, match="speed: not an option of the crowd kind; allowed: reacting, behavior"):
        generate("crowd", 0, speed=2.0)
    with pytest.raises(ConfigError, match="reacting: not an option of the sparse kind; allowed: none"):
        generate("sparse", 0, reacting=True)


@pytest.mark.parametrize("behavior", ["orca", "sfm"])
def test_people_who_see_a_standing_robot_keep_off_it_and_off_each_other(behavior):
    # The social force with IR-SIM's defaults failed both: people walked into a standing robot in
    # 26 of 40 crowds and 1.6 pairs overlapped a step (common.moving_kinds.CROWD_SFM).
    crashes, overlaps, steps = 0, 0, 0
    for seed in range(20):
        world = World(generate("crowd", seed, 0.5, "eval", reacting=True, behavior=behavior), seed=seed)
        world.reset()
        for _ in range(300):
            readings = world.step(0.0, 0.0)
            rows = readings.movers.rows
            gaps = np.hypot(rows[:, None, 0] - rows[None, :, 0], rows[:, None, 1] - rows[None, :, 1])
            overlaps += int((gaps < rows[:, None, 5] + rows[None, :, 5] - 0.05).sum() - len(rows)) // 2
            steps += 1
            if readings.collided:
                crashes += 1
                break
    assert crashes == 0
    assert overlaps / steps < 0.05
