"""Does a policy drive IR-SIM as it drives flatland? Each shipped 2D policy on the same held-out
episodes in both worlds, under the same conditions (the policy's own, less the knobs IR-SIM
cannot model), judged within its trained radius; success with Wilson intervals, and the
episodes whose outcomes differ.

    python -m common.curriculum.irsim_agreement [--episodes 200] [--suites sparse,cluttered] [--policy ZIP ...] [--jobs N]

``--suites`` takes any suite, and ``crowd_sfm`` and ``crowd_orca``: the crowd suite's people under
the social force (seeing the robot) or ORCA (blind to it), each on a fixed route (:func:`common.irsim_export.fixed_routes`). Its people move by the same
model in both, but each simulator draws their randomness from its own generator (an episode's
crowd in flatland is seeded by the episode, IR-SIM's by ``irsim.make``), so crowd rows compare
the two success rates, not episode by episode.

prints a Markdown table (docs/deploy.md#policies-in-ir-sim-itself quotes it).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections import Counter
from pathlib import Path
from typing import Any, Sequence

from common.conditions import Conditions, conditions_of
from common.curriculum.cli import whole_number
from common.curriculum.policy import load_policy
from common.evaluation import Summary, episode_limit, evaluate
from common.generators import Suite, get_suite
from common.irsim_export import fixed_routes
from common.statistics import mcnemar, p_value_text
from common.task import judged_radius

SHIPPED = Path(__file__).resolve().parents[2] / "curricula" / "policies"
SHIPPED_2D = ("stage1_2d_ppo", "stage1_2d_sac", "stage1_2d_td3", "curriculum_2d_ppo", "curriculum_2d_sac",
              "curriculum_2d_sac_36beams", "cluttered_2d_sac", "moving_2d_sac")


# The crowd both simulators move alike: people under the social force (IR-SIM's group sees the
# robot as the suite's people do), each walking back and forth on its own route.
# ORCA people do not see the robot there: IR-SIM's ORCA sees only the agents it moves.
CROWDS = {"crowd_sfm": Suite(name="crowd_sfm", kind="crowd", options=(("reacting", True), ("behavior", "sfm"))),
          "crowd_orca": Suite(name="crowd_orca", kind="crowd", options=(("reacting", False), ("behavior", "orca")))}


def _scenarios(suite: str, count: int, seed: int):
    if suite in CROWDS:
        return (fixed_routes(scenario) for scenario in CROWDS[suite].scenarios(count=count, seed=seed))
    return get_suite(suite).scenarios(count=count, seed=seed)


def compare_worlds(policy_path: str | Path, suite: str, episodes: int, seed: int = 0, jobs: int = 1) -> dict[str, Any]:
    """The policy's summaries in flatland and in IR-SIM on the suite's first ``episodes`` held-out
    scenarios (in ``jobs`` processes: :func:`common.evaluation.evaluate`), and where each episode
    whose outcome differs parts (:func:`first_difference`)."""
    agent = load_policy(policy_path)
    # The knobs IR-SIM cannot model (delays, wheel dynamics) are dropped for both worlds alike.
    shared = Conditions.parse(conditions_of(agent.trained_conditions).for_tier("irsim", strict=False).given())
    scenarios = list(_scenarios(suite, episodes, seed))
    radius = judged_radius(agent.env_kwargs)
    result: dict[str, Any] = {world: evaluate([agent], scenarios, world, seed=seed, conditions=shared,
                                              goal_radius=radius, jobs=jobs)[0] for world in ("flatland", "irsim")}
    pairs = zip(scenarios, result["flatland"].rows, result["irsim"].rows)
    result["differences"] = Counter(
        first_difference(policy_path, scenario, seed + i, shared, radius, episode_limit(agent, None))
        for i, (scenario, ours, theirs) in enumerate(pairs) if ours.outcome != theirs.outcome)
    return result


def first_difference(policy_path: str | Path, scenario, seed: int, conditions: Conditions, radius: float | None,
                     max_steps: int) -> str:
    """Where an episode's two runs part, driven in lockstep: ``graze`` (flatland's swept move
    touches something inside a step whose end pose, where IR-SIM checks, is clear), ``contact``
    (the worlds disagree on a contact otherwise), ``drift`` (the poses part by 1 mm before any
    contact differs: sensing or arithmetic), or ``none``."""
    from common.evaluation import start_agent
    from common.kinematics import Pose2D
    from common.task import Task
    from common.tiers import make_world

    worlds = [make_world(world, scenario, seed=seed, conditions=conditions) for world in ("flatland", "irsim")]
    agents = [load_policy(policy_path) for _ in worlds]
    task = Task(radius, max_steps)
    readings = [world.reset(seed=seed) for world in worlds]
    task.start(worlds[0].scenario, readings[0])
    for agent, world in zip(agents, worlds):
        start_agent(agent, world.scenario, task.radius)
    try:
        for _ in range(max_steps):
            readings = [world.step(*agent.act(r, scenario.goal)) for agent, world, r in zip(agents, worlds, readings)]
            flat, irsim = readings
            if flat.collided != irsim.collided:
                clear = flat.collided and not worlds[0].overlaps(Pose2D(*irsim.pose))
                return "graze" if clear else "contact"
            if math.dist(flat.pose[:2], irsim.pose[:2]) > 1e-3:
                return "drift"
            if task.step(flat) is not None:
                return "none"
        return "none"
    finally:
        worlds[1].close()


def _paired(flat: Summary, irsim: Summary) -> str:
    """Episodes that arrived in one world only, each way, and the exact McNemar test's p-value:
    whether one world lets the policy arrive more often than chance flips would."""
    only_flat, only_irsim, p = mcnemar(flat.arrivals(), irsim.arrivals())
    return f"{only_flat} / {only_irsim} ({p_value_text(p)})"


def _rate(summary: Summary) -> str:
    low, high = summary.success_ci95
    return f"{100 * summary.success_rate:.1f}% ({100 * low:.1f}–{100 * high:.1f})"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m common.curriculum.irsim_agreement", description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--suites", default="sparse,cluttered", help="comma-separated suites, or crowd_sfm, crowd_orca")
    parser.add_argument("--policy", nargs="*", metavar="ZIP", help="default: the shipped 2D policies")
    parser.add_argument("--jobs", type=whole_number(1, 1024), default=1, help="worker processes for the episodes (the same figures)")
    args = parser.parse_args(argv)
    policies = args.policy or [str(SHIPPED / f"{name}.zip") for name in SHIPPED_2D]
    print("| policy | suite | flatland success (95% CI) | IR-SIM success (95% CI) | difference, points "
          "| arrived in one world only: flatland / IR-SIM (McNemar p) | episodes with another outcome, by where they part |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for path in policies:
        for suite in args.suites.split(","):
            result = compare_worlds(path, suite, args.episodes, jobs=args.jobs)
            flat, irsim = result["flatland"], result["irsim"]
            differ = result["differences"]
            parts = ", ".join(f"{count} {kind}" for kind, count in sorted(differ.items())) or "0"
            print(f"| {Path(path).stem} | {suite} | {_rate(flat)} | {_rate(irsim)} | "
                  f"{100 * (irsim.success_rate - flat.success_rate):+.1f} | {_paired(flat, irsim)} | {parts} |",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
