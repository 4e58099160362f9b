"""Where an env's scenarios come from: one fixed scenario, a generator kind, or a world file.

An env calls ``source.draw(rng)`` at every reset with its own seeded generator, so a seed fixes
the whole sequence of episodes whatever the source.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping, Protocol, Sequence

import numpy as np

from common.errors import ConfigError
from common.generators import KINDS, generate
from common.scenario import Scenario
from common.world_file import read_world_file, world_file_is_random


class ScenarioSource(Protocol):
    """Anything that yields a scenario per episode."""

    def draw(self, rng: np.random.Generator) -> Scenario: ...


class FixedSource:
    """Always the same scenario."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario

    def draw(self, rng: np.random.Generator) -> Scenario:
        return self.scenario


class ListSource:
    """A scenario picked at random from a list each episode."""

    def __init__(self, scenarios: Sequence[Scenario]) -> None:
        if not scenarios:
            raise ConfigError(None, "world", "an empty list of scenarios")
        self.scenarios = list(scenarios)

    def draw(self, rng: np.random.Generator) -> Scenario:
        return self.scenarios[int(rng.integers(len(self.scenarios)))]


class GeneratorSource:
    """A fresh training-split scenario of a kind each episode (seed drawn from the env's generator)."""

    def __init__(self, kind: str, difficulty: float = 0.5, template: Scenario | None = None) -> None:
        self.kind, self.difficulty, self.template = kind, difficulty, template
        generate(kind, 0, difficulty, "train", template)  # fail now, not at the first reset

    def draw(self, rng: np.random.Generator) -> Scenario:
        return generate(self.kind, int(rng.integers(2**31 - 1)), self.difficulty, "train", self.template)


class MixSource:
    """Each episode a kind drawn by weight, then a fresh training-split scenario of that kind."""

    def __init__(self, weights: Mapping[str, float], difficulty: float = 0.5, template: Scenario | None = None) -> None:
        if not weights or any(w <= 0 for w in weights.values()):
            raise ConfigError(None, "world", "a mix needs at least one kind, each with a positive weight")
        self.sources = [_kind_source(kind, difficulty, template) for kind in weights]
        total = float(sum(weights.values()))
        self.probabilities = [w / total for w in weights.values()]

    def draw(self, rng: np.random.Generator) -> Scenario:
        return self.sources[int(rng.choice(len(self.sources), p=self.probabilities))].draw(rng)


class FileSource:
    """A world file; redrawn each episode only if it places objects at random (IR-SIM ``distribution``)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.random = world_file_is_random(self.path)
        self.scenario = read_world_file(self.path, seed=0)

    def draw(self, rng: np.random.Generator) -> Scenario:
        return read_world_file(self.path, seed=int(rng.integers(2**31 - 1))) if self.random else self.scenario


def _kind_source(kind: str, difficulty: float, template: Scenario | None) -> GeneratorSource:
    if kind not in KINDS:
        raise ConfigError(None, "world", f"unknown scenario kind {kind!r}; allowed: {', '.join(KINDS)}")
    # The warehouse is defined by its 31 obstacles: it is always drawn at full difficulty.
    return GeneratorSource(kind, 1.0 if kind == "warehouse" else difficulty, template)


def scenario_source(world: Scenario | str | Path | Sequence[Scenario] | Mapping[str, float] | ScenarioSource,
                    difficulty: float = 0.5, template: Scenario | None = None) -> ScenarioSource:
    """Interpret an env's ``world`` argument: a Scenario, a list of them, a generator kind or suite
    name (``open``, ``sparse``, ``cluttered``, ``warehouse``, ``trap``), a mapping of kinds to
    weights (a mix), or a YAML path."""
    if isinstance(world, Scenario):
        return FixedSource(world)
    if isinstance(world, Mapping):
        return MixSource(world, difficulty, template)
    if isinstance(world, (str, Path)):
        if str(world) in KINDS:
            return _kind_source(str(world), difficulty, template)
        if Path(world).suffix in (".yaml", ".yml") or Path(world).exists():
            return FileSource(world)
        raise ConfigError(None, "world", f"{str(world)!r} is neither a scenario kind ({', '.join(KINDS)}) nor a YAML file")
    if isinstance(world, Sequence):
        return ListSource(world)
    if hasattr(world, "draw"):
        return world
    raise ConfigError(None, "world", f"expected a Scenario, a kind name or a YAML path, got {type(world).__name__}")
