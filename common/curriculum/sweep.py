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
bootstrap interval is the aggregate rliable recommends for few seeds (Agarwal et al. 2021). Trials
that failed are marked there (status ``error``, the first line of their error, named in ``failed``);
the command then exits with code 1.

A search space is YAML: dotted paths into the curriculum, each a distribution::

    stages.0.hyperparams.learning_rate: {loguniform: [1.0e-4, 1.0e-3]}
    stages.0.hyperparams.n_epochs: {choice: [3, 5, 10]}
    stages.0.env_kwargs.lidar_noise: {uniform: [0.0, 0.05]}

It is checked completely before Ray starts (:func:`load_space`), so a value the curriculum's schema
refuses is a one-line error naming the space file and the path, not a sweep of failed trials.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import socket
import time
from pathlib import Path
from typing import Annotated, Any, Callable, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from common.atomic import atomic_write, writable_place
from common.curriculum.sweep_report import METRICS, trial_name, write_results
from common.errors import ConfigError, quote
from common.yaml_io import read_yaml, read_yaml_mapping

DISTRIBUTIONS = ("uniform", "loguniform", "randint", "choice")
SEED_STRIDE = 1000  # seeds of a seed sweep: curriculum seed + 1000·k, so no two runs share a stage seed


# -- search spaces -------------------------------------------------------------------------------

INT_BOUND = 2**53  # randint bounds: whole numbers Tune and Optuna sample exactly (floats hold them)
MAX_PARAMS = 64  # parameters of one space: more is no search TPE can do in any number of trials
MAX_CHOICES = 256  # values of one choice, each checked against the schema before Ray starts
RESERVED = {"seed": "the sweep sets each trial's seed (--seeds); leave it out of the space"}


def load_space(path: str | Path, curriculum: dict, source: str | Path | None = None) -> dict[str, tuple[str, list]]:
    """A validated search space: dotted path -> (distribution, arguments); one-line errors naming ``path``.

    Checked completely before Ray starts: every path leads into the curriculum, every distribution's
    kind and arguments are valid and finite, and the curriculum (``source``, already valid) stays
    valid with each parameter at each end of its range (and inside it), alone and all together.
    """
    data = read_yaml_mapping(path)
    if len(data) > MAX_PARAMS:
        raise ConfigError(path, None, f"{len(data)} parameters; allowed: at most {MAX_PARAMS}")
    space = {}
    for key, spec in data.items():
        if not isinstance(key, str):
            raise ConfigError(path, quote(key), "not a path into the curriculum (e.g. stages.0.hyperparams.learning_rate)")
        if key in RESERVED:
            raise ConfigError(path, key, RESERVED[key])
        if not isinstance(spec, dict) or len(spec) != 1 or next(iter(spec)) not in DISTRIBUTIONS:
            raise ConfigError(path, key, f"got {quote(spec)}; allowed: {{{' | '.join(DISTRIBUTIONS)}: [...]}}")
        kind, args = next(iter(spec.items()))
        space[key] = (kind, _arguments(path, f"{key}.{kind}", kind, args))
        _check_path(curriculum, key, path)
    if not space:
        raise ConfigError(path, None, "an empty search space; allowed: dotted curriculum paths with distributions")
    for key in space:
        inner = next((other for other in space if other.startswith(key + ".")), None)
        if inner is not None:
            raise ConfigError(path, key, f"overlaps {inner}; allowed: each curriculum value in one parameter")
    _check_values(path, space, curriculum, source)
    return space


def _arguments(path: str | Path, field: str, kind: str, args: Any) -> list:
    """A distribution's arguments, checked: finite numbers in order, or a list of JSON values for choice."""
    if kind == "choice":
        if not isinstance(args, list) or not 1 <= len(args) <= MAX_CHOICES:
            raise ConfigError(path, field, f"got {quote(args)}; allowed: a list of 1 to {MAX_CHOICES} values")
        for value in args:
            try:
                json.dumps(value, allow_nan=False)
            except (TypeError, ValueError):
                raise ConfigError(path, field, f"got {quote(value)}; allowed: finite numbers, strings, booleans, "
                                  "null, lists and mappings of them") from None
        return args
    numbers = isinstance(args, list) and len(args) == 2 and all(  # (an int past a float's range is not finite)
        isinstance(a, (int, float)) and not isinstance(a, bool) and abs(a) < 1e308 and math.isfinite(a) for a in args)
    if not numbers:
        raise ConfigError(path, field, f"got {quote(args)}; allowed: [low, high], two finite numbers")
    if not args[0] < args[1] or not math.isfinite(float(args[1]) - float(args[0])):
        raise ConfigError(path, field, f"got {quote(args)}; allowed: low < high, a finite range")
    if kind == "loguniform" and args[0] <= 0:
        raise ConfigError(path, field, f"got {quote(args)}; allowed: 0 < low < high")
    if kind == "randint":
        if not all(float(a).is_integer() and abs(a) <= INT_BOUND for a in args):
            raise ConfigError(path, field, f"got {quote(args)}; allowed: two whole numbers from -2**53 to 2**53")
        return [int(a) for a in args]
    return [float(a) for a in args]


