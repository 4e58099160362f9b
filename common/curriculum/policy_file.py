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
unbounded memory nor time:

* the zip is read through :mod:`common.files` (a regular file, at most :data:`MAX_ZIP_BYTES`,
  whatever its size header says), and its member count (:data:`MAX_MEMBERS`) and central
  directory size are checked from its end record *before* :mod:`zipfile` lists the members;
* each member's uncompressed size is checked against its cap before it is decompressed, and its
  CRC-32 when it has been read whole (a bad CRC or a size header that lies is one line);
* a ``.pth`` member is itself a zip (torch's format): its record count (:data:`MAX_TENSOR_RECORDS`)
  and its pickle (:data:`MAX_PICKLE_BYTES`) are bounded before ``torch.load`` unpickles it, the
  tensors it builds may not add up to more than the member's cap (views repeating one small
  storage would), and every floating value must be finite.

The caps, against the shipped policies (the largest zip 3.8 MB, 9 members, ``policy.pth`` 1.9 MB,
its pickle 5 kB) and the largest network a manifest may describe by its shape (SAC, 16 layers, 10
critics: a ``policy.pth`` of 722 records and a 105 kB pickle):

==================================  ==========  =====================================================
what                                cap         why
==================================  ==========  =====================================================
the zip file                        64 MiB      17x the largest shipped policy
members                             16          SB3 writes 7 or 8, this project 1 or 2 more
central directory                   64 KiB      16 members of 4 KiB each
JSON member (manifest, normaliser)  1 MiB       the manifest is 2 kB
any other member, uncompressed      64 MiB      a network of 16 M float32 parameters
all members together, uncompressed  256 MiB     4x the zip: what deflate does to float weights
records in a ``.pth`` (its zip)     2048        a tensor each: 2.8x the 722 of that SAC (62 bytes of
                                                directory each; 256 allowed)
a ``.pth``'s pickle                 256 KiB     2.5x that SAC's (a million tiny values fit in 1 MiB)
==================================  ==========  =====================================================

The worst accepted: a PPO zip of 63.4 MiB (a ``policy.pth`` of 16.6 M parameters) loads in 0.3 s
and 250 MB over the imports; a 256 KiB pickle of 261,000 empty lists is refused in 0.8 s and 55 MB.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Callable, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, field_validator

from common.actions import MAPPINGS
from common.atomic import atomic_write
from common.curriculum.hyperparams import PolicyKwargs
from common.errors import ConfigError
from common.files import ZIP_DAMAGE, open_zip, parse_json, read_bytes, size_text, zip_damage
from common.generators import SUITES
from common.observations import LAYOUTS
from common.task import MAX_STEPS
from common.tiers import TIERS

MANIFEST = "nav_manifest.json"
NORMALIZER = "nav_normalizer.json"
FORMAT = 2  # 2: the network as data (policy_kwargs, use_sde); format 1 files meant SB3's default network
ALGORITHMS = ("ppo", "sac", "td3")
MAX_ZIP_BYTES = 64 * 1024 * 1024
MAX_MEMBERS = 16
MAX_DIRECTORY_BYTES = 64 * 1024
MAX_JSON_BYTES = 1024 * 1024
MAX_WEIGHTS_BYTES = 64 * 1024 * 1024  # any member but the JSON ones, uncompressed
MAX_UNCOMPRESSED_BYTES = 256 * 1024 * 1024
MAX_TENSOR_RECORDS = 2048
MAX_PICKLE_BYTES = 256 * 1024
_EMPTY_ZIP = b"PK\x05\x06" + b"\0" * 18


class FinalEval(BaseModel):
    """A policy's own test figure (``final_eval``): where ``curriculum eval`` evaluates it by default.
    The figures beside these three fields are kept as written."""

    model_config = ConfigDict(frozen=True, extra="allow", allow_inf_nan=False)

    suite: Literal[tuple(SUITES)]  # type: ignore[valid-type]
    first_seed: Annotated[int, Field(strict=True, ge=0, lt=2**32)]
    episodes: Annotated[int, Field(strict=True, ge=1, le=1_000_000)]


