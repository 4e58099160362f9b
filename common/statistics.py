"""Aggregates of learning figures over seeds: the interquartile mean with a bootstrap interval;
and two agents' outcomes on the same episodes compared pair by pair.

A learning figure is a distribution over seeds; with few seeds the interquartile mean and its
percentile-bootstrap 95 % interval are what rliable recommends (Agarwal et al. 2021). Two agents
driven on the same episodes are compared episode by episode (McNemar's test), which tells apart
rates whose separate intervals overlap.
"""

from __future__ import annotations

from typing import Any, Sequence

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


def mcnemar(first: Sequence[bool], second: Sequence[bool]) -> tuple[int, int, float]:
    """Paired outcomes (arrived or not) of two agents on the same episodes: how many only the first
    arrived in, how many only the second, and McNemar's exact two-sided p-value (a binomial test of
    the one count among both: whether one arrives more often than chance flips would say)."""
    if len(first) != len(second):
        raise ValueError(f"paired outcomes need the same episodes: {len(first)} against {len(second)}")
    only_first = sum(a and not b for a, b in zip(first, second))
    only_second = sum(b and not a for a, b in zip(first, second))
    either = only_first + only_second
    return only_first, only_second, float(stats.binomtest(only_first, either).pvalue) if either else 1.0
