"""Observation layouts: readings + goal -> a normalised float32 vector, the same in both tiers.

Both layouts read what a real robot has: the odometry pose and velocity, the lidar and the IMU.
Every entry is scaled by a property of the robot or sensor (v_max, w_max, range_max) or by a fixed
distance scale, never by the world's size, so a policy trained in one world reads another.

``nav7`` (the 2D tutorial's layout):

====  ===========================================  ====  ===
idx   meaning                                       min   max
====  ===========================================  ====  ===
0     goal direction x, world frame (dx / d)        -1    1
1     goal direction y, world frame (dy / d)        -1    1
2     heading error to the goal / pi                -1    1
3     linear velocity / v_max                       -1    1
4     angular velocity / w_max                      -1    1
5     nearest lidar return / range_max               0    1
6     goal distance / goal_distance_scale            0    1
====  ===========================================  ====  ===

``lidar43`` (the 3D tutorial's layout): indices 0-4 as above, then

====  ===========================================  ====  ===
5     yaw rate (IMU) / w_max                        -1    1
6-41  36 lidar ranges / range_max, over the scan     0    1
42    goal distance / goal_distance_scale            0    1
====  ===========================================  ====  ===

``lidar43_log``: as ``lidar43``, but each sector reads log(r / r0) / log(range_max / r0), where r0
is the robot's bounding radius (the range of a return at contact). A linear scale spends a
tenth of its span on the last half metre before contact, where the policy has to judge
clearances to a few centimetres; the log scale spends nearly two fifths on it (0.39 with the
default 0.2 m robot and 5 m lidar).

``lidar79_motion``: as ``lidar43_log``, then how fast each sector's nearest return came nearer
or went away since the last step, with the robot's own motion taken out; a single scan cannot
tell a person walking into the robot's path from one standing in it, two consecutive ones can:

====  ==================================================================  ====  ===
43-78 36 range rates: (r_t - r_still) / (t - t_{t-1}) / RANGE_RATE_SCALE     -1    1
====  ==================================================================  ====  ===

r_t is the sector's nearest return now, r_still its nearest had nothing moved: the last scan,
carried by the odometry's motion since into the present sensor frame (each return read by the
beam nearest its bearing, and neighbouring returns on one surface joined), so what stands still
reads 0 whatever the robot does and a person walking at it reads their speed. RANGE_RATE_SCALE is
3 m/s (a person at 1.5 m/s meeting the robot at 1.5 m/s); a rate is 0 on the first step of an
episode and where the last scan says nothing about a sector (all of it newly seen). Carrying a
scan needs beams finer than the things it sees: with 36 beams (10° apart) a turn of half a beam
moves a pole between beams, and nearly a third of a still world's sectors read a rate over 0.5 m/s while
the robot drives; with 180 beams, 4 % (``tests/test_motion_layout.py``; the ``lidar_beams``
condition sets the beams). It is the one layout with memory: :meth:`ObservationLayout.reset`
starts it afresh (the env and a policy agent do, every episode).

``lidar49_robot``: for one policy that drives robots of other sizes, shapes and limits (the
``robot_family`` condition trains it on them). Its 36 sectors read the robot's *clearance*, not
the range: each beam's return less how far the beam runs inside the footprint (a box is wider
than long ahead and narrower to the side), log(c / d0 + 1) / log(range_max / d0 + 1) with
d0 = 5 cm, so 0 is touching and the first 10 cm, where a rectangle threads a gap 1.2 widths
across, span a quarter of the scale (0.24; on ``lidar43_log``'s scale a box's sides read 0 as
long as anything is within its bounding circle). Then the robot itself:

====  ==================================================================  ====  ===
43    bounding radius / 0.5 m                                               0    1
44    width across the heading / 1 m                                        0    1
45    length along the heading / 1 m                                        0    1
46    v_max / 2 m/s                                                         0    1
47    w_max / 3 rad/s                                                       0    1
48    1 for a box footprint, 0 for a circle                                 0    1
====  ==================================================================  ====  ===

``lidar51_route``: ``lidar49_robot`` and the route a global planner gives it on the static map
(:mod:`common.route`): where the route is ``ROUTE_LOOKAHEAD`` (1 m) further on, from the odometry
pose, in the robot's frame. Among thin posts the goal's bearing points at the fence; this points
at the gap. The env plans the route at each episode's start, and the evaluator plans it for a
policy agent (:func:`common.evaluation.start_agent`), each handing it to the layout
(:meth:`ObservationLayout.follow`); without one, these entries read the goal itself:

====  ==================================================================  ====  ===
49    route point ahead, x in the robot's frame (forward) / 1 m              -1    1
50    route point ahead, y in the robot's frame (left) / 1 m                 -1    1
====  ==================================================================  ====  ===

The route point is the goal once the goal is nearer than 1 m down the route, so the entries'
length falls below 1 only on the last metre.

A lidar with other than 36 beams is reduced to 36 sectors of consecutive beams, each reading its
nearest return. Values are clipped into the bounds (sensor noise may push them out).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from gymnasium import spaces

from common.errors import ConfigError, quote
from common.geometry import sensor_origin
from common.kernel_cache import kernel, uncounted
from common.kinematics import wrap_angle
from common.params import is_real
from common.readings import Readings
from common.robots import footprint_reach
from common.route import Route
from common.scenario import LidarSpec, RobotProfile

LAYOUTS = ("nav7", "lidar43", "lidar43_log", "lidar79_motion", "lidar49_robot", "lidar51_route")
ROUTE_LOOKAHEAD = 1.0  # m
RANGE_RATE_SCALE = 3.0  # m/s
_TWO_PI = 2.0 * math.pi
# Neighbouring returns further apart than this in range are two surfaces (an edge), not one to
# interpolate along: a person 2 m ahead of a wall at 5 m.
_ONE_SURFACE = 0.5  # m
LIDAR43_BEAMS = 36
DEFAULT_GOAL_DISTANCE_SCALE = 10.0


def _remembers_nothing() -> None:
    """What a layout without memory forgets at an episode's start."""


