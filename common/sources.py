"""Where an env's scenarios come from: one fixed scenario, a generator kind, or a world file.

An env calls ``source.draw(rng)`` at every reset with its own seeded generator, so a seed fixes
the whole sequence of episodes whatever the source. ``draw(rng, resample=True)`` asks a world file
with random placements for a new layout (IR-SIM's ``reset(random=True)``); without it a file's
initial state is restored, as IR-SIM's ``reset()`` does. Generator kinds draw anew every episode.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping, Protocol, Sequence, Union

import numpy as np

from common.errors import ConfigError, quote
from common.generators import KINDS, generate
from common.params import is_real
from common.robots import RobotFamily
from common.scenario import Scenario
from common.world_file import WorldFile


class ScenarioSource(Protocol):
    """Anything that yields a scenario per episode; ``examples`` are the worlds it made or read as
    it was built (one of each kind it draws), for checks before the first episode."""

    examples: list[Scenario]

    def draw(self, rng: np.random.Generator, resample: bool = False) -> Scenario: ...


def _inside_its_world(scenario: Scenario, field: str) -> Scenario:
    """A scenario written in Python (kind ``custom``) whose start and goal lie in its world: a goal
    outside a walled world trained until every episode's truncation without a word. (Only these:
    a generator's are inside by construction, and IR-SIM runs its files whatever their goals.)"""
    if scenario.kind == "custom" and (problems := scenario.outside_problems()):
        raise ConfigError(None, f"{field}.{problems[0].field}", f"scenario {quote(scenario.name)}: {problems[0].problem}")
    return scenario


