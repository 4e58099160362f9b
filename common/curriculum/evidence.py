"""The evidence for a transfer, written by the run: is starting from the previous stage's policy
better than starting from nothing, and by how much?

A curriculum with ``evidence: {seeds: N, scratch: true}`` has a last stage that starts from the
previous stage's policy (``init_from: previous``; typically a 2D stage, then a 3D one). After the
curriculum's own run, the runner runs the other arms, each an ordinary run directory under
``OUT/evidence/``:

* ``transfer-seedS``: the whole curriculum again with seed S (the curriculum's own run is the first
  seed), for N seeds in all;
* ``scratch-seedS``: the last stage alone, without ``init_from``, with the same stage seed, budget,
  conditions and evaluation draws.

It then measures, per seed, the previous stage's policy on the last stage's test draw before any
step of it (*zero-shot*), the last stage's policy after it (*fine-tuned*) and the scratch arm's
(*from scratch*), and the last stage's steps to a 90 % validation success in either arm, and
writes them to ``state.json`` (``transfer``), ``report.md``, ``transfer.png`` and the final
policy's manifest (``transfer``). Arm seeds are ``seed + 1000·k``, so no two runs share a stage
seed; every arm meets the same validation and test scenarios.
"""

from __future__ import annotations

import csv
import json
import statistics
from pathlib import Path
from typing import Any, Protocol

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from common.atomic import atomic_write_all
from common.curriculum.policy_file import update_manifest
from common.curriculum.run_directory import StagePaths
from common.curriculum.schema import CurriculumConfig, StageSpec
from common.evaluation import Summary


class EvidenceHost(Protocol):
    """What gathering evidence needs of the run whose last stage it judges (a
    :class:`~common.curriculum.runner.Runner`)."""

    config: CurriculumConfig
    out: Path

    def arm(self, config: CurriculumConfig, out: Path, resume: bool) -> "EvidenceHost": ...

    def run(self) -> dict: ...

    def evaluate_policy(self, stage: StageSpec, policy: Path, test: bool = True) -> Summary: ...

SEED_STRIDE = 1000
TARGET = 0.9  # validation success whose first crossing counts as "reached"


def arm_configs(config: CurriculumConfig) -> dict[str, CurriculumConfig]:
    """The further runs of the evidence, by directory name (the curriculum's own run is not among them)."""
    spec = config.evidence
    last = len(config.stages) - 1
    arms: dict[str, CurriculumConfig] = {}
    for k in range(spec.seeds):
        seed = config.seed + SEED_STRIDE * k
        if k > 0:
            arms[f"transfer-seed{seed}"] = config.model_copy(update={"seed": seed, "evidence": None,
                                                                     "name": f"{config.name}-transfer-seed{seed}"})
        if spec.scratch:
            stage = config.stages[last].model_copy(update={"init_from": None})
            # Seeded so the stage trains with the same seed as the transfer arm's last stage.
            arms[f"scratch-seed{seed}"] = config.model_copy(update={"seed": seed + last, "stages": [stage], "evidence": None,
                                                                    "name": f"{config.name}-scratch-seed{seed}"})
    return arms


def _curve(run: Path, stage: str) -> list[tuple[int, float]]:
    with (run / "eval.csv").open(newline="") as handle:
        return [(int(r["timesteps"]), float(r["success_rate"])) for r in csv.DictReader(handle) if r["stage"] == stage]


def steps_to(curve: list[tuple[int, float]], target: float = TARGET) -> int | None:
    """The first evaluated step count whose validation success reaches ``target`` (None: never)."""
    return next((steps for steps, success in curve if success >= target), None)


def _mean(values: list[float]) -> float:
    return statistics.fmean(values)


def _spread(values: list[float]) -> float:
    return statistics.pstdev(values) if len(values) > 1 else 0.0


def gather_evidence(runner: EvidenceHost, state: dict) -> dict[str, Any]:
    """Run the missing arms (resuming any that were interrupted) and write the evidence."""
    config, out = runner.config, runner.out
    last, previous = config.stages[-1], config.stages[-2]
    runs = {"transfer": [(config.seed, out)], "scratch": []}
    for name, arm in arm_configs(config).items():
        directory = out / "evidence" / name
        resume = (directory / "state.json").exists()
        runner.arm(arm, directory, resume).run()
        runs["scratch" if name.startswith("scratch") else "transfer"].append((arm.seed, directory))
    per_seed: dict[str, list[dict[str, Any]]] = {"transfer": [], "scratch": []}
    for arm, members in runs.items():
        for seed, run in members:
            index = len(config.stages) - 1 if arm == "transfer" else 0  # a scratch run has the last stage alone
            final = json.loads((run / "stages" / f"{index}-{last.name}" / "final_eval.json").read_text())
            curve = _curve(run, last.name)
            row = {"seed": seed, "run": str(run.relative_to(out)) if run != out else ".",
                   "test_success": final["success_rate"], "steps_to_90": steps_to(curve), "curve": curve,
                   "wall_seconds": json.loads((run / "state.json").read_text())["stages"][last.name]["wall_seconds"]}
            if arm == "transfer":
                before = StagePaths.of(run, len(config.stages) - 2, previous.name).policy
                row["zero_shot_test"] = runner.evaluate_policy(last, before).success_rate
                row["zero_shot_validation"] = runner.evaluate_policy(last, before, test=False).success_rate
                row["curve"] = [(0, row["zero_shot_validation"]), *curve]
                row["steps_to_90"] = steps_to(row["curve"])
            per_seed[arm].append(row)
    evidence = _summary(per_seed, last.budget)
    report = out / "report.md"
    text = (report.read_text() if report.exists() else "") + _report_section(evidence, per_seed, last.name)
    # Written as one set (a kill leaves the run's own report whole): a resume writes them again.
    atomic_write_all({out / "transfer.png": lambda tmp: _figure(per_seed, tmp, last.name),
                      report: lambda tmp: tmp.write_text(text)})
    policy = out / state["stages"][last.name]["policy"]
    update_manifest(policy, {"transfer": {k: v for k, v in evidence.items() if k != "per_seed"}})
    return evidence


