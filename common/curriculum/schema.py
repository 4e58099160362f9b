"""The curriculum YAML schema (validated with pydantic; errors are one line: file, field, allowed).

```yaml
name: stage1_2d
seed: 0
device: auto            # auto | cpu | cuda | mps
stages:
  - name: sparse
    world: flatland      # flatland | physics3d
    scenarios: {kind: sparse, difficulty: 0.5}     # or {suite: NAME} or {file: PATH}
    observation: lidar43 # nav7 | lidar43 | lidar43_log
    action_mapping: linear  # linear | rectified (common/actions.py)
    reward: default      # a preset (default, tutorial2d, tutorial3d) or {term: weight | {weight, params}}
    max_steps: 300       # episode length
    algorithm: ppo       # ppo | sac | td3
    hyperparams: {learning_rate: 3.0e-4, n_steps: 256}   # stable-baselines3's own argument names
    n_envs: 8
    vec_env: dummy       # dummy | subproc
    optimizer_kernels: foreach   # foreach (SB3's weights to the bit) | fused (faster on CPU, rounded differently)
    normalize: false     # VecNormalize on observations
    budget: 500000       # environment steps
    eval: {suite: sparse, episodes: 100, every: 50000}
    promote: {success_rate: 0.95}   # end the stage early when the evaluation reaches it
    init_from: null      # null | previous | path/to/policy.zip
    env_kwargs: {goal_threshold: [0.1, 0.5]}   # further env arguments (not those the keys above set)
```
"""

from __future__ import annotations

import inspect
import re
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (AfterValidator, BaseModel, ConfigDict, Field, ValidationError, field_validator,
                      model_validator)

from common.actions import MAPPINGS
from common.conditions import Conditions
from common.curriculum.hyperparams import CONFIGURABLE, OPTIMIZER_KERNELS, policy_kwargs_from_yaml, resolve_hyperparams
from common.curriculum.policy_file import ALGORITHMS
from common.drive import refuse_other_drives
from common.errors import ConfigError, did_you_mean, quote
from common.files import regular_file
from common.generators import KINDS, SUITES
from common.observations import LAYOUTS
from common.rewards import resolve_reward_spec
from common.scenario import pydantic_error
from common.task import MAX_EPISODES, MAX_STEPS, check_env_kwargs
from common.tiers import TIERS
from common.yaml_io import read_yaml_mapping

MAX_SEED = 2**31 - 1  # a curriculum's seed, and so every seed a sweep derives from it
MAX_STAGES = 64  # each is validated by building its worlds: 15,000 stages took minutes before a refusal
MAX_BUDGET = 10**10  # a stage's env steps: days on a cluster; a typo's 10^29 is refused, not trained toward



class _Strict(BaseModel):
    # Strict types: in pydantic's lax mode `budget: true` was a budget of one step.
    model_config = ConfigDict(frozen=True, extra="forbid", strict=True)


_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")


def _path_safe(name: str) -> str:
    """A curriculum's or stage's name, which names directories of its run: never a path (a name
    with ``/`` or ``..`` wrote a stage's policies outside the run directory)."""
    if not _NAME.fullmatch(name):
        raise ValueError(f"{quote(name)}; allowed: letters, digits, '_', '-' and '.', starting with a letter "
                         "or digit, at most 64 characters")
    return name


Name = Annotated[str, AfterValidator(_path_safe)]


class ScenarioSpec(_Strict):
    """Where a stage's training scenarios come from: exactly one of kind, mix, suite or file."""

    kind: Literal[KINDS] | None = None  # type: ignore[valid-type]
    mix: dict[Literal[KINDS], Annotated[float, Field(gt=0.0, le=1e6)]] | None = None  # type: ignore[valid-type]
    difficulty: Annotated[float, Field(ge=0.0, le=1.0)] = 0.5
    suite: str | None = None
    file: str | None = None

    @property
    def world(self) -> str | dict[str, float]:
        """What a stage's env is given as its ``world``: the kind, mix, suite (its kind's training
        split) or file."""
        return self.kind or self.mix or self.suite or self.file  # type: ignore[return-value]

    @model_validator(mode="after")
    def _exactly_one(self) -> "ScenarioSpec":
        given = [k for k in ("kind", "mix", "suite", "file") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"give exactly one of kind, mix, suite or file (got {', '.join(given) or 'none'})")
        if self.mix == {}:
            raise ValueError(f"mix names no kind; allowed: a weight for one or more of {', '.join(KINDS)}")
        if self.suite is not None and self.suite not in KINDS:
            # A suite trains on its kind's training split; the *_unaware suites are eval-only.
            unknown = "an eval-only suite" if self.suite in SUITES else "unknown suite"
            raise ValueError(f"{unknown} {quote(self.suite)}; allowed: {', '.join(KINDS)}")
        return self


