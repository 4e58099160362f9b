"""Random-action rollouts and their comparison, shared by both tiers' determinism tests."""

from __future__ import annotations

import numpy as np


def rollout(env, seed: int, steps: int = 200, action_seed: int | None = None) -> list:
    """Observations, rewards and episode ends of ``steps`` random actions (seeded by ``action_seed``,
    else ``seed``) from ``reset(seed=seed)``, resetting as episodes end."""
    observation, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed if action_seed is None else action_seed)
    trace = [observation]
    for _ in range(steps):
        observation, reward, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
        trace.append((observation, reward, terminated, truncated))
        if terminated or truncated:
            trace.append(env.reset()[0])
    return trace


def _equal(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    return np.array_equal(a, b)


def same(a: list, b: list) -> bool:
    """Whether two rollouts are identical, step for step."""
    return all(
        _equal(x[0], y[0]) and x[1:] == y[1:] if isinstance(x, tuple) else _equal(x, y)
        for x, y in zip(a, b, strict=True)
    )
