"""Trainables the sweep tests inject: a trial whose process dies once, after its first checkpoint; a
trial that fails outright; a trial that records the niceness it runs at."""

from __future__ import annotations

import os
from pathlib import Path

from common.curriculum.sweep import run_trial


def crash_once(config: dict) -> None:
    """Run the trial; the first time, kill its process at its first report (after that evaluation's
    checkpoint), as a lost node would. Tune retries it, and the run resumes from the checkpoint."""
    from ray import tune

    marker = Path(config["sweep_dir"]) / f"crashed-seed{config['seed']}"
    if not marker.exists():
        def die(metrics, **kwargs):
            marker.write_text(str(metrics.get("timesteps")))
            os._exit(1)

        tune.report = die
    run_trial(config)



def fail_first_to_start(config: dict) -> None:
    """Run the trial; the first trial of the sweep to start fails at its first evaluation (its run
    directory begun) with a two-line error. The others run as usual."""
    from ray import tune

    try:
        os.close(os.open(Path(config["sweep_dir"]) / "failed-once", os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        return run_trial(config)

    def fail(metrics, **kwargs):
        raise RuntimeError("planted failure at the first evaluation\nits second line")

    report, tune.report = tune.report, fail
    try:
        run_trial(config)
    finally:
        tune.report = report  # a reused worker runs its next trial as usual


def record_niceness(config: dict) -> None:
    """Run the trial, first writing the niceness its training thread runs at."""
    (Path(config["sweep_dir"]) / f"niceness-seed{config['seed']}").write_text(str(os.getpriority(os.PRIO_PROCESS, 0)))
    run_trial(config)
