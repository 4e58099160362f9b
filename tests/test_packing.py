"""Arrays packed into one buffer: the same values, shared with the buffer, rebuilt in compiled code."""

import numpy as np
import pytest
from numba import njit
from numpy.testing import assert_array_equal

from common.motion.packing import pack, view1, view2, view3


@njit
def _bump(buffer, layout):
    """Add 1 to every element of the packed 1-, 2- and 3-dimensional arrays, through rebuilt views."""
    view1(buffer, layout, 0)[:] += 1.0
    view2(buffer, layout, 1)[:, :] += 1.0
    view3(buffer, layout, 2)[:, :, :] += 1.0
    return view2(buffer, layout, 1)[1, 2], view3(buffer, layout, 2)[1, 0, 1]


def test_packed_arrays_keep_their_values_and_share_the_buffer_with_compiled_code():
    rng = np.random.default_rng(0)
    arrays = [rng.random(4), rng.random((2, 3)), np.asfortranarray(rng.random((2, 3, 2))), np.empty((0, 5))]
    buffer, layout, views = pack(arrays, np.float64)
    assert buffer.shape == (4 + 6 + 12,)
    for array, view in zip(arrays, views):
        assert view.shape == array.shape and view.flags.c_contiguous
        assert array.size == 0 or np.shares_memory(view, buffer)
        assert_array_equal(view, array)
    corner, deep = _bump(buffer, layout)
    assert (corner, deep) == (arrays[1][1, 2] + 1.0, arrays[2][1, 0, 1] + 1.0)
    for array, view in zip(arrays, views):
        assert_array_equal(view, array + 1.0)  # Python's views see what the kernel wrote


def test_pack_refuses_what_it_cannot_rebuild():
    with pytest.raises(ValueError, match="one to three dimensions"):
        pack([np.zeros(2), np.zeros((1, 1, 1, 1))], np.float64)
