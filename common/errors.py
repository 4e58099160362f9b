"""One error type for bad input, rendered as a single line: file, field, what is allowed."""

from __future__ import annotations

import difflib
import reprlib
from pathlib import Path
from typing import Any, Iterable

QUOTE_CHARS = 80  # the most of a user's value an error message repeats
SOURCE_CHARS = 240  # a file named longer than this is shown by its start and end, so the problem still shows
MESSAGE_CHARS = 1000  # a safety net: no message, however built, floods a terminal (the longest allowed-keys list is ~300)

_short = reprlib.Repr()  # Python 3.11's Repr takes no keyword arguments
_short.maxlevel, _short.maxdict, _short.maxlist, _short.maxtuple, _short.maxset = 2, 4, 4, 4, 4
_short.maxstring = _short.maxother = QUOTE_CHARS - 2
_short.maxlong = 40


def quote(value: Any) -> str:
    """``repr(value)`` cut to about :data:`QUOTE_CHARS` characters, cheap even for huge or shared structures."""
    text = " ".join(_short.repr(value).split())  # one line, even for a numpy array's repr
    return text if len(text) <= QUOTE_CHARS else text[: QUOTE_CHARS - 3] + "..."


def did_you_mean(given: object, allowed: Iterable[str]) -> str:
    """" (did you mean 'x'?)" when one of ``allowed`` is close to ``given`` (a typo), else ""."""
    close = difflib.get_close_matches(str(given), list(allowed), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def require_flag(name: str, value: Any, source: str | Path | None = None) -> None:
    """A one-line error unless ``value`` is true or false: "false", a non-empty string, is truthy."""
    if not isinstance(value, bool):
        raise ConfigError(source, name, f"got {quote(value)}; allowed: true or false")


def _shortened(name: str) -> str:
    """A file name cut in the middle to :data:`SOURCE_CHARS` characters (a 5,000-character path
    filled the whole message before its problem could be read)."""
    if len(name) <= SOURCE_CHARS:
        return name
    keep = (SOURCE_CHARS - 3) // 2
    return f"{name[:keep]}...{name[-keep:]}"


class ScenarioWarning(UserWarning):
    """A world file that runs, but probably not as its author meant (IR-SIM runs such files too)."""


class ConfigError(ValueError):
    """Bad user input: a file, a field in it, and what would have been allowed.

    ``str(error)`` is one line, ready for a CLI to print before exiting with code 2.
    """

    def __init__(self, source: str | Path | None, field: str | None, problem: str) -> None:
        self.source = None if source is None else _shortened(str(source))
        self.field = field
        self.problem = problem
        parts = [p for p in (self.source, self.field) if p]
        message = " ".join(": ".join([*parts, problem]).split())  # one line, whatever the parts held
        if len(message) > MESSAGE_CHARS:
            message = message[: MESSAGE_CHARS - 3] + "..."
        super().__init__(message)

    def __reduce__(self):
        # Pickled by its three parts (an exception pickles its message alone, which this class
        # cannot be built from): a worker process's error reaches the caller as this one line.
        return ConfigError, (self.source, self.field, self.problem)

    def with_source(self, source: str | Path) -> "ConfigError":
        """The same error, attributed to ``source`` (for loaders that parse text before knowing its file)."""
        return ConfigError(source, self.field, self.problem)
