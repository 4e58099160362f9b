"""Keyword parameters from YAML, checked against a function's own annotations.

Controllers and reward terms take their parameters as keyword arguments with defaults; a YAML
mapping can override any of them. :func:`coerce` turns a YAML value into the annotated type (an
int is a valid float, a list a valid tuple) or raises a one-line :class:`ConfigError` naming the
field, the value and what is allowed.
"""

from __future__ import annotations

import inspect
import math
import numbers
import types
import typing
from pathlib import Path
from typing import Any, Callable

import numpy as np

from common.errors import ConfigError, quote


def keyword_parameters(function: Callable) -> dict[str, tuple[Any, Any]]:
    """A callable's keyword parameters (a class's constructor's): name -> (annotation, default)."""
    target = function.__init__ if inspect.isclass(function) else function
    hints = typing.get_type_hints(target)
    return {name: (hints.get(name, Any), p.default) for name, p in inspect.signature(target).parameters.items()
            if name != "self" and p.default is not inspect.Parameter.empty
            and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}


class _Mismatch(Exception):
    pass


def _convert(value: Any, annotation: Any) -> Any:
    """``value`` as ``annotation``, or _Mismatch."""
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        for option in typing.get_args(annotation):
            try:
                return _convert(value, option)
            except _Mismatch:
                continue
        raise _Mismatch
    if annotation is type(None):
        if value is None:
            return None
    elif annotation is float:
        # bool is an int in Python, but "true" for a gain is a mistake, not 1.0.
        if isinstance(value, (int, float)) and not isinstance(value, bool) and is_finite(value):
            return float(value)
    elif annotation is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif annotation in (bool, str):
        if isinstance(value, annotation):
            return value
    elif origin is typing.Literal:
        if value in typing.get_args(annotation):
            return value
    elif origin is tuple and isinstance(value, (list, tuple)):
        args = typing.get_args(annotation)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(item, args[0]) for item in value)
        if len(args) == len(value):
            return tuple(_convert(item, arg) for item, arg in zip(value, args))
    elif annotation is Any:
        return value
    raise _Mismatch


def describe(annotation: Any) -> str:
    """What an annotation allows, in words."""
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(describe(option) for option in typing.get_args(annotation))
    if annotation is type(None):
        return "null"
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(v) for v in typing.get_args(annotation))
    if origin is tuple:
        args = typing.get_args(annotation)
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of ({describe(args[0])})"
        return "a list of " + ", ".join(describe(arg) for arg in args)
    return {float: "a finite number", int: "an integer", bool: "true/false", str: "a string"}.get(
        annotation, getattr(annotation, "__name__", str(annotation)))


def coerce(value: Any, annotation: Any, default: Any, source: str | Path | None, field: str) -> Any:
    """``value`` as the annotated type, or a ConfigError naming what is allowed."""
    try:
        return _convert(value, annotation)
    except _Mismatch:
        raise ConfigError(source, field, f"got {quote(value)}; allowed: {describe(annotation)} (default {quote(default)})") from None


def is_real(value: Any) -> bool:
    """A real number (NumPy's included): not a bool, not a string such as "0.5"."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def numeral(text: str) -> float | None:
    """The number a string such as "0.5" reads as (None if it reads as none)."""
    try:
        return float(text)
    except ValueError:
        return None


def is_finite(number: int | float) -> bool:
    """Whether ``number`` is finite as a float (an integer past a float's range, as a file may hold, is not)."""
    try:
        return math.isfinite(number)
    except OverflowError:
        return False
