"""SAC and TD3 replay buffers as plain arrays (``.npz``), so resuming a run never unpickles.

stable-baselines3 saves a replay buffer by pickling the whole object; here only its arrays and
two counters are written, and read back without pickles into the buffer of a model built from
the curriculum, after checking every array's shape and type against that buffer.
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Callable

import numpy as np

from common.atomic import atomic_write
from common.errors import ConfigError
from common.files import ZIP_DAMAGE, open_regular, open_zip, zip_damage

_CHUNK = 1024 * 1024

_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


def _arrays(buffer) -> dict[str, np.ndarray]:
    # With optimize_memory_usage SB3 keeps no next_observations (they are the next row's observations).
    return {name: getattr(buffer, name) for name in _ARRAYS if getattr(buffer, name, None) is not None}


def _filled(buffer, pos: int, full: bool) -> int:
    """How many rows of the buffer hold transitions."""
    return buffer.buffer_size if full else pos


def save_replay(buffer, path: str | Path) -> Path:
    """Write a buffer's position and its arrays' filled rows atomically (the whole 300k-row buffer
    of a SAC stage was 109 MB after 8,000 transitions)."""
    return atomic_write(Path(path), replay_writer(buffer))


def replay_writer(buffer) -> Callable[[Path], None]:
    """What :func:`save_replay` writes, as a function of the file to write it to (written with
    the checkpoint as one set: :func:`~common.atomic.atomic_write_all`)."""
    rows = _filled(buffer, buffer.pos, buffer.full)

    def write(tmp: Path) -> None:
        with tmp.open("wb") as handle:  # a handle: np.savez would append ".npz" to a name
            np.savez(handle, pos=np.array(buffer.pos), full=np.array(buffer.full),
                     **{name: array[:rows] for name, array in _arrays(buffer).items()})

    return write


_SLACK = 64 * 1024  # a file's bytes beyond its arrays': zip records and .npy headers (about 250 bytes a member)


def load_replay(buffer, path: str | Path) -> None:
    """Fill ``buffer`` from a file :func:`save_replay` wrote; a file that does not fit it is refused.

    The file is read through :mod:`common.files` (a regular file no larger than the buffer's
    arrays and their headers); each array's header is checked against the buffer's array (shape,
    type, order) before its data is read, straight into the buffer, and its CRC-32 once read.
    """
    path = Path(path)
    expected = _arrays(buffer)

    def refuse(problem: str) -> ConfigError:
        return ConfigError(path, None, f"{problem}; not this stage's replay buffer (delete it to resume without one)")

    limit = sum(array.nbytes for array in expected.values()) + _SLACK
    with open_regular(path, limit, "this stage's replay buffer",
                      too_large="more than this stage's buffer holds; not its replay buffer (delete it to resume without one)") as handle:
        with open_zip(handle, path, None, len(expected) + 2, _SLACK, "this stage's replay buffer") as archive:
            members = {info.filename.removesuffix(".npy"): info for info in archive.infolist()}
            if set(members) != set(expected) | {"pos", "full"} or len(members) != len(archive.infolist()):
                raise refuse(f"holds {sorted(members)[:10]}")
            pos, full = (_read_scalar(archive, members[name], refuse) for name in ("pos", "full"))
            if isinstance(pos, bool) or not isinstance(pos, int) or not isinstance(full, (bool, int)):
                raise refuse("pos must be an integer and full a boolean")
            if not 0 <= pos < buffer.buffer_size:
                raise refuse(f"position {pos} outside the buffer")
            rows = _filled(buffer, pos, bool(full))
            for name, array in expected.items():
                # Its filled rows, or (a file written before only they were) the whole buffer.
                _read_into(archive, members[name], (array[:rows], array), refuse)
                # Weights with a NaN are refused as they open; a NaN transition would train them into it.
                if array.dtype.kind == "f" and not np.isfinite(array[:rows]).all():
                    raise refuse(f"{name}: holds NaN or infinite values")
    buffer.pos, buffer.full = pos, bool(full)


def _header(handle, name: str, refuse):
    """A .npy member's (shape, fortran_order, dtype), read from its header alone."""
    try:
        version = np.lib.format.read_magic(handle)
        if version == (1, 0):
            return np.lib.format.read_array_header_1_0(handle)
        if version == (2, 0):
            return np.lib.format.read_array_header_2_0(handle)
    except ZIP_DAMAGE as exc:
        raise refuse(f"{name}: {zip_damage(exc) if isinstance(exc, zipfile.BadZipFile) else 'not a .npy array'}") from None
    raise refuse(f"{name}: a .npy array of format {version}")


def _read_into(archive: zipfile.ZipFile, info: zipfile.ZipInfo, targets: tuple[np.ndarray, ...], refuse) -> None:
    """Read a member straight into the first of ``targets`` (views of the buffer's array) its
    header fits (no copy, no pickle)."""
    name, whole = info.filename, targets[-1]
    # The header's size is checked before reading, so a crafted file cannot claim memory.
    if info.file_size > whole.nbytes + 4096:
        raise refuse(f"{name} is larger than the buffer")
    try:
        with archive.open(info) as handle:
            shape, fortran, dtype = _header(handle, name, refuse)
            array = next((t for t in targets if t.shape == shape), targets[0])
            if shape != array.shape or dtype != array.dtype or (fortran and array.ndim > 1) or not array.flags.c_contiguous:
                raise refuse(f"{name} is {shape} {dtype}, the buffer's filled rows {array.shape} {array.dtype}")
            view, done = memoryview(array.reshape(-1).view(np.uint8)), 0
            while done < array.nbytes:
                got = handle.readinto(view[done:done + _CHUNK])
                if not got:
                    raise refuse(f"{name} ends before its {array.nbytes:,} bytes")
                done += got
            if handle.read(4097):  # reading to its end checks the CRC-32 too
                raise refuse(f"{name} holds more than its array")
            if handle.tell() != info.file_size:  # zipfile stops early, without a word, when the header says more
                raise refuse(f"{name}: {zip_damage(zipfile.BadZipFile('size'))}")
    except ZIP_DAMAGE as exc:
        if isinstance(exc, ConfigError):
            raise
        raise refuse(f"{name}: {zip_damage(exc)}") from None


def _read_scalar(archive: zipfile.ZipFile, info: zipfile.ZipInfo, refuse):
    """A 0-d integer or boolean member (pos, full) as a Python value."""
    if info.file_size > 4096:
        raise refuse(f"{info.filename} is not a number")
    try:
        with archive.open(info) as handle:
            value = np.lib.format.read_array(handle, allow_pickle=False)
            handle.read()  # to its end: the CRC-32 is checked there
    except ZIP_DAMAGE as exc:
        if isinstance(exc, ConfigError):
            raise
        raise refuse(f"{info.filename}: {zip_damage(exc) if isinstance(exc, zipfile.BadZipFile) else 'not a .npy array'}") from None
    if value.shape != () or value.dtype.kind not in "biu":
        raise refuse(f"{info.filename} is {value.shape} {value.dtype}, not a number")
    return value.item()
