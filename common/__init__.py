"""Shared core of the navigation curriculum: kinematics, scenarios, observations, rewards, CLI."""

from common.kernel_cache import refresh as _refresh_kernel_cache

__version__ = "0.1.0"

_refresh_kernel_cache()  # before any module defines a cached kernel
