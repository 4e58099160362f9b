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


RVO_WORLD = """\
world: {height: 10, width: 10, step_time: 0.1, collision_mode: stop}
robot:
  - kinematics: {name: diff}
    shape: {name: rectangle, length: 0.5, width: 0.4}
    state: [1, 1, 0]
    goal: [9, 9, 0]
obstacle:
  - number: 3
    distribution: {name: circle, radius: 3, center: [5, 5]}
    kinematics: {name: omni}
    shape: {name: circle, radius: 0.3}
    behavior: {name: rvo, vxmax: 1.0, vymax: 1.0, acce: 1.0, factor: 2.0, mode: hrvo}
  - shape: {name: polygon, vertices: [[7, 1], [8, 1], [8, 2]]}
"""


def _worlds(tmp_path):
    import flatland
    from common.generators import generate
    from physics3d.robot import TEMPLATE

    (tmp_path / "rvo.yaml").write_text(RVO_WORLD)
    yield from (generate("crowd", 1, 1.0, "eval", None, reacting=True, behavior=behavior) for behavior in ("sfm", "orca"))
    yield generate("warehouse_moving", 2, 1.0, "eval")
    yield generate("crowd", 3, 0.5, "eval", TEMPLATE, reacting=False, behavior="sfm")
    yield flatland.load_world(tmp_path / "rvo.yaml").scenario  # an IR-SIM world: polygons, rvo in Python


def test_every_world_of_movers_packs_into_the_types_its_step_was_compiled_for(tmp_path):
    # The movers' step is called through machine code looked up once for these types: a world
    # whose packed arguments typed otherwise would have its arrays misread, not refused.
    from common.kernel_cache import compiled_for
    from common.motion.movers import Movers, finish_code
    from common.motion.step import finish_packed

    for scenario in _worlds(tmp_path):
        movers = Movers(scenario)
        assert movers.count > 0
        assert compiled_for(finish_packed, *movers._packed, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, False) is finish_code()
