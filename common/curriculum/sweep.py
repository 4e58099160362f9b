"""``curriculum sweep``: a curriculum over many seeds, or a hyperparameter search, as Ray Tune trials.

Each trial is the ordinary runner writing its own run directory under ``OUT/trials/``, so nothing
about a run changes when it is swept, and a trial that dies (its process killed, its node lost) is
retried by Tune and resumes from its run's last checkpoint. The runner reports every periodic
evaluation to Tune; in a search, ASHA stops the hopeless trials early and Optuna proposes the next.

Ray runs in-process by default (``ray.init(address="local")``: a new local cluster of this
machine's cores, never one already running here); with ``address`` the trials go to an existing
cluster (``ray start --head`` on one machine, ``ray start --address HEAD:6379`` on the others).
The sweep directory must be on storage every node sees.

Results: ``OUT/sweep.json`` (every trial with its seed, parameters, status, final test figures and
run directory; ``aggregate`` per metric: mean, interquartile mean and a bootstrap 95 % interval),
``OUT/sweep.md`` and ``OUT/sweep.png``. The interquartile mean (the mean of the middle half) with a
bootstrap interval is the aggregate rliable recommends for few seeds (Agarwal et al. 2021).

A search space is YAML: dotted paths into the curriculum, each a distribution::

    stages.0.hyperparams.learning_rate: {loguniform: [1.0e-4, 1.0e-3]}
    stages.0.hyperparams.n_epochs: {choice: [3, 5, 10]}
    stages.0.env_kwargs.lidar_noise: {uniform: [0.0, 0.05]}
"""

from __future__ import annotations

import json
import math
import os
import shutil
import socket
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from common.curriculum.sweep_report import METRICS, write_results
from common.errors import ConfigError, quote
from common.yaml_io import read_yaml, read_yaml_mapping

DISTRIBUTIONS = ("uniform", "loguniform", "randint", "choice")
SEED_STRIDE = 1000  # seeds of a seed sweep: curriculum seed + 1000·k, so no two runs share a stage seed


# -- search spaces -------------------------------------------------------------------------------


def load_space(path: str | Path, curriculum: dict) -> dict[str, tuple[str, list]]:
    """A validated search space: dotted path -> (distribution, arguments); one-line errors."""
    data = read_yaml_mapping(path)
    space = {}
    for key, spec in data.items():
        if not isinstance(spec, dict) or len(spec) != 1 or next(iter(spec)) not in DISTRIBUTIONS:
            raise ConfigError(path, str(key), f"got {quote(spec)}; allowed: {{{' | '.join(DISTRIBUTIONS)}: [...]}}")
        kind, args = next(iter(spec.items()))
        if not isinstance(args, list) or not args or (kind != "choice" and len(args) != 2):
            raise ConfigError(path, f"{key}.{kind}", "allowed: [low, high] (or a list of values for choice)")
        if kind != "choice" and not all(isinstance(a, (int, float)) and math.isfinite(a) for a in args):
            raise ConfigError(path, f"{key}.{kind}", f"got {quote(args)}; allowed: two finite numbers")
        if kind != "choice" and not args[0] < args[1]:
            raise ConfigError(path, f"{key}.{kind}", f"got {quote(args)}; allowed: low < high")
        if kind == "loguniform" and args[0] <= 0:
            raise ConfigError(path, f"{key}.{kind}", "allowed: 0 < low < high")
        _check_path(curriculum, str(key), path)
        space[str(key)] = (kind, args)
    if not space:
        raise ConfigError(path, None, "an empty search space; allowed: dotted curriculum paths with distributions")
    return space


def _check_path(curriculum: dict, dotted: str, source: str | Path) -> None:
    """A path must lead into an existing stage; its last key may be new (a hyperparameter, say)."""
    node: Any = curriculum
    parts = dotted.split(".")
    for depth, part in enumerate(parts[:-1]):
        key: Any = int(part) if isinstance(node, list) and part.isdigit() else part
        try:
            node = node[key]
        except (KeyError, IndexError, TypeError):
            node = {} if depth >= 2 else None  # stages.0.hyperparams may not exist yet
        if node is None:
            raise ConfigError(source, dotted, "not a path into the curriculum (e.g. stages.0.hyperparams.learning_rate)")


def with_params(curriculum: dict, params: dict[str, Any]) -> dict:
    """A copy of a curriculum mapping with each dotted path set."""
    data = json.loads(json.dumps(curriculum))
    for dotted, value in params.items():
        node = data
        parts = dotted.split(".")
        for part in parts[:-1]:
            node = node[int(part)] if isinstance(node, list) else node.setdefault(part, {})
        node[parts[-1]] = value.item() if isinstance(value, np.generic) else value
    return data


def _tune_domain(kind: str, args: list):
    from ray import tune

    return {"uniform": lambda: tune.uniform(*args), "loguniform": lambda: tune.loguniform(*args),
            "randint": lambda: tune.randint(int(args[0]), int(args[1]) + 1), "choice": lambda: tune.choice(args)}[kind]()


# -- the trial -----------------------------------------------------------------------------------


