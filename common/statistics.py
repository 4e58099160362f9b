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
    """Mean, interquartile mean (scipy's 25 %-trimmed mean, as rliable's) and its bootstrap 95 %
    interval: None from one value (one seed says nothing of the spread). A value that is not finite
    is left out and counted (``non_finite``): one NaN made every figure NaN, and NaN is no JSON."""
    data = np.asarray(values, dtype=float)
    finite = np.isfinite(data)
    data = data[finite]
    out: dict[str, Any] = {"n": int(data.size), "values": [float(v) for v in data]}
    if not finite.all():
        out["non_finite"] = int((~finite).sum())
    if data.size == 0:
        return {**out, "mean": None, "iqm": None, "ci95": None}
    iqm = float(stats.trim_mean(data, 0.25))
    if data.size == 1:
        ci = None
    elif np.ptp(data) > 0:
        result = stats.bootstrap((data,), lambda x, axis: stats.trim_mean(x, 0.25, axis=axis), n_resamples=resamples,
                                 method="percentile", random_state=np.random.default_rng(seed))
        ci = [float(result.confidence_interval.low), float(result.confidence_interval.high)]
    else:
        ci = [iqm, iqm]  # every seed alike: no resample differs
    return {**out, "mean": float(data.mean()), "iqm": iqm, "ci95": ci}


def interval_text(agg: dict[str, Any], separator: str = "–", label: str = "95% CI ") -> str:
    """An aggregate's interval as a report writes it: ``95% CI low–high``, or what one value lacks."""
    ci = agg["ci95"]
    return "no interval from one value" if ci is None else f"{label}{ci[0]:.3f}{separator}{ci[1]:.3f}"


def p_value_text(p: float) -> str:
    """A p-value as the tables print it: two decimals, or "< 0.01" (not a rounded 0.00)."""
    return f"{p:.2f}" if p >= 0.01 else "< 0.01"


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
