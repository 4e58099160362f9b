"""The navigation env logic both tiers share: scenario per episode, action mapping, observation,
reward terms, termination. A tier subclasses :class:`NavigationEnv` and supplies its world.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping, Protocol, Sequence

import gymnasium as gym
import numpy as np

from common.actions import ACTION_SPACE, ActionMapping
from common.kinematics import wrap_angle
from common.observations import DEFAULT_GOAL_DISTANCE_SCALE, ObservationLayout, make_layout
from common.readings import Readings, nearest_return
from common.rewards import Reward, StepContext
from common.conditions import Conditions, HeadingSource
from common.errors import ConfigError, quote
from common.scenario import MAX_LENGTH, Scenario
from common.sources import ScenarioSource, scenario_source
from common.tiers import generator_template


class WorldLike(Protocol):
    """What the env needs of a tier's world."""

    scenario: Scenario

    def reset(self, seed: int | None = None) -> Readings: ...

    def step(self, v: float, w: float) -> Readings: ...


class NavigationEnv(gym.Env):
    """Reach a goal without touching anything (see a tier's env class for the full description)."""

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}
    tier = "flatland"  # the tier whose default conditions apply (common.conditions)

    def __init__(
        self,
        world: Scenario | str | Path | Sequence[Scenario] | ScenarioSource = "sparse",
        observation: str = "nav7",
        reward: str | Mapping[str, Any] = "default",
        render_mode: str | None = None,
        max_steps: int = 500,
        difficulty: float = 0.5,
        goal_distance_scale: float = DEFAULT_GOAL_DISTANCE_SCALE,
        template: Scenario | None = None,
        action_mapping: str = "linear",
        resample: bool = False,
        goal_threshold: float | Sequence[float] | None = None,
        robot: str | Mapping[str, Any] | None = None,
        lidar_noise: float | None = None,
        odometry_noise: float | None = None,
        action_delay: int | tuple[int, int] | None = None,
        motor_scale: Sequence[float] | None = None,
        friction: Sequence[float] | None = None,
        mass_scale: Sequence[float] | None = None,
        control_period: float | None = None,
        dynamics: str | None = None,
        heading_source: HeadingSource | None = None,
        gyro_noise: float | None = None,
        gyro_bias: float | None = None,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode {render_mode!r}; allowed: None, {', '.join(self.metadata['render_modes'])}")
        self.render_mode = render_mode
        given = dict(robot=robot, lidar_noise=lidar_noise, odometry_noise=odometry_noise, action_delay=action_delay,
                     motor_scale=motor_scale, friction=friction, mass_scale=mass_scale, control_period=control_period,
                     dynamics=dynamics, heading_source=heading_source, gyro_noise=gyro_noise, gyro_bias=gyro_bias)
        self.conditions = Conditions.parse({k: v for k, v in given.items() if v is not None}).for_tier(self.tier)
        template = template or generator_template(self.tier)
        if self.conditions.profile is not None:
            # Generated scenarios leave gaps sized for the robot that will drive them.
            template = template.model_copy(update={"robot": self.conditions.profile})
        self.source = scenario_source(world, difficulty, template, resample)
        self.goal_threshold = threshold_range(goal_threshold)
        self.observation_name = observation
        self.action_mapping = action_mapping
        self.goal_distance_scale = goal_distance_scale
        self.reward = Reward(reward)
        self.max_steps = int(max_steps)
        self.action_space = ACTION_SPACE
        self._drawn: Scenario | None = None
        self._load(self.source.draw(np.random.default_rng(0)))
        self.observation_space = self.layout.space
        self._readings: Readings | None = None
        self._pending_rng: dict | None = None
        self._steps = 0
        self._prev_distance = 0.0
        self.trajectory: list[tuple[float, float]] = []

    def _build_world(self, scenario: Scenario) -> WorldLike:
        raise NotImplementedError

    def _make_layout(self, scenario: Scenario) -> ObservationLayout:
        """The observation layout for a scenario's robot and lidar (after its world is built)."""
        return make_layout(self.observation_name, scenario.robot, scenario.lidar, self.goal_distance_scale)

    def _load(self, drawn: Scenario) -> None:
        """Build the world, observation layout and action mapping for a drawn scenario, under the
        env's conditions (``self.scenario`` is the scenario as conditioned: robot, sensor noise)."""
        previous = None if self._drawn is None else self.scenario
        self._drawn = drawn
        self.scenario = scenario = self.conditions.scenario(drawn)
        self.world = self._build_world(scenario)
        if previous is None or scenario.robot != previous.robot or scenario.lidar != previous.lidar:
            self.layout = self._make_layout(scenario)
            self.actions = ActionMapping(scenario.robot, self.action_mapping)
        self._goal = scenario.goal
        self._threshold = scenario.goal_threshold

    def _distance_and_bearing(self, readings: Readings) -> tuple[float, float]:
        x, y, yaw = readings.pose
        dx, dy = self._goal[0] - x, self._goal[1] - y
        return math.hypot(dx, dy), wrap_angle(math.atan2(dy, dx) - yaw)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        """Start an episode; ``options={"resample": True}`` redraws a random world file's layout
        (IR-SIM's ``reset(random=True)``) where a plain reset restores its initial state."""
        super().reset(seed=seed)
        if self._pending_rng is not None:
            self.np_random.bit_generator.state, self._pending_rng = self._pending_rng, None
        drawn = self.source.draw(self.np_random, resample=bool((options or {}).get("resample", False)))
        if drawn is not self._drawn:
            self._load(drawn)
        scenario = self.scenario
        self._readings = self.world.reset(seed=int(self.np_random.integers(2**31 - 1)))
        if self.goal_threshold is not None:
            low, high = self.goal_threshold
            self._threshold = float(self.np_random.uniform(low, high)) if high > low else low
        self.reward.reset()
        self._steps = 0
        self._prev_distance, _ = self._distance_and_bearing(self._readings)
        self.trajectory = [tuple(self._readings.pose[:2])]
        if self.render_mode == "human":
            self.render()
        info = {"distance": self._prev_distance, "scenario": scenario.name, "goal_threshold": self._threshold}
        return self.layout(self._readings, self._goal), info

    def step(self, action) -> tuple[np.ndarray, float, bool, bool, dict]:
        v, w = self.actions.to_velocity(action)
        readings = self._readings = self.world.step(v, w)
        self._steps += 1
        distance, bearing = self._distance_and_bearing(readings)
        reached = distance < self._threshold
        ctx = StepContext(distance, self._prev_distance, bearing, v, w, nearest_return(readings.lidar), readings.collided, reached)
        self._prev_distance = distance
        reward, shares = self.reward(ctx)
        # A crash is a termination, not a truncation: its value must not bootstrap from the next state.
        terminated = reached or readings.collided
        truncated = not terminated and self._steps >= self.max_steps
        self.trajectory.append((readings.pose[0], readings.pose[1]))
        info = {"reward_terms": shares, "distance": distance, "is_success": reached, "collided": readings.collided}
        if self.render_mode == "human":
            self.render()
        return self.layout(readings, self._goal), float(reward), terminated, truncated, info

    def rng_state(self) -> dict:
        """The state of the env's random generator (JSON-able): what the next reset will draw from."""
        return self.np_random.bit_generator.state

    def restore_rng(self, state: dict) -> None:
        """Make the next reset continue from ``state`` (whatever seed it is given), so a resumed
        run draws the scenarios the interrupted one would have drawn next."""
        self._pending_rng = state

    @property
    def readings(self) -> Readings | None:
        """The last readings (None before the first reset)."""
        return self._readings


def judged_radius(env_kwargs: Mapping[str, Any]) -> float | None:
    """The goal radius a policy trained with ``env_kwargs`` is judged by: its ``goal_threshold``,
    the smallest of a range (it trained to arrive that close), or None (each scenario's own)."""
    limits = threshold_range(env_kwargs.get("goal_threshold"))
    return None if limits is None else limits[0]


def with_radius(scenarios: Sequence[Scenario], radius: float | None) -> list[Scenario]:
    """The scenarios judged at ``radius`` (unchanged for None)."""
    return list(scenarios) if radius is None else [s.model_copy(update={"goal_threshold": radius}) for s in scenarios]


def threshold_range(value: float | Sequence[float] | None) -> tuple[float, float] | None:
    """``goal_threshold`` as (low, high): None keeps each scenario's, a number fixes it, a pair is drawn
    from uniformly per episode (so a policy learns to arrive whatever radius it is judged by)."""
    if value is None:
        return None
    pair = (value, value) if isinstance(value, (int, float)) and not isinstance(value, bool) else value
    try:
        low, high = (float(v) for v in pair)
    except (TypeError, ValueError):
        raise ConfigError(None, "goal_threshold", f"got {quote(value)}; allowed: null, a number or [low, high] in metres") from None
    if not (0.0 < low <= high <= MAX_LENGTH):
        raise ConfigError(None, "goal_threshold", f"got {quote(value)}; allowed: 0 < low <= high <= {MAX_LENGTH:g} m")
    return low, high
