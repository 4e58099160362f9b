"""Compiled kernels whose on-disk cache goes stale when any module they call into changes.

numba keys a cached kernel on its own source file only (upstream proposals to follow the
callees' files, numba PRs 8396 and 9563, were not merged). A kernel in ``occupancy.py`` that
inlines a ``geometry.py`` function would keep the old machine code after ``geometry.py`` alone
changed, as after a ``git pull`` into an editable install: silently wrong, not slow.

:func:`kernel` is ``numba.njit(cache=True)`` with one difference: a cached kernel's source stamp
is its own file's *and* a hash of every module in :data:`KERNEL_MODULES`. A cache compiled
against other sources no longer matches its stamp, so numba itself recompiles and overwrites it.
Nothing is deleted or written at import (numba probes a cache directory by writing to it, so the
cache is made when its kernel first compiles); the hash is computed once per process, by reading.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path
from typing import Callable

from numba import njit
from numba.extending import register_jitable
from numba.core.dispatcher import Dispatcher
from numba.core.caching import CompileResultCacheImpl, FunctionCache, InTreeCacheLocator, UserWideCacheLocator

ROOT = Path(__file__).resolve().parent.parent
# Every module with cached numba kernels or with functions compiled into them (register_jitable);
# tests/test_packaging.py checks the list.
KERNEL_MODULES = (
    "common/geometry.py", "common/polygons.py", "common/placement.py", "common/layouts.py", "common/occupancy.py",
    "common/irsim_format.py", "common/irsim_geometry.py", "common/kinematics.py", "common/motion/orca.py",
    "common/motion/packing.py", "common/motion/sfm.py", "common/motion/slide.py", "common/motion/steering.py", "common/motion/step.py",
    "common/motion/table.py",
    "common/moving_kinds.py", "common/observations.py", "common/planners/astar.py", "common/planners/collision.py",
    "common/planners/footprint.py", "common/planners/rrt.py", "common/planners/smoothing.py", "common/readings.py", "common/route.py",
    "flatland/clearance.py", "flatland/free_step.py", "flatland/lidar.py",
)


@functools.lru_cache(maxsize=None)
def sources_digest(root: Path = ROOT, modules: tuple[str, ...] = KERNEL_MODULES) -> str:
    """One hash over the kernel modules' sources (a missing module hashes as empty)."""
    digest = hashlib.sha256()
    for module in modules:
        path = root / module
        digest.update(module.encode())
        digest.update(path.read_bytes() if path.is_file() else b"")
    return digest.hexdigest()


def cached_kernels(root: Path, modules: tuple[str, ...]) -> Callable:
    """A ``kernel`` decorator whose caches are stamped with the sources of ``modules`` under ``root``."""

    class Stamped:
        def get_source_stamp(self):
            return super().get_source_stamp(), sources_digest(root, modules)

    class InTree(Stamped, InTreeCacheLocator):
        pass

    class UserWide(Stamped, UserWideCacheLocator):
        pass

    class Impl(CompileResultCacheImpl):
        _locator_classes = [InTree, UserWide]

    class Cache(FunctionCache):
        _impl_class = Impl

    class OnFirstUse:
        """The cache, made when the kernel first compiles: making it probes (writes to) its directory."""

        def __init__(self, python_function: Callable) -> None:
            self.python_function, self.made = python_function, None

        def __getattr__(self, name: str):
            if self.made is None:
                self.made = Cache(self.python_function)
            return getattr(self.made, name)

    def kernel(function: Callable | None = None, **options) -> Callable:
        """``numba.njit(cache=True, **options)``, its cache stamped with every kernel module's source."""

        def compile_cached(python_function: Callable) -> Callable:
            dispatcher = njit(**options)(python_function)
            dispatcher._cache = OnFirstUse(dispatcher.py_func)  # njit(cache=True) sets a Cache here
            return dispatcher

        return compile_cached(function) if function is not None else compile_cached

    return kernel


kernel = cached_kernels(ROOT, KERNEL_MODULES)

# A function compiled into the kernels that call it, without numba's reference counting: numba
# counts references to every array a compiled function is handed (two atomic operations per array
# per call), which took a third of the movers' compiled step in calls to small helpers. Such a function must
# not allocate, nor call one that does: numba refuses to compile it then.
uncounted = register_jitable(_nrt=False)


def compiled_for(dispatcher: Dispatcher, *args) -> Callable:
    """The machine code of ``dispatcher`` (a kernel) for arguments of the types of ``args``,
    compiled or loaded from its cache now. Calling it skips the dispatcher's matching of every
    argument's type to a compiled signature (for the movers' step, 35 arguments, about 5 µs of a
    24 µs call); so it may only be called with arrays of exactly those dtypes, layouts and ranks
    (numbers are converted as the dispatcher would)."""
    return dispatcher.compile(tuple(dispatcher.typeof_pyval(arg) for arg in args))