def _check_path(curriculum: dict, dotted: str, source: str | Path) -> None:
    """A path runs through the curriculum's mappings and lists as :func:`with_params` will set it: list
    indices must exist; a mapping's key may be new (a hyperparameter, say; the schema then judges it)."""
    parts = dotted.split(".")
    node: Any = curriculum
    for depth, part in enumerate(parts):
        where = ".".join(parts[:depth]) or "the curriculum"
        if not part:
            raise ConfigError(source, dotted, "not a path into the curriculum (e.g. stages.0.hyperparams.learning_rate)")
        if isinstance(node, list):
            # Written as an index is (no leading zero): stages.00 and stages.0 were two parameters setting one value.
            if not (part.isascii() and part.isdigit() and str(int(part)) == part and int(part) < len(node)):
                allowed = f"an index from 0 to {len(node) - 1}" if node else "none (the list is empty)"
                raise ConfigError(source, dotted, f"{where} is a list of {len(node)}; allowed: {allowed}")
            node = node[int(part)]
        elif isinstance(node, dict):
            node = node.get(part, {})
        else:
            raise ConfigError(source, dotted, f"{where} is {quote(node)}, not a mapping or list to set {part!r} in")


def _samples(kind: str, args: list) -> list:
    """The values a trial may get that the schema could refuse: both ends and a fractional inside."""
    if kind == "choice":
        return args
    low, high = args
    if kind == "randint":
        return [low, high]
    inside = math.exp(math.log(low) + 0.382 * (math.log(high) - math.log(low))) if kind == "loguniform" else \
        low + 0.382 * (high - low)
    return [low, high, inside]


def _check_values(path: str | Path, space: dict[str, tuple[str, list]], curriculum: dict,
                  source: str | Path | None) -> None:
    """The curriculum with each parameter's values substituted (alone, then all low, then all high)
    still validates, so no trial fails on a value the curriculum's schema refuses."""
    from common.curriculum.schema import curriculum_from_mapping

    def refused(params: dict[str, Any]) -> str | None:
        try:
            curriculum_from_mapping(with_params(curriculum, params), source)
        except (ValueError, TypeError) as error:
            if isinstance(error, ConfigError):
                return ": ".join(p for p in (error.field, error.problem) if p)
            return f"{type(error).__name__}: {error}"
        return None

    for key, (kind, args) in space.items():
        for value in _samples(kind, args):
            problem = refused({key: value})
            if problem:
                raise ConfigError(path, key, f"{kind} value {quote(value)} is not valid in the curriculum ({problem})")
    for end in (0, -1):
        params = {key: _samples(kind, args)[end] for key, (kind, args) in space.items()}
        problem = refused(params)
        if problem:
            ends = "low" if end == 0 else "high"
            raise ConfigError(path, None, f"every parameter at its {ends} end together is not valid in the curriculum ({problem})")


def with_params(curriculum: dict, params: dict[str, Any]) -> dict:
    """A copy of a curriculum mapping with each dotted path set."""
    data = json.loads(json.dumps(curriculum))
    for dotted, value in params.items():
        node = data
        parts = dotted.split(".")
        for part in parts[:-1]:
            node = node[int(part)] if isinstance(node, list) else node.setdefault(part, {})
        last: Any = int(parts[-1]) if isinstance(node, list) else parts[-1]
        node[last] = value.item() if isinstance(value, np.generic) else value
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

    from common.curriculum.machine import describe, machine
    from common.curriculum.runner import Runner
    from common.curriculum.schema import curriculum_from_mapping

    data = with_params(config["curriculum"], config.get("params", {}))
    data["seed"] = int(config["seed"])
    curriculum = curriculum_from_mapping(data, config["source"])
    run_dir = Path(config["sweep_dir"]) / "trials" / trial_name(config, tune.get_context().get_trial_id())
    node = ray.get_runtime_context().get_node_id()
    on = describe(machine())  # a cluster's nodes may differ, and a seed trains other weights on another CPU

    def report(row: dict) -> None:
        tune.report({"success_rate": float(row["success_rate"]), "spl": float(row["spl"]), "stage": row["stage"],
                     "timesteps": int(row["timesteps"]), "node": node, "machine": on, "run_dir": str(run_dir)})

    state = Runner(curriculum, run_dir, resume=(run_dir / "state.json").exists(), device=config.get("device"),
                   progress=False, on_evaluation=report).run()
    final = state["stages"][curriculum.stages[-1].name]["final"]
    tune.report({"success_rate": final["success_rate"], "spl": final["spl"], "stage": "final",
                 "timesteps": state["stages"][curriculum.stages[-1].name]["timesteps"], "node": node,
                 "machine": on, "run_dir": str(run_dir), "final": final, "done": True})


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


