"""The run's report.md and learning-curve PNG, written from state.json and eval.csv."""

from __future__ import annotations

from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from common.atomic import atomic_write_all
from common.curriculum.machine import describe
from common.curriculum.schema import CurriculumConfig


def learning_curve(rows: list[dict], path: Path) -> Path:
    """Validation success rate and SPL against timesteps, one line per stage, from eval.csv's
    ``rows`` (as :meth:`~common.curriculum.run_directory.EvalLog.rows` checks them)."""
    figure = Figure(figsize=(8, 4), dpi=100)
    FigureCanvasAgg(figure)
    ax = figure.add_subplot(1, 1, 1)
    offset = 0
    for stage in dict.fromkeys(r["stage"] for r in rows):
        own = [r for r in rows if r["stage"] == stage]
        steps = [offset + int(r["timesteps"]) for r in own]
        ax.plot(steps, [float(r["success_rate"]) for r in own], marker="o", label=f"{stage} success")
        ax.plot(steps, [float(r["spl"]) for r in own], linestyle="--", label=f"{stage} SPL")
        offset = steps[-1] if steps else offset
    ax.set_xlabel("timesteps (stages end to end)")
    ax.set_ylim(0, 1.02)
    ax.set_ylabel("validation rate")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # beside the axes: over them it hid points
    figure.tight_layout()
    figure.savefig(path, format="png")  # the format said: a temporary file's name does not end in .png
    return path


def write_report(out: Path, config: CurriculumConfig, state: dict, run: dict, rows: list[dict]) -> Path:
    """report.md: per stage, training figures and the final (test-draw) evaluation; ``run``: the
    run's run.json, ``rows``: its eval.csv, both as the runner checked them."""
    lines = [f"# {config.name}", "",
             f"seed {config.seed}, device {run['device']}, package {run['package_version']}, commit {run['git_commit']}"
             + (f", on {on}" if (on := describe(run.get("machine"))) else ""), "",
             "| stage | algorithm | observation | timesteps | wall time s | training env steps/s | promoted | test success (95% CI) | collision | timeout | stuck | SPL | steps (successes) | episodes |",
             "|---|---|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|"]
    for index, stage in enumerate(config.stages):
        result = state["stages"].get(stage.name)
        if result is None:
            continue
        final = result["final"]
        lo, hi = final["success_ci95"]
        steps = "–" if final["mean_steps"] is None else f"{final['mean_steps']:.0f}"
        lines.append(
            f"| {stage.name} | {stage.algorithm} | {stage.observation} | {result['timesteps']:,} | {result['wall_seconds']:.0f} | "
            f"{result['steps_per_second']:.0f} | {'yes' if result['promoted'] else 'no'} | {final['success_rate']:.1%} ({lo:.1%}–{hi:.1%}) | "
            f"{final['collision_rate']:.1%} | {final['timeout_rate']:.1%} | {final['stuck_rate']:.1%} | {final['spl']:.3f} | {steps} | {final['episodes']} |")
    lines += ["", "Test success: the stage's policy (its best validation checkpoint) on a held-out draw of its eval "
              "suite that never chose a checkpoint. Wall time: training and periodic evaluations, not the final "
              "evaluation; training env steps/s excludes the evaluations.", "",
              "![learning curve](learning_curve.png)", ""]
    path = out / "report.md"
    # One set, each file whole: a kill while they are written (a resume rewrites them) leaves the last ones.
    atomic_write_all({out / "learning_curve.png": lambda tmp: learning_curve(rows, tmp),
                      path: lambda tmp: tmp.write_text("\n".join(lines))})
    return path
