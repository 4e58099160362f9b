"""The curriculum CLI: validate's one-line errors (exit code 2, no traceback) and bench's JSON."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from common.curriculum.cli import main
from common.errors import ConfigError
from common.scenario import Scenario
from tests.conftest import optional

GOOD = Scenario(name="good").to_yaml()

BAD_FILES = {
    "unknown key": ("name: x\nwheels: 3\n", "wheels: unknown key; allowed: difficulty, goal, goal_threshold, grid_map"),
    "a misspelt key": ("name: x\nrobot: {v_maxx: 1}\n", "robot.v_maxx: unknown key (did you mean 'v_max'?); allowed: accel_lateral"),
    "unknown key of an obstacle": ("obstacles:\n  - {type: circle, x: 5, y: 5, radius: 1, colour: red}\n",
                                   "obstacles.0.colour: unknown key; allowed: height, motion, radius, type"),
    "an unknown key of a behaviour": (
        "obstacles:\n  - {type: circle, x: 5, y: 5, radius: 0.3, motion: {behavior: {name: dash, foo: 1}, goals: [[6, 6]]}}\n",
        "obstacles.0.motion.behavior.foo: unknown key; allowed: angle_tolerance, name, yield_distance"),
    "a boolean that is none": ("name: !!bool maybe\n", "line 1: 'maybe' is not a valid bool; refused"),
    "an integer that is none": ("world: {width: !!int 1x}\n", "line 1: '1x' is not a valid int"),
    "a sign for an integer": ("seed: !!int +\n", "line 1: '+' is not a valid int; refused"),
    "a separator for an integer": ("seed: !!int _\n", "line 1: '_' is not a valid int; refused"),
    "a word for a date": ("name: !!timestamp hello\n", "line 1: 'hello' is not a valid date; refused"),
    "a tag that builds an object": ("!!python/object:os.system\nx: 1\n",
                                    "line 1: the tag '!!python/object:os.system' is refused; allowed: plain YAML"),
    "wrong type": ("world:\n  width: wide\n", "world.width: Input should be a valid number"),
    "negative radius": ("obstacles:\n  - {type: circle, x: 5, y: 5, radius: -1}\n", "obstacles.0.radius: Input should be greater than 0"),
    "unknown obstacle type": ("obstacles:\n  - {type: blob, x: 5, y: 5}\n", "obstacles.0"),
    "empty file": ("", "the file is empty"),
    "not YAML": ("name: [unclosed\n  - {\n", "not valid YAML"),
    "not a mapping": ("- 1\n- 2\n", "expected a YAML mapping"),
    "goal inside obstacle": ("goal: [5, 5]\nobstacles:\n  - {type: circle, x: 5, y: 5, radius: 1}\n", "goal: (5, 5) is inside an obstacle"),
    "start outside world": ("start: [-3, 1, 0]\n", "start: (-3, 1) lies outside the world"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_validate_reports_one_line_naming_file_and_field(case, tmp_path, capsys):
    text, expected = BAD_FILES[case]
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert str(path) in err and expected in err, err


def test_validate_accepts_a_good_file_and_missing_files_fail(tmp_path, capsys):
    good = tmp_path / "good.yaml"
    good.write_text(GOOD)
    assert main(["validate", str(good)]) == 0
    assert "ok:" in capsys.readouterr().out
    assert main(["validate", str(tmp_path / "missing.yaml")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_validate_warns_of_a_curriculum_stage_on_a_world_irsim_runs_as_it_is(tmp_path, capsys):
    (tmp_path / "irsim.yaml").write_text(
        "world: {height: 10, width: 10}\nrobot:\n  - kinematics: {name: diff}\n    shape: {name: circle, radius: 0.2}\n"
        "    state: [2.35, 5, 3.14159]\n    goal: [9, 9, 0]\nobstacle:\n  - shape: {name: rectangle, length: 1, width: 1}\n"
        "    state: [3, 5, 0]\n")
    curriculum = tmp_path / "c.yaml"
    curriculum.write_text("name: c\nstages:\n  - name: s\n    scenarios: {file: irsim.yaml}\n    budget: 1000\n"
                          "    eval: {suite: sparse}\n")
    assert main(["validate", str(curriculum)]) == 0
    captured = capsys.readouterr()
    assert captured.out == f"ok: {curriculum}: curriculum 'c', 1 stage\n"
    assert captured.err.startswith("warning: ") and "start: (2.35, 5)" in captured.err and captured.err.count("\n") == 1


def test_validate_answers_every_file_and_fails_if_any_is_bad(tmp_path, capsys):
    good, bad, missing = tmp_path / "good.yaml", tmp_path / "bad.yaml", tmp_path / "missing.yaml"
    good.write_text(GOOD)
    bad.write_text(BAD_FILES["negative radius"][0])
    assert main(["validate", str(bad), str(good), str(missing), str(good)]) == 2
    captured = capsys.readouterr()
    assert captured.out.splitlines() == [f"ok: {good}: scenario 'good', 0 obstacles"] * 2
    errors = captured.err.splitlines()
    assert len(errors) == 2 and str(bad) in errors[0] and str(missing) in errors[1] and "no such file" in errors[1]


def test_validate_prints_a_worlds_warnings_and_leaves_a_librarys_to_python(tmp_path, capsys, monkeypatch):
    import warnings

    import common.world_file
    from common.errors import ScenarioWarning

    real = common.world_file.WorldFile

    def warning_world_file(path):
        warnings.warn("start touches an obstacle", ScenarioWarning)
        warnings.warn("a library's deprecation", DeprecationWarning)
        return real(path)

    monkeypatch.setattr(common.world_file, "WorldFile", warning_world_file)
    good = tmp_path / "good.yaml"
    good.write_text(GOOD)
    with pytest.warns(DeprecationWarning, match="a library's deprecation"):
        assert main(["validate", str(good)]) == 0
    assert capsys.readouterr().err == "warning: start touches an obstacle\n"


def test_a_curriculum_given_as_a_scenario_file_is_named_for_what_it_is(tmp_path, capsys):
    curriculum = tmp_path / "c.yaml"
    curriculum.write_text("name: c\nstages: []\n")
    assert main(["compare", "--controllers", "go_to_goal", "--episodes", "1", "--scenario-file", str(curriculum)]) == 2
    assert capsys.readouterr().err == f"error: {curriculum}: is a curriculum (it has stages), not a scenario or an " \
                                      "IR-SIM world file; run it with: curriculum run FILE\n"


def test_cli_process_exits_2_without_traceback(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("obstacles:\n  - {type: circle, x: 5, y: 5, radius: -1}\n")
    result = subprocess.run([sys.executable, "-m", "common.curriculum.cli", "validate", str(path)], capture_output=True, text=True)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_bench_json_has_the_agreed_keys(capsys, monkeypatch, tmp_path):
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    assert main(["bench", "--json", "--steps", "2000"]) == 0
    assert not list(tmp_path.glob("SB3-*")), "the bench left a training log folder behind"
    results = json.loads(capsys.readouterr().out)
    assert results["obstacles"] == 31 and results["lidar_beams"] == 36
    assert results["flatland_steps_per_s"] > 0
    assert "irsim_steps_per_s" in results
    for kind in ("open", "sparse", "cluttered", "warehouse", "trap", "irsim_random"):
        assert results[f"reset_ms_{kind}"] > 0
    assert results["circles_flatland_steps_per_s"] > 0 and "circles_flatland_vs_irsim" in results
    assert results["grid_flatland_steps_per_s"] > 0 and results["grid_flatland_vs_irsim"] > 0
    assert results["warehouse_env_steps_per_s"] > 0 and results["ppo_steps_per_s_cluttered"] > 0
    assert 0 < results["ppo_rollout_share_sparse"] < 1
    assert results["ppo_steps_per_s_cluttered_subproc"] > 0 and results["ppo_subproc_vs_dummy"] > 0
    assert results["ppo_stock_steps_per_s_sparse"] > 0 and results["ppo_vs_stock_sparse"] > 0
    assert results["ppo_rollout_share_cluttered"] < 1
    assert all(math.isfinite(value) for value in results.values() if isinstance(value, float))
    assert results["movers_vs_static"] > 0 and results["physics3d_movers_vs_static"] > 0
    assert results["reset_ms_maze"] > 0 and results["reset_ms_passages"] > 0
    for algorithm in ("ppo", "sac"):
        assert results[f"onnx_actions_per_s_{algorithm}"] > 0 and results[f"onnx_vs_torch_{algorithm}"] > 0
        assert results[f"agent_actions_per_s_{algorithm}"] > 0 and results[f"agent_vs_torch_{algorithm}"] > 0


def test_bench_reads_each_ppo_figure_from_the_measure_made_for_it(monkeypatch):
    from common.curriculum import bench

    measured = iter([100.0, 60.0, 80.0, 90.0])
    order = []

    def fake(kind, steps, seed=0, vec_env="dummy"):
        order.append((kind, vec_env))
        return next(measured)

    monkeypatch.setattr(bench, "ppo_steps_per_s", fake)
    monkeypatch.setattr(bench, "ppo_kinds_steps_per_s", lambda kinds, rollouts: {
        "sparse": (120.0, 0.7), "cluttered": (108.0, 0.75)})
    monkeypatch.setattr(bench, "ppo_runner_and_stock_steps_per_s", lambda rollouts: (110.0, 88.0))
    figures = bench._ppo_figures(2048)
    assert order == [("cluttered", "dummy"), ("cluttered", "subproc")] * 2  # alternated, the best of two
    assert figures["ppo_steps_per_s_sparse"] == 120.0 and figures["ppo_rollout_share_sparse"] == 0.7
    assert figures["ppo_steps_per_s_cluttered"] == 108.0 and figures["ppo_cluttered_vs_sparse"] == round(108 / 120, 3)
    assert figures["ppo_rollout_share_cluttered"] == 0.75
    assert figures["ppo_steps_per_s_cluttered_subproc"] == 90.0 and figures["ppo_subproc_vs_dummy"] == round(90 / 100, 3)
    assert figures["ppo_stock_steps_per_s_sparse"] == 88.0 and figures["ppo_vs_stock_sparse"] == round(110 / 88, 3)


def test_the_bench_s_stock_and_runner_ways_switch_every_setting_and_restore_torch_s(monkeypatch):
    # The stock way is stable-baselines3's and torch's defaults; the runner's, this project's
    # settings. Left switched, a bench run would change how the rest of the process trains.
    import torch

    from common.curriculum import bench
    from common.curriculum.schema import load_curriculum
    from common.rewards import Reward
    from common.task import Task

    checks = torch.distributions.Distribution._validate_args
    with bench._main_job_ppo("open") as model:
        # The main job's own settings, read from its file: a copy here once went on timing 64 x 64.
        main_job = load_curriculum(bench.MAIN_JOB).stages[0]
        assert model.policy.net_arch == main_job.hyperparams["policy_kwargs"]["net_arch"]
        assert (model.n_envs, model.n_steps) == (main_job.n_envs, main_job.hyperparams["n_steps"])
        env = model.get_env().envs[0].unwrapped  # its envs as the runner makes them, on the kind asked for
        assert env.reward.spec == Reward(main_job.reward).spec and env.action_mapping == main_job.action_mapping
        assert env.task.threshold == Task(main_job.env_kwargs["goal_threshold"], 1).threshold
        assert env.scenario.name.startswith("open")
        groups = model.policy.optimizer.param_groups
        assert not torch.distributions.Distribution._validate_args
        assert model.policy.direct_layer_calls and all(group["foreach"] for group in groups)
        bench._train_as(model, stock=True)
        assert torch.distributions.Distribution._validate_args
        assert not model.policy.direct_layer_calls and all(group["foreach"] is None for group in groups)
        bench._train_as(model, stock=False)
        assert model.policy.direct_layer_calls and all(group["foreach"] for group in groups)
    assert torch.distributions.Distribution._validate_args == checks


@pytest.mark.parametrize("measure", ["flatland_steps_per_s", "physics3d_steps_per_s", "physics3d_and_bare"])
def test_bench_times_its_own_work_not_the_time_other_work_held_the_core(monkeypatch, measure):
    """Each step here also waits 10 ms, as if a second job held the core: by the wall clock the
    env would run under 100 steps/s; timed on CPU time it runs at its own speed (hundreds or more)."""
    import time

    from common.curriculum import bench
    from common.nav_env import NavigationEnv

    step = NavigationEnv.step

    def held_up(self, action):
        time.sleep(0.01)
        return step(self, action)

    monkeypatch.setattr(NavigationEnv, "step", held_up)
    world = bench.physics3d_bench_scenario() if measure.startswith("physics3d") else bench.bench_scenario()
    figure = getattr(bench, measure)(world, steps=50)
    rate = figure[0] if isinstance(figure, tuple) else figure  # physics3d_and_bare: the env's, then the bare loop's
    assert rate > 200


def test_drives_taking_turns_make_every_step_once_in_order_one_turn_each_in_turn():
    from common.curriculum import bench

    log = []

    def drive(name):
        def steps(indices):
            sum(range(20_000))  # some CPU time to measure
            log.append((name, list(indices)))
        return steps

    rates = bench.steps_per_s_taking_turns([drive("env"), drive("reference")], [10, 3], rounds=3)
    assert [name for name, _ in log] == ["env", "reference"] * 3
    assert [k for name, turn in log if name == "env" for k in turn] == list(range(10))
    assert [k for name, turn in log if name == "reference" for k in turn] == list(range(3))
    assert all(rate > 0 for rate in rates)


def test_bench_gui_without_a_display_says_how_to_run_it(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    assert main(["bench", "--gui"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: --gui: needs an X display (DISPLAY is not set); run it as: xvfb-run -a curriculum bench --gui"]


@pytest.mark.parametrize("argv, expected", [
    (["compare", "--episodes", "0"], "--episodes: must be from 1 to"),
    (["compare", "--suite", "mars"], "invalid choice: 'mars'"),
    (["compare", "--scenario-file", "/no/such.yaml"], "/no/such.yaml: no such file"),
    (["compare", "--controllers", "teleport"], "controllers.teleport: unknown controller; allowed: go_to_goal"),
    (["eval", "--policy", "/no/such.zip"], "/no/such.zip: no such file"),
    (["render", "--agent", "teleport"], "--agent: 'teleport' is neither a controller (go_to_goal"),
    (["bench", "--steps", "lots"], "--steps: expected a whole number, got 'lots'"),
    (["fly"], "invalid choice: 'fly'"),
    (["compare", "--env-kwargs", "lidar_nosie:0.02"], "got 'lidar_nosie:0.02' (did you mean 'lidar_noise'?)"),
])
def test_bad_flags_and_missing_files_are_one_line_exit_2(argv, expected):
    result = subprocess.run([sys.executable, "-m", "common.curriculum.cli", *argv], capture_output=True, text=True)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0] and "Traceback" not in result.stderr, result.stderr


def test_compare_writes_table_csv_chart_and_prints_the_agreed_json(tmp_path, capsys):
    out = tmp_path / "cmp"
    assert main(["compare", "--suite", "sparse", "--episodes", "2", "--controllers", "go_to_goal,astar_pursuit",
                 "--out", str(out), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert set(result) == {"go_to_goal", "astar_pursuit"}
    for figures in result.values():
        assert {"success_rate", "collision_rate", "timeout_rate", "spl", "mean_steps", "mean_path_length",
                "episodes"} <= set(figures) and figures["episodes"] == 2
    table, paired = (out / "comparison.md").read_text().split("Paired with ")
    assert table.count("| astar_pursuit |") == 1 and table.count("| go_to_goal |") == 1
    assert paired.count("| astar_pursuit |") + paired.count("| go_to_goal |") == 1  # the other against the best
    assert (out / "episodes.csv").read_text().count("\n") == 5
    assert (out / "comparison.png").stat().st_size > 1000


def test_compare_reads_an_irsim_world_file(tmp_path, capsys):
    world = tmp_path / "irsim.yaml"
    world.write_text("world: {height: 10, width: 10}\nrobot:\n  kinematics: {name: diff}\n  shape: {name: circle, radius: 0.2}\n"
                     "  state: [1, 1, 0]\n  goal: [8, 8, 0]\n  goal_threshold: 0.3\n"
                     "  sensors: [{name: lidar2d, range_max: 5, angle_range: 6.283, number: 36}]\n"
                     "obstacle:\n  - shape: {name: circle, radius: 0.5}\n    state: [5, 5, 0]\n")
    assert main(["compare", "--scenario-file", str(world), "--episodes", "2", "--controllers", "pid_blend",
                 "--out", str(tmp_path / "o"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["pid_blend"]["success_rate"] == 1.0


def test_render_writes_a_gif_and_the_drift_plot(tmp_path, capsys):
    gif, drift = tmp_path / "e.gif", tmp_path / "d.png"
    assert main(["render", "--suite", "sparse", "--agent", "astar_pursuit", "--out", str(gif), "--every", "5",
                 "--drift", str(drift), "--env-kwargs", "odometry_noise:0.05"]) == 0
    from PIL import Image

    with Image.open(gif) as image:
        assert image.n_frames > 3
    printed = capsys.readouterr()
    assert drift.stat().st_size > 1000 and "(encoder noise 0.05)" in printed.out
    assert "astar_pursuit: flatland, suite sparse, 1 episode from seed 0, judged within each scenario's goal radius; " \
           "conditions: odometry_noise=0.05, action_delay=0, dynamics=kinematic" in printed.err


@pytest.mark.parametrize("flag, name", [("--drift", "d.txt"), ("--drift", "plots"), ("--out", "e.png"), ("--gif", "f.yaml")])
def test_an_output_of_the_wrong_kind_is_refused_before_any_episode_runs(flag, name, tmp_path, capsys, monkeypatch):
    import common.evaluation

    (tmp_path / "plots").mkdir()
    (tmp_path / "f.yaml").write_text("x: 1\n")
    monkeypatch.setattr(common.evaluation, "run_episode", lambda *args, **kwargs: pytest.fail("an episode ran"))
    monkeypatch.setattr("flatland.render.record_agent", lambda *args, **kwargs: pytest.fail("an episode ran"))
    outputs = {"--out": str(tmp_path / "e.gif"), flag: str(tmp_path / name)}
    command = ["compare", "--controllers", "go_to_goal", "--episodes", "1"] if flag == "--gif" else ["render"]
    argv = command + [part for pair in outputs.items() for part in pair]
    if flag == "--gif":
        argv[argv.index("--out") + 1] = str(tmp_path / "cmp")
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{flag} names" in err and str(tmp_path / name) in err, err
    assert not (tmp_path / "cmp").exists()


def test_render_makes_the_drift_plots_folder(tmp_path, capsys):
    drift = tmp_path / "new" / "d.png"
    assert main(["render", "--agent", "go_to_goal", "--out", str(tmp_path / "e.gif"), "--max-steps", "3",
                 "--drift", str(drift)]) == 0
    assert drift.stat().st_size > 1000 and f"{drift}: odometry drift" in capsys.readouterr().out


@pytest.mark.parametrize("argv, expected", [
    (["render", "--index", "-1"], "argument --index: must be from 0"),
    (["eval", "--policy", "p.zip", "--seed", "-1"], "argument --seed: must be from 0"),
    (["bench", "--steps", "0"], "argument --steps: must be from 100"),
    (["render", "--env-kwargs", "odometry_noise:nan"], "--env-kwargs.odometry_noise: Input should be a valid number (got 'nan')"),
    (["render", "--env-kwargs", "odometry_noise:.nan"], "--env-kwargs.odometry_noise: Input should be a finite number"),
    (["render", "--env-kwargs", "odometry_noise:-1"], "--env-kwargs.odometry_noise: Input should be greater than or equal to 0"),
    (["render", "--env-kwargs", "robot:{colour: 1}"], "--env-kwargs.robot: colour: unknown key; allowed: accel_lateral"),
    (["render", "--env-kwargs", "motor_scale:1.2"], "motor_scale: expected a range [low, high] drawn per episode, got 1.2"),
    (["render", "--episodes", "3"], "unrecognized arguments: --episodes 3"),
    (["compare", "--controllers", ",,,"], "--controllers: no controller named in ',,,'"),
    (["compare", "--max-steps", "0"], "argument --max-steps: must be from 1"),
    (["compare", "--jobs", "0"], "argument --jobs: must be from 1"),
    (["eval", "--policy", "p.zip", "--jobs", "two"], "argument --jobs: expected a whole number, got 'two'"),
    (["eval", "--policy", "p.zip", "--goal-threshold", "-0.1"], "argument --goal-threshold: must be more than 0"),
])
def test_every_bad_argument_names_its_flag(argv, expected, capsys):
    try:
        code = main(argv)
    except SystemExit as exit_:  # argparse's usage errors exit; input errors return
        code = exit_.code
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and expected in err, err


@pytest.mark.slow
def test_render_drives_a_policy_and_compare_writes_a_gif_per_agent(untrained_policy, tmp_path, capsys):
    gif = tmp_path / "policy.gif"
    assert main(["render", "--suite", "open", "--agent", str(untrained_policy), "--out", str(gif)]) == 0
    out = capsys.readouterr().out
    from PIL import Image

    with Image.open(gif) as image:
        # The manifest's 30-step episodes: at most 31 frames (the start and one per step).
        assert 2 < image.n_frames <= 31
    assert "untrained on" in out
    folder = tmp_path / "gifs"
    assert main(["compare", "--suite", "open", "--episodes", "1", "--controllers", "go_to_goal", "--policy",
                 str(untrained_policy), "--gif", str(folder), "--out", str(tmp_path / "cmp")]) == 0
    assert sorted(p.name for p in folder.iterdir()) == ["go_to_goal.gif", "untrained.gif"]


def test_eval_runs_episodes_as_long_as_the_policy_trained_with(untrained_policy, tmp_path, capsys):
    assert main(["compare", "--suite", "open", "--episodes", "3", "--controllers", "pid_blend", "--policy",
                 str(untrained_policy), "--out", str(tmp_path / "cmp")]) == 0
    import csv

    rows = list(csv.DictReader((tmp_path / "cmp" / "episodes.csv").open()))
    policy_steps = [int(r["steps"]) for r in rows if r["agent"] == "untrained"]
    assert len(policy_steps) == 3 and max(policy_steps) <= 30, policy_steps
    assert main(["compare", "--suite", "open", "--episodes", "1", "--controllers", "pid_blend", "--policy",
                 str(untrained_policy), "--max-steps", "5", "--out", str(tmp_path / "cmp5")]) == 0
    rows = list(csv.DictReader((tmp_path / "cmp5" / "episodes.csv").open()))
    assert all(int(r["steps"]) <= 5 for r in rows)


def test_controllers_and_policies_arrive_on_an_irsim_world_with_its_default_goal_radius(tmp_path, capsys):
    world = tmp_path / "irsim.yaml"
    # No goal_threshold: IR-SIM's default, 0.1 m. Controllers used to stop 0.3 m short and be scored stuck.
    world.write_text("world: {height: 10, width: 10}\nrobot:\n  kinematics: {name: diff}\n  shape: {name: circle, radius: 0.2}\n"
                     "  state: [1, 1, 0]\n  goal: [8, 8, 0]\n"
                     "  sensors: [{name: lidar2d, range_max: 5, angle_range: 6.283, number: 36}]\n"
                     "obstacle:\n  - shape: {name: circle, radius: 0.5}\n    state: [6, 3, 0]\n")
    assert main(["compare", "--scenario-file", str(world), "--episodes", "1", "--controllers",
                 "go_to_goal,reactive,potential_field,pid_blend,astar_pursuit,rrt_pursuit", "--out", str(tmp_path / "o"),
                 "--json"]) == 0
    results = json.loads(capsys.readouterr().out)
    assert {name: figures["success_rate"] for name, figures in results.items()} == dict.fromkeys(results, 1.0)
    # The same radius asked of a suite's scenarios.
    assert main(["compare", "--suite", "sparse", "--episodes", "3", "--goal-threshold", "0.1", "--controllers", "pid_blend",
                 "--out", str(tmp_path / "s"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["pid_blend"]["success_rate"] == 1.0


def test_a_policys_conditions_are_evaluated_by_default_and_the_command_line_overrides(untrained_policy, tmp_path):
    import shutil

    from common.curriculum.cli import _conditions, _settle, build_parser
    from common.curriculum.policy import load_policy
    from common.curriculum.policy_file import update_manifest

    path = tmp_path / "noisy.zip"
    shutil.copy(untrained_policy, path)
    update_manifest(path, {"env_kwargs": {"lidar_noise": 0.2, "robot": "physics3d", "dynamics": "first_order",
                                          "goal_threshold": 0.1}})
    agent = load_policy(path)

    def conditions(*flags: str):
        args = build_parser().parse_args(["eval", "--policy", str(path), *flags])
        _settle(args, [agent])
        return _conditions(args, [agent])

    assert conditions().model_dump(exclude_none=True) == {"robot": "physics3d", "lidar_noise": 0.2, "action_delay": 0,
                                                           "dynamics": "first_order"}
    overridden = conditions("--env-kwargs", "lidar_noise:0", "motor_scale:[0.9,1.1]")
    assert overridden.lidar_noise == 0.0 and overridden.motor_scale == (0.9, 1.1)
    assert overridden.robot == "physics3d" and overridden.dynamics == "first_order"  # the knobs not named stay
    in_3d = conditions("--world", "physics3d")
    assert in_3d.dynamics is None and in_3d.lidar_noise == 0.2 and in_3d.friction == (0.8, 1.2)  # 2D-only knob dropped
    with pytest.raises(ConfigError, match="--policy: these policies trained under different conditions"):
        args = build_parser().parse_args(["compare", "--policy", str(path), str(untrained_policy)])
        _settle(args, [agent])
        _conditions(args, [agent, load_policy(untrained_policy)])


def test_a_policy_trained_on_the_urdf_robot_meets_its_2d_profile_in_flatland_and_irsim(untrained_policy, tmp_path):
    import shutil

    from common.curriculum.cli import _conditions, _settle, build_parser
    from common.curriculum.policy import load_policy
    from common.curriculum.policy_file import update_manifest

    path = tmp_path / "urdf.zip"
    shutil.copy(untrained_policy, path)
    update_manifest(path, {"tier": "physics3d", "env_kwargs": {"action_delay": [0, 1]}})
    agent = load_policy(path)

    def robot(*flags: str):
        args = build_parser().parse_args(["eval", "--policy", str(path), *flags])
        _settle(args, [agent])
        return _conditions(args, [agent]).robot

    assert robot("--world", "flatland") == "physics3d" and robot("--world", "irsim") == "physics3d"
    assert robot("--world", "physics3d") == "physics3d"  # the tier's own default there
    assert robot("--world", "flatland", "--env-kwargs", "robot:{radius: 0.3}") == {"radius": 0.3}
    update_manifest(path, {"env_kwargs": {"robot": None}})  # said, but no robot
    agent = load_policy(path)
    assert robot("--world", "flatland") == "physics3d"


def test_a_policy_is_judged_within_the_goal_radius_it_trained_for(untrained_policy, tmp_path):
    import shutil

    from common.curriculum.cli import _judged, build_parser
    from common.controllers import make_controller
    from common.curriculum.policy import load_policy
    from common.curriculum.policy_file import update_manifest

    path = tmp_path / "precise.zip"
    shutil.copy(untrained_policy, path)
    update_manifest(path, {"env_kwargs": {"goal_threshold": [0.1, 0.5]}})
    precise, plain = load_policy(path), load_policy(untrained_policy)

    def radius(*flags: str, agents=(precise,)):
        return _judged(build_parser().parse_args(["compare", "--episodes", "3", *flags]), list(agents))

    assert radius() == 0.1  # the smallest radius it trained for
    assert radius("--goal-threshold", "0.4") == 0.4
    assert radius(agents=(plain, make_controller("pid_blend"))) is None  # each scenario's own
    with pytest.raises(ConfigError, match="trained for different goal radii"):
        radius(agents=(precise, plain))


def test_policies_named_alike_are_told_apart_by_their_paths(tmp_path, capsys):
    # Two runs' best.zip share one name; keyed by it, the JSON kept only the last of them.
    shipped = Path(__file__).resolve().parents[1] / "curricula" / "policies" / "stage1_2d_ppo.zip"
    paths = []
    for run in ("a", "b"):
        (tmp_path / run).mkdir()
        paths.append(tmp_path / run / "best.zip")
        paths[-1].write_bytes(shipped.read_bytes())
    assert main(["eval", "--policy", *map(str, paths), "--episodes", "2", "--json"]) == 0
    assert sorted(json.loads(capsys.readouterr().out)) == sorted(map(str, paths))


def test_bench_reports_no_policy_figures_where_the_shipped_policies_are_not(monkeypatch, tmp_path):
    # An installed package holds no curricula/: the policy keys are null, the rest is measured.
    from common.curriculum import bench

    monkeypatch.setattr(bench, "SHIPPED_POLICIES", tmp_path)
    figures = bench.onnx_figures(calls=10)
    assert figures and all(value is None for value in figures.values())
    assert {"agent_vs_torch_ppo", "onnx_vs_torch_sac", "torch_actions_per_s_sac"} <= figures.keys()


RANDOM_WORLD = ("world: {width: 10, height: 10}\nrobot: {kinematics: {name: diff}, shape: {name: circle, radius: 0.2}, "
                "state: [1, 1, 0], goal: [9, 9, 0]}\nobstacle:\n  - number: 6\n    distribution: {name: random, "
                "range_low: [3, 3, 0], range_high: [7, 7, 0]}\n    shape: {name: circle, radius: 0.3}\n")


@pytest.mark.parametrize("from_file", [False, True])
def test_render_index_draws_that_scenario_alone(from_file, tmp_path):
    """`render --index K` draws scenario K from its own seed: it was the last of K + 1 drawn (355 s
    for K = 1,000,000)."""
    import argparse

    from common.curriculum.cli import _scenarios

    (tmp_path / "random.yaml").write_text(RANDOM_WORLD)
    source = {"suite": None, "scenario_file": str(tmp_path / "random.yaml")} if from_file else {"suite": "sparse", "scenario_file": None}
    args = argparse.Namespace(seed=7, world="flatland", episodes=None, **source)
    all_five = list(_scenarios(args, count=5))
    assert [_scenarios(args, count=1, first=k).first() for k in range(5)] == all_five
    assert len({s.model_dump_json() for s in all_five}) == 5, "the five draws must differ for the test to tell them apart"


def test_an_evaluations_scenarios_are_drawn_as_they_are_read(monkeypatch):
    """`eval --episodes 1000000` drew every scenario before its first episode (tens of GB)."""
    import argparse
    import itertools

    import common.generators
    from common.curriculum.cli import _scenarios

    draws: list[int] = []
    generate = common.generators.generate
    monkeypatch.setattr(common.generators, "generate", lambda *a, **k: draws.append(1) or generate(*a, **k))
    args = argparse.Namespace(seed=7, world="flatland", episodes=None, suite="sparse", scenario_file=None)
    scenarios = _scenarios(args, count=1_000_000)
    assert len(scenarios) == 1_000_000 and not draws
    assert list(itertools.islice(scenarios, 2)) == list(_scenarios(args, count=2)) and len(draws) == 4


def test_a_world_file_is_read_once_for_a_whole_evaluation(tmp_path):
    """Workers re-read the file for every chunk: one edited mid-run mixed two worlds in one run,
    unchecked, and repeated its warnings."""
    import argparse
    import pickle

    from common.curriculum.cli import _scenarios

    world = tmp_path / "random.yaml"
    world.write_text(RANDOM_WORLD)
    args = argparse.Namespace(seed=7, world="flatland", episodes=None, suite=None, scenario_file=str(world))
    drawn = _scenarios(args, count=3)
    before = list(drawn)
    world.write_text("not: [a world")
    assert list(pickle.loads(pickle.dumps(drawn)).part(0, 3)) == before == list(drawn)


def test_checking_the_scenarios_before_the_episodes_shows_its_progress(monkeypatch, tmp_path):
    """The check before the first episode draws every scenario: a million took half an hour with
    nothing on the screen."""
    import rich.progress

    shown: list[tuple[str, int]] = []
    track = rich.progress.track

    def recording_track(sequence, description, total, **kwargs):
        shown.append((description, total))
        return track(sequence, description, total=total, **kwargs)

    monkeypatch.setattr(rich.progress, "track", recording_track)
    code = main(["compare", "--controllers", "go_to_goal", "--suite", "sparse", "--episodes", "3", "--max-steps", "1",
                 "--out", str(tmp_path / "out")])
    assert code == 0 and shown == [("checking 3 scenarios", 3)]


def test_a_scenario_that_cannot_be_drawn_is_refused_before_any_episode_in_any_block(tmp_path, monkeypatch, capsys):
    """Drawn a block at a time, episode 7's scenario (a radius range reaching below zero) was
    refused only after the block of episodes before it had run, and their results lost."""
    import common.evaluation

    monkeypatch.setattr("common.evaluation.EVALUATION_BLOCK", 2)
    ran: list[int] = []
    run_episode = common.evaluation.run_episode
    monkeypatch.setattr(common.evaluation, "run_episode", lambda *a, **k: ran.append(1) or run_episode(*a, **k))
    world = tmp_path / "negative.yaml"
    world.write_text("world: {width: 10, height: 10}\nrobot: {kinematics: {name: diff}, shape: {name: circle, radius: 0.2}, "
                     "state: [1, 1, 0], goal: [9, 9, 0]}\nobstacle:\n  - number: 1\n    distribution: {name: random, "
                     "range_low: [4, 4, 0], range_high: [6, 6, 0]}\n    shape: {name: circle, random_shape: true, "
                     "radius_range: [-0.02, 0.5]}\n")
    code = main(["compare", "--controllers", "go_to_goal", "--scenario-file", str(world), "--episodes", "10",
                 "--max-steps", "1", "--out", str(tmp_path / "out")])
    assert code == 2 and not ran
    assert "radius_range: must give radii > 0" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_world_no_tier_can_build_is_refused_by_validate_and_named_where_it_is_driven(tmp_path, capsys):
    """validate said ok to a polygon robot among movers, which every command then refused; and a
    refusal raised where a world is driven named no file."""
    among = tmp_path / "among.yaml"
    among.write_text("start: [1, 1, 0]\ngoal: [8, 8]\nrobot: {shape: polygon, vertices: [[0.2, 0], [-0.2, 0.15], "
                     "[-0.2, -0.15]]}\nobstacles: [{type: circle, x: 5, y: 5, radius: 0.3, motion: {goals: [[6, 6]]}}]\n")
    assert main(["validate", str(among)]) == 2
    assert capsys.readouterr().err == f"error: {among}: robot.shape: a polygon robot among movers is not modelled; " \
                                      "allowed: circle, box\n"
    omni = tmp_path / "omni.yaml"
    omni.write_text("start: [1, 1, 0]\ngoal: [8, 8]\nrobot: {kinematics: omni}\n")
    assert main(["compare", "--controllers", "reactive", "--episodes", "1", "--scenario-file", str(omni),
                 "--out", str(tmp_path / "c")]) == 2
    # One line, the refusal: nothing is announced for a comparison that cannot run.
    assert capsys.readouterr().err.startswith(f"error: {omni}: robot.kinematics: the reactive controller drives")
    shipped = Path(__file__).resolve().parents[1] / "curricula" / "policies" / "stage1_2d_ppo.zip"
    assert main(["eval", "--policy", str(shipped), "--episodes", "1", "--scenario-file", str(omni)]) == 2
    assert capsys.readouterr().err.startswith(f"error: {omni}: robot.kinematics: the policy 'stage1_2d_ppo' drives")
    # An error of a flag stays the flag's, and so does one of the robot --env-kwargs put in.
    assert main(["compare", "--controllers", "teleport", "--scenario-file", str(omni), "--out", str(tmp_path / "d")]) == 2
    assert capsys.readouterr().err.startswith("error: --controllers: controllers.teleport: unknown controller")
    small = tmp_path / "small.yaml"
    small.write_text("world: {width: 3, height: 3}\nstart: [1, 1, 0]\ngoal: [2, 2]\n")
    assert main(["compare", "--controllers", "go_to_goal", "--episodes", "1", "--scenario-file", str(small),
                 "--env-kwargs", "robot:{radius: 2.5}", "--out", str(tmp_path / "e")]) == 2
    assert capsys.readouterr().err.splitlines()[-1].startswith("error: robot: 5 m across, it does not fit")
    # A world the chosen tier cannot build is refused before the announcement too, named by its suite.
    assert main(["compare", "--world", "physics3d", "--suite", "maze", "--controllers", "go_to_goal", "--episodes", "1",
                 "--out", str(tmp_path / "f")]) == 2
    assert capsys.readouterr().err == "error: suite maze: grid_map: an occupancy grid map is not built in the 3D tier; " \
                                      "allowed: null\n"
    assert not (tmp_path / "f").exists()  # nothing written for a comparison that cannot run


def test_a_place_no_output_can_be_written_to_is_refused_before_any_episode(tmp_path, capsys):
    """compare ran every episode, replaced the earlier comparison, then failed on --gif; render
    wrote its GIF before failing on --drift; export named its temporary file, not --onnx."""
    blocked = tmp_path / "a_file"
    blocked.write_text("")  # nothing can be made under a file
    earlier = tmp_path / "earlier"
    earlier.mkdir()
    (earlier / "comparison.md").write_text("the earlier comparison")
    assert main(["compare", "--controllers", "go_to_goal", "--episodes", "1", "--out", str(earlier),
                 "--gif", str(blocked / "gifs")]) == 2
    assert capsys.readouterr().err.splitlines()[-1] == (f"error: {blocked / 'gifs'}: cannot write here (Not a directory); "
                                                        "choose another --gif")
    assert (earlier / "comparison.md").read_text() == "the earlier comparison"
    gif = tmp_path / "episode.gif"
    assert main(["render", "--agent", "go_to_goal", "--out", str(gif), "--drift", str(blocked / "drift.png")]) == 2
    assert capsys.readouterr().err.splitlines()[-1] == (f"error: {blocked / 'drift.png'}: cannot write here (Not a "
                                                        "directory); choose another --drift")
    assert not gif.exists()
    optional("onnx")
    shipped = Path(__file__).resolve().parents[1] / "curricula" / "policies" / "stage1_2d_ppo.zip"
    assert main(["export", str(shipped), "--onnx", str(blocked / "policy.onnx")]) == 2
    assert capsys.readouterr().err == (f"error: {blocked / 'policy.onnx'}: cannot write here (Not a directory); "
                                       "choose another --onnx\n")


def test_usage_errors_point_at_the_subcommands_help_and_a_repeated_env_kwarg_is_refused(capsys):
    """An unknown flag of `render` pointed at `curriculum --help`; `--env-kwargs k:1 k:2` silently
    took the last."""
    with pytest.raises(SystemExit) as stop:
        main(["render", "--agent", "go_to_goal", "--episodes", "2"])
    assert stop.value.code == 2
    assert capsys.readouterr().err == ("error: curriculum render: unrecognized arguments: --episodes 2 "
                                       "(see curriculum render --help)\n")
    assert main(["eval", "--policy", str(Path(__file__).resolve().parents[1] / "curricula" / "policies" / "stage1_2d_ppo.zip"),
                 "--episodes", "1", "--env-kwargs", "lidar_noise:0.1", "lidar_noise:0.2"]) == 2
    assert capsys.readouterr().err == "error: --env-kwargs.lidar_noise: given twice; allowed: each key once\n"
    # A knob of the other tier is refused as such, before its value's advice (which it could not follow).
    assert main(["compare", "--controllers", "go_to_goal", "--episodes", "1", "--env-kwargs", "friction:0.5"]) == 2
    assert capsys.readouterr().err.startswith("error: --env-kwargs.friction: not a flatland knob; allowed: robot,")
    assert main(["compare", "--controllers", "go_to_goal", "--episodes", "1", "--env-kwargs", "robot_family:xyz"]) == 2
    assert capsys.readouterr().err == ("error: --env-kwargs.robot_family: expected a mapping of length, radius, shapes, "
                                       "v_max, w_max, width (got 'xyz')\n")
