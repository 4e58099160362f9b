"""The tiers a scenario can be run in, by name, imported only when used."""

from __future__ import annotations

import importlib

from common.conditions import Conditions
from common.errors import ConfigError, quote
from common.nav_env import WorldLike
from common.scenario import Scenario

_WORLDS = {"flatland": "flatland.world:World", "physics3d": "physics3d.world:World"}
TIERS = tuple(_WORLDS)


def make_world(tier: str, scenario: Scenario, seed: int | None = None, conditions: Conditions | None = None) -> WorldLike:
    """A world of the named tier built from ``scenario`` under ``conditions`` (the tier's defaults
    where unset; :mod:`common.conditions`). ``world.scenario`` is the scenario as conditioned."""
    if tier not in _WORLDS:
        raise ConfigError(None, "world", f"unknown tier {quote(tier)}; allowed: {', '.join(TIERS)}")
    module_name, class_name = _WORLDS[tier].split(":")
    try:
        world_class = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError):
        raise ConfigError(None, "world", f"the {tier} tier is not available in this version") from None
    resolved = (conditions or Conditions()).for_tier(tier)
    return world_class(resolved.scenario(scenario), seed=seed, **resolved.world_kwargs(tier))
