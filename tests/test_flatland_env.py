"""The flatland/Nav-v0 env: checkers, determinism, bounds, episode ends, rendering."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import flatland  # noqa: F401
from tests.rollouts import rollout, same
from common.observations import LAYOUTS
from common.scenario import CircleObstacle, Scenario
from flatland.world import World


def make(**kwargs):
    return gym.make("flatland/Nav-v0", **kwargs)


@pytest.mark.parametrize("observation", LAYOUTS)
def test_env_passes_gymnasium_and_sb3_checkers(observation):
    env = make(world="sparse", observation=observation)
    check_env(env.unwrapped)
    sb3_check_env(env.unwrapped)


@pytest.mark.parametrize("world", ["cluttered", "warehouse"])
def test_reset_with_the_same_seed_replays_the_same_episodes(world):
    from common.generators import generate

    # The same actions from another seed: the seed alone changes the episode, by what it draws.
    def differ(env) -> bool:
        return not same(rollout(env, 3, action_seed=0), rollout(env, 4, action_seed=0))

    env = make(observation="lidar43", world=world)
    assert same(rollout(env, 3), rollout(env, 3)) and differ(env)  # the layout
    fixed = generate(world, 0)
    assert not differ(make(observation="lidar43", world=fixed))  # one layout and no noise: nothing drawn
    noisy = fixed.model_copy(update={"lidar": fixed.lidar.model_copy(update={"noise_std": 0.05})})
    # Each source of noise alone in that one layout: a world reseeds its generator only where something draws.
    for kwargs in ({"world": noisy}, {"world": fixed, "robot": {"encoder_noise": 0.05}},
                   {"world": fixed, "motor_scale": (0.8, 1.2)},
                   {"world": fixed, "robot": {"motion_noise": [0.05, 0.01, 0.01, 0.05]}}):  # IR-SIM's alpha
        env = make(observation="lidar43", **kwargs)
        assert same(rollout(env, 3), rollout(env, 3)), kwargs
        assert differ(env), kwargs


def test_observations_stay_within_bounds_over_long_random_rollouts():
    for observation in LAYOUTS:
        env = make(world="cluttered", observation=observation)
        space = env.observation_space
        for item in rollout(env, 0, steps=3000):
            obs = item[0] if isinstance(item, tuple) else item
            assert space.contains(obs), obs


def test_driving_into_an_obstacle_terminates_with_a_collision():
    scenario = Scenario(start=(2, 5, 0), goal=(8, 5), obstacles=[CircleObstacle(x=4, y=5, radius=0.5)])
    env = make(world=scenario, reward="tutorial3d")
    env.reset(seed=0)
    for step in range(100):
        _, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
        if terminated:
            break
    assert terminated and not truncated and info["collided"] and not info["is_success"]
    assert info["reward_terms"]["collision"] == -10.0
    assert 10 <= step <= 15  # 1.3 m to contact at 0.1 m per step


def test_reaching_the_goal_terminates_with_success_and_the_bonus():
    scenario = Scenario(start=(2, 5, 0), goal=(4, 5))
    env = make(world=scenario)
    env.reset(seed=0)
    for _ in range(40):
        _, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
        if terminated:
            break
    assert info["is_success"] and not info["collided"] and info["reward_terms"]["goal"] == 100.0


def test_truncation_after_max_steps():
    env = make(world=Scenario(start=(2, 5, 0), goal=(8, 5)), max_steps=7)
    env.reset(seed=0)
    ends = [env.step(np.array([-1.0, 0.0], dtype=np.float32))[2:4] for _ in range(7)]
    assert ends[-1] == (False, True) and all(end == (False, False) for end in ends[:-1])


def test_actions_map_to_forward_only_velocities():
    env = make(world=Scenario(start=(2, 5, 0), goal=(8, 5)))
    env.reset(seed=0)
    env.step(np.array([-1.0, 1.0], dtype=np.float32))
    assert env.unwrapped.readings.velocity == (0.0, 1.0)
    env.step(np.array([1.0, -1.0], dtype=np.float32))
    assert env.unwrapped.readings.velocity == (1.0, -1.0)


def test_world_argument_accepts_a_yaml_path(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text(Scenario(name="from-file").to_yaml())
    env = make(world=str(path))
    env.reset(seed=0)
    assert isinstance(env.unwrapped.world, World)
    assert env.unwrapped.scenario.name == "from-file"


@pytest.mark.parametrize("tier", ["flatland/Nav-v0", "physics3d/WarehouseNav-v0"])
def test_a_list_of_anything_but_scenarios_is_one_line_naming_its_item(tier):
    import physics3d  # noqa: F401
    from common.errors import ConfigError

    with pytest.raises(ConfigError) as error:
        gym.make(tier, world=[Scenario(), "cluttered"])
    assert str(error.value).startswith("world.1: got 'cluttered'; allowed: a list of Scenario objects")


def test_rgb_array_frames_and_gif(tmp_path):
    from flatland.render import record_episode

    env = make(world="sparse", render_mode="rgb_array", max_steps=20)
    env.reset(seed=0)
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    assert frame.std() > 0  # something was drawn
    path, info = record_episode(env, lambda obs: np.array([0.0, 0.3]), tmp_path / "ep.gif", seed=0)
    from PIL import Image

    with Image.open(path) as gif:
        assert gif.n_frames >= 2


def test_a_mix_of_kinds_draws_each_by_weight():
    env = make(world={"cluttered": 3, "trap": 1})
    kinds = []
    for seed in range(80):
        env.reset(seed=seed)
        kinds.append(env.unwrapped.scenario.kind)
    assert set(kinds) == {"cluttered", "trap"} and 0.6 < kinds.count("cluttered") / len(kinds) < 0.9


def test_a_new_robot_or_lidar_gets_its_own_world_observation_and_action_mapping():
    # The env reuses its world, layout and mapping only while the robot and lidar stay the same.
    from common.scenario import LidarSpec, RobotProfile

    slow_short = Scenario(robot=RobotProfile(v_max=0.5), lidar=LidarSpec(range_max=2.0), start=(3, 5, 0), goal=(8, 5))
    fast_long = slow_short.model_copy(update={"robot": RobotProfile(v_max=2.0), "lidar": LidarSpec(range_max=8.0)})
    env = make(world=[slow_short, fast_long], observation="lidar43").unwrapped
    seen = set()
    for seed in range(12):
        observation, _ = env.reset(seed=seed)
        scenario = env.scenario
        seen.add(scenario.robot.v_max)
        assert env.actions.to_velocity(np.array([1.0, 0.0]))[0] == scenario.robot.v_max
        assert env.world.scenario is scenario and env.world.lidar.spec.range_max == scenario.lidar.range_max
        # The nearest wall is 3 m away: beyond a 2 m lidar (every sector reads 1), within an 8 m one.
        assert (observation[6:42].min() == 1.0) == (scenario.lidar.range_max == 2.0)
    assert seen == {0.5, 2.0}


def test_human_render_mode_runs_headless(monkeypatch):
    """The human path draws into a pyplot figure; under the Agg backend it must run without a display."""
    import matplotlib

    matplotlib.use("Agg")
    env = make(world="sparse", render_mode="human", max_steps=3)
    env.reset(seed=0)
    env.step(np.array([0.0, 0.5], dtype=np.float32))
    assert env.unwrapped._renderer is not None and env.unwrapped._renderer.human
    env.close()


def test_rectified_mapping_stands_still_on_the_lower_half_of_the_range():
    env = make(world=Scenario(start=(2, 5, 0), goal=(8, 5)), action_mapping="rectified")
    env.reset(seed=0)
    env.step(np.array([-0.4, 0.5], dtype=np.float32))
    assert env.unwrapped.readings.velocity == (0.0, 0.5)
    env.step(np.array([0.5, 0.0], dtype=np.float32))
    assert env.unwrapped.readings.velocity == (0.5, 0.0)
    from common.actions import ActionMapping

    mapping = ActionMapping(Scenario().robot, "rectified")
    assert mapping.to_velocity(mapping.to_action(0.3, -0.2)) == pytest.approx((0.3, -0.2))


RANDOM_WORLD = ("world: {width: 10, height: 10}\nrobot:\n  kinematics: {name: diff}\n  state: [1, 1, 0]\n  goal: [9, 9, 0]\n"
                "obstacle:\n  - number: 6\n    distribution: {name: random, range_low: [3, 3, 0], range_high: [7, 7, 0]}\n"
                "    shape: {name: circle, radius: 0.3}\n")


def test_a_random_irsim_world_restores_its_initial_state_unless_resampled(tmp_path, monkeypatch):
    import common.world_file as world_file

    path = tmp_path / "random.yaml"
    path.write_text(RANDOM_WORLD)
    reads = []
    read = world_file.read_yaml_mapping
    monkeypatch.setattr(world_file, "read_yaml_mapping", lambda p: reads.append(p) or read(p))
    env = make(world=str(path))
    env.reset(seed=0)
    initial = env.unwrapped.scenario
    for options in ({"seed": 0}, {"seed": 7}, {}):
        env.reset(**options)
        assert env.unwrapped.scenario is initial  # IR-SIM's reset(): back to the initial state
    env.reset(options={"resample": True})  # IR-SIM's reset(random=True)
    assert env.unwrapped.scenario.obstacles != initial.obstacles
    env.reset()
    assert env.unwrapped.scenario is initial
    resampling = make(world=str(path), resample=True)
    layouts = []
    for seed in (1, None, None, 1):
        resampling.reset(seed=seed)
        layouts.append(resampling.unwrapped.scenario.obstacles)
    assert layouts[0] != layouts[1] != layouts[2] and layouts[0] == layouts[3]  # new per episode, seeded
    assert len(reads) == 2  # each env read and parsed the file once


def test_goal_threshold_option_fixes_or_draws_the_goal_radius():
    scenario = Scenario(start=(1, 5, 0), goal=(2, 5), goal_threshold=0.25)

    def steps_to_goal(**kwargs) -> tuple[int, float]:
        env = make(world=scenario, **kwargs)
        _, info = env.reset(seed=0)
        for step in range(1, 50):
            *_, terminated, _, _ = env.step(np.array([1.0, 0.0], dtype=np.float32))
            if terminated:
                return step, info["goal_threshold"]
        raise AssertionError("never arrived")

    assert steps_to_goal() == (8, 0.25)  # 0.1 m per step: inside 0.25 m after 8 steps
    assert steps_to_goal(goal_threshold=0.12) == (9, 0.12)
    drawn = make(world=scenario, goal_threshold=[0.1, 0.5])
    radii = [drawn.reset(seed=seed)[1]["goal_threshold"] for seed in range(20)]
    assert all(0.1 <= r <= 0.5 for r in radii) and len(set(radii)) == 20
    assert radii == [drawn.reset(seed=seed)[1]["goal_threshold"] for seed in range(20)]
    with pytest.raises(ValueError, match="goal_threshold"):
        make(world=scenario, goal_threshold=[0.5, 0.1])


def test_a_world_reloaded_many_times_holds_no_more_shapes():
    """Each load made new pymunk shapes for polygons and segments; removed from the space, they
    stayed in the static body's set: about 3 kB a reset, without end, in the crowd's corridors."""
    env = gym.make("flatland/Nav-v0", world="crowd")
    env.reset(seed=0)
    for _ in range(300):
        env.reset()
    assert len(env.unwrapped.world.space.static_body.shapes) < 100  # 1,000 and more when they leaked


@pytest.mark.parametrize("world", ["cluttered", "crowd"])
def test_the_records_a_step_builds_by_position_are_whole(world):
    """The hot path builds its NamedTuples field by field in C (common.kinematics.record), which
    checks no count: a field added to a record and not to its builder would read as missing only
    where something asked for it."""
    from common.readings import Imu, Odometry, Readings
    from common.rewards import StepContext

    env = make(world=world, observation="lidar43").unwrapped
    contexts = []

    class Seen:  # the env's reward, keeping each step's context
        def __init__(self, reward) -> None:
            self.reward = reward

        def __call__(self, ctx):
            contexts.append(ctx)
            return self.reward(ctx)

        def __getattr__(self, name):
            return getattr(self.reward, name)

    env.reward = Seen(env.reward)
    env.reset(seed=0)
    for _ in range(30):
        *_, terminated, truncated, _ = env.step(np.array([0.6, 0.1], dtype=np.float32))
        readings = env.readings
        assert (len(readings), len(readings.odometry), len(readings.imu), len(readings.pose)) == (
            len(Readings._fields), len(Odometry._fields), len(Imu._fields), 3)
        if terminated or truncated:
            env.reset()
    assert contexts and all(len(ctx) == len(StepContext._fields) for ctx in contexts)
