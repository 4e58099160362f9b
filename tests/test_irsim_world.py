"""IR-SIM itself as a world (``--world irsim``): a scenario of each kind moves and senses in
IR-SIM as in flatland (the lidar sees the crowd's people where flatland's sees them), the evaluator and the CLI run agents in it, and what IR-SIM cannot model
is refused in one line."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from common.conditions import Conditions
from common.errors import ConfigError
from common.generators import KINDS, MOVING_KINDS, generate
from common.irsim_export import fixed_routes, scenario_to_irsim
from common.tiers import make_world
from tests.conftest import optional

ROOT = Path(__file__).resolve().parents[1]
STEPS = 150


def _worlds(kind: str, tmp_path: Path):
    """A held-out scenario of the kind in flatland and in IR-SIM. The moving kinds as IR-SIM can
    move them alike (each person and forklift on a fixed route; the crowd under the social force;
    the warehouse's drivers and people blind to the robot: their own suites hold movers IR-SIM
    cannot express), flatland's side read from the export as ``irsim.make`` reads it, with IR-SIM's
    random draws (``flatland.load_world``)."""
    import flatland

    if kind not in MOVING_KINDS:
        scenario = generate(kind, 3, split="eval")
        return scenario, make_world("flatland", scenario, seed=3), make_world("irsim", scenario, seed=3)
    # IR-SIM's forklifts never yield to the robot: the warehouse's drivers blind to it.
    options = {"behavior": "sfm", "reacting": True} if kind == "crowd" else {"reacting": False}
    scenario = fixed_routes(generate(kind, 3, 0.5, "eval", **options))
    path = tmp_path / f"{kind}.yaml"
    path.write_text(yaml.safe_dump(scenario_to_irsim(scenario)))
    ours = flatland.load_world(path, seed=3)
    return ours.scenario, ours, make_world("irsim", scenario, seed=3)


@pytest.mark.parametrize("kind", KINDS)
def test_a_scenario_of_each_kind_moves_and_senses_in_irsim_as_in_flatland(kind, tmp_path):
    optional("irsim")
    from common.controllers import make_controller

    scenario, ours, theirs = _worlds(kind, tmp_path)
    try:
        controller = make_controller("reactive")
        controller.bind(scenario.robot, scenario.lidar, scenario.goal_threshold)
        controller.reset()
        mine, irsim = ours.reset(seed=3), theirs.reset(seed=3)
        for step in range(STEPS):
            assert math.dist(mine.pose[:2], irsim.pose[:2]) <= 1e-6, f"step {step}"
            assert abs(math.remainder(mine.pose[2] - irsim.pose[2], 2 * math.pi)) <= 1e-6
            assert mine.collided == irsim.collided, f"step {step}"
            close = np.abs(mine.lidar - irsim.lidar) <= 0.02
            assert close.mean() >= 0.95, f"step {step}: {close.mean():.0%} of beams within 2 cm"
            assert irsim.odometry.v == pytest.approx(mine.odometry.v, abs=1e-9)
            if mine.collided or math.dist(mine.pose[:2], scenario.goal) < scenario.goal_threshold:
                break
            command = controller.act(mine, scenario.goal)
            mine, irsim = ours.step(*command), theirs.step(*command)
        assert step > 10  # the robot drove before the episode ended
    finally:
        theirs.close()


def test_a_policy_scores_alike_in_both_worlds_through_the_cli(capsys):
    optional("irsim")
    from common.curriculum.cli import main

    policy = str(ROOT / "curricula" / "policies" / "stage1_2d_ppo.zip")
    scores = {}
    for world in ("flatland", "irsim"):
        capsys.readouterr()
        assert main(["eval", "--policy", policy, "--world", world, "--suite", "cluttered", "--episodes", "4",
                     "--json"]) == 0
        scores[world] = json.loads(capsys.readouterr().out)
    assert scores["irsim"]["episodes"] == 4
    assert scores["irsim"]["success_rate"] == scores["flatland"]["success_rate"]
    assert scores["irsim"]["mean_steps"] == pytest.approx(scores["flatland"]["mean_steps"], abs=3)


def test_what_irsim_cannot_model_is_refused_in_one_line(capsys, monkeypatch):
    optional("irsim")
    from common.curriculum import irsim_world
    from common.curriculum.cli import main

    with pytest.raises(ConfigError, match="action_delay: not an irsim knob"):
        Conditions(action_delay=2).for_tier("irsim")
    assert main(["compare", "--world", "irsim", "--controllers", "reactive", "--episodes", "1",
                 "--env-kwargs", "dynamics:first_order"]) == 2
    assert "--env-kwargs.dynamics: not an irsim knob" in capsys.readouterr().err
    with pytest.raises(ConfigError, match="IR-SIM's ORCA group sees only its members"):
        make_world("irsim", generate("crowd", 0, split="eval"))
    monkeypatch.setattr(irsim_world, "import_irsim", lambda: None)
    with pytest.raises(ConfigError, match=r"--world: irsim needs IR-SIM: pip install 'nav-curriculum\[irsim\]'"):
        make_world("irsim", generate("sparse", 0))


def test_an_irsim_world_file_runs_in_irsim_through_the_cli(capsys, tmp_path):
    """IR-SIM's own social-force crowd, read and written back, the robot driven by a controller."""
    optional("irsim")
    from common.curriculum.cli import main

    world = ROOT.parent / "shared" / "irsim_usage" / "23sfm_world" / "sfm_world.yaml"
    if not world.exists():
        pytest.skip("IR-SIM's usage worlds are not beside this checkout")
    assert main(["compare", "--world", "irsim", "--scenario-file", str(world), "--controllers", "dwa",
                 "--episodes", "1", "--json", "--out", str(tmp_path)]) == 0
    assert json.loads(capsys.readouterr().out)["dwa"]["episodes"] == 1


