"""What a stage trains with, is judged on, and writes into its policies' manifests.

Periodic evaluations use the eval suite's *validation* draw (suite seeds from 0); the report's final
evaluation uses a *test* draw (suite seeds from :data:`TEST_SEED_SHIFT`) of the same suite. Both
are the eval split, disjoint from the training scenarios, and the test draw never chose a checkpoint.
"""

from __future__ import annotations

import functools
import warnings
from typing import Iterator

import common
from common.conditions import conditions_of
from common.curriculum.machine import machine
from common.curriculum.schema import CurriculumConfig, StageSpec
from common.errors import ScenarioWarning
from common.generators import get_suite
from common.task import judged_radius
from common.observations import DEFAULT_GOAL_DISTANCE_SCALE
from common.scenario import RobotProfile, Scenario

TEST_SEED_SHIFT = 100_000


def stage_scenarios(stage: StageSpec, count: int, first: int) -> Iterator[Scenario]:
    """A draw of the stage's eval suite (judged within :func:`stage_radius`; a suite laid out for
    its robot, for the stage's), drawn as it is read (a million held at once would take tens of GB)."""
    robot = conditions_of(stage.env_kwargs).for_tier(stage.world).profile
    return get_suite(stage.eval.suite).scenarios(count=count, seed=first, robot=robot)


def stage_radius(stage: StageSpec) -> float | None:
    """The goal radius a stage's policies are judged by, as the stage trains: its own if it sets
    one (a stage that trains to arrive within 0.1 m is measured on arriving within 0.1 m), else
    each scenario's."""
    return judged_radius(stage.env_kwargs)


def training_robot(stage: StageSpec) -> RobotProfile:
    """The robot profile a stage trains with: its conditions' (the tier's default included), else
    its world file's, else the generator template's."""
    profile = conditions_of(stage.env_kwargs).for_tier(stage.world).profile
    if profile is not None:
        return profile
    if stage.scenarios.file is not None:  # the file's robot, which the env drives (a deployment reads it here)
        return _file_robot(stage.scenarios.file)
    return Scenario().robot


@functools.lru_cache(maxsize=16)
def _file_robot(path: str) -> RobotProfile:
    """A world file's robot, read once a process: every checkpoint's manifest asks, and a file
    edited during the stage must not change what its policies say they trained on."""
    from common.world_file import WorldFile

    with warnings.catch_warnings():  # the file's warnings were given as the curriculum was read
        warnings.simplefilter("ignore", ScenarioWarning)
        return WorldFile(path).initial.robot


def manifest_for(config: CurriculumConfig, commit: str | None, index: int, timesteps: int, wall_time: float,
                 evaluation: dict | None) -> dict:
    """What a policy zip of stage ``index`` says about itself (``commit``: the code the run started
    from; ``machine``: the one that saved it, whose CPU decides how its training rounded)."""
    stage = config.stages[index]
    return {"algorithm": stage.algorithm, "observation": stage.observation,
            "goal_distance_scale": DEFAULT_GOAL_DISTANCE_SCALE, "action_mapping": stage.action_mapping,
            "max_steps": stage.max_steps, "env_kwargs": stage.env_kwargs, "tier": stage.world,
            "robot": training_robot(stage).model_dump(mode="json"), "curriculum": config.name, "stage": stage.name,
            "stage_index": index, "seed": config.seed + index, "git_commit": commit,
            "package_version": common.__version__, "machine": machine(), "timesteps": timesteps,
            "wall_time_s": round(wall_time, 1), "eval": evaluation}
