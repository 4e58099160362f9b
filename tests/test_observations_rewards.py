"""Observation layouts and reward terms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.errors import ConfigError
from common.kinematics import Pose2D
from common.observations import make_layout
from common.readings import Imu, Odometry, Readings
from common.rewards import PRESETS, Reward, StepContext, resolve_reward_spec
from common.scenario import LidarSpec, RobotProfile

ROBOT = RobotProfile(v_max=0.5, w_max=1.5)


def _readings(pose=(0.0, 0.0, 0.0), v=0.25, w=0.75, lidar=None, beams=36) -> Readings:
    ranges = np.full(beams, 5.0) if lidar is None else np.asarray(lidar, dtype=float)
    return Readings(pose=Pose2D(*pose), velocity=(v, w), odometry=Odometry(Pose2D(*pose), v, w), lidar=ranges,
                    imu=Imu((0.0, 0.0, 9.81), (0.0, 0.0, w)), collided=False, time=0.0)


def test_nav7_values_match_the_documented_table():
    layout = make_layout("nav7", ROBOT, LidarSpec(range_max=5.0))
    lidar = np.full(36, 5.0)
    lidar[3] = 1.0
    obs = layout(_readings(pose=(1.0, 1.0, math.pi / 2), lidar=lidar), goal=(4.0, 5.0))
    np.testing.assert_allclose(obs, [0.6, 0.8, (math.atan2(4, 3) - math.pi / 2) / math.pi, 0.5, 0.5, 0.2, 0.5], rtol=1e-6)
    assert layout.space.contains(obs)


def test_lidar43_layout_and_yaw_rate():
    layout = make_layout("lidar43", ROBOT, LidarSpec())
    ranges = np.linspace(0.5, 5.0, 36)
    obs = layout(_readings(lidar=ranges, w=-1.5), goal=(3.0, 0.0))
    assert obs.shape == (43,)
    np.testing.assert_allclose(obs[:6], [1, 0, 0, 0.5, -1, -1], atol=1e-6)
    np.testing.assert_allclose(obs[6:42], ranges / 5.0, rtol=1e-6)
    assert obs[42] == pytest.approx(0.3)


def _sectors(ranges: np.ndarray) -> np.ndarray:
    """The 36 sector entries lidar43 makes of a scan (range_max 5 m)."""
    beams = len(ranges)
    layout = make_layout("lidar43", ROBOT, LidarSpec(beams=beams, range_max=5.0))
    return layout(_readings(lidar=ranges, beams=beams), goal=(1, 1))[6:42]


def test_lidar43_reduces_other_beam_counts_to_36_nearest_returns():
    np.testing.assert_array_equal(_sectors(np.arange(72, dtype=float) / 20), (np.arange(0, 72, 2) / 100).astype(np.float32))
    # Fewer beams than sectors: each sector reads the beam under it.
    np.testing.assert_array_equal(_sectors(np.arange(18, dtype=float) / 4), (np.repeat(np.arange(18), 2) / 20).astype(np.float32))


def test_lidar43_log_reads_contact_as_0_range_max_as_1_and_keeps_the_other_entries():
    layout = make_layout("lidar43_log", ROBOT, LidarSpec(range_max=5.0))
    ranges = np.linspace(0.1, 5.0, 36)
    obs = layout(_readings(lidar=ranges, w=-1.5), goal=(3.0, 0.0))
    linear = make_layout("lidar43", ROBOT, LidarSpec(range_max=5.0))(_readings(lidar=ranges, w=-1.5), goal=(3.0, 0.0))
    np.testing.assert_array_equal(obs[:6], linear[:6])
    assert obs[42] == linear[42]
    expected = np.log(np.maximum(ranges, 0.2) / 0.2) / np.log(5.0 / 0.2)
    np.testing.assert_allclose(obs[6:42], expected, rtol=1e-6)
    assert obs[6] == 0.0 and obs[41] == pytest.approx(1.0)
    # Half a metre from contact spans more than a quarter of the scale (a tenth when linear).
    assert layout(_readings(lidar=np.full(36, 0.7)), goal=(3.0, 0.0))[6] > 0.25


@pytest.mark.parametrize("name", ["nav7", "lidar43", "lidar43_log"])
def test_values_are_clipped_into_the_bounds(name):
    layout = make_layout(name, ROBOT, LidarSpec())
    obs = layout(_readings(v=5.0, w=-9.0, lidar=np.full(36, 7.0)), goal=(100.0, 0.0))
    assert layout.space.contains(obs)


def test_unknown_layout_is_a_config_error():
    with pytest.raises(ConfigError, match="allowed: nav7, lidar43"):
        make_layout("rgb", ROBOT, LidarSpec())


def _ctx(**changes) -> StepContext:
    base = dict(distance=2.0, prev_distance=2.1, heading_error=0.5, v=0.5, w=0.2, min_range=1.0,
                collided=False, reached=False)
    return StepContext(**{**base, **changes})


def test_tutorial2d_preset_reproduces_the_tutorials_v2_reward():
    reward = Reward("tutorial2d")
    total, shares = reward(_ctx())
    assert total == pytest.approx(1.0)  # 10 x 0.1 m of progress
    total, shares = reward(_ctx(prev_distance=1.9, w=1.0, min_range=0.4))
    assert shares == pytest.approx({"progress": 0.0, "spin": -1.0, "proximity_bands": -1.0, "goal": 0.0})
    total, _ = reward(_ctx(min_range=0.2, reached=True))
    assert total == pytest.approx(1.0 - 5.0 + 100.0)


def test_tutorial3d_preset_terms():
    reward = Reward("tutorial3d")
    total, shares = reward(_ctx(collided=True, min_range=0.1, w=2.5))
    assert shares["collision"] == -10.0
    assert shares["proximity"] == pytest.approx(-0.2)
    assert shares["spin"] == pytest.approx(-0.1)
    assert shares["heading_alignment"] == pytest.approx(0.05)
    assert shares["time"] == -0.01
    assert total == pytest.approx(sum(shares.values()))


def test_near_speed_prices_speed_only_inside_its_threshold():
    reward = Reward({"near_speed": {"weight": -10.0, "threshold": 0.5}})
    assert reward(_ctx(v=1.0, min_range=0.3))[0] == pytest.approx(-2.0)  # 1 m/s, 0.2 m inside
    assert reward(_ctx(v=-0.5, min_range=0.3))[0] == pytest.approx(-1.0)  # reversing is speed too
    assert reward(_ctx(v=0.0, min_range=0.3))[0] == 0.0  # standing close costs nothing
    assert reward(_ctx(v=1.0, min_range=0.6))[0] == 0.0  # outside the threshold


def test_stuck_fires_after_a_window_without_progress_and_resets():
    reward = Reward({"stuck": {"weight": -1.0, "window": 5, "threshold": 0.05}})
    values = [reward(_ctx(prev_distance=2.0, distance=2.0))[0] for _ in range(6)]
    assert values == [0, 0, 0, 0, -1, -1]
    reward.reset()
    assert reward(_ctx(prev_distance=2.0, distance=2.0))[0] == 0


def test_reward_spec_errors_name_the_field_and_the_allowed_values():
    with pytest.raises(ConfigError, match=r"reward\.warp: unknown reward term; allowed: progress"):
        resolve_reward_spec({"warp": 1.0}, "c.yaml")
    with pytest.raises(ConfigError, match=r"reward\.spin\.limit: unknown parameter; allowed: weight, threshold"):
        resolve_reward_spec({"spin": {"weight": -1, "limit": 2}})
    with pytest.raises(ConfigError, match=r"reward\.goal\.weight: expected a finite number"):
        resolve_reward_spec({"goal": "lots"})
    with pytest.raises(ConfigError, match="unknown preset"):
        resolve_reward_spec("tutorial9d")


def test_presets_are_valid_specs():
    for name in PRESETS:
        assert resolve_reward_spec(name)


def test_a_sector_reads_its_nearest_beam_wherever_it_lies():
    ranges = np.random.default_rng(0).permutation(np.linspace(0.2, 5.0, 720))
    np.testing.assert_array_equal(_sectors(ranges), (ranges.reshape(36, 20).min(axis=1) / 5.0).astype(np.float32))
    np.testing.assert_array_equal(_sectors(ranges[:72]), (ranges[:72].reshape(36, 2).min(axis=1) / 5.0).astype(np.float32))


# -- the env's wiring: what it feeds the reward and the observation -------------------------------


def _flat_env(scenario, **kwargs):
    import gymnasium as gym

    import flatland  # noqa: F401

    return gym.make("flatland/Nav-v0", world=scenario, **kwargs)


STAND_STILL = np.array([-1.0, 0.0], dtype=np.float32)  # the linear mapping's v = 0, w = 0


def test_the_env_pays_proximity_on_the_nearest_lidar_return():
    from common.scenario import Scenario, SegmentObstacle

    # A wall 0.4 m ahead: the nearest beams (±5°) read 0.4 / cos 5°, the rest farther.
    wall = SegmentObstacle(points=[(5.4, 3.0), (5.4, 7.0)])
    env = _flat_env(Scenario(start=(5.0, 5.0, 0.0), goal=(2.0, 5.0), obstacles=[wall]), observation="nav7")
    env.reset(seed=0)
    observation, _, _, _, info = env.step(STAND_STILL)
    nearest = 0.4 / math.cos(math.pi / 36)
    assert info["reward_terms"]["proximity"] == pytest.approx(-5.0 * (0.5 - nearest))
    assert observation[5] == pytest.approx(nearest / 5.0)  # nav7's nearest return


def test_the_env_pays_heading_alignment_on_the_bearing_to_the_goal():
    from common.scenario import Scenario

    # The step works the bearing out only for a reward that reads it: facing the goal pays 1,
    # facing away 1 - pi, and a reward without the term is not paid for it.
    for yaw, paid in ((0.0, 1.0), (math.pi, 1.0 - math.pi), (math.pi / 2, 1.0 - math.pi / 2)):
        env = _flat_env(Scenario(start=(2.0, 5.0, yaw), goal=(8.0, 5.0)), observation="nav7",
                        reward={"heading_alignment": 1.0, "time": 0.0})
        env.reset(seed=0)
        assert env.step(STAND_STILL)[4]["reward_terms"]["heading_alignment"] == pytest.approx(paid, abs=1e-9)
    env = _flat_env(Scenario(start=(2.0, 5.0, math.pi), goal=(8.0, 5.0)), observation="nav7", reward={"time": -1.0})
    env.reset(seed=0)
    assert env.step(STAND_STILL)[1] == -1.0


def test_a_deep_copy_of_a_step_info_is_equal_and_independent():
    import copy

    from common.scenario import Scenario

    # stable-baselines3's DummyVecEnv deep-copies every info every step, after adding the episode's
    # last observation to it: the info's own deep copy (cheaper than the generic one) must still
    # copy what can change.
    env = _flat_env(Scenario(start=(2.0, 2.0, 0.0), goal=(8.0, 8.0)), observation="nav7")
    env.reset(seed=0)
    info = env.step(STAND_STILL)[4]
    info["terminal_observation"] = np.zeros(3)
    copied = copy.deepcopy(info)
    assert copied.keys() == info.keys() and copied["reward_terms"] == info["reward_terms"]
    assert copied["distance"] == info["distance"] and np.array_equal(copied["terminal_observation"], np.zeros(3))
    info["terminal_observation"][0] = 1.0
    info["reward_terms"]["time"] = 99.0
    assert copied["terminal_observation"][0] == 0.0 and copied["reward_terms"]["time"] != 99.0
    assert copied["is_success"] is False and "proximity" in copied["reward_terms"]


def test_the_env_observes_through_odometry_not_the_true_pose():
    from common.scenario import RobotProfile as Profile, Scenario

    scenario = Scenario(start=(2.0, 2.0, 0.0), goal=(8.0, 8.0), robot=Profile(encoder_noise=0.3))
    env = _flat_env(scenario, observation="lidar43")
    env.reset(seed=3)
    for _ in range(40):
        observation, *_ = env.step(np.array([0.5, 0.4], dtype=np.float32))
    readings = env.unwrapped.readings
    (x, y, yaw), (tx, ty, _) = readings.odometry.pose, readings.pose
    assert math.dist((x, y), (tx, ty)) > 0.05  # the noise has made them differ
    heading = math.atan2(8.0 - y, 8.0 - x)
    assert observation[2] == pytest.approx(math.remainder(heading - yaw, 2 * math.pi) / math.pi, abs=1e-6)
    assert observation[42] == pytest.approx(math.dist((x, y), (8.0, 8.0)) / 10.0, abs=1e-6)
    assert observation[3] == pytest.approx(readings.odometry.v / scenario.robot.v_max, abs=1e-6)


def _episode_return(reward: str, action: np.ndarray) -> float:
    from common.scenario import Scenario

    env = _flat_env(Scenario(start=(3.0, 3.0, 0.0), goal=(7.0, 7.0)), reward=reward, max_steps=500)
    env.reset(seed=0)
    total = 0.0
    for _ in range(500):
        _, reward_, terminated, truncated, _ = env.step(action)
        total += reward_
        if terminated or truncated:
            break
    return total


def test_driving_in_circles_earns_nothing_under_the_default_but_pays_under_tutorial2d():
    # 1 m/s at 0.8 rad/s (just under tutorial2d's spin penalty): 500 steps round a 1.25 m loop.
    circle = np.array([1.0, 0.8], dtype=np.float32)
    assert _episode_return("default", circle) < 0
    # The tutorial's flaw, kept as a lesson: paid for every approach, charged nothing for leaving;
    # circling earns more than reaching the goal does (10 x 5.4 m + 100).
    assert _episode_return("tutorial2d", circle) > 10 * (4 * math.sqrt(2) - 0.3) + 100


def test_the_default_reward_pays_for_reaching_the_goal():
    from common.scenario import Scenario

    env = _flat_env(Scenario(start=(3.0, 3.0, math.pi / 4), goal=(7.0, 7.0)), max_steps=200)
    env.reset(seed=0)
    total = 0.0
    for _ in range(200):
        _, reward, terminated, _, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
        total += reward
        if terminated:
            break
    assert info["is_success"] and info["reward_terms"]["goal"] == 100.0
    assert total > 100 + 10 * (4 * math.sqrt(2) - 0.3) - 0.05 * 60 - 1


def test_the_nearest_return_is_the_smallest_range_wherever_it_lies():
    from common.readings import nearest_return

    ranges = np.random.default_rng(0).uniform(0.1, 5.0, 36)
    for index in (0, 17, 35):
        scan = ranges.copy()
        scan[index] = 0.05
        assert nearest_return(scan) == 0.05 == scan.min()
    assert nearest_return(np.zeros(0)) == math.inf
