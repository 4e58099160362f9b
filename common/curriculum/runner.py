"""Run a curriculum stage by stage: train, evaluate on held-out scenarios, checkpoint, promote, resume.

The run directory's files are :mod:`common.curriculum.run_directory`'s; the evaluation draws
:mod:`common.curriculum.stage`'s.

A run holds ``OUT/.lock`` (an OS file lock, released when the process ends, even by ``kill -9``),
so a second run or resume of the same directory is refused instead of interleaving with it. A
directory whose run died before its first checkpoint holds nothing worth keeping: the same
command (or ``--resume``) starts it afresh.
"""

from __future__ import annotations

import platform
import subprocess
import time
from pathlib import Path
from typing import Annotated, Callable

import numpy as np
import yaml
from filelock import FileLock, Timeout
from pydantic import BaseModel, ConfigDict, Field, ValidationError

import common
from common.atomic import atomic_write
from common.conditions import conditions_of
from common.curriculum.comparison import write_csv
from common.curriculum.hyperparams import resolve_hyperparams
from common.curriculum.machine import machine
from common.curriculum.policy import (DeterministicAction, algorithm_class, load_weights, use_optimizer_kernels,
                                      policy_class, vec_env_class)
from common.curriculum.policy_file import Normalizer, PolicyFile, update_manifest
from common.curriculum.replay import load_replay
from common.curriculum.run_directory import (LOCK_NAME, MARKER, EvalLog, StagePaths, check_claimable, clear_unstarted,
                                             is_marked, mark, unstarted, write_json)
from common.curriculum.schema import CurriculumConfig, StageSpec
from common.curriculum.stage import TEST_SEED_SHIFT, stage_radius, stage_scenarios
from common.errors import ConfigError
from common.evaluation import Summary, evaluate
from common.observations import DEFAULT_GOAL_DISTANCE_SCALE
from common.policy_agent import PolicyAgent
from common.yaml_io import read_yaml


def resolve_device(device: str, source: str | Path | None = None, field: str = "device") -> str:
    """``auto`` picks CUDA, then Apple's MPS, then the CPU. A device this machine lacks is a
    :class:`ConfigError` naming ``source`` and ``field``: stable-baselines3 would train on the CPU without a word,
    and the stage's policy then failed to load onto the device asked for, after the whole stage."""
    import torch

    cuda = torch.cuda.is_available()
    mps = getattr(torch.backends, "mps", None) is not None and torch.backends.mps.is_available()
    if device == "auto":
        return "cuda" if cuda else "mps" if mps else "cpu"
    if (device == "cuda" and not cuda) or (device == "mps" and not mps):
        here = ", ".join(["auto", "cpu", *(["cuda"] if cuda else []), *(["mps"] if mps else [])])
        raise ConfigError(source, field, f"{device!r}, but torch finds no {device.upper()} device on this machine; "
                          f"allowed here: {here}")
    return device


def git_commit() -> str | None:
    """The project's git commit (with ``-dirty`` when tracked files differ from it), or None outside a checkout."""
    here = Path(__file__).resolve().parent
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=True, cwd=here).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True,
                               check=True, cwd=here).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return f"{commit}-dirty" if dirty else commit


def stage_env_kwargs(stage: StageSpec) -> dict:
    """The keyword arguments of each env a stage trains in."""
    spec = stage.scenarios
    return dict(world=spec.world, observation=stage.observation, reward=stage.reward, max_steps=stage.max_steps,
                difficulty=spec.difficulty, action_mapping=stage.action_mapping, **stage.env_kwargs)


def _env_rng_states(file: PolicyFile, count: int) -> list[dict] | None:
    """The ``count`` envs' generator states a checkpoint holds (None if it holds none for as
    many envs: they draw afresh), each checked as a generator takes it."""
    states = file.raw_manifest.get("env_rng")
    if not isinstance(states, list) or len(states) != count:
        return None
    for state in states:
        try:
            np.random.PCG64().state = state
        except (TypeError, ValueError, KeyError, OverflowError):
            raise ConfigError(file.path, "nav_manifest.json: env_rng", "not the envs' generator states a run writes; "
                              "the checkpoint is damaged") from None
    return states


def _is_state(state: object, config: CurriculumConfig) -> bool:
    """Whether ``state`` is what a run of ``config`` writes: done stages (in order, each with its
    result) and results by stage name."""
    if not isinstance(state, dict) or not isinstance(state.get("done"), list) or not isinstance(state.get("stages"), dict):
        return False
    names = [stage.name for stage in config.stages]
    done, results = state["done"], state["stages"]
    return done == names[: len(done)] and all(_is_result(results.get(name)) for name in done) and set(results) <= set(names)


