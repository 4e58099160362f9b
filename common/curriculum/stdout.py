"""Keeping stdout for this project's own output (JSON, tables) while libraries print."""

from __future__ import annotations

import contextlib
import os
import sys


@contextlib.contextmanager
def stdout_to_stderr():
    """Keep stdout for our JSON: what Python code prints (IR-SIM probing its GUI backends on
    import) and what C libraries write to descriptor 1 (PyBullet's GUI) goes to stderr."""
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        with contextlib.redirect_stdout(sys.stderr):
            yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
