"""Arrays of one dtype kept in one buffer, so that a compiled call takes one argument for them all.

numba unboxes every array argument anew on every call. The movers' step took 25 arrays: an empty
kernel of its arguments cost 7% of a crowd's env step, one of 11 arguments almost nothing.
:func:`pack` copies such arrays into one buffer and gives them back as views of it, for Python to
read and write as before; a kernel rebuilds the views from the buffer and its layout with
:func:`view1` to :func:`view3`. Rebuilding costs part of what unboxing did: the crowd's env step
ran 0.7–4.2% faster packed (four runs, the two taking turns in one process).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numba.extending import register_jitable

OFFSET, ROWS, COLUMNS, DEPTH = range(4)  # columns of a layout row


def pack(arrays: Sequence[np.ndarray], dtype: type) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """One buffer of ``dtype`` holding ``arrays`` (each of one to three dimensions, copied in C
    order), its layout (one row per array: where it starts, then its shape padded with 1s) and
    the arrays again as C-contiguous views of the buffer, in order."""
    shapes = [array.shape for array in arrays]
    if any(not 1 <= len(shape) <= 3 for shape in shapes):
        raise ValueError(f"pack takes arrays of one to three dimensions, got shapes {shapes}")
    # Plain Python arithmetic: NumPy's per-call overhead would cost more than the copies (a world
    # of movers is packed once per scenario, and training draws a scenario every episode).
    layout, start = [], 0
    for shape in shapes:
        layout.append((start, *shape, *(1,) * (3 - len(shape))))
        start += math.prod(shape)
    buffer = np.empty(start, dtype=dtype)
    views = []
    for array, shape, (first, *_) in zip(arrays, shapes, layout):
        view = buffer[first:first + math.prod(shape)].reshape(shape)
        view[...] = array
        views.append(view)
    return buffer, np.array(layout, dtype=np.int64).reshape(-1, 4), views


@register_jitable
def view1(buffer: np.ndarray, layout: np.ndarray, k: int) -> np.ndarray:
    """Array ``k`` of a packed buffer, one-dimensional."""
    start = layout[k, OFFSET]
    return buffer[start:start + layout[k, ROWS]]


@register_jitable
def view2(buffer: np.ndarray, layout: np.ndarray, k: int) -> np.ndarray:
    """Array ``k`` of a packed buffer, two-dimensional."""
    start, rows, columns = layout[k, OFFSET], layout[k, ROWS], layout[k, COLUMNS]
    return buffer[start:start + rows * columns].reshape((rows, columns))


@register_jitable
def view3(buffer: np.ndarray, layout: np.ndarray, k: int) -> np.ndarray:
    """Array ``k`` of a packed buffer, three-dimensional."""
    start, rows, columns, depth = layout[k, OFFSET], layout[k, ROWS], layout[k, COLUMNS], layout[k, DEPTH]
    return buffer[start:start + rows * columns * depth].reshape((rows, columns, depth))
