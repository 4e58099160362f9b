"""Test-wide settings: headless plotting, so no test needs a display."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")
