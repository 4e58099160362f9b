"""One error type for bad input, rendered as a single line: file, field, what is allowed."""

from __future__ import annotations

from pathlib import Path


class ConfigError(ValueError):
    """Bad user input: a file, a field in it, and what would have been allowed.

    ``str(error)`` is one line, ready for a CLI to print before exiting with code 2.
    """

    def __init__(self, source: str | Path | None, field: str | None, problem: str) -> None:
        self.source = str(source) if source is not None else None
        self.field = field
        self.problem = problem
        parts = [p for p in (self.source, self.field) if p]
        super().__init__(": ".join([*parts, problem]))

    def with_source(self, source: str | Path) -> "ConfigError":
        """The same error, attributed to ``source`` (for loaders that parse text before knowing its file)."""
        return ConfigError(source, self.field, self.problem)
