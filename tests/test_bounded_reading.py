"""Every file the project opens is read through one bounded reader (common.files): regular files only
(devices, FIFOs, sockets and directories refused before they are opened, symlinks resolved), never
more than a cap whatever the size header says; policy zips with their members counted, sizes and
CRCs checked, the manifest's network bounded by its weights and the weights finite; replay buffers,
run state and YAML through the same reader. Each refusal is one line (exit code 2 from the CLI),
fast, and costs no memory to speak of."""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import socket
import struct
import subprocess
import sys
import time
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from common.curriculum.cli import main
from common.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "tests" / "data" / "tiny_curriculum.yaml"

# Runs the CLI in a fresh process limited to 4 GiB of address space (a reader that is not bounded
# fails there with a MemoryError instead of taking the machine), and reports its exit code, the
# seconds the command took and the process's peak resident memory.
_CLI = """
import json, resource, sys, time
resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))
from common.curriculum.cli import main
began = time.perf_counter()
code = main(sys.argv[1:])
print(json.dumps({"code": code, "seconds": time.perf_counter() - began,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""

# Loads a file in a fresh process, as above, timing the loader alone (what it imports first is not timed).
_TIMED = """
import json, resource, sys, time
resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))
PRELOAD
from LOADER import load
from common.errors import ConfigError
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
began = time.perf_counter()
try:
    load(sys.argv[1])
    error = None
except ConfigError as exc:
    error = str(exc)
