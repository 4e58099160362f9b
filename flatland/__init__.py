"""The 2D tier: a fast pymunk world in the style of IR-SIM, and the ``flatland/Nav-v0`` env.

>>> import gymnasium as gym, flatland
>>> env = gym.make("flatland/Nav-v0", world="sparse", observation="nav7")
"""

from __future__ import annotations

from pathlib import Path

from gymnasium.envs.registration import register, registry

from common.nav_env import ENV_REGISTRATION
from common.world_file import WorldFile
from flatland.world import World

__all__ = ["World", "load_world"]


def load_world(path: str | Path, seed: int | None = 0) -> World:
    """A World from an IR-SIM world YAML or a project scenario YAML (``seed``: IR-SIM's random
    placement, wandering goals and noise, drawn as ``irsim.make(path, seed=seed)`` draws them)."""
    scenario, generator = WorldFile(path).scenario_and_generator(0 if seed is None else seed)
    return World(scenario, seed=seed, rng=generator)


if "flatland/Nav-v0" not in registry:
    register(id="flatland/Nav-v0", entry_point="flatland.env:NavEnv",
             **ENV_REGISTRATION)
