"""The curriculum runner: schema errors, artefacts, kill -9 and resume, learning, policy zips."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from common.curriculum.cli import main
from common.curriculum.schema import curriculum_from_mapping, load_curriculum
from common.errors import ConfigError
from common.generators import generate

TINY = Path(__file__).parent / "data" / "tiny_curriculum.yaml"
ROOT = Path(__file__).resolve().parents[1]


def _tiny() -> dict:
    return yaml.safe_load(TINY.read_text())


def _with(change: dict, stage: dict | None = None) -> dict:
    data = _tiny()
    data.update(change)
    if stage:
        data["stages"][0].update(stage)
    return data


@pytest.mark.parametrize("data, field, message", [
    (_with({"seeds": 1}), "seeds", "unknown key (did you mean 'seed'?); allowed: device, evidence, name, seed, stages"),
    (_with({}, {"n_env": 3}), "stages.0.n_env", "unknown key (did you mean 'n_envs'?); allowed: action_mapping, algorithm, budget"),
    (_with({"device": "tpu"}), "device", "'auto', 'cpu', 'cuda' or 'mps'"),
    (_with({}, {"algorithm": "dqn"}), "stages.0.algorithm", "'ppo', 'sac' or 'td3'"),
    (_with({}, {"optimizer_kernels": "together"}), "stages.0.optimizer_kernels", "'foreach' or 'fused'"),
    (_with({}, {"budget": -5}), "stages.0.budget", "greater than or equal to 1"),
    (_with({}, {"budget": 10**29}), "stages.0.budget", "less than or equal to 10000000000"),
    (_with({}, {"hyperparams": {"learning_rte": 0.1}}), "stages.0.hyperparams.learning_rte", "not a PPO argument (did you mean 'learning_rate'?); allowed:"),
    (_with({}, {"hyperparams": {"policy_kwargs": {"net_arc": [64]}}}), "stages.0.hyperparams.policy_kwargs.net_arc",
     "unknown key (did you mean 'net_arch'?); allowed: activation_fn, bounded_mean"),
    (_with({}, {"reward": {"speed": 1}}), "stages.0.reward.speed", "unknown reward term"),
    (_with({}, {"reward": {"proximity": {"weight": -1, "threshold": "fast"}}}), "stages.0.reward.proximity.threshold",
     "got 'fast'; allowed: a finite number (default 0.3)"),
    (_with({}, {"reward": {"stuck": {"weight": -1, "window": 2.5}}}), "stages.0.reward.stuck.window", "allowed: an integer"),
    (_with({}, {"scenarios": {"kind": "sparse", "suite": "sparse"}}), "stages.0.scenarios", "exactly one of kind, mix, suite or file"),
    (_with({}, {"eval": {"suite": "mars"}}), "stages.0.eval.suite", "unknown suite"),
    (_with({}, {"init_from": "previous"}), "stages.0.init_from", "the first stage has no previous stage"),
    # Opened when validated, not when the stage starts (after the earlier stages trained).
    (_with({}, {"init_from": str(TINY)}), "stages.0.init_from", "tiny_curriculum.yaml': not a zip file"),
    (_with({}, {"init_from": str(ROOT / "curricula" / "policies" / "stage1_2d_sac.zip")}), "stages.0.init_from",
     "is a sac policy, whose network a ppo stage cannot load; allowed: a ppo policy"),
    (_with({"stages": []}), "stages", "at least 1 item"),
    (_with({}, {"name": "a/../../x"}), "stages.0.name", "'a/../../x'; allowed: letters, digits, '_', '-' and '.'"),
    (_with({"name": "../escape"}), "name", "'../escape'; allowed: letters, digits"),
    (_with({"name": ""}), "name", "''; allowed: letters, digits"),
    (_with({}, {"scenarios": {"mix": {"sparse": float("inf")}}}), "stages.0.scenarios.mix.sparse", "less than or equal to 1000000"),
    (_with({}, {"env_kwargs": {"goal_treshold": 0.1}}), "stages.0.env_kwargs.goal_treshold",
     "not a flatland env argument (did you mean 'goal_threshold'?); allowed: action_delay"),
    (_with({}, {"hyperparams": {"nsteps": 64}}), "stages.0.hyperparams.nsteps",
     "not a PPO argument (did you mean 'n_steps'?); allowed: batch_size"),
    (_with({}, {"world": "physics3d", "observation": "lidar43", "normalize": False, "env_kwargs": {"camera": "false"}}),
     "stages.0.env_kwargs.camera", "got 'false'; allowed: true or false"),
    (_with({}, {"env_kwargs": {"lidar_noise": -1}}), "stages.0.env_kwargs.lidar_noise", "greater than or equal to 0"),
    (_with({}, {"scenarios": {"mix": {}}}), "stages.0.scenarios", "mix names no kind; allowed: a weight for one or more of open"),
    (_with({}, {"scenarios": {"file": "/"}}), "stages.0.scenarios.file", "'/': a directory, not a regular file; expected a "
     "file; allowed: a scenario"),
    # A name too long for the file system raised from Path.is_file: 5 KB of it, naming no field.
    (_with({}, {"scenarios": {"file": "a" * 5000}}), "stages.0.scenarios.file", "aaaa': cannot be read (file name too long)"),
    (_with({}, {"init_from": "/nowhere.zip"}), "stages.0.init_from", "'/nowhere.zip': no such file; allowed: null, previous"),
    (_with({"stages": [{"name": f"s{k}", "scenarios": {"kind": "sparse"}, "budget": 1, "eval": {"suite": "sparse"}}
                       for k in range(65)]}), "stages", "List should have at most 64 items"),
    (_with({}, {"eval": {"suite": "sparse", "episodes": 10**9}}), "stages.0.eval.episodes", "less than or equal to 1000000"),
    (_with({}, {"budget": True}), "stages.0.budget", "Input should be a valid integer (got True)"),
    # A union's member tag (constrained-int) named no field and was printed as one.
    (_with({}, {"env_kwargs": {"action_delay": 10**9}}), "stages.0.env_kwargs.action_delay", "less than or equal to 20"),
    (_with({}, {"hyperparams": {"n_steps": 0}}), "stages.0.hyperparams.n_steps", "got 0; allowed: a whole number >= 1"),
    (_with({}, {"hyperparams": {"batch_size": 1}}), "stages.0.hyperparams.batch_size", "allowed: a whole number >= 2"),
    (_with({}, {"hyperparams": {"n_epochs": "five"}}), "stages.0.hyperparams.n_epochs", "got 'five'; allowed: a whole number"),
    (_with({}, {"hyperparams": {"gamma": 2.0}}), "stages.0.hyperparams.gamma", "got 2.0; allowed: a finite number > 0 and <= 1"),
    (_with({}, {"hyperparams": {"learning_rate": float("nan")}}), "stages.0.hyperparams.learning_rate", "got nan; allowed"),
    (_with({}, {"hyperparams": {"target_kl": -1}}), "stages.0.hyperparams.target_kl", "got -1; allowed: a finite number > 0"),
    (_with({}, {"hyperparams": {"use_sde": "yes"}}), "stages.0.hyperparams.use_sde", "allowed: true or false"),
    (_with({}, {"hyperparams": {"learning_rate": "cos_1e-3"}}), "stages.0.hyperparams.learning_rate", "'lin_<number>'"),
    (_with({}, {"algorithm": "td3", "hyperparams": {"action_noise": {"type": "pink"}}}),
     "stages.0.hyperparams.action_noise", "allowed: {type: normal | ornstein_uhlenbeck"),
    # Each of these passed `validate` and ended `run` in a traceback inside stable-baselines3.
    (_with({}, {"algorithm": "td3", "hyperparams": {"action_noise": {"type": "normal", "sigma": float("nan")}}}),
     "stages.0.hyperparams.action_noise.sigma", "expected a finite number >= 0, got nan"),
    (_with({}, {"hyperparams": {"ent_coef": "auto"}}), "stages.0.hyperparams.ent_coef", "got 'auto'; allowed: a number >= 0"),
    # An integer past a float's range overflowed math.isfinite: a traceback, not a refusal.
    (_with({}, {"algorithm": "sac", "hyperparams": {"ent_coef": 10**400}}), "stages.0.hyperparams.ent_coef",
     "allowed: a number >= 0, 'auto'"),
    (_with({}, {"algorithm": "sac", "hyperparams": {"action_noise": {"type": "normal", "sigma": 10**400}}}),
     "stages.0.hyperparams.action_noise.sigma", "expected a finite number >= 0"),
    (_with({}, {"algorithm": "sac", "hyperparams": {"ent_coef": "auto_-1"}}), "stages.0.hyperparams.ent_coef",
     "allowed: a number >= 0, 'auto' or 'auto_<initial value > 0>'"),
    (_with({}, {"algorithm": "sac", "hyperparams": {"target_entropy": "bogus"}}), "stages.0.hyperparams.target_entropy",
     "allowed: 'auto' or a finite number"),
    (_with({}, {"algorithm": "sac", "hyperparams": {"train_freq": -1}}), "stages.0.hyperparams.train_freq",
     "allowed: a whole number >= 1 (steps) or [n, step | episode]"),
    (_with({}, {"algorithm": "sac", "hyperparams": {"train_freq": [4, "hour"]}}), "stages.0.hyperparams.train_freq",
     "[n, step | episode]"),
    (_with({}, {"algorithm": "td3", "hyperparams": {"gradient_steps": 0}}), "stages.0.hyperparams.gradient_steps",
     "allowed: a whole number >= 1, or -1"),
    (_with({}, {"algorithm": "sac", "hyperparams": {"target_update_interval": 0}}),
     "stages.0.hyperparams.target_update_interval", "got 0; allowed: a whole number >= 1"),
    (_with({}, {"algorithm": "sac", "hyperparams": {"optimize_memory_usage": True}}),
     "stages.0.hyperparams.optimize_memory_usage", "got True; allowed: false"),
    (_with({}, {"algorithm": "sac", "hyperparams": {"use_sde_at_warmup": 1}}), "stages.0.hyperparams.use_sde_at_warmup",
     "allowed: true or false"),
    (_with({}, {"hyperparams": {"normalize_advantage": "maybe"}}), "stages.0.hyperparams.normalize_advantage",
     "got 'maybe'; allowed: true or false"),
    (_with({}, {"hyperparams": {"clip_range_vf": "abc"}}), "stages.0.hyperparams.clip_range_vf", "'lin_<number>'"),
    (_with({}, {"hyperparams": {"sde_sample_freq": -2}}), "stages.0.hyperparams.sde_sample_freq", "whole number >= -1"),
    (_with({}, {"n_envs": 1, "hyperparams": {"n_steps": 1}}), "stages.0.hyperparams.n_steps",
     "allowed: n_steps x n_envs of at least 2"),
    (_with({}, {"hyperparams": {"rollout_buffer_class": "x"}}), "stages.0.hyperparams.rollout_buffer_class",
     "takes code (a class or its arguments), which a curriculum does not name; allowed: batch_size,"),
    (_with({}, {"algorithm": "sac", "hyperparams": {"replay_buffer_kwargs": {"foo": 1}}}),
     "stages.0.hyperparams.replay_buffer_kwargs", "takes code"),
    (_with({}, {"scenarios": {"kind": "sparse"}, "env_kwargs": {"robot": {"radius": 1.5}}}), "stages.0.env_kwargs.robot",
     "no reachable sparse layout in 200 attempts (seed 0) for a robot of bounding radius 1.5 m"),
])
def test_schema_errors_name_the_field_and_what_is_allowed(data, field, message):
    with pytest.raises(ConfigError) as error:
        curriculum_from_mapping(data, "c.yaml")
    assert str(error.value).startswith(f"c.yaml: {field}: ") and message in str(error.value), str(error.value)


@pytest.mark.parametrize("world, scenarios, file, message", [
    ("flatland", None, "robot: {kinematics: omni}\n",
     "stages.0.scenarios: world.yaml: scenario: robot.kinematics: a curriculum stage drives a differential drive (v, w)"),
    ("physics3d", {"kind": "maze"}, None,
     "stages.0.scenarios: world: the physics3d tier does not build the 'maze' kind (grid_map: an occupancy grid map is "
     "not built in the 3D tier); allowed: "
     "open, sparse, cluttered, warehouse, trap, crowd, warehouse_moving, passages"),
    ("physics3d", None, "grid_map: {image: map.png}\n",
     "stages.0.scenarios: world.yaml: scenario: grid_map: an occupancy grid map is not built in the 3D tier"),
    ("physics3d", {"mix": {"sparse": 1, "maze": 1}}, None, "world: the physics3d tier does not build the 'maze' kind"),
    ("physics3d", None, "robot: {kinematics: omni}\n",
     "stages.0.scenarios: world.yaml: scenario: robot.kinematics: the 3D robot is a differential drive, not 'omni'"),
    ("flatland", {"suite": "crowd_unaware"}, None, "stages.0.scenarios: an eval-only suite 'crowd_unaware'; allowed: open, "),
    ("flatland", None, "MOVERS_ON_A_MAZE",
     "stages.0.scenarios: world.yaml: maze-train-0: grid_map: movers on a grid map are not modelled"),
    # The stage's robot is fine: the file's is what the 3D tier cannot build.
    ("physics3d", None, "OMNI_UNDER_THE_3D_ROBOT", "stages.0.scenarios: world.yaml: scenario: robot.kinematics: the 3D robot"),
    ("flatland", None, "A_CURRICULUM", "stages.0.scenarios: world.yaml: is a curriculum (it has stages)"),
])
def test_a_stage_whose_worlds_its_tier_or_its_policy_cannot_drive_is_refused(world, scenarios, file, message, tmp_path):
    """The worlds a stage's env would draw are checked as it validates, not when training starts."""
    from PIL import Image

    Image.new("L", (20, 20), 255).save(tmp_path / "map.png")
    special = {"MOVERS_ON_A_MAZE": _movers_on_a_maze, "OMNI_UNDER_THE_3D_ROBOT": lambda: "robot: {kinematics: omni}\n",
               "A_CURRICULUM": lambda: yaml.safe_dump(_tiny())}
    if file is not None:
        (tmp_path / "world.yaml").write_text(special[file]() if file in special else file)
        scenarios = {"file": "world.yaml"}
    env_kwargs = {"robot": "physics3d" if file == "OMNI_UNDER_THE_3D_ROBOT" else {"radius": 0.2}} if file in special else {}
    data = _with({}, {"world": world, "scenarios": scenarios, "normalize": False, "observation": "lidar43",
                      "env_kwargs": env_kwargs})
    path = tmp_path / "c.yaml"
    with pytest.raises(ConfigError) as error:
        curriculum_from_mapping(data, path)
    assert str(error.value).startswith(f"{path}: ") and message in str(error.value) and "\n" not in str(error.value), \
        str(error.value)


