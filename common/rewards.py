"""Reward terms, weights and presets.

A reward is a mapping of term name -> weight (or ``{weight: w, <param>: value}``); each term is a
small function of a :class:`StepContext` returning an unweighted value, and :class:`Reward` sums
``weight * term`` and reports every weighted share, so ``info["reward_terms"]`` shows what the
agent was paid for. ``default`` is the envs' default; the tutorial presets reproduce the two
tutorials' final rewards.
"""

from __future__ import annotations

import collections
import functools
import math
from pathlib import Path
from typing import Any, Callable, Mapping, NamedTuple

from common.errors import ConfigError, quote
from common.info import Info
from common.params import coerce, is_finite, keyword_parameters


class StepContext(NamedTuple):
    """What a reward term may look at after one step (ground truth, metres and radians)."""

    distance: float  # to the goal, after the step
    prev_distance: float  # to the goal, before the step
    heading_error: float  # goal bearing minus yaw, wrapped to [-pi, pi) (see COSTLY_FIELDS)
    v: float  # commanded linear velocity, m/s
    w: float  # commanded angular velocity, rad/s
    min_range: float  # nearest lidar return, m
    collided: bool
    reached: bool
    clearance: float = math.inf  # nearest return less how far its beam runs inside the footprint, m (see COSTLY_FIELDS)
    route_gain: float = 0.0  # metres of the route's cost-to-go gained this step (see COSTLY_FIELDS)
    stride: float = 1.0  # m: the robot's step at full speed (v_max times the step's period)


def progress(ctx: StepContext, positive_only: bool = False, per_stride: bool = False) -> float:
    """Metres gained toward the goal this step (only gains, if ``positive_only``); with
    ``per_stride``, in the robot's full-speed steps (``ctx.stride``) instead: a robot four times
    slower then earns as much per step as a fast one, so the per-step terms (time, clearance)
    weigh alike against its progress, where in metres they cost it four times as much per metre."""
    gained = ctx.prev_distance - ctx.distance
    if per_stride:
        gained /= ctx.stride
    return max(0.0, gained) if positive_only else gained


def route_progress(ctx: StepContext) -> float:
    """Metres gained along the route to the goal this step (:mod:`common.route`): toward the gap
    the route goes through, where ``progress`` pays for closing on the goal through the fence."""
    return ctx.route_gain


def heading_alignment(ctx: StepContext, min_distance: float = 1.0) -> float:
    """1 - |heading error| (radians) while farther than ``min_distance`` from the goal, else 0."""
    return 1.0 - abs(ctx.heading_error) if ctx.distance > min_distance else 0.0


def goal(ctx: StepContext) -> float:
    """1 on the step the goal is reached."""
    return 1.0 if ctx.reached else 0.0


def collision(ctx: StepContext) -> float:
    """1 on the step the robot collides."""
    return 1.0 if ctx.collided else 0.0


def time(ctx: StepContext) -> float:
    """1 every step (give it a negative weight to make the robot hurry)."""
    return 1.0


def proximity(ctx: StepContext, threshold: float = 0.3) -> float:
    """How far the nearest lidar return is inside ``threshold`` metres (0 outside it)."""
    return max(0.0, threshold - ctx.min_range)


def clearance(ctx: StepContext, threshold: float = 0.3) -> float:
    """How far the robot's clearance (from its footprint, not its centre) is inside ``threshold``
    metres: ``proximity`` for robots of every shape and size."""
    return max(0.0, threshold - ctx.clearance)


def near_speed(ctx: StepContext, threshold: float = 0.5) -> float:
    """Speed |v| (m/s) times how far the nearest return is inside ``threshold`` metres: prices
    passing obstacles fast, where ``proximity`` prices only passing them close."""
    return abs(ctx.v) * max(0.0, threshold - ctx.min_range)


def proximity_bands(ctx: StepContext, bands: tuple[tuple[float, float], ...] = ((0.3, 5.0), (0.5, 1.0))) -> float:
    """The value of the first (distance, value) band whose distance exceeds the nearest return."""
    for distance, value in bands:
        if ctx.min_range < distance:
            return float(value)
    return 0.0


def spin(ctx: StepContext, threshold: float = 0.8) -> float:
    """How much |w| exceeds ``threshold`` rad/s (0 below it)."""
    return max(0.0, abs(ctx.w) - threshold)


class _Stuck:
    """1 when the distance to the goal changed by less than ``threshold`` metres, either way, over
    the last ``window`` steps, farther than ``min_distance`` from the goal: the 3D tutorial's
    ``abs(sum(recent_progress))``, so a robot backing away is not stuck. Stateful: it keeps the
    recent progress."""

    def __init__(self, window: int = 20, threshold: float = 0.05, min_distance: float = 1.0) -> None:
        self.window, self.threshold, self.min_distance = window, threshold, min_distance
        self.recent: collections.deque[float] = collections.deque(maxlen=window)

    def reset(self) -> None:
        self.recent.clear()

    def __call__(self, ctx: StepContext) -> float:
        self.recent.append(ctx.prev_distance - ctx.distance)
        full = len(self.recent) == self.window
        return 1.0 if full and abs(sum(self.recent)) < self.threshold and ctx.distance > self.min_distance else 0.0


