"""The stable-baselines3 callback that evaluates, checkpoints and promotes during a stage."""

from __future__ import annotations

import shutil
import time
from typing import Callable, Protocol

from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecNormalize

from common.atomic import atomic_write, atomic_write_all
from common.curriculum.policy import load_policy
from common.curriculum.policy_file import Normalizer, policy_writer
from common.curriculum.replay import replay_writer
from common.curriculum.run_directory import EvalLog, StagePaths
from common.curriculum.schema import CurriculumConfig, StageSpec
from common.curriculum.stage import manifest_for
from common.evaluation import Summary


class StageHost(Protocol):
    """What the callback needs of the run that trains the stage (a :class:`~common.curriculum.runner.Runner`)."""

    config: CurriculumConfig
    commit: str | None
    eval_log: EvalLog
    on_evaluation: Callable[[dict], None] | None

    def evaluate_model(self, model, stage: StageSpec, normalizer: Normalizer | None, episodes: int,
                       seed_shift: int) -> Summary: ...


class CurriculumCallback(BaseCallback):
    """Every ``eval.every`` steps: evaluate on the validation draw, append to eval.csv, save the best
    and the last checkpoint (atomically, in that order after the row), and stop the stage once the
    promotion threshold is met."""

    def __init__(self, runner: StageHost, index: int, stage: StageSpec, paths: StagePaths) -> None:
        super().__init__()
        self.runner, self.index, self.stage, self.paths = runner, index, stage, paths
        rows = [r for r in runner.eval_log.rows() if r["stage"] == stage.name]
        self.best_success = max((float(r["success_rate"]) for r in rows), default=-1.0)
        self.last_eval_at = max((int(r["timesteps"]) for r in rows), default=-1)
        threshold = stage.promote.success_rate if stage.promote else None
        self.promoted_before = bool(rows) and threshold is not None and float(rows[-1]["success_rate"]) >= threshold
        self.promoted = self.promoted_before
        self.previous_wall = float(rows[-1]["wall_time"]) if rows else 0.0
        self.started = time.perf_counter()
        self.eval_seconds = 0.0  # this session's time in evaluations and checkpoints, not training

    def _on_training_start(self) -> None:
        every = self.stage.eval.every
        self.next_eval = (self.num_timesteps // every + 1) * every

    def _on_step(self) -> bool:
        if self.num_timesteps < self.next_eval:
            return True
        self.next_eval += self.stage.eval.every
        return self._evaluate_and_checkpoint(self.model)

    def _normalizer(self, model) -> Normalizer | None:
        env = model.get_env()
        return Normalizer.from_vec_normalize(env) if isinstance(env, VecNormalize) else None

    def wall_time(self) -> float:
        return self.previous_wall + time.perf_counter() - self.started

    def _evaluate_and_checkpoint(self, model) -> bool:
        began = time.perf_counter()
        try:
            return self._evaluate_and_save(model)
        finally:
            self.eval_seconds += time.perf_counter() - began

    def _evaluate_and_save(self, model) -> bool:
        normalizer = self._normalizer(model)
        summary = self.runner.evaluate_model(model, self.stage, normalizer, self.stage.eval.episodes, seed_shift=0)
        timesteps = int(model.num_timesteps)
        row = {
            "stage": self.stage.name, "timesteps": timesteps, "wall_time": round(self.wall_time(), 1),
            "success_rate": summary.success_rate, "collision_rate": summary.collision_rate,
            "timeout_rate": summary.timeout_rate, "stuck_rate": summary.stuck_rate, "spl": round(summary.spl, 4),
            "mean_steps": "" if summary.mean_steps is None else round(summary.mean_steps, 1),
        }
        self.runner.eval_log.append(row)
        self.last_eval_at = timesteps
        manifest = manifest_for(self.runner.config, self.runner.commit, self.index, timesteps, self.wall_time(),
                                {"suite": self.stage.eval.suite, "draw": "validation", **summary.to_json()})
        # The envs' generators travel with the checkpoint, so a resume continues their scenario
        # sequence. The replay buffer and a new best are written with it as one set: a kill between
        # them left a buffer a checkpoint ahead of the weights, which a resume trained on without a
        # word, or a best.zip from the stretch of training the resume discards.
        checkpoint = {self.paths.last: policy_writer(model, {**manifest, "env_rng": model.get_env().env_method("rng_state")},
                                                     normalizer)}
        if hasattr(model, "replay_buffer"):
            checkpoint[self.paths.replay] = replay_writer(model.replay_buffer)
        if summary.success_rate > self.best_success or not self.paths.best.exists():
            checkpoint[self.paths.best] = policy_writer(model, manifest, normalizer)
        atomic_write_all(checkpoint)
        self.best_success = max(self.best_success, summary.success_rate)
        if self.runner.on_evaluation is not None:
            self.runner.on_evaluation(row)  # after the checkpoint: a sweep may stop the trial here
        threshold = self.stage.promote.success_rate if self.stage.promote else None
        self.promoted = threshold is not None and summary.success_rate >= threshold
        return not self.promoted

    def finish(self, model) -> None:
        """Evaluate the final weights if the last evaluation was earlier; the best checkpoint becomes
        the policy, once it opens as one (a damaged best.zip is refused, the policy.zip kept)."""
        if self.last_eval_at < int(model.num_timesteps) and not self.promoted:
            self._evaluate_and_checkpoint(model)
        load_policy(self.paths.best)
        atomic_write(self.paths.policy, lambda tmp: shutil.copyfile(self.paths.best, tmp))