@pytest.mark.parametrize("data, what", [
    ({"world": {"width": 10, "height": 10}, "start": [1, 1, 0], "goal": [8, 8]}, "is a scenario"),
    ({"world": {"height": 10, "width": 10, "sample_time": 0.1}, "obstacle": []}, "is an IR-SIM world file"),
])
def test_a_world_file_given_as_a_curriculum_is_named_for_what_it_is(data, what):
    with pytest.raises(ConfigError) as error:
        curriculum_from_mapping(data, "w.yaml")
    assert str(error.value) == (f"w.yaml: {what}, not a curriculum (it has no stages); "
                                "try it with: curriculum compare --scenario-file FILE")
    with pytest.raises(ConfigError) as error:  # a curriculum's own keys (name, seed) do not make a scenario
        curriculum_from_mapping({"name": "x", "seed": 0, "stage": []}, "w.yaml")
    assert "not a curriculum" not in str(error.value)


def _movers_on_a_maze() -> str:
    """A maze with one person dashing across it: IR-SIM runs it, this project's tiers do not."""
    data = generate("maze", 0).model_dump(mode="json")
    data["obstacles"] = [{"type": "circle", "x": 1.0, "y": 1.0, "radius": 0.2,
                          "motion": {"behavior": {"name": "dash"}, "goals": [[2.0, 2.0]]}}]
    return yaml.safe_dump(data)


