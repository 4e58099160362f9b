"""One set of episode rules: the env and the evaluator end the same episode alike, at the same radius."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import flatland  # noqa: F401  (registers the env)
from common.errors import ConfigError
from common.evaluation import run_episode
from common.readings import Readings
from common.scenario import CircleObstacle, Scenario
from common.task import STUCK_WINDOW, Task, judged_radius, threshold_range
from flatland.world import World

OPEN = Scenario(start=(1.0, 5.0, 0.0), goal=(7.0, 5.0), goal_threshold=0.3)


class Replay:
    """An agent that sends a fixed list of commands, then stands still."""

    name = "replay"

    def __init__(self, commands: list[tuple[float, float]]) -> None:
        self.commands = commands

    def bind(self, robot, lidar, goal_threshold) -> None:
        self.radius = goal_threshold

    def reset(self) -> None:
        self.step = 0

    def act(self, readings, goal):
        self.step += 1
        return self.commands[self.step - 1] if self.step <= len(self.commands) else (0.0, 0.0)


def _env_outcome(scenario: Scenario, commands, radius: float | None, max_steps: int) -> tuple[str, int]:
    """Drive the gym env with raw commands (its linear action mapping inverted) to its episode's end."""
    env = gym.make("flatland/Nav-v0", world=scenario, goal_threshold=radius, max_steps=max_steps).unwrapped
    env.reset(seed=0)
    robot = env.scenario.robot
    for step, (v, w) in enumerate(commands + [(0.0, 0.0)] * max_steps, start=1):
        action = np.array([2.0 * (v - robot.v_min) / (robot.v_max - robot.v_min) - 1.0, w / robot.w_max], np.float32)
        _, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            outcome = "success" if info["is_success"] else "collision" if terminated else "timeout"
            return outcome, step
    raise AssertionError("the env never ended the episode")


@pytest.mark.parametrize("case, commands, radius, max_steps", [
    ("arrives within the scenario's radius", [(1.0, 0.0)] * 80, None, 200),
    ("arrives within a tighter radius later", [(1.0, 0.0)] * 57 + [(0.1, 0.0)] * 40, 0.05, 200),
    ("hits the post", [(1.0, 0.0)] * 80, None, 200),
    ("runs out of steps", [(0.5, 1.0)] * 60, None, 30),
])
def test_the_env_and_the_evaluator_end_the_same_drive_alike(case, commands, radius, max_steps):
    scenario = OPEN
    if case == "hits the post":
        scenario = OPEN.model_copy(update={"obstacles": [CircleObstacle(x=4.0, y=5.0, radius=0.5)]})
    episode = run_episode(Replay(commands), scenario, max_steps=max_steps, goal_radius=radius)
    assert (episode.outcome, episode.steps) == _env_outcome(scenario, commands, radius, max_steps)
    assert episode.outcome == {"arrives within the scenario's radius": "success", "hits the post": "collision",
                               "arrives within a tighter radius later": "success",
                               "runs out of steps": "timeout"}[case]


def test_the_evaluator_judges_within_the_radius_it_is_given():
    # Stop 0.2 m short of the goal: within the scenario's 0.3 m, not within 0.1 m.
    short = [(0.5, 0.0)] * 116  # 5.8 m at 0.05 m a step
    assert run_episode(Replay(short), OPEN, max_steps=300).outcome == "success"
    tight = run_episode(Replay(short), OPEN, max_steps=300, goal_radius=0.1)
    assert tight.outcome == "stuck" and tight.shortest_path == pytest.approx(6.0 - 0.1, abs=0.05)


def test_an_agent_that_stops_making_way_is_stuck_only_when_judged_so():
    world = World(OPEN)
    readings = world.reset()
    judged, training = Task(judge_stuck=True), Task()
    judged.start(OPEN, readings)
    training.start(OPEN, readings)
    outcomes = [(judged.step(world.step(0.0, 0.0)), training.step(world.readings)) for _ in range(STUCK_WINDOW)]
    assert outcomes[-1] == ("stuck", None) and all(o == (None, None) for o in outcomes[:-1])


def test_a_radius_range_is_drawn_per_episode_from_the_generator_and_judged_at_its_low_end():
    task = Task(goal_threshold=[0.1, 0.5])
    radii = {task.radius_for(OPEN, np.random.default_rng(seed)) for seed in range(5)}
    assert len(radii) == 5 and all(0.1 <= r <= 0.5 for r in radii)
    assert task.radius_for(OPEN, np.random.default_rng(3)) in radii  # the same generator, the same radius
    assert Task().radius_for(OPEN) == 0.3 and Task(0.2).radius_for(OPEN, np.random.default_rng(0)) == 0.2
    assert judged_radius({"goal_threshold": [0.1, 0.5]}) == 0.1 and judged_radius({}) is None


