"""The policy zip, read without running anything in it.

A policy zip is stable-baselines3's own zip (so anyone who trusts it can still ``PPO.load`` it)
plus two JSON files of ours:

* ``nav_manifest.json`` (:class:`Manifest`): the algorithm, the network as plain data
  (``policy_kwargs``), the observation layout and its distance scale, the action mapping, the
  episode length, and provenance (curriculum, stage, seed, commit, steps, evaluations).
* ``nav_normalizer.json`` (:class:`Normalizer`), when the policy saw normalised observations.

What this project reads back is only those two JSON files and the ``*.pth`` tensors, the latter
with ``torch.load(weights_only=True)``: a restricted unpickler that builds tensors and plain
containers and refuses anything else. SB3's ``data`` entry, which holds cloudpickled Python
objects, is never read. Every size is bounded before it is read, so a crafted zip costs neither
unbounded memory nor time.
"""

from __future__ import annotations

import json
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from common.actions import MAPPINGS
from common.atomic import atomic_write
from common.curriculum.hyperparams import PolicyKwargs
from common.errors import ConfigError
from common.observations import LAYOUTS
from common.task import MAX_STEPS

MANIFEST = "nav_manifest.json"
NORMALIZER = "nav_normalizer.json"
FORMAT = 2  # 2: the network as data (policy_kwargs, use_sde); format 1 files meant SB3's default network
ALGORITHMS = ("ppo", "sac", "td3")
MAX_ZIP_BYTES = 256 * 1024 * 1024
MAX_JSON_BYTES = 1024 * 1024
MAX_WEIGHTS_BYTES = 128 * 1024 * 1024


class Manifest(BaseModel):
    """What a policy zip says about itself; the fields this project acts on are validated, the
    rest (provenance, evaluations) is kept as it is."""

    model_config = ConfigDict(frozen=True, extra="allow", allow_inf_nan=False)

    format: Literal[1, 2]
    algorithm: Literal[ALGORITHMS]  # type: ignore[valid-type]
    observation: Literal[LAYOUTS]  # type: ignore[valid-type]
    goal_distance_scale: Annotated[float, Field(gt=0.0, le=1000.0)]
    action_mapping: Literal[MAPPINGS] = "linear"  # type: ignore[valid-type]
    max_steps: Annotated[int, Field(ge=1, le=MAX_STEPS)] = 500
    policy_kwargs: PolicyKwargs = PolicyKwargs()
    use_sde: bool = False
    timesteps: Annotated[int, Field(ge=0)] = 0
    n_updates: Annotated[int, Field(ge=0)] = 0
    env_kwargs: dict[str, Any] = {}

    @property
    def home(self) -> tuple[str, str, int, int] | None:
        """(tier, suite, first seed, episodes) of the policy's own test figure (``final_eval``), if valid."""
        from common.generators import SUITES
        from common.tiers import TIERS

        final, tier = getattr(self, "final_eval", None), getattr(self, "tier", "flatland")
        if not isinstance(final, dict) or tier not in TIERS:
            return None
        suite, seed, episodes = final.get("suite"), final.get("first_seed"), final.get("episodes")
        whole = all(isinstance(n, int) and not isinstance(n, bool) for n in (seed, episodes))
        valid = suite in SUITES and whole and 0 <= seed < 2**32 and 1 <= episodes <= 1_000_000
        return (tier, suite, seed, episodes) if valid else None

    @field_validator("env_kwargs")
    @classmethod
    def _valid_conditions(cls, value: dict[str, Any]) -> dict[str, Any]:
        from common.conditions import conditions_of

        try:
            conditions_of(value)
        except ConfigError as error:
            raise ValueError(f"{error.field}: {error.problem}") from None
        return value