@pytest.mark.parametrize("env_kwargs, message", [
    ({"robot": {"radius": 0.2, "motion_noise": [0.01, 0.01, 0.01, 0.01]}, "world": "physics3d"},
     "stages.0.env_kwargs.robot.motion_noise: IR-SIM's kinematic stand-in is not modelled in the 3D tier"),
    ({"robot_family": True}, "stages.0.scenarios: world.yaml: robot_family: robots drawn per episode need worlds generated"),
])
def test_a_stage_whose_conditions_its_worlds_cannot_take_names_the_knob(env_kwargs, message, tmp_path):
    (tmp_path / "world.yaml").write_text("name: w\n")
    world = env_kwargs.pop("world", "flatland")
    scenarios = {"kind": "sparse"} if world == "physics3d" else {"file": "world.yaml"}
    data = _with({}, {"world": world, "scenarios": scenarios, "normalize": False, "observation": "lidar43",
                      "env_kwargs": env_kwargs})
    with pytest.raises(ConfigError) as error:
        curriculum_from_mapping(data, tmp_path / "c.yaml")
    assert message in str(error.value), str(error.value)


def test_shipped_curricula_validate(capsys):
    files = sorted(str(p) for p in (ROOT / "curricula").glob("*.yaml"))
    assert files and main(["validate", *files]) == 0
    assert capsys.readouterr().out.count("ok:") == len(files)