OPTIONS_FILE = "options.json"  # what the sweep was asked to do, for a resume to hold to
OPTION_DEFAULTS = {"seeds": 1, "space": None, "trials": 8, "metric": "success_rate"}


class SweepOptions(BaseModel):
    """:data:`OPTIONS_FILE`'s content, within the command line's ranges."""

    model_config = ConfigDict(extra="forbid", strict=True)

    seeds: Annotated[int, Field(ge=1, le=1000)]
    space: Annotated[str, Field(max_length=4096)] | None
    trials: Annotated[int, Field(ge=1, le=10_000)]
    metric: Literal[METRICS]  # type: ignore[valid-type]
    curriculum_sha256: Annotated[str, Field(pattern="^[0-9a-f]{64}$")] | None = None  # None: recorded before digests
    space_sha256: Annotated[str, Field(pattern="^[0-9a-f]{64}$")] | None = None  # a search's space file, likewise


def curriculum_digest(curriculum: dict) -> str:
    """A digest of a curriculum's content (not its comments or layout), for a resume to compare."""
    return hashlib.sha256(json.dumps(curriculum, sort_keys=True, default=str).encode()).hexdigest()


def sweep_options(out: Path, given: dict[str, Any], resume: bool, source: str | Path, digest: str) -> dict[str, Any]:
    """The options a sweep runs with: those given, defaults for the rest, and its curriculum's
    ``digest``; resumed, those it began with (read from :data:`OPTIONS_FILE`), an option given
    otherwise or an edited curriculum refused: Tune restores the sweep it saved, and --seeds 3 on
    a sweep of 2 kept 2 seeds without a word, as an edited budget kept the old one."""
    from pydantic import ValidationError

    from common.files import read_json
    from common.scenario import pydantic_error

    path = out / OPTIONS_FILE
    if resume and path.is_file():
        data = read_json(path, 64 * 1024, "the options a sweep began with")
        try:  # checked as the command line checks them: a run directory is shared, and seeds drive a loop
            recorded = SweepOptions.model_validate(data).model_dump()
        except ValidationError as exc:
            raise pydantic_error(path, exc, SweepOptions) from None
        for name, value in given.items():
            if value is not None and value != recorded[name]:
                raise ConfigError(None, f"--{name}", f"{quote(value)}, but this sweep began with {quote(recorded[name])}: a "
                                  "resume continues it as it began (leave the option out, or choose another --out)")
        if recorded["curriculum_sha256"] not in (None, digest):
            raise ConfigError(source, None, "changed since this sweep began; a resume continues it as it began "
                              "(restore the file, or start a new sweep with another --out)")
        return recorded
    return {**{name: OPTION_DEFAULTS[name] if value is None else value for name, value in given.items()},
            "curriculum_sha256": digest}


def _refuse_options_that_do_not_apply(seeds: int | None, space: str | Path | None, trials: int | None,
                                      metric: str | None) -> None:
    """A seed sweep has no trials to count or metric to maximise, and a search runs one seed: an
    option given where it does not apply was recorded and silently ignored (a researcher asking a
    search for three seeds got one)."""
    if space is not None and seeds is not None and seeds != 1:
        raise ConfigError(None, "--seeds", f"{seeds} with --space; allowed: a search (--space) runs the curriculum's "
                          "seed, so leave --seeds out, or sweep seeds without --space")
    for name, value in (("--trials", trials), ("--metric", metric)):
        if space is None and value is not None:
            raise ConfigError(None, name, f"{quote(value)} without --space; allowed: only with a search (--space)")


