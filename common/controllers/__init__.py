"""Classical navigation controllers that read only a real robot's sensors.

>>> controller = make_controller("pid_blend", {"safety_distance": 0.8})
>>> controller.bind(scenario.robot, scenario.lidar); controller.reset()
>>> v, w = controller.act(readings, scenario.goal)

Every parameter is a constructor keyword argument with a default, so a YAML mapping
``controllers: {<name>: {<param>: value}}`` can override any of them; ``make_controller`` checks
names and types and reports a bad one as a one-line :class:`ConfigError`.
"""

from __future__ import annotations

import inspect
import math
import types
import typing
from pathlib import Path
from typing import Any

from common.controllers.base import Controller, LidarGeometry
from common.controllers.go_to_goal import GoToGoal
from common.controllers.path_follower import AStarPursuit, PathFollower, RrtPursuit
from common.controllers.pid_blend import PidHeadingBlend
from common.controllers.potential_field import PotentialField
from common.controllers.reactive import ReactiveAvoidance
from common.errors import ConfigError, quote

__all__ = ["AStarPursuit", "CONTROLLERS", "Controller", "GoToGoal", "PathFollower", "RrtPursuit", "LidarGeometry", "PidHeadingBlend", "PotentialField",
           "ReactiveAvoidance", "controller_parameters", "make_controller"]

CONTROLLERS: dict[str, type[Controller]] = {
    "go_to_goal": GoToGoal,
    "reactive": ReactiveAvoidance,
    "potential_field": PotentialField,
    "pid_blend": PidHeadingBlend,
    "astar_pursuit": AStarPursuit,
    "rrt_pursuit": RrtPursuit,
}


def controller_parameters(cls: type[Controller]) -> dict[str, tuple[Any, Any]]:
    """The constructor's keyword parameters of a controller class: name -> (type annotation, default)."""
    hints = typing.get_type_hints(cls.__init__)
    return {name: (hints.get(name, Any), p.default) for name, p in inspect.signature(cls.__init__).parameters.items()
            if name != "self" and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}


def make_controller(name: str, params: dict | None = None, source: str | Path | None = None) -> Controller:
    """A controller by registry name, its defaults overridden by ``params``.

    Raises :class:`ConfigError` (field ``controllers.<name>[.<param>]``) for an unknown controller,
    an unknown parameter or a value of the wrong type.
    """
    if name not in CONTROLLERS:
        raise ConfigError(source, f"controllers.{name}", f"unknown controller; allowed: {', '.join(CONTROLLERS)}")
    cls = CONTROLLERS[name]
    if params is None:
        params = {}
    if not isinstance(params, dict):
        raise ConfigError(source, f"controllers.{name}",
                          f"expected a mapping of parameters, got {type(params).__name__}")
    allowed = controller_parameters(cls)
    kwargs = {}
    for key, value in params.items():
        field = f"controllers.{name}.{key}"
        if key not in allowed:
            raise ConfigError(source, field, f"unknown parameter; allowed: {', '.join(allowed)}")
        annotation, default = allowed[key]
        kwargs[key] = _coerce(value, annotation, default, source, field)
    return cls(**kwargs)


def _coerce(value: Any, annotation: Any, default: Any, source: str | Path | None, field: str) -> Any:
    """``value`` as the annotated type (an int is a valid float), or a ConfigError naming what is allowed."""
    options = typing.get_args(annotation) if typing.get_origin(annotation) in (typing.Union, types.UnionType) else (
        annotation,)
    for option in options:
        if option is type(None) and value is None:
            return None
        # bool is an int in Python, but "true" for a gain is a mistake, not 1.0.
        if option is float and isinstance(value, (int, float)) and not isinstance(value, bool):
            if math.isfinite(value):
                return float(value)
        elif option is int and isinstance(value, int) and not isinstance(value, bool):
            return value
        elif option in (bool, str) and isinstance(value, option):
            return value
        elif typing.get_origin(option) is typing.Literal and value in typing.get_args(option):
            return value
        elif option is Any:
            return value
    allowed = " or ".join(_describe(option) for option in options)
    raise ConfigError(source, field, f"got {quote(value)}; allowed: {allowed} (default {quote(default)})")


def _describe(option: Any) -> str:
    if option is type(None):
        return "null"
    if typing.get_origin(option) is typing.Literal:
        return "one of " + ", ".join(repr(v) for v in typing.get_args(option))
    return {float: "a finite number", int: "an integer", bool: "true/false", str: "a string"}.get(
        option, getattr(option, "__name__", str(option)))
