"""Movers as IR-SIM moves them, behaviour by behaviour, in small worlds written for the purpose
(IR-SIM's example worlds are walked in tests/test_irsim_usage.py): every mover where IR-SIM has it
at every step, the controlled robot driven with the same commands, contacts and stops alike."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from tests.conftest import optional

os.environ.setdefault("MPLBACKEND", "Agg")
irsim = optional("irsim")

import flatland  # noqa: E402

HEAD = """\
world: {{height: 10, width: 10, step_time: 0.1, collision_mode: {mode}}}
robot:
  - kinematics: {{name: diff}}
    shape: {{name: circle, radius: 0.2}}
    state: [1, 1, 0]
    goal: [9, 9, 0]
    sensors: [{{name: lidar2d, number: 60, range_max: 6, angle_range: 6.283185307179586}}]
"""


def run_both(tmp_path: Path, text: str, steps: int, command=(0.3, 0.2)):
    """Every step's movers (flatland's rows, IR-SIM's states in the same order), robot poses and collision flags."""
    path = tmp_path / "world.yaml"
    path.write_text(text)
    world = flatland.load_world(path)
    env = irsim.make(str(path), display=False, log_level="ERROR")
    moving = [i + 1 for i in world.movers.table.obstacle_index if i >= 0]
    ours, theirs = [], []
    try:
        world.reset()
        for _ in range(steps):
            readings = world.step(*command)
            env.step(list(command))
            ours.append((readings.movers.rows[:, :2].copy(), np.array(readings.pose[:2]), readings.collided))
            theirs.append((np.array([env.objects[j].state[:2, 0] for j in moving]),
                           np.asarray(env.get_robot_state()[:2, 0], dtype=float), bool(env.robot.collision_flag)))
    finally:
        env.end(0)
    return ours, theirs


def assert_alike(ours, theirs, tolerance: float) -> None:
    for k, ((movers, pose, hit), (their_movers, their_pose, their_hit)) in enumerate(zip(ours, theirs)):
        np.testing.assert_allclose(movers, their_movers, rtol=0, atol=tolerance, err_msg=f"movers, step {k}")
        np.testing.assert_allclose(pose, their_pose, rtol=0, atol=1e-3, err_msg=f"robot, step {k}")
        assert hit == their_hit, f"collision flag, step {k}"


def test_a_group_under_the_social_force_moves_as_irsims_batch(tmp_path):
    text = HEAD.format(mode="unobstructed") + """\
  - number: 6
    distribution: {name: circle, radius: 3.5, center: [5, 5]}
    kinematics: {name: omni}
    shape: {name: circle, radius: 0.25}
    vel_max: [1, 1]
    vel_min: [-1, -1]
    goal_threshold: 0.2
    group_behavior: {name: sfm, vmax: 1.0, safety_radius: 0.1}
obstacle:
  - shape: {name: linestring, vertices: [[2, 8.5], [8, 8.5]]}
    state: [0, 0, 0]
"""
    ours, theirs = run_both(tmp_path, text, 300)
    assert_alike(ours, theirs, 1e-3)
    assert np.hypot(*(ours[-1][0] - ours[0][0]).T).min() > 3.0  # every member crossed the circle


def test_omni_agents_avoid_each_other_by_irsims_rvo(tmp_path):
    text = HEAD.format(mode="stop") + """\
obstacle:
  - number: 4
    distribution: {name: circle, radius: 3, center: [5, 5]}
    kinematics: {name: omni}
    shape: {name: circle, radius: 0.3}
    behavior: {name: rvo, vxmax: 1.0, vymax: 1.0, acce: 1.0, factor: 2.0, mode: hrvo}
    vel_max: [1, 1]
    vel_min: [-1, -1]
    goal_threshold: 0.2
"""
    ours, theirs = run_both(tmp_path, text, 200)
    assert_alike(ours, theirs, 1e-6)


def test_an_orca_group_walks_past_a_robot_that_is_not_a_member_as_irsim_s_does(tmp_path):
    """IR-SIM's ORCA (RVO2) plans among the group's members only; read as people who see the
    robot, the pair swerved round it, 0.15 m from IR-SIM's paths by step 30."""
    text = HEAD.format(mode="unobstructed").replace("state: [1, 1, 0]", "state: [3, 5, 0]") + """obstacle:
  - number: 2
    distribution: {name: manual}
    kinematics: {name: omni}
    shape: {name: circle, radius: 0.3}
    state: [[4, 6.5, 0], [4.5, 3.5, 0]]
    goal: [[4, 3.0, 0], [4.5, 7.0, 0]]
    vel_max: [0.6, 0.6]
    vel_min: [-0.6, -0.6]
    group_behavior: {name: orca, neighborDist: 3.0, maxNeighbors: 5, timeHorizon: 3.0, timeHorizonObst: 3.0}
"""
    ours, theirs = run_both(tmp_path, text, 60, command=(0.0, 0.0))
    assert_alike(ours, theirs, 1e-3)


def test_the_robot_halts_on_a_mover_and_goes_on_when_it_has_passed(tmp_path):
    # unobstructed_obstacles: the robot stops while a person crossing its path touches it, the
    # person walks on, and the robot drives on once they no longer touch (IR-SIM judges a stop anew
    # every step). An omni dash mover crossing y = 1 from above.
    text = HEAD.format(mode="unobstructed_obstacles") + """\
obstacle:
  - kinematics: {name: omni}
    shape: {name: circle, radius: 0.3}
    state: [2.2, 4, 0]
    goal: [2.2, -3, 0]
    behavior: {name: dash}
    vel_max: [0.6, 0.6]
    vel_min: [-0.6, -0.6]
"""
    ours, theirs = run_both(tmp_path, text, 80, command=(0.25, 0.0))
    assert_alike(ours, theirs, 1e-6)
    hits = [hit for _, _, hit in ours]
    first, last = hits.index(True), len(hits) - 1 - hits[::-1].index(True)
    assert 0 < first < last < len(hits) - 5
    assert ours[-1][1][0] > ours[last][1][0] + 0.5  # it drove on
