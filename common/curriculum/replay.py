"""SAC and TD3 replay buffers as plain arrays (``.npz``), so resuming a run never unpickles.

stable-baselines3 saves a replay buffer by pickling the whole object; here only its arrays and
two counters are written, and read back with ``allow_pickle=False`` into the buffer of a model
built from the curriculum, after checking every array's shape and type against that buffer.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from common.atomic import atomic_write
from common.errors import ConfigError

_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


def _arrays(buffer) -> dict[str, np.ndarray]:
    # With optimize_memory_usage SB3 keeps no next_observations (they are the next row's observations).
    return {name: getattr(buffer, name) for name in _ARRAYS if getattr(buffer, name, None) is not None}


def save_replay(buffer, path: str | Path) -> Path:
    """Write a buffer's arrays and position atomically."""

    def write(tmp: Path) -> None:
        with tmp.open("wb") as handle:  # a handle: np.savez would append ".npz" to a name
            np.savez(handle, pos=np.array(buffer.pos), full=np.array(buffer.full), **_arrays(buffer))

    return atomic_write(Path(path), write)


def load_replay(buffer, path: str | Path) -> None:
    """Fill ``buffer`` from a file :func:`save_replay` wrote; a file that does not fit it is refused."""
    path = Path(path)
    expected = _arrays(buffer)

    def refuse(problem: str) -> ConfigError:
        return ConfigError(path, None, f"{problem}; not this stage's replay buffer (delete it to resume without one)")

    try:
        with np.load(path, allow_pickle=False) as saved:
            names = set(saved.files)
            if names != set(expected) | {"pos", "full"}:
                raise refuse(f"holds {sorted(names)}")
            sizes = {info.filename.removesuffix(".npy"): info.file_size for info in saved.zip.infolist()}
            for name, array in expected.items():
                # The header's size is checked before reading, so a crafted file cannot claim memory.
                if sizes[name] > array.nbytes + 4096:
                    raise refuse(f"{name} is larger than the buffer")
                value = saved[name]
                if value.shape != array.shape or value.dtype != array.dtype:
                    raise refuse(f"{name} is {value.shape} {value.dtype}, the buffer {array.shape} {array.dtype}")
                array[...] = value
            pos, full = int(saved["pos"]), bool(saved["full"])
    except (OSError, ValueError, TypeError, zipfile.BadZipFile, KeyError) as exc:
        if isinstance(exc, ConfigError):
            raise
        raise refuse(f"unreadable ({type(exc).__name__})") from None
    if not 0 <= pos < buffer.buffer_size:
        raise refuse(f"position {pos} outside the buffer")
    buffer.pos, buffer.full = pos, full
