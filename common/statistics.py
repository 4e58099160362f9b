"""Aggregates of learning figures over seeds: the interquartile mean with a bootstrap interval.

A learning figure is a distribution over seeds; with few seeds the interquartile mean and its
percentile-bootstrap 95 % interval are what rliable recommends (Agarwal et al. 2021).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import stats


def aggregate(values: list[float], seed: int = 0, resamples: int = 2000) -> dict[str, Any]:
    """Mean, interquartile mean (scipy's 25 %-trimmed mean) and its bootstrap 95 % interval."""
    data = np.asarray(values, dtype=float)
    out: dict[str, Any] = {"n": int(data.size), "values": [float(v) for v in data]}
    if data.size == 0:
        return {**out, "mean": None, "iqm": None, "ci95": None}
    iqm = float(stats.trim_mean(data, 0.25))
    if data.size > 1 and np.ptp(data) > 0:
        result = stats.bootstrap((data,), lambda x, axis: stats.trim_mean(x, 0.25, axis=axis), n_resamples=resamples,
                                 method="percentile", random_state=np.random.default_rng(seed))
        ci = [float(result.confidence_interval.low), float(result.confidence_interval.high)]
    else:
        ci = [iqm, iqm]
    return {**out, "mean": float(data.mean()), "iqm": iqm, "ci95": ci}