TERMS: dict[str, Callable[..., Any]] = {
    "progress": progress,
    "route_progress": route_progress,
    "heading_alignment": heading_alignment,
    "goal": goal,
    "collision": collision,
    "time": time,
    "stuck": _Stuck,
    "proximity": proximity,
    "clearance": clearance,
    "near_speed": near_speed,
    "proximity_bands": proximity_bands,
    "spin": spin,
}
STATEFUL = {"stuck"}

PRESETS: dict[str, dict[str, Any]] = {
    # The envs' default, and what every shipped curriculum trains with: signed progress (a loop
    # nets nothing, the time term makes it cost), a crash costing what the goal pays, and a small
    # price for closing within 0.5 m of an obstacle (docs/training.md measures each piece).
    "default": {
        "progress": 10.0,
        "goal": 100.0,
        "collision": -100.0,
        "time": -0.05,
        "proximity": {"weight": -5.0, "threshold": 0.5},
    },
    # 2D tutorial, reward v2: progress-based, spin and proximity penalties, goal bonus. Kept as the
    # tutorial had it, flaw included: paying only for gains, a loop earns on every approach and
    # loses nothing on the way back, and a crash ends the proximity penalties.
    "tutorial2d": {
        "progress": {"weight": 10.0, "positive_only": True},
        "spin": {"weight": -5.0, "threshold": 0.8},
        "proximity_bands": {"weight": -1.0, "bands": [[0.3, 5.0], [0.5, 1.0]]},
        "goal": 100.0,
    },
    # 3D tutorial's final reward.
    "tutorial3d": {
        "progress": 1.0,
        "heading_alignment": {"weight": 0.1, "min_distance": 1.0},
        "goal": 50.0,
        "collision": -10.0,
        "time": -0.01,
        "stuck": {"weight": -0.1, "window": 20, "threshold": 0.05, "min_distance": 1.0},
        "proximity": {"weight": -1.0, "threshold": 0.3},
        "spin": {"weight": -0.2, "threshold": 2.0},
    },
}


# The step context's fields that cost the env a computation each step, and the terms that read
# each: a reward without those terms gets 0 (heading_error, route_gain) or inf (clearance) there.
COSTLY_FIELDS = {"heading_error": ("heading_alignment",), "clearance": ("clearance",), "route_gain": ("route_progress",)}


class Reward:
    """A weighted sum of terms. Call :meth:`reset` at each episode start.

    Args:
        spec: a preset name or a mapping of term -> weight | {weight, **params}.
        source: the file the spec came from, for error messages.
    """

    def __init__(self, spec: str | Mapping[str, Any], source: str | Path | None = None) -> None:
        self.spec = resolve_reward_spec(spec, source)
        self._terms: list[tuple[str, float, Callable[[StepContext], float]]] = []
        self._stateful = []
        for name, entry in self.spec.items():
            weight, params = float(entry["weight"]), {k: v for k, v in entry.items() if k != "weight"}
            if name in STATEFUL:
                fn = TERMS[name](**params)
                self._stateful.append(fn)
            else:
                fn = functools.partial(TERMS[name], **params) if params else TERMS[name]
            self._terms.append((name, weight, fn))

    def reads(self, field: str) -> bool:
        """Whether a term of this reward reads the step context's ``field``, one of
        :data:`COSTLY_FIELDS` (the env works those out only for a reward that reads them)."""
        return any(term in self.spec for term in COSTLY_FIELDS[field])

    def reset(self) -> None:
        """Forget per-episode state (e.g. the stuck detector's history)."""
        for term in self._stateful:
            term.reset()

    def __call__(self, ctx: StepContext) -> tuple[float, Info]:
        """The total reward and each term's weighted share (summed in the terms' order)."""
        shares = Info()
        total = 0.0
        for name, weight, fn in self._terms:  # one loop: a comprehension and sum() cost 40% more per step
            shares[name] = share = weight * fn(ctx)
            total += share
        return total, shares


def resolve_reward_spec(spec: str | Mapping[str, Any], source: str | Path | None = None) -> dict[str, dict[str, Any]]:
    """Validate a reward spec and return it as term -> {weight, **params}."""
    if isinstance(spec, str):
        if spec not in PRESETS:
            raise ConfigError(source, "reward", f"unknown preset {quote(spec)}; allowed: {', '.join(PRESETS)} or a mapping of term -> weight")
        spec = PRESETS[spec]
    if not isinstance(spec, Mapping) or not spec:
        raise ConfigError(source, "reward", "expected a preset name or a non-empty mapping of term -> weight")
    resolved: dict[str, dict[str, Any]] = {}
    for name, entry in spec.items():
        field = f"reward.{name}"
        if name not in TERMS:
            raise ConfigError(source, field, f"unknown reward term; allowed: {', '.join(TERMS)}")
        entry = {"weight": entry} if not isinstance(entry, Mapping) else dict(entry)
        weight = entry.get("weight")
        if isinstance(weight, bool) or not isinstance(weight, (int, float)) or not is_finite(weight):
            raise ConfigError(source, f"{field}.weight", f"expected a finite number, got {quote(weight)}")
        allowed = keyword_parameters(TERMS[name])
        for param, value in list(entry.items()):
            if param == "weight":
                continue
            if param not in allowed:
                names = ", ".join(["weight", *allowed])
                raise ConfigError(source, f"{field}.{param}", f"unknown parameter; allowed: {names}")
            annotation, default = allowed[param]
            entry[param] = coerce(value, annotation, default, source, f"{field}.{param}")
        resolved[name] = entry
    return resolved
