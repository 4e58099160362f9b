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


def _worlds():
    from common.generators import generate
    from common.motion.spec import Motion, Rvo
    from common.scenario import CircleObstacle, PolygonObstacle, RobotProfile, Scenario
    from physics3d.robot import TEMPLATE

    yield from (generate("crowd", 1, 1.0, "eval", None, reacting=True, behavior=behavior) for behavior in ("sfm", "orca"))
    yield generate("warehouse_moving", 2, 1.0, "eval")
    yield generate("crowd", 3, 0.5, "eval", TEMPLATE, reacting=False, behavior="sfm")
    # IR-SIM's rvo (stepped in Python first), a box robot and a polygon to keep off.
    walkers = [CircleObstacle(x=x, y=5.0, radius=0.3, motion=Motion(behavior=Rvo(), goals=[(10.0 - x, 5.0)]))
               for x in (3.0, 7.0)]
    yield Scenario(robot=RobotProfile(shape="box", length=0.5, width=0.4), start=(1.0, 1.0, 0.0), goal=(9.0, 9.0),
                   obstacles=[*walkers, PolygonObstacle(vertices=[(7.0, 1.0), (8.0, 1.0), (8.0, 2.0)])])


def test_every_world_of_movers_packs_into_the_types_its_step_was_compiled_for():
    # The movers' step is called through machine code looked up once for these types: a world
    # whose packed arguments typed otherwise would have its arrays misread, not refused.
    from common.kernel_cache import compiled_for
    from common.motion.movers import Movers, finish_code
    from common.motion.step import finish_packed
    from flatland.free_step import free_step_among, free_step_among_code
    from flatland.world import World

    in_python = []
    for scenario in _worlds():
        movers = Movers(scenario)
        assert movers.count > 0
        assert compiled_for(finish_packed, *movers._packed, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, False) is finish_code()
        in_python.append(movers._python)
        # And flatland's step that makes the movers' inside its own call, with a world's arrays.
        world = World(scenario)
        ranges = np.empty(world.lidar.spec.beams)
        arguments = (*world.pose, *world.odometry.pose, 0.0, 0.0, world._constants, world.lidar.circles,
                     world.lidar.boxes, world.lidar.segments, world._solids, ranges, world._moved,
                     *world.movers.step_arguments, False)
        assert compiled_for(free_step_among, *arguments) is free_step_among_code()
    assert in_python == [False] * 4 + [True]  # the rvo world steps its movers in Python first
