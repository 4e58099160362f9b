"""Atomic file writes: a kill mid-write never leaves a half-written file behind."""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path
from typing import Callable, Iterable, Mapping

from common.errors import ConfigError

TEMPORARY_SUFFIX = ".tmp"
_UMASK = os.umask(0)
os.umask(_UMASK)


def writable_place(path: str | Path, flag: str, directory: bool = False) -> Path:
    """``path`` (a directory, else a file's folder) made and probed with a temporary file, so that
    a place no file can be written to is refused before any work, naming ``flag``: the atomic
    writes would fail only after the work, on a temporary's name."""
    path = Path(path)
    folder = path if directory else path.parent
    try:
        if folder.exists() and not folder.is_dir():  # mkdir would say "File exists"
            raise NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR))
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise ConfigError(path, None, f"cannot write here ({error.strerror or error}); choose another {flag}") from None
    return path


def atomic_write(path: str | Path, write: Callable[[Path], object]) -> Path:
    """Call ``write(tmp_path)`` then rename the temporary file over ``path``."""
    return atomic_write_all({Path(path): write})[0]


def atomic_write_all(writes: Mapping[Path, Callable[[Path], object]]) -> list[Path]:
    """Write each file to a temporary beside it, then rename them all over their paths.

    Files that belong together (a comparison's table, episodes and chart): a kill while they are
    written leaves the earlier set whole; only a kill between the renames, microseconds apart,
    could mix two sets.
    """
    temporaries: dict[Path, Path] = {}
    try:
        for path, write in writes.items():
            path.parent.mkdir(parents=True, exist_ok=True)
            handle, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=TEMPORARY_SUFFIX)
            os.close(handle)
            temporaries[path] = Path(tmp)
            write(Path(tmp))
            os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600 files; give the usual permissions
        for path, tmp in temporaries.items():
            os.replace(tmp, path)
    finally:
        for tmp in temporaries.values():
            tmp.unlink(missing_ok=True)
    return list(writes)


def is_temporary_of(name: str, file_names: Iterable[str]) -> bool:
    """Whether ``name`` is a temporary a killed :func:`atomic_write` left beside one of ``file_names``."""
    return name.endswith(TEMPORARY_SUFFIX) and any(name.startswith(f".{file}.") for file in file_names)