@dataclass(frozen=True)
class ObservationLayout:
    """A named layout: its Box space, the function that fills it, (for a layout with memory) the
    function that forgets the last episode and (for one that reads a route) the function that
    takes an episode's route."""

    name: str
    space: spaces.Box
    compute: Callable[[Readings, tuple[float, float]], np.ndarray]
    forget: Callable[[], None] = _remembers_nothing
    take_route: Callable[[Route], None] | None = None

    def __call__(self, readings: Readings, goal: tuple[float, float]) -> np.ndarray:
        return self.compute(readings, goal)

    def __deepcopy__(self, memo: dict) -> "ObservationLayout":
        # Immutable but for the memory its closures hold (the last scan, the episode's route): a
        # copy would share that memory, two envs feeding one.
        if self.forget is not _remembers_nothing:
            raise TypeError(f"the {self.name} layout remembers each episode in closures a copy would share; "
                            "make another env (gym.make) instead of copying one")
        return self

    def reset(self) -> None:
        """Start a new episode (call before its first observation)."""
        self.forget()

    @property
    def reads_route(self) -> bool:
        """Whether it reads a route on the static map (give it one with :meth:`follow`)."""
        return self.take_route is not None

    def follow(self, route: Route) -> None:
        """Read this episode's route (after :meth:`reset`)."""
        if self.take_route is not None:
            self.take_route(route)


@uncounted
def goal_terms(x: float, y: float, yaw: float, goal_x: float, goal_y: float,
               scale: float) -> tuple[float, float, float, float]:
    """Goal direction (x, y), heading error / pi and the scaled goal distance, from the pose (x, y, yaw)."""
    dx, dy = goal_x - x, goal_y - y
    distance = math.hypot(dx, dy)
    inv = 1.0 / max(distance, 1e-6)
    return dx * inv, dy * inv, wrap_angle(math.atan2(dy, dx) - yaw) / math.pi, distance / scale


def sector_bounds(beams: int, sectors: int) -> np.ndarray:
    """Rows [first, end) of the beams each of ``sectors`` sectors reads: consecutive beams when
    there are more beams than sectors, else the beam under each sector (repeated)."""
    starts = np.floor(np.arange(sectors) * beams / sectors).astype(np.int64)
    ends = np.append(starts[1:], beams) if beams > sectors else starts + 1
    return np.column_stack([starts, ends])


