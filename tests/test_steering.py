"""common.motion.steering against IR-SIM's own functions, bit for bit, from Python and compiled."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numba
import numpy as np
import pytest

from common.motion import steering
from tests.conftest import optional

optional("irsim")
from irsim.lib.behavior.behavior_methods import DiffDash, OmniDash  # noqa: E402
from irsim.util.util import WrapToPi, vel_omni2world, vel_world2diff, vel_world2omni  # noqa: E402
from irsim.world.object_base import ObjectBase  # noqa: E402

CASES = 4000
SPECIAL_ANGLES = [0.0, -0.0, math.pi, -math.pi, 2 * math.pi, -2 * math.pi, math.pi / 2, 3 * math.pi, -3 * math.pi,
                  math.nextafter(math.pi, 0.0), math.nextafter(-math.pi, 0.0), math.nextafter(math.pi, 4.0),
                  math.nextafter(-math.pi, -4.0), 1e-300, -1e-300, 1e17, -1e17, math.inf, -math.inf, math.nan]


def same(ours: float, theirs: float) -> bool:
    """Equal as floats, with the same sign of zero; NaN matches NaN."""
    if math.isnan(ours) or math.isnan(theirs):
        return math.isnan(ours) and math.isnan(theirs)
    return ours == theirs and math.copysign(1.0, ours) == math.copysign(1.0, theirs)


def assert_same(ours, theirs, context) -> None:
    ours, theirs = [float(v) for v in np.ravel(ours)], [float(v) for v in np.ravel(theirs)]
    assert len(ours) == len(theirs) and all(map(same, ours, theirs)), (context, ours, theirs)
    for value in ours:  # Python floats, not numpy scalars, for the callers
        assert type(value) is float


def halfway_squares(rng: np.random.Generator, count: int) -> np.ndarray:
    """Values whose exact squares lie halfway between two doubles: there the C library's pow(v, 2)
    rounds differently from v * v for about half of them."""
    mantissas = rng.integers(94906267, 2**27, count) | 1  # odd, 27 bits, square of 54 bits
    signs = rng.choice([-1.0, 1.0], count)
    exponents = rng.integers(-1, 3, count)
    return np.array([s * math.ldexp(int(m), -27 - int(e)) for s, m, e in zip(signs, mantissas, exponents)])


def near_threshold_goals(rng, x, y, threshold, count):
    """Goals at (almost) exactly ``threshold`` from (x, y): the distance test's rounding decides."""
    angles = rng.uniform(-math.pi, math.pi, count)
    return x + threshold * np.cos(angles), y + threshold * np.sin(angles)


# --- the Python functions against IR-SIM ----------------------------------------------------------------


def test_wrap_to_pi_is_irsims():
    rng = np.random.default_rng(1)
    angles = [*SPECIAL_ANGLES, *rng.uniform(-30.0, 30.0, CASES), *rng.uniform(-4.0, 4.0, CASES),
              *(k * math.pi for k in range(-9, 10))]
    for angle in angles:
        assert same(steering.wrap_to_pi(angle), WrapToPi(angle)), angle
        assert same(steering.wrap_to_pi(angle), WrapToPi(np.float64(angle))), angle


