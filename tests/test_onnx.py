"""Policies exported to ONNX: the exported actor acts as the policy does, a damaged or mismatched
file is refused in one line, the runtime needs neither torch nor stable-baselines3, and the CLI
scores an exported policy as it scores its zip (docs/deploy.md)."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from common.errors import ConfigError
from tests.conftest import optional

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "curricula" / "policies"
OBSERVATIONS = 10_000
TOLERANCE = 1e-5


def _normalised_ppo(folder: Path) -> Path:
    """An untrained PPO policy (lidar43_log) with a normaliser far from the identity, so a graph
    without it, or with it applied wrongly, acts otherwise; its means reach past [-1, 1], where
    ``predict`` clips."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO

    import flatland  # noqa: F401
    from common.curriculum.policy_file import Normalizer, save_policy

    env = gym.make("flatland/Nav-v0", world="sparse", observation="lidar43_log")
    model = PPO("MlpPolicy", env, n_steps=64, batch_size=64, device="cpu", seed=0)
    with torch.no_grad():  # PPO's last layer starts near zero (gain 0.01): make its actions span [-1, 1], past it
        model.policy.action_net.weight.mul_(300.0)
    rng = np.random.default_rng(1)
    size = env.observation_space.shape[0]
    normalizer = Normalizer(rng.normal(0.0, 0.4, size), rng.uniform(0.0, 0.5, size), 3.0, 0.01, 1000.0)
    return save_policy(model, folder / "normalised_ppo.zip",
                       {"algorithm": "ppo", "observation": "lidar43_log", "goal_distance_scale": 10.0}, normalizer)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """name -> (policy zip, its ONNX export)."""
    optional("onnxruntime")
    from common.curriculum.onnx_export import export_onnx

    folder = tmp_path_factory.mktemp("onnx")
    zips = {name: SHIPPED / f"{name}.zip" for name in ("stage1_2d_ppo", "stage1_2d_sac", "stage1_2d_td3")}
    zips["normalised_ppo"] = _normalised_ppo(folder)
    return {name: (path, export_onnx(path, folder / f"{name}.onnx")) for name, path in zips.items()}


def _episode_observations(agent, count: int) -> np.ndarray:
    """Raw observations (before any normaliser) of ``agent`` driving held-out sparse episodes."""
    from common.generators import generate
    from flatland.world import World

    observations = []
    seed = 0
    while len(observations) < count:
        scenario = generate("sparse", seed, split="eval")
        world = World(scenario, seed=seed)
        readings = world.reset()
        agent.bind(scenario.robot, scenario.lidar)
        agent.reset()
        for _ in range(300):
            observations.append(agent.layout(readings, scenario.goal).copy())
            readings = world.step(*agent.act(readings, scenario.goal))
            if readings.collided or math.dist(readings.pose[:2], scenario.goal) < 0.1:
                break
        seed += 1
    return np.array(observations[:count], dtype=np.float32)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["stage1_2d_ppo", "stage1_2d_sac", "stage1_2d_td3", "normalised_ppo"])
def test_the_onnx_actor_acts_as_the_policy_over_10000_observations_of_real_episodes(exported, name):
    import torch

    from common.curriculum.onnx_policy import load_onnx_policy
    from common.curriculum.policy import load_policy

    zip_path, onnx_path = exported[name]
    runtime = load_onnx_policy(onnx_path)
    observations = _episode_observations(runtime, OBSERVATIONS)
    policy = load_policy(zip_path)
    inputs = observations if policy.normalizer is None else np.stack([policy.normalizer(o) for o in observations])
    with torch.no_grad():
        theirs, _ = policy.model.predict(inputs, deterministic=True)
    ours, _ = runtime.model.predict(observations)
    assert ours.shape == theirs.shape == (OBSERVATIONS, 2)
    assert np.abs(ours - theirs).max() <= TOLERANCE
    assert np.ptp(theirs, axis=0).min() > 0.1  # the episodes made the policy act, not sit at one action


def test_the_file_carries_the_policy_manifest_and_what_the_export_did(exported):
    from common.curriculum.onnx_policy import OnnxPolicy
    from common.curriculum.policy_file import PolicyFile

    zip_path, onnx_path = exported["normalised_ppo"]
    runtime = OnnxPolicy(onnx_path)
    assert runtime.raw_manifest == PolicyFile(zip_path).raw_manifest
    assert runtime.size == 43 and runtime.manifest.observation == "lidar43_log"


