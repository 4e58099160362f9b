"""lidar79_motion: the range rates see a person coming, start afresh every episode, and a policy
trained on lidar43_log starts a stage on it acting exactly as before."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import SAC

import flatland  # noqa: F401
from common.curriculum.policy import load_policy, load_weights
from common.curriculum.policy_file import save_policy
from common.generators import generate
from common.motion.spec import Motion
from common.observations import RANGE_RATE_SCALE, make_layout
from common.scenario import CircleObstacle, LidarSpec, Scenario


def _walker_scenario() -> Scenario:
    # 37 beams all round: one looks straight ahead, at the person walking at the robot at 1 m/s.
    walker = CircleObstacle(x=4.0, y=1.0, radius=0.25, motion=Motion(goals=[(1.6, 1.0)], vel_max=(1.0, 1.0)))
    return Scenario(start=(1.0, 1.0, 0.0), goal=(1.0, 9.0), lidar=LidarSpec(beams=37), obstacles=[walker])


def test_the_sector_ahead_reads_the_person_closing_in_and_the_rest_read_nothing():
    env = gym.make("flatland/Nav-v0", world=_walker_scenario(), observation="lidar79_motion").unwrapped
    observation, _ = env.reset(seed=0)
    assert observation.shape == (79,) and np.all(observation[43:] == 0.0)  # no rate before a second scan
    observation, *_ = env.step(np.array([-1.0, 0.0], dtype=np.float32))  # stand still
    rates = observation[43:]
    ahead = 18  # the sector around the beam straight ahead
    assert rates[ahead] == pytest.approx(-1.0 / RANGE_RATE_SCALE, abs=1e-6)  # 1 m/s closer
    assert np.count_nonzero(np.abs(rates) > 1e-9) == 1
    np.testing.assert_array_equal(observation[:43], make_layout("lidar43_log", env.scenario.robot, env.scenario.lidar)(
        env.readings, env.scenario.goal))


def _rates_while_driving(kind: str, beams: int) -> np.ndarray:
    """|range rate| in m/s of every sector, every step, of a robot driving and turning at random
    through still worlds of ``kind`` with a lidar of ``beams`` beams."""
    template = Scenario(lidar=LidarSpec(beams=beams))
    rates = []
    for seed in range(3):
        scenario = generate(kind, seed, template=template)
        world, layout = flatland.World(scenario), make_layout("lidar79_motion", scenario.robot, scenario.lidar)
        layout(world.reset(), scenario.goal)
        turns = np.random.default_rng(seed).uniform(-1.0, 1.0, 80)
        for turn in turns:
            readings = world.step(0.5, turn)
            if readings.collided:
                break
            rates.append(np.abs(layout(readings, scenario.goal)[43:]) * RANGE_RATE_SCALE)
    return np.array(rates)


@pytest.mark.parametrize("kind", ["cluttered", "warehouse"])
def test_a_still_world_reads_still_while_the_robot_drives_and_turns(kind):
    # The last scan is carried by odometry into the robot's present frame: what still stands reads
    # no rate, whatever the robot does (robot-frame differences read over 0.5 m/s in two fifths of
    # the sectors here, and a 36-beam scan is too coarse to carry: nearly a third).
    rates = _rates_while_driving(kind, 180)
    assert len(rates) > 100
    assert (rates > 0.5).mean() < 0.08 and np.median(rates) < 0.05


def test_a_new_episode_starts_without_the_last_ones_scan():
    layout = make_layout("lidar79_motion", Scenario().robot, LidarSpec(beams=37))
    env = gym.make("flatland/Nav-v0", world=_walker_scenario(), observation="lidar43_log").unwrapped
    first = env.reset(seed=0) and env.readings
    layout.reset()
    layout(first, (1.0, 9.0))
    for _ in range(3):
        env.step(np.zeros(2, dtype=np.float32))
    layout.reset()
    assert np.all(layout(env.readings, (1.0, 9.0))[43:] == 0.0)  # without reset() it would read the 3 steps


@pytest.fixture(scope="module")
def sac_on_lidar43_log(tmp_path_factory):
    model = SAC("MlpPolicy", gym.make("flatland/Nav-v0", world="open", observation="lidar43_log"), device="cpu", seed=0,
                buffer_size=100, learning_starts=10, policy_kwargs={"net_arch": [32, 32]})
    model.learn(30)
    path = tmp_path_factory.mktemp("sac") / "policy.zip"
    return save_policy(model, path, {"algorithm": "sac", "observation": "lidar43_log", "goal_distance_scale": 10.0,
                                     "policy_kwargs": {"net_arch": [32, 32]}})


def test_a_lidar43_log_policy_starts_a_lidar79_motion_stage_acting_as_before(sac_on_lidar43_log):
    env = gym.make("flatland/Nav-v0", world="crowd", observation="lidar79_motion")
    model = SAC("MlpPolicy", env, device="cpu", seed=1, buffer_size=100, policy_kwargs={"net_arch": [32, 32]})
    load_weights(model, sac_on_lidar43_log, policy_only=True)
    old = load_policy(sac_on_lidar43_log)
    observations = np.random.default_rng(0).uniform(-1, 1, (64, 79)).astype(np.float32)
    with torch.no_grad():
        widened = model.policy.actor(torch.as_tensor(observations), deterministic=True)
        before = old.model.actor(torch.as_tensor(observations[:, :43]), deterministic=True)
        q_new = model.policy.critic(torch.as_tensor(observations), widened)
        q_old = old.model.critic(torch.as_tensor(observations[:, :43]), widened)
    torch.testing.assert_close(widened, before)  # the rates read zero weights: the same actions
    for new, previous in zip(q_new, q_old):
        torch.testing.assert_close(new, previous)  # and the same values, the action read after the rates
    first = model.policy.state_dict()["actor.latent_pi.0.weight"]
    assert first.shape == (32, 79) and torch.all(first[:, 43:] == 0)