@kernel
def _encode(out, x, y, yaw, goal_x, goal_y, scale, v, w, yaw_rate, ranges, bounds, inv_range, floor, log_scale,
            low, high):
    """Fill ``out``: the goal terms (:func:`goal_terms`: from the odometry pose ``x, y, yaw`` to the
    goal, the distance scaled by ``scale``) at 0-2 and last, v and w at 3-4, the yaw rate at 5
    where the sectors start at 6, then each sector's nearest return, linear (r / range_max) or,
    with ``log_scale`` > 0, log(max(r, floor) / floor) * log_scale; then clip all of ``out`` into
    [low, high]. One compiled call: element writes from Python cost more than the sectors, and the
    pose and goal come as floats because a tuple argument costs the call more than a float each.
    The rounding follows the NumPy code it replaced (log in float64, the scale in float32),
    identical where the C library's log and NumPy's agree (on this project's machine, on a million
    values; NumPy's own SIMD log on AVX-512 may differ in the last bit). Unlike np.minimum/maximum,
    the clip does not pass NaN through: no lidar here returns one."""
    n = out.shape[0]
    first = n - 1 - bounds.shape[0]
    out[0], out[1], out[2], out[n - 1] = goal_terms(x, y, yaw, goal_x, goal_y, scale)
    out[3], out[4] = v, w
    if first > 5:
        out[5] = yaw_rate
    inv_floor = 1.0 / floor
    for k in range(bounds.shape[0]):
        nearest = ranges[bounds[k, 0]]
        for i in range(bounds[k, 0] + 1, bounds[k, 1]):
            nearest = min(nearest, ranges[i])
        if log_scale > 0.0:
            # Returns inside the floor (sensor noise, a lidar off the robot's centre) read 0.
            out[first + k] = np.float32(math.log(max(nearest, floor) * inv_floor)) * np.float32(log_scale)
        else:
            out[first + k] = nearest * inv_range
    for i in range(n):
        out[i] = min(max(out[i], low[i]), high[i])


def make_layout(
    name: str, robot: RobotProfile, lidar: LidarSpec, goal_distance_scale: float = DEFAULT_GOAL_DISTANCE_SCALE
) -> ObservationLayout:
    """Build the named layout for a robot and its lidar (``goal_distance_scale``: the distance, in
    metres, that the goal-distance entry reads as 1)."""
    if not (is_real(goal_distance_scale) and 0.0 < goal_distance_scale < math.inf):  # NaN fails too
        raise ConfigError(None, "goal_distance_scale", f"got {quote(goal_distance_scale)}; allowed: a finite distance > 0 (metres)")
    inv_v, inv_w, inv_r = 1.0 / robot.v_max, 1.0 / robot.w_max, 1.0 / lidar.range_max
    if name == "nav7":
        low = np.array([-1, -1, -1, -1, -1, 0, 0], dtype=np.float32)
        high = np.ones(7, dtype=np.float32)
        whole_scan = sector_bounds(lidar.beams, 1)  # one sector: the nearest return of all

        def compute(readings: Readings, goal: tuple[float, float]) -> np.ndarray:
            out = np.empty(7, dtype=np.float32)
            odometry = readings.odometry
            x, y, yaw = odometry.pose
            _encode(out, x, y, yaw, goal[0], goal[1], goal_distance_scale, odometry.v * inv_v, odometry.w * inv_w, 0.0,
                    readings.lidar, whole_scan, inv_r, 1.0, 0.0, low, high)
            return out

    elif name == "lidar79_motion":
        return _motion_layout(robot, lidar, goal_distance_scale)
    elif name == "lidar49_robot":
        return _robot_layout(robot, lidar, goal_distance_scale)
    elif name == "lidar51_route":
        return _route_layout(robot, lidar, goal_distance_scale)
    elif name in ("lidar43", "lidar43_log"):
        floor = min(robot.bounding_radius, 0.5 * lidar.range_max)
        log_scale = 1.0 / math.log(lidar.range_max / floor) if name == "lidar43_log" else 0.0
        return _sector_layout(name, robot, lidar, goal_distance_scale, inv_r, floor, log_scale)
    else:
        raise ConfigError(None, "observation", f"unknown layout {quote(name)}; allowed: {', '.join(LAYOUTS)}")
    return ObservationLayout(name, spaces.Box(low, high, dtype=np.float32), compute)


def _sector_layout(name: str, robot: RobotProfile, lidar: LidarSpec, goal_distance_scale: float, inv_range: float,
                   floor: float, log_scale: float, shift: np.ndarray | None = None) -> ObservationLayout:
    """The 43 entries of ``lidar43`` (goal, motion and 36 sectors; :func:`_encode` says how the
    sectors read), each beam's range plus ``shift`` where given (``lidar49_robot``'s clearance)."""
    low = np.concatenate([[-1, -1, -1, -1, -1, -1], np.zeros(LIDAR43_BEAMS + 1)]).astype(np.float32)
    high = np.ones(43, dtype=np.float32)
    bounds = sector_bounds(lidar.beams, LIDAR43_BEAMS)
    inv_v, inv_w = 1.0 / robot.v_max, 1.0 / robot.w_max

    def compute(readings: Readings, goal: tuple[float, float]) -> np.ndarray:
        out = np.empty(43, dtype=np.float32)
        odometry = readings.odometry
        ranges = readings.lidar if shift is None else readings.lidar + shift
        x, y, yaw = odometry.pose
        _encode(out, x, y, yaw, goal[0], goal[1], goal_distance_scale, odometry.v * inv_v, odometry.w * inv_w,
                readings.imu.angular_velocity[2] * inv_w, ranges, bounds, inv_range, floor, log_scale, low, high)
        return out

    return ObservationLayout(name, spaces.Box(low, high, dtype=np.float32), compute)


