"""The tiers a scenario can be run in, by name, imported only when used."""

from __future__ import annotations

import functools
import importlib
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Protocol

from common.conditions import Conditions
from common.errors import ConfigError, quote
from common.readings import Readings
from common.scenario import Scenario

if TYPE_CHECKING:  # common.sources imports the generators, which most users of this module never need
    from common.sources import ScenarioSource, WorldArgument


class WorldLike(Protocol):
    """What the env and the evaluator need of a tier's world."""

    scenario: Scenario
    period: float  # simulated seconds a step covers

    def reset(self, seed: int | None = None) -> Readings: ...

    def step(self, v: float, w: float) -> Readings: ...


_WORLDS = {"flatland": "flatland.world:World", "physics3d": "physics3d.world:World",
           "irsim": "common.curriculum.irsim_world:IrsimWorld"}
# What each tier's generator kinds draw scenarios around (flatland: the defaults of Scenario).
_TEMPLATES = {"flatland": "common.scenario:Scenario", "physics3d": "physics3d.robot:TEMPLATE",
              "irsim": "common.scenario:Scenario"}
# What a tier refuses to build, checked without building it (flatland builds every valid scenario).
_REFUSALS = {"physics3d": "physics3d.world:refuse_unmodelled"}
_LIMITS = {"physics3d": "physics3d.world:refuse_untrackable"}  # of the robot as conditioned
TIERS = ("flatland", "physics3d")  # the tiers this project trains in
# Where agents are evaluated: the tiers, and IR-SIM itself (an optional extra), run with the same
# scenarios and metrics to tell navigation learnt from flatland learnt.
WORLDS = (*TIERS, "irsim")


def _load(tier: str, table: dict[str, str]) -> Any:
    """The object a tier's entry in ``table`` names ("module:attribute"), imported now."""
    if tier not in table:
        raise ConfigError(None, "world", f"unknown tier {quote(tier)}; allowed: {', '.join(WORLDS)}")
    module_name, name = table[tier].split(":")
    try:
        return getattr(importlib.import_module(module_name), name)
    except (ImportError, AttributeError):
        raise ConfigError(None, "world", f"the {tier} tier is not available in this version") from None


def make_world(tier: str, scenario: Scenario, seed: int | None = None, conditions: Conditions | None = None) -> WorldLike:
    """A world of the named tier built from ``scenario`` under ``conditions`` (the tier's defaults
    where unset; :mod:`common.conditions`). ``world.scenario`` is the scenario as conditioned."""
    return _load(tier, _WORLDS)(scenario, seed=seed, conditions=conditions)


def generator_template(tier: str) -> Scenario:
    """The robot, lidar and world a tier's generator kinds draw scenarios around."""
    template = _load(tier, _TEMPLATES)
    return template() if isinstance(template, type) else template


def tier_source(tier: str, world: WorldArgument, difficulty: float, conditions: Conditions,
                template: Scenario | None = None, resample: bool = False) -> ScenarioSource:
    """The :class:`~common.sources.ScenarioSource` an env of ``tier`` draws ``world`` from under
    ``conditions`` (:func:`~common.sources.scenario_source` takes the same ``world``); generated
    scenarios are drawn around the robot the conditions put in, so their gaps fit it."""
    from common.sources import scenario_source

    _refuse_unbuilt_kinds(tier, [world] if isinstance(world, str) else list(world) if isinstance(world, Mapping) else [],
                          difficulty)
    if template is not None and not isinstance(template, Scenario):
        raise ConfigError(None, "template", f"got {quote(template)}; allowed: a Scenario (the robot, lidar and world "
                          "size the generator kinds draw around) or None")
    template = template or generator_template(tier)
    if conditions.profile is not None:
        template = template.model_copy(update={"robot": conditions.profile})
    return scenario_source(world, difficulty, template, resample, conditions.robot_family)


def _refuse_unbuilt_kinds(tier: str, kinds: list[str], difficulty: float) -> None:
    """A one-line error for a generator kind among ``kinds`` that ``tier`` cannot build (the maze's
    grid map in 3D): a mix drew such a kind only after some resets, mid-training."""
    if tier not in _REFUSALS:
        return
    from common.generators import KINDS
    from common.sources import check_difficulty

    if any(kind in KINDS for kind in kinds):
        check_difficulty(difficulty)  # before a kind is drawn at it: its error is not the tier's
    for kind in kinds:
        if kind in KINDS and (error := _kind_refusal(tier, kind, difficulty)) is not None:
            built = [other for other in KINDS if _kind_refusal(tier, other, difficulty) is None]
            raise ConfigError(None, "world", f"the {tier} tier does not build the {quote(kind)} kind "
                              f"({error.field}: {error.problem.split(';')[0]}); allowed: {', '.join(built)}")


@functools.cache
def _kind_refusal(tier: str, kind: str, difficulty: float) -> ConfigError | None:
    """The tier's own refusal (:func:`refuse_as_written`) of a scenario of ``kind`` drawn around its
    plain template, or None. The plain template, not a stage's robot: what the tier refuses of that
    robot is named by its own field. Cached: every env of a vector env asks it again."""
    from common.generators import generate

    try:
        refuse_as_written(tier, generate(kind, 0, difficulty, "train", generator_template(tier)))
    except ConfigError as error:
        return error
    return None


def refuse_as_written(tier: str, scenario: Scenario) -> None:
    """A one-line error for what a training tier cannot build of ``scenario`` as written (its
    robot and geometry, before any condition replaces them), found without building the world."""
    if tier in _REFUSALS:
        _load(tier, _REFUSALS)(scenario)


def refuse_unbuildable(world: str, scenario: Scenario, conditioned: Scenario) -> None:
    """The one-line error the named world (a tier, or ``irsim``) would raise when built from
    ``scenario`` (as written) made ``conditioned``, found without building it. IR-SIM says what it
    refuses only when it loads the file."""
    if world in TIERS:
        refuse_as_written(world, scenario)
        _refuse_as_conditioned(world, conditioned)


def _refuse_as_conditioned(tier: str, conditioned: Scenario) -> None:
    """A one-line error for what a training tier cannot drive of a scenario under its conditions:
    robot limits its body cannot follow (the URDF robot's in 3D), movers it cannot model."""
    from common.motion.movers import refuse_unmodelled

    if tier in _LIMITS:
        _load(tier, _LIMITS)(conditioned.robot)
    refuse_unmodelled(conditioned)


def as_built(tier: str, scenario: Scenario, conditions: Conditions) -> Scenario:
    """``scenario`` (which :func:`refuse_as_written` let through) as a training tier's world drives
    it under ``conditions``; or a one-line error for what it cannot drive under them
    (:func:`_refuse_as_conditioned`)."""
    conditioned = conditions.for_tier(tier).scenario(scenario)
    _refuse_as_conditioned(tier, conditioned)
    return conditioned