@pytest.mark.parametrize("value, message", [
    ("far", "allowed: null, a number or [low, high] in metres"),
    ([0.5, 0.1], "allowed: 0 < low <= high"),
    (0.0, "allowed: 0 < low <= high"),
])
def test_a_bad_goal_threshold_is_one_line_naming_it(value, message):
    with pytest.raises(ConfigError, match="goal_threshold") as caught:
        threshold_range(value)
    assert message in str(caught.value) and "\n" not in str(caught.value)


def test_arriving_and_touching_on_the_same_step_counts_as_arriving():
    task = Task()
    start = World(OPEN).reset()
    task.start(OPEN, start)
    arrived = Readings(pose=(6.9, 5.0, 0.0), velocity=start.velocity, odometry=start.odometry, lidar=start.lidar,
                       imu=start.imu, collided=True, time=0.1)
    assert task.step(arrived) == "success"


@pytest.mark.parametrize("max_steps", [0, -5, 1.5, True, "300", 10**7])
def test_max_steps_is_a_positive_whole_number(max_steps):
    with pytest.raises(ConfigError, match="max_steps: got .*; allowed: a whole number of steps from 1 to 1,000,000"):
        gym.make("flatland/Nav-v0", world=OPEN, max_steps=max_steps)
    assert Task(max_steps=np.int64(7)).max_steps == 7


@pytest.mark.parametrize("env_id", ["flatland/Nav-v0", "physics3d/WarehouseNav-v0"])
def test_a_closed_env_refuses_to_step_or_reset_in_both_tiers(env_id):
    import physics3d  # noqa: F401  (registers the 3D env)

    env = gym.make(env_id, world="open", render_mode="rgb_array")
    env.reset(seed=0)
    env.render()
    env.close()
    for call in (lambda: env.step(env.action_space.sample()), lambda: env.reset(seed=1), env.render):
        with pytest.raises(gym.error.ClosedEnvironmentError, match="closed env"):
            call()


@pytest.mark.parametrize("env_id", ["flatland/Nav-v0", "physics3d/WarehouseNav-v0"])
def test_an_env_never_reset_refuses_to_step_in_both_tiers(env_id):
    import physics3d  # noqa: F401  (registers the 3D env)

    env = gym.make(env_id, world="open")
    assert env is env.unwrapped  # registered without wrappers: the env's own order check is the only one
    with pytest.raises(gym.error.ResetNeeded, match=r"step\(\) before reset\(\)"):
        env.step(env.action_space.sample())
    env.reset(seed=0)
    env.step(env.action_space.sample())
    env.close()


@pytest.mark.parametrize("env_id", ["flatland/Nav-v0", "physics3d/WarehouseNav-v0"])
def test_an_ended_episode_refuses_another_step_until_reset_in_both_tiers(env_id):
    """Stepping on past the end paid the goal's +100 again every step, the robot driving on."""
    import physics3d  # noqa: F401  (registers the 3D env)

    env = gym.make(env_id, world=Scenario(start=(2.0, 2.0, 0.0), goal=(2.5, 2.0), goal_threshold=0.3)).unwrapped
    env.reset(seed=0)
    ended = False
    for _ in range(50):
        _, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
        if terminated or truncated:
            ended = True
            break
    assert ended and info["is_success"] and reward > 50.0
    with pytest.raises(gym.error.ResetNeeded, match=r"step\(\) after the episode ended"):
        env.step(np.array([1.0, 0.0], dtype=np.float32))
    env.reset(seed=0)
    env.step(np.array([1.0, 0.0], dtype=np.float32))  # a new episode steps again
    env.close()


@pytest.mark.parametrize("world_module", ["flatland", "physics3d"])
def test_a_nan_command_is_refused_by_the_world_and_leaves_it_driving(world_module):
    """NaN passed the limits' clips: the pose turned NaN, and the 3D robot crawled in every later
    episode (0.002 m in 20 steps), a reset notwithstanding."""
    import importlib

    World = importlib.import_module(world_module).World
    world = World(Scenario(start=(2.0, 2.0, 0.0), goal=(8.0, 8.0)), seed=0)
    world.reset(seed=0)
    with pytest.raises(ValueError, match=r"command \(nan, 0\.0\): NaN is not a velocity"):
        world.step(float("nan"), 0.0)
    world.reset(seed=0)
    for _ in range(20):
        readings = world.step(0.5, 0.0)
    assert readings.pose[0] - 2.0 > 0.5  # 20 steps of 0.1 s at 0.5 m/s: about 1 m
    if world_module == "physics3d":
        world.close()


