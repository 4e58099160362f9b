"""A sweep's results: sweep.json (trials and aggregates), sweep.md (tables), sweep.png (curves)."""

from __future__ import annotations

import csv
import hashlib
import importlib.util
import json
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from common.atomic import atomic_write
from common.statistics import aggregate, interval_text

METRICS = ("success_rate", "spl")  # of the last stage's final test draw (and of each validation on the way)


def _trial(result) -> dict[str, Any]:
    config, metrics = result.config, result.metrics or {}
    if config is None:  # Ctrl-C before Ray started it (more trials than cores): no seed of its own yet
        return {"name": "(not started)", "seed": None, "params": {}, "status": "not started", "final": None,
                "run_dir": None, "node": None, "machine": None, "error": None}
    status = "done" if metrics.get("done") else ("error" if result.error else "stopped early")
    return {"name": trial_name(config, metrics.get("trial_id")), "seed": config["seed"],
            "params": config.get("params") or {}, "status": status, "final": metrics.get("final"),
            "run_dir": metrics.get("run_dir"), "node": metrics.get("node"), "machine": metrics.get("machine"),
            "error": first_line(result.error)}


def trial_name(config: dict[str, Any], trial_id: str | None = None) -> str:
    """A trial's run directory name: stable across retries and resumes, and one file name.

    A seed sweep's trials are named by seed (``seed1000``), which a sweep restarted from nothing but
    its run directories relies on. A search's also carry Tune's trial id, since a search may propose
    the same values twice and two trials must never share a run directory. A name that would not be
    a short, plain file name (a long or path-like value) is replaced by a digest of the parameters.
    """
    params = config.get("params") or {}
    suffix = "-".join(f"{k.split('.')[-1]}={v:.4g}" if isinstance(v, float) else f"{k.split('.')[-1]}={v}"
                      for k, v in sorted(params.items()))
    if len(suffix) > 120 or not set(suffix) <= _NAME_CHARS:
        digest = hashlib.sha256(json.dumps(params, sort_keys=True, default=str).encode()).hexdigest()[:12]
        suffix = f"params={digest}"
    if params and trial_id:
        suffix += f"-{trial_id}"
    return f"seed{config['seed']}" + (f"-{suffix}" if suffix else "")


_NAME_CHARS = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_+-=.,")


_ANSI = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")


def first_line(error: BaseException | None) -> str | None:
    """What went wrong in a trial, in one line: the trial's own exception (Ray wraps it in a
    RayTaskError whose text starts with the worker's address and a traceback), its first line."""
    if error is None:
        return None
    cause = getattr(error, "cause", None) or error
    lines = [line.strip() for line in _ANSI.sub("", str(cause)).splitlines() if line.strip()]
    text = f"{type(cause).__name__}: {lines[0]}" if lines else type(cause).__name__
    return text if len(text) <= 200 else text[:197] + "..."


def _curve(run_dir: str | None) -> list[tuple[int, float]]:
    """Validation success against the last stage's timesteps."""
    path = Path(run_dir or "") / "eval.csv"
    if not path.is_file():
        return []
    rows = list(csv.DictReader(path.open(newline="")))
    last = rows[-1]["stage"] if rows else None
    return [(int(r["timesteps"]), float(r["success_rate"])) for r in rows if r["stage"] == last]


def write_results(out: Path, grid, metric: str, address: str | None, concurrent: int, wall_seconds: float,
                  searched: bool, resumed: bool = False) -> dict[str, Any]:
    """sweep.json, sweep.md and sweep.png; ``wall_seconds`` is this invocation's (``resumed``: since the resume)."""
    trials = sorted((_trial(result) for result in grid),
                    key=lambda t: (t["seed"] is None, t["seed"] or 0, json.dumps(t["params"], sort_keys=True)))
    done = [t for t in trials if t["final"] is not None]
    results = {
        "backend": "ray", "address": address or "local", "metric": metric, "concurrent_trials": concurrent,
        "wall_seconds": round(wall_seconds, 1), "resumed": resumed, "trials": trials,
        "failed": [t["name"] for t in trials if t["status"] == "error"],
        "aggregate": {m: aggregate([t["final"][m] for t in done]) for m in METRICS},
    }
    if searched and done:
        best = max(done, key=lambda t: t["final"][metric])
        results["best"] = {"params": best["params"], "seed": best["seed"], metric: best["final"][metric]}
    atomic_write(out / "sweep.json", lambda tmp: tmp.write_text(json.dumps(results, indent=2)))
    atomic_write(out / "sweep.md", lambda tmp: tmp.write_text(_markdown(results)))
    _figure(trials, results, out / "sweep.png", searched)
    return results


