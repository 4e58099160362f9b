"""IR-SIM's velocity conversions and goal-seeking ("dash") laws, as functions of floats.

Reproduces, bit for bit, IR-SIM 2.12's ``WrapToPi``, ``vel_world2diff``, ``vel_world2omni`` and
``vel_omni2world`` (``irsim/util/util.py``), ``DiffDash`` and ``OmniDash``
(``irsim/lib/behavior/behavior_methods.py``) and ``ObjectBase.get_desired_omni_vel``
(``irsim/world/object_base.py``, ``normalized=False``). Exactness matters because a mover's
command feeds its next state: a last-bit difference in a heading or a speed grows over a
trajectory, and in RVO it can pick another grid candidate outright, so a world would no longer
replay as it does in IR-SIM.

Every function is ``uncounted`` (:mod:`common.kernel_cache`; the two helpers below: an ``overload``):
Python calls it as a plain function, and compiled kernels inline it. Both must give the same bits, which needs care
in two places where numba and CPython differ:

* squares: IR-SIM writes ``v ** 2`` on scalars, which CPython and numpy compute with the C
  library's ``pow``. ``pow`` is not correctly rounded and differs from ``v * v`` in the last bit
  for about one input in a thousand, while numba (and LLVM, given ``pow(v, 2.0)``) turns every
  square into ``v * v``. :func:`c_pow` calls the C library's ``pow`` in both worlds.
* distances: IR-SIM's ``relative_position`` uses ``math.hypot``, which CPython computes with its
  own algorithm (``vector_norm`` in ``Modules/mathmodule.c``), not the C library's ``hypot`` that
  numba and ``np.hypot`` call; they differ in the last bit for about one input in 200.
  :func:`python_hypot` is ``math.hypot`` from Python and, compiled, a port of the running
  interpreter's algorithm (3.10/3.11's, or the later one, which differs for subnormal lengths).
"""

from __future__ import annotations

import math
import sys

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic, overload

from common.kernel_cache import uncounted

__all__ = [
    "c_pow", "desired_omni_velocity", "diff_dash", "omni_dash", "omni_to_world", "python_hypot", "world_to_diff",
    "world_to_omni", "wrap_to_pi",
]

_DBL_MIN = 2.2250738585072014e-308  # smallest normal double (C's DBL_MIN)
_VELTKAMP = 134217729.0  # 2 ** 27 + 1: splits a double into two halves whose products are exact


# --- CPython's scalar arithmetic, reproduced in compiled code ---------------------------------------


def c_pow(x: float, y: float) -> float:
    """``x ** y`` as CPython (and numpy's float64 scalars) compute it: the C library's ``pow``."""
    return float(x) ** float(y)


@intrinsic
def _libm_pow(typingctx, x, y):
    """A call of the C library's ``pow`` that LLVM may not rewrite (it folds ``pow(v, 2.0)`` to ``v * v``)."""
    signature = types.float64(types.float64, types.float64)

    def codegen(context, builder, sig, args):
        double = ir.DoubleType()
        function = cgutils.get_or_insert_function(builder.module, ir.FunctionType(double, [double, double]), "pow")
        # Not a builtin: LLVM keeps the library call instead of simplifying it by its known semantics.
        function.attributes.add("nobuiltin")
        return builder.call(function, args)

    return signature, codegen


@overload(c_pow)
def _c_pow_compiled(x, y):
    def implementation(x, y):
        return _libm_pow(float(x), float(y))

    return implementation


def python_hypot(x: float, y: float) -> float:
    """``math.hypot(x, y)``: CPython's own algorithm, not the C library's ``hypot``."""
    return math.hypot(x, y)


@uncounted
def _split(value: float) -> tuple[float, float]:
    """Veltkamp's split: ``value = high + low``, halves of at most 26 bits whose products are exact."""
    scaled = value * _VELTKAMP
    high = scaled - (scaled - value)
    return high, value - high


@uncounted
def _exact_product(a: float, b: float) -> tuple[float, float]:
    """Dekker's product: ``a * b = high + low`` exactly (later CPython's ``dl_mul``, there with fma: the same bits)."""
    a_high, a_low = _split(a)
    b_high, b_low = _split(b)
    product = a_high * b_high
    cross = a_high * b_low + a_low * b_high
    high = product + cross
    return high, product - high + cross + a_low * b_low


