"""The installed IR-SIM package (the ``irsim`` extra), imported headless and without its noise."""

from __future__ import annotations

import contextlib
import io
import os


def import_irsim():
    """IR-SIM (headless: matplotlib's Agg backend), or None where it is not installed."""
    os.environ.setdefault("MPLBACKEND", "Agg")
    try:
        # On import IR-SIM tries the GUI backends (TkAgg, Qt5Agg) whatever MPLBACKEND says, and prints
        # a line for each that fails: noise on every headless run, kept from the user's output.
        with contextlib.redirect_stdout(io.StringIO()):
            import irsim
    except ImportError:
        return None
    return irsim
