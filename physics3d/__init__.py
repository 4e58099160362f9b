"""The 3D tier: the URDF robot in a PyBullet warehouse, and the ``physics3d/WarehouseNav-v0`` env.

>>> import gymnasium as gym, physics3d
>>> env = gym.make("physics3d/WarehouseNav-v0", world="warehouse", observation="lidar43")
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from physics3d.world import World

__all__ = ["World"]

if "physics3d/WarehouseNav-v0" not in registry:
    register(id="physics3d/WarehouseNav-v0", entry_point="physics3d.env:WarehouseNavEnv")