def _rewritten(source: Path, target: Path, change) -> Path:
    """The ONNX file with its model protobuf changed by ``change``."""
    onnx = optional("onnx")
    model = onnx.load_from_string(source.read_bytes())
    change(model)
    target.write_bytes(model.SerializeToString())
    return target


def _set_metadata(key: str, value: str | None):
    def change(model) -> None:
        kept = [(entry.key, entry.value) for entry in model.metadata_props if entry.key != key]
        del model.metadata_props[:]
        for k, v in kept + ([(key, value)] if value is not None else []):
            entry = model.metadata_props.add()
            entry.key, entry.value = k, v
    return change


def _manifest_with(**change):
    """The manifest's ``change``d keys over the same graph."""
    def rewrite(model) -> None:
        manifest = json.loads(next(e.value for e in model.metadata_props if e.key == "nav_manifest"))
        _set_metadata("nav_manifest", json.dumps({**manifest, **change}))(model)
    return rewrite


def _with_node(op_type: str, domain: str = ""):
    """A node of ``op_type`` added to the graph (unconnected: refused before anything runs it)."""
    def change(model) -> None:
        from onnx import helper

        model.graph.node.append(helper.make_node(op_type, ["observation"], ["unused"], domain=domain))
    return change


def _external_weight(model) -> None:
    """A weight stored in a file beside the model: onnxruntime read it from the working directory."""
    from onnx import TensorProto

    tensor = TensorProto(name="beside", data_type=TensorProto.UINT8, dims=[4], data_location=TensorProto.EXTERNAL)
    for key, value in (("location", "secret.bin"), ("offset", "0"), ("length", "4")):
        entry = tensor.external_data.add()
        entry.key, entry.value = key, value
    model.graph.initializer.append(tensor)


def _nan_weight(model) -> None:
    from onnx import numpy_helper

    first = model.graph.initializer[0]
    values = numpy_helper.to_array(first).copy()
    values.flat[0] = np.nan
    first.CopyFrom(numpy_helper.from_array(values, first.name))


def _unfilled_weight(model) -> None:
    """A weight whose declared shape its data does not fill (numpy's reshape raised a traceback)."""
    first = model.graph.initializer[0]
    del first.dims[:]
    first.dims.extend([2**31, 2**31])
    first.ClearField("raw_data")


def _reused_weight(nodes: int):
    """``nodes`` MatMuls of one 1024 x 1024 weight in a chain: seconds an action from a 4 MB file."""
    def change(model) -> None:
        from onnx import helper, numpy_helper

        model.graph.initializer.append(numpy_helper.from_array(np.zeros((1024, 1024), np.float32), "square"))
        model.graph.initializer.append(numpy_helper.from_array(np.zeros((43, 1024), np.float32), "widen"))
        names = ["observation"] + [f"h{k}" for k in range(nodes + 1)]
        model.graph.node.append(helper.make_node("MatMul", ["observation", "widen"], ["h0"]))
        for k in range(nodes):
            model.graph.node.append(helper.make_node("MatMul", [names[k + 1], "square"], [names[k + 2]]))
    return change


def _broadcast(model) -> None:
    """Add of (batch, 1, N) and (N, 1): (batch, N, N) values, gigabytes from a file of megabytes."""
    from onnx import helper, numpy_helper

    model.graph.initializer.append(numpy_helper.from_array(np.zeros((32768, 1), np.float32), "column"))
    model.graph.initializer.append(numpy_helper.from_array(np.zeros((43, 32768), np.float32), "row"))
    model.graph.node.append(helper.make_node("MatMul", ["observation", "row"], ["wide"]))
    model.graph.node.append(helper.make_node("Add", ["wide", "column"], ["square"]))


def _export_record(**change):
    record = {"format": 1, "observation_size": 43, "normaliser_folded_in": False, "input": "observation",
              "output": "action"}
    return _set_metadata("nav_onnx", json.dumps({**record, **change}))