@pytest.mark.parametrize("argument, value", [("goal_distance_scale", 0.0), ("goal_distance_scale", -1.0),
                                             ("goal_distance_scale", float("nan")), ("difficulty", 5.0),
                                             ("difficulty", float("nan")), ("difficulty", "0.5"),
                                             ("goal_distance_scale", "10")])
@pytest.mark.parametrize("world", ["warehouse", "sparse"])
def test_env_arguments_out_of_range_are_one_line_errors(world, argument, value):
    with pytest.raises(ConfigError, match=f"^{argument}: "):
        gym.make("flatland/Nav-v0", world=world, **{argument: value})


def test_python_arguments_are_checked_when_the_env_is_made_and_numpy_numbers_accepted():
    """A NaN or a string weight in a mix failed at the first reset with NumPy's error; a list of
    scenarios mixing kinematics at whichever reset drew the odd one; float32 was no number."""
    from common.scenario import RobotProfile

    for weights in ({"sparse": float("nan"), "open": 1}, {"sparse": float("inf")}, {"sparse": "1"}):
        with pytest.raises(ConfigError, match=r"^world: got .*; a mix needs at least one kind, each with a finite weight"):
            gym.make("flatland/Nav-v0", world=weights)
    with pytest.raises(ConfigError, match=r"^world: scenarios of robots with kinematics diff, omni; an env's action"):
        gym.make("flatland/Nav-v0", world=[OPEN, OPEN.model_copy(update={"robot": RobotProfile(kinematics="omni")})])
    assert gym.make("flatland/Nav-v0", world=OPEN, goal_threshold=np.float32(0.25)).unwrapped.task.threshold == (0.25, 0.25)
    env = gym.make("flatland/Nav-v0", world=OPEN, robot=RobotProfile(v_max=2.0, radius=0.15))
    env.reset(seed=0)
    assert env.unwrapped.scenario.robot.v_max == 2.0 and env.unwrapped.scenario.robot.radius == 0.15


def test_what_a_copy_would_share_refuses_to_be_copied():
    """A deep copy of a 3D env drove the same PyBullet client (the original's robot moved, and
    closing one closed both); a copy of a lidar79_motion env shared its last scan."""
    import copy
    import pickle

    import physics3d  # noqa: F401  (registers the 3D env)

    three_d = gym.make("physics3d/WarehouseNav-v0", world=OPEN)
    three_d.reset(seed=0)
    with pytest.raises(TypeError, match="a physics3d World is a PyBullet client, which cannot be copied"):
        copy.deepcopy(three_d)
    with pytest.raises(TypeError, match="a physics3d World is a PyBullet client, which cannot be pickled"):
        pickle.dumps(three_d.unwrapped.world)
    three_d.close()
    moving = gym.make("flatland/Nav-v0", world=OPEN, observation="lidar79_motion")
    moving.reset(seed=0)
    with pytest.raises(TypeError, match="the lidar79_motion layout remembers each episode in closures a copy would share"):
        copy.deepcopy(moving)
    # A layout without memory copies, and the copy runs the original's episode.
    plain = gym.make("flatland/Nav-v0", world=OPEN, observation="lidar43_log")
    plain.reset(seed=0)
    twin = copy.deepcopy(plain)
    action = np.array([1.0, 0.2], dtype=np.float32)
    assert all(np.array_equal(plain.step(action)[0], twin.step(action)[0]) for _ in range(5))
    # Among movers too: the copy's people walked on in its world while its readings and lidar kept
    # them where they stood when it was copied (views of packed arrays, each copied on its own).
    crowd = gym.make("flatland/Nav-v0", world="crowd", observation="lidar43_log")
    crowd.reset(seed=0)
    twin = copy.deepcopy(crowd)
    still = np.array([-1.0, 0.0], dtype=np.float32)
    first = crowd.unwrapped.readings.movers.rows.copy()
    for _ in range(30):
        assert np.array_equal(crowd.step(still)[0], twin.step(still)[0])
        assert np.array_equal(crowd.unwrapped.readings.movers.rows, twin.unwrapped.readings.movers.rows)
    assert not np.array_equal(twin.unwrapped.readings.movers.rows[:, :2], first[:, :2])  # they walked
    kept = crowd.unwrapped.readings  # a snapshot: the world's next step leaves it as it was
    rows = kept.movers.rows.copy()
    crowd.step(still)
    assert np.array_equal(kept.movers.rows, rows) and not np.array_equal(crowd.unwrapped.readings.movers.rows, rows)
