"""The navigation env logic both tiers share: scenario per episode, action mapping, observation,
reward terms, termination. A tier subclasses :class:`NavigationEnv` and supplies its world.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping, Sequence

import gymnasium as gym
import numpy as np

from common.actions import ActionMapping
from common.info import Info
from common.kinematics import record, wrap_angle
from common.observations import DEFAULT_GOAL_DISTANCE_SCALE, ObservationLayout, make_layout
from common.readings import Readings, nearest_clearance, nearest_return
from common.robots import footprint_reach
from common.rewards import Reward, StepContext
from common.route import Route
from common.conditions import Conditions
from common.errors import ConfigError, require_flag
from common.scenario import Scenario
from common.sources import ScenarioSource
from common.task import DEFAULT_MAX_STEPS, GoalThreshold, Task
from common.tiers import WorldLike, tier_source


ENV_REGISTRATION = {"order_enforce": False, "disable_env_checker": True}
"""How both tiers register their env: ``gym.make`` adds no wrappers. The env refuses a step
before reset (or after an episode ended) itself, and the tests check it with gymnasium's and
stable-baselines3's env checkers. The two wrappers cost 2.2 and 2.6 µs of flatland's 18.6-19.7 µs
step on IR-SIM's circle world in two paired runs (a third was within the machine's noise)."""


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
        max_steps: int = DEFAULT_MAX_STEPS,
        difficulty: float = 0.5,
        goal_distance_scale: float = DEFAULT_GOAL_DISTANCE_SCALE,
        template: Scenario | None = None,
        action_mapping: str = "linear",
        resample: bool = False,
        goal_threshold: GoalThreshold = None,
        **conditions: Any,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode {render_mode!r}; allowed: None, {', '.join(self.metadata['render_modes'])}")
        self.render_mode = render_mode
        require_flag("resample", resample)
        # Every other keyword is a condition knob (common.conditions), validated there by name.
        self.conditions = Conditions.parse({k: v for k, v in conditions.items() if v is not None}).for_tier(self.tier)
        self.source = tier_source(self.tier, world, difficulty, self.conditions, template, resample)
        if self.conditions.profile is None:
            # The action space is fixed: found now, not at whichever reset first draws the odd one out.
            kinds = {example.robot.kinematics for example in self.source.examples}
            if len(kinds) > 1:
                raise ConfigError(None, "world", f"scenarios of robots with kinematics {', '.join(sorted(kinds))}; an "
                                  "env's action space is fixed, so its scenarios must share the robot's kinematics")
        self.task = Task(goal_threshold, max_steps)
        self.observation_name = observation
        self.action_mapping = action_mapping
        self.goal_distance_scale = goal_distance_scale
        self.reward = Reward(reward)
        self._reads_heading = self.reward.reads("heading_error")
        self._reads_route = self.reward.reads("route_gain")
        self._route: Route | None = None
        self._route_distance = 0.0
        self.world: WorldLike | None = None
        self._drawn: Scenario | None = None
        self._load(self.source.draw(np.random.default_rng(0)))
        self.action_space = self.actions.space  # one number per command channel of the robot's kinematics
        self.observation_space = self.layout.space
        self._readings: Readings | None = None
        self._pending_rng: dict | None = None
        self._closed = False
        self._ended = False  # the episode terminated or was truncated: step() needs a reset first
        self.trajectory: list[tuple[float, float]] = []

    @property
    def max_steps(self) -> int:
        """Steps before an episode is truncated."""
        return self.task.max_steps

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
        try:
            self.world = self._build_world(drawn)
        except ConfigError as error:  # what a tier cannot build, named in the file the user wrote
            file = getattr(self.source, "file", None)
            if error.source is not None or file is None:
                raise
            raise error.with_source(file.path) from None
        self.scenario = scenario = self.world.scenario
        # Frames a recorder writes per second: one per step (3D: control_period may change the step).
        self.metadata = {**type(self).metadata, "render_fps": round(1.0 / self.world.period, 3)}
        if previous is None or scenario.robot != previous.robot or scenario.lidar != previous.lidar:
            if previous is not None and scenario.robot.kinematics != previous.robot.kinematics:
                raise ValueError(f"scenario {scenario.name!r}: a {scenario.robot.kinematics} robot after a "
                                 f"{previous.robot.kinematics} one; an env's action space is fixed, so its "
                                 "scenarios must share the robot's kinematics")
            self.layout = self._make_layout(scenario)
            self.actions = ActionMapping(scenario.robot, self.action_mapping)
            # Per beam, how far it runs inside the footprint, for a reward that reads the clearance.
            self._reach = footprint_reach(scenario.robot, scenario.lidar) if self.reward.reads("clearance") else None
        self._goal = scenario.goal
        self._stride = scenario.robot.v_max * self.world.period

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        """Start an episode; ``options={"resample": True}`` redraws a random world file's layout
        (IR-SIM's ``reset(random=True)``) where a plain reset restores its initial state."""
        if self._closed:
            self._refuse("reset")
        super().reset(seed=seed)
        if self._pending_rng is not None:
            self.np_random.bit_generator.state, self._pending_rng = self._pending_rng, None
        resample = (options or {}).get("resample", False)
        require_flag('options["resample"]', resample)  # "no" read as true
        drawn = self.source.draw(self.np_random, resample=resample)
        if drawn is not self._drawn:
            self._load(drawn)
        scenario = self.scenario
        self._readings = self.world.reset(seed=int(self.np_random.integers(2**31 - 1)))
        self.task.start(scenario, self._readings, self.np_random)
        self._ended = False
        self.reward.reset()
        self.layout.reset()
        if self.layout.reads_route or self._reads_route:
            self._plan_route(scenario)
        self.trajectory = [tuple(self._readings.pose[:2])]
        if self.render_mode == "human":
            self.render()
        info = Info(distance=self.task.distance, scenario=scenario.name, goal_threshold=self.task.radius)
        return self.layout(self._readings, self._goal), info

    def _plan_route(self, scenario: Scenario) -> None:
        """The episode's route on the static map, for the layout and the reward that read one (a
        fixed world's route is planned once)."""
        route = self._route
        if route is None or route.scenario is not scenario or route.goal_radius != self.task.radius:
            route = self._route = Route(scenario, self.task.radius)
        self.layout.follow(route)
        self._route_distance = route.distance(*self._readings.pose[:2])

    def step(self, action) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self._closed or self._readings is None or self._ended:
            self._refuse("step")
        command = self.actions.to_velocity(action)
        readings = self._readings = self.world.step(*command)
        # The reward's speed and turn: the command's for a differential drive, else its forward
        # speed and the turn the robot made.
        v, w = command if self.actions.kinematics == "diff" else (command[0], readings.velocity[1])
        task, previous = self.task, self.task.distance
        outcome = task.step(readings)
        reached = outcome == "success"
        bearing = 0.0
        if self._reads_heading:
            x, y, yaw = readings.pose
            bearing = wrap_angle(math.atan2(self._goal[1] - y, self._goal[0] - x) - yaw)
        clearance = math.inf if self._reach is None else nearest_clearance(readings.lidar, self._reach)
        route_gain = 0.0
        if self._reads_route:
            previous_route, self._route_distance = self._route_distance, self._route.distance(*readings.pose[:2])
            route_gain = previous_route - self._route_distance
        ctx = record(StepContext, (task.distance, previous, bearing, v, w, nearest_return(readings.lidar),
                                   readings.collided, reached, clearance, route_gain, self._stride))
        reward, shares = self.reward(ctx)
        # A crash is a termination, not a truncation: its value must not bootstrap from the next state.
        terminated = reached or outcome == "collision"
        truncated = outcome == "timeout"
        self._ended = terminated or truncated
        self.trajectory.append((readings.pose[0], readings.pose[1]))
        info = Info(reward_terms=shares, distance=task.distance, is_success=reached, collided=readings.collided)
        if self.render_mode == "human":
            self.render()
        return self.layout(readings, self._goal), float(reward), terminated, truncated, info

    def _refuse(self, call: str) -> None:
        """Raise what ``call`` meets on an env that is closed or was never reset: without the
        check a first step measured progress from nowhere (a reward near -100)."""
        if self._closed:
            raise gym.error.ClosedEnvironmentError(f"{call}() on a closed env; make a new one")
        if self._ended:
            # Stepping on paid the goal's +100 again every step, the robot driving on past its end.
            raise gym.error.ResetNeeded(f"{call}() after the episode ended (terminated or truncated); call reset() first")
        raise gym.error.ResetNeeded(f"{call}() before reset(); call reset() first")

    def render(self) -> np.ndarray | None:
        """The tier's frame (``rgb_array``) or window (``human``); None without a render mode or
        before the first reset. Refused on a closed env, as ``step`` is."""
        if self._closed:
            self._refuse("render")
        if self.render_mode is None or self._readings is None:
            return None
        return self._draw()

    def _draw(self) -> np.ndarray | None:
        raise NotImplementedError

    def close(self) -> None:
        """Release the world; ``step``, ``reset`` and ``render`` refuse after this, in both tiers alike."""
        self._closed = True
        super().close()

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