def _shape(root: Path) -> set[str]:
    """Files of a run directory, ignoring TensorBoard event names (they carry host and time)."""
    return {str(p.relative_to(root)) for p in root.rglob("*") if p.is_file() and "tensorboard" not in p.parts}


def _run(out: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "common.curriculum.cli", "run", str(TINY), "--out", str(out), *extra],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


class _Stop(Exception):
    """Raised in place of training, to look at a resumed model before it learns anything."""


def _resumed_model(run_dir: Path, monkeypatch):
    """The model a --resume of ``run_dir`` would start training, as it is handed to SB3's learn."""
    from stable_baselines3 import PPO

    from common.curriculum.runner import Runner

    captured = {}

    def learn(self, *args, **kwargs):
        captured["model"] = self
        raise _Stop

    monkeypatch.setattr(PPO, "learn", learn)
    with pytest.raises(_Stop):
        Runner(load_curriculum(TINY), run_dir, resume=True, progress=False).run()
    monkeypatch.undo()
    return captured["model"]


def _assert_resumed_exactly(model, checkpoint: Path, stage_seed_scenarios: list[str]) -> None:
    """The model, its optimiser, its step count and its normaliser are the checkpoint's, and its
    envs go on from the checkpoint's generators instead of starting the stage's sequence again."""
    import torch

    from common.curriculum.policy_file import PolicyFile

    file = PolicyFile(checkpoint)
    weights = file.tensors("policy.pth")
    assert weights.keys() == model.policy.state_dict().keys()
    assert all(torch.equal(model.policy.state_dict()[key], value) for key, value in weights.items())
    saved, live = file.tensors("policy.optimizer.pth")["state"], model.policy.optimizer.state_dict()["state"]
    assert saved.keys() == live.keys() and all(torch.equal(saved[k]["exp_avg"], live[k]["exp_avg"]) for k in saved)
    assert model.num_timesteps == file.manifest.timesteps > 0
    venv = model.get_env()
    normalizer = file.normalizer(venv.observation_space.shape[0])
    assert np.array_equal(venv.obs_rms.mean, normalizer.mean) and np.array_equal(venv.obs_rms.var, normalizer.var)
    assert venv.obs_rms.count == normalizer.count > 1000
    venv.reset()
    assert [s.name for s in venv.get_attr("scenario")] != stage_seed_scenarios