class EvalSpec(_Strict):
    """Periodic evaluation on held-out scenarios (the suite's eval split, disjoint from training)."""

    suite: str
    episodes: Annotated[int, Field(ge=1, le=MAX_EPISODES)] = 100
    every: Annotated[int, Field(ge=1)] = 50_000
    final_episodes: Annotated[int, Field(ge=1, le=MAX_EPISODES)] | None = None  # the report's final evaluation (default: episodes)

    @field_validator("suite")
    @classmethod
    def _known_suite(cls, value: str) -> str:
        if value not in SUITES:
            raise ValueError(f"unknown suite {quote(value)}; allowed: {', '.join(SUITES)}")
        return value


class PromoteSpec(_Strict):
    """The stage ends early once an evaluation's success rate reaches this."""

    success_rate: Annotated[float, Field(gt=0.0, le=1.0)] = 0.9


class StageSpec(_Strict):
    """One stage of a curriculum."""

    name: Name
    world: Literal[TIERS] = "flatland"  # type: ignore[valid-type]
    scenarios: ScenarioSpec
    observation: Literal[LAYOUTS] = "lidar43"  # type: ignore[valid-type]
    action_mapping: Literal[MAPPINGS] = "linear"  # type: ignore[valid-type]
    reward: str | dict[str, Any] = "default"
    max_steps: Annotated[int, Field(ge=1, le=MAX_STEPS)] = 500
    algorithm: Literal[ALGORITHMS] = "ppo"  # type: ignore[valid-type]
    hyperparams: dict[str, Any] = {}
    n_envs: Annotated[int, Field(ge=1, le=256)] = 8
    vec_env: Literal["dummy", "subproc"] = "dummy"
    optimizer_kernels: Literal[OPTIMIZER_KERNELS] = "foreach"  # type: ignore[valid-type]
    normalize: bool = False
    budget: Annotated[int, Field(ge=1, le=MAX_BUDGET)]
    eval: EvalSpec
    promote: PromoteSpec | None = None
    init_from: str | None = None
    env_kwargs: dict[str, Any] = {}


class EvidenceSpec(_Strict):
    """Evidence for a transfer: the last stage (which starts from the previous stage's policy) is
    also run from scratch, and both arms over several seeds (common/curriculum/evidence.py)."""

    seeds: Annotated[int, Field(ge=1, le=20)] = 3
    scratch: bool = True


class CurriculumConfig(_Strict):
    """A curriculum: stages run in order, each optionally continuing from the previous policy."""

    name: Name
    seed: Annotated[int, Field(ge=0, le=MAX_SEED)] = 0
    device: Literal["auto", "cpu", "cuda", "mps"] = "auto"
    stages: Annotated[list[StageSpec], Field(min_length=1, max_length=MAX_STAGES)]
    evidence: EvidenceSpec | None = None

    @model_validator(mode="after")
    def _evidence_needs_a_transfer(self) -> "CurriculumConfig":
        if self.evidence is not None and (len(self.stages) < 2 or self.stages[-1].init_from != "previous"):
            raise ValueError("evidence compares a transfer with training from scratch: the last stage must have "
                             "init_from: previous")
        return self


