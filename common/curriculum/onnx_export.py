"""A policy zip's actor exported to ONNX (the file: :mod:`common.curriculum.onnx_policy`).

The graph is the deterministic action stable-baselines3's ``predict`` computes, with the
observation normaliser folded in before it: PPO's Gaussian mean (its tanh with ``bounded_mean``)
clipped to [-1, 1] (``predict`` clips to the action space), SAC's tanh of its mean, TD3's actor
(a tanh already). Export goes through torch's own exporter (``torch.onnx.export`` with ``dynamo=True``: ``torch.export``, then
onnxscript's translation); the batch dimension stays free.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import logging
import warnings
from pathlib import Path

import torch
from torch import nn

from common.atomic import atomic_write, writable_place
from common.curriculum.onnx_policy import INPUT, OUTPUT, export_metadata, observation_size
from common.curriculum.policy import load_policy
from common.curriculum.policy_file import Normalizer, PolicyFile
from common.errors import ConfigError


class DeterministicActor(nn.Module):
    """Raw observation -> the action ``predict(obs, deterministic=True)`` returns, as one module."""

    def __init__(self, policy: nn.Module, algorithm: str, normalizer: Normalizer | None) -> None:
        super().__init__()
        self.policy, self.algorithm = policy, algorithm
        self.normalised = normalizer is not None
        if normalizer is not None:
            # float64 statistics rounded once, as the zip's policy sees float32 observations.
            self.register_buffer("mean", torch.as_tensor(normalizer.mean, dtype=torch.float32))
            self.register_buffer("std", torch.as_tensor((normalizer.var + normalizer.epsilon) ** 0.5, dtype=torch.float32))
            self.clip = float(normalizer.clip)

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        if self.normalised:
            observation = torch.clamp((observation - self.mean) / self.std, -self.clip, self.clip)
        policy = self.policy
        if self.algorithm == "ppo":
            features = policy.extract_features(observation, policy.pi_features_extractor)
            mean = policy.action_net(policy.mlp_extractor.forward_actor(features))
            return torch.clamp(torch.tanh(mean) if policy.bounded_mean else mean, -1.0, 1.0)
        if self.algorithm == "sac":
            mean, _, _ = policy.actor.get_action_dist_params(observation)
            return torch.tanh(mean)
        return policy.actor(observation)


def export_onnx(policy_path: str | Path, out_path: str | Path) -> Path:
    """Write the policy zip's actor as an ONNX file (atomically); returns its path."""
    out_path = Path(out_path)
    if out_path.suffix.lower() != ".onnx":  # as eval tells an ONNX file from a zip
        raise ConfigError(None, "--onnx", f"{str(out_path)!r}: expected a file name ending in .onnx")
    if out_path.is_dir():
        raise ConfigError(None, "--onnx", f"{str(out_path)!r} is a directory; allowed: the path of the .onnx file to write")
    if out_path.resolve() == Path(policy_path).resolve():  # a policy named .onnx was replaced by its own export
        raise ConfigError(None, "--onnx", f"{str(out_path)!r} is the policy being exported; allowed: another path")
    missing = [name for name in ("onnx", "onnxscript") if importlib.util.find_spec(name) is None]
    if missing:
        raise ConfigError(None, "--onnx", f"exporting needs {' and '.join(missing)} (torch's exporter): "
                          "pip install 'nav-curriculum[onnx]'")
    file = PolicyFile(policy_path)
    writable_place(out_path, "--onnx")
    raw_manifest = dict(file.raw_manifest)
    agent = load_policy(file)
    actor = DeterministicActor(agent.model, file.manifest.algorithm, agent.normalizer).eval()
    example = torch.zeros(1, observation_size(file.manifest))
    # The exporter reports each pass on stdout and warns about what it skips (torchvision's operators).
    exporter_log = logging.getLogger("torch.onnx")
    level = exporter_log.level
    exporter_log.setLevel(logging.ERROR)
    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()), torch.no_grad():
            warnings.simplefilter("ignore")
            program = torch.onnx.export(actor, (example,), dynamo=True, external_data=False, verbose=False,
                                        input_names=[INPUT], output_names=[OUTPUT],
                                        dynamic_shapes=({0: torch.export.Dim("batch")},))
    finally:
        exporter_log.setLevel(level)
    model = program.model_proto
    for key, value in export_metadata(raw_manifest, actor.normalised).items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    return atomic_write(out_path, lambda tmp: tmp.write_bytes(model.SerializeToString()))
