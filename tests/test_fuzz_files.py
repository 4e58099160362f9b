"""Seeded mutations of every kind of file the project reads (policy zips, curricula, scenario files,
IR-SIM world files, a run's state) are each loaded as a user's command would load them: a file
loads, or it is refused with a one-line ConfigError, never a traceback, and never past the caps
on time and memory (docs/curricula.md, "Files from others: one bounded reader")."""

from __future__ import annotations

import io
import re
import resource
import shutil
import time
import zipfile
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from common.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
SEED = 20261124
SECONDS_PER_FILE = 2.0
MEGABYTES = 500

IRSIM_WORLD = """\
world: {height: 10, width: 10, step_time: 0.1, sample_time: 0.1, collision_mode: stop}
robot:
  - kinematics: {name: diff}
    shape: {name: circle, radius: 0.2}
    state: [1, 1, 0.5]
    goal: [9, 9, 0]
    vel_max: [1, 1]
    sensors: [{name: lidar2d, range_min: 0, range_max: 6, angle_range: 6.283, number: 72, noise: false}]
obstacle:
  - {shape: {name: polygon, vertices: [[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]]}, state: [2, 2.5, 0]}
  - {shape: {name: linestring, vertices: [[0, 0], [1, 1], [2, 0.5]]}, state: [5, 1, 0]}
  - {shape: {name: rectangle, length: 1.0, width: 0.5}, state: [7, 6, 0.3]}
  - {number: 4, distribution: {name: circle, radius: 3, center: [5, 5]}, shape: {name: circle, radius: 0.3}}
"""

# Tokens a hostile or broken file tends to hold.
NASTY = [b"\x00", b"\xff\xfe", b"&a [1, 2]", b"*a", b"!!python/object:os.system", b"[" * 60, b"{" * 60,
         b"9" * 5000, b"1e308", b"-1e308", b".nan", b".inf", b"2024-02-30", b"~", b"''", b"'", b'"', b"\t",
         b": : :", b"- - -", b"\n  \n- ", b"\r\n", b"<<: *a", b"1000000", b"-5", b"0"]


def _mutate(data: bytes, rng: np.random.Generator) -> bytes:
    """One random change: flipped bits, a span cut, doubled or replaced, a number made extreme, a
    nasty token inserted, or the end cut off."""
    data = bytearray(data)
    kind = int(rng.integers(7))
    at = int(rng.integers(len(data) + 1))
    span = int(rng.integers(1, 64))
    if kind == 0:
        for _ in range(int(rng.integers(1, 8))):
            i = int(rng.integers(len(data)))
            data[i] ^= 1 << int(rng.integers(8))
    elif kind == 1:
        del data[at:at + span]
    elif kind == 2:
        data[at:at] = data[at:at + span] * int(rng.integers(2, 50))
    elif kind == 3:
        numbers = list(re.finditer(rb"-?\d+(\.\d+)?", bytes(data)))
        if numbers:
            match = numbers[int(rng.integers(len(numbers)))]
            data[match.start():match.end()] = [b"1e300", b"-1e300", b"0", b"-1", b"1000000", b"9" * 400, b".nan"][
                int(rng.integers(7))]
    elif kind == 4:
        data[at:at] = NASTY[int(rng.integers(len(NASTY)))]
    elif kind == 5:
        del data[at:]
    else:
        data[at:at + span] = rng.integers(0, 256, span, dtype=np.uint8).tobytes()
    return bytes(data)


def _mutate_zip(original: bytes, rng: np.random.Generator) -> bytes:
    """A policy zip with its raw bytes mutated, or rebuilt with one member's (the manifest's, most often)."""
    if rng.random() < 0.3:
        return _mutate(original, rng)
    with zipfile.ZipFile(io.BytesIO(original)) as source:
        members = {info.filename: source.read(info) for info in source.infolist()}
    names = sorted(members)
    target = "manifest.json" if "manifest.json" in members and rng.random() < 0.7 else names[int(rng.integers(len(names)))]
    members[target] = _mutate(members[target], rng)
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as mutated:
        for name in names:
            mutated.writestr(name, members[name])
    return out.getvalue()


def _load_policy(path: Path) -> None:
    from common.curriculum.policy import load_policy

    load_policy(path)


def _load_curriculum(path: Path) -> None:
    from common.curriculum.schema import load_curriculum

    load_curriculum(path)


def _load_world(path: Path) -> None:
    """A scenario or IR-SIM file, loaded and driven a few steps in flatland, as `curriculum compare` would."""
    from common.world_file import WorldFile
    from flatland.world import World

    scenario = WorldFile(path).scenario(0)
    world = World(scenario, seed=0)
    world.reset()
    for _ in range(3):
        world.step(0.5, 0.2)