@uncounted
def _norm_311(a: float, b: float, largest: float) -> float:
    """CPython 3.10/3.11's ``vector_norm`` for two finite coordinates ``0 <= a, b <= largest``, ``largest > 0``."""
    exponent = math.frexp(largest)[1]
    total, frac1, frac2, frac3 = 1.0, 0.0, 0.0, 0.0  # starting at 1.0 keeps the compensated sums exact
    if exponent >= -1023:
        scale = math.ldexp(1.0, -exponent)  # lossless: the coordinates become < 1
        for coordinate in (a, b):
            coordinate *= scale
            high, low = _split(coordinate)
            term = high * high  # the square as hi^2 + 2 hi lo + lo^2, each term exact
            previous = total
            total += term
            frac1 += (previous - total) + term
            term = 2.0 * high * low
            previous = total
            total += term
            frac2 += (previous - total) + term
            frac3 += low * low
        root = math.sqrt(total - 1.0 + (frac1 + frac2 + frac3))
        # One differential correction of the square root from the exactly computed residual.
        high, low = _split(root)
        term = -high * high
        previous = total
        total += term
        frac1 += (previous - total) + term
        term = -2.0 * high * low
        previous = total
        total += term
        frac2 += (previous - total) + term
        term = -low * low
        previous = total
        total += term
        frac3 += (previous - total) + term
        residual = total - 1.0 + (frac1 + frac2 + frac3)
        return (root + residual / (2.0 * root)) / scale
    # Subnormal: the scale would overflow, so divide by the largest instead.
    for coordinate in (a, b):
        coordinate /= largest
        term = coordinate * coordinate
        previous = total
        total += term
        frac1 += (previous - total) + term
    return largest * math.sqrt(total - 1.0 + frac1)


@uncounted
def _scaled_norm_312(a: float, b: float, largest: float) -> float:
    """Later CPython's ``vector_norm`` for two finite coordinates, ``largest`` > 0 and normal."""
    exponent = math.frexp(largest)[1]
    scale = math.ldexp(1.0, -exponent)  # lossless: the coordinates become < 1
    total, frac1, frac2 = 1.0, 0.0, 0.0  # starting at 1.0 keeps the fast two-sum below exact
    for coordinate in (a, b):
        coordinate *= scale
        high, low = _exact_product(coordinate, coordinate)
        new_total = total + high
        frac2 += (total - new_total) + high
        total = new_total
        frac1 += low
    root = math.sqrt(total - 1.0 + (frac1 + frac2))
    # One differential correction of the square root from the exactly computed residual.
    high, low = _exact_product(-root, root)
    new_total = total + high
    frac2 += (total - new_total) + high
    total = new_total
    frac1 += low
    residual = total - 1.0 + (frac1 + frac2)
    root += residual / (2.0 * root)
    return root / scale


@uncounted
def _norm_312(a: float, b: float, largest: float) -> float:
    """Later CPython's ``vector_norm`` (3.12 on, as far as we know), with its rescaling of subnormal coordinates."""
    if math.frexp(largest)[1] < -1023:
        # The scale 2 ** -exponent would overflow: make the coordinates normal first.
        return _DBL_MIN * _scaled_norm_312(a / _DBL_MIN, b / _DBL_MIN, largest / _DBL_MIN)
    return _scaled_norm_312(a, b, largest)


@overload(python_hypot)
def _python_hypot_compiled(x, y):
    # The interpreter's own algorithm; they differ only for subnormal lengths in practice. The switch
    # version is our reading of CPython's history; the tests compare with the running interpreter.
    norm = _norm_311 if sys.version_info < (3, 12) else _norm_312

    def implementation(x, y):
        a = abs(float(x))
        b = abs(float(y))
        largest = 0.0
        if a > largest:
            largest = a
        if b > largest:
            largest = b
        if math.isinf(largest):  # before the NaN test, as in CPython: hypot(inf, nan) is inf
            return largest
        if math.isnan(a) or math.isnan(b):
            return math.nan
        if largest == 0.0:
            return largest
        return norm(a, b, largest)

    return implementation


@uncounted
def _sign(value: float) -> float:
    """``np.sign`` of a float: 1, -1, 0 (also for -0.0) or NaN."""
    if value > 0.0:
        return 1.0
    if value < 0.0:
        return -1.0
    if value == 0.0:
        return 0.0
    return value


# --- IR-SIM's functions --------------------------------------------------------------------------------


@uncounted
def wrap_to_pi(angle: float) -> float:
    """IR-SIM's ``WrapToPi``: ``(a + pi) % (2 pi) - pi``; 0.0 for a non-finite angle.

    Unlike ``common.kinematics.wrap_angle`` it keeps IR-SIM's result just below -pi (+pi).
    """
    if not math.isfinite(angle):
        return 0.0
    shifted = angle + math.pi
    # x % 2 pi is x itself for x in [0, 2 pi): the same bits, without the modulo's fmod.
    return (shifted if 0.0 <= shifted < 2.0 * math.pi else shifted % (2.0 * math.pi)) - math.pi


