"""A policy exported to ONNX (``curriculum export POLICY.zip --onnx OUT.onnx``), run with
onnxruntime: no torch, no stable-baselines3 (``tests/test_onnx.py`` checks the import set).

An exported file holds the policy's actor as one graph:

* input ``observation``: float32 (batch, N), the observation layout its manifest names, raw (the
  observation normaliser the policy trained with is folded into the graph);
* output ``action``: float32 (batch, 2) in [-1, 1], the deterministic action (PPO's mean, SAC's
  squashed mean, TD3's actor), which the manifest's ``action_mapping`` turns into (v, w)
  (:mod:`common.actions`);
* metadata: ``nav_manifest``, the policy zip's manifest (layout, goal distance scale, action
  mapping, episode length, provenance), and ``nav_onnx``, what the export did (:data:`FORMAT`).

Opening a file runs nothing in it (ONNX is a graph of standard operators, no code), reads at most
:data:`MAX_ONNX_BYTES` and nothing beside it, and refuses in one line a file that is no ONNX model,
lacks or garbles the metadata, whose graph uses an operator the exporter does not write
(:data:`OPERATORS`: some compute for as long, or build tensors as large, as a file says), keeps a
tensor outside the file or a weight that is not finite, or does not read and write the sizes its
metadata promises. Checking the graph needs the ``onnx`` package beside onnxruntime (both in the
``onnx`` extra).
"""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from common.curriculum.policy_file import Manifest
from common.errors import ConfigError
from common.files import parse_json, read_bytes, size_text
from common.observations import make_layout
from common.policy_agent import PolicyAgent
from common.scenario import LidarSpec, RobotProfile

MANIFEST_KEY = "nav_manifest"
EXPORT_KEY = "nav_onnx"
FORMAT = 1
INPUT, OUTPUT = "observation", "action"
ACTION_SIZE = 2
MAX_ONNX_BYTES = 64 * 1024 * 1024  # as a policy zip: a network of 16 M float32 parameters
EXPECTED = "an ONNX policy written by `curriculum export`"
MAX_NODES = 256
MAX_ELEMENTS = 2**20  # values of one tensor, for one observation (a 256-wide layer holds 256)
MAX_WORK = 2**24  # multiply-adds an action (a 256 x 256 actor: about 80,000)
OPERATORS = frozenset({"Gemm", "MatMul", "Add", "Sub", "Mul", "Div", "Clip", "Tanh", "Relu", "Elu", "LeakyRelu",
                       "Gelu", "Sigmoid", "Identity"})
"""The operators of an exported actor: torch's exporter writes Gemm and the activation (every
``activation_fn`` a manifest may name: Tanh, Relu, Elu, LeakyRelu, Gelu, Sigmoid with Mul), Clip
and Tanh for the action, Sub, Div and Clip for a folded normaliser; MatMul, Add and Identity as
another exporter version may write them. None takes a subgraph or builds a tensor of a size it is given."""


class ExportRecord(BaseModel):
    """What the export did (the file's ``nav_onnx`` metadata)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    format: Literal[FORMAT]  # type: ignore[valid-type]
    observation_size: Annotated[int, Field(strict=True, ge=1, le=100_000)]
    normaliser_folded_in: Annotated[bool, Field(strict=True)]
    input: Literal[INPUT]  # type: ignore[valid-type]
    output: Literal[OUTPUT]  # type: ignore[valid-type]


def observation_size(manifest: Manifest) -> int:
    """How many values the manifest's observation layout holds."""
    return int(make_layout(manifest.observation, RobotProfile(), LidarSpec(), manifest.goal_distance_scale).space.shape[0])


def export_metadata(raw_manifest: dict[str, Any], normalised: bool) -> dict[str, str]:
    """The metadata an exported file carries (its keys and JSON values)."""
    manifest = Manifest.model_validate(raw_manifest)
    export = {"format": FORMAT, "observation_size": observation_size(manifest), "normaliser_folded_in": normalised,
              "input": INPUT, "output": OUTPUT}
    return {MANIFEST_KEY: json.dumps(raw_manifest), EXPORT_KEY: json.dumps(export)}