class _Checked(BaseModel):
    # Strict: JSON's true is no count, "3" no number; NaN is no figure. Other keys are kept as written.
    model_config = ConfigDict(strict=True, extra="allow", allow_inf_nan=False)


class _FinalFigures(_Checked):
    """A stage's final evaluation, as the report and the closing lines read it."""

    success_rate: float
    collision_rate: float
    timeout_rate: float
    stuck_rate: float
    spl: float
    episodes: int
    success_ci95: Annotated[list[float], Field(min_length=2, max_length=2)]
    mean_steps: float | None


class _StageResult(_Checked):
    """A finished stage's result in state.json."""

    timesteps: int
    wall_seconds: float
    steps_per_second: float
    promoted: bool
    policy: str
    final: _FinalFigures


def _is_result(result: object) -> bool:
    """Whether ``result`` is a finished stage's result as a run writes it."""
    try:
        _StageResult.model_validate(result)
    except ValidationError:
        return False
    return True


def _purge_tensorboard_after(log_dir: Path, run_name: str, step: int) -> None:
    """Hide the TensorBoard points an interrupted run logged past ``step`` (the checkpoint a resume
    continues from, and so logs again): TensorBoard's purge marker, in the run folder SB3 continues."""
    from stable_baselines3.common.utils import get_latest_run_id
    from torch.utils.tensorboard import SummaryWriter

    latest = get_latest_run_id(str(log_dir), run_name)
    if latest:
        SummaryWriter(str(log_dir / f"{run_name}_{latest}"), purge_step=step).close()


def _env_class(stage: StageSpec) -> type:
    """The env class of a stage's tier. make_vec_env gets the class, not a registered id: a subprocess
    env unpickles the class by its module, which imports (and registers) the tier, where an id
    would be unknown in a fresh process ("Namespace flatland not found")."""
    if stage.world == "flatland":
        from flatland.env import NavEnv

        return NavEnv
    from physics3d.env import WarehouseNavEnv

    return WarehouseNavEnv