def _first_scenarios(stage_seed: int) -> list[str]:
    """The scenarios a fresh start of TINY's first stage gives its four envs."""
    from stable_baselines3.common.env_util import make_vec_env

    import flatland  # noqa: F401

    venv = make_vec_env("flatland/Nav-v0", n_envs=4, seed=stage_seed, env_kwargs={"world": "open", "difficulty": 0.2})
    venv.reset()
    return [s.name for s in venv.get_attr("scenario")]


@pytest.mark.slow
def test_run_writes_every_artefact_and_resumes_after_kill(tmp_path, monkeypatch):
    whole = tmp_path / "whole"
    # With the progress bar (SB3 needs tqdm and rich for it) and TensorBoard logging, as a user runs it.
    finished = _run(whole)
    assert finished.wait(timeout=300) == 0, finished.stdout.read()
    expected = {"config.yaml", "run.json", "state.json", "eval.csv", "report.md", "learning_curve.png",
                "stages/0-open/checkpoints/last.zip", "stages/0-open/best.zip", "stages/0-open/policy.zip",
                "stages/0-open/final_eval.json", "stages/1-sparse/policy.zip"}
    assert expected <= _shape(whole)
    assert any((whole / "stages/0-open/tensorboard").rglob("events.out.tfevents.*"))
    run = json.loads((whole / "run.json").read_text())
    assert run["package_version"] and "git_commit" in run and run["seed"] == 0
    # The machine, whose instructions decide how torch's kernels round: another trains other weights.
    import torch

    capability = torch.backends.cpu.get_cpu_capability()
    assert run["machine"]["cpu"] and run["machine"]["cores"] == os.cpu_count() and run["machine"]["cpu_capability"] == capability
    report = (whole / "report.md").read_text()
    assert "| open | ppo | nav7 | 6,144 |" in report
    assert f", on {run['machine']['cpu']} ({capability}, {os.cpu_count()} cores)" in report.splitlines()[2]
    from common.curriculum.policy_file import read_manifest

    manifest = read_manifest(whole / "stages/0-open/policy.zip")
    assert manifest["curriculum"] == "tiny" and manifest["observation"] == "nav7" and manifest["timesteps"] > 0
    assert manifest["machine"] == run["machine"]  # the machine that saved it, here the one the run started on
    assert manifest["final_eval"]["draw"] == "test" and manifest["final_eval"]["episodes"] == 6
    from common.curriculum.policy_file import PolicyFile
    from common.generators import get_suite

    # The final test draw is the suite's scenarios from seed 100,000: none of the validation draw's.
    tested = {r["scenario"] for r in csv.DictReader((whole / "stages/0-open/final_episodes.csv").open())}
    assert tested == {s.name for s in get_suite("open").scenarios(count=6, seed=100_000)}
    assert not tested & {s.name for s in get_suite("open").scenarios(count=4, seed=0)}
    # The second stage started from the first one's normaliser: its count goes on from there.
    first, second = PolicyFile(whole / "stages/0-open/policy.zip"), PolicyFile(whole / "stages/1-sparse/policy.zip")
    assert second.normalizer(7).count >= first.normalizer(7).count + second.manifest.timesteps

    killed = tmp_path / "killed"
    process = _run(killed, "--no-progress")
    last = killed / "stages/0-open/checkpoints/last.zip"
    deadline = time.time() + 240
    while not last.exists() and time.time() < deadline and process.poll() is None:
        time.sleep(0.05)
    assert process.poll() is None, "the run ended before it could be killed"
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    assert not (killed / "report.md").exists()
    assert (killed / ".lock").exists()  # the killed run's lock file stays; its OS lock died with it
    before = (killed / "eval.csv").read_text()
    # As if commits landed between the kill and the resume: the policies keep the run's start commit.
    provenance = json.loads((killed / "run.json").read_text())
    (killed / "run.json").write_text(json.dumps({**provenance, "git_commit": "commit-at-start"}))
    _assert_resumed_exactly(_resumed_model(killed, monkeypatch), last, _first_scenarios(stage_seed=0))
    resumed = _run(killed, "--resume", "--no-progress")
    assert resumed.wait(timeout=300) == 0, resumed.stdout.read()
    assert _shape(killed) == _shape(whole)

    assert read_manifest(killed / "stages/1-sparse/policy.zip")["git_commit"] == "commit-at-start"
    rows = list(csv.DictReader((killed / "eval.csv").open()))
    assert (killed / "eval.csv").read_text().startswith(before.splitlines()[0])
    for stage in ("open", "sparse"):
        steps = [int(r["timesteps"]) for r in rows if r["stage"] == stage]
        assert steps == sorted(set(steps)) and steps, f"{stage}: evaluations lost or repeated: {steps}"
    assert [int(r["timesteps"]) for r in rows if r["stage"] == "open"] == [1024 * k for k in range(1, 7)]