_MANAGED = {"policy", "env", "seed", "device", "verbose", "tensorboard_log", "_init_setup_model"}
def _check_worlds(stage: StageSpec, conditions: Conditions, source: str | Path, field: str) -> None:
    """The stage's worlds (and so its robot) as its env gets them under ``conditions``: its
    scenario source built from the same argument (so refused where the env would refuse it: a
    robot too wide for a kind's layouts, robots drawn per episode on a file), then each world the
    source made (one of each kind, or its file's) checked in the order a world checks it: what the
    tier cannot build as written, then under the stage's conditions what its movers cannot, and
    the drive (a stage's policy file holds a (v, w) actor), whichever the robot came from."""
    from common.tiers import as_built, refuse_as_written, tier_source

    spec = stage.scenarios
    try:
        drawn = tier_source(stage.world, spec.world, spec.difficulty, conditions)
    except ConfigError as error:
        # A world file's own problems are the file's; a kind's are the robot's it was drawn for.
        raise _world_error(stage, source, field, error, stage_robot=error.source is None) from None
    for raw in drawn.examples:
        try:
            refuse_as_written(stage.world, raw)
        except ConfigError as error:
            # Generated worlds are drawn around the stage's robot; a file's robot is the file's.
            raise _world_error(stage, source, field, error, raw.name, stage_robot=spec.file is None) from None
        try:
            refuse_other_drives(as_built(stage.world, raw, conditions).robot, "a curriculum stage")
        except ConfigError as error:
            raise _world_error(stage, source, field, error, raw.name) from None


def _require_file(path: str, source: str | Path, field: str, allowed: str) -> None:
    """A one-line error naming ``field`` unless ``path`` is a regular file: a name too long for the
    file system, a directory or a FIFO is refused as a missing file is."""
    try:
        regular_file(path)
    except ConfigError as error:
        raise ConfigError(source, field, f"{quote(path)}: {error.problem}; allowed: {allowed}") from None


def _world_error(stage: StageSpec, source: str | Path, field: str, error: ConfigError, world: str | None = None,
                 stage_robot: bool = True) -> ConfigError:
    """A problem of a stage's worlds, named where the stage set it: its own robot (``env_kwargs``)
    where that robot drives (``stage_robot``), else its scenarios, with the world file and the
    world that showed it."""
    if stage_robot and "robot" in stage.env_kwargs and (error.field or "").startswith("robot"):
        return ConfigError(source, f"{field}.env_kwargs.{error.field}", error.problem)
    file = error.source or stage.scenarios.file
    if file is not None and source is not None and Path(file).is_relative_to(Path(source).parent):
        file = Path(file).relative_to(Path(source).parent)  # as the curriculum names it
    where = [str(file or ""), world or "", error.field or ""]
    return ConfigError(source, f"{field}.scenarios", ": ".join([part for part in where if part] + [error.problem]))


def _check_stage(stage: StageSpec, index: int, source: str | Path) -> None:
    """What pydantic cannot know: reward terms, SB3 argument names, init_from order and paths."""
    field = f"stages.{index}"
    try:
        resolve_reward_spec(stage.reward)
    except ConfigError as error:
        raise ConfigError(source, f"{field}.{error.field}", error.problem) from None
    from common.curriculum.policy import algorithm_class  # torch and stable-baselines3: seconds, for curricula only

    parameters = inspect.signature(algorithm_class(stage.algorithm).__init__).parameters
    arguments = set(parameters)
    allowed = sorted(arguments & CONFIGURABLE)
    for key in stage.hyperparams:
        if key in arguments - _MANAGED - CONFIGURABLE - {"self"}:
            raise ConfigError(source, f"{field}.hyperparams.{key}",
                              f"takes code (a class or its arguments), which a curriculum does not name; "
                              f"allowed: {', '.join(allowed)}")
        if key not in allowed:
            raise ConfigError(source, f"{field}.hyperparams.{key}",
                              f"not a {stage.algorithm.upper()} argument{did_you_mean(key, allowed)}; "
                              f"allowed: {', '.join(allowed)}")
    resolve_hyperparams(stage.hyperparams, source=source, field=f"{field}.hyperparams", algorithm=stage.algorithm)
    if stage.algorithm == "ppo" and stage.hyperparams.get("n_steps", parameters["n_steps"].default) * stage.n_envs < 2:
        # PPO's advantage normalisation needs two samples a rollout (SB3 asserts it when it starts).
        raise ConfigError(source, f"{field}.hyperparams.n_steps", f"1 step in {stage.n_envs} env makes a rollout of one "
                          "step; allowed: n_steps x n_envs of at least 2")
    if "policy_kwargs" in stage.hyperparams:
        kwargs = policy_kwargs_from_yaml(stage.hyperparams["policy_kwargs"], source, f"{field}.hyperparams.policy_kwargs")
        if refusal := kwargs.refused_by(stage.algorithm):
            raise ConfigError(source, f"{field}.hyperparams.policy_kwargs.{refusal[0]}",
                              f"{refusal[1]} (this stage's: {stage.algorithm})")
    conditions = check_env_kwargs(stage.env_kwargs, stage.world, source, f"{field}.env_kwargs")
    if stage.init_from == "previous" and index == 0:
        raise ConfigError(source, f"{field}.init_from", "the first stage has no previous stage; allowed: null or a policy path")
    if stage.init_from not in (None, "previous"):
        _require_file(stage.init_from, source, f"{field}.init_from", "null, previous or a .zip path")
        _check_init_policy(stage, source, f"{field}.init_from")
    if stage.scenarios.file is not None:
        _require_file(stage.scenarios.file, source, f"{field}.scenarios.file", "a scenario or IR-SIM world YAML file")
    _check_worlds(stage, conditions, source, field)