class Runner:
    """Runs a validated curriculum into a run directory."""

    def __init__(self, config: CurriculumConfig, out: Path, resume: bool = False, device: str | None = None,
                 progress: bool = True, on_evaluation: Callable[[dict], None] | None = None) -> None:
        self.config, self.out, self.resume = config, Path(out), resume
        self.device = resolve_device(device or config.device, field="--device" if device else "device")
        self.progress = progress
        self.on_evaluation = on_evaluation  # sees every periodic evaluation's eval.csv row (a sweep reports them)
        self.eval_log: EvalLog | None = None
        self.provenance: dict = {}  # run.json, once prepare() has read and checked it
        self._lock: FileLock | None = None

    def prepare(self) -> dict:
        """Lock the run directory, create (or, resuming, reopen) it; return the curriculum state."""
        state_path = self.out / "state.json"
        if self.resume and not state_path.exists():
            raise ConfigError(self.out, None, "nothing to resume here (no state.json); run without --resume")
        check_claimable(self.out)
        self._lock = FileLock(self.out / LOCK_NAME)
        try:
            self.out.mkdir(parents=True, exist_ok=True)
            self._lock.acquire(timeout=0)
        except Timeout:
            raise ConfigError(self.out, None, "another run is using this directory; wait for it to finish or choose another --out") from None
        except OSError as error:
            raise ConfigError(self.out, None, f"cannot write here ({error.strerror}); choose another --out") from None
        try:
            return self._open()
        except BaseException:
            self.release()
            raise

    def _open(self) -> dict:
        from common.files import MAX_STATE_BYTES, read_json

        state_path = self.out / "state.json"
        if not is_marked(self.out):
            mark(self.out)  # before anything else is written
        fresh = unstarted(self.out)
        if fresh:
            # A run that died before its first checkpoint (say, a missing dependency) left only
            # what prepare() writes: nothing to keep, nothing to resume.
            clear_unstarted(self.out)
        if self.resume and not fresh:
            saved = read_yaml(self.out / "config.yaml")
            if saved != self.config.model_dump(mode="json"):
                raise ConfigError(self.out, "config.yaml", "the curriculum changed since this run started; resume it with the same file")
            state = read_json(state_path, MAX_STATE_BYTES, "this run's state.json")
            if not _is_state(state, self.config):
                raise ConfigError(state_path, None, "not the state this project writes (done stages, their results); "
                                  "the run directory is damaged")
        else:
            # Where a fresh start was cleared, what is left in stages/ is a user's own, kept beside the run.
            if any(p.name not in (LOCK_NAME, MARKER) and not (fresh and p.name == "stages") for p in self.out.iterdir()):
                raise ConfigError(self.out, None, "the run directory is not empty; pass --resume to continue it or choose another --out")
            atomic_write(self.out / "config.yaml",
                         lambda tmp: tmp.write_text(yaml.safe_dump(self.config.model_dump(mode="json"), sort_keys=False)))
            write_json(self.out / "run.json", self._provenance())
            state = {"done": [], "stages": {}}
            write_json(state_path, state)
        self.eval_log = EvalLog(self.out / "eval.csv")
        provenance = read_json(self.out / "run.json", MAX_STATE_BYTES, "this run's run.json")
        if not isinstance(provenance, dict) or not isinstance(provenance.get("git_commit", 0), (str, type(None))):
            raise ConfigError(self.out / "run.json", "git_commit", "missing; the run directory is damaged")
        for key in ("device", "package_version"):  # the report's first line reads them
            if not isinstance(provenance.get(key), str):
                raise ConfigError(self.out / "run.json", key, "missing; the run directory is damaged")
        self.provenance = provenance
        return state

    @property
    def commit(self) -> str | None:
        """The commit the run started from (run.json's): the code that trains every stage, even
        when a policy is saved, or the run resumed, after later commits."""
        return self.provenance.get("git_commit")

    def release(self) -> None:
        """Let another run use the directory."""
        if self._lock is not None:
            self._lock.release()

    def _provenance(self) -> dict:
        import stable_baselines3
        import torch

        return {"curriculum": self.config.name, "seed": self.config.seed, "package_version": common.__version__,
                "git_commit": git_commit(), "device": self.device, "python": platform.python_version(),
                "torch": torch.__version__, "stable_baselines3": stable_baselines3.__version__,
                "machine": machine(), "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}

    def run(self) -> dict:
        """Train every stage not done yet; write the report; return the final state."""
        state = self.prepare()
        try:
            for index, stage in enumerate(self.config.stages):
                if stage.name in state["done"]:
                    continue
                result = self._run_stage(index, stage, state)
                state["stages"][stage.name] = result
                state["done"].append(stage.name)
                write_json(self.out / "state.json", state)
            from common.curriculum.report import write_report

            write_report(self.out, self.config, state, self.provenance, self.eval_log.rows())
            if self.config.evidence is not None:
                from common.curriculum.evidence import gather_evidence

                state["transfer"] = gather_evidence(self, state)
                write_json(self.out / "state.json", state)
        finally:
            self.release()
        return state

    def arm(self, config: CurriculumConfig, out: Path, resume: bool) -> "Runner":
        """A quiet run of another curriculum on this run's device (an evidence arm)."""
        return Runner(config, out, resume=resume, device=self.device, progress=False)

    def stage_paths(self, index: int, stage: StageSpec) -> StagePaths:
        return StagePaths.of(self.out, index, stage.name)

    def _run_stage(self, index: int, stage: StageSpec, state: dict) -> dict:
        import torch
        from stable_baselines3.common.env_util import make_vec_env
        from stable_baselines3.common.vec_env import VecNormalize

        from common.curriculum.training import CurriculumCallback

        if self.device == "cpu":
            torch.set_num_threads(1)  # measured: one thread is fastest for these small MLPs on 2 cores
        # torch checks every distribution's parameters as it builds one, about 19 µs each time the
        # policy acts or is updated. A diverged policy still stops the run: the envs refuse NaN actions.
        torch.distributions.Distribution.set_default_validate_args(False)
        paths = self.stage_paths(index, stage)
        seed = self.config.seed + index
        venv = make_vec_env(_env_class(stage), n_envs=stage.n_envs, seed=seed, env_kwargs=stage_env_kwargs(stage),
                            vec_env_cls=vec_env_class(stage.vec_env))
        resuming = self.resume and paths.last.exists()
        paths.clear_temporaries()
        if stage.normalize:
            venv = VecNormalize(venv, norm_obs=True, norm_reward=False)
        model = algorithm_class(stage.algorithm)(policy_class(stage.algorithm), venv, seed=seed, device=self.device, verbose=0,
                                                 tensorboard_log=str(paths.tensorboard),
                                                 **resolve_hyperparams(stage.hyperparams))
        # Both a resume and init_from load weights (never pickles) into the model the curriculum describes.
        source = paths.last if resuming else self._init_source(index, stage)
        if source is not None:
            file = load_weights(model, source, policy_only=not resuming)
            if resuming and paths.replay.exists() and hasattr(model, "replay_buffer"):
                load_replay(model.replay_buffer, paths.replay)
            normalizer = file.normalizer(venv.observation_space.shape[0]) if file is not None else None
            if normalizer is not None and isinstance(venv, VecNormalize):
                normalizer.apply_to(venv)
            states = _env_rng_states(file, venv.num_envs) if resuming else None
            for env_index, env_state in enumerate(states or ()):
                venv.env_method("restore_rng", env_state, indices=[env_index])
        use_optimizer_kernels(model, stage.optimizer_kernels)
        already = int(model.num_timesteps)
        self.eval_log.truncate(stage.name, already)
        if resuming:
            _purge_tensorboard_after(paths.tensorboard, stage.name, already)
        callback = CurriculumCallback(self, index, stage, paths)
        start = time.perf_counter()
        remaining = max(0, stage.budget - already)
        if remaining and not callback.promoted_before:
            model.learn(remaining, callback=callback, reset_num_timesteps=not resuming, progress_bar=self.progress,
                        tb_log_name=stage.name)
        learn_seconds = time.perf_counter() - start - callback.eval_seconds
        callback.finish(model)
        venv.close()
        summary = self.final_evaluation(stage, paths.policy)
        return {"timesteps": int(model.num_timesteps), "wall_seconds": round(callback.wall_time(), 1),
                "steps_per_second": round((int(model.num_timesteps) - already) / max(learn_seconds, 1e-9), 1),
                "promoted": callback.promoted, "best_success_rate": callback.best_success,
                "final": summary.to_json(), "policy": str(paths.policy.relative_to(self.out))}

    def _init_source(self, index: int, stage: StageSpec) -> Path | None:
        if stage.init_from is None:
            return None
        if stage.init_from == "previous":
            previous = self.config.stages[index - 1]
            return self.stage_paths(index - 1, previous).policy
        return Path(stage.init_from)

    def evaluate_model(self, model, stage: StageSpec, normalizer: Normalizer | None, episodes: int,
                       seed_shift: int) -> Summary:
        """Success and SPL of the current model on the stage's eval suite (a held-out draw)."""
        agent = PolicyAgent(model, stage.observation, DEFAULT_GOAL_DISTANCE_SCALE, normalizer, name=stage.name,
                            action_mapping=stage.action_mapping, max_steps=stage.max_steps,
                            predict=DeterministicAction(model.policy))
        (summary,) = evaluate([agent], stage_scenarios(stage, episodes, seed_shift), stage.world, seed=seed_shift,
                              max_steps=stage.max_steps, conditions=conditions_of(stage.env_kwargs),
                              goal_radius=stage_radius(stage))
        return summary

    def evaluate_policy(self, stage: StageSpec, policy: Path, test: bool = True) -> Summary:
        """A policy zip on the stage's eval suite, under the stage's conditions: the test draw (the
        report's) or the validation draw (the periodic evaluations')."""
        from common.curriculum.policy import load_policy

        agent = load_policy(policy, device=self.device, name=stage.name)
        episodes = (stage.eval.final_episodes or stage.eval.episodes) if test else stage.eval.episodes
        first = TEST_SEED_SHIFT if test else 0
        (summary,) = evaluate([agent], stage_scenarios(stage, episodes, first), stage.world, seed=first,
                              max_steps=stage.max_steps, conditions=conditions_of(stage.env_kwargs),
                              goal_radius=stage_radius(stage))
        return summary

    def final_evaluation(self, stage: StageSpec, policy: Path) -> Summary:
        """The report's evaluation of a stage's policy on the test draw of its eval suite."""
        summary = self.evaluate_policy(stage, policy)
        figures = {"suite": stage.eval.suite, "draw": "test", "first_seed": TEST_SEED_SHIFT, **summary.to_json()}
        write_json(policy.parent / "final_eval.json", figures)
        atomic_write(policy.parent / "final_episodes.csv", lambda tmp: write_csv([summary], tmp))
        update_manifest(policy, {"final_eval": figures})
        return summary


__all__ = ["Runner", "resolve_device", "TEST_SEED_SHIFT"]