@dataclass(frozen=True)
class Normalizer:
    """Observation normalisation as VecNormalize applies it: clip((obs - mean) / sqrt(var + eps)).

    ``count`` is the number of observations the statistics summarise: VecNormalize weighs new
    observations against it, so a restored normaliser without it would be overwritten by the
    first few observations of the next run.
    """

    mean: np.ndarray
    var: np.ndarray
    clip: float
    epsilon: float
    count: float

    @classmethod
    def from_vec_normalize(cls, venv) -> "Normalizer":
        rms = venv.obs_rms
        return cls(np.asarray(rms.mean, dtype=np.float64), np.asarray(rms.var, dtype=np.float64),
                   float(venv.clip_obs), float(venv.epsilon), float(rms.count))

    def apply_to(self, venv) -> None:
        """Restore these statistics into a VecNormalize."""
        venv.obs_rms.mean, venv.obs_rms.var, venv.obs_rms.count = self.mean.copy(), self.var.copy(), self.count

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return np.clip((obs - self.mean) / np.sqrt(self.var + self.epsilon), -self.clip, self.clip).astype(np.float32)

    def to_json(self) -> dict:
        return {"mean": self.mean.tolist(), "var": self.var.tolist(), "clip": self.clip, "epsilon": self.epsilon,
                "count": self.count}

    @classmethod
    def from_json(cls, data: Any, size: int, source: str | Path) -> "Normalizer":
        """Validated statistics for observations of ``size`` values (one-line errors)."""
        def bad(problem: str) -> ConfigError:
            return ConfigError(source, NORMALIZER, problem)

        if not isinstance(data, dict) or not {"mean", "var", "clip", "epsilon"} <= data.keys():
            raise bad("expected {mean, var, clip, epsilon, count}")
        try:
            mean, var = np.asarray(data["mean"], dtype=np.float64), np.asarray(data["var"], dtype=np.float64)
            clip, epsilon = float(data["clip"]), float(data["epsilon"])
            count = float(data.get("count", 1e-4))  # VecNormalize's initial count: files from before it was kept
        except (TypeError, ValueError):
            raise bad("mean and var must be lists of numbers; clip, epsilon and count numbers") from None
        if mean.shape != (size,) or var.shape != (size,):
            raise bad(f"mean and var must hold {size} values each (the observation's size)")
        if not (np.isfinite(mean).all() and np.isfinite(var).all() and (var >= 0).all()):
            raise bad("mean and var must be finite, var not negative")
        if not all(math.isfinite(v) and v > 0 for v in (clip, epsilon, count)):
            raise bad("clip, epsilon and count must be positive numbers")
        return cls(mean, var, clip, epsilon, count)


def manifest_network(model) -> dict[str, Any]:
    """The manifest fields that describe a model's network (ValueError for a network they cannot describe)."""
    kwargs = PolicyKwargs.from_sb3(model.policy_kwargs)
    return {"policy_kwargs": kwargs.model_dump(exclude_none=True), "use_sde": bool(getattr(model, "use_sde", False))}


def save_policy(model, path: str | Path, manifest: dict[str, Any], normalizer: Normalizer | None = None) -> Path:
    """Save an SB3 model with the manifest (and normaliser) inside its zip, atomically.

    The manifest gets the format, the network (from the model itself) and its step count.
    """
    manifest = {"format": FORMAT, **manifest_network(model), "timesteps": int(model.num_timesteps),
                "n_updates": int(getattr(model, "_n_updates", 0)), **manifest}
    Manifest.model_validate(manifest)  # never write a file this project would refuse to read

    def write(tmp: Path) -> None:
        model.save(tmp)
        # SB3 appends ".zip" to a name without it: our temporary name ends in .tmp.
        saved = tmp if tmp.stat().st_size else tmp.with_name(tmp.name + ".zip")
        if saved != tmp:
            saved.replace(tmp)
        with zipfile.ZipFile(tmp, "a") as archive:
            archive.writestr(MANIFEST, json.dumps(manifest, indent=2))
            if normalizer is not None:
                archive.writestr(NORMALIZER, json.dumps(normalizer.to_json()))

    return atomic_write(Path(path), write)