class OnnxPolicy:
    """An exported policy's actor, with SB3's ``predict`` call (so a :class:`PolicyAgent` drives it).

    ``threads``: onnxruntime's threads for one call; 1 suits one observation per control period
    (a batch of thousands gains from more).
    """

    def __init__(self, path: str | Path, threads: int = 1) -> None:
        self.path = Path(path)
        data = read_bytes(self.path, MAX_ONNX_BYTES, EXPECTED, too_large=f"expected {EXPECTED} of at most "
                          f"{size_text(MAX_ONNX_BYTES)}")
        try:
            import onnx
            import onnxruntime
        except ImportError:
            raise ConfigError(self.path, None, "running an ONNX policy needs onnx and onnxruntime: "
                              "pip install 'nav-curriculum[onnx]'") from None
        try:
            model = onnx.load_model_from_string(data)
        except Exception as exc:  # protobuf's DecodeError, onnx's own errors
            raise ConfigError(self.path, None, f"not an ONNX model ({type(exc).__name__}); refused") from None
        self._check_graph(model)
        options = onnxruntime.SessionOptions()
        options.intra_op_num_threads, options.inter_op_num_threads = threads, 1
        options.log_severity_level = 3  # its warnings are ours to phrase
        with tempfile.TemporaryDirectory() as nowhere:
            # Loaded from bytes, onnxruntime looks for external weight files in the working
            # directory; pointed at an empty one, it finds none (the graph check refuses them first).
            options.add_session_config_entry("session.model_external_initializers_file_folder_path", nowhere)
            try:
                self._session = onnxruntime.InferenceSession(data, options, providers=["CPUExecutionProvider"])
            except Exception as exc:  # onnxruntime raises its own Fail, InvalidGraph, InvalidProtobuf...
                raise ConfigError(self.path, None, f"not an ONNX model onnxruntime can run ({type(exc).__name__}); "
                                  "refused") from None
        metadata = self._session.get_modelmeta().custom_metadata_map
        self.raw_manifest = self._json(metadata, MANIFEST_KEY)
        self.manifest = self._validated(Manifest, self.raw_manifest, MANIFEST_KEY)
        self.size = observation_size(self.manifest)
        record = self._validated(ExportRecord, self._json(metadata, EXPORT_KEY), EXPORT_KEY)
        self._check_signature()
        if record.observation_size != self.size:
            raise ConfigError(self.path, f"{EXPORT_KEY}: observation_size", f"{record.observation_size}; the "
                              f"{self.manifest.observation} layout holds {self.size} values")

    def _check_graph(self, model: Any) -> None:
        """Only :data:`OPERATORS`, every tensor inside the file and every weight finite."""
        from onnx import TensorProto, numpy_helper

        graph = model.graph
        for node in graph.node:
            if node.domain not in ("", "ai.onnx") or node.op_type not in OPERATORS:
                raise ConfigError(self.path, "graph", f"operator {'.'.join(filter(None, (node.domain, node.op_type)))}; "
                                  f"allowed: {', '.join(sorted(OPERATORS))} (what `curriculum export` writes)")
        if graph.sparse_initializer or model.functions:
            raise ConfigError(self.path, "graph", f"sparse weights or functions; not {EXPECTED}")
        if len(graph.node) > MAX_NODES:
            raise ConfigError(self.path, "graph", f"{len(graph.node):,} operators; allowed: at most {MAX_NODES} "
                              "(an exported actor has a few dozen)")
        for tensor in graph.initializer:
            if tensor.data_location == TensorProto.EXTERNAL or tensor.external_data:
                raise ConfigError(self.path, f"graph weight {tensor.name!r}", "stored outside the file; allowed: "
                                  "weights inside it (as `curriculum export` writes them)")
            try:
                values = numpy_helper.to_array(tensor)
            except (ValueError, TypeError, KeyError):  # a shape its data does not fill, an unknown element type
                raise ConfigError(self.path, f"graph weight {tensor.name!r}", "its data does not fill its declared "
                                  "shape and type; refused") from None
            if values.dtype.kind == "f" and not np.isfinite(values).all():
                raise ConfigError(self.path, f"graph weight {tensor.name!r}", "holds a value that is not finite; refused")
        self._check_work(model)

    def _check_work(self, model: Any) -> None:
        """Every tensor the graph computes for one observation holds at most :data:`MAX_ELEMENTS`
        values and its products take at most :data:`MAX_WORK` multiply-adds, by ONNX's shape
        inference: a few operators reusing one large weight took seconds an action, and Add
        broadcasting (1, N) against (N, 1) built N x N values (gigabytes)."""
        from onnx import shape_inference

        try:
            inferred = shape_inference.infer_shapes(model, strict_mode=True).graph
        except Exception as exc:  # onnx's InferenceError and its kin
            raise ConfigError(self.path, "graph", f"its shapes do not follow from its input ({type(exc).__name__}); "
                              "refused") from None
        sizes: dict[str, list[int]] = {}
        for info in [*inferred.input, *inferred.value_info, *inferred.output]:
            dims = info.type.tensor_type.shape.dim
            if not all(d.HasField("dim_value") or d.HasField("dim_param") for d in dims):
                raise ConfigError(self.path, f"graph tensor {info.name!r}", "of a size shape inference cannot tell; refused")
            sizes[info.name] = shape = [d.dim_value if d.HasField("dim_value") else 1 for d in dims]  # a batch of one
            if (values := math.prod(shape)) > MAX_ELEMENTS:
                raise ConfigError(self.path, f"graph tensor {info.name!r}", f"{values:,} values for one observation; "
                                  f"allowed: at most {MAX_ELEMENTS:,}")
        for tensor in inferred.initializer:
            sizes[tensor.name] = list(tensor.dims)
        work = sum(math.prod(sizes.get(node.output[0], [0])) * (sizes.get(node.input[0]) or [1])[-1]
                   for node in inferred.node if node.op_type in ("Gemm", "MatMul"))
        if work > MAX_WORK:
            raise ConfigError(self.path, "graph", f"{work:,} multiply-adds an action; allowed: at most {MAX_WORK:,}")

    def _validated(self, model: type[BaseModel], data: dict, key: str) -> Any:
        """``data`` (the metadata entry ``key``) as ``model``, or its first problem in one line."""
        try:
            return model.model_validate(data)
        except ValidationError as exc:
            from common.scenario import pydantic_error

            error = pydantic_error(None, exc, model)
            raise ConfigError(self.path, f"{key}: {error.field}", error.problem) from None

    def _json(self, metadata: dict[str, str], key: str) -> dict:
        if key not in metadata:
            raise ConfigError(self.path, key, f"missing from the metadata; not {EXPECTED}")
        value = parse_json(metadata[key], self.path, key)
        if not isinstance(value, dict):
            raise ConfigError(self.path, key, "expected a JSON object")
        return value

    def _check_signature(self) -> None:
        """One input of (batch, layout size), one output of (batch, 2), both float32."""
        inputs, outputs = self._session.get_inputs(), self._session.get_outputs()
        layout = f"{self.manifest.observation} layout"
        for found, name, size, what in ((inputs, INPUT, self.size, f"the {layout}'s {self.size} values"),
                                        (outputs, OUTPUT, ACTION_SIZE, f"{ACTION_SIZE} action values")):
            shape = found[0].shape if len(found) == 1 and found[0].name == name else None
            if shape is None or len(shape) != 2 or shape[1] != size or found[0].type != "tensor(float)":
                got = ", ".join(f"{arg.name} {arg.type} {arg.shape}" for arg in found)
                raise ConfigError(self.path, f"graph {name}", f"expected one float tensor {name!r} of (batch, {size}): "
                                  f"{what}; the graph has {got}; refused")

    def predict(self, observation: np.ndarray, deterministic: bool = True) -> tuple[np.ndarray, None]:
        """The action for one observation (N,) or a batch (B, N), as SB3's ``predict`` returns it
        (the actor is deterministic: ``deterministic`` is accepted for that call's sake)."""
        obs = np.asarray(observation, dtype=np.float32)
        single = obs.ndim == 1
        try:
            actions = self._session.run(None, {INPUT: obs[None] if single else obs})[0]
        except Exception as exc:  # onnxruntime's Fail (a buffer it could not allocate), RuntimeException...
            raise ConfigError(self.path, None, f"onnxruntime could not run it ({type(exc).__name__}); refused") from None
        return (actions[0] if single else actions), None


def load_onnx_policy(path: str | Path, name: str | None = None, threads: int = 1) -> PolicyAgent:
    """A :class:`PolicyAgent` running an exported policy: it observes and acts as the policy zip did."""
    policy = OnnxPolicy(path, threads)
    manifest = policy.manifest
    name = name or Path(path).stem
    return PolicyAgent(policy, manifest.observation, manifest.goal_distance_scale, None,
                       name=name, action_mapping=manifest.action_mapping,
                       max_steps=manifest.max_steps, env_kwargs=manifest.env_kwargs, home=manifest.home,
                       tier=manifest.tier, reopen=(load_onnx_policy, (str(path), name, threads)))