def run_trial(config: dict[str, Any]) -> None:
    """Ray Tune's function trainable: one run of the curriculum, resumed if it ran before."""
    import ray
    from ray import tune

    from common.curriculum.runner import Runner
    from common.curriculum.schema import curriculum_from_mapping

    data = with_params(config["curriculum"], config.get("params", {}))
    data["seed"] = int(config["seed"])
    curriculum = curriculum_from_mapping(data, config["source"])
    run_dir = Path(config["sweep_dir"]) / "trials" / trial_name(config)
    node = ray.get_runtime_context().get_node_id()

    def report(row: dict) -> None:
        tune.report({"success_rate": float(row["success_rate"]), "spl": float(row["spl"]), "stage": row["stage"],
                     "timesteps": int(row["timesteps"]), "node": node, "run_dir": str(run_dir)})

    state = Runner(curriculum, run_dir, resume=(run_dir / "state.json").exists(), device=config.get("device"),
                   progress=False, on_evaluation=report).run()
    final = state["stages"][curriculum.stages[-1].name]["final"]
    tune.report({"success_rate": final["success_rate"], "spl": final["spl"], "stage": "final",
                 "timesteps": state["stages"][curriculum.stages[-1].name]["timesteps"], "node": node,
                 "run_dir": str(run_dir), "final": final, "done": True})


def trial_name(config: dict[str, Any]) -> str:
    """A trial's run directory name: stable across retries and resumes."""
    params = config.get("params") or {}
    suffix = "-".join(f"{k.split('.')[-1]}={v:.4g}" if isinstance(v, float) else f"{k.split('.')[-1]}={v}"
                      for k, v in sorted(params.items()))
    return f"seed{config['seed']}" + (f"-{suffix}" if suffix else "")


# -- the sweep -----------------------------------------------------------------------------------


def check_address(address: str, timeout: float = 3.0) -> None:
    """A one-line error, within seconds, for a cluster address nothing answers at."""
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        raise ConfigError(None, "--address", f"{address!r}: allowed: HOST:PORT of a Ray head (ray start --head)")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout):
            pass
    except OSError as exc:
        raise ConfigError(None, "--address", f"no Ray cluster answers at {address} ({exc.strerror or exc}); "
                          "start one with `ray start --head` or leave --address out to run locally") from None


def run_sweep(source: str | Path, out: Path, seeds: int = 1, space: str | Path | None = None, trials: int = 8,
              metric: str = "success_rate", address: str | None = None, cpus_per_trial: float = 1.0,
              max_failures: int = 2, resume: bool = False, device: str | None = None,
              trainable: Callable[[dict], None] = run_trial) -> dict[str, Any]:
    """Run the sweep (or continue an interrupted one) and write its results; return sweep.json's content."""
    from common.curriculum.schema import load_curriculum

    if metric not in METRICS:
        raise ConfigError(None, "--metric", f"{metric!r}; allowed: {', '.join(METRICS)}")
    if address:
        check_address(address)
    load_curriculum(source)  # one-line errors before any trial starts
    # Tune's newer console output ignores verbose=0; the runs' own reports are what users read.
    os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")
    import ray
    from ray import tune

    curriculum = read_yaml(source)
    out = Path(out).resolve()
    experiment = out / "ray"
    restore = resume and tune.Tuner.can_restore(str(experiment))
    if resume and not restore and not (out / "trials").is_dir():
        raise ConfigError(out, None, "nothing to resume here (no sweep ran); run without --resume")
    if not resume and experiment.exists():
        raise ConfigError(out, None, "a sweep already ran here; pass --resume to continue it or choose another --out")
    if resume and not restore:
        # Killed before Tune saved its first state: start Tune afresh; each trial still resumes
        # from its own run directory, which is where the training lives.
        shutil.rmtree(experiment, ignore_errors=True)
    began = time.perf_counter()
    # "local": a Ray of its own, as documented. Without it Ray joins whatever cluster this machine
    # last started (another sweep's, a test's, a `ray start`), and dies when that one does.
    ray.init(address=address or "local", include_dashboard=False, log_to_driver=False, ignore_reinit_error=True,
             configure_logging=False)
    try:
        resources = tune.with_resources(trainable, {"cpu": cpus_per_trial})
        if restore:
            tuner = tune.Tuner.restore(str(experiment), trainable=resources, resume_errored=True)
        else:
            base = {"curriculum": curriculum, "source": str(Path(source).resolve()), "sweep_dir": str(out), "device": device}
            if space is None:
                param_space = {**base, "seed": tune.grid_search([curriculum.get("seed", 0) + SEED_STRIDE * k
                                                                 for k in range(seeds)])}
                tune_config = tune.TuneConfig()
            else:
                from ray.tune.schedulers import ASHAScheduler
                from ray.tune.search.optuna import OptunaSearch

                domains = load_space(space, curriculum)
                param_space = {**base, "seed": curriculum.get("seed", 0),
                               "params": {key: _tune_domain(kind, args) for key, (kind, args) in domains.items()}}
                tune_config = tune.TuneConfig(metric=metric, mode="max", num_samples=trials,
                                              search_alg=OptunaSearch(seed=0),
                                              scheduler=ASHAScheduler(grace_period=2, reduction_factor=2))
            out.mkdir(parents=True, exist_ok=True)
            tuner = tune.Tuner(resources, param_space=param_space, tune_config=tune_config,
                               run_config=tune.RunConfig(name="ray", storage_path=str(out), verbose=0,
                                                         failure_config=tune.FailureConfig(max_failures=max_failures)))
        grid = tuner.fit()
        concurrent = int(ray.cluster_resources().get("CPU", 1) // cpus_per_trial)
    finally:
        ray.shutdown()

    return write_results(out, grid, metric, address, concurrent, time.perf_counter() - began,
                         searched=space is not None)
