"""IR-SIM itself as a world (``--world irsim``): a scenario exported to IR-SIM's format
(:func:`common.irsim_export.scenario_to_irsim`), run headless by the installed IR-SIM (the
``irsim`` extra), read back as the same :class:`~common.readings.Readings` the tiers report.

The agent reads only what IR-SIM gives: its robot state (the pose, which stands in for odometry:
IR-SIM has no wheels to dead-reckon with), the velocity it moved at (the IMU's yaw rate is its w)
and its lidar's ranges, whose beams the export points where the scenario's point. A contact is
IR-SIM's collision flag; arrival is judged by the evaluator, as in every tier. Movers move as
IR-SIM moves them (they are not reported: no social figures here): through walls and shelves,
where the tiers' generated people slide along them (:func:`common.irsim_export.passing`). Conditions IR-SIM cannot
model (delays, wheel dynamics, odometry noise, the 3D knobs) are refused for this world
(:data:`common.conditions.NOT_IN_IRSIM`).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import yaml

from common.conditions import Conditions
from common.curriculum.stdout import stdout_to_stderr
from common.errors import ConfigError
from common.grid_maps import OWN_GENERATORS, GridMap, occupancy, write_occupancy_image
from common.irsim_export import passing, scenario_to_irsim
from common.irsim_package import import_irsim
from common.kinematics import Pose2D
from common.readings import Imu, Odometry, Readings, frozen
from common.scenario import Scenario


def _with_map_image(scenario: Scenario, folder: Path) -> Scenario:
    """The scenario with a grid map of this project's own generators (a maze) as an image IR-SIM
    reads to the same cells (IR-SIM knows only its own generators)."""
    grid = scenario.grid_map
    if grid is None or grid.image is not None or dict(grid.generator or {}).get("name") not in OWN_GENERATORS:
        return scenario
    world = scenario.world
    image = write_occupancy_image(occupancy(grid, world.width, world.height), folder / "map.png")
    return scenario.model_copy(update={"grid_map": GridMap(image=str(image))})


class IrsimWorld:
    """A scenario run in IR-SIM, with the tiers' ``reset`` and ``step``."""

    def __init__(self, scenario: Scenario, seed: int | None = None, conditions: Conditions | None = None) -> None:
        irsim = import_irsim()
        if irsim is None:
            raise ConfigError(None, "--world", "irsim needs IR-SIM: pip install 'nav-curriculum[irsim]'")
        self.conditions = (conditions or Conditions()).for_tier("irsim")
        self.scenario = self.conditions.scenario(scenario)
        self.period = self.scenario.world.step_time  # s: one step
        with tempfile.TemporaryDirectory() as folder, stdout_to_stderr():
            data = scenario_to_irsim(passing(_with_map_image(self.scenario, Path(folder))))
            path = Path(folder) / "world.yaml"
            path.write_text(yaml.safe_dump(data, sort_keys=False))
            try:
                self.env = irsim.make(str(path), display=False, log_level="ERROR", seed=seed)
            except (ValueError, KeyError, TypeError) as exc:  # what the export says that IR-SIM will not run
                message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                raise ConfigError(None, "--world", f"IR-SIM refused {scenario.name}: {message}") from None
        self.dt = self.scenario.world.step_time
        self.steps = 0

    def reset(self, seed: int | None = None) -> Readings:
        self.env.reset()
        self.steps = 0
        return self._readings()

    def step(self, v: float, w: float) -> Readings:
        self.env.step(np.array([[v], [w]], dtype=float))
        self.steps += 1
        return self._readings()

    def _readings(self) -> Readings:
        robot = self.env.robot
        x, y, yaw = (float(value) for value in robot.state[:3, 0])
        v, w = (float(value) for value in robot.velocity[:2, 0])
        pose = Pose2D(x, y, yaw)
        ranges = frozen(np.asarray(self.env.get_lidar_scan()["ranges"], dtype=np.float64).copy())
        return Readings(pose=pose, velocity=(v, w), odometry=Odometry(pose, v, w), lidar=ranges,
                        imu=Imu((0.0, 0.0, 0.0), (0.0, 0.0, w)), collided=bool(robot.collision_flag),
                        time=self.steps * self.dt)

    def close(self) -> None:
        self.env.end(0)