def _reached(rows: list[dict[str, Any]]) -> int | None:
    steps = [row["steps_to_90"] for row in rows]
    return round(_mean(steps)) if steps and None not in steps else None


def _summary(per_seed: dict[str, list[dict[str, Any]]], budget: int) -> dict[str, Any]:
    transfer, scratch = per_seed["transfer"], per_seed["scratch"]
    out: dict[str, Any] = {
        "seeds": len(transfer),
        "budget": budget,
        "zero_shot_success": _mean([r["zero_shot_test"] for r in transfer]),
        "zero_shot_success_std": _spread([r["zero_shot_test"] for r in transfer]),
        "fine_tuned_success": _mean([r["test_success"] for r in transfer]),
        "fine_tuned_success_std": _spread([r["test_success"] for r in transfer]),
        "steps_to_90": {"transfer": _reached(transfer), "scratch": _reached(scratch) if scratch else None},
        "per_seed": {arm: [{k: v for k, v in r.items() if k != "curve"} for r in rows] for arm, rows in per_seed.items()},
    }
    if scratch:
        out["scratch_success"] = _mean([r["test_success"] for r in scratch])
        out["scratch_success_std"] = _spread([r["test_success"] for r in scratch])
    return out


def _figure(per_seed: dict[str, list[dict[str, Any]]], path: Path, stage: str) -> Path:
    """Validation success against the last stage's steps: each arm's mean over seeds and its range."""
    figure = Figure(figsize=(7, 4), dpi=100)
    FigureCanvasAgg(figure)
    ax = figure.add_subplot(1, 1, 1)
    for arm, colour in (("transfer", "tab:blue"), ("scratch", "tab:orange")):
        curves = [dict(r["curve"]) for r in per_seed[arm]]
        if not curves:
            continue
        steps = sorted(set.intersection(*(set(c) for c in curves)))
        values = [[c[s] for c in curves] for s in steps]
        ax.plot(steps, [_mean(v) for v in values], color=colour, marker="o", label=f"{arm} (mean of {len(curves)} seeds)")
        ax.fill_between(steps, [min(v) for v in values], [max(v) for v in values], color=colour, alpha=0.2)
    ax.axhline(TARGET, color="0.5", linestyle=":", linewidth=1)
    ax.set_xlabel(f"{stage} env steps")
    ax.set_ylabel("validation success")
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title("transfer against training from scratch (band: range over seeds)", fontsize=9)
    figure.tight_layout()
    figure.savefig(path, format="png")  # the format said: a temporary file's name does not end in .png
    return path


def _percent(rows: list[dict[str, Any]], key: str) -> str:
    values = [r[key] for r in rows]
    each = ", ".join(f"{v:.1%}" for v in values)
    return f"{_mean(values):.1%} ± {_spread(values):.1%} ({each})"


def _steps(rows: list[dict[str, Any]]) -> str:
    each = ", ".join("never" if r["steps_to_90"] is None else f"{r['steps_to_90']:,}" for r in rows)
    reached = _reached(rows)
    if reached is None:
        label = "never" if all(r["steps_to_90"] is None for r in rows) else "not in every seed"
    else:
        label = f"{reached:,} (mean)"
    return f"{label} ({each})"


def _report_section(evidence: dict[str, Any], per_seed: dict[str, list[dict[str, Any]]], stage: str) -> str:
    """The transfer evidence's section of report.md."""
    transfer, scratch = per_seed["transfer"], per_seed["scratch"]
    lines = ["", f"## Transfer: `{stage}` from the previous stage's policy, against from scratch", "",
             f"{evidence['seeds']} seeds per arm, {evidence['budget']:,} `{stage}` steps each, the same validation "
             "and test draws. Test success on the stage's test draw (mean ± std over seeds, then each seed); steps to "
             f"{TARGET:.0%} validation success (0: the previous stage's policy already reached it).", "",
             "| arm | test success | steps to 90% validation | wall time s (each seed) |", "|---|---:|---:|---:|",
             f"| zero-shot (before any `{stage}` step) | {_percent(transfer, 'zero_shot_test')} | – | – |",
             f"| fine-tuned | {_percent(transfer, 'test_success')} | {_steps(transfer)} | "
             f"{', '.join(str(round(r['wall_seconds'])) for r in transfer)} |"]
    if scratch:
        lines.append(f"| from scratch | {_percent(scratch, 'test_success')} | {_steps(scratch)} | "
                     f"{', '.join(str(round(r['wall_seconds'])) for r in scratch)} |")
    lines += ["", "![transfer against scratch](transfer.png)", ""]
    return "\n".join(lines)