class PolicyFile:
    """A policy zip opened for reading: sizes bounded, the manifest validated, nothing executed.

    ``require_manifest=False`` also opens an SB3 zip from elsewhere (``manifest`` is then None):
    its weights can seed a new stage, though nothing says how to observe for it.
    """

    manifest: Manifest | None

    def __init__(self, path: str | Path, require_manifest: bool = True) -> None:
        self.path = Path(path)
        try:
            size = self.path.stat().st_size
            if size > MAX_ZIP_BYTES:
                raise ConfigError(self.path, None, f"larger than {MAX_ZIP_BYTES // 2**20} MiB; not a policy of this project")
            with zipfile.ZipFile(self.path) as archive:
                self.members = {info.filename: info for info in archive.infolist()}
        except FileNotFoundError:
            raise ConfigError(self.path, None, "no such file") from None
        except (zipfile.BadZipFile, IsADirectoryError, OSError):
            raise ConfigError(self.path, None, "not a zip file; expected a policy saved by `curriculum run`") from None
        if MANIFEST not in self.members:
            if not require_manifest:
                self.manifest, self.raw_manifest = None, {}
                return
            raise ConfigError(self.path, None, f"not a policy of this project (no {MANIFEST}); train one with `curriculum run`")
        self.raw_manifest = self.json(MANIFEST)
        try:
            self.manifest = Manifest.model_validate(self.raw_manifest)
        except ValidationError as exc:
            from common.scenario import pydantic_error

            error = pydantic_error(None, exc)
            raise ConfigError(self.path, f"{MANIFEST}: {error.field}" if error.field else MANIFEST, error.problem) from None

    def _read(self, name: str, limit: int) -> bytes:
        info = self.members.get(name)
        if info is None:
            raise ConfigError(self.path, name, "missing from the zip")
        if info.file_size > limit:
            raise ConfigError(self.path, name, f"larger than {limit // 2**20} MiB; refused")
        with zipfile.ZipFile(self.path) as archive, archive.open(info) as handle:
            data = handle.read(limit + 1)  # the header's size may lie: never read past the limit
        if len(data) > limit:
            raise ConfigError(self.path, name, f"larger than {limit // 2**20} MiB; refused")
        return data

    def json(self, name: str) -> Any:
        """A JSON member, parsed."""
        try:
            return json.loads(self._read(name, MAX_JSON_BYTES))
        except (UnicodeDecodeError, json.JSONDecodeError, RecursionError):
            raise ConfigError(self.path, name, "not valid JSON") from None

    def has(self, name: str) -> bool:
        return name in self.members

    def tensors(self, name: str, device: str = "cpu") -> Any:
        """A ``.pth`` member as tensors and plain containers (weights only: no code runs)."""
        import io

        import torch

        data = self._read(name, MAX_WEIGHTS_BYTES)
        try:
            return torch.load(io.BytesIO(data), map_location=device, weights_only=True)
        except Exception as exc:  # torch raises UnpicklingError, RuntimeError and more for a bad file
            raise ConfigError(self.path, name, f"not plain weights ({type(exc).__name__}); refused") from None

    def normalizer(self, size: int) -> Normalizer | None:
        """The normaliser, validated for observations of ``size`` values, or None if there is none."""
        if not self.has(NORMALIZER):
            return None
        return Normalizer.from_json(self.json(NORMALIZER), size, self.path)


def read_manifest(path: str | Path) -> dict[str, Any]:
    """The validated manifest of a policy zip, as a dict (one-line errors for anything else)."""
    return PolicyFile(path).raw_manifest


def update_manifest(path: str | Path, extra: dict[str, Any]) -> Path:
    """Add keys to a policy zip's manifest (the zip is rebuilt and swapped in atomically)."""
    manifest = {**read_manifest(path), **extra}
    Manifest.model_validate(manifest)

    def write(tmp: Path) -> None:
        with zipfile.ZipFile(path) as source, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as target:
            for item in source.infolist():
                data = json.dumps(manifest, indent=2).encode() if item.filename == MANIFEST else source.read(item)
                target.writestr(item, data)

    return atomic_write(Path(path), write)
