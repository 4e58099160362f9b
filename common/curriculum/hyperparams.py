"""Turn YAML hyperparameters into what stable-baselines3 takes, as rl-baselines3-zoo does.

Three values cannot be written as plain YAML: a learning-rate schedule (``"lin_3e-4"``: linear from
3e-4 to 0 over the stage), action noise (``{type: normal, sigma: 0.1}`` or
``{type: ornstein_uhlenbeck, sigma: 0.1}``, one sigma for both action dimensions) and the network's
activation (``policy_kwargs: {activation_fn: relu}``, by name). ``policy_kwargs`` takes the keys of
:class:`PolicyKwargs`: what describes an MLP policy as plain data, so a policy file's manifest can
rebuild the network without running anything.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Callable, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from common.errors import ConfigError, quote
from common.params import is_finite, is_real, numeral

_NOISE_TYPES = ("normal", "ornstein_uhlenbeck")


def _linear(start: float):
    return lambda progress_remaining: progress_remaining * start


def _schedule(value: Any, source, field: str) -> Any:
    """A number as it is (:func:`_check_values` has checked it), or ``"lin_<number>"`` as a
    linear schedule from that number to 0."""
    if isinstance(value, str):
        try:
            kind, number = value.split("_", 1)
            if kind != "lin" or not 0.0 < float(number) < math.inf:
                raise ValueError
            return _linear(float(number))
        except ValueError:
            raise ConfigError(source, field, f"{quote(value)}: allowed: a number > 0 or 'lin_<number>' (linear to 0)") from None
    return value


# Stable-baselines3's numeric arguments: (type, low, high, low included). Unchecked, a zero
# n_steps or a NaN learning rate passed `curriculum validate` and failed in SB3 with a traceback.
_RANGES: dict[str, tuple[type, float, float, bool]] = {
    "learning_rate": (float, 0.0, math.inf, False), "clip_range": (float, 0.0, math.inf, False),
    "n_steps": (int, 1, 10**6, True), "batch_size": (int, 2, 10**7, True), "n_epochs": (int, 1, 1000, True),
    "gamma": (float, 0.0, 1.0, False), "gae_lambda": (float, 0.0, 1.0, True), "vf_coef": (float, 0.0, 1e6, True),
    "max_grad_norm": (float, 0.0, math.inf, False), "target_kl": (float, 0.0, math.inf, False),
    "buffer_size": (int, 1, 10**8, True), "learning_starts": (int, 0, 10**9, True), "tau": (float, 0.0, 1.0, False),
    "policy_delay": (int, 1, 10**6, True), "target_policy_noise": (float, 0.0, 1e6, True),
    "target_noise_clip": (float, 0.0, 1e6, True), "clip_range_vf": (float, 0.0, math.inf, False),
    "target_update_interval": (int, 1, 10**9, True), "sde_sample_freq": (int, -1, 10**9, True),
    "stats_window_size": (int, 1, 10**6, True),
}
_NULLABLE = {"target_kl", "clip_range_vf"}  # SB3's defaults, None: no early stop; the value not clipped
_SCHEDULES = ("learning_rate", "clip_range", "clip_range_vf")  # a number, or a schedule written as text
_FLAGS = ("use_sde", "normalize_advantage", "use_sde_at_warmup")


def _finite(value: Any, low: float) -> bool:
    """A finite real number (an integer past a float's range is not) of at least ``low``."""
    return is_real(value) and is_finite(value) and value >= low


def _ent_coef(value: Any, algorithm: str | None) -> str | None:
    """What ``ent_coef`` allows if ``value`` is not that, else None: SAC's may be learnt from an
    initial value (``"auto"``, ``"auto_0.1"``)."""
    initial = numeral(value[5:]) if isinstance(value, str) and value.startswith("auto_") else None
    learnt = algorithm != "ppo" and (value == "auto" or (initial is not None and _finite(initial, 0.0) and initial > 0))
    if _finite(value, 0.0) or learnt:
        return None
    return "a number >= 0" + ("" if algorithm == "ppo" else ", 'auto' or 'auto_<initial value > 0>'")


def _target_entropy(value: Any, algorithm: str | None) -> str | None:
    return None if value == "auto" or _finite(value, -math.inf) else "'auto' or a finite number"


def _train_freq(value: Any, algorithm: str | None) -> str | None:
    every = value[0] if isinstance(value, list) and len(value) == 2 and value[1] in ("step", "episode") else value
    ok = not isinstance(every, bool) and isinstance(every, int) and 1 <= every <= 10**9
    return None if ok else "a whole number >= 1 (steps) or [n, step | episode]"


def _gradient_steps(value: Any, algorithm: str | None) -> str | None:
    ok = not isinstance(value, bool) and isinstance(value, int) and (value == -1 or 1 <= value <= 10**6)
    return None if ok else "a whole number >= 1, or -1 (as many as the steps collected)"


def _no_memory_saving(value: Any, algorithm: str | None) -> str | None:
    # SB3's replay buffer refuses it beside the timeout handling (truncations bootstrap) these envs need.
    return None if value is False else "false (the replay buffer's memory saving cannot tell truncations apart)"


# Arguments whose values are not numbers in a range: each a check that gives what is allowed, or None.
_CHECKS: dict[str, Callable[[Any, str | None], str | None]] = {
    "ent_coef": _ent_coef, "target_entropy": _target_entropy, "train_freq": _train_freq,
    "gradient_steps": _gradient_steps, "optimize_memory_usage": _no_memory_saving,
}
CONFIGURABLE = frozenset(_RANGES) | frozenset(_CHECKS) | frozenset(_FLAGS) | {"policy_kwargs", "action_noise"}
"""Stable-baselines3's arguments a curriculum may set; the others take code (a buffer's class or
its arguments), which a YAML file does not name."""


def _checked(value: Any, source, field: str, kind: type, low: float, high: float, low_included: bool) -> None:
    """A one-line error unless ``value`` is a ``kind`` within its range (NaN and inf outside any)."""
    whole = kind is int
    ok = (not isinstance(value, bool) and isinstance(value, int if whole else (int, float))
          and (low <= value if low_included else low < value) and value <= high)
    if not ok:
        what = "a whole number" if whole else "a finite number"
        bounds = f"{'>=' if low_included else '>'} {low:g}" + (f" and <= {high:g}" if high < math.inf else "")
        raise ConfigError(source, field, f"got {quote(value)}; allowed: {what} {bounds}")


def _check_values(values: dict[str, Any], source, field: str, algorithm: str | None) -> None:
    for key, value in values.items():
        if key in _FLAGS and not isinstance(value, bool):
            raise ConfigError(source, f"{field}.{key}", f"got {quote(value)}; allowed: true or false")
        if key in _CHECKS and (allowed := _CHECKS[key](value, algorithm)) is not None:
            raise ConfigError(source, f"{field}.{key}", f"got {quote(value)}; allowed: {allowed}")
        if key not in _RANGES or (value is None and key in _NULLABLE) or (key in _SCHEDULES and isinstance(value, str)):
            continue
        _checked(value, source, f"{field}.{key}", *_RANGES[key])


def _noise(value: Any, action_dim: int, source, field: str) -> Any:
    from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise

    if not isinstance(value, dict) or value.get("type") not in _NOISE_TYPES or set(value) - {"type", "sigma"}:
        raise ConfigError(source, field, f"allowed: {{type: {' | '.join(_NOISE_TYPES)}, sigma: <number>}}")
    sigma = value.get("sigma", 0.1)
    if not _finite(sigma, 0.0):
        raise ConfigError(source, f"{field}.sigma", f"expected a finite number >= 0, got {quote(sigma)}")
    noise = NormalActionNoise if value["type"] == "normal" else OrnsteinUhlenbeckActionNoise
    return noise(mean=np.zeros(action_dim), sigma=float(sigma) * np.ones(action_dim))


ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu", "gelu", "silu")
# How the optimisers update their tensors on CPU (common.curriculum.policy.use_optimizer_kernels).
OPTIMIZER_KERNELS = ("foreach", "fused")
Layers = Annotated[list[Annotated[int, Field(ge=1, le=4096)]], Field(max_length=16)]


class PolicyKwargs(BaseModel):
    """An MLP policy's shape as plain data: stable-baselines3's ``policy_kwargs`` that need no code."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    net_arch: Layers | dict[Literal["pi", "vf", "qf"], Layers] | None = None
    activation_fn: Literal[ACTIVATIONS] | None = None  # type: ignore[valid-type]
    n_critics: Annotated[int, Field(ge=1, le=10)] | None = None
    share_features_extractor: bool | None = None
    log_std_init: Annotated[float, Field(ge=-20.0, le=20.0)] | None = None
    ortho_init: bool | None = None
    # PPO: the Gaussian's mean squashed into [-1, 1] by tanh (common.curriculum.policy.NavActorCriticPolicy).
    bounded_mean: bool | None = None

    def refused_by(self, algorithm: str) -> tuple[str, str] | None:
        """The key ``algorithm``'s policy would refuse (SB3 with a TypeError deep inside training),
        and why, or None: one rule for curricula and policy files alike."""
        if algorithm == "ppo" and self.n_critics is not None:
            return "n_critics", "a PPO policy has no critics to count; allowed: sac, td3"
        if algorithm != "ppo" and self.bounded_mean is not None:
            return "bounded_mean", "bounds a PPO policy's Gaussian mean; allowed: ppo"
        return None

    def to_sb3(self) -> dict[str, Any]:
        """The keyword arguments stable-baselines3 takes (unset keys left to its defaults)."""
        out = self.model_dump(exclude_none=True)
        if "activation_fn" in out:
            out["activation_fn"] = activation_classes()[out["activation_fn"]]
        return out

    @classmethod
    def from_sb3(cls, kwargs: dict[str, Any]) -> "PolicyKwargs":
        """Describe a model's ``policy_kwargs``; ValueError if they hold what plain data cannot."""
        data = {k: v for k, v in kwargs.items() if k != "use_sde"}  # SAC keeps use_sde there too
        if "activation_fn" in data:
            names = {activation: name for name, activation in activation_classes().items()}
            data["activation_fn"] = names.get(data["activation_fn"], repr(data["activation_fn"]))
        try:
            return cls.model_validate(data)
        except ValidationError as exc:
            raise ValueError(f"policy_kwargs {quote(kwargs)} cannot be stored as data: {exc.errors()[0]['msg']}") from None


def activation_classes() -> dict[str, type]:
    import torch.nn as nn

    return {"tanh": nn.Tanh, "relu": nn.ReLU, "elu": nn.ELU, "leaky_relu": nn.LeakyReLU, "gelu": nn.GELU, "silu": nn.SiLU}


def resolve_hyperparams(hyperparams: dict[str, Any], action_dim: int = 2, source: str | Path | None = None,
                        field: str = "hyperparams", algorithm: str | None = None) -> dict[str, Any]:
    """SB3 keyword arguments from a stage's YAML hyperparameters (``algorithm``'s, where known)."""
    out = dict(hyperparams)
    _check_values(out, source, field, algorithm)
    for key in _SCHEDULES:
        if key in out:
            out[key] = _schedule(out[key], source, f"{field}.{key}")
    if isinstance(out.get("train_freq"), list):
        out["train_freq"] = tuple(out["train_freq"])  # YAML's [n, unit]: SB3 takes a tuple
    if "action_noise" in out:
        out["action_noise"] = _noise(out["action_noise"], action_dim, source, f"{field}.action_noise")
    if "policy_kwargs" in out:
        out["policy_kwargs"] = policy_kwargs_from_yaml(out["policy_kwargs"], source, f"{field}.policy_kwargs").to_sb3()
    return out


def policy_kwargs_from_yaml(value: Any, source: str | Path | None = None, field: str = "policy_kwargs") -> PolicyKwargs:
    """Validate a YAML (or manifest JSON) ``policy_kwargs`` mapping; one-line errors."""
    from common.scenario import pydantic_error

    if not isinstance(value, dict):
        raise ConfigError(source, field, f"got {quote(value)}; allowed: a mapping with keys {', '.join(PolicyKwargs.model_fields)}")
    try:
        return PolicyKwargs.model_validate(value)
    except ValidationError as exc:
        error = pydantic_error(None, exc, PolicyKwargs)
        raise ConfigError(source, f"{field}.{error.field}" if error.field else field, error.problem) from None
