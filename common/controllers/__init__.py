"""Classical navigation controllers that read only a real robot's sensors.

>>> controller = make_controller("pid_blend", {"safety_distance": 0.8})
>>> controller.bind(scenario.robot, scenario.lidar); controller.reset()
>>> v, w = controller.act(readings, scenario.goal)

Every parameter is a constructor keyword argument with a default, so a YAML mapping
``controllers: {<name>: {<param>: value}}`` can override any of them; ``make_controller`` checks
names and types and reports a bad one as a one-line :class:`ConfigError`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from common.controllers.base import Controller, LidarGeometry
from common.controllers.dwa import DynamicWindow
from common.controllers.go_to_goal import GoToGoal
from common.controllers.path_follower import AStarPursuit, PathFollower, RrtPursuit
from common.controllers.pid_blend import PidHeadingBlend
from common.controllers.potential_field import PotentialField
from common.controllers.reactive import ReactiveAvoidance
from common.controllers.velocity_obstacle import VelocityObstacle
from common.errors import ConfigError
from common.params import coerce, keyword_parameters

__all__ = ["AStarPursuit", "CONTROLLERS", "Controller", "DynamicWindow", "GoToGoal", "PathFollower", "RrtPursuit", "LidarGeometry",
           "PidHeadingBlend", "PotentialField", "ReactiveAvoidance", "VelocityObstacle", "controller_parameters", "make_controller"]

CONTROLLERS: dict[str, type[Controller]] = {
    "go_to_goal": GoToGoal,
    "reactive": ReactiveAvoidance,
    "potential_field": PotentialField,
    "pid_blend": PidHeadingBlend,
    "astar_pursuit": AStarPursuit,
    "rrt_pursuit": RrtPursuit,
    "dwa": DynamicWindow,
    "orca": VelocityObstacle,
}


def controller_parameters(cls: type[Controller]) -> dict[str, tuple[Any, Any]]:
    """The constructor's keyword parameters of a controller class: name -> (type annotation, default)."""
    return keyword_parameters(cls)


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
        kwargs[key] = coerce(value, annotation, default, source, field)
    return cls(**kwargs)
