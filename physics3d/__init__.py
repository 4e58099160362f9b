"""The 3D tier: the URDF robot in a PyBullet warehouse, and the ``physics3d/WarehouseNav-v0`` env.

>>> import gymnasium as gym, physics3d
>>> env = gym.make("physics3d/WarehouseNav-v0", world="warehouse", observation="lidar43")
"""

from __future__ import annotations

import os
import sys

from gymnasium.envs.registration import register, registry

from common.nav_env import ENV_REGISTRATION


def _import_pybullet_quietly() -> None:
    """Import PyBullet with descriptor 2 closed to it: its C module prints its build time on
    stderr, a line in front of every 3D command's own (and of a one-line error)."""
    sys.stderr.flush()
    saved, devnull = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 2)
    try:
        import pybullet  # noqa: F401
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


_import_pybullet_quietly()

from physics3d.world import World  # noqa: E402  (after PyBullet's quiet import)

__all__ = ["World"]

if "physics3d/WarehouseNav-v0" not in registry:
    register(id="physics3d/WarehouseNav-v0", entry_point="physics3d.env:WarehouseNavEnv",
             **ENV_REGISTRATION)
