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
