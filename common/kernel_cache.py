"""numba's on-disk kernel cache, kept true when a module that a kernel calls into changes.

numba keys a cached kernel on its own source file only (upstream proposals to follow the
callees' files, numba PRs 8396 and 9563, were not merged). A kernel in ``occupancy.py`` that
inlines a ``geometry.py`` function would keep the old machine code after ``geometry.py`` alone
changed, as after a ``git pull`` into an editable install: silently wrong, not slow. So at import
the package hashes the sources of every module holding cached kernels; when the hash differs from
the one recorded beside the caches, it deletes those modules' cache files and numba recompiles.

This covers caches kept beside the sources (numba's choice wherever the package directory is
writable, as in an editable install). A non-writable install keeps them in numba's user-wide
directory, but it is replaced whole on upgrade, so every module's own stamp changes anyway.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from common.atomic import atomic_write

ROOT = Path(__file__).resolve().parent.parent
# Every module with cached numba kernels or with functions compiled into them (register_jitable);
# tests/test_packaging.py checks the list.
KERNEL_MODULES = (
    "common/geometry.py", "common/polygons.py", "common/placement.py", "common/layouts.py", "common/occupancy.py",
    "common/irsim_format.py", "common/kinematics.py", "common/observations.py", "common/planners/astar.py",
    "common/planners/collision.py", "common/planners/rrt.py", "common/planners/smoothing.py", "common/readings.py",
    "flatland/clearance.py", "flatland/free_step.py", "flatland/lidar.py",
)
STAMP = "kernel-sources.sha256"


def sources_digest(root: Path = ROOT, modules: tuple[str, ...] = KERNEL_MODULES) -> str:
    """One hash over the kernel modules' sources (a missing module hashes as empty)."""
    digest = hashlib.sha256()
    for module in modules:
        path = root / module
        digest.update(module.encode())
        digest.update(path.read_bytes() if path.is_file() else b"")
    return digest.hexdigest()


def refresh(root: Path = ROOT, modules: tuple[str, ...] = KERNEL_MODULES) -> bool:
    """Delete the kernel modules' cache files if their sources changed since the last refresh;
    whether they had. Never raises for a file system that refuses: caching is an optimisation."""
    stamp = root / "common" / "__pycache__" / STAMP
    digest = sources_digest(root, modules)
    try:
        if stamp.is_file() and stamp.read_text() == digest:
            return False
        for module in modules:
            path = root / module
            for cached in (path.parent / "__pycache__").glob(f"{path.stem}.*.nb[ic]"):
                cached.unlink(missing_ok=True)
        atomic_write(stamp, lambda tmp: tmp.write_text(digest))
    except OSError:
        pass
    return True