def _markdown(results: dict[str, Any]) -> str:
    lines = [f"# Sweep ({results['backend']}, {results['address']})", "",
             f"{len(results['trials'])} trials, {results['concurrent_trials']} at a time, {results['wall_seconds']:.0f} s"
             + (" since the sweep was resumed (the time before is not counted)." if results.get("resumed") else "."), ""]
    failed = [t for t in results["trials"] if t["status"] == "error"]
    if failed:
        lines += [f"**{len(failed)} of {len(results['trials'])} trials failed**; the aggregate is over the others:", ""]
        lines += [f"- `{t['name']}`: {t['error']}" for t in failed] + [""]
    machines = sorted({t["machine"] for t in results["trials"] if t.get("machine")})
    if len(machines) == 1:
        lines += [f"Every trial ran on {machines[0]}.", ""]
    elif machines:
        lines += [f"**The trials ran on {len(machines)} kinds of machine**; a seed trains other weights on "
                  "another CPU, so the spread below mixes machines with seeds:", ""]
        lines += [f"- {m}: seeds {', '.join(str(t['seed']) for t in results['trials'] if t.get('machine') == m)}"
                  for m in machines] + [""]
    lines += ["| seed | parameters | status | test success | test SPL | run directory |", "|---:|---|---|---:|---:|---|"]
    for t in results["trials"]:
        params = ", ".join(f"{k.split('.')[-1]}={v:.4g}" if isinstance(v, float) else f"{k.split('.')[-1]}={v}"
                           for k, v in t["params"].items()) or "–"
        final = t["final"] or {}
        success = "–" if not final else f"{final['success_rate']:.1%}"
        spl = "–" if not final else f"{final['spl']:.3f}"
        status = "**failed**" if t["status"] == "error" else t["status"]
        lines.append(f"| {t['seed']} | {params} | {status} | {success} | {spl} | {t['run_dir'] or '–'} |")
    lines += ["", "| metric | trials | mean | IQM | IQM 95% CI (bootstrap) |", "|---|---:|---:|---:|---:|"]
    for name, agg in results["aggregate"].items():
        if agg["iqm"] is None:
            continue
        interval = interval_text(agg, " – ", label="")  # the column says what it is
        lines.append(f"| test {name} | {agg['n']} | {agg['mean']:.3f} | {agg['iqm']:.3f} | {interval} |")
    lines += ["", "![sweep](sweep.png)", ""]
    return "\n".join(lines)


def _figure(trials: list[dict], results: dict[str, Any], path: Path, searched: bool) -> None:
    figure = Figure(figsize=(11 if searched else 7, 4), dpi=100)
    FigureCanvasAgg(figure)
    ax = figure.add_subplot(1, 2 if searched else 1, 1)
    curves = [dict(_curve(t["run_dir"])) for t in trials]
    for trial, curve in zip(trials, curves):
        if curve:
            ax.plot(list(curve), list(curve.values()), color="tab:blue", alpha=0.35, linewidth=1,
                    label="each trial" if trial is trials[0] else None)
    common = sorted(set.intersection(*(set(c) for c in curves if c))) if any(curves) else []
    if common:
        values = np.array([[c[s] for c in curves if c] for s in common])
        ax.plot(common, values.mean(axis=1), color="tab:blue", linewidth=2.5, label="mean")
        ax.fill_between(common, values.min(axis=1), values.max(axis=1), color="tab:blue", alpha=0.15, label="range")
    agg = results["aggregate"]["success_rate"]
    title = "validation success of the last stage"
    if agg["iqm"] is not None:
        title += f"\ntest IQM {agg['iqm']:.3f} ({interval_text(agg)}, n={agg['n']})"
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("timesteps")
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:  # no curves when every trial failed
        ax.legend(fontsize=8, loc="lower right")
    if searched:
        _importance(figure.add_subplot(1, 2, 2), trials, results["metric"])
    figure.tight_layout()
    figure.savefig(path)


def _importance(ax, trials: list[dict], metric: str) -> None:
    """Optuna's parameter importance (fANOVA, or PED-ANOVA without scikit-learn) over the finished trials."""
    import optuna

    done = [t for t in trials if t["final"] is not None and t["params"]]
    if len(done) < 2:
        ax.set_axis_off()
        return
    if len({t["final"][metric] for t in done}) == 1:
        # Every trial scored the same: no parameter explains a difference, and PED-ANOVA's equal
        # shares (0.5 each for two) would read as a finding.
        ax.set_axis_off()
        ax.text(0.5, 0.5, f"every trial scored the same test {metric}:\nno parameter importance to show",
                ha="center", va="center", fontsize=9, transform=ax.transAxes)
        return
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(direction="maximize")
    keys = list(done[0]["params"])
    distributions = {k: _distribution([d["params"][k] for d in done]) for k in keys}
    for t in done:
        params = {k: t["params"][k] if isinstance(distributions[k], optuna.distributions.FloatDistribution)
                  else json.dumps(t["params"][k]) for k in keys}
        study.add_trial(optuna.trial.create_trial(params=params, distributions=distributions, value=t["final"][metric]))
    # fANOVA fits a random forest with scikit-learn, which the sweep extra does not install; without
    # it, PED-ANOVA (Optuna's own, numpy only) rather than a report that dies after the sweep ran.
    if importlib.util.find_spec("sklearn") is not None:
        method, evaluator = "fANOVA", optuna.importance.FanovaImportanceEvaluator(seed=0)
    else:
        method, evaluator = "PED-ANOVA", optuna.importance.PedAnovaImportanceEvaluator()
    with warnings.catch_warnings():  # the estimators' own notes on few trials
        warnings.simplefilter("ignore")
        importances = optuna.importance.get_param_importances(study, evaluator=evaluator)
    names = list(importances)
    ax.barh([n.split(".")[-1] for n in names], [importances[n] for n in names], color="tab:orange")
    ax.set_title(f"parameter importance for test {metric} ({method})", fontsize=9)


def _distribution(values: list):
    import optuna

    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        low, high = float(min(values)), float(max(values))
        return optuna.distributions.FloatDistribution(low, high if high > low else low + 1e-12)
    return optuna.distributions.CategoricalDistribution(sorted({json.dumps(v) for v in values}))
