"""Checked reads of an IR-SIM world file's values: numbers, vectors, flags, strings, mappings,
each failing with a one-line :class:`ConfigError` that names the field's path in the file."""

from __future__ import annotations

import math
import numbers as numeric
from typing import Any, NamedTuple

import numpy as np
from pydantic import BaseModel, ValidationError

from common.errors import ConfigError, did_you_mean, quote
from common.scenario import pydantic_error, refuse_misread


class Value(NamedTuple):
    """A YAML value and the field path that names it in error messages."""

    value: Any
    path: str


Entry = dict[str, Value]  # one object's keys after IR-SIM's per-object fan-out


def fail(path: str | None, problem: str) -> ConfigError:
    # Raised without a source; parse_irsim attributes every error to the file at the end.
    return ConfigError(None, path, problem)


def join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


# -- scalar and vector checks ------------------------------------------------------------------


def is_number(value: Any) -> bool:
    # The exact-type test first: an abstract-class check costs a microsecond, and a random world
    # file has thousands of numbers to read per layout.
    return type(value) in (float, int) or (isinstance(value, numeric.Real) and not isinstance(value, bool))


def real(value: Any, path: str, low: float | None = None, strict: bool = False, allow_inf: bool = False) -> float:
    """A real number, finite unless ``allow_inf``, optionally bounded below (``strict``: exclusive)."""
    if not is_number(value):
        raise fail(path, f"expected a number (got {quote(value)})")
    try:
        value = float(value)
    except OverflowError:  # an integer beyond any float
        raise fail(path, "expected a finite number (got an integer too large for a float)") from None
    if math.isnan(value):
        raise fail(path, f"expected a number (got {quote(value)})")
    if math.isinf(value) and not allow_inf:
        raise fail(path, f"expected a finite number (got {quote(value)})")
    if low is not None and (value <= low if strict else value < low):
        raise fail(path, f"must be {'>' if strict else '>='} {low:g} (got {value:g})")
    return value


def whole(value: Any, path: str, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numeric.Integral):
        raise fail(path, f"expected an integer (got {quote(value)})")
    if not low <= value <= high:
        raise fail(path, f"must be >= {low} and <= {high} (got {value})")
    return int(value)


def boolean(value: Any, path: str) -> bool:
    if not isinstance(value, bool):
        raise fail(path, f"expected true or false (got {quote(value)})")
    return value


def string(value: Any, path: str, allowed: tuple[str, ...] | None = None) -> str:
    if not isinstance(value, str):
        raise fail(path, f"expected a string (got {quote(value)})")
    if allowed is not None and value not in allowed:
        raise fail(path, f"unsupported value {quote(value)}; allowed: {', '.join(allowed)}")
    return value


_PLAIN_NUMBERS = frozenset((float, int))


def number_list(value: Any, path: str, size: int | None = None, min_size: int = 0, allow_inf: bool = False) -> list[float]:
    """A list of numbers, of exactly ``size`` entries or at least ``min_size``."""
    if not isinstance(value, (list, tuple)) or (size is not None and len(value) != size) or len(value) < min_size:
        wanted = f"{size} numbers" if size is not None else f"at least {min_size} numbers" if min_size else "numbers"
        raise fail(path, f"expected a list of {wanted} (got {quote(value)})")
    if _PLAIN_NUMBERS.issuperset(map(type, value)):
        try:
            # The common case, without naming each entry's path: a finite float sum has no NaN, no
            # inf and no integer beyond a float (an overflowing one takes the checked path).
            if math.isfinite(sum(map(float, value))):
                return [float(v) for v in value]
        except OverflowError:
            pass
    return [real(v, f"{path}[{i}]", allow_inf=allow_inf) for i, v in enumerate(value)]


def ordered_bounds(low: list[float], high: list[float], path: str) -> None:
    """Random draws need finite bounds with low <= high in every component."""
    for i, (a, b) in enumerate(zip(low, high)):
        if not (math.isfinite(a) and math.isfinite(b)) or a > b:
            raise fail(path, f"component {i}: expected finite bounds with low <= high (got {a:g}, {b:g})")


def point_list(value: Any, path: str, min_count: int) -> np.ndarray:
    """A list of at least ``min_count`` [x, y] points, as an (N, 2) array."""
    if not isinstance(value, (list, tuple)) or len(value) < min_count:
        raise fail(path, f"expected a list of at least {min_count} [x, y] points (got {quote(value)})")
    return np.array([number_list(p, f"{path}[{i}]", size=2) for i, p in enumerate(value)], dtype=float)


def mapping_of(value: Any, path: str) -> dict:
    if not isinstance(value, dict):
        raise fail(path, f"expected a mapping (got {quote(value)})")
    return value


def check_keys(mapping: dict, allowed: tuple[str, ...], path: str) -> None:
    for key in mapping:
        if key not in allowed:
            raise fail(join(path, str(key)), f"unknown key{did_you_mean(key, allowed)}; allowed: {', '.join(allowed)}")


def fit3(values: list[float]) -> tuple[float, float, float]:
    """IR-SIM's state fitting: zero-padded or truncated to x, y, theta."""
    if len(values) >= 3:
        return values[0], values[1], values[2]
    x, y, theta = (list(values) + [0.0, 0.0, 0.0])[:3]
    return x, y, theta


def refuse_misread_values(model: type[BaseModel], fields: dict[str, Value]) -> None:
    """A value of ``fields`` written for ``model`` that pydantic would misread (true or "0.7" for
    a number: :func:`~common.scenario.refuse_misread`), named by the IR-SIM field it came from. For
    the values the reader hands over as written (a behaviour's parameters); the others it has
    read by type already."""
    for name, item in fields.items():
        try:
            refuse_misread({name: item.value}, model)
        except ConfigError as error:
            rest = (error.field or "").partition(".")[2]
            raise fail(_within(item.path, rest), error.problem) from None


def build_model(model: type[BaseModel], path: str, fields: dict[str, Value]) -> Any:
    """Validate a model; a pydantic error names the IR-SIM field it came from."""
    try:
        return model(**{name: item.value for name, item in fields.items()})
    except ValidationError as exc:
        error = pydantic_error(None, exc)
        # pydantic names an element as "start.0": the IR-SIM key that gave "start", then the rest.
        head, _, rest = (error.field or "").partition(".")
        raise fail(_within(fields[head].path, rest) if head in fields else path, error.problem) from None


def _within(path: str, location: str) -> str:
    """``path`` extended by a pydantic location ("0", "motion.1"), written as IR-SIM paths are: state[0]."""
    for part in location.split(".") if location else ():
        path = f"{path}[{part}]" if part.isdigit() else join(path, part)
    return path


def values_of(entry: Entry, keys: tuple[str, ...]) -> tuple:
    """The value objects an entry has for ``keys`` (None where absent), to key :class:`ReadCache` reads."""
    return tuple([getattr(entry.get(key), "value", None) for key in keys])


def value_of(entry: Entry, key: str, default: Any, path: str) -> Value:
    """An entry's value for ``key``, or ``default`` (also for an explicit null)."""
    item = entry.get(key)
    if item is None or item.value is None:
        return Value(default, join(path, key))
    return item