MAX_TIMESTEPS = 10**12  # a thousand years of training at this machine's 30,000 env steps/s


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
    # Bounded: 10**30 steps passed, and a resume's TensorBoard purge failed on it with a traceback.
    timesteps: Annotated[int, Field(ge=0, le=MAX_TIMESTEPS)] = 0
    n_updates: Annotated[int, Field(ge=0, le=MAX_TIMESTEPS)] = 0
    tier: Literal[TIERS] = "flatland"  # type: ignore[valid-type]  # where it trained last
    env_kwargs: dict[str, Any] = {}  # after tier: checked for it
    final_eval: FinalEval | None = None  # written by the runner when the policy's stage ends

    @property
    def home(self) -> tuple[str, str, int, int] | None:
        """(tier, suite, first seed, episodes) of the policy's own test figure, if it has one."""
        final = self.final_eval
        return None if final is None else (self.tier, final.suite, final.first_seed, final.episodes)

    @field_validator("env_kwargs")
    @classmethod
    def _valid_env_kwargs(cls, value: dict[str, Any], info: ValidationInfo) -> dict[str, Any]:
        """As a stage's ``env_kwargs`` are checked: a policy is refused when it is opened, not at its first use."""
        from common.task import check_env_kwargs

        if "tier" in info.data:  # else the tier's own error is the one to report
            try:
                check_env_kwargs(value, info.data["tier"], None, "env_kwargs")
            except ConfigError as error:
                raise ValueError(f"{error.field.removeprefix('env_kwargs.')}: {error.problem}") from None
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
    return atomic_write(Path(path), policy_writer(model, manifest, normalizer))


def policy_writer(model, manifest: dict[str, Any], normalizer: Normalizer | None = None) -> Callable[[Path], None]:
    """What :func:`save_policy` writes, as a function of the file to write it to (for
    :func:`~common.atomic.atomic_write_all`, which writes a set of files together)."""
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

    return write


class PolicyFile:
    """A policy zip opened for reading: sizes bounded, the manifest validated, nothing executed.

    ``require_manifest=False`` also opens an SB3 zip from elsewhere (``manifest`` is then None):
    its weights can seed a new stage, though nothing says how to observe for it.
    """

    manifest: Manifest | None

    def __init__(self, path: str | Path, require_manifest: bool = True) -> None:
        self.path = Path(path)
        data = read_bytes(self.path, MAX_ZIP_BYTES, "a policy zip saved by `curriculum run`",
                          too_large="not a policy of this project")
        self._archive = open_zip(data, self.path, None, MAX_MEMBERS, MAX_DIRECTORY_BYTES, "a policy saved by `curriculum run`")
        self.members: dict[str, zipfile.ZipInfo] = {}
        for info in self._archive.infolist():
            if info.filename in self.members:
                raise ConfigError(self.path, info.filename, "appears twice in the zip; refused")
            self.members[info.filename] = info
        total = sum(info.file_size for info in self.members.values())
        if total > MAX_UNCOMPRESSED_BYTES:
            raise ConfigError(self.path, None, f"its members hold {size_text(total)} uncompressed; allowed: at most "
                              f"{size_text(MAX_UNCOMPRESSED_BYTES)}; refused")
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

            error = pydantic_error(None, exc, Manifest)
            raise ConfigError(self.path, f"{MANIFEST}: {error.field}" if error.field else MANIFEST, error.problem) from None

    def read(self, name: str, limit: int = MAX_WEIGHTS_BYTES) -> bytes:
        """A member's bytes: its size checked before it is decompressed, its CRC-32 once it is read whole."""
        info = self.members.get(name)
        if info is None:
            raise ConfigError(self.path, name, "missing from the zip")
        if info.file_size > limit:
            raise ConfigError(self.path, name, f"larger than {size_text(limit)}; refused")
        try:
            with self._archive.open(info) as handle:
                data = handle.read(limit + 1)  # zipfile stops at the header's size and checks the CRC there
        except ZIP_DAMAGE as exc:
            raise ConfigError(self.path, name, f"{zip_damage(exc)}; refused") from None
        if len(data) > limit:
            raise ConfigError(self.path, name, f"larger than {size_text(limit)}; refused")
        if len(data) != info.file_size:  # zipfile stops early, without a word, when the header says more
            raise ConfigError(self.path, name, f"{zip_damage(zipfile.BadZipFile('size'))}; refused")
        return data

    def json(self, name: str) -> Any:
        """A JSON member, parsed."""
        return parse_json(self.read(name, MAX_JSON_BYTES), self.path, name)

    def has(self, name: str) -> bool:
        return name in self.members

    def tensors(self, name: str, device: str = "cpu") -> Any:
        """A ``.pth`` member as tensors and plain containers (weights only: no code runs), every
        floating value finite; bounded before and after ``torch.load`` (see the module's caps)."""
        import torch

        data = self.read(name, MAX_WEIGHTS_BYTES)
        try:  # torch's format is a zip: its records counted, its pickle bounded, before torch reads it
            archive = open_zip(data, self.path, name, MAX_TENSOR_RECORDS, MAX_TENSOR_RECORDS * 256, "torch's zip format")
        except ConfigError as error:
            raise ConfigError(self.path, name, f"not plain weights ({error.problem}); refused") from None
        with archive:
            pickles = [info for info in archive.infolist() if info.filename.endswith(".pkl")]
        if not pickles or any(info.file_size > MAX_PICKLE_BYTES for info in pickles):
            raise ConfigError(self.path, name, f"not plain weights (no pickle, or one over {size_text(MAX_PICKLE_BYTES)}); refused")
        try:
            value = torch.load(io.BytesIO(data), map_location=device, weights_only=True)
        except Exception as exc:  # torch raises UnpicklingError, RuntimeError and more for a bad file
            raise ConfigError(self.path, name, f"not plain weights ({type(exc).__name__}); refused") from None
        check_tensors(value, self.path, name, MAX_WEIGHTS_BYTES)
        return value

    def close(self) -> None:
        """Let go of the zip's bytes (members can no longer be read); the manifest stays."""
        self._archive.close()
        self._archive = zipfile.ZipFile(io.BytesIO(_EMPTY_ZIP))

    def normalizer(self, size: int) -> Normalizer | None:
        """The normaliser, validated for observations of ``size`` values, or None if there is none."""
        if not self.has(NORMALIZER):
            return None
        return Normalizer.from_json(self.json(NORMALIZER), size, self.path)


