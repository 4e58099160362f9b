"""A step whose move touches nothing, in one compiled call: most steps are such steps.

In Python such a step passes through a dozen small calls (the pose update, the clearance test, the
odometry, the scan), whose calling costs more than their arithmetic. :class:`flatland.World` takes
this path for noise-free encoders (noise draws stay in Python, in their order) and falls back to
its Python path, the full sweep against pymunk, when the move is not clear. The kernel calls the
functions that path calls (compiled from the same source), so both compute the same bits.
"""

from __future__ import annotations

import functools
from typing import Callable

import numpy as np
from numba.extending import register_jitable

from common.geometry import sensor_origin
from common.kernel_cache import compiled_for, kernel
from common.kinematics import Pose2D, body_velocity, unicycle_euler, unicycle_exact, wheel_speeds
from common.motion.packing import view2
from common.motion.step import PACKED_BOX_ROWS, PACKED_CIRCLE_ROWS, finish_packed
from flatland.clearance import path_clear, swept_capsule
from flatland.lidar import cast_scan, cast_scan_among


def step_constants(*, step_time: float, exact: bool, sweep_radius: float, wheel_radius: float, wheel_base: float,
                   mount_x: float, mount_y: float, first_beam: float, beam_step: float, range_max: float) -> np.ndarray:
    """The robot's and sensor's constants as :func:`free_step` takes them, in one array."""
    return np.array([step_time, float(exact), sweep_radius, wheel_radius, wheel_base, mount_x, mount_y, first_beam,
                     beam_step, range_max], dtype=np.float64)


@register_jitable
def _integrate(pose: Pose2D, v: float, w: float, dt: float, exact: bool) -> Pose2D:
    """The world's integrator, chosen by flag (a kernel cannot take the Python function)."""
    return unicycle_exact(pose, v, w, dt) if exact else unicycle_euler(pose, v, w, dt)


@kernel
def free_step(x, y, yaw, odometry_x, odometry_y, odometry_yaw, v, w, constants, circles, boxes, segments, solids,
              ranges, out) -> bool:
    """Advance the robot (pose x, y, yaw; odometry pose) by (v, w) for one step if no obstacle comes
    within the swept capsule of its path (``path_clear``): then write the new pose, odometry pose
    and odometry velocity into ``out`` (8 values), the exact scan from the new pose into ``ranges``,
    and return True. Otherwise return False with nothing written."""
    dt, exact = constants[0], constants[1] > 0.0
    end = _integrate(Pose2D(x, y, yaw), v, w, dt, exact)
    if not path_clear(x, y, end[0], end[1], swept_capsule(constants[2], v, w, dt), circles, boxes, segments, solids):
        return False
    wheel_radius, wheel_base = constants[3], constants[4]
    left, right = wheel_speeds(v, w, wheel_radius, wheel_base)
    odometry_v, odometry_w = body_velocity(left, right, wheel_radius, wheel_base)
    odometry = _integrate(Pose2D(odometry_x, odometry_y, odometry_yaw), odometry_v, odometry_w, dt, exact)
    out[0], out[1], out[2] = end
    out[3], out[4], out[5] = odometry
    out[6], out[7] = odometry_v, odometry_w
    if ranges.shape[0] == 0:
        return True
    sensor_x, sensor_y = sensor_origin(end[0], end[1], end[2], constants[5], constants[6])
    cast_scan(sensor_x, sensor_y, end[2] + constants[7], constants[8], circles, boxes, segments, constants[9], ranges)
    return True


@kernel
def free_step_among(x, y, yaw, odometry_x, odometry_y, odometry_yaw, v, w, constants, circles, boxes, segments, solids,
                    ranges, out, floats, float_layout, ints, int_layout, orca_velocity, inside, irsim, dt, advanced,
                    mode, stopped) -> tuple[bool, int, bool]:
    """:func:`free_step` among movers, whose step follows the robot's in the same call: if the move
    is clear, the movers' step after it (:func:`~common.motion.step.finish_packed`, its packed
    arguments as :attr:`~common.motion.movers.Movers.step_arguments` gives them) and the scan from
    the new pose among the static shapes and the movers where they now are. Whether the move was
    clear (if not, nothing is written), the first mover (table row) the robot touched or -1, and
    whether a wanderer arrived. Three calls a step made one, each unboxing its arguments, with
    Python between them: a crowd's env step runs 4-5% faster (docs/benchmarks.md)."""
    if not free_step(x, y, yaw, odometry_x, odometry_y, odometry_yaw, v, w, constants, circles, boxes, segments, solids,
                     ranges[:0], out):
        return False, -1, False
    touched, wanders = finish_packed(floats, float_layout, ints, int_layout, orca_velocity, inside, irsim, dt, advanced,
                                     mode, out[0], out[1], out[2], v, w, 0.0, stopped)
    sensor_x, sensor_y = sensor_origin(out[0], out[1], out[2], constants[5], constants[6])
    cast_scan_among(sensor_x, sensor_y, out[2] + constants[7], constants[8], circles, boxes, segments,
                    view2(floats, float_layout, PACKED_CIRCLE_ROWS), view2(floats, float_layout, PACKED_BOX_ROWS),
                    constants[9], ranges)
    return True, touched, wanders


@functools.cache
def free_step_code() -> Callable:
    """:func:`free_step`'s machine code for the arrays a world hands it (every one float64 and
    C-contiguous): called directly, it skips the dispatcher's matching of its 15 arguments' types
    (about 0.4 µs of IR-SIM's circle world's 16 µs env step)."""
    table = np.empty((0, 4))
    return compiled_for(free_step, *(0.0,) * 8, np.empty(10), np.empty((0, 3)), np.empty((0, 6)), table, table,
                        np.empty(0), np.empty(8))


@functools.cache
def free_step_among_code() -> Callable:
    """:func:`free_step_among`'s machine code for the arrays a world and its movers hand it (as
    :func:`free_step_code` and :func:`common.motion.movers.finish_code`)."""
    table, layout = np.empty((0, 4)), np.empty((0, 4), dtype=np.int64)
    return compiled_for(free_step_among, *(0.0,) * 8, np.empty(10), np.empty((0, 3)), np.empty((0, 6)), table, table,
                        np.empty(0), np.empty(8), np.empty(0), layout, np.empty(0, dtype=np.int64), layout,
                        np.empty((0, 2), dtype=np.float32), np.empty((0, 0), dtype=np.bool_), False, 0.0, False, 0,
                        False)