def test_resume_refuses_a_changed_or_missing_run(tmp_path, capsys):
    assert main(["run", str(TINY), "--out", str(tmp_path / "none"), "--resume"]) == 2
    assert "nothing to resume" in capsys.readouterr().err
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "something").write_text("x")
    assert main(["run", str(TINY), "--out", str(tmp_path / "full")]) == 2
    assert "not empty and not a run directory of this project" in capsys.readouterr().err


def _evaluate(agent, count: int = 20) -> float:
    from common.evaluation import evaluate
    from common.generators import get_suite

    (summary,) = evaluate([agent], get_suite("open").scenarios(count=count, seed=7), max_steps=150)
    return summary.success_rate


class RandomAgent:
    name = "random"

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def bind(self, robot, lidar, goal_threshold) -> None:
        self.robot = robot

    def reset(self) -> None:
        pass

    def act(self, readings, goal):
        return self.rng.uniform(0, self.robot.v_max), self.rng.uniform(-self.robot.w_max, self.robot.w_max)


@pytest.mark.slow
def test_short_ppo_training_beats_a_random_policy_and_round_trips(tmp_path):
    import torch
    from stable_baselines3 import PPO

    import flatland  # noqa: F401
    from common.curriculum.policy import load_policy
    from common.curriculum.policy_file import save_policy
    from common.policy_agent import PolicyAgent

    from stable_baselines3.common.env_util import make_vec_env

    torch.set_num_threads(1)
    env = make_vec_env("flatland/Nav-v0", n_envs=8, seed=0, env_kwargs=dict(
        world="open", observation="nav7", max_steps=150, reward={"progress": 10, "goal": 100, "collision": -100, "time": -0.05}))
    model = PPO("MlpPolicy", env, n_steps=128, batch_size=128, n_epochs=5, learning_rate=1e-3, seed=0, device="cpu")
    model.learn(40_000)
    trained = _evaluate(PolicyAgent(model, "nav7", 10.0, name="ppo"))
    random = _evaluate(RandomAgent(0))
    # Measured here: 95% against 0% (40k steps, about 15 s); the margin leaves room for other BLAS builds.
    assert trained >= random + 0.5, (trained, random)

    path = save_policy(model, tmp_path / "p.zip", {"algorithm": "ppo", "observation": "nav7", "goal_distance_scale": 10.0})
    loaded = load_policy(path)
    observations = np.random.default_rng(0).uniform(-1, 1, (50, 7)).astype(np.float32)
    assert np.array_equal(model.predict(observations, deterministic=True)[0],
                          loaded.model.predict(observations, deterministic=True)[0])