@pytest.mark.parametrize(("case", "make", "field", "problem"), [
    ("truncated", lambda source, target: target.write_bytes(source.read_bytes()[:5000]) and target, None,
     "not an ONNX model"),
    ("not ONNX", lambda source, target: target.write_bytes(b"hello, robot\n" * 100) and target, None,
     "not an ONNX model"),
    ("no manifest", lambda source, target: _rewritten(source, target, _set_metadata("nav_manifest", None)),
     "nav_manifest", "missing from the metadata"),
    ("garbled manifest", lambda source, target: _rewritten(source, target, _set_metadata("nav_manifest", "{oops")),
     "nav_manifest", "not valid JSON"),
    ("unknown format", lambda source, target: _rewritten(source, target, _set_metadata("nav_onnx", '{"format": 9}')),
     "nav_onnx: format", "Input should be 1"),
    ("another layout", lambda source, target: _rewritten(source, target, _manifest_with(observation="nav7")),
     "graph observation", "expected one float tensor 'observation' of (batch, 7)"),
    ("unknown policy key", lambda source, target: _rewritten(source, target, _manifest_with(policy_kwargs={"net_arc": [8]})),
     "nav_manifest: policy_kwargs.net_arc", "unknown key (did you mean 'net_arch'?); allowed: activation_fn"),
    # What could run for as long, or build a tensor as large, as the file says (Loop, ConstantOfShape).
    ("a loop", lambda source, target: _rewritten(source, target, _with_node("Loop")), "graph",
     "operator Loop; allowed: Add, Clip, Div, Elu, Gelu, Gemm"),
    ("a custom domain", lambda source, target: _rewritten(source, target, _with_node("Relu", "com.example")), "graph",
     "operator com.example.Relu"),
    ("an external weight", lambda source, target: _rewritten(source, target, _external_weight),
     "graph weight 'beside'", "stored outside the file"),
    ("a NaN weight", lambda source, target: _rewritten(source, target, _nan_weight), "graph weight", "not finite"),
    # Each of these ended in a traceback, or ran for as long or built a tensor as large as the file said.
    ("an unfilled weight", lambda source, target: _rewritten(source, target, _unfilled_weight), "graph weight",
     "its data does not fill its declared shape and type"),
    ("too many operators", lambda source, target: _rewritten(source, target, _reused_weight(300)), "graph",
     "308 operators; allowed: at most 256"),
    ("a weight reused", lambda source, target: _rewritten(source, target, _reused_weight(20)), "graph",
     "multiply-adds an action; allowed: at most 16,777,216"),
    ("a broadcast", lambda source, target: _rewritten(source, target, _broadcast), "graph tensor 'square'",
     "1,073,741,824 values for one observation; allowed: at most 1,048,576"),
    ("a garbled export record", lambda source, target: _rewritten(source, target, _export_record(normaliser_folded_in="banana")),
     "nav_onnx: normaliser_folded_in", "Input should be a valid boolean"),
    ("another observation size", lambda source, target: _rewritten(source, target, _export_record(observation_size=99)),
     "nav_onnx: observation_size", "99; the lidar43_log layout holds 43 values"),
])
def test_a_damaged_or_mismatched_onnx_file_is_refused_in_one_line(exported, tmp_path, case, make, field, problem):
    from common.curriculum.onnx_policy import OnnxPolicy

    _, source = exported["stage1_2d_ppo"]
    path = make(source, tmp_path / "bad.onnx")
    with pytest.raises(ConfigError) as error:
        OnnxPolicy(path)
    # A field named in full, or by its start (a weight's field names the weight).
    named = error.value.field == field or (field is not None and error.value.field.startswith(field + " "))
    assert named and problem in error.value.problem, str(error.value)
    assert "\n" not in str(error.value)


