"""The policies the repository ships: each opens as data, says what it is, and still drives."""

from pathlib import Path

import pytest

from common.conditions import conditions_of
from common.curriculum.policy import load_policy
from common.curriculum.policy_file import read_manifest
from common.evaluation import evaluate
from common.generators import get_suite

POLICIES = Path(__file__).resolve().parents[1] / "curricula" / "policies"
SHIPPED = sorted(POLICIES.glob("*.zip"))


def test_the_readme_policies_are_shipped():
    assert {p.name for p in SHIPPED} >= {"stage1_2d_ppo.zip", "stage1_2d_sac.zip", "stage1_2d_td3.zip",
                                         "curriculum_2d_ppo.zip", "curriculum_2d_sac.zip", "cluttered_2d_sac.zip",
                                         "curriculum_2d_sac_36beams.zip", "transfer_3d_ppo.zip", "moving_2d_sac.zip",
                                         "transfer_moving_3d_ppo.zip"}


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_a_shipped_policy_opens_as_data_and_names_its_training(path):
    manifest = read_manifest(path)
    assert manifest["format"] == 2
    assert manifest["algorithm"] in {"ppo", "sac", "td3"}
    assert manifest["final_eval"]["episodes"] >= 200
    load_policy(path)


@pytest.mark.parametrize("name", ["transfer_3d_ppo", "transfer_moving_3d_ppo"])
def test_a_transfer_policy_carries_its_evidence(name):
    manifest = read_manifest(POLICIES / f"{name}.zip")
    assert manifest["tier"] == "physics3d" and manifest["robot"]["v_max"] == 0.5
    evidence = manifest["transfer"]
    assert evidence["seeds"] >= 3
    for key in ("zero_shot_success", "fine_tuned_success", "scratch_success"):
        assert 0.0 <= evidence[key] <= 1.0
    assert set(evidence["steps_to_90"]) == {"transfer", "scratch"}


def _arrivals_within_a_tenth_of_a_metre(name: str, suite: str, tier: str = "flatland", count: int = 10) -> float:
    """Success of a shipped policy on ``count`` held-out episodes of ``suite``, judged within 0.1 m
    and driven as it was trained (its lidar, noise and actuation: the conditions it names). A
    policy can score as well without them (the 180-beam moving policy arrives 8 times in 10 on
    the suite's 36 beams), so the lidar its episodes bound it to is checked against its manifest."""
    agent = load_policy(POLICIES / f"{name}.zip")
    beams = set()
    bind = agent.bind

    def bind_recording(robot, lidar, *arguments):
        beams.add(lidar.beams)
        bind(robot, lidar, *arguments)

    agent.bind = bind_recording
    worlds = list(get_suite(suite).scenarios(count=count, seed=100_000))
    (summary,) = evaluate([agent], worlds, tier=tier, conditions=conditions_of(agent.env_kwargs), goal_radius=0.1,
                          seed=100_000)
    trained = read_manifest(POLICIES / f"{name}.zip").get("env_kwargs") or {}
    assert beams == {trained.get("lidar_beams", worlds[0].lidar.beams)}, f"{name} drove with {beams} beams"
    return summary.success_rate


@pytest.mark.parametrize("name", ["stage1_2d_ppo", "stage1_2d_sac", "stage1_2d_td3"])
def test_a_shipped_sparse_policy_still_arrives_within_a_tenth_of_a_metre(name):
    # IR-SIM's default radius, the tightest the policies promise: their figures there are
    # 97.0-98.5%, so 8 of 10 fails only when the observation, the action mapping or the weights no
    # longer reach the policy as trained.
    assert _arrivals_within_a_tenth_of_a_metre(name, "sparse") >= 0.8


@pytest.mark.parametrize("name", ["curriculum_2d_ppo", "curriculum_2d_sac", "curriculum_2d_sac_36beams",
                                  "cluttered_2d_sac"])
def test_a_shipped_clutter_policy_arrives_within_a_tenth_of_a_metre_among_clutter(name):
    # Their test figures there are 92.5%, 95.5% (on 180 beams), 96.0% and 96.0% of 200 (trained at
    # 0.1 m); the PPO policy curriculum_2d_ppo replaced scores 6 of 10.
    assert _arrivals_within_a_tenth_of_a_metre(name, "cluttered") >= 0.8


@pytest.mark.parametrize(("name", "tier", "suite", "count"), [("moving_2d_sac", "flatland", "crowd", 10),
                                                            ("transfer_moving_3d_ppo", "physics3d", "warehouse_moving", 5)])
def test_a_shipped_moving_policy_still_arrives_among_movers(name, tier, suite, count):
    # Their test figures: 98.5% of 200 crowds in flatland, 96.5% of 200 moving warehouses in
    # PyBullet; judged as trained (within 0.1 m, their lidar of 180 beams and actuation delay).
    assert _arrivals_within_a_tenth_of_a_metre(name, suite, tier, count) >= 0.8