class FixedSource:
    """Always the same scenario."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = _inside_its_world(scenario, "world")
        self.examples = [scenario]

    def draw(self, rng: np.random.Generator, resample: bool = False) -> Scenario:
        return self.scenario


class ListSource:
    """A scenario picked at random from a list each episode."""

    def __init__(self, scenarios: Sequence[Scenario]) -> None:
        if not scenarios:
            raise ConfigError(None, "world", "an empty list of scenarios")
        for index, scenario in enumerate(scenarios):
            if not isinstance(scenario, Scenario):
                raise ConfigError(None, f"world.{index}", f"got {quote(scenario)}; allowed: a list of Scenario objects "
                                  "(several kinds: a mix such as {'sparse': 1, 'cluttered': 1})")
            _inside_its_world(scenario, f"world.{index}")
        self.scenarios = self.examples = list(scenarios)

    def draw(self, rng: np.random.Generator, resample: bool = False) -> Scenario:
        return self.scenarios[int(rng.integers(len(self.scenarios)))]


class GeneratorSource:
    """A fresh training-split scenario of a kind each episode (seed drawn from the env's generator);
    with a ``family``, first a robot drawn from it, the scenario generated for that robot."""

    def __init__(self, kind: str, difficulty: float = 0.5, template: Scenario | None = None,
                 family: RobotFamily | None = None) -> None:
        self.kind, self.difficulty, self.template, self.family = kind, difficulty, template or Scenario(), family
        # Fail now, not at the first reset (with a family, for one robot of it).
        robot = family.draw(np.random.default_rng(0), self.template.robot) if family else self.template.robot
        self.examples = [generate(kind, 0, difficulty, "train", self.template.model_copy(update={"robot": robot}))]

    def draw(self, rng: np.random.Generator, resample: bool = False) -> Scenario:
        template = self.template
        if self.family is not None:
            template = template.model_copy(update={"robot": self.family.draw(rng, template.robot)})
        return generate(self.kind, int(rng.integers(2**31 - 1)), self.difficulty, "train", template)


class MixSource:
    """Each episode a kind drawn by weight, then a fresh training-split scenario of that kind."""

    def __init__(self, weights: Mapping[str, float], difficulty: float = 0.5, template: Scenario | None = None,
                 family: RobotFamily | None = None) -> None:
        if not weights or not all(is_real(w) and 0.0 < w < math.inf for w in weights.values()):  # NaN fails too
            raise ConfigError(None, "world", f"got {quote(dict(weights))}; a mix needs at least one kind, each with a "
                              "finite weight above 0")
        self.sources = [_kind_source(kind, difficulty, template, family) for kind in weights]
        self.examples = [example for source in self.sources for example in source.examples]
        total = float(sum(weights.values()))
        self.probabilities = [w / total for w in weights.values()]

    def draw(self, rng: np.random.Generator, resample: bool = False) -> Scenario:
        return self.sources[int(rng.choice(len(self.sources), p=self.probabilities))].draw(rng)


class FileSource:
    """A world file, parsed once: its initial state every episode, or with ``resample`` (always, or
    for one ``draw``) a new random layout drawn from the env's generator."""

    def __init__(self, path: str | Path, resample: bool = False) -> None:
        self.file = WorldFile(path)
        self.resample = resample
        self.examples = [self.file.initial]

    def draw(self, rng: np.random.Generator, resample: bool = False) -> Scenario:
        if self.file.random and (resample or self.resample):
            return self.file.scenario(int(rng.integers(1, 2**31 - 1)))
        return self.file.initial


WorldArgument = Union[Scenario, str, Path, Sequence[Scenario], Mapping[str, float], ScenarioSource]
"""What an env takes as its ``world`` (:func:`scenario_source` says how each is read)."""


def check_difficulty(difficulty: float) -> None:
    """A generator's difficulty is a number from 0 to 1 (NaN fails too)."""
    if not (is_real(difficulty) and 0.0 <= difficulty <= 1.0):
        raise ConfigError(None, "difficulty", f"got {quote(difficulty)}; allowed: a number from 0 to 1")


def _kind_source(kind: str, difficulty: float, template: Scenario | None,
                 family: RobotFamily | None = None) -> GeneratorSource:
    if kind not in KINDS:
        raise ConfigError(None, "world", f"unknown scenario kind {quote(kind)}; allowed: {', '.join(KINDS)}")
    check_difficulty(difficulty)  # here, as the warehouse's is replaced below
    # The warehouse is defined by its 31 obstacles: it is always drawn at full difficulty.
    return GeneratorSource(kind, 1.0 if kind == "warehouse" else difficulty, template, family)


def scenario_source(world: WorldArgument, difficulty: float = 0.5, template: Scenario | None = None,
                    resample: bool = False, family: RobotFamily | None = None) -> ScenarioSource:
    """Interpret an env's ``world`` argument: a Scenario, a list of them, a generator kind or suite
    name (``open``, ``sparse``, ``cluttered``, ``warehouse``, ``trap``), a mapping of kinds to
    weights (a mix), or a YAML path (``resample``: a random file's layout is redrawn every episode).
    A robot ``family`` needs a kind or a mix: only a generator lays a world out for each robot."""
    if family is not None:
        if isinstance(world, Mapping):
            return MixSource(world, difficulty, template, family)
        if isinstance(world, str) and world in KINDS:
            return _kind_source(world, difficulty, template, family)
        raise ConfigError(None, "robot_family", "robots drawn per episode need worlds generated for them; "
                          "allowed: world as a generator kind or a mix of kinds")
    if isinstance(world, Scenario):
        return FixedSource(world)
    if isinstance(world, Mapping):
        return MixSource(world, difficulty, template)
    if isinstance(world, (str, Path)):
        if str(world) in KINDS:
            return _kind_source(str(world), difficulty, template)
        if Path(world).suffix in (".yaml", ".yml") or Path(world).exists():
            return FileSource(world, resample)
        raise ConfigError(None, "world", f"{quote(str(world))} is neither a scenario kind ({', '.join(KINDS)}) nor a YAML file")
    if isinstance(world, Sequence):
        return ListSource(world)
    if hasattr(world, "draw"):
        return world
    raise ConfigError(None, "world", f"expected a Scenario, a kind name or a YAML path, got {type(world).__name__}")
