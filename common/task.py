"""The rules of an episode, for the env and the evaluator alike: the goal radius, and how it ends.

An episode ends in *success* when the robot's true position comes within the goal radius of the
goal, checked first, so arriving and touching on the same step counts as arriving; in *collision*
when the robot touches anything; in *stuck* (when judged: the evaluator does, training does not)
when it drove less than :data:`STUCK_DISTANCE` over the last :data:`STUCK_WINDOW` steps; and in
*timeout* when it reaches its step limit. The env terminates on success and collision and
truncates on timeout (a crash must not bootstrap from the next state).

The goal radius is a scenario's own, or a ``goal_threshold``: a radius for every episode, or
``[low, high]`` drawn per episode (a policy trained so arrives whatever radius it is judged by,
and is judged by the smallest: :func:`judged_radius`).
"""

from __future__ import annotations

import math
import numbers
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from common.errors import ConfigError, did_you_mean, quote, require_flag
from common.readings import Readings
from common.scenario import MAX_LENGTH, Scenario

if TYPE_CHECKING:
    from common.conditions import Conditions

OUTCOMES = ("success", "collision", "timeout", "stuck")
DEFAULT_MAX_STEPS = 500
MAX_STEPS = 1_000_000
MAX_EPISODES = 1_000_000  # in one evaluation, from a file or the command line
STUCK_WINDOW = 100  # steps
STUCK_DISTANCE = 0.1  # m: an agent that moved less than this over the window is stuck

GoalThreshold = float | Sequence[float] | None


def threshold_range(value: GoalThreshold) -> tuple[float, float] | None:
    """``goal_threshold`` as (low, high): None keeps each scenario's, a number fixes it, a pair is drawn
    from uniformly per episode."""
    if value is None:
        return None
    # numbers.Real: NumPy's float32 (a policy's output, a config's array) is no float, but a number.
    pair = (value, value) if isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_)) else value
    try:
        low, high = (float(v) for v in pair)
    except (TypeError, ValueError):
        raise ConfigError(None, "goal_threshold", f"got {quote(value)}; allowed: null, a number or [low, high] in metres") from None
    if not (0.0 < low <= high <= MAX_LENGTH):
        raise ConfigError(None, "goal_threshold", f"got {quote(value)}; allowed: 0 < low <= high <= {MAX_LENGTH:g} m")
    return low, high


# Env arguments besides the conditions (common/conditions.py) that shape training only.
TASK_OPTIONS = {"flatland": ("goal_threshold", "resample"), "physics3d": ("goal_threshold", "resample", "camera")}


def check_env_kwargs(env_kwargs: Mapping[str, Any], tier: str, source: str | Path | None, field: str) -> "Conditions":
    """Every key a condition of ``tier`` or one of its task options, every value valid (a
    :class:`ConfigError` naming ``source`` and ``field.key``); the conditions, as the tier fills them in."""
    from common.conditions import CONDITION_KEYS, ONLY_2D, ONLY_3D, conditions_of

    other_tier = ONLY_3D if tier == "flatland" else ONLY_2D
    allowed = sorted((*(k for k in CONDITION_KEYS if k not in other_tier), *TASK_OPTIONS[tier]))
    for key in env_kwargs:
        if key not in allowed:
            raise ConfigError(source, f"{field}.{key}",
                              f"not a {tier} env argument{did_you_mean(key, allowed)}; allowed: {', '.join(allowed)}")
    try:
        conditions = conditions_of(dict(env_kwargs), source, field).for_tier(tier)
        if "goal_threshold" in env_kwargs:
            threshold_range(env_kwargs["goal_threshold"])
    except ConfigError as error:  # named once: the conditions' own errors start with the field already
        named = error.field if (error.field or "").startswith(field) else f"{field}.{error.field}"
        raise ConfigError(source, named, error.problem) from None
    for flag in ("resample", "camera"):
        if flag in env_kwargs:
            require_flag(f"{field}.{flag}", env_kwargs[flag], source)
    return conditions


def judged_radius(env_kwargs: Mapping[str, Any]) -> float | None:
    """The goal radius a policy trained with ``env_kwargs`` is judged by: its ``goal_threshold``,
    the smallest of a range (it trained to arrive that close), or None (each scenario's own)."""
    limits = threshold_range(env_kwargs.get("goal_threshold"))
    return None if limits is None else limits[0]


class Task:
    """Judges episodes: ``start`` at the first readings, then ``step`` with each next readings
    until it returns an outcome.

    Args:
        goal_threshold: the goal radius (see the module); None: each scenario's own.
        max_steps: steps before a timeout.
        judge_stuck: end an episode that stopped making way (the evaluator's rule), measuring
            the path driven on the way (``travelled``; training needs neither).
    """

    def __init__(self, goal_threshold: GoalThreshold = None, max_steps: int = DEFAULT_MAX_STEPS,
                 judge_stuck: bool = False) -> None:
        self.threshold = threshold_range(goal_threshold)
        if isinstance(max_steps, bool) or not isinstance(max_steps, numbers.Integral) or not 1 <= max_steps <= MAX_STEPS:
            raise ConfigError(None, "max_steps", f"got {quote(max_steps)}; allowed: a whole number of steps from 1 to {MAX_STEPS:,}")
        self.max_steps = int(max_steps)
        self.judge_stuck = judge_stuck
        self.goal, self.radius = (0.0, 0.0), 0.0
        self.distance = self.travelled = 0.0
        self.steps = 0
        self._position = (0.0, 0.0)
        self._recent: list[float] = []

    def radius_for(self, scenario: Scenario, rng: np.random.Generator | None = None) -> float:
        """The goal radius of an episode of ``scenario``: drawn from ``rng`` if the threshold is a range."""
        if self.threshold is None:
            return scenario.goal_threshold
        low, high = self.threshold
        return float(rng.uniform(low, high)) if high > low and rng is not None else low

    def start(self, scenario: Scenario, readings: Readings, rng: np.random.Generator | None = None) -> None:
        """Begin an episode of ``scenario`` at ``readings``."""
        self.goal, self.radius = scenario.goal, self.radius_for(scenario, rng)
        self.steps, self.travelled = 0, 0.0
        self._position = (readings.pose[0], readings.pose[1])
        self.distance = math.hypot(self.goal[0] - self._position[0], self.goal[1] - self._position[1])
        self._recent = [0.0]

    def step(self, readings: Readings) -> str | None:
        """Account for one step that led to ``readings``; the episode's outcome if it ended."""
        x, y = readings.pose[0], readings.pose[1]
        self.steps += 1
        if self.judge_stuck:
            self.travelled += math.hypot(x - self._position[0], y - self._position[1])
            self._position = (x, y)
        self.distance = distance = math.hypot(self.goal[0] - x, self.goal[1] - y)
        if distance < self.radius:
            return "success"
        if readings.collided:
            return "collision"
        if self.judge_stuck:
            recent = self._recent
            recent.append(self.travelled)
            if len(recent) > STUCK_WINDOW and recent[-1] - recent[-1 - STUCK_WINDOW] < STUCK_DISTANCE:
                return "stuck"
        return "timeout" if self.steps >= self.max_steps else None
