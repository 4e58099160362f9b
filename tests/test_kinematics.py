"""Differential-drive kinematics against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from common.kinematics import (
    INTEGRATORS,
    Pose2D,
    WheelOdometry,
    body_velocity,
    unicycle_euler,
    unicycle_exact,
    wheel_speeds,
    wrap_angle,
)

WHEEL_RADIUS = 0.05
WHEEL_BASE = 0.22


def integrate(step, pose: Pose2D, v: float, w: float, dt: float, n: int) -> list[Pose2D]:
    """All poses of ``n`` steps of a constant command, the start excluded."""
    poses = []
    for _ in range(n):
        pose = step(pose, v, w, dt)
        poses.append(pose)
    return poses


def assert_same_angle(a: float, b: float, atol: float = 1e-9) -> None:
    assert abs(wrap_angle(a - b)) < atol, (a, b)


# --- straight lines and circles -------------------------------------------------------------


@pytest.mark.parametrize("step", [unicycle_euler, unicycle_exact], ids=["euler", "exact"])
def test_straight_line_when_w_is_zero(step):
    start = Pose2D(1.0, -2.0, 0.7)
    pose = integrate(step, start, 0.8, 0.0, 0.05, 40)[-1]
    distance = 0.8 * 0.05 * 40
    assert_allclose(pose, (1.0 + distance * math.cos(0.7), -2.0 + distance * math.sin(0.7), 0.7), atol=1e-12)


@pytest.mark.parametrize("n", [1, 1000], ids=["one-step", "many-steps"])
def test_exact_full_circle_returns_to_start(n):
    start = Pose2D(0.5, 1.5, 0.3)
    pose = integrate(unicycle_exact, start, 1.0, 1.0, 2.0 * math.pi / n, n)[-1]
    assert_allclose(pose[:2], start[:2], atol=1e-9)
    assert_same_angle(pose.yaw, start.yaw)


@pytest.mark.parametrize("v, w", [(1.0, 1.0), (0.6, -1.5), (2.0, 0.25)])
def test_exact_arc_radius_is_v_over_w(v, w):
    start = Pose2D(0.0, 0.0, 0.0)
    radius = v / w
    centre = np.array([0.0, radius])  # left of the heading for w > 0, right for w < 0
    poses = np.array(integrate(unicycle_exact, start, v, w, 0.01, 200))
    assert_allclose(np.hypot(*(poses[:, :2] - centre).T), abs(radius), rtol=1e-9)
    # Arc length travelled equals v * t, so the heading turned equals w * t.
    assert_same_angle(poses[-1, 2], w * 0.01 * 200)


def test_euler_uses_heading_at_step_start():
    start = Pose2D(1.0, 2.0, 0.3)
    v, w, dt = 1.5, 2.0, 0.4
    pose = unicycle_euler(start, v, w, dt)
    assert_allclose(pose, (1.0 + v * dt * math.cos(0.3), 2.0 + v * dt * math.sin(0.3), 0.3 + w * dt), atol=1e-12)
    # ... which differs from the exact arc at first order in dt (the chord bends by w*dt/2).
    exact = unicycle_exact(start, v, w, dt)
    assert math.hypot(pose.x - exact.x, pose.y - exact.y) > 0.05
    assert_allclose(pose.yaw, exact.yaw, atol=1e-12)


def test_euler_global_error_is_first_order():
    """Over a fixed time on an arc, Euler's position error halves when dt halves."""
    start, v, w, t = Pose2D(0.0, 0.0, 0.0), 1.0, 1.0, 1.0
    exact = unicycle_exact(start, v, w, t)

    def error(n: int) -> float:
        pose = integrate(unicycle_euler, start, v, w, t / n, n)[-1]
        return math.hypot(pose.x - exact.x, pose.y - exact.y)

    errors = np.array([error(n) for n in (100, 200, 400)])
    assert_allclose(errors[:-1] / errors[1:], 2.0, rtol=0.02)


def test_integrators_registry():
    assert INTEGRATORS == {"euler": unicycle_euler, "exact": unicycle_exact}


# --- wrap_angle -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "angle, expected",
    [
        (0.0, 0.0),
        (1.0, 1.0),
        (-1.0, -1.0),
        (math.pi, -math.pi),
        (-math.pi, -math.pi),
        (2.0 * math.pi, 0.0),
        (-2.0 * math.pi, 0.0),
        (3.0 * math.pi, -math.pi),
        (-3.0 * math.pi, -math.pi),
        (math.pi / 2 + 4.0 * math.pi, math.pi / 2),
        (-math.pi / 2 - 10.0 * math.pi, -math.pi / 2),
    ],
)
def test_wrap_angle_values(angle, expected):
    assert wrap_angle(angle) == pytest.approx(expected, abs=1e-12)


def test_wrap_angle_range_on_random_floats():
    rng = np.random.default_rng(0)
    for angle in rng.uniform(-100.0, 100.0, 2000).tolist():
        wrapped = wrap_angle(angle)
        assert -math.pi <= wrapped < math.pi
        assert_allclose(math.sin(wrapped), math.sin(angle), atol=1e-9)
        assert_allclose(math.cos(wrapped), math.cos(angle), atol=1e-9)


@pytest.mark.parametrize(
    "angle",
    [math.nextafter(-math.pi, -math.inf), -3.0 + (-0.14159265358979356)],
    ids=["just-below-minus-pi", "yaw-plus-step"],
)
def test_wrap_angle_just_below_minus_pi_stays_in_range(angle):
    assert -math.pi <= wrap_angle(angle) < math.pi


