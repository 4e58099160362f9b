"""Test-wide settings: headless plotting, and the comparison tables printed into the log."""

import os
import tempfile
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")

TABLES_ENV = "NAV_TEST_TABLES_DIR"


def pytest_configure(config):
    # The controller process makes the folder; pytest-xdist workers inherit the variable.
    if not hasattr(config, "workerinput"):
        os.environ[TABLES_ENV] = tempfile.mkdtemp(prefix="nav-tables-")


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """Print the controller-comparison tables (tests/test_baselines.py) into the log, as CI's record."""
    folder = os.environ.get(TABLES_ENV)
    tables = sorted(Path(folder).glob("*.md")) if folder else []
    if tables:
        terminalreporter.section("controller comparison (flatland)")
        for table in tables:
            terminalreporter.write(table.read_text() + "\n")


import pytest  # noqa: E402


@pytest.fixture(scope="session")
def untrained_policy(tmp_path_factory) -> Path:
    """A PPO policy zip (nav7, untrained) whose manifest says it trained with 30-step episodes."""
    import gymnasium as gym
    from stable_baselines3 import PPO

    import flatland  # noqa: F401
    from common.curriculum.policy_file import save_policy

    model = PPO("MlpPolicy", gym.make("flatland/Nav-v0", world="open"), n_steps=64, batch_size=64, device="cpu", seed=0)
    return save_policy(model, tmp_path_factory.mktemp("policy") / "untrained.zip",
                       {"algorithm": "ppo", "observation": "nav7", "goal_distance_scale": 10.0, "max_steps": 30})
