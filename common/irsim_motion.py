"""An IR-SIM object's behaviour, read as a project :class:`Motion` with IR-SIM's numbers.

IR-SIM moves an object that has kinematics and a ``behavior`` (``dash``, ``rvo``, ``sfm``) or
belongs to a group with a ``group_behavior`` (``orca``, ``sfm``); the group's plan wins over the
object's own. A ``wander`` behaviour draws its first goal from the file's generator as the object
is made (after its shape's draws), as IR-SIM does, so every later draw stays IR-SIM's. Keys IR-SIM
passes to a behaviour and ignores are ignored here too; anything flatland cannot move as IR-SIM
does (another kinematics, a shape off its centre, a custom behaviour) is a one-line refusal.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from common.irsim_values import Entry, Value, boolean, build_model, fail, join, mapping_of, number_list, real, \
    refuse_misread_values, string, value_of
from common.motion.spec import Dash, Motion, Orca, Rvo, Sfm

BEHAVIORS = ("dash", "rvo", "sfm")  # an object's own
GROUP_BEHAVIORS = ("orca", "sfm")  # a group's
MOVING_KINEMATICS = ("diff", "omni")
_ROUTE_KEYS = ("wander", "loop", "range_low", "range_high", "target_roles", "name")
_ORCA_KEYS = {"neighborDist": "neighbor_dist", "maxNeighbors": "max_neighbors", "timeHorizon": "time_horizon",
              "timeHorizonObst": "time_horizon_obst", "safe_radius": "safe_radius", "maxSpeed": "max_speed"}
_DEFAULT_WANDER = ([0.0, 0.0, -math.pi], [10.0, 10.0, math.pi])  # IR-SIM's range_low and range_high


def _config(entry: Entry, key: str, path: str) -> tuple[dict, str]:
    item = value_of(entry, key, {}, path)
    return mapping_of(item.value, item.path), item.path


def moves(entry: Entry, path: str) -> bool:
    """Whether IR-SIM moves this object: a driving kinematics, not static, and a behaviour."""
    kinematics = entry.get("kinematics")
    if kinematics is None or not isinstance(kinematics.value, dict) or kinematics.value.get("name") is None:
        return False  # passive: IR-SIM keeps it where it is
    if entry.get("static") is not None and boolean(entry["static"].value, entry["static"].path):
        return False
    return bool(_config(entry, "behavior", path)[0] or _config(entry, "group_behavior", path)[0])


def read_motion(entry: Entry, path: str, rng: np.random.Generator, group: str, role: str) -> Motion:
    """The motion of a moving object (``moves`` said so), drawing a wanderer's first goal from
    ``rng``; ``group`` names its YAML group, ``role`` is ``robot`` or ``obstacle``."""
    own, own_path = _config(entry, "behavior", path)
    shared, shared_path = _config(entry, "group_behavior", path)
    kinematics_item = entry["kinematics"]
    kinematics = string(kinematics_item.value.get("name"), join(kinematics_item.path, "name")).lower()
    if kinematics not in MOVING_KINEMATICS:
        raise fail(join(kinematics_item.path, "name"), f"a moving {quote_name(kinematics)} object is not supported; "
                   f"allowed: {', '.join(MOVING_KINEMATICS)}")
    if value_of(entry, "arrive_mode", "position", path).value != "position":
        raise fail(join(path, "arrive_mode"), "only position arrival is modelled for movers; allowed: position")
    config, config_path = (shared, shared_path) if shared else (own, own_path)
    names, kind = (GROUP_BEHAVIORS, "group behaviour") if shared else (BEHAVIORS, "behaviour")
    name = string(config.get("name"), join(config_path, "name"))
    if name not in names:
        raise fail(join(config_path, "name"), f"the {kind} {quote_name(name)} is not supported; allowed: {', '.join(names)}")
    route_config, route_path = (own, own_path) if own else (shared, shared_path)  # IR-SIM's beh_config
    fields: dict[str, Value] = {
        "behavior": Value(_behavior(name, config, config_path), config_path),
        "kinematics": Value(kinematics, kinematics_item.path),
        "role": Value(role, path),
        "label": Value(role, path),
        "group": Value(group if shared else None, path),
        "target_roles": Value(string(route_config.get("target_roles", "all"), join(route_path, "target_roles"),
                                     ("all", "robot", "obstacle")), join(route_path, "target_roles")),
    }
    if name == "orca":
        # IR-SIM's ORCA group (RVO2) plans among its members only: a controlled robot that is not
        # one is not avoided (flatland's default has people see the robot).
        fields["reacts_to_robot"] = Value(False, config_path)
    for key in ("vel_min", "vel_max", "acce", "velocity"):
        item = entry.get(key)
        if item is not None and item.value is not None:
            fields[key] = Value(tuple(number_list(item.value, item.path, size=2, allow_inf=key == "acce")), item.path)
    threshold = value_of(entry, "goal_threshold", 0.1, path)
    fields["goal_threshold"] = Value(real(threshold.value, threshold.path, 0, strict=True), threshold.path)
    if route_config.get("wander") is not None and boolean(route_config["wander"], join(route_path, "wander")):
        low, high = _wander_range(route_config, route_path)
        drawn = rng.uniform(np.c_[low], np.c_[high])  # IR-SIM's draw, as the object is made
        fields["goals"] = Value([(float(drawn[0, 0]), float(drawn[1, 0]))], join(route_path, "wander"))
        fields["wander"] = Value((low[0], low[1], high[0], high[1]), join(route_path, "range_low"))
    else:
        fields["goals"] = Value(_goals(entry), join(path, "goal"))
        loop = route_config.get("loop")
        if loop is not None and boolean(loop, join(route_path, "loop")):
            fields["route"] = Value("loop", join(route_path, "loop"))
    return build_model(Motion, path, fields)


def quote_name(name: Any) -> str:
    return repr(name) if isinstance(name, str) else str(name)


def _behavior(name: str, config: dict, path: str) -> Any:
    """The behaviour's model from IR-SIM's keys (keys IR-SIM ignores are ignored)."""
    if name == "orca":
        values = {ours: config[theirs] for theirs, ours in _ORCA_KEYS.items() if config.get(theirs) is not None}
        model, fields = Orca, {k: Value(v, join(path, _theirs(k))) for k, v in values.items()}
    else:
        model = {"dash": Dash, "rvo": Rvo, "sfm": Sfm}[name]
        keys = [key for key in model.model_fields if key != "name" and key in config and key not in _ROUTE_KEYS]
        fields = {key: Value(config[key], join(path, key)) for key in keys}
    refuse_misread_values(model, fields)  # handed over as written: true or "0.7" for a number is refused
    return build_model(model, path, fields)


def _theirs(ours: str) -> str:
    return next(theirs for theirs, mine in _ORCA_KEYS.items() if mine == ours)


def _wander_range(config: dict, path: str) -> tuple[list[float], list[float]]:
    low = number_list(config.get("range_low", _DEFAULT_WANDER[0]), join(path, "range_low"), size=3)
    high = number_list(config.get("range_high", _DEFAULT_WANDER[1]), join(path, "range_high"), size=3)
    for axis in (0, 1):
        if low[axis] > high[axis]:
            raise fail(join(path, "range_high"), f"component {axis}: {high[axis]:g} is below range_low's "
                       f"{low[axis]:g}; allowed: range_low <= range_high")
    return low, high


def _goals(entry: Entry) -> list[tuple[float, float]]:
    """The object's goals in order (IR-SIM's goal, or list of goals)."""
    goal = entry["goal"]
    value = goal.value
    if isinstance(value, list) and value and isinstance(value[0], (list, tuple)):
        return [tuple(number_list(g, f"{goal.path}[{i}]", min_size=2)[:2]) for i, g in enumerate(value)]
    return [tuple(number_list(value, goal.path, min_size=2)[:2])]


def needs_tracking(entry: Entry, path: str) -> bool:
    """Whether the controlled robot's own IR-SIM behaviour matters although commands drive it: it
    wanders (IR-SIM draws its goals) or it belongs to a group that plans together."""
    own, own_path = _config(entry, "behavior", path)
    shared, _ = _config(entry, "group_behavior", path)
    route = own or shared
    wanders = route.get("wander") is not None and boolean(route["wander"], join(own_path, "wander"))
    return bool(shared) or wanders
