"""Test-wide settings: headless plotting, and the comparison tables printed into the log."""

import importlib
import os
import shutil
import tempfile
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")

TABLES_ENV = "NAV_TEST_TABLES_DIR"


_MADE: list[str] = []  # the folders this session made, removed when it ends


def pytest_configure(config):
    # pytest-xdist's default scheduler hands each worker chunks of up to a quarter of the tests
    # left, so the session's last tests (the course site's) reached one worker while lessons still
    # waited in the other's chunk, and the site's build ran them itself. One test at a time keeps
    # the order pytest_collection_modifyitems sets, and no worker sits on a queue of long tests.
    if config.pluginmanager.hasplugin("xdist") and config.getoption("maxschedchunk") is None:
        config.option.maxschedchunk = 1
    # The controller process makes the folder; pytest-xdist workers inherit the variable.
    if not hasattr(config, "workerinput"):
        _MADE.append(tempfile.mkdtemp(prefix="nav-tables-"))
        os.environ[TABLES_ENV] = _MADE[-1]
        # SB3 gives every model trained without a logger a /tmp/SB3-<time> folder; keep them in one place.
        if "SB3_LOGDIR" not in os.environ:
            _MADE.append(tempfile.mkdtemp(prefix="nav-sb3-logs-"))
            os.environ["SB3_LOGDIR"] = _MADE[-1]


def pytest_unconfigure(config):
    """Remove the session's folders (after the summary has printed the tables from them)."""
    while _MADE:
        shutil.rmtree(_MADE.pop(), ignore_errors=True)


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """Print the controller-comparison tables (tests/test_baselines.py) and the count of IR-SIM's
    usage worlds (tests/test_irsim_usage.py) into the log, as CI's record."""
    folder = os.environ.get(TABLES_ENV)
    tables = sorted(Path(folder).glob("*.md")) if folder else []
    if tables:
        terminalreporter.section("controller comparison (flatland)")
        for table in tables:
            terminalreporter.write(table.read_text() + "\n")
    results = sorted((Path(folder) / "irsim_usage").glob("*.txt")) if folder else []
    if results:
        terminalreporter.section("IR-SIM's usage worlds in flatland")
        outcomes = [path.read_text() for path in results]
        for path, outcome in zip(results, outcomes):
            terminalreporter.write(f"{path.stem.replace('__', '/')}: {outcome}\n")
        counts = {kind: sum(o.startswith(kind) for o in outcomes) for kind in ("reproduced", "refused", "not run")}
        terminalreporter.write(f"IR-SIM runs {len(outcomes) - counts['not run']} of {len(outcomes)}: flatland reproduces "
                               f"{counts['reproduced']}, refuses {counts['refused']} with one line, diverges on none "
                               f"(a divergence fails its test)\n")


import pytest  # noqa: E402


def pytest_collection_modifyitems(config, items):
    """The files holding long tests (marked ``slow``) first and the course site's tests last, each
    in file order. pytest-xdist hands tests to its workers in this order: long tests begun early
    end before the short ones run out, rather than leaving one worker alone at the end; a file
    kept whole sets its module fixtures up once; and when the site is built, every lesson test
    has long finished and filled the cache the site reads (tests/test_notebooks.py), so the build
    waits for no lesson still running on the other worker. (That holds as tests are handed out
    one at a time: :func:`pytest_configure`.)"""
    slow_files = {item.path for item in items if item.get_closest_marker("slow")}

    def rank(item) -> int:
        if "site" in getattr(item, "fixturenames", ()):
            return 2
        return 0 if item.path in slow_files else 1

    items.sort(key=rank)  # stable: file order within each rank


IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")


def optional(module: str):
    """Import an optional test dependency: skip without it, except in CI (CI=true), where a
    missing one fails, so a green CI never hides a test that did not run."""
    if IN_CI:
        return importlib.import_module(module)  # the module itself, also for a dotted name
    return pytest.importorskip(module)


def missing(what: str) -> None:
    """Skip a test whose tool (a display server, say) is not on this machine; fail in CI."""
    if IN_CI:
        pytest.fail(f"{what} is missing in CI, where every test must run")
    pytest.skip(f"{what} is missing")


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