print(json.dumps({"error": error, "seconds": time.perf_counter() - began,
                  "grew_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 - before}))
"""
_LOAD = _TIMED.replace("PRELOAD", "import stable_baselines3, torch  # noqa: F401").replace(
    "from LOADER import load", "from common.curriculum.policy import load_policy as load")
_YAML = _TIMED.replace("PRELOAD", "").replace("from LOADER import load", "from common.yaml_io import read_yaml as load")


def _in_process(script: str, *args: str, timeout: float = 60) -> tuple[dict, str]:
    result = subprocess.run([sys.executable, "-c", script, *map(str, args)], capture_output=True, text=True,
                            timeout=timeout, cwd=ROOT)
    assert "Traceback" not in result.stderr, result.stderr[-2000:]
    return json.loads(result.stdout.strip().splitlines()[-1]), result.stderr


def _one_line(err: str, expected: str) -> None:
    assert err.count("\n") == 1 and err.startswith("error: ") and expected in err, err
    assert "Traceback" not in err and len(err) < 400, err


@contextlib.contextmanager
def _deadline(seconds: float):
    """Fail, instead of hanging, if the block takes longer (a blocking open() of a FIFO, say)."""
    def expire(signum, frame):
        raise TimeoutError(f"still reading after {seconds} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


# -- the reader ----------------------------------------------------------------------------------


KINDS = {"directory": "a directory, not a regular file", "device": "a character device, not a regular file",
         "fifo": "a FIFO (named pipe), not a regular file", "socket": "a socket, not a regular file",
         "symlink to a device": "resolves to /dev/urandom, a character device, not a regular file",
         "symlink loop": "a symlink loop", "missing": "no such file"}


@pytest.mark.parametrize("kind", KINDS)
def test_the_reader_refuses_anything_but_a_regular_file_before_opening_it(kind, tmp_path):
    from common.files import read_bytes

    path = {"directory": tmp_path, "device": Path("/dev/zero")}.get(kind, tmp_path / "file")
    server = socket.socket(socket.AF_UNIX)
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "socket":
        server.bind(str(path))
    elif kind == "symlink to a device":
        path.symlink_to("/dev/urandom")
    elif kind == "symlink loop":
        path.symlink_to(path)
    try:
        with _deadline(10), pytest.raises(ConfigError) as error:  # a FIFO opened for reading waits for a writer
            read_bytes(path, 100, "a YAML file")
    finally:
        server.close()
    message = str(error.value)
    assert message.startswith(f"{path}: ") and KINDS[kind] in message and "\n" not in message, message


def test_the_reader_reads_at_most_its_cap_whatever_the_size_header_says(tmp_path):
    from common.files import read_bytes, read_text

    status = Path("/proc/self/status")  # a regular file whose size header says 0 bytes; it holds about 1 kB
    assert status.stat().st_size == 0 and len(status.read_bytes()) > 100
    with pytest.raises(ConfigError, match=r"/proc/self/status: larger than 100 bytes; expected a file of at most 100 bytes"):
        read_bytes(status, 100)
    exact = tmp_path / "exact"
    exact.write_bytes(b"x" * 100)
    assert read_bytes(exact, 100) == b"x" * 100
    exact.write_bytes(b"x" * 101)
    with pytest.raises(ConfigError, match="larger than 100 bytes"):
        read_bytes(exact, 100)
    exact.write_bytes(b"a: 1\r\nb: \xff\n")
    with pytest.raises(ConfigError, match=r"exact: not UTF-8 text \(byte 9\)"):
        read_text(exact, 100)


@pytest.mark.parametrize("case", ["validate /dev/zero", "eval --policy /dev/zero", "validate WORLD -> /dev/urandom",
                                  "compare --scenario-file WORLD -> /dev/urandom", "validate FIFO", "eval --policy FIFO",
                                  "compare --scenario-file FIFO"])
def test_devices_symlinks_to_them_and_fifos_are_one_line_refusals_from_the_cli(case, tmp_path):
    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "world.yaml").symlink_to("/dev/urandom")
    words = case.split(" -> ")[0].replace("WORLD", str(tmp_path / "world.yaml")).replace("FIFO", str(tmp_path / "fifo")).split()
    words += {"validate": [], "eval": ["--episodes", "1"],
              "compare": ["--episodes", "1", "--controllers", "go_to_goal", "--out", str(tmp_path / "out")]}[words[0]]
    # Unbounded, each of these took gigabytes in seconds, or (a FIFO) waited for ever.
    stats, err = _in_process(_CLI, *words, timeout=20)
    _one_line(err, "a FIFO (named pipe), not a regular file" if "FIFO" in case else "a character device, not a regular file")
    # The time includes what main imports on its way (the schema's torch: about 4 s on this machine,
    # 5.4 s once under load against the old 5 s bound); an unbounded read never ends.
    assert stats["code"] == 2 and stats["seconds"] < 12 and stats["peak_mb"] < 1500, stats
    assert not (tmp_path / "out").exists()


# -- YAML and JSON values Python cannot build --------------------------------------------------


@pytest.mark.parametrize("text, expected", [
    ("name: x\nseed: " + "9" * 5000 + "\n", "line 2: an integer of more than 4300 digits; refused"),
    ("name: x\nseed: 0x" + "f" * 4000 + "\n", "line 2: an integer of more than 4300 digits; refused"),
    ("name: x\nseed: 2024-02-30\n", "line 2: '2024-02-30' is not a valid date (day is out of range for month); refused"),
])
def test_yaml_values_python_cannot_build_are_one_line_refusals(text, expected, tmp_path, capsys):
    path = tmp_path / "values.yaml"
    path.write_text(text)
    assert main(["validate", str(path)]) == 2
    _one_line(capsys.readouterr().err, f"{path}: {expected}")


@pytest.mark.parametrize("unit", ["1, ", "{}, ", "- 1\n"])
def test_a_yaml_file_of_a_million_values_is_refused_fast_for_what_it_holds(unit, tmp_path, capsys):
    path = tmp_path / "many.yaml"
    head = "name: x\nv:\n" if unit.startswith("-") else "name: x\nv: ["
    tail = "" if unit.startswith("-") else "1]\n"
    path.write_text(head + unit * ((2 * 2**20 - len(head) - len(tail)) // len(unit)) + tail)
    assert path.stat().st_size <= 2 * 2**20
    stats, _ = _in_process(_YAML, path, timeout=60)
    # Composed whole before the count, these took 11 to 20 s and 400 to 800 MB, and the error blamed
    # aliases. Memory tells the two apart on any machine; the time bound is loose because a loaded
    # machine took 2.4 s for what an idle one does in under 1.
    assert stats["error"].startswith(f"{path}: line ") and stats["error"].endswith(": holds more than 200,000 values; refused")
    assert stats["seconds"] < 8 and stats["grew_mb"] < 200, stats
    assert main(["validate", str(path)]) == 2
    _one_line(capsys.readouterr().err, "holds more than 200,000 values; refused")


def test_a_json_integer_past_pythons_digit_limit_is_a_one_line_refusal(tmp_path):
    from common.files import read_json

    path = tmp_path / "state.json"
    path.write_text('{"done": [], "n": ' + "9" * 5000 + "}")
    with pytest.raises(ConfigError, match=rf"{path}: holds an integer of more than 4300 digits"):
        read_json(path, 2**20)


# -- policy zips ---------------------------------------------------------------------------------


def _rewrite(source: Path, target: Path, replace: dict[str, bytes], method: int = zipfile.ZIP_DEFLATED) -> Path:
    with zipfile.ZipFile(source) as old, zipfile.ZipFile(target, "w", method) as new:
        for item in old.infolist():
            new.writestr(item.filename, replace.get(item.filename, old.read(item)))
    return target


def _manifest(policy: Path) -> dict:
    return json.loads(zipfile.ZipFile(policy).read("nav_manifest.json"))


def _saved(value) -> bytes:
    buffer = io.BytesIO()
    torch.save(value, buffer)
    return buffer.getvalue()


def _central_record(data: bytes, member: str) -> int:
    """Where ``member``'s central directory record starts in the zip ``data``."""
    at = data.find(b"PK\x01\x02")
    while at >= 0:
        length = struct.unpack_from("<H", data, at + 28)[0]
        if data[at + 46:at + 46 + length] == member.encode():
            return at
        at = data.find(b"PK\x01\x02", at + 4)
    raise AssertionError(member)


def test_a_policy_zip_with_a_bad_crc_is_a_one_line_refusal(untrained_policy, tmp_path, capsys):
    data = bytearray(_rewrite(untrained_policy, tmp_path / "stored.zip", {}, zipfile.ZIP_STORED).read_bytes())
    at = bytes(data).find(b'"max_steps": 30')  # in the manifest, stored as it is
    data[at + len('"max_steps": ')] = ord("9")  # still valid JSON, still a valid manifest: only the CRC tells
    bad = tmp_path / "bad-crc.zip"
    bad.write_bytes(bytes(data))
    assert main(["eval", "--policy", str(bad), "--episodes", "1"]) == 2
    _one_line(capsys.readouterr().err, "nav_manifest.json: its CRC-32 does not match its data (a damaged or edited zip); refused")


@pytest.mark.parametrize("member, change", [("nav_manifest.json", -10), ("nav_manifest.json", +10), ("policy.pth", +1000),
                                            ("policy.pth", -1000)])
def test_a_policy_zip_whose_size_header_lies_is_a_one_line_refusal(untrained_policy, tmp_path, capsys, member, change):
    data = bytearray(untrained_policy.read_bytes())
    record = _central_record(bytes(data), member)
    size = struct.unpack_from("<I", data, record + 24)[0]
    struct.pack_into("<I", data, record + 24, size + change)  # the uncompressed size zipfile trusts
    bad = tmp_path / "lying.zip"
    bad.write_bytes(bytes(data))
    assert main(["eval", "--policy", str(bad), "--episodes", "1"]) == 2
    _one_line(capsys.readouterr().err, f"{member}: its")


def _many_members(path: Path, count: int, claimed: int | None = None) -> Path:
    """A zip of ``count`` empty members (all naming one local header, so it stays small: 52 bytes
    a member); its end record claims ``claimed`` members (default: the truth)."""
    local = struct.pack("<4s5H3L2H", b"PK\x03\x04", 20, 0, 0, 0, 0, 0, 0, 0, 6, 0) + b"000000"
    record = np.dtype([("sig", "S4"), ("head", "<u2", (6,)), ("crc", "<u4"), ("sizes", "<u4", (2,)),
                       ("lengths", "<u2", (5,)), ("attrs", "<u4", (2,)), ("name", "S6")])
    assert record.itemsize == 52
    directory = np.zeros(count, dtype=record)
    directory["sig"] = b"PK\x01\x02"
    directory["head"][:, 0:2] = 20
    directory["lengths"][:, 0] = 6
    directory["name"] = np.char.zfill(np.arange(count).astype("S6"), 6)
    claimed = count if claimed is None else claimed
    end = struct.pack("<4s4H2LH", b"PK\x05\x06", 0, 0, min(claimed, 0xFFFF), min(claimed, 0xFFFF),
                      directory.nbytes, len(local), 0)
    if claimed >= 0xFFFF:  # as zipfile writes it: the true count in a Zip64 end record, and a locator
        at = len(local) + directory.nbytes
        end = (struct.pack("<4sQ2H2L4Q", b"PK\x06\x06", 44, 45, 45, 0, 0, claimed, claimed, directory.nbytes, len(local))
               + struct.pack("<4sLQL", b"PK\x06\x07", 0, at, 1) + end)
    path.write_bytes(local + directory.tobytes() + end)
    assert len(zipfile.ZipFile(path).infolist()) == count if count < 100 else True
    return path


@pytest.mark.parametrize("count, claimed", [(1_000_000, None), (1_000_000, 3), (17, None)])
def test_a_zip_of_too_many_members_is_refused_fast_without_listing_them(tmp_path, count, claimed):
    from common.curriculum.policy_file import PolicyFile

    path = _many_members(tmp_path / "many.zip", count, claimed)
    tracemalloc.start()
    began = time.perf_counter()
    try:
        with pytest.raises(ConfigError) as error:
            PolicyFile(path)
        seconds, peak = time.perf_counter() - began, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    message = str(error.value)
    assert "allowed: at most 16 members" in message and "\n" not in message, message
    # Listing a million members took 49 s and 1.6 GB; the zip itself (52 MB here) is read whole.
    assert seconds < 1 and peak < 1.2 * path.stat().st_size + 5e6, (seconds, peak)


@pytest.mark.parametrize("algorithm, net_arch, critics", [
    ("sac", {"pi": [4096] * 16, "qf": [4096] * 16}, 10),
    ("ppo", [4096] * 16, None),
    ("td3", [4096] * 16, 10),
])
def test_a_manifest_whose_network_outgrows_its_weights_is_refused_before_anything_is_built(
        untrained_policy, tmp_path, algorithm, net_arch, critics):
    manifest = _manifest(untrained_policy)
    manifest.update(algorithm=algorithm, policy_kwargs={"net_arch": net_arch, **({"n_critics": critics} if critics else {})})
    bad = _rewrite(untrained_policy, tmp_path / "huge.zip", {"nav_manifest.json": json.dumps(manifest).encode()})
    # Built from the manifest first, these took about 21 GB (SAC) or minutes (PPO).
    stats, _ = _in_process(_LOAD, bad, timeout=60)
    assert stats["error"] and stats["error"].startswith(f"{bad}: policy.pth: the weights do not fit a {algorithm.upper()} policy")
    assert "GiB of parameters, they hold 37.3 KiB (the manifest's policy_kwargs:" in stats["error"], stats
    assert stats["error"].endswith("; refused") and "\n" not in stats["error"], stats
    assert stats["seconds"] < 1 and stats["grew_mb"] < 100, stats


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_weights_of_the_right_shapes_that_are_not_finite_are_refused(untrained_policy, tmp_path, capsys, value):
    state = torch.load(io.BytesIO(zipfile.ZipFile(untrained_policy).read("policy.pth")), weights_only=True)
    state["action_net.weight"][0, 0] = value
    bad = _rewrite(untrained_policy, tmp_path / "nan.zip", {"policy.pth": _saved(state)})
    assert main(["eval", "--policy", str(bad), "--episodes", "1"]) == 2
    _one_line(capsys.readouterr().err, "policy.pth: action_net.weight holds NaN or infinite values; refused")


def test_weights_that_repeat_one_small_storage_are_refused_before_their_values_are_read(untrained_policy, tmp_path, capsys):
    state = torch.load(io.BytesIO(zipfile.ZipFile(untrained_policy).read("policy.pth")), weights_only=True)
    state["huge"] = torch.zeros(1).expand(100_000, 100_000)  # 40 GB of float32 as a view of 4 bytes
    bad = _rewrite(untrained_policy, tmp_path / "views.zip", {"policy.pth": _saved(state)})
    assert len(bad.read_bytes()) < 200_000
    assert main(["eval", "--policy", str(bad), "--episodes", "1"]) == 2
    _one_line(capsys.readouterr().err, "policy.pth: its tensors span more than 64 MiB; refused")


def test_a_manifest_integer_past_pythons_digit_limit_is_a_one_line_refusal(untrained_policy, tmp_path, capsys):
    text = json.dumps(_manifest(untrained_policy)).replace('"max_steps": 30', '"max_steps": ' + "9" * 5000)
    bad = _rewrite(untrained_policy, tmp_path / "digits.zip", {"nav_manifest.json": text.encode()})
    assert main(["eval", "--policy", str(bad), "--episodes", "1"]) == 2
    _one_line(capsys.readouterr().err, "nav_manifest.json: holds an integer of more than 4300 digits")


# -- run state and replay buffers ----------------------------------------------------------------


def _started_run(tmp_path: Path) -> Path:
    """A run directory as a run leaves it after its first evaluation (resumable)."""
    from common.curriculum.runner import Runner
    from common.curriculum.schema import load_curriculum

    out = tmp_path / "run"
    runner = Runner(load_curriculum(TINY), out)
    runner.prepare()
    runner.eval_log.append({"stage": "open", "timesteps": 1024, "wall_time": 1.0, "success_rate": 0.5, "collision_rate": 0.5,
                            "timeout_rate": 0.0, "stuck_rate": 0.0, "spl": 0.4, "mean_steps": ""})
    runner.release()
    return out


@pytest.mark.parametrize("name", ["state.json", "run.json"])
def test_run_state_past_pythons_digit_limit_or_a_fifo_is_a_one_line_refusal_on_resume(tmp_path, name):
    from common.curriculum.runner import Runner
    from common.curriculum.schema import load_curriculum

    out = _started_run(tmp_path)
    (out / name).write_text('{"done": [], "stages": {}, "git_commit": ' + "9" * 5000 + "}")
    with pytest.raises(ConfigError, match=rf"{out / name}: holds an integer of more than 4300 digits"):
        Runner(load_curriculum(TINY), out, resume=True).prepare()
    (out / name).unlink()
    os.mkfifo(out / name)
    with _deadline(10), pytest.raises(ConfigError, match=rf"{out / name}: a FIFO \(named pipe\), not a regular file"):
        Runner(load_curriculum(TINY), out, resume=True).prepare()


def _sac_buffer():
    import gymnasium as gym
    from stable_baselines3 import SAC

    import flatland  # noqa: F401

    model = SAC("MlpPolicy", gym.make("flatland/Nav-v0", world="open"), buffer_size=50, learning_starts=10,
                device="cpu", seed=0)
    return model.replay_buffer


def test_a_replay_buffer_that_is_a_fifo_a_device_or_larger_than_the_buffer_is_refused(tmp_path):
    from common.curriculum.replay import load_replay, save_replay

    buffer = _sac_buffer()
    buffer.observations[:] = 1.5
    buffer.pos = 7
    good = save_replay(buffer, tmp_path / "replay.npz")
    fresh = _sac_buffer()
    load_replay(fresh, good)
    assert fresh.pos == 7 and np.array_equal(fresh.observations[:7], buffer.observations[:7])

    os.mkfifo(tmp_path / "fifo.npz")
    (tmp_path / "zero.npz").symlink_to("/dev/zero")
    big = tmp_path / "big.npz"
    big.write_bytes(good.read_bytes() + b"\0" * 2**20)
    for path, expected in [(tmp_path / "fifo.npz", "a FIFO (named pipe), not a regular file"),
                           (tmp_path / "zero.npz", "resolves to /dev/zero, a character device"),
                           (big, "larger than")]:
        with _deadline(10), pytest.raises(ConfigError) as error:
            load_replay(_sac_buffer(), path)
        assert str(error.value).startswith(f"{path}: ") and expected in str(error.value), error.value


def test_a_replay_buffer_file_holds_its_filled_rows_and_the_whole_buffer_is_still_read(tmp_path):
    """The whole buffer was written at every checkpoint: 109 MB for a SAC stage's 8,000 transitions."""
    from common.curriculum.replay import load_replay, save_replay

    buffer = _sac_buffer()
    buffer.observations[:7] = np.arange(7, dtype=np.float32).reshape(7, 1, 1)
    buffer.pos = 7
    whole = tmp_path / "whole.npz"  # as written before: the whole arrays whatever pos
    with whole.open("wb") as handle:
        np.savez(handle, pos=np.array(7), full=np.array(False), **{name: getattr(buffer, name) for name in
                 ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")})
    small = save_replay(buffer, tmp_path / "replay.npz")
    assert small.stat().st_size < whole.stat().st_size / 2  # 7 of 50 rows, beside the members' headers
    fresh = _sac_buffer()
    load_replay(fresh, small)
    assert fresh.pos == 7 and np.array_equal(fresh.observations, buffer.observations)
    buffer.full, buffer.observations[:] = True, 2.0  # full: every row, wherever pos is
    fresh = _sac_buffer()
    load_replay(fresh, save_replay(buffer, tmp_path / "full.npz"))
    assert fresh.full and np.array_equal(fresh.observations, buffer.observations)
    fresh = _sac_buffer()
    load_replay(fresh, whole)
    assert fresh.pos == 7 and not fresh.full and np.array_equal(fresh.observations[:7], np.load(whole)["observations"][:7])


def test_a_replay_buffer_with_a_bad_crc_is_a_one_line_refusal(tmp_path):
    from common.curriculum.replay import load_replay, save_replay

    buffer = _sac_buffer()
    buffer.rewards[:] = 0.25
    buffer.pos = 5
    data = bytearray(save_replay(buffer, tmp_path / "replay.npz").read_bytes())
    at = data.find(np.float32(0.25).tobytes())
    data[at] ^= 1
    bad = tmp_path / "bad.npz"
    bad.write_bytes(bytes(data))
    with pytest.raises(ConfigError, match=r"bad.npz: rewards.npy: its CRC-32 does not match its data"):
        load_replay(_sac_buffer(), bad)


NETWORKS = [("ppo", {}, False), ("ppo", {"net_arch": [16, 8]}, True), ("ppo", {"net_arch": {"pi": [], "vf": [5, 3]}}, False),
            ("sac", {}, False), ("sac", {"net_arch": {"pi": [8], "qf": [5, 4]}, "n_critics": 3}, True),
            ("sac", {"net_arch": [], "share_features_extractor": True}, False), ("td3", {"net_arch": [7, 9], "n_critics": 1}, False)]


@pytest.mark.parametrize("algorithm, kwargs, sde", NETWORKS)
@pytest.mark.parametrize("observation", ["nav7", "lidar43_log"])
def test_the_network_a_manifest_describes_is_counted_exactly_without_building_it(algorithm, kwargs, sde, observation):
    from common.curriculum.policy import build_policy, network_parameters
    from common.curriculum.policy_file import Manifest

    manifest = Manifest.model_validate({"format": 2, "algorithm": algorithm, "observation": observation,
                                        "goal_distance_scale": 10.0, "policy_kwargs": kwargs, "use_sde": sde})
    built = build_policy(manifest)
    assert network_parameters(manifest) == sum(t.numel() for t in built.state_dict().values())


@pytest.mark.parametrize("algorithm, kwargs, expected", [
    ("ppo", {"n_critics": 2}, "policy_kwargs.n_critics: a PPO policy has no critics to count; allowed: sac, td3"),
    ("sac", {"net_arch": {"pi": [64]}}, "policy_kwargs.net_arch: a SAC network needs both pi and qf"),
])
def test_a_manifest_sb3_could_not_build_is_a_one_line_refusal(untrained_policy, tmp_path, capsys, algorithm, kwargs, expected):
    manifest = _manifest(untrained_policy)
    manifest.update(algorithm=algorithm, policy_kwargs=kwargs)
    bad = _rewrite(untrained_policy, tmp_path / "bad.zip", {"nav_manifest.json": json.dumps(manifest).encode()})
    assert main(["eval", "--policy", str(bad), "--episodes", "1"]) == 2
    _one_line(capsys.readouterr().err, f"nav_manifest.json: {expected}")


def _with_pickle(policy: Path, target: Path, value, fast: bool = False) -> Path:
    """``policy`` with its policy.pth holding ``value``: pickled by torch, or (``fast``) by a pickler
    without a memo, which packs a million tiny values into a megabyte."""
    import pickle

    weights = _saved(value)
    if fast:
        inner = zipfile.ZipFile(io.BytesIO(weights))
        buffer = io.BytesIO()
        pickler = pickle.Pickler(buffer, 2)
        pickler.fast = True
        pickler.dump(value)
        out = io.BytesIO()
        with zipfile.ZipFile(out, "w") as rebuilt:
            for item in inner.infolist():
                rebuilt.writestr(item, buffer.getvalue() if item.filename.endswith(".pkl") else inner.read(item))
        weights = out.getvalue()
    return _rewrite(policy, target, {"policy.pth": weights})


def test_a_weights_pickle_or_record_count_past_its_cap_is_refused_before_it_is_unpickled(untrained_policy, tmp_path, capsys):
    many_values = _with_pickle(untrained_policy, tmp_path / "values.zip", {"junk": [[] for _ in range(300_000)]}, fast=True)
    began = time.perf_counter()
    assert main(["eval", "--policy", str(many_values), "--episodes", "1"]) == 2
    assert time.perf_counter() - began < 2
    _one_line(capsys.readouterr().err, "policy.pth: not plain weights (no pickle, or one over 256 KiB); refused")
    many_tensors = _with_pickle(untrained_policy, tmp_path / "tensors.zip", {f"t{i}": torch.zeros(1) for i in range(2100)})
    assert main(["eval", "--policy", str(many_tensors), "--episodes", "1"]) == 2
    _one_line(capsys.readouterr().err, "policy.pth: not plain weights (a zip of 2,10")