@pytest.mark.slow
def test_the_agreement_table_pairs_the_episodes_of_both_worlds(capsys):
    optional("irsim")
    from common.curriculum.irsim_agreement import _paired, main
    from common.evaluation import Episode, summarise

    def summary(outcomes: str):
        return summarise("p", [Episode("p", f"s{i}", i, "success" if c == "s" else "collision", 1, 1.0, 1.0, 1.0, 0.0)
                               for i, c in enumerate(outcomes)])

    # Two arrived only in flatland, six only in IR-SIM: the exact two-sided test of 2 in 8.
    assert _paired(summary("ssssss" + "cccccc" + "ss"), summary("sssscc" + "ssssss" + "ss")) == "2 / 6 (0.29)"
    assert _paired(summary("s" * 10), summary("c" * 10)) == "10 / 0 (< 0.01)"  # p = 2 / 1024, not a rounded 0.00
    policy = str(ROOT / "curricula" / "policies" / "stage1_2d_ppo.zip")
    assert main(["--episodes", "2", "--suites", "sparse", "--policy", policy, "--jobs", "2"]) == 0
    row = capsys.readouterr().out.strip().splitlines()[-1]
    assert row.startswith("| stage1_2d_ppo | sparse | ") and row.count("|") == 8


def test_importing_irsim_prints_nothing():
    """IR-SIM tries the GUI backends on import and prints a line for each that fails headless;
    none of it reaches the user's output (a fresh process: an imported module prints no more)."""
    import os
    import subprocess
    import sys

    optional("irsim")
    result = subprocess.run([sys.executable, "-c", "from common.curriculum.irsim_world import import_irsim; "
                             "assert import_irsim() is not None"], capture_output=True, text=True, cwd=ROOT,
                            env={k: v for k, v in os.environ.items() if k != "DISPLAY"})
    assert result.returncode == 0 and result.stdout == "" and result.stderr == "", result