def check_tensors(value: Any, source: str | Path, name: str, limit: int) -> int:
    """The bytes the tensors in ``value`` (nested in dicts, lists and tuples) span, refused in one
    line when they add up to more than ``limit`` (a view can repeat one small storage endlessly:
    the size is counted before any value is looked at), are not plain dense tensors, or hold a
    NaN or an infinity (so do plain floats beside them, an optimiser's betas say)."""
    import torch

    def refuse(problem: str) -> ConfigError:
        return ConfigError(source, name, f"{problem}; refused")

    tensors: list[tuple[str, Any]] = []
    floats: list[tuple[str, float]] = []
    total = 0
    stack: list[tuple[str, Any]] = [("", value)]
    while stack:
        where, item = stack.pop()
        if isinstance(item, torch.Tensor):
            if item.layout != torch.strided or item.is_quantized or item.device.type == "meta":
                raise refuse(f"{where or 'the value'} is not a plain dense tensor")
            total += item.numel() * item.element_size()
            if total > limit:
                raise refuse(f"its tensors span more than {size_text(limit)}")
            tensors.append((where, item))
        elif isinstance(item, dict):
            stack.extend((f"{where}.{key}" if where else str(key), child) for key, child in item.items())
        elif isinstance(item, (list, tuple)):
            stack.extend((f"{where}[{i}]", child) for i, child in enumerate(item))
        elif isinstance(item, float):
            floats.append((where, item))
    for where, item in tensors:
        if (item.is_floating_point() or item.is_complex()) and not bool(torch.isfinite(item).all()):
            raise refuse(f"{where or 'the tensor'} holds NaN or infinite values")
    for where, item in floats:
        if not math.isfinite(item):
            raise refuse(f"{where or 'the value'} is {item}, not a finite number")
    return total


def read_manifest(path: str | Path) -> dict[str, Any]:
    """The validated manifest of a policy zip, as a dict (one-line errors for anything else)."""
    return PolicyFile(path).raw_manifest


def update_manifest(path: str | Path, extra: dict[str, Any]) -> Path:
    """Add keys to a policy zip's manifest (the zip is rebuilt and swapped in atomically)."""
    source = PolicyFile(path)  # read through the same bounds as any policy
    manifest = {**source.raw_manifest, **extra}
    Manifest.model_validate(manifest)

    def write(tmp: Path) -> None:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as target:
            for name, item in source.members.items():
                data = json.dumps(manifest, indent=2).encode() if name == MANIFEST else source.read(name)
                target.writestr(item, data)

    return atomic_write(Path(path), write)