@kernel
def _still_world_ranges(previous, x0, y0, t0, x1, y1, t1, mount, a0, step, wrap, range_max, out) -> None:
    """Fill ``out`` with what each beam would read now if nothing had moved since the last scan
    (``previous``, taken with the robot at odometry pose (x0, y0, t0); it is now at (x1, y1, t1)):
    the last scan's returns carried into the present sensor frame, each read by the beam nearest
    its bearing and, where two neighbouring returns lie on one surface, interpolated between them
    for the beams in between; a miss stays a miss. NaN where the last scan says nothing. ``a0``
    and ``step``: the first beam's angle and the spacing (sensor frame); ``wrap``: a full circle."""
    n = previous.shape[0]
    out[:] = np.nan
    if n < 2:
        return
    myaw = mount[2]
    sx0, sy0 = sensor_origin(x0, y0, t0, mount[0], mount[1])
    sx1, sy1 = sensor_origin(x1, y1, t1, mount[0], mount[1])
    bearing, reach = np.empty(n), np.empty(n)
    for k in range(n):
        if previous[k] >= range_max:  # a miss says "nothing within range" along its own beam
            reach[k], bearing[k] = range_max, k * step
        else:
            angle = t0 + myaw + a0 + k * step
            dx = sx0 + previous[k] * math.cos(angle) - sx1
            dy = sy0 + previous[k] * math.sin(angle) - sy1
            reach[k] = math.hypot(dx, dy)
            bearing[k] = (math.atan2(dy, dx) - t1 - myaw - a0) % _TWO_PI  # from the first beam
        m = int(round(bearing[k] / step))
        m = m % n if wrap else m
        if 0 <= m < n and not reach[k] >= out[m]:
            out[m] = reach[k]
    for k in range(n if wrap else n - 1):
        j = (k + 1) % n
        if previous[k] >= range_max or previous[j] >= range_max or abs(previous[k] - previous[j]) > _ONE_SURFACE:
            continue
        span = (bearing[j] - bearing[k]) % _TWO_PI
        if span <= 0.0 or span > 3.0 * step:
            continue
        for m in range(int(math.ceil(bearing[k] / step)), int(math.floor((bearing[k] + span) / step)) + 1):
            beam = m % n if wrap else m
            if 0 <= beam < n:
                expected = reach[k] + (m * step - bearing[k]) / span * (reach[j] - reach[k])
                if not expected >= out[beam]:
                    out[beam] = expected


@kernel
def _range_rates(out, first, ranges, expected, bounds, elapsed, scale) -> None:
    """Write each sector's range rate (see the module) into ``out[first:]``: its nearest return
    now against its nearest if nothing had moved (``expected``, NaN-free beams only); 0 where
    there is no such expectation or no time has passed (an episode's first observation)."""
    for k in range(bounds.shape[0]):
        nearest, still = np.inf, np.inf
        for i in range(bounds[k, 0], bounds[k, 1]):
            nearest = min(nearest, ranges[i])
            if not math.isnan(expected[i]):
                still = min(still, expected[i])
        rate = 0.0 if elapsed <= 0.0 or still == np.inf else (nearest - still) / elapsed / scale
        out[first + k] = min(max(rate, -1.0), 1.0)


ROBOT_SCALES = (0.5, 1.0, 1.0, 2.0, 3.0, 1.0)  # lidar49_robot's divisors of the robot's entries
CLEARANCE_FLOOR = 0.05  # m: lidar49_robot's d0


def robot_entries(robot: RobotProfile) -> np.ndarray:
    """``lidar49_robot``'s last six entries: the robot's size, limits and shape, scaled into [0, 1]."""
    values = (robot.bounding_radius, robot.width_across, robot.length_along, robot.v_max, robot.w_max,
              float(robot.shape == "box"))
    return np.clip(np.array(values) / ROBOT_SCALES, 0.0, 1.0).astype(np.float32)


