"""The controller-comparison tables CI prints, with floors that catch a regressing baseline.

Floors were set from measurement (20 episodes per suite, seed 0; see docs/controllers.md) with
room for one or two unlucky episodes. The potential field's trap ceiling is the tutorial's lesson:
if it starts escaping traps, the trap generator stopped making traps.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from common.controllers import CONTROLLERS, make_controller
from common.evaluation import evaluate
from common.generators import get_suite
from common.curriculum.comparison import markdown_table

EPISODES = 20
FLOORS = {  # (suite, controller): minimum success rate
    ("sparse", "reactive"): 0.85, ("sparse", "pid_blend"): 0.85, ("sparse", "potential_field"): 0.75,
    ("sparse", "astar_pursuit"): 0.9, ("sparse", "rrt_pursuit"): 0.9,
    ("cluttered", "reactive"): 0.85, ("cluttered", "pid_blend"): 0.7, ("cluttered", "potential_field"): 0.6,
    ("cluttered", "astar_pursuit"): 0.9, ("cluttered", "rrt_pursuit"): 0.9,
    ("trap", "astar_pursuit"): 0.9, ("trap", "rrt_pursuit"): 0.9,
}
CEILINGS = {("trap", "potential_field"): 0.1, ("trap", "go_to_goal"): 0.1, ("cluttered", "go_to_goal"): 0.2}


SUITES = ["sparse", "cluttered", "trap"]


@pytest.mark.slow
@pytest.mark.parametrize("suite", SUITES)
def test_controller_comparison_meets_its_floors(suite):
    agents = [make_controller(name) for name in CONTROLLERS]
    summaries = evaluate(agents, get_suite(suite).scenarios(count=EPISODES), "flatland", seed=0)
    folder = os.environ.get("NAV_TEST_TABLES_DIR")
    if folder:  # printed at the end of the run by conftest.py
        table = markdown_table(summaries, f"flatland / {suite}: {EPISODES} episodes, seed 0")
        (Path(folder) / f"{SUITES.index(suite)}-{suite}.md").write_text(table)
    rates = {s.agent: s.success_rate for s in summaries}
    low = {a: r for (s, a), floor in FLOORS.items() if s == suite and (r := rates[a]) < floor}
    high = {a: r for (s, a), ceiling in CEILINGS.items() if s == suite and (r := rates[a]) > ceiling}
    assert not low, f"{suite}: below their floors: {low}"
    assert not high, f"{suite}: above their ceilings (the scenario no longer tests what it should): {high}"
