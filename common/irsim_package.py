"""The installed IR-SIM package (the ``irsim`` extra), imported headless and without its noise."""

from __future__ import annotations

import contextlib
import io
import os


def import_irsim():
    """IR-SIM (headless: matplotlib's Agg backend), or None where it is not installed."""
    os.environ.setdefault("MPLBACKEND", "Agg")
    try:
        with quiet_stdout():
            import irsim
    except ImportError:
        return None
    return irsim


def quiet_stdout() -> contextlib.AbstractContextManager:
    """Python's stdout kept from the user within: on import IR-SIM's modules try the GUI backends
    (TkAgg, Qt5Agg) whatever MPLBACKEND says, and print a line for each that fails, noise on every
    headless run (and in front of a command's JSON)."""
    return contextlib.redirect_stdout(io.StringIO())
