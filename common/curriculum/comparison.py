"""Comparison tables as Markdown, CSV and a PNG bar chart."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from common.evaluation import OUTCOMES, Summary, episodes_as_dicts
from common.statistics import mcnemar, p_value_text

_COLOURS = {"success": "tab:green", "collision": "tab:red", "timeout": "tab:orange", "stuck": "tab:gray"}


def _pm(mean: float | None, std: float | None, digits: int = 1) -> str:
    return "–" if mean is None else f"{mean:.{digits}f} ± {std:.{digits}f}"


def markdown_table(summaries: Sequence[Summary], title: str | None = None) -> str:
    """One row per agent: rates (success with its 95% interval), SPL, steps and path length; among
    movers also the social figures (collisions with movers, and who moved into whom; the closest
    gap to a person, mean and least; seconds within 0.5 m of one)."""
    social = any(s.social is not None for s in summaries)
    lines = [f"### {title}", ""] if title else []
    lines += [
        "| agent | episodes | success (95% CI) | collision | timeout | stuck | SPL | steps (successes) | path m (successes) |"
        + (" mover collisions (robot into / into robot) | closest to a person m (mean, least) | s within 0.5 m |"
           if social else ""),
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|" + ("---:|---:|---:|" if social else ""),
    ]
    for s in summaries:
        lo, hi = s.success_ci95
        line = (
            f"| {s.agent} | {s.episodes} | {s.success_rate:.0%} ({lo:.0%}–{hi:.0%}) | {s.collision_rate:.0%} | "
            f"{s.timeout_rate:.0%} | {s.stuck_rate:.0%} | {s.spl:.2f} | {_pm(s.mean_steps, s.std_steps, 0)} | "
            f"{_pm(s.mean_path_length, s.std_path_length, 2)} |"
        )
        if social:
            line += _social_cells(s.social)
        lines.append(line)
    return "\n".join(lines) + "\n"


def paired_table(summaries: Sequence[Summary]) -> str:
    """Each agent against the one that arrived most often (the first of equals), episode by episode
    on the same episodes: those only it arrived in, those only the best did, and McNemar's exact
    p-value (:func:`common.statistics.mcnemar`). Empty for fewer than two agents."""
    if len(summaries) < 2:
        return ""
    best = max(summaries, key=lambda s: s.success_rate)
    lines = [f"Paired with `{best.agent}`, the agent that arrived most often, on the same episodes:", "",
             f"| agent | arrived where `{best.agent}` did not | `{best.agent}` arrived where it did not | McNemar p |",
             "|---|---:|---:|---:|"]
    for s in summaries:
        if s is not best:
            only_it, only_best, p = mcnemar(s.arrivals(), best.arrivals())
            lines.append(f"| {s.agent} | {only_it} | {only_best} | {p_value_text(p)} |")
    return "\n".join(lines) + "\n"


def _social_cells(figures: dict | None) -> str:
    if figures is None:
        return " – | – | – |"
    gap = ("–" if figures["mean_min_person_gap"] is None
           else f"{figures['mean_min_person_gap']:.2f}, {figures['min_person_gap']:.2f}")
    return (f" {figures['collision_mover_rate']:.0%} ({figures['collision_robot_into_mover_rate']:.0%} / "
            f"{figures['collision_mover_into_robot_rate']:.0%}) | {gap} | {figures['mean_time_near_people']:.1f} |")


def write_csv(summaries: Sequence[Summary], path: str | Path) -> Path:
    """Every episode as a CSV row (agent, scenario, seed, outcome, steps, lengths, SPL, wall time)."""
    path = Path(path)
    rows = episodes_as_dicts(summaries)
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]) if rows else ["agent"], lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    return path


def bar_chart(summaries: Sequence[Summary], path: str | Path, title: str = "") -> Path:
    """Stacked outcome shares per agent, with SPL marked."""
    figure = Figure(figsize=(max(4.0, 1.2 * len(summaries) + 2), 4.0), dpi=100)
    FigureCanvasAgg(figure)
    ax = figure.add_subplot(1, 1, 1)
    x = np.arange(len(summaries))
    bottom = np.zeros(len(summaries))
    for outcome in OUTCOMES:
        share = np.array([getattr(s, f"{outcome}_rate") for s in summaries])
        ax.bar(x, share, bottom=bottom, color=_COLOURS[outcome], label=outcome, width=0.6)
        bottom += share
    ax.plot(x, [s.spl for s in summaries], "k_", markersize=22, markeredgewidth=2, label="SPL")
    ax.set_xticks(x, [s.agent for s in summaries], rotation=20, ha="right")
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("share of episodes")
    ax.set_title(title)
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    figure.tight_layout()
    figure.savefig(path, format="png")  # the format said: a temporary file's name does not end in .png
    return Path(path)