@uncounted
def _relative_position(x: float, y: float, gx: float, gy: float) -> tuple[float, float]:
    """IR-SIM's ``relative_position``: CPython's hypot distance and the wrapped bearing to the goal."""
    distance = python_hypot(gx - x, gy - y)
    # atan2 is already in [-pi, pi], but IR-SIM wraps it, and the wrap can change the last bit.
    return distance, wrap_to_pi(math.atan2(gy - y, gx - x))


@uncounted
def world_to_diff(
    heading: float, vx: float, vy: float, w_max: float, guarantee_time: float, tolerance: float, mini_speed: float
) -> tuple[float, float]:
    """IR-SIM's ``vel_world2diff``: a world-frame velocity to (linear, angular) for a diff robot."""
    speed = math.sqrt(c_pow(vx, 2.0) + c_pow(vy, 2.0))
    if speed <= mini_speed:
        return 0.0, 0.0
    diff = wrap_to_pi(heading - math.atan2(vy, vx))
    if abs(diff) < tolerance:
        w = 0.0
    else:
        w = -diff / guarantee_time
        if w > w_max:
            w = float(w_max)
        if w < -w_max:
            w = float(-w_max)
    v = speed * math.cos(diff)
    if v < 0:
        v = 0.0
    return v, w


@uncounted
def world_to_omni(heading: float, vx: float, vy: float) -> tuple[float, float]:
    """IR-SIM's ``vel_world2omni``: a world-frame velocity to (forward, lateral) in the body frame."""
    cos_t = math.cos(heading)
    sin_t = math.sin(heading)
    return vx * cos_t + vy * sin_t, -vx * sin_t + vy * cos_t


@uncounted
def omni_to_world(heading: float, forward: float, lateral: float) -> tuple[float, float]:
    """IR-SIM's ``vel_omni2world``: a body-frame (forward, lateral) velocity to the world frame."""
    cos_t = math.cos(heading)
    sin_t = math.sin(heading)
    return forward * cos_t - lateral * sin_t, forward * sin_t + lateral * cos_t


@uncounted
def diff_dash(
    x: float, y: float, theta: float, gx: float, gy: float, v_max: float, w_max: float, goal_threshold: float,
    angle_tolerance: float, angular_acce: float, dt: float,
) -> tuple[float, float]:
    """IR-SIM's ``DiffDash``: (linear, angular) to drive a diff robot at the goal.

    The turn rate is capped so that the robot can brake within the remaining heading error
    (``angular_acce`` finite and > 0), else it is bang-bang at ``|w_max|``.
    """
    distance, bearing = _relative_position(x, y, gx, gy)
    if distance < goal_threshold:  # strict, as IR-SIM's (its OmniDash has the opposite test)
        return 0.0, 0.0
    diff = wrap_to_pi(bearing - theta)
    # IR-SIM's np.cos: the C library's cos for a scalar with this numpy (a build that sends float64
    # cos to its own AVX-512 code could differ in the last bit; the tests would show it).
    linear = v_max * math.cos(diff)
    if abs(diff) < angle_tolerance:
        angular = 0.0
    else:
        limit = abs(w_max)
        if math.isfinite(angular_acce) and angular_acce > 0:
            remaining = abs(diff) - angle_tolerance
            a_dt = angular_acce * dt
            ramp = -a_dt + math.sqrt(c_pow(a_dt, 2.0) + 2.0 * angular_acce * remaining)
            # Python's min(limit, ramp): the first unless the second is smaller (so not a NaN ramp).
            max_ang = ramp if ramp < limit else limit
        else:
            max_ang = limit
        angular = _sign(diff) * max_ang
    return linear, angular


@uncounted
def omni_dash(
    x: float, y: float, theta: float, gx: float, gy: float, v_forward_max: float, v_lateral_max: float,
    goal_threshold: float,
) -> tuple[float, float]:
    """IR-SIM's ``OmniDash``: body-frame (forward, lateral) toward the goal, zero once within the threshold."""
    distance, bearing = _relative_position(x, y, gx, gy)
    if distance > goal_threshold:
        diff = wrap_to_pi(bearing - theta)
        return v_forward_max * math.cos(diff), v_lateral_max * math.sin(diff)
    return 0.0, 0.0


@uncounted
def desired_omni_velocity(
    x: float, y: float, gx: float, gy: float, speed_x: float, speed_y: float, threshold: float
) -> tuple[float, float]:
    """IR-SIM's ``get_desired_omni_vel`` (not normalized): the world-frame velocity RVO steers toward.

    ``speed_x``/``speed_y`` are the caller's per-kinematics bounds (IR-SIM's ``_desired_speed_bounds``);
    IR-SIM's ``desired_omni_vel`` property uses ``threshold`` 0.1.
    """
    distance, bearing = _relative_position(x, y, gx, gy)
    if distance > threshold:
        return speed_x * math.cos(bearing), speed_y * math.sin(bearing)
    return 0.0, 0.0
