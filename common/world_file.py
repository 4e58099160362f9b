"""Read a world file in either format: the project's scenario YAML or an IR-SIM world YAML."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from common.errors import ConfigError, ScenarioWarning
from common.scenario import Scenario, scenario_from_mapping
from common.yaml_io import read_yaml_mapping

_IRSIM_ONLY_KEYS = {"obstacle", "gui", "custom", "irsim"}
# A project scenario's top-level keys that an IR-SIM world file does not have (IR-SIM's share
# world and robot; a name is harmless in either).
_SCENARIO_ONLY_KEYS = set(Scenario.model_fields) - {"world", "robot", "name"}
_IRSIM_ROBOT_KEYS = {"state", "sensors", "vel_max", "vel_min", "distribution", "number"}
# Keys of IR-SIM's world section that a project scenario's world lacks (IR-SIM's empty world has no robot).
_IRSIM_WORLD_KEYS = {"name", "sample_time", "step_mode", "control_mode", "obstacle_map", "mdownsample", "fog_map",
                     "fog_map_resolution", "gravity", "friction", "restitution", "drive_tau", "plot", "status"}


def irsim_mark(data: dict) -> str | None:
    """The field that marks a parsed YAML mapping as an IR-SIM world rather than a project
    scenario (``obstacle``, ``world.gravity``, ``robot.state``, ...), or None."""
    if found := sorted(_IRSIM_ONLY_KEYS & data.keys()):
        return found[0]
    world = data.get("world")
    if isinstance(world, dict) and (found := sorted(_IRSIM_WORLD_KEYS & world.keys())):
        return f"world.{found[0]}"
    robot = data.get("robot")
    if isinstance(robot, list):
        return "robot"  # a list of robots
    if not isinstance(robot, dict):
        return None
    # A scenario's robot names its kinematics and shape; an IR-SIM robot maps them.
    if found := sorted(_IRSIM_ROBOT_KEYS & robot.keys()):
        return f"robot.{found[0]}"
    return next((f"robot.{key}" for key in ("shape", "kinematics") if isinstance(robot.get(key), dict)), None)


def is_irsim(data: dict) -> bool:
    """Whether a parsed YAML mapping is an IR-SIM world rather than a project scenario."""
    return irsim_mark(data) is not None


class WorldFile:
    """A world file, read and parsed once, as a scenario per seed.

    A project scenario is the same for every seed. An IR-SIM world that places or shapes objects
    at random (``distribution: random``, ``random_shape``) gives a new layout per seed, drawn as
    ``irsim.make(path, seed=seed)`` would; seed 0 is its *initial state*.

    A project scenario whose start or goal is outside the world or inside an obstacle is a
    :class:`ConfigError`; an IR-SIM world gets a :class:`ScenarioWarning` instead (once, for the
    initial state), since IR-SIM runs it: the robot collides at once, or never arrives.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.data = read_yaml_mapping(self.path)
        if "stages" in self.data:  # a curriculum's mark (common.curriculum.schema.is_curriculum)
            raise ConfigError(self.path, None, "is a curriculum (it has stages), not a scenario or an IR-SIM world file; "
                              "run it with: curriculum run FILE")
        mark = irsim_mark(self.data)
        self.irsim = mark is not None
        if self.irsim and (ours := sorted(_SCENARIO_ONLY_KEYS & self.data.keys())):
            # Told apart by one key, a file mixing the formats was read as the wrong one: an IR-SIM
            # key under world: made a scenario's start an unknown key, with no word of the cause.
            raise ConfigError(self.path, ours[0], f"a project scenario's key, in a file that {mark} marks as an "
                              "IR-SIM world; allowed: one format per file (docs/scenarios.md)")
        if self.irsim:
            from common.irsim_format import ReadCache, has_random_placement

            self.random = has_random_placement(self.data)
            self._reads = ReadCache()  # a new seed re-reads only what it draws
        else:
            self.random = False
        self.initial = self._parse(0, warn=True)[0]

    def scenario(self, seed: int = 0) -> Scenario:
        """The file's scenario for ``seed`` (the initial state for seed 0, and for every seed if the file has no randomness)."""
        return self._parse(seed, warn=False)[0] if self.random and seed != 0 else self.initial

    def scenario_and_generator(self, seed: int = 0) -> tuple[Scenario, np.random.Generator]:
        """The file's scenario for ``seed`` and the generator to go on drawing from: an IR-SIM
        file's where its parse left it (IR-SIM's next draws, e.g. a wanderer's next goal), else
        one seeded with ``seed``."""
        return self._parse(seed, warn=False)

    def _parse(self, seed: int, warn: bool) -> tuple[Scenario, np.random.Generator]:
        if not self.irsim:
            return scenario_from_mapping(self.data, self.path), np.random.default_rng(seed)
        from common.irsim_format import parse_irsim_drawing

        scenario, generator = parse_irsim_drawing(self.data, source=self.path, seed=seed, reads=self._reads)
        for problem in scenario.placement_problems(self.path) if warn else ():
            warnings.warn(f"{problem} (IR-SIM runs it as it is)", ScenarioWarning, stacklevel=3)
        return scenario, generator


def read_world_file(path: str | Path, seed: int = 0) -> Scenario:
    """The scenario in a world file (project or IR-SIM YAML) for ``seed``; see :class:`WorldFile`."""
    return WorldFile(path).scenario(seed)


__all__ = ["WorldFile", "is_irsim", "read_world_file"]
