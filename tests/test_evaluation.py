"""Episode outcomes, SPL on toy cases, Wilson intervals, aggregation and report files."""

from __future__ import annotations

import math

import pytest

from common.errors import ConfigError
from common.evaluation import Episode, evaluate, run_episode, shortest_path_length, summarise, wilson_interval
from common.kinematics import wrap_angle
from common.curriculum.comparison import bar_chart, markdown_table, write_csv
from common.scenario import BoxObstacle, CircleObstacle, RobotProfile, Scenario


class Scripted:
    """A toy agent: steer to the goal at a fixed speed, or follow a fixed (v, w)."""

    def __init__(self, name: str, command: tuple[float, float] | None = None, via: tuple[float, float] | None = None):
        self.name, self.command, self.via = name, command, via

    def bind(self, robot, lidar, goal_threshold) -> None:
        pass

    def reset(self) -> None:
        self.passed_via = self.via is None

    def act(self, readings, goal):
        if self.command is not None:
            return self.command
        x, y, yaw = readings.odometry.pose
        target = goal if self.passed_via else self.via
        if not self.passed_via and math.hypot(target[0] - x, target[1] - y) < 0.1:
            self.passed_via, target = True, goal
        error = wrap_angle(math.atan2(target[1] - y, target[0] - x) - yaw)
        return (0.0 if abs(error) > 0.3 else 0.5), max(-1.0, min(1.0, 3.0 * error))


OPEN = Scenario(start=(1.0, 5.0, 0.0), goal=(7.0, 5.0), goal_threshold=0.3)


def test_straight_drive_to_the_goal_has_spl_near_one():
    episode = run_episode(Scripted("direct"), OPEN)
    assert episode.outcome == "success"
    assert episode.shortest_path == pytest.approx(6.0 - 0.3, abs=0.05)
    assert episode.spl == pytest.approx(1.0, abs=0.03)


def test_a_detour_halves_spl_roughly_by_its_extra_length():
    episode = run_episode(Scripted("detour", via=(4.0, 9.0)), OPEN, max_steps=2000)
    assert episode.outcome == "success"
    expected = episode.shortest_path / episode.path_length
    assert episode.spl == pytest.approx(expected)
    assert 0.5 < episode.spl < 0.75  # 5 + ~4.6 m against 5.7 m


def test_outcomes_collision_stuck_timeout():
    blocked = OPEN.model_copy(update={"obstacles": [CircleObstacle(x=4.0, y=5.0, radius=0.5)]})
    assert run_episode(Scripted("ram", (0.5, 0.0)), blocked).outcome == "collision"
    assert run_episode(Scripted("idle", (0.0, 0.0)), OPEN).outcome == "stuck"
    circling = run_episode(Scripted("circle", (0.5, 1.0)), OPEN, max_steps=50)
    assert circling.outcome == "timeout" and circling.steps == 50
    assert run_episode(Scripted("ram", (0.5, 0.0)), blocked).spl == 0.0


def test_shortest_path_goes_around_obstacles():
    wall = OPEN.model_copy(update={"obstacles": [CircleObstacle(x=4.0, y=5.0, radius=1.5)]})
    assert shortest_path_length(wall) > shortest_path_length(OPEN) + 0.5


def test_wilson_interval_known_values():
    lo, hi = wilson_interval(10, 20)
    assert lo == pytest.approx(0.2993, abs=1e-3) and hi == pytest.approx(0.7007, abs=1e-3)
    assert wilson_interval(20, 20)[1] == 1.0 and wilson_interval(20, 20)[0] == pytest.approx(0.8389, abs=1e-3)
    # Exactly 0 at no successes and 1 at all (the arithmetic alone leaves 5.6e-17 at n=1, 1 - 1.1e-16 at n=10).
    for n in (1, 7, 10, 50, 200, 1000):
        assert wilson_interval(0, n)[0] == 0.0 and wilson_interval(n, n)[1] == 1.0


def _episode(outcome: str, steps: int = 10, length: float = 1.0, spl: float = 0.0) -> Episode:
    return Episode("a", "s", 0, outcome, steps, length, 1.0, spl, 0.01)