def _check_out(out: Path) -> None:
    """Refuse, before anything is written, an ``out`` that is a file, or a directory that holds
    files and is not a sweep's (the results would be written among a user's files)."""
    if out.exists() and not out.is_dir():
        raise ConfigError(out, None, "is not a directory; --out names the sweep's directory")
    if out.is_dir() and any(out.iterdir()) and not any((out / name).exists() for name in (OPTIONS_FILE, "ray", "trials")):
        raise ConfigError(out, None, f"is not empty and not a sweep's directory (it has no {OPTIONS_FILE}, ray or "
                          "trials); choose an empty or a new --out (nothing was changed)")


def run_sweep(source: str | Path, out: Path, seeds: int | None = None, space: str | Path | None = None,
              trials: int | None = None, metric: str | None = None, address: str | None = None, cpus_per_trial: float = 1.0,
              max_failures: int = 2, resume: bool = False, device: str | None = None,
              trainable: Callable[[dict], None] | None = None) -> dict[str, Any]:
    """Run the sweep (or continue an interrupted one) and write its results; return sweep.json's content.

    Every input is checked before Ray starts. Trials that fail are in the results (status ``error``,
    the first line of the error, and the names in ``failed``), for the caller to report and exit on.
    """
    from common.curriculum.schema import MAX_SEED, load_curriculum

    out = Path(out).resolve()
    _check_out(out)
    _refuse_options_that_do_not_apply(seeds, space, trials, metric)
    if resume and not out.exists():
        raise ConfigError(out, None, "nothing to resume here (no sweep ran); run without --resume")
    given = {"seeds": seeds, "space": None if space is None else str(Path(space).resolve()), "trials": trials,
             "metric": metric}
    curriculum = read_yaml(source)
    options = sweep_options(out, given, resume, source, curriculum_digest(curriculum))
    seeds, space, trials, metric = (options[name] for name in OPTION_DEFAULTS)
    if metric not in METRICS:
        raise ConfigError(None, "--metric", f"{metric!r}; allowed: {', '.join(METRICS)}")
    if not (isinstance(cpus_per_trial, (int, float)) and 0 < cpus_per_trial <= 1024):  # refuses NaN too
        raise ConfigError(None, "--cpus-per-trial", f"got {cpus_per_trial!r}; allowed: a number above 0, at most 1024")
    config = load_curriculum(source)  # one-line errors before any trial starts
    if space is None and (last := config.seed + SEED_STRIDE * (seeds - 1)) > MAX_SEED:
        raise ConfigError(source, "seed", f"{config.seed}: --seeds {seeds} runs seeds up to {last:,}; allowed: a seed of "
                          f"at most {MAX_SEED - SEED_STRIDE * (seeds - 1):,} for --seeds {seeds}")
    domains = None if space is None else load_space(space, read_yaml(source), source)
    if space is not None:
        digest = curriculum_digest(read_yaml(space))
        if resume and options.get("space_sha256") not in (None, digest):
            raise ConfigError(space, None, "changed since this sweep began; a resume continues it as it began "
                              "(restore the file, or start a new sweep with another --out)")
        options["space_sha256"] = digest
    if address:
        check_address(address)
    writable_place(out, "--out", directory=True)
    trainable = trainable or run_trial
    # Tune's newer console output ignores verbose=0; the runs' own reports are what users read.
    os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")
    # Ray starts its workers at niceness 15, as for background chores. Trials are the user's main
    # job: at 15, anything else on the machine starves them (a trial got 6% of a core beside two
    # other processes on 2 cores). The local cluster's raylet reads this; an --address cluster
    # keeps its own setting.
    os.environ.setdefault("RAY_worker_niceness", "0")
    import ray
    from ray import tune

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

                param_space = {**base, "seed": curriculum.get("seed", 0),
                               "params": {key: _tune_domain(kind, args) for key, (kind, args) in domains.items()}}
                tune_config = tune.TuneConfig(metric=metric, mode="max", num_samples=trials,
                                              search_alg=OptunaSearch(seed=0),
                                              scheduler=ASHAScheduler(grace_period=2, reduction_factor=2))
            out.mkdir(parents=True, exist_ok=True)
            atomic_write(out / OPTIONS_FILE, lambda tmp: tmp.write_text(json.dumps(options, indent=2) + "\n"))
            tuner = tune.Tuner(resources, param_space=param_space, tune_config=tune_config,
                               run_config=tune.RunConfig(name="ray", storage_path=str(out), verbose=0,
                                                         failure_config=tune.FailureConfig(max_failures=max_failures)))
        grid = tuner.fit()
        concurrent = int(ray.cluster_resources().get("CPU", 1) // cpus_per_trial)
    finally:
        ray.shutdown()

    return write_results(out, grid, metric, address, concurrent, time.perf_counter() - began,
                         searched=space is not None, resumed=resume)