def world_to_diff_inputs(rng):
    count = CASES
    headings = np.concatenate([rng.uniform(-7.0, 7.0, count), np.resize(SPECIAL_ANGLES[:-3], count // 4)])
    n = headings.size
    vx = rng.uniform(-2.0, 2.0, n)
    vy = rng.uniform(-2.0, 2.0, n)
    slow = rng.random(n) < 0.1  # around mini_speed
    vx[slow] *= 0.015
    vy[slow] *= 0.015
    hard = rng.random(n) < 0.25
    vx[hard] = halfway_squares(rng, int(hard.sum()))
    vy[hard] = halfway_squares(rng, int(hard.sum()))
    vx[: n // 50] = 0.0
    w_max = rng.choice([1.5, 0.5, 3.0], n)
    guarantee = rng.choice([0.2, 0.1, 1.0], n)
    tolerance = rng.choice([0.1, 0.0, 0.3], n)
    mini = rng.choice([0.02, 0.0, 0.05], n)
    return headings, vx, vy, w_max, guarantee, tolerance, mini


def test_world_to_diff_is_irsims_vel_world2diff():
    args = world_to_diff_inputs(np.random.default_rng(2))
    for heading, vx, vy, w_max, guarantee, tolerance, mini in zip(*(a.tolist() for a in args)):
        ours = steering.world_to_diff(heading, vx, vy, w_max, guarantee, tolerance, mini)
        theirs = vel_world2diff(heading, np.array([[vx], [vy]]), w_max, guarantee, tolerance, mini)
        assert_same(ours, theirs, (heading, vx, vy, w_max, guarantee, tolerance, mini))
        # DiffRVO passes a list [vx, vy]; IR-SIM then takes the same path.
        assert_same(ours, vel_world2diff(heading, [vx, vy], w_max, guarantee, tolerance, mini), "list")


def test_world_omni_conversions_are_irsims():
    rng = np.random.default_rng(3)
    headings = [*SPECIAL_ANGLES[:-3], *rng.uniform(-7.0, 7.0, CASES)]
    for heading in headings:
        a, b = rng.uniform(-2.0, 2.0, 2).tolist()
        assert_same(steering.world_to_omni(heading, a, b), vel_world2omni(heading, np.array([[a], [b]])), heading)
        assert_same(steering.omni_to_world(heading, a, b), vel_omni2world(heading, np.array([[a], [b]])), heading)


def dash_inputs(rng, count):
    x, y, theta = rng.uniform(-5.0, 5.0, count), rng.uniform(-5.0, 5.0, count), rng.uniform(-7.0, 7.0, count)
    theta[: len(SPECIAL_ANGLES) - 3] = SPECIAL_ANGLES[:-3]
    gx, gy = rng.uniform(-5.0, 5.0, count), rng.uniform(-5.0, 5.0, count)
    threshold = rng.choice([0.1, 0.3, 0.0], count)
    # A quarter of the goals at the threshold's distance, some at the robot itself.
    edge = rng.random(count) < 0.25
    gx[edge], gy[edge] = near_threshold_goals(rng, x[edge], y[edge], threshold[edge], int(edge.sum()))
    gx[:20], gy[:20] = x[:20], y[:20]
    # Some goals straight ahead or behind (a heading error of exactly 0 or pi after wrapping).
    line = slice(20, 60)
    theta[line] = np.arctan2(gy[line] - y[line], gx[line] - x[line]) + rng.choice([0.0, math.pi], 40)
    return x, y, theta, gx, gy, threshold


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")  # IR-SIM's inf - inf, dt = inf
def test_diff_dash_is_irsims():
    rng = np.random.default_rng(4)
    x, y, theta, gx, gy, threshold = dash_inputs(rng, CASES)
    v_max = rng.choice([1.0, 0.5, 2.0], CASES)
    w_max = rng.choice([1.5, -1.0, 0.5], CASES)  # IR-SIM takes |w_max|
    tolerance = rng.choice([0.2, 0.0, 0.05, 0.5], CASES)
    acce = rng.choice([math.inf, 2.0, 0.5, 10.0, 0.0, -1.0, math.nan], CASES)
    dt = rng.choice([0.1, 0.0, 0.05, math.inf], CASES)  # an infinite step: a NaN ramp, which min() skips
    turns = ramps = 0
    for case in zip(x, y, theta, gx, gy, v_max, w_max, threshold, tolerance, acce, dt):
        case = tuple(float(v) for v in case)
        x0, y0, th, g0, g1, vm, wm, thr, tol, acc, step = case
        ours = steering.diff_dash(*case)
        pose, goal, limits = np.array([[x0], [y0], [th]]), np.array([[g0], [g1]]), np.array([[vm], [wm]])
        theirs = DiffDash(pose, goal, limits, thr, tol, acc, step)
        assert_same(ours, theirs, case)
        turns += ours[1] != 0.0
        ramps += ours[1] != 0.0 and abs(ours[1]) < abs(wm)
    assert turns > CASES // 4 and ramps > CASES // 40  # both the bang-bang and the braking ramp were compared


def test_omni_dash_is_irsims():
    rng = np.random.default_rng(5)
    x, y, theta, gx, gy, threshold = dash_inputs(rng, CASES)
    forward = rng.choice([1.0, 0.5, 0.0], CASES)
    lateral = rng.choice([1.0, 0.3, -0.5], CASES)
    for case in zip(x, y, theta, gx, gy, forward, lateral, threshold):
        case = tuple(float(v) for v in case)
        x0, y0, th, g0, g1, vf, vl, thr = case
        ours = steering.omni_dash(*case)
        theirs = OmniDash(np.array([[x0], [y0], [th]]), np.array([[g0], [g1]]), np.array([[vf], [vl]]), thr)
        assert_same(ours, theirs, case)


def irsim_desired_omni_vel(x, y, gx, gy, speed_x, speed_y, threshold):
    """ObjectBase.get_desired_omni_vel itself, on an object reduced to what it reads."""
    obj = SimpleNamespace(state=np.array([[x], [y], [0.3]]), goal=np.array([[gx], [gy], [0.0]]),
                          _desired_speed_bounds=lambda: (speed_x, speed_y))
    return ObjectBase.get_desired_omni_vel(obj, threshold, normalized=False)


def test_desired_omni_velocity_is_irsims():
    rng = np.random.default_rng(6)
    x, y, _, gx, gy, threshold = dash_inputs(rng, CASES)
    speed_x = rng.choice([1.0, 1.5, 0.5], CASES)
    speed_y = rng.choice([1.0, 0.7, 1.5], CASES)
    for case in zip(x, y, gx, gy, speed_x, speed_y, threshold):
        case = tuple(float(v) for v in case)
        assert_same(steering.desired_omni_velocity(*case), irsim_desired_omni_vel(*case), case)


# --- the same functions compiled --------------------------------------------------------------------------


@numba.njit
def _compiled_world_to_diff(h, vx, vy, w_max, guarantee, tolerance, mini):
    out = np.empty((h.size, 2))
    for i in range(h.size):
        out[i] = steering.world_to_diff(h[i], vx[i], vy[i], w_max[i], guarantee[i], tolerance[i], mini[i])
    return out


@numba.njit
def _compiled_omni(h, a, b):
    out = np.empty((h.size, 5))
    for i in range(h.size):
        out[i, 0:2] = steering.world_to_omni(h[i], a[i], b[i])
        out[i, 2:4] = steering.omni_to_world(h[i], a[i], b[i])
        out[i, 4] = steering.wrap_to_pi(h[i])
    return out


@numba.njit
def _compiled_wrap(h):
    out = np.empty((h.size, 1))
    for i in range(h.size):
        out[i, 0] = steering.wrap_to_pi(h[i])
    return out


@numba.njit
def _compiled_dashes(x, y, theta, gx, gy, threshold, acce, dt):
    out = np.empty((x.size, 6))
    for i in range(x.size):
        out[i, 0:2] = steering.diff_dash(x[i], y[i], theta[i], gx[i], gy[i], 1.0, 1.5, threshold[i], 0.2, acce[i],
                                         dt[i])
        out[i, 2:4] = steering.omni_dash(x[i], y[i], theta[i], gx[i], gy[i], 1.0, 0.7, threshold[i])
        out[i, 4:6] = steering.desired_omni_velocity(x[i], y[i], gx[i], gy[i], 1.5, 1.0, threshold[i])
    return out


@numba.njit
def _compiled_helpers(a, b):
    out = np.empty((a.size, 2))
    for i in range(a.size):
        out[i, 0] = steering.python_hypot(a[i], b[i])
        out[i, 1] = steering.c_pow(a[i], 2.0)
    return out


def assert_rows_same(compiled: np.ndarray, python: list) -> None:
    for index, (row, expected) in enumerate(zip(compiled, python)):
        assert all(same(float(u), float(v)) for u, v in zip(row, expected)), (index, row, expected)


def test_compiled_functions_give_the_python_bits():
    rng = np.random.default_rng(7)
    args = world_to_diff_inputs(rng)
    python = [steering.world_to_diff(*c) for c in zip(*(a.tolist() for a in args))]
    assert_rows_same(_compiled_world_to_diff(*args), python)

    # (math.cos of a non-finite angle raises in Python, as in IR-SIM: only wrap_to_pi takes those.)
    assert_rows_same(_compiled_wrap(np.array(SPECIAL_ANGLES)), [(steering.wrap_to_pi(h),) for h in SPECIAL_ANGLES])
    h = np.concatenate([np.array(SPECIAL_ANGLES[:-3]), rng.uniform(-30.0, 30.0, CASES)])
    a, b = rng.uniform(-2.0, 2.0, h.size), rng.uniform(-2.0, 2.0, h.size)
    python = [(*steering.world_to_omni(*c), *steering.omni_to_world(*c), steering.wrap_to_pi(c[0]))
              for c in zip(h.tolist(), a.tolist(), b.tolist())]
    assert_rows_same(_compiled_omni(h, a, b), python)

    x, y, theta, gx, gy, threshold = dash_inputs(rng, CASES)
    acce = rng.choice([math.inf, 2.0, 0.0, math.nan], CASES)
    dt = rng.choice([0.1, 0.0], CASES)
    python = []
    for c in zip(*(v.tolist() for v in (x, y, theta, gx, gy, threshold, acce, dt))):
        python.append((*steering.diff_dash(c[0], c[1], c[2], c[3], c[4], 1.0, 1.5, c[5], 0.2, c[6], c[7]),
                       *steering.omni_dash(c[0], c[1], c[2], c[3], c[4], 1.0, 0.7, c[5]),
                       *steering.desired_omni_velocity(c[0], c[1], c[3], c[4], 1.5, 1.0, c[5])))
    assert_rows_same(_compiled_dashes(x, y, theta, gx, gy, threshold, acce, dt), python)


@pytest.mark.parametrize("scale", [1.0, 1e-8, 1e300, 1e-309, 1e-312])
def test_compiled_hypot_and_pow_are_cpythons(scale):
    # math.hypot is CPython's own algorithm and ** the C library's pow; numba's own math.hypot and
    # squares differ from them in the last bit (checked below), so the compiled helpers must not use those.
    rng = np.random.default_rng(8)
    a = rng.uniform(-1.0, 1.0, 20000) * scale
    b = rng.uniform(-1.0, 1.0, 20000) * rng.choice([scale, scale * 1e-3, 0.0], 20000)
    if scale == 1.0:
        a[:2000] = halfway_squares(rng, 2000)
    compiled = _compiled_helpers(a, b)
    assert_rows_same(compiled[:, :1], [(math.hypot(u, v),) for u, v in zip(a.tolist(), b.tolist())])
    if scale <= 1.0:  # (Python's ** raises on overflow)
        assert_rows_same(compiled[:, 1:], [(u**2,) for u in a.tolist()])
    if scale == 1.0:
        assert np.any(np.hypot(a, b) != compiled[:, 0])  # the C library's hypot is another function
        assert np.any(a * a != compiled[:, 1])  # and v * v is not pow(v, 2)


def test_compiled_hypot_special_values():
    values = np.array([0.0, -0.0, math.inf, -math.inf, math.nan, 5e-324, 1e-310, 1.0, 3.0, 1e308])
    a, b = (grid.ravel() for grid in np.meshgrid(values, values))
    assert_rows_same(_compiled_helpers(a, b)[:, :1], [(math.hypot(u, v),) for u, v in zip(a.tolist(), b.tolist())])