def test_summary_rates_and_success_only_means():
    rows = [_episode("success", 10, 2.0, 0.8), _episode("success", 20, 4.0, 0.6), _episode("collision", 5),
            _episode("stuck", 100)]
    s = summarise("a", rows)
    assert (s.success_rate, s.collision_rate, s.stuck_rate, s.timeout_rate) == (0.5, 0.25, 0.25, 0.0)
    assert s.mean_steps == 15 and s.mean_path_length == 3.0 and s.spl == pytest.approx(0.35)
    assert set(s.to_json()) >= {"success_rate", "collision_rate", "timeout_rate", "spl", "mean_steps",
                                "mean_path_length", "episodes"}


def test_same_scenarios_for_every_agent_and_report_files(tmp_path):
    summaries = evaluate([Scripted("direct"), Scripted("idle", (0.0, 0.0))], [OPEN, OPEN], max_steps=200)
    assert [s.agent for s in summaries] == ["direct", "idle"]
    assert [r.scenario for r in summaries[0].rows] == [r.scenario for r in summaries[1].rows]
    table = markdown_table(summaries, "toy")
    assert "| direct | 2 | 100% (" in table and "| idle | 2 | 0% (" in table
    assert write_csv(summaries, tmp_path / "e.csv").read_text().count("\n") == 5
    assert bar_chart(summaries, tmp_path / "c.png").stat().st_size > 1000


@pytest.mark.slow
def test_episodes_run_in_worker_processes_end_as_they_do_in_this_one():
    # Agents cross to the workers pickled (a policy as the recipe that opens its file) and every
    # episode builds its own world from its scenario and seed: the rows must match, in order.
    from pathlib import Path

    from common.controllers import make_controller
    from common.curriculum.policy import load_policy
    from common.generators import SUITES

    policy = load_policy(Path(__file__).resolve().parents[1] / "curricula" / "policies" / "stage1_2d_ppo.zip")
    agents = [make_controller("potential_field"), policy]
    scenarios = list(SUITES["cluttered"].scenarios(count=7, seed=100000))
    seen: list[int] = []
    here = evaluate(agents, scenarios, seed=100000, goal_radius=0.1)
    there = evaluate(agents, scenarios, seed=100000, goal_radius=0.1, jobs=2, progress=seen.append)
    with pytest.MonkeyPatch.context() as patch:
        # Read three scenarios at a time: blocks of 3, 3 and 1, each chunked anew over the workers.
        patch.setattr("common.evaluation.EVALUATION_BLOCK", 3)
        in_blocks_there = evaluate(agents, iter(scenarios), seed=100000, goal_radius=0.1, jobs=2)
        in_blocks_here = evaluate(agents, iter(scenarios), seed=100000, goal_radius=0.1)

    def rows(summaries):
        return [(s.agent, [(e.agent, e.scenario, e.seed, e.outcome, e.steps, e.path_length) for e in s.rows])
                for s in summaries]

    assert rows(there) == rows(here) == rows(in_blocks_there) == rows(in_blocks_here)
    assert len({e.outcome for s in here for e in s.rows}) > 1  # episodes that end differently, so an offset shows
    assert sum(seen) == 14


@pytest.mark.slow
def test_worker_processes_draw_their_own_scenarios_and_end_as_this_one(monkeypatch):
    """The CLI's scenarios go to the workers as the recipe that draws them (a chunk of scenarios
    sent through the pool's queue could fill its pipe and hang a Ctrl-C); each worker draws its
    chunks' own, two episodes at a time here."""
    import argparse
    import pickle

    from common.controllers import make_controller
    from common.curriculum.cli import _scenarios

    monkeypatch.setattr("common.evaluation.EVALUATION_BLOCK", 2)
    args = argparse.Namespace(seed=100000, world="flatland", episodes=None, suite="cluttered", scenario_file=None)
    drawn = _scenarios(args, count=7)
    assert pickle.loads(pickle.dumps(drawn)) == drawn
    assert list(drawn.part(3, 5)) == list(drawn)[3:5]
    agents = [make_controller("go_to_goal"), make_controller("reactive")]
    here = evaluate(agents, list(drawn), seed=100000, goal_radius=0.1)
    there = evaluate(agents, drawn, seed=100000, goal_radius=0.1, jobs=2)

    def rows(summaries):
        return [[(e.scenario, e.seed, e.outcome, e.steps, e.path_length) for e in s.rows] for s in summaries]

    assert rows(there) == rows(here)
    assert len({e.outcome for s in here for e in s.rows}) > 1


