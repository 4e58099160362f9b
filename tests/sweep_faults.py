"""Fault injection for the sweep tests: a trial whose process dies once, after its first checkpoint."""

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
