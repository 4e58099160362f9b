"""The machine a run trains on, as its run.json, report and sweep record it.

The same seed trains the same weights to the bit on one machine and other weights where torch's
CPU kernels use other vector instructions: they then add in another order and round otherwise.
Figures of two runs compare only with their machines beside them.
"""

from __future__ import annotations

import os
import platform
from typing import Any


def machine() -> dict[str, Any]:
    """This machine: its CPU model, the vector instructions torch's CPU kernels use (``AVX2``,
    ``AVX512``, ...) and its cores."""
    import torch

    model = None
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as info:  # Linux; a few kB
            model = next((line.split(":", 1)[1].strip() for line in info if line.startswith("model name")), None)
    except OSError:
        pass
    return {"cpu": model or platform.processor() or platform.machine() or None,
            "cpu_capability": torch.backends.cpu.get_cpu_capability(), "cores": os.cpu_count()}


def describe(recorded: object) -> str | None:
    """``AMD EPYC (AVX2, 2 cores)`` from a recorded :func:`machine`; None for a record without one
    (a run that predates it, a damaged file)."""
    if not isinstance(recorded, dict) or not isinstance(recorded.get("cpu"), str):
        return None
    cores = recorded.get("cores")
    details = [str(recorded.get("cpu_capability") or "unknown instructions")]
    if isinstance(cores, int) and not isinstance(cores, bool):
        details.append(f"{cores} cores")
    return f"{recorded['cpu']} ({', '.join(details)})"
