"""Observation layouts and reward terms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.errors import ConfigError
from common.kinematics import Pose2D
from common.observations import make_layout, sector_minimum
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


def test_lidar43_reduces_other_beam_counts_to_36_nearest_returns():
    reduce = sector_minimum(72, 36)
    ranges = np.arange(72, dtype=float)
    np.testing.assert_array_equal(reduce(ranges), ranges[::2])
    layout = make_layout("lidar43", ROBOT, LidarSpec(beams=720))
    assert layout(_readings(lidar=np.full(720, 2.5), beams=720), goal=(1, 1)).shape == (43,)
    assert sector_minimum(18, 36)(np.arange(18.0)).shape == (36,)


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