# --- wheel speeds ---------------------------------------------------------------------------


def test_wheel_speeds_known_values():
    # Straight: both wheels turn at v / r.
    assert_allclose(wheel_speeds(1.0, 0.0, WHEEL_RADIUS, WHEEL_BASE), (20.0, 20.0))
    # Spin in place counter-clockwise: wheels opposite, rim speed w * base / 2.
    left, right = wheel_speeds(0.0, 2.0, WHEEL_RADIUS, WHEEL_BASE)
    assert_allclose((left, right), (-2.0 * 0.11 / 0.05, 2.0 * 0.11 / 0.05))
    assert_allclose(body_velocity(10.0, 10.0, WHEEL_RADIUS, WHEEL_BASE), (0.5, 0.0), atol=1e-15)
    assert_allclose(body_velocity(-4.4, 4.4, WHEEL_RADIUS, WHEEL_BASE), (0.0, 2.0), atol=1e-15)


def test_wheel_speeds_body_velocity_round_trip():
    rng = np.random.default_rng(1)
    for v, w, radius, base in zip(
        rng.uniform(-3, 3, 200), rng.uniform(-5, 5, 200), rng.uniform(0.01, 0.3, 200), rng.uniform(0.05, 1, 200)
    ):
        left, right = wheel_speeds(v, w, radius, base)
        assert_allclose(body_velocity(left, right, radius, base), (v, w), rtol=1e-12, atol=1e-12)
        assert_allclose(wheel_speeds(*body_velocity(left, right, radius, base), radius, base), (left, right),
                        rtol=1e-12, atol=1e-12)


# --- wheel odometry -------------------------------------------------------------------------


def commands(seed: int, n: int = 200) -> np.ndarray:
    """A fixed random sequence of (v, w) commands."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(0.0, 1.0, n), rng.uniform(-1.0, 1.0, n)])


def drive(odometry: WheelOdometry, cmds: np.ndarray, dt: float = 0.1,
          integrate=unicycle_exact) -> tuple[Pose2D, Pose2D]:
    """Feed true wheel speeds to the odometry; return (estimated, true) final poses, the truth
    integrated by ``integrate``."""
    start = Pose2D(1.0, 2.0, 0.5)
    odometry.reset(start)
    truth = start
    for v, w in cmds:
        odometry.update(*wheel_speeds(v, w, odometry.wheel_radius, odometry.wheel_base), dt)
        truth = integrate(truth, v, w, dt)
    return odometry.pose, truth


def make_odometry(noise: float, seed: int = 0, integrate=unicycle_exact) -> WheelOdometry:
    return WheelOdometry(WHEEL_RADIUS, WHEEL_BASE, noise, np.random.default_rng(seed), integrate)


@pytest.mark.parametrize("name", sorted(INTEGRATORS))
def test_noiseless_odometry_tracks_the_integrator(name):
    odometry = make_odometry(0.0, integrate=INTEGRATORS[name])
    cmds = commands(2)
    estimate, truth = drive(odometry, cmds, integrate=INTEGRATORS[name])
    assert_allclose(estimate, truth, atol=1e-9)
    assert_allclose((odometry.v, odometry.w), cmds[-1], atol=1e-12)


def test_odometry_reset_is_at_rest():
    odometry = make_odometry(0.0)
    drive(odometry, commands(3, 5))
    odometry.reset(Pose2D(3.0, 4.0, 1.0))
    assert odometry.pose == (3.0, 4.0, 1.0)
    assert (odometry.v, odometry.w) == (0.0, 0.0)


def test_odometry_drift_grows_with_noise():
    cmds = commands(4)
    noises = (0.01, 0.05, 0.2)
    mean_errors = []
    for noise in noises:
        errors = []
        for seed in range(20):
            estimate, truth = drive(make_odometry(noise, seed), cmds)
            errors.append(math.hypot(estimate.x - truth.x, estimate.y - truth.y))
        mean_errors.append(float(np.mean(errors)))
    assert mean_errors[0] > 0.0
    assert mean_errors[0] < mean_errors[1] < mean_errors[2], mean_errors
    # Small multiplicative slip: drift roughly proportional to the noise level.
    assert mean_errors[1] / mean_errors[0] > 2.5
    assert mean_errors[2] / mean_errors[1] > 2.0


def test_odometry_same_seed_same_drift():
    cmds = commands(5)
    first, _ = drive(make_odometry(0.1, seed=42), cmds)
    second, _ = drive(make_odometry(0.1, seed=42), cmds)
    other, _ = drive(make_odometry(0.1, seed=43), cmds)
    assert first == second
    assert first != other


def test_a_measured_turn_replaces_the_wheels_heading_and_keeps_their_speed():
    cmds = commands(6)
    odometry = make_odometry(0.2, seed=1)  # encoders so noisy that their own heading is far off
    start = Pose2D(1.0, 2.0, 0.5)
    odometry.reset(start)
    yaw = start.yaw
    for v, w in cmds:
        odometry.update(*wheel_speeds(v, w, odometry.wheel_radius, odometry.wheel_base), 0.1, turned=w * 0.1)
        yaw += w * 0.1
    assert odometry.pose.yaw == pytest.approx(math.remainder(yaw, 2.0 * math.pi), abs=1e-9)
    assert odometry.w == pytest.approx(cmds[-1][1])
    assert odometry.v != pytest.approx(cmds[-1][0], abs=1e-6)  # the speed is still the noisy wheels'
