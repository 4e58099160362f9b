"""Files and values from strangers: bounded YAML, range-checked worlds, policies that never run
code, refused actions, a locked run directory. Each answer is one line, fast, and harmless."""

from __future__ import annotations

import base64
import json
import math
import pickle
import subprocess
import sys
import time
import tracemalloc
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

import flatland  # noqa: F401
import physics3d  # noqa: F401
from common.curriculum.cli import main
from common.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "tests" / "data" / "tiny_curriculum.yaml"
ROBOT = "robot:\n  kinematics: {name: diff}\n  state: [1, 1, 0]\n  goal: [8, 8, 0]\n"


def _laughs(levels: int = 9) -> str:
    """A billion-laughs document whose last alias is a polygon's vertices: 9^9 points once expanded."""
    lines = ["a: &a [[1, 1], [2, 1], [2, 2]]"]
    for i in range(1, levels):
        name, previous = chr(ord("a") + i), chr(ord("a") + i - 1)
        lines.append(f"{name}: &{name} [{', '.join(['*' + previous] * 9)}]")
    last = chr(ord("a") + levels - 1)
    return "\n".join(lines) + f"\nobstacles:\n  - {{type: polygon, vertices: *{last}}}\n"


HOSTILE = {
    "billion laughs": (_laughs(), "aliases expand to more than"),
    "deep nesting": ("name: x\nworld: " + "[" * 4900 + "]" * 4900 + "\n", "nested deeper than"),
    "self-referencing alias": ("obstacles: &o [*o]\n", "an alias refers to a value that contains it"),
    "huge radius": ("world: {width: 1.0e+308, height: 1.0e+308}\nobstacles:\n  - {type: circle, x: 5, y: 5, radius: 1.0e+300}\n",
                    "less than or equal to 1000"),
    "nan coordinate": ("obstacles:\n  - {type: circle, x: .nan, y: 5, radius: 1}\n", "finite number"),
    "irsim huge radius": (ROBOT + "obstacle:\n  - shape: {name: circle, radius: 1.0e+300}\n    state: [5, 5, 0]\n",
                          "less than or equal to 1000"),
    "impossible spacing": (ROBOT + "obstacle:\n  - number: 500\n    distribution: {name: random, min_distance: 50}\n",
                           "random-placement spacing checks"),
    "fifty anchored groups": (ROBOT + "obstacle:\n  - &g {number: 1000, distribution: {name: random, min_distance: 0.001}}\n"
                              + "".join("  - *g\n" for _ in range(49)), "objects in all"),
    "thousands of vertices": (ROBOT + "obstacle:\n  - number: 1000\n    shape: {name: polygon, random_shape: true, "
                              "num_vertices_range: [900, 999]}\n", "polygon vertices in all"),
    "one polygon shared by many": (ROBOT + "obstacle:\n  - number: 1000\n    distribution: {name: random, min_distance: 0}\n"
                                   "    shape: {name: polygon, vertices: [" + ", ".join(f"[{math.cos(k / 4):.3f}, {math.sin(k / 4):.3f}]" for k in range(25)) + "]}\n",
                                   "polygon vertices in all"),
    "an integer beyond any float": (ROBOT + "  vel_max: [" + "9" * 400 + ", 1]\n", "robot.vel_max[0]: expected a finite number"),
    "crossed polygon": ("obstacles:\n  - {type: polygon, vertices: [[0, 0], [2, 2], [2, 0], [0, 2]]}\n", "crosses itself"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_world_files_are_one_line_errors_within_bounded_time_and_memory(case, tmp_path, capsys):
    text, expected = HOSTILE[case]
    assert len(text) < 10_000
    path = tmp_path / "hostile.yaml"
    path.write_text(text)
    tracemalloc.start()
    began = time.perf_counter()
    try:
        code = main(["validate", str(path)])
        seconds = time.perf_counter() - began
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and expected in err, err
    assert len(err) < 400, err
    # Bounds with room for a slow machine and tracemalloc's own cost; each case took minutes or
    # gigabytes before the reader was bounded.
    assert seconds < 10 and peak < 200e6, (seconds, peak)


def test_too_many_obstacles_and_too_large_files_are_refused(tmp_path, capsys):
    many = tmp_path / "many.yaml"
    many.write_text("obstacles:\n" + "".join(f"  - {{type: circle, x: {i % 100 / 10}, y: {i // 100 / 10}, radius: 0.01}}\n"
                                             for i in range(5000)))
    assert main(["validate", str(many)]) == 2
    assert "obstacles: List should have at most 2000 items" in capsys.readouterr().err
    huge = tmp_path / "huge.yaml"
    huge.write_text("name: " + "x" * (3 * 2**20) + "\n")
    assert main(["validate", str(huge)]) == 2
    assert "larger than 2 MiB" in capsys.readouterr().err


def test_every_entry_point_refuses_a_bad_world_in_one_line(tmp_path):
    from common.world_file import read_world_file

    path = tmp_path / "bad.yaml"
    path.write_text(HOSTILE["irsim huge radius"][0])
    with pytest.raises(ConfigError, match="less than or equal to 1000"):
        flatland.load_world(path)
    with pytest.raises(ConfigError):
        read_world_file(path, seed=3)
    result = subprocess.run([sys.executable, "-m", "common.curriculum.cli", "compare", "--scenario-file", str(path), "--episodes", "1",
                             "--controllers", "go_to_goal", "--out", str(tmp_path / "o")], capture_output=True, text=True)
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr


def test_an_irsim_start_outside_the_world_is_a_warning_not_an_error(tmp_path, capsys):
    path = tmp_path / "far.yaml"
    path.write_text("world: {width: 10, height: 10}\nrobot:\n  kinematics: {name: diff}\n  state: [50, 50, 0]\n  goal: [8, 8, 0]\n")
    assert main(["validate", str(path)]) == 0
    captured = capsys.readouterr()
    assert "warning:" in captured.err and "start: (50, 50) lies outside the world" in captured.err
    assert "IR-SIM runs it" in captured.err and "ok:" in captured.out
    project = tmp_path / "project.yaml"
    project.write_text("start: [50, 50, 0]\n")
    assert main(["validate", str(project)]) == 2


# -- policies ------------------------------------------------------------------------------------


class _Marker:
    """Unpickling this creates a file: proof that code ran."""

    def __init__(self, path: Path) -> None:
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def _rewrite(source: Path, target: Path, replace: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(source) as old, zipfile.ZipFile(target, "w") as new:
        for item in old.infolist():
            new.writestr(item.filename, replace.get(item.filename, old.read(item)))
    return target


def test_a_pickle_payload_in_a_untrained_policy_never_runs(untrained_policy, tmp_path, capsys):
    from stable_baselines3 import PPO

    data = json.loads(zipfile.ZipFile(untrained_policy).read("data"))
    marker_ours, marker_sb3 = tmp_path / "ours", tmp_path / "sb3"

    def evil(marker: Path) -> Path:
        payload = dict(data)
        payload["lr_schedule"] = {":type:": "<class 'function'>",
                                  ":serialized:": base64.b64encode(pickle.dumps(_Marker(marker))).decode()}
        return _rewrite(untrained_policy, tmp_path / f"evil-{marker.name}.zip", {"data": json.dumps(payload).encode()})

    # The payload is live: stable-baselines3's own loader runs it.
    PPO.load(evil(marker_sb3), device="cpu")
    assert marker_sb3.exists()
    assert main(["eval", "--policy", str(evil(marker_ours)), "--suite", "open", "--episodes", "1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["episodes"] == 1
    assert not marker_ours.exists()


def test_a_pickle_in_place_of_weights_is_refused_without_running(untrained_policy, tmp_path, capsys):
    marker = tmp_path / "marker"
    evil = _rewrite(untrained_policy, tmp_path / "evil.zip", {"policy.pth": pickle.dumps(_Marker(marker), protocol=2)})
    assert main(["eval", "--policy", str(evil), "--episodes", "1"]) == 2
    err = capsys.readouterr().err
    assert "policy.pth: not plain weights" in err and err.count("\n") == 1
    assert not marker.exists()


@pytest.mark.parametrize("change, expected", [
    (lambda m: m.pop("algorithm"), "nav_manifest.json: algorithm: Field required"),
    (lambda m: m.update(algorithm="sac"), "policy.pth: the weights do not fit a SAC policy"),
    (lambda m: m.update(observation="lidar43"), "policy.pth: the weights do not fit a PPO policy"),
    (lambda m: m.update(policy_kwargs={"net_arch": [32]}), "policy.pth: the weights do not fit"),
    (lambda m: m.update(goal_distance_scale=float("inf")), "goal_distance_scale"),
    (lambda m: m.update(policy_kwargs={"activation_fn": "os.system"}), "activation_fn"),
    (lambda m: m.update(tier="mars"), "nav_manifest.json: tier: Input should be 'flatland' or 'physics3d'"),
    (lambda m: m.update(policy_kwargs={"net_arc": [32]}),
     "nav_manifest.json: policy_kwargs.net_arc: unknown key (did you mean 'net_arch'?); allowed: activation_fn"),
    # The env arguments are checked as a stage's are, for the tier the policy names.
    (lambda m: m.update(env_kwargs={"goal_threshold": -1}),
     "nav_manifest.json: env_kwargs: goal_threshold: got -1; allowed: 0 < low <= high <= 1000 m"),
    (lambda m: m.update(env_kwargs={"friction": 0.5}), "env_kwargs: friction: not a flatland env argument"),
    (lambda m: m.update(tier="physics3d", env_kwargs={"robot_family": True}),
     "env_kwargs: robot_family: not a physics3d env argument"),
    (lambda m: m.update(env_kwargs={"resample": "yes"}), "env_kwargs: resample: got 'yes'; allowed: true or false"),
    (lambda m: m.update(env_kwargs={"lidar_noise": -1}), "nav_manifest.json: env_kwargs: lidar_noise: "),  # named once
    # The policy's own test figure says where eval runs by default: a damaged one was ignored (sparse, seed 0).
    (lambda m: m.update(final_eval={"suite": "cluttred", "first_seed": 100000, "episodes": 200}),
     "nav_manifest.json: final_eval.suite: Input should be"),
    (lambda m: m.update(final_eval={"suite": "sparse", "first_seed": True, "episodes": 200}),
     "nav_manifest.json: final_eval.first_seed: Input should be a valid integer"),
    (lambda m: m.update(final_eval={"suite": "sparse", "first_seed": 0, "episodes": 0}),
     "nav_manifest.json: final_eval.episodes: Input should be greater than or equal to 1"),
    (lambda m: m.update(final_eval=[1]), "nav_manifest.json: final_eval: "),
])
@pytest.mark.parametrize("command", ["eval", "export"])
def test_an_inconsistent_manifest_is_a_one_line_refusal(untrained_policy, tmp_path, capsys, change, expected, command):
    manifest = json.loads(zipfile.ZipFile(untrained_policy).read("nav_manifest.json"))
    change(manifest)
    bad = _rewrite(untrained_policy, tmp_path / "bad.zip", {"nav_manifest.json": json.dumps(manifest).encode()})
    args = ["--policy", str(bad), "--episodes", "1"] if command == "eval" else [str(bad), "--onnx", str(tmp_path / "p.onnx")]
    assert main([command, *args]) == 2
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1, err
    assert not (tmp_path / "p.onnx").exists()


@pytest.mark.parametrize("kept", [574_800, 50_000])
def test_a_truncated_policy_is_named_truncated(tmp_path, capsys, kept):
    """Cut short, a policy's last end record can be a member's own (its weights are a zip in the
    zip): it was read as the policy's, and the file refused as a zip of 45 members or no policy."""
    cut = tmp_path / "cut.zip"
    cut.write_bytes((ROOT / "curricula" / "policies" / "stage1_2d_ppo.zip").read_bytes()[:kept])
    assert main(["eval", "--policy", str(cut), "--episodes", "1"]) == 2
    err = capsys.readouterr().err
    assert "cut.zip: a truncated or damaged zip (its end record is not at its end)" in err and err.count("\n") == 1, err


def test_oversized_members_are_refused_before_they_are_read(untrained_policy, tmp_path, capsys):
    bomb = _rewrite(untrained_policy, tmp_path / "bomb.zip", {"nav_manifest.json": b" " * (2 * 2**20)})
    assert main(["eval", "--policy", str(bomb)]) == 2
    assert "nav_manifest.json: larger than 1 MiB" in capsys.readouterr().err


def test_a_replay_buffer_is_arrays_and_a_pickled_one_is_refused(tmp_path):
    from stable_baselines3 import SAC

    from common.curriculum.replay import load_replay, save_replay

    def model():
        return SAC("MlpPolicy", gym.make("flatland/Nav-v0", world="open"), buffer_size=50, learning_starts=10,
                   device="cpu", seed=0)

    trained = model()
    trained.learn(30)
    path = save_replay(trained.replay_buffer, tmp_path / "replay.npz")
    fresh = model()
    load_replay(fresh.replay_buffer, path)
    assert fresh.replay_buffer.pos == trained.replay_buffer.pos == 30
    assert np.array_equal(fresh.replay_buffer.observations, trained.replay_buffer.observations)

    marker = tmp_path / "marker"
    arrays = dict(np.load(path))
    arrays["observations"] = np.array([_Marker(marker)], dtype=object)
    with (tmp_path / "evil.npz").open("wb") as handle:
        np.savez(handle, **arrays)
    with pytest.raises(ConfigError, match="not this stage's replay buffer"):
        load_replay(model().replay_buffer, tmp_path / "evil.npz")
    assert not marker.exists()

    # A NaN in a filled row is refused (training on it would put NaN into the weights); past the
    # filled rows the buffer's contents are never read.
    for name, row in (("observations", 3), ("rewards", 29), ("next_observations", 0)):
        arrays = dict(np.load(path))
        arrays[name][row] = np.nan
        np.savez(tmp_path / "nan.npz", **arrays)
        with pytest.raises(ConfigError, match=f"{name}: holds NaN or infinite values"):
            load_replay(model().replay_buffer, tmp_path / "nan.npz")
    whole = {name: np.concatenate([array, np.full((50 - len(array), *array.shape[1:]), np.inf, array.dtype)])
             if array.ndim and array.dtype.kind == "f" else array for name, array in np.load(path).items()}
    np.savez(tmp_path / "whole.npz", **whole)  # the whole buffer, as files were once written
    load_replay(model().replay_buffer, tmp_path / "whole.npz")


# -- actions -------------------------------------------------------------------------------------


BAD_ACTIONS = [np.array([np.nan, 0.0]), [0.0, np.inf], np.zeros(3), np.zeros(1), 0.5, None, [0.1, "a"], np.zeros((2, 1))]


@pytest.mark.parametrize("env_id, world", [("flatland/Nav-v0", "sparse"), ("physics3d/WarehouseNav-v0", "open")])
def test_both_tiers_refuse_non_finite_or_misshapen_actions_and_keep_their_state(env_id, world):
    env = gym.make(env_id, world=world)
    env.reset(seed=0)
    pose = env.unwrapped.readings.pose
    for action in BAD_ACTIONS:
        with pytest.raises(ValueError, match=r"action .*: expected (shape \(2,\)|two numbers|finite numbers)"):
            env.step(action)
    assert env.unwrapped.readings.pose == pose
    observation, *_ = env.step(np.array([5.0, -5.0]))  # finite but out of range: clamped, as before
    assert env.observation_space.contains(observation)
    env.close()


# -- the run directory ---------------------------------------------------------------------------


def test_a_locked_run_directory_is_refused(tmp_path, capsys):
    from filelock import FileLock

    out = tmp_path / "run"
    out.mkdir()
    with FileLock(out / ".lock"):
        assert main(["run", str(TINY), "--out", str(out), "--no-progress"]) == 2
    assert "another run is using this directory" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == [".lock"]  # nothing written while refused


def test_a_run_that_died_before_its_first_checkpoint_starts_afresh(tmp_path):
    from common.curriculum.runner import Runner
    from common.curriculum.schema import load_curriculum

    config = load_curriculum(TINY)
    out = tmp_path / "run"
    first = Runner(config, out)
    first.prepare()  # what a run writes before it trains
    (out / "stages" / "0-open" / "tensorboard").mkdir(parents=True)
    first.release()  # ... and then it died
    for resume in (False, True):
        again = Runner(config, out, resume=resume)
        assert again.prepare() == {"done": [], "stages": {}}
        again.release()
    # A directory with an evaluation in it holds progress: only --resume may continue it.
    again.eval_log.append({"stage": "open", "timesteps": 1024, "wall_time": 1.0, "success_rate": 0.5, "collision_rate": 0.5,
                            "timeout_rate": 0.0, "stuck_rate": 0.0, "spl": 0.4, "mean_steps": ""})
    with pytest.raises(ConfigError, match="not empty"):
        Runner(config, out).prepare()
    assert (out / "eval.csv").read_text().count("\n") == 2  # nothing lost by the refusal


def test_an_unknown_env_argument_in_a_stage_names_the_field():
    from common.curriculum.schema import curriculum_from_mapping

    data = yaml.safe_load(TINY.read_text())
    data["stages"][0]["env_kwargs"] = {"gravity": 3}
    with pytest.raises(ConfigError, match=r"c.yaml: stages.0.env_kwargs.gravity: not a flatland env argument; allowed: action_delay, dynamics, goal_threshold"):
        curriculum_from_mapping(data, "c.yaml")