def curriculum_from_mapping(data: dict, source: str | Path | None = None) -> CurriculumConfig:
    """Validate a parsed curriculum mapping. Relative ``init_from`` and ``scenarios.file`` paths are
    resolved against the file's folder (``source``), as a curriculum shared with its files expects."""
    if not is_curriculum(data) and (world := world_file_format(data)):
        raise ConfigError(source, None, f"is {world}, not a curriculum (it has no stages); "
                          "try it with: curriculum compare --scenario-file FILE")
    try:
        config = CurriculumConfig.model_validate(data)
    except ValidationError as exc:
        raise pydantic_error(source, exc, CurriculumConfig) from None
    if source is not None:
        config = _resolve_paths(config, Path(source).parent)
    for index, stage in enumerate(config.stages):
        _check_stage(stage, index, source)
    names = [stage.name for stage in config.stages]
    if len(set(names)) != len(names):
        raise ConfigError(source, "stages", f"stage names must be unique, got {names}")
    return config


def _check_init_policy(stage: StageSpec, source: str | Path | None, field: str) -> None:
    """The policy ``init_from`` names, opened now (bounded, no code run) and, where it holds this
    project's manifest, trained by the stage's algorithm: found wanting only when its stage
    began, a later stage's start failed after the earlier ones had trained."""
    from common.curriculum.policy_file import PolicyFile

    try:
        file = PolicyFile(stage.init_from, require_manifest=False)
    except ConfigError as error:
        raise ConfigError(source, field, f"{quote(stage.init_from)}: {error.problem}") from None
    if file.manifest is not None and file.manifest.algorithm != stage.algorithm:
        raise ConfigError(source, field, f"{quote(stage.init_from)} is a {file.manifest.algorithm} policy, whose network "
                          f"a {stage.algorithm} stage cannot load; allowed: a {stage.algorithm} policy")


def _resolve_paths(config: CurriculumConfig, base: Path) -> CurriculumConfig:
    def resolve(path: str) -> str:
        return path if Path(path).is_absolute() else str((base / path).resolve())

    stages = []
    for stage in config.stages:
        update: dict[str, Any] = {}
        if stage.init_from not in (None, "previous"):
            update["init_from"] = resolve(stage.init_from)
        if stage.scenarios.file is not None:
            update["scenarios"] = stage.scenarios.model_copy(update={"file": resolve(stage.scenarios.file)})
        stages.append(stage.model_copy(update=update) if update else stage)
    return config.model_copy(update={"stages": stages})


def load_curriculum(path: str | Path) -> CurriculumConfig:
    """Read and validate a curriculum YAML file."""
    return curriculum_from_mapping(read_yaml_mapping(path), path)


def world_file_format(data: dict) -> str | None:
    """What a parsed YAML mapping without stages is, if a world file: "an IR-SIM world file" or
    "a scenario" (one of the scenario's own keys at its top level)."""
    from common.scenario import Scenario
    from common.world_file import irsim_mark

    if irsim_mark(data) is not None:
        return "an IR-SIM world file"
    # Keys a curriculum has too (name, seed) tell nothing: a curriculum with a misspelt stages has them.
    return "a scenario" if (set(Scenario.model_fields) - set(CurriculumConfig.model_fields)) & data.keys() else None


def is_curriculum(data: dict) -> bool:
    """Whether a parsed YAML mapping is a curriculum (rather than a world file)."""
    return "stages" in data