def test_an_evaluation_reads_its_scenarios_a_block_at_a_time(monkeypatch):
    """A million episodes' scenarios held at once took tens of GB before the first episode: the
    scenarios drawn stay within a block of the episodes driven."""
    monkeypatch.setattr("common.evaluation.EVALUATION_BLOCK", 4)
    driven: list[int] = []

    class Counting(Scripted):
        def reset(self) -> None:
            driven.append(1)
            super().reset()

    ahead: list[int] = []

    def drawn():
        for i in range(10):
            ahead.append(i - len(driven))  # how far the draws run ahead of the episodes
            yield OPEN.model_copy(update={"name": f"open-{i}"})

    (summary,) = evaluate([Counting("c", command=(0.5, 0.0))], drawn(), seed=3)
    assert [e.scenario for e in summary.rows] == [f"open-{i}" for i in range(10)]
    assert [e.seed for e in summary.rows] == list(range(3, 13))
    assert max(ahead) <= 3 and len(driven) == 10


class Refusing(Scripted):
    """A toy agent that refuses every robot, as a policy refuses one it cannot drive."""

    def bind(self, robot, lidar, goal_threshold) -> None:
        raise ConfigError("robot.yaml", "kinematics", "this agent drives no robot")


def test_an_agent_s_refusal_in_a_worker_process_reaches_the_caller_as_its_one_line():
    with pytest.raises(ConfigError) as error:
        evaluate([Refusing("r")], [OPEN, OPEN, OPEN], jobs=2)
    assert str(error.value) == "robot.yaml: kinematics: this agent drives no robot"


def _arrivals(agent: str, outcomes: str) -> list[Episode]:
    return [Episode(agent, f"s{i}", i, "success" if c == "s" else "collision", 10, 1.0, 1.0, 1.0, 0.0)
            for i, c in enumerate(outcomes)]


def test_the_paired_table_sets_each_agent_against_the_one_that_arrived_most_often():
    from common.curriculum.comparison import paired_table

    best = summarise("best", _arrivals("best", "ssssssss" + "ss"))
    # 'near' misses two the best arrived in; 'other' misses six, and arrives in none the best missed.
    near = summarise("near", _arrivals("near", "ssssssss" + "cc"))
    other = summarise("other", _arrivals("other", "sscccccc" + "ss"))
    table = paired_table([near, best, other])
    assert "Paired with `best`" in table
    assert "| near | 0 | 2 | 0.50 |" in table and "| other | 0 | 6 | 0.03 |" in table
    assert "| best |" not in table
    assert paired_table([best]) == ""
    far = summarise("far", _arrivals("far", "cccccccc" + "cc"))
    assert "| far | 0 | 10 | < 0.01 |" in paired_table([best, far])  # p = 2 / 1024


@pytest.mark.parametrize("robot", [RobotProfile(radius=0.2), RobotProfile(shape="box", length=0.4, width=0.4)],
                         ids=["circle", "box"])
def test_a_box_shaped_persons_gap_is_measured_to_its_box_not_the_circle_around_it(robot):
    # A cart (1.0 x 0.6 m, counted as a person: the default label) passes 0.3 m beside a robot
    # standing still, its long side to the robot. Its bounding circle reached 0.28 m closer.
    from common.evaluation import SocialRecord
    from common.motion.spec import Dash, Motion
    from flatland.world import World

    cart = BoxObstacle(x=2.0, y=5.8, length=1.0, width=0.6,
                       motion=Motion(behavior=Dash(), goals=[(8.0, 5.8)], vel_max=(1.0, 1.0), reacts_to_robot=False))
    world = World(Scenario(robot=robot, start=(5.0, 5.0, 0.0), goal=(9.0, 1.0), obstacles=[cart]), seed=0)
    social = SocialRecord(robot)
    social(world.reset())
    for _ in range(60):
        social(world.step(0.0, 0.0))
    assert social.min_gap == pytest.approx(0.3, abs=1e-9)
    # Within 0.5 m while the cart's near end is close enough: its centre within 0.5 m plus, for the
    # disc, sqrt(0.7^2 - 0.5^2) (a corner 0.5 m above its centre) and, for the box, 0.2 + sqrt(0.5^2 - 0.3^2)
    # (a corner 0.3 m above the robot's) either side of the robot's x.
    reach = 0.5 + (math.sqrt(0.7**2 - 0.5**2) if robot.shape == "circle" else 0.2 + math.sqrt(0.5**2 - 0.3**2))
    assert social.time_near == pytest.approx(2 * reach, abs=0.11)
