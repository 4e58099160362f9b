"""IR-SIM's own example worlds (``../shared/irsim_usage``): every file IR-SIM runs, flatland either
reproduces or refuses with one line; none may load and then diverge.

For each file, robot 0 gets a 360° lidar (so movers show in its scans) and both simulators drive
it with the same seeded commands (one per channel of its kinematics) for 300 steps (IR-SIM's ``control_mode: keyboard`` read as
``auto``: here the program drives robot 0 and every other robot its behaviour). Reproduced means
every step alike: robot 0's pose within 1 mm, at least 95 % of the beams within 2 cm (IR-SIM's
circles are 64-gons), the collision flag, and every mover within 1 mm (1e-6 m where all move by
``dash``). "IR-SIM runs it" is the usage README's test: ``irsim.make`` and 20 steps without an
action. The count is printed at the end of the test log.

The worlds sit outside this repository, beside it (``../shared/irsim_usage`` from the project root)
or where ``NAV_IRSIM_USAGE`` says; a clone without them skips the walk and says so.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from tests.conftest import TABLES_ENV, optional

os.environ.setdefault("MPLBACKEND", "Agg")
USAGE = Path(os.environ.get("NAV_IRSIM_USAGE") or Path(__file__).resolve().parents[2] / "shared" / "irsim_usage")
FILES = sorted(USAGE.glob("*/*.yaml"))
STEPS = 300


def _irsim_runs(irsim, path: Path) -> bool:
    try:
        env = irsim.make(str(path), display=False, log_level="ERROR")
        for _ in range(20):
            env.step()
        env.end(0)
        return True
    except Exception:  # noqa: BLE001  (whatever stops IR-SIM, it does not run the file)
        return False


def _driven_copy(path: Path, out: Path) -> Path:
    """The file with robot 0 given a 360° lidar and the program (not a keyboard) driving."""
    data = yaml.safe_load(path.read_text())
    world = data.get("world") or {}
    world["control_mode"] = "auto"
    data["world"] = world
    robots = data.get("robot")
    if robots:
        first = robots[0] if isinstance(robots, list) else robots
        first["sensors"] = [{"name": "lidar2d", "range_max": 6, "angle_range": 2 * math.pi, "number": 90}]
    out.write_text(yaml.safe_dump(data))
    return out


def _record(name: str, result: str) -> None:
    folder = os.environ.get(TABLES_ENV)
    if folder:
        (Path(folder) / "irsim_usage").mkdir(exist_ok=True)
        (Path(folder) / "irsim_usage" / f"{name.replace('/', '__')}.txt").write_text(result)


@pytest.mark.skipif(bool(FILES), reason="the usage worlds are here")
def test_usage_worlds_are_found():
    pytest.skip(f"IR-SIM's usage worlds are not at {USAGE} (set NAV_IRSIM_USAGE): none walked")


@pytest.mark.slow
@pytest.mark.parametrize("path", FILES, ids=[f"{p.parent.name}/{p.name}" for p in FILES])
def test_every_usage_world_irsim_runs_is_reproduced_or_refused(path, tmp_path):
    irsim = optional("irsim")
    import flatland
    from common.errors import ConfigError

    name = f"{path.parent.name}/{path.name}"
    if not _irsim_runs(irsim, path):
        _record(name, "not run by IR-SIM")
        pytest.skip("IR-SIM itself does not run this file")
    copy = _driven_copy(path, tmp_path / path.name)
    try:
        world = flatland.load_world(copy, seed=0)
    except ConfigError as error:
        text = str(error)
        assert "\n" not in text and text.startswith(f"{copy}: "), text
        _record(name, f"refused: {text.removeprefix(str(copy) + ': ')}")
        return
    env = irsim.make(str(copy), display=False, log_level="ERROR", seed=0)
    moving = [] if world.movers is None else [i + 1 for i in world.movers.table.obstacle_index if i >= 0]
    dash_only = world.movers is None or all(o.motion.behavior.name == "dash" for o in world.scenario.movers)
    tolerance = 1e-6 if dash_only else 1e-3
    rng = np.random.default_rng(1)
    commands = np.column_stack([rng.uniform(-0.2, 1.0, STEPS), rng.uniform(-1.0, 1.0, STEPS)])
    if world.drive is not None and len(world.drive.channels) == 3:  # omni_angular: forward, lateral, w
        commands = np.column_stack([commands, rng.uniform(-1.0, 1.0, STEPS)])
    try:
        world.reset()
        for k, command in enumerate(commands):
            ours = world.step(*command)
            env.step(command.reshape(-1, 1))
            pose = np.asarray(env.get_robot_state()[:3, 0], dtype=float)
            np.testing.assert_allclose(ours.pose[:2], pose[:2], rtol=0, atol=1e-3, err_msg=f"robot 0, step {k}")
            close = np.abs(ours.lidar - env.get_lidar_scan()["ranges"]) <= 0.02
            assert close.mean() >= 0.95, f"step {k}: only {close.mean():.0%} of beams within 2 cm"
            assert ours.collided == bool(env.robot.collision_flag), f"collision flag, step {k}"
            if moving:
                theirs = np.array([env.objects[j].state[:2, 0] for j in moving])
                np.testing.assert_allclose(ours.movers.rows[:, :2], theirs, rtol=0, atol=tolerance,
                                           err_msg=f"movers, step {k}")
    finally:
        env.end(0)
    _record(name, f"reproduced ({len(moving)} movers)")