@pytest.fixture(scope="module")
def prepared_run(tmp_path_factory) -> Path:
    """A run directory as a run leaves it before its first checkpoint, with an evaluation row."""
    from common.curriculum.runner import Runner
    from common.curriculum.schema import load_curriculum

    out = tmp_path_factory.mktemp("fuzz") / "run"
    runner = Runner(load_curriculum(ROOT / "tests/data/tiny_curriculum.yaml"), out)
    runner.prepare()
    runner.eval_log.append({"stage": "open", "timesteps": 1024, "wall_time": 1.0, "success_rate": 0.5, "collision_rate": 0.5,
                            "timeout_rate": 0.0, "stuck_rate": 0.0, "spl": 0.4, "mean_steps": ""})
    runner.release()
    return out


def _resume(run: Path) -> Callable[[Path], None]:
    def load(path: Path) -> None:
        from common.curriculum.runner import Runner
        from common.curriculum.schema import load_curriculum

        runner = Runner(load_curriculum(ROOT / "tests/data/tiny_curriculum.yaml"), path.parent, resume=True)
        try:
            runner.prepare()
        finally:
            runner.release()

    return load


def _check(load: Callable[[Path], None], path: Path, case: str, slowest: list) -> None:
    start = time.perf_counter()
    try:
        load(path)
    except ConfigError as error:
        assert "\n" not in str(error), f"{case}: a refusal of more than one line: {error}"
    except Exception as error:  # noqa: BLE001 -- anything else is the defect this test looks for
        raise AssertionError(f"{case}: {type(error).__name__}: {error}") from error
    slowest.append((time.perf_counter() - start, case))


def _campaign(name: str, seed_files: list[tuple[str, bytes]], mutate, load, cases: int, tmp_path: Path,
              file_name: str | None = None) -> list:
    rng = np.random.default_rng([SEED, len(name)])
    slowest: list = []
    for index in range(cases):
        origin, original = seed_files[index % len(seed_files)]
        path = tmp_path / (file_name or Path(origin).name)
        path.write_bytes(mutate(original, rng))
        _check(load, path, f"{name} case {index} (from {origin})", slowest)
    return slowest


def _assert_within_caps(slowest: list, rss_before: int) -> None:
    worst = max(slowest)
    assert worst[0] < SECONDS_PER_FILE, f"{worst[1]} took {worst[0]:.2f} s"
    grown = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss_before) / 1024
    assert grown < MEGABYTES, f"the peak memory grew by {grown:.0f} MB"


@pytest.mark.slow
def test_mutated_policy_zips_load_or_are_refused_in_one_line(tmp_path):
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    seeds = [(str(p), p.read_bytes()) for p in sorted((ROOT / "curricula/policies").glob("*.zip"))]
    # Untimed: the first load imports torch and stable-baselines3 (2.4 s here when this test ran alone).
    _load_policy(Path(seeds[0][0]))
    _assert_within_caps(_campaign("policy", seeds, _mutate_zip, _load_policy, 400, tmp_path, "policy.zip"), rss)


def test_mutated_curricula_load_or_are_refused_in_one_line(tmp_path):
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    files = sorted((ROOT / "curricula").glob("*.yaml")) + sorted((ROOT / "tests/data").glob("tiny_*.yaml"))
    seeds = [(str(p), p.read_bytes()) for p in files]
    # Curricula name files relative to themselves: the mutants sit beside the originals' targets.
    shutil.copytree(ROOT / "curricula/policies", tmp_path / "policies")
    _assert_within_caps(_campaign("curriculum", seeds, _mutate, _load_curriculum, 1200, tmp_path, "c.yaml"), rss)


def test_mutated_scenario_and_irsim_files_load_or_are_refused_in_one_line(tmp_path):
    from common.generators import generate

    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    scenarios = [(f"{kind} scenario", generate(kind, 0).to_yaml().encode()) for kind in ("sparse", "warehouse", "trap")]
    seeds = scenarios + [("IR-SIM world", IRSIM_WORLD.encode())]
    _assert_within_caps(_campaign("world", seeds, _mutate, _load_world, 1600, tmp_path, "world.yaml"), rss)


def test_mutated_run_state_resumes_or_is_refused_in_one_line(tmp_path, prepared_run):
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    rng = np.random.default_rng(SEED)
    slowest: list = []
    names = ["state.json", "run.json", "eval.csv", "config.yaml"]
    for index in range(400):
        run = tmp_path / f"run{index}"
        shutil.copytree(prepared_run, run)
        name = names[index % len(names)]
        (run / name).write_bytes(_mutate((run / name).read_bytes(), rng))
        _check(_resume(run), run / name, f"run state case {index} ({name})", slowest)
        shutil.rmtree(run)
    _assert_within_caps(slowest, rss)