def test_eval_json_schema_and_bad_policy_files(tmp_path, capsys):
    import gymnasium as gym
    from stable_baselines3 import PPO

    import flatland  # noqa: F401
    from common.curriculum.policy_file import save_policy

    model = PPO("MlpPolicy", gym.make("flatland/Nav-v0", world="open"), n_steps=64, batch_size=64, device="cpu")
    path = save_policy(model, tmp_path / "p.zip", {"algorithm": "ppo", "observation": "nav7", "goal_distance_scale": 10.0})
    assert main(["eval", "--policy", str(path), "--suite", "open", "--episodes", "3", "--max-steps", "50", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert {"success_rate", "collision_rate", "timeout_rate", "spl", "mean_steps", "mean_path_length", "episodes"} <= set(result)
    assert result["episodes"] == 3
    (tmp_path / "junk.zip").write_text("not a zip")
    assert main(["eval", "--policy", str(tmp_path / "junk.zip")]) == 2
    assert "not a zip file" in capsys.readouterr().err
    assert main(["eval", "--policy", str(tmp_path / "missing.zip")]) == 2


def test_zoo_style_schedules_and_action_noise():
    from stable_baselines3.common.noise import NormalActionNoise

    from common.curriculum.hyperparams import resolve_hyperparams

    out = resolve_hyperparams({"learning_rate": "lin_1e-3", "action_noise": {"type": "normal", "sigma": 0.2}, "gamma": 0.98})
    assert out["learning_rate"](1.0) == pytest.approx(1e-3) and out["learning_rate"](0.25) == pytest.approx(2.5e-4)
    assert isinstance(out["action_noise"], NormalActionNoise) and out["gamma"] == 0.98
    np.testing.assert_array_equal(out["action_noise"]._sigma, [0.2, 0.2])  # the sigma asked for, per action
    out = resolve_hyperparams({"action_noise": {"type": "ornstein_uhlenbeck", "sigma": 0.3}})
    np.testing.assert_array_equal(out["action_noise"]._sigma, [0.3, 0.3])


@pytest.mark.parametrize("algorithm, hyperparams", [
    ("ppo", {"ent_coef": 0.01, "clip_range_vf": "lin_0.2", "normalize_advantage": False, "sde_sample_freq": -1,
             "stats_window_size": 10}),
    ("ppo", {"clip_range_vf": None}),
    ("sac", {"ent_coef": "auto_0.1", "target_entropy": -2.0, "train_freq": [1, "episode"], "gradient_steps": -1,
             "target_update_interval": 2, "optimize_memory_usage": False, "use_sde_at_warmup": False}),
    ("sac", {"ent_coef": 0.2, "target_entropy": "auto", "train_freq": 4}),
    ("td3", {"train_freq": [2, "step"], "gradient_steps": 2}),
])
def test_every_value_the_checks_allow_builds_the_model(algorithm, hyperparams):
    """What the checks let through, stable-baselines3 takes: a check stricter than SB3 would
    refuse a curriculum that trains."""
    import gymnasium as gym

    import flatland  # noqa: F401
    from common.curriculum.hyperparams import resolve_hyperparams
    from common.curriculum.policy import algorithm_class

    curriculum_from_mapping(_with({}, {"algorithm": algorithm, "hyperparams": hyperparams}), "c.yaml")
    env = gym.make("flatland/Nav-v0", world="open")
    model = algorithm_class(algorithm)("MlpPolicy", env, device="cpu", **resolve_hyperparams(hyperparams))
    model.learn(8)
    env.close()


def test_policy_zip_is_the_checkpoint_of_the_best_validation(tmp_path, monkeypatch):
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO

    import flatland  # noqa: F401
    from common.curriculum.policy_file import PolicyFile
    from common.curriculum.runner import Runner
    from common.curriculum.training import CurriculumCallback
    from common.evaluation import Episode, summarise

    config = load_curriculum(TINY)
    runner = Runner(config, tmp_path / "run", progress=False)
    runner.prepare()
    rates = iter([0.25, 0.75, 0.5])

    def scripted_evaluation(model, stage, normalizer, episodes, seed_shift):
        wins = int(next(rates) * 4)
        return summarise("policy", [Episode("policy", "s", i, "success" if i < wins else "timeout", 10, 1.0, 1.0,
                                            float(i < wins), 0.0) for i in range(4)])

    monkeypatch.setattr(runner, "evaluate_model", scripted_evaluation)
    model = PPO("MlpPolicy", gym.make("flatland/Nav-v0", world="open"), n_steps=64, batch_size=64, device="cpu")
    stage = config.stages[0]
    paths = runner.stage_paths(0, stage)
    callback = CurriculumCallback(runner, 0, stage, paths)
    weights = []
    for step in (1024, 2048, 3072):
        model.num_timesteps = step
        with torch.no_grad():
            for parameter in model.policy.parameters():
                parameter.add_(1.0)  # each checkpoint's weights differ
        weights.append({key: value.clone() for key, value in model.policy.state_dict().items()})
        callback._evaluate_and_checkpoint(model)
    callback.finish(model)
    runner.release()
    policy = PolicyFile(paths.policy)
    assert policy.manifest.timesteps == 2048 and policy.raw_manifest["eval"]["success_rate"] == 0.75
    assert all(torch.equal(policy.tensors("policy.pth")[key], value) for key, value in weights[1].items())
    assert PolicyFile(paths.last).manifest.timesteps == 3072


@pytest.mark.slow
def test_a_transfer_curriculum_writes_its_evidence(tmp_path, capsys, monkeypatch):
    from common.curriculum import runner
    from common.curriculum.policy_file import read_manifest
    from common.curriculum.vec_envs import PreloadedSubprocVecEnv

    # Both tiers' stages step their envs in subprocesses (the file asks so), where each tier must register.
    classes, original = [], runner.vec_env_class
    monkeypatch.setattr(runner, "vec_env_class", lambda name: classes.append(original(name)) or classes[-1])
    out = tmp_path / "transfer"
    assert main(["run", str(ROOT / "tests/data/tiny_transfer.yaml"), "--out", str(out), "--no-progress"]) == 0
    assert classes and set(classes) == {PreloadedSubprocVecEnv}
    assert "transfer over 2 seeds: zero-shot" in capsys.readouterr().out
    assert {p.name for p in (out / "evidence").iterdir()} == {"transfer-seed1000", "scratch-seed0", "scratch-seed1000"}
    state = json.loads((out / "state.json").read_text())
    transfer = read_manifest(out / "stages/1-three/policy.zip")["transfer"]
    for key in ("zero_shot_success", "fine_tuned_success", "scratch_success", "steps_to_90"):
        assert key in transfer and transfer[key] == state["transfer"][key]
    assert set(transfer["steps_to_90"]) == {"transfer", "scratch"}
    assert [r["seed"] for r in state["transfer"]["per_seed"]["scratch"]] == [1, 1001]  # the 3D stage's seeds
    assert "## Transfer" in (out / "report.md").read_text() and (out / "transfer.png").stat().st_size > 1000
    # Every arm is judged on the eval split; training draws from the train split.
    for run in (out, *(out / "evidence").iterdir()):
        for episodes in run.glob("stages/*/final_episodes.csv"):
            names = {r["scenario"] for r in csv.DictReader(episodes.open())}
            assert names and all("-eval-" in name for name in names), names
    # The 3D stage evaluated the URDF robot under physics3d's conditions, as it trained.
    assert read_manifest(out / "stages/1-three/policy.zip")["robot"]["v_max"] == 0.5


def test_a_stage_is_evaluated_within_its_own_goal_radius():
    from common.curriculum.stage import stage_radius

    config = curriculum_from_mapping(_with({}, {"env_kwargs": {"goal_threshold": [0.12, 0.5]}}), "c.yaml")
    assert stage_radius(config.stages[0]) == 0.12
    assert stage_radius(config.stages[1]) is None  # each scenario's own


def test_a_resumed_stage_logs_each_tensorboard_step_once(tmp_path):
    # A run killed after logging past its checkpoint logs those steps again when resumed from it.
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
    from torch.utils.tensorboard import SummaryWriter

    from common.curriculum.runner import _purge_tensorboard_after

    def log(steps: range) -> None:
        with SummaryWriter(str(tmp_path / "open_1")) as writer:
            for step in steps:
                writer.add_scalar("time/fps", float(step), step)

    log(range(1, 11))  # killed at step 10, its last checkpoint at step 5
    _purge_tensorboard_after(tmp_path, "open", 5)
    log(range(5, 13))  # the resumed run, from the checkpoint on
    steps = [event.step for event in EventAccumulator(str(tmp_path / "open_1")).Reload().Scalars("time/fps")]
    assert steps == list(range(1, 13))


@pytest.mark.parametrize("text, expected", [
    ("start: [1, 1, 0]\ngoal: [8, 8]\nrobot: {shape: box, length: 0.5, width: 0.3, w_max: 1.5}\n",
     {"shape": "box", "length": 0.5, "width": 0.3, "w_max": 1.5}),
    ("world: {height: 10, width: 10}\nrobot:\n  kinematics: {name: diff}\n  shape: {name: circle, radius: 0.35}\n"
     "  state: [1, 1, 0]\n  goal: [8, 8, 0]\n  vel_max: [0.8, 1.2]\n", {"shape": "circle", "radius": 0.35, "v_max": 0.8}),
])
def test_a_policy_trained_on_a_world_file_records_the_file_s_robot(tmp_path, text, expected):
    """The manifest said the template's 0.2 m circle while the env drove the file's robot; a
    deployment sets its robot from the manifest."""
    from common.curriculum.stage import manifest_for

    (tmp_path / "world.yaml").write_text(text)
    data = _with({}, {"scenarios": {"file": "world.yaml"}, "normalize": False})
    config = curriculum_from_mapping(data, tmp_path / "c.yaml")
    robot = manifest_for(config, None, 0, 0, 0.0, None)["robot"]
    assert {key: robot[key] for key in expected} == expected, robot


def test_a_report_interrupted_while_written_leaves_the_last_one_whole(tmp_path, monkeypatch):
    """A resume rewrites report.md and learning_curve.png: a kill then must not leave half a file."""
    from matplotlib.figure import Figure

    from common.curriculum.report import write_report
    from common.curriculum.schema import load_curriculum

    config = load_curriculum(Path(__file__).parents[1] / "curricula" / "stage1_2d.yaml")
    run = {"device": "cpu", "package_version": "0", "git_commit": None}
    rows = [{"stage": "sparse", "timesteps": "1000", "success_rate": "0.5", "spl": "0.4"}]
    write_report(tmp_path, config, {"stages": {}}, run, rows)
    before = {name: (tmp_path / name).read_bytes() for name in ("report.md", "learning_curve.png")}
    assert before["learning_curve.png"].startswith(b"\x89PNG")

    def killed_while_drawing(figure, path, **kwargs):
        Path(path).write_bytes(b"\x89PNG half")
        raise KeyboardInterrupt

    rows.append({"stage": "sparse", "timesteps": "2000", "success_rate": "0.9", "spl": "0.8"})
    monkeypatch.setattr(Figure, "savefig", killed_while_drawing)
    with pytest.raises(KeyboardInterrupt):
        write_report(tmp_path, config, {"stages": {}}, run, rows)
    assert {name: (tmp_path / name).read_bytes() for name in before} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["learning_curve.png", "report.md"]