def _robot_layout(robot: RobotProfile, lidar: LidarSpec, goal_distance_scale: float) -> ObservationLayout:
    """``lidar49_robot``: goal and motion as ``lidar43_log``, the sectors' clearance from the
    footprint, and the robot's own entries (see the module)."""
    # _encode's log scale reads log(max(r, floor) / floor): given clearance + d0 and floor d0, that is log(c / d0 + 1).
    sectors = _sector_layout("lidar49_robot", robot, lidar, goal_distance_scale, 0.0, CLEARANCE_FLOOR,
                             1.0 / math.log(lidar.range_max / CLEARANCE_FLOOR + 1.0),
                             shift=CLEARANCE_FLOOR - footprint_reach(robot, lidar))
    low = np.concatenate([sectors.space.low, np.zeros(len(ROBOT_SCALES), dtype=np.float32)])
    high = np.ones(len(low), dtype=np.float32)
    own = robot_entries(robot)

    def compute(readings: Readings, goal: tuple[float, float]) -> np.ndarray:
        out = np.empty(len(low), dtype=np.float32)
        out[:43] = sectors(readings, goal)
        out[43:] = own
        return out

    return ObservationLayout("lidar49_robot", spaces.Box(low, high, dtype=np.float32), compute)


def _motion_layout(robot: RobotProfile, lidar: LidarSpec, goal_distance_scale: float) -> ObservationLayout:
    """``lidar79_motion``: ``lidar43_log`` and the sectors' range rates (see the module)."""
    scan = make_layout("lidar43_log", robot, lidar, goal_distance_scale)
    low = np.concatenate([scan.space.low, -np.ones(LIDAR43_BEAMS, dtype=np.float32)])
    high = np.ones(43 + LIDAR43_BEAMS, dtype=np.float32)
    bounds = sector_bounds(lidar.beams, LIDAR43_BEAMS)
    a0, step = float(lidar.beam_angles()[0]), lidar.beam_spacing
    mount = np.asarray(lidar.offset, dtype=float)
    previous, expected = np.zeros(lidar.beams), np.full(lidar.beams, np.nan)
    last: list = [None]  # the last observation's time and odometry pose; None: a new episode

    def compute(readings: Readings, goal: tuple[float, float]) -> np.ndarray:
        out = np.empty(43 + LIDAR43_BEAMS, dtype=np.float32)
        out[:43] = scan(readings, goal)
        pose = readings.odometry.pose
        elapsed = 0.0
        if last[0] is not None:
            time, (x0, y0, t0) = last[0]
            elapsed = readings.time - time
            _still_world_ranges(previous, x0, y0, t0, *pose, mount, a0, step, lidar.full_circle, lidar.range_max,
                                expected)
        _range_rates(out, 43, readings.lidar, expected, bounds, elapsed, RANGE_RATE_SCALE)
        previous[:] = readings.lidar
        last[0] = (readings.time, tuple(pose))
        return out

    def forget() -> None:
        last[0] = None

    return ObservationLayout("lidar79_motion", spaces.Box(low, high, dtype=np.float32), compute, forget)


def _route_layout(robot: RobotProfile, lidar: LidarSpec, goal_distance_scale: float) -> ObservationLayout:
    """``lidar51_route``: ``lidar49_robot`` and the route point ahead (see the module)."""
    base = _robot_layout(robot, lidar, goal_distance_scale)
    low = np.concatenate([base.space.low, -np.ones(2, dtype=np.float32)])
    high = np.ones(len(low), dtype=np.float32)
    n = len(base.space.low)
    route: list[Route | None] = [None]

    def compute(readings: Readings, goal: tuple[float, float]) -> np.ndarray:
        out = np.empty(len(low), dtype=np.float32)
        out[:n] = base(readings, goal)
        x, y, yaw = readings.odometry.pose
        ahead_x, ahead_y = goal if route[0] is None else route[0].ahead(x, y, ROUTE_LOOKAHEAD)
        dx, dy, c, s = ahead_x - x, ahead_y - y, math.cos(yaw), math.sin(yaw)
        out[n] = min(max((c * dx + s * dy) / ROUTE_LOOKAHEAD, -1.0), 1.0)
        out[n + 1] = min(max((c * dy - s * dx) / ROUTE_LOOKAHEAD, -1.0), 1.0)
        return out

    def forget() -> None:
        route[0] = None

    def take_route(given: Route) -> None:
        route[0] = given

    return ObservationLayout("lidar51_route", spaces.Box(low, high, dtype=np.float32), compute, forget, take_route)