@pytest.mark.slow
def test_the_cli_exports_scores_the_onnx_file_as_the_zip_and_refuses_bad_input_with_exit_2(exported, tmp_path, capsys):
    from common.curriculum.cli import main

    zip_path = SHIPPED / "stage1_2d_ppo.zip"
    out = tmp_path / "main.onnx"
    assert main(["export", str(zip_path), "--onnx", str(out)]) == 0
    scores = []
    for policy in (zip_path, out):
        capsys.readouterr()
        assert main(["eval", "--policy", str(policy), "--suite", "sparse", "--episodes", "6", "--json"]) == 0
        scores.append(json.loads(capsys.readouterr().out))
    # The same outcomes and steps; lengths within what actions 1e-6 apart move a robot.
    exact = ("episodes", "success_rate", "success_ci95", "collision_rate", "timeout_rate", "mean_steps")
    assert scores[0]["episodes"] == 6 and [scores[0][key] for key in exact] == [scores[1][key] for key in exact]
    for key in ("spl", "mean_path_length"):
        assert scores[0][key] == pytest.approx(scores[1][key], rel=1e-5)
    # Sent to worker processes, the ONNX file is opened again there and scores as here.
    assert main(["eval", "--policy", str(out), "--suite", "sparse", "--episodes", "6", "--json", "--jobs", "2"]) == 0
    assert json.loads(capsys.readouterr().out) == scores[1]
    (tmp_path / "folder.onnx").mkdir()
    named_onnx = tmp_path / "policy.onnx"  # a policy zip named .onnx: its export replaced it
    named_onnx.write_bytes(zip_path.read_bytes())
    for argv, expected in ((["export", str(ROOT / "README.md"), "--onnx", str(tmp_path / "x.onnx")], "README.md"),
                           (["export", str(named_onnx), "--onnx", str(tmp_path / "." / "policy.onnx")],
                            "is the policy being exported; allowed: another path"),
                           (["export", str(zip_path), "--onnx", str(tmp_path / "x.zip")], "ending in .onnx"),
                           (["export", str(zip_path), "--onnx", str(tmp_path / "folder.onnx")],
                            "folder.onnx' is a directory; allowed: the path of the .onnx file to write"),
                           (["eval", "--policy", str(ROOT / "README.md") + ".onnx"], "README.md.onnx")):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and expected in err and ".tmp" not in err, err
    assert not (tmp_path / "x.onnx").exists() and not any((tmp_path / "folder.onnx").iterdir())
    assert named_onnx.read_bytes() == zip_path.read_bytes()


def _example_loop() -> str:
    text = (ROOT / "docs" / "deploy.md").read_text()
    return re.search(r"## An example loop.*?```python\n(.*?)```", text, re.S).group(1)


def test_the_documented_robot_loop_runs_on_onnxruntime_alone_and_arrives(exported, tmp_path):
    _, onnx_path = exported["stage1_2d_ppo"]
    script = tmp_path / "example.py"
    script.write_text(_example_loop() + "\nprint('MODULES', ' '.join(sorted(sys.modules)))\n")
    result = subprocess.run([sys.executable, str(script), str(onnx_path)], capture_output=True, text=True,
                            cwd=tmp_path, timeout=300, check=True)
    lines = result.stdout.splitlines()
    loaded = set(lines[-1].split()[1:])
    assert "onnxruntime" in loaded
    assert not {m for m in loaded if m.split(".")[0] in ("torch", "stable_baselines3", "pymunk", "pybullet")}
    assert lines[-2] == "arrived"
    commands = [line for line in lines if line.startswith("t=")]
    assert 20 < len(commands) < 300  # it drove, and arrived before the loop ran out


def test_onnxruntime_is_not_let_read_weights_from_the_working_directory(exported, tmp_path, monkeypatch):
    """Behind the graph check: loaded from bytes, onnxruntime looked for a weight stored outside the
    file in the working directory (a policy file could read any file there, of any size)."""
    onnx = optional("onnx")
    from onnx import TensorProto, helper, numpy_helper

    from common.curriculum.onnx_policy import OnnxPolicy

    _, source = exported["stage1_2d_ppo"]
    model = onnx.load_from_string(source.read_bytes())
    for node in model.graph.node:
        node.output[:] = ["before" if name == "action" else name for name in node.output]
    tensor = TensorProto(name="beside", data_type=TensorProto.UINT8, dims=[4], data_location=TensorProto.EXTERNAL)
    for key, value in (("location", "secret.bin"), ("offset", "0"), ("length", "4")):
        entry = tensor.external_data.add()
        entry.key, entry.value = key, value
    model.graph.initializer.append(tensor)
    # action = before + 0 * max(the file's bytes): what onnxruntime loads the file for, unfolded.
    model.graph.initializer.append(numpy_helper.from_array(np.zeros((), dtype=np.float32), "zero"))
    model.graph.node.extend([helper.make_node("Cast", ["beside"], ["as_float"], to=TensorProto.FLOAT),
                             helper.make_node("ReduceMax", ["as_float"], ["largest"], keepdims=0),
                             helper.make_node("Mul", ["largest", "zero"], ["nothing"]),
                             helper.make_node("Add", ["before", "nothing"], ["action"])])
    path = tmp_path / "reads_beside.onnx"
    path.write_bytes(model.SerializeToString())
    (tmp_path / "secret.bin").write_bytes(b"abcd")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(OnnxPolicy, "_check_graph", lambda self, model: None)
    with pytest.raises(ConfigError, match="not an ONNX model onnxruntime can run"):
        OnnxPolicy(path)
