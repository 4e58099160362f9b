"""Policies as self-describing zips: stable-baselines3's own zip plus a manifest and normaliser.

The manifest (``nav_manifest.json`` inside the zip) names the algorithm, the observation layout
and its distance scale, so :func:`load_policy` can rebuild exactly the observations the policy was
trained on; observation-normaliser statistics travel as ``nav_normalizer.json``. Writes are atomic
(a temporary file renamed over the target), so a kill never leaves half a zip behind.
"""

from __future__ import annotations

import json
import os
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from common.actions import ActionMapping
from common.errors import ConfigError
from common.observations import ObservationLayout, make_layout
from common.readings import Readings
from common.scenario import LidarSpec, RobotProfile

MANIFEST = "nav_manifest.json"
NORMALIZER = "nav_normalizer.json"
FORMAT = 1
_UMASK = os.umask(0)
os.umask(_UMASK)


def algorithm_class(name: str):
    """The stable-baselines3 class of an algorithm name."""
    from stable_baselines3 import PPO, SAC, TD3

    return {"ppo": PPO, "sac": SAC, "td3": TD3}[name]


@dataclass(frozen=True)
class Normalizer:
    """Observation normalisation as VecNormalize applies it: clip((obs - mean) / sqrt(var + eps))."""

    mean: np.ndarray
    var: np.ndarray
    clip: float
    epsilon: float

    @classmethod
    def from_vec_normalize(cls, venv) -> "Normalizer":
        rms = venv.obs_rms
        return cls(np.asarray(rms.mean, dtype=np.float64), np.asarray(rms.var, dtype=np.float64),
                   float(venv.clip_obs), float(venv.epsilon))

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return np.clip((obs - self.mean) / np.sqrt(self.var + self.epsilon), -self.clip, self.clip).astype(np.float32)

    def to_json(self) -> dict:
        return {"mean": self.mean.tolist(), "var": self.var.tolist(), "clip": self.clip, "epsilon": self.epsilon}

    @classmethod
    def from_json(cls, data: dict) -> "Normalizer":
        return cls(np.asarray(data["mean"]), np.asarray(data["var"]), float(data["clip"]), float(data["epsilon"]))


def atomic_write(path: Path, write) -> Path:
    """Call ``write(tmp_path)`` then rename the temporary file over ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(handle)
    try:
        write(Path(tmp))
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600 files; give the usual permissions
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def save_policy(model, path: str | Path, manifest: dict[str, Any], normalizer: Normalizer | None = None) -> Path:
    """Save an SB3 model with the manifest (and normaliser) inside its zip, atomically."""

    def write(tmp: Path) -> None:
        model.save(tmp)
        # SB3 appends ".zip" to a name without it: our temporary name ends in .tmp.
        saved = tmp if tmp.stat().st_size else tmp.with_name(tmp.name + ".zip")
        if saved != tmp:
            os.replace(saved, tmp)
        with zipfile.ZipFile(tmp, "a") as archive:
            archive.writestr(MANIFEST, json.dumps({"format": FORMAT, **manifest}, indent=2))
            if normalizer is not None:
                archive.writestr(NORMALIZER, json.dumps(normalizer.to_json()))

    return atomic_write(Path(path), write)


def update_manifest(path: str | Path, extra: dict[str, Any]) -> Path:
    """Add keys to a policy zip's manifest (the zip is rebuilt and swapped in atomically)."""
    manifest, _ = read_manifest(path)
    manifest.update(extra)

    def write(tmp: Path) -> None:
        with zipfile.ZipFile(path) as source, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as target:
            for item in source.infolist():
                data = json.dumps(manifest, indent=2).encode() if item.filename == MANIFEST else source.read(item)
                target.writestr(item, data)

    return atomic_write(Path(path), write)


def read_manifest(path: str | Path) -> tuple[dict, Normalizer | None]:
    """The manifest and normaliser of a policy zip (one-line errors for anything else)."""
    path = Path(path)
    try:
        with zipfile.ZipFile(path) as archive:
            names = set(archive.namelist())
            if MANIFEST not in names:
                raise ConfigError(path, None, f"not a policy of this project (no {MANIFEST}); train one with `curriculum run`")
            manifest = json.loads(archive.read(MANIFEST))
            normalizer = Normalizer.from_json(json.loads(archive.read(NORMALIZER))) if NORMALIZER in names else None
    except FileNotFoundError:
        raise ConfigError(path, None, "no such file") from None
    except (zipfile.BadZipFile, IsADirectoryError):
        raise ConfigError(path, None, "not a zip file; expected a policy saved by `curriculum run`") from None
    return manifest, normalizer


class PolicyAgent:
    """A trained policy driven like a controller: readings -> observation -> action -> (v, w).

    It builds its observations with the layout in its manifest, so evaluation in either tier
    sees what the policy saw in training.
    """

    def __init__(self, model, observation: str, goal_distance_scale: float, normalizer: Normalizer | None = None,
                 name: str = "policy", action_mapping: str = "linear") -> None:
        self.model, self.observation, self.goal_distance_scale = model, observation, goal_distance_scale
        self.normalizer, self.name, self.action_mapping = normalizer, name, action_mapping

    def bind(self, robot: RobotProfile, lidar: LidarSpec) -> None:
        self.layout: ObservationLayout = make_layout(self.observation, robot, lidar, self.goal_distance_scale)
        self.mapping = ActionMapping(robot, self.action_mapping)

    def reset(self) -> None:
        pass

    def observe(self, readings: Readings, goal: tuple[float, float]) -> np.ndarray:
        obs = self.layout(readings, goal)
        return self.normalizer(obs) if self.normalizer is not None else obs

    def act(self, readings: Readings, goal: tuple[float, float]) -> tuple[float, float]:
        action, _ = self.model.predict(self.observe(readings, goal), deterministic=True)
        return self.mapping.to_velocity(action)


def load_policy(path: str | Path, device: str = "cpu", name: str | None = None) -> PolicyAgent:
    """A :class:`PolicyAgent` from a policy zip."""
    manifest, normalizer = read_manifest(path)
    model = algorithm_class(manifest["algorithm"]).load(str(path), device=device)
    if name is None:
        # A run's files are all called policy/best/last.zip: name those by curriculum and stage.
        stem = Path(path).stem
        generic = stem in ("policy", "best", "last") and "curriculum" in manifest
        name = f"{manifest['curriculum']}/{manifest['stage']}" if generic else stem
    return PolicyAgent(model, manifest["observation"], manifest["goal_distance_scale"], normalizer,
                       name=name, action_mapping=manifest.get("action_mapping", "linear"))
