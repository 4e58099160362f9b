"""Turn YAML hyperparameters into what stable-baselines3 takes, as rl-baselines3-zoo does.

Two values cannot be written as plain YAML: a learning-rate schedule (``"lin_3e-4"``: linear from
3e-4 to 0 over the stage) and action noise (``{type: normal, sigma: 0.1}`` or
``{type: ornstein_uhlenbeck, sigma: 0.1}``, one sigma for both action dimensions).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from common.errors import ConfigError

_NOISE_TYPES = ("normal", "ornstein_uhlenbeck")


def _linear(start: float):
    return lambda progress_remaining: progress_remaining * start


def _schedule(value: Any, source, field: str) -> Any:
    if isinstance(value, str):
        try:
            kind, number = value.split("_", 1)
            if kind != "lin":
                raise ValueError
            return _linear(float(number))
        except ValueError:
            raise ConfigError(source, field, f"{value!r}: allowed: a number or 'lin_<number>' (linear to 0)") from None
    return value


def _noise(value: Any, action_dim: int, source, field: str) -> Any:
    from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise

    if not isinstance(value, dict) or value.get("type") not in _NOISE_TYPES or set(value) - {"type", "sigma"}:
        raise ConfigError(source, field, f"allowed: {{type: {' | '.join(_NOISE_TYPES)}, sigma: <number>}}")
    sigma = value.get("sigma", 0.1)
    if isinstance(sigma, bool) or not isinstance(sigma, (int, float)) or sigma < 0:
        raise ConfigError(source, f"{field}.sigma", f"expected a number >= 0, got {sigma!r}")
    noise = NormalActionNoise if value["type"] == "normal" else OrnsteinUhlenbeckActionNoise
    return noise(mean=np.zeros(action_dim), sigma=float(sigma) * np.ones(action_dim))


def resolve_hyperparams(hyperparams: dict[str, Any], action_dim: int = 2, source: str | Path | None = None,
                        field: str = "hyperparams") -> dict[str, Any]:
    """SB3 keyword arguments from a stage's YAML hyperparameters."""
    out = dict(hyperparams)
    for key in ("learning_rate", "clip_range"):
        if key in out:
            out[key] = _schedule(out[key], source, f"{field}.{key}")
    if "action_noise" in out:
        out["action_noise"] = _noise(out["action_noise"], action_dim, source, f"{field}.action_noise")
    return out
