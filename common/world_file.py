"""Read a world file in either format: the project's scenario YAML or an IR-SIM world YAML."""

from __future__ import annotations

from pathlib import Path

from common.scenario import Scenario, read_yaml_mapping, scenario_from_mapping

_IRSIM_ONLY_KEYS = {"obstacle", "gui", "custom", "irsim"}
_IRSIM_ROBOT_KEYS = {"kinematics", "state", "sensors", "vel_max", "vel_min", "distribution", "number"}


def is_irsim(data: dict) -> bool:
    """Whether a parsed YAML mapping is an IR-SIM world rather than a project scenario."""
    if _IRSIM_ONLY_KEYS & data.keys():
        return True
    robot = data.get("robot")
    if isinstance(robot, list):
        return True
    return isinstance(robot, dict) and (bool(_IRSIM_ROBOT_KEYS & robot.keys()) or isinstance(robot.get("shape"), dict))


def read_world_file(path: str | Path, seed: int | None = 0) -> Scenario:
    """The scenario in a YAML file; ``seed`` drives IR-SIM's random placements, if the file has any."""
    data = read_yaml_mapping(path)
    if is_irsim(data):
        from common.irsim_format import parse_irsim

        return parse_irsim(data, source=path, seed=seed)
    return scenario_from_mapping(data, path)


def world_file_is_random(path: str | Path) -> bool:
    """Whether reading the file with different seeds can give different scenarios."""
    data = read_yaml_mapping(path)
    if not is_irsim(data):
        return False
    from common.irsim_format import has_random_placement

    return has_random_placement(data)


__all__ = ["is_irsim", "read_world_file", "world_file_is_random"]
