"""The transfer evidence's figures from given curves: steps to 90 % validation success counts the
first evaluation at or above it, the zero-shot evaluation is the transfer arm's step 0, and an arm
reaches 90 % only if every one of its seeds does."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest

from common.curriculum.evidence import TARGET, gather_evidence, steps_to
from common.curriculum.policy_file import read_manifest
from common.curriculum.run_directory import EVAL_FIELDS, StagePaths
from common.curriculum.schema import CurriculumConfig, load_curriculum

TRANSFER = Path(__file__).parent / "data" / "tiny_transfer.yaml"  # two seeds per arm, with scratch

Curve = list[tuple[int, float]]


def test_steps_to_is_the_first_evaluation_at_or_above_the_target():
    assert steps_to([(64, 0.5), (128, TARGET), (192, 1.0)]) == 128
    assert steps_to([(64, 0.5), (128, 0.95)], target=0.95) == 128
    assert steps_to([(0, 1.0), (64, 0.5)]) == 0
    assert steps_to([(64, 0.5), (128, 0.89)]) is None and steps_to([]) is None


def _write_run(run: Path, config: CurriculumConfig, curve: Curve) -> None:
    """What a finished run leaves that the evidence reads: eval.csv, state.json and the last
    stage's final_eval.json."""
    last = config.stages[-1]
    final = StagePaths.of(run, len(config.stages) - 1, last.name).policy.parent
    final.mkdir(parents=True, exist_ok=True)
    (final / "final_eval.json").write_text(json.dumps({"success_rate": curve[-1][1]}))
    (run / "state.json").write_text(json.dumps({"stages": {last.name: {"wall_seconds": 1.0}}}))
    with (run / "eval.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=EVAL_FIELDS, restval="")
        writer.writeheader()
        writer.writerows({"stage": last.name, "timesteps": steps, "success_rate": success} for steps, success in curve)


class _Arm:
    """A finished evidence arm: its files are written when it runs."""

    def __init__(self, config: CurriculumConfig, out: Path, curve: Curve) -> None:
        self.config, self.out, self.curve = config, out, curve

    def run(self) -> dict:
        _write_run(self.out, self.config, self.curve)
        return {}


class _Host:
    """A curriculum run whose arms and evaluations give scripted figures, keyed by arm directory
    name ("." for the run itself): each arm's validation curve and, for the transfer arms, the
    previous stage's policy's zero-shot validation success."""

    def __init__(self, out: Path, curves: dict[str, Curve], zero_shot: dict[str, float]) -> None:
        self.config, self.out = load_curriculum(TRANSFER), out
        self.curves, self.zero_shot = curves, zero_shot

    def arm(self, config: CurriculumConfig, out: Path, resume: bool) -> _Arm:
        return _Arm(config, out, self.curves[out.name])

    def evaluate_policy(self, stage, policy: Path, test: bool = True) -> SimpleNamespace:
        run = next(name for name in self.zero_shot if (self.out / name).resolve() in policy.resolve().parents)
        return SimpleNamespace(success_rate=self.zero_shot[run])


def _gather(tmp_path: Path, policy: Path, curves: dict[str, Curve], zero_shot: dict[str, float]) -> dict:
    out = tmp_path / "run"
    out.mkdir()
    host = _Host(out, curves, zero_shot)
    _write_run(out, host.config, curves["."])
    last = StagePaths.of(out, len(host.config.stages) - 1, host.config.stages[-1].name).policy
    shutil.copyfile(policy, last)  # the final policy's manifest receives the evidence
    return gather_evidence(host, {"stages": {host.config.stages[-1].name: {"policy": str(last.relative_to(out))}}})


REACHES_AT_128: Curve = [(64, 0.5), (128, TARGET), (192, 1.0)]
NEVER: Curve = [(64, 0.5), (128, 0.75), (192, 0.8)]


def test_the_transfer_arm_counts_its_zero_shot_success_as_step_0(tmp_path, untrained_policy):
    curves = {".": REACHES_AT_128, "transfer-seed1000": NEVER, "scratch-seed0": REACHES_AT_128,
              "scratch-seed1000": REACHES_AT_128}
    # Both transfer seeds reach 90 % before any step of the last stage: one of them never does after.
    evidence = _gather(tmp_path, untrained_policy, curves, zero_shot={".": 0.95, "transfer-seed1000": 1.0})
    assert [row["steps_to_90"] for row in evidence["per_seed"]["transfer"]] == [0, 0]
    assert evidence["steps_to_90"] == {"transfer": 0, "scratch": 128}
    assert read_manifest(tmp_path / "run/stages/1-three/policy.zip")["transfer"]["steps_to_90"]["transfer"] == 0


def test_a_seed_that_never_reaches_90_percent_leaves_its_arm_without_a_figure(tmp_path, untrained_policy):
    curves = {".": REACHES_AT_128, "transfer-seed1000": [(64, TARGET), (128, 1.0)], "scratch-seed0": REACHES_AT_128,
              "scratch-seed1000": NEVER}
    evidence = _gather(tmp_path, untrained_policy, curves, zero_shot={".": 0.5, "transfer-seed1000": 0.5})
    assert [row["steps_to_90"] for row in evidence["per_seed"]["scratch"]] == [128, None]
    assert evidence["steps_to_90"] == {"transfer": 96, "scratch": None}  # transfer: the mean of 128 and 64
    report = (tmp_path / "run/report.md").read_text()
    assert "| from scratch |" in report and "not in every seed (128, never)" in report


@pytest.mark.parametrize("zero_shot", [0.3, TARGET])
def test_a_zero_shot_success_of_exactly_90_percent_counts_as_reached(tmp_path, untrained_policy, zero_shot):
    curves = {".": NEVER, "transfer-seed1000": NEVER, "scratch-seed0": NEVER, "scratch-seed1000": NEVER}
    evidence = _gather(tmp_path, untrained_policy, curves, zero_shot={".": zero_shot, "transfer-seed1000": zero_shot})
    assert evidence["steps_to_90"]["transfer"] == (0 if zero_shot >= TARGET else None)
