"""One step of the movers, in IR-SIM's order and arithmetic, compiled.

A step is: the groups plan from one snapshot (:func:`plan_groups`); each mover in object order
starts its step (:func:`prepare`: a stopped mover halts, an arrived one takes its next goal; a
wanderer's was drawn before the step, by :func:`draw_wanderers`), finds its command (its group's
plan, ``dash``, or the social force among the others where they are now; ``rvo`` is the caller's,
in Python) and moves (:func:`move`); then every mover is judged (:func:`settle`): arrival, which
pops its goal queue, and contact, which stops it where the collision mode says.
:func:`finish_step` is the one compiled call a step makes after the robot's own move, the next
step's plans included (a call costs microseconds; a crowd's step, tens of them). The other
functions are plain Python where called from Python (``register_jitable``, most of them
``uncounted``: compiled without reference counting, so they allocate nothing), so the slow path
and the compiled one compute the same bits.
"""

from __future__ import annotations

import math

import numpy as np
from numba.extending import register_jitable

from common.geometry import (
    beyond_segment_bounds, box_distance, boxes_separation, hypot_excess, point_in_polygon, segment_box_gap,
    segment_distance,
)
from common.irsim_geometry import centroid
from common.kernel_cache import kernel, uncounted
from common.kinematics import unicycle_euler
from common.motion.orca import orca_velocities
from common.motion.packing import view1, view2, view3
from common.motion.slide import slack, slide_out
from common.motion.sfm import (
    NEIGHBOR_THRESHOLD, SOCIAL, VMAX, desire, pair_force, social_force_velocity, velocity_under,
)
from common.motion.steering import (
    desired_omni_velocity, diff_dash, omni_dash, omni_to_world, world_to_diff, world_to_omni, wrap_to_pi,
)
from common.motion.table import (
    ACC0, ACC1, ANGLE_TOLERANCE, ARRIVED, BEHAVIOR, BOX, DIFF, DRIVEN, EXTEND, GOAL_THRESHOLD, GROUP, HEAD, KINEMATICS, LENGTH,
    LOOP, OBSTACLE, OBSTACLES, OR, ORCA, OROLE, OUTLINE, OVX, OVY, OX, OY, PLAN0, PLAN1, PLANNED, RADIUS, REACTS, ROBOT,
    ROBOTS, ROLE, ROUTE_LENGTH, ROW, SEEN_RADIUS, SFM, SHAPE, SLACK, SLIDES, START_X, START_Y, STOPPED, TAIL, TARGET, THETA,
    UNOBSTRUCTED, V0, V1, VMAX0, VMAX1, VMIN0, VMIN1, WANDER, WANDER_X0, WANDER_X1, WANDER_Y0, WANDER_Y1, WIDTH, X, Y,
)

STOP, UNOBSTRUCTED_ALL, UNOBSTRUCTED_OBSTACLES = range(3)  # collision modes, as WorldSpec names them
COLLISION_MODES = ("stop", "unobstructed", "unobstructed_obstacles")
LANE_MARGIN = 0.1  # m: a yielding mover's lane reaches this far beyond its sides and the robot's


@uncounted
def velocity_range(F: np.ndarray, m: int, dt: float) -> tuple[float, float, float, float]:
    """The command window (low 0, low 1, high 0, high 1): the limits, narrowed to what the
    acceleration reaches from the last command (IR-SIM's ``get_vel_range``)."""
    lo0, lo1, hi0, hi1 = F[m, VMIN0], F[m, VMIN1], F[m, VMAX0], F[m, VMAX1]
    if math.isinf(F[m, ACC0]) and math.isinf(F[m, ACC1]):
        return lo0, lo1, hi0, hi1
    w0, w1 = F[m, ACC0] * dt, F[m, ACC1] * dt
    return max(lo0, F[m, V0] - w0), max(lo1, F[m, V1] - w1), min(hi0, F[m, V0] + w0), min(hi1, F[m, V1] + w1)


@uncounted
def world_velocity(kinematics: int, theta: float, c0: float, c1: float) -> tuple[float, float]:
    """A command's world-frame velocity (IR-SIM's ``velocity_xy``)."""
    if kinematics == DIFF:
        return c0 * math.cos(theta), c0 * math.sin(theta)
    return omni_to_world(theta, c0, c1)


@uncounted
def desired_velocity(F: np.ndarray, I: np.ndarray, goals: np.ndarray, m: int) -> tuple[float, float]:  # noqa: E741
    """Full speed toward the current goal, zero within 0.1 m of it (IR-SIM's ``desired_omni_vel``)."""
    speed_y = F[m, VMAX0] if I[m, KINEMATICS] == DIFF else F[m, VMAX1]
    return desired_omni_velocity(F[m, X], F[m, Y], goals[m, I[m, HEAD], 0], goals[m, I[m, HEAD], 1], F[m, VMAX0],
                                 speed_y, 0.1)


@uncounted
def sees(I: np.ndarray, objects: np.ndarray, m: int, row: int) -> bool:  # noqa: E741
    """Whether mover ``m``'s behaviour takes object ``row`` into account (not itself, not a line,
    the robot only if it reacts to it, and only the roles it targets)."""
    if row == I[m, ROW] or objects[row, OR] < 0.0:
        return False
    if row == 0 and I[m, REACTS] == 0:
        return False
    target = I[m, TARGET]
    if target == ROBOTS:
        return objects[row, OROLE] == ROBOT
    if target == OBSTACLES:
        return objects[row, OROLE] == OBSTACLE
    return True


@uncounted
def gather(I: np.ndarray, objects: np.ndarray, m: int, out: np.ndarray) -> int:  # noqa: E741
    """Write the objects mover ``m`` reacts to into ``out`` as rows x, y, vx, vy, radius; their count."""
    count = 0
    for row in range(objects.shape[0]):
        if sees(I, objects, m, row):
            count = _add_neighbor(objects, row, out, count)
    return count


@uncounted
def to_command(F: np.ndarray, I: np.ndarray, m: int, vx: float, vy: float, w_max: float, dt: float,  # noqa: E741
               tolerance: float) -> tuple[float, float]:
    """A planned world-frame velocity as the mover's command."""
    if I[m, KINEMATICS] == DIFF:
        return world_to_diff(F[m, THETA], vx, vy, w_max, dt, tolerance, 0.02)
    return world_to_omni(F[m, THETA], vx, vy)


@uncounted
def _sfm(F, I, params, goals, objects, segments, m, neighbors, count, dt):  # noqa: E741
    """The social-force command of mover ``m`` among the first ``count`` rows of ``neighbors``."""
    row = I[m, ROW]
    desired_x, desired_y = desire(*desired_velocity(F, I, goals, m), params[m, VMAX], I[m, GROUP] >= 0)
    vx, vy = social_force_velocity(F[m, X], F[m, Y], objects[row, OVX], objects[row, OVY], F[m, SEEN_RADIUS] + EXTEND,
                                   desired_x, desired_y, neighbors, count,
                                   segments if I[m, TARGET] != ROBOTS else segments[:0], params[m], I[m, GROUP] >= 0)
    w_max = velocity_range(F, m, dt)[3]
    return to_command(F, I, m, vx, vy, w_max, dt, 0.02)


@register_jitable
def plan_groups(F, I, params, goals, objects, segments, orca_velocity, members, inside, dt, neighbors):  # noqa: E741
    """Every group's commands from one snapshot of the world, into PLAN0/PLAN1 (PLANNED set).
    ``members[g]``: group g's movers in order (-1 after the last); ``inside[g, row]``: whether
    object ``row`` belongs to group g."""
    for g in range(members.shape[0]):
        count = 0
        while count < members.shape[1] and members[g, count] >= 0:
            count += 1
        group = members[g, :count]
        if I[group[0], BEHAVIOR] == ORCA:
            _plan_orca(F, I, params, goals, objects, orca_velocity, group, inside[g], dt)
        else:
            _plan_sfm(F, I, params, goals, objects, segments, group, inside[g], dt, neighbors)
        for m in group:
            I[m, PLANNED] = 1


@register_jitable
def _plan_orca(F, I, params, goals, objects, orca_velocity, members, inside, dt):  # noqa: E741
    """ORCA among the group (RVO2, as IR-SIM runs it); a group that sees the robot without it being
    a member counts it as one more agent, moving as it moves (its own plan is dropped)."""
    k = members.shape[0]
    extra = 1 if I[members[0], REACTS] == 1 and not inside[0] else 0
    n = k + extra
    positions, preferred = np.empty((n, 2), dtype=np.float32), np.empty((n, 2), dtype=np.float32)
    velocities, out = np.empty((n, 2), dtype=np.float32), np.empty((n, 2), dtype=np.float32)
    radii, speeds = np.empty(n, dtype=np.float32), np.empty(n, dtype=np.float32)
    reach, horizons = np.empty(n, dtype=np.float32), np.empty(n, dtype=np.float32)
    limit = np.empty(n, dtype=np.int64)
    for j in range(k):
        m = members[j]
        p = params[m]
        speed = p[4]
        if I[m, KINEMATICS] == DIFF:
            gx, gy = goals[m, I[m, HEAD], 0], goals[m, I[m, HEAD], 1]
            bearing = wrap_to_pi(math.atan2(gy - F[m, Y], gx - F[m, X]))
            px, py = speed * math.cos(bearing), speed * math.sin(bearing)
        else:
            dx, dy = desired_velocity(F, I, goals, m)
            norm = math.hypot(dx, dy)
            px, py = (0.0, 0.0) if norm < 1e-9 else (speed * dx / norm, speed * dy / norm)
        positions[j, 0], positions[j, 1] = F[m, X], F[m, Y]
        preferred[j, 0], preferred[j, 1] = px, py
        velocities[j] = orca_velocity[m]
        radii[j] = F[m, SEEN_RADIUS] + p[3]
        speeds[j], reach[j], limit[j], horizons[j] = speed, p[0], int(p[1]), p[2]
    if extra:
        p = params[members[0]]
        positions[k, 0], positions[k, 1] = objects[0, OX], objects[0, OY]
        velocities[k, 0], velocities[k, 1] = objects[0, OVX], objects[0, OVY]
        preferred[k] = velocities[k]
        radii[k] = objects[0, OR] - EXTEND + p[3]
        speeds[k], reach[k], limit[k], horizons[k] = max(math.hypot(objects[0, OVX], objects[0, OVY]), 1e-3), p[0], 0, p[2]
    orca_velocities(positions, velocities, preferred, radii, speeds, reach, limit, horizons, np.float32(dt), out)
    for j in range(k):
        m = members[j]
        orca_velocity[m] = out[j]
        F[m, PLAN0], F[m, PLAN1] = to_command(F, I, m, np.float64(out[j, 0]), np.float64(out[j, 1]), F[m, VMAX1], dt, 0.1)


@uncounted
def _plan_sfm(F, I, params, goals, objects, segments, members, inside, dt, neighbors):  # noqa: E741
    """The social force among a group from one snapshot, as IR-SIM's batched model: each member
    among the others (in order), then the objects outside the group it sees. A pair of members
    with the same parameters pushes each other equally and oppositely (:func:`pair_force`), so
    each such pair is computed once: the crowd's step costs half. Row a of ``neighbors`` (scratch
    here) sums member a's pushes in member order, as the batched model sums them; row k + a holds
    member a's x, y, vx, vy, so that the pairs beyond every member's reach (most of a crowd's) are
    passed over reading two adjacent rows, by :func:`pair_force`'s own first test."""
    k = members.shape[0]
    reach = 0.0
    for a in range(k):
        row = I[members[a], ROW]
        neighbors[a, 0] = neighbors[a, 1] = 0.0
        neighbors[k + a, 0], neighbors[k + a, 1] = objects[row, OX], objects[row, OY]
        neighbors[k + a, 2], neighbors[k + a, 3] = objects[row, OVX], objects[row, OVY]
        reach = max(reach, params[members[a], NEIGHBOR_THRESHOLD])
    beyond = reach * reach * (1.0 + 1e-6)  # as pair_force's test, for the largest reach: beyond everyone's
    alike = True  # whether every member pushes with the same parameters (a crowd's usual case)
    for a in range(1, k):
        alike = alike and _same_social(params[members[0]], params[members[a]])
    for a in range(k):
        i = members[a]
        x, y, vx, vy = neighbors[k + a, 0], neighbors[k + a, 1], neighbors[k + a, 2], neighbors[k + a, 3]
        for c in range(a + 1, k):
            ox, oy = neighbors[k + c, 0], neighbors[k + c, 1]
            if (ox - x) * (ox - x) + (oy - y) * (oy - y) > beyond:
                continue
            j, ovx, ovy = members[c], neighbors[k + c, 2], neighbors[k + c, 3]
            fx, fy, counts = pair_force(x, y, vx, vy, ox, oy, ovx, ovy, params[i], False)
            if counts:
                neighbors[a, 0] += fx
                neighbors[a, 1] += fy
            if not (alike or _same_social(params[i], params[j])):
                fx, fy, counts = pair_force(ox, oy, ovx, ovy, x, y, vx, vy, params[j], False)
                fx, fy = -fx, -fy
            if counts:
                neighbors[c, 0] -= fx
                neighbors[c, 1] -= fy
    for a in range(k):
        m = members[a]
        row = I[m, ROW]
        x, y, vx, vy = objects[row, OX], objects[row, OY], objects[row, OVX], objects[row, OVY]
        fx, fy = neighbors[a, 0], neighbors[a, 1]
        for other in range(objects.shape[0]):
            if not inside[other] and sees(I, objects, m, other):
                gx, gy, counts = pair_force(x, y, vx, vy, objects[other, OX], objects[other, OY], objects[other, OVX],
                                            objects[other, OVY], params[m], False)
                if counts:
                    fx += gx
                    fy += gy
        desired_x, desired_y = _group_desire(F, I, goals, params, m)
        wx, wy = velocity_under(F[m, X], F[m, Y], vx, vy, F[m, SEEN_RADIUS] + EXTEND, desired_x, desired_y,
                                (fx, fy), segments if I[m, TARGET] != ROBOTS else segments[:0], params[m])
        F[m, PLAN0], F[m, PLAN1] = to_command(F, I, m, wx, wy, velocity_range(F, m, dt)[3], dt, 0.02)


@uncounted
def _group_desire(F, I, goals, params, m):  # noqa: E741
    """A group member's desired velocity: ``vmax`` toward its goal, none within 0.1 m of it. IR-SIM
    takes the cosine and sine of the bearing at the mover's speeds and rescales them to ``vmax``;
    where the two speeds are equal (a diff mover's always are) that is the unit vector to the goal to
    within rounding, which the batched model's figures carry anyway, at a fraction of the cost."""
    speed_y = F[m, VMAX0] if I[m, KINEMATICS] == DIFF else F[m, VMAX1]
    if F[m, VMAX0] != speed_y or speed_y <= 0.0:
        return desire(*desired_velocity(F, I, goals, m), params[m, VMAX], True)
    dx, dy = goals[m, I[m, HEAD], 0] - F[m, X], goals[m, I[m, HEAD], 1] - F[m, Y]
    distance = math.sqrt(dx * dx + dy * dy)
    if distance <= 0.1:
        return 0.0, 0.0
    return params[m, VMAX] * dx / distance, params[m, VMAX] * dy / distance


@uncounted
def _same_social(p: np.ndarray, q: np.ndarray) -> bool:
    for index in SOCIAL:
        if p[index] != q[index]:
            return False
    return True


@uncounted
def _add_neighbor(objects, row, neighbors, count) -> int:
    neighbors[count, 0], neighbors[count, 1] = objects[row, OX], objects[row, OY]
    neighbors[count, 2], neighbors[count, 3] = objects[row, OVX], objects[row, OVY]
    neighbors[count, 4] = objects[row, OR]
    return count + 1


@uncounted
def prepare(F, I, goals, routes, objects, m) -> bool:  # noqa: E741
    """Start mover ``m``'s step: a stopped mover halts (False); an arrived one takes its next goal
    (a loop starts over; a wanderer's was drawn before the step, by :func:`draw_wanderers`)."""
    if I[m, STOPPED] == 1:
        F[m, V0] = F[m, V1] = 0.0
        row = I[m, ROW]
        objects[row, OVX] = objects[row, OVY] = 0.0
        return False
    if I[m, LOOP] == 1 and I[m, ARRIVED] == 1:
        length = I[m, ROUTE_LENGTH]
        if length > 1:
            for k in range(length):
                goals[m, k, 0], goals[m, k, 1] = routes[m, k, 0], routes[m, k, 1]
        else:  # one goal: back and forth between it and the start
            goals[m, 0, 0], goals[m, 0, 1] = routes[m, 0, 0], routes[m, 0, 1]
            goals[m, 1, 0], goals[m, 1, 1] = F[m, START_X], F[m, START_Y]
            length = 2
        I[m, HEAD], I[m, TAIL], I[m, ARRIVED] = 0, length, 0
    return I[m, DRIVEN] == 0


def draw_wanderers(F: np.ndarray, I: np.ndarray, goals: np.ndarray, rng: np.random.Generator) -> None:  # noqa: E741
    """Give every wanderer that arrived last step (and is not halted) its next goal, in mover
    order: x, y and a heading IR-SIM draws and never uses, as IR-SIM's ``random_point_range``.
    The step draws nothing else, so drawing them all first keeps IR-SIM's order; and a Generator
    passed into a compiled step would cost more than the step."""
    for m in np.flatnonzero((I[:, WANDER] == 1) & (I[:, ARRIVED] == 1) & (I[:, STOPPED] == 0)):
        x = F[m, WANDER_X0] + (F[m, WANDER_X1] - F[m, WANDER_X0]) * rng.random()
        y = F[m, WANDER_Y0] + (F[m, WANDER_Y1] - F[m, WANDER_Y0]) * rng.random()
        rng.random()
        goals[m, 0, 0], goals[m, 0, 1] = x, y
        I[m, HEAD], I[m, TAIL], I[m, ARRIVED] = 0, 1, 0


@uncounted
def command(F, I, params, goals, objects, segments, m, dt, neighbors) -> tuple[float, float]:  # noqa: E741
    """Mover ``m``'s command this step, unless it uses ``rvo`` (the caller's)."""
    if I[m, PLANNED] == 1:
        return F[m, PLAN0], F[m, PLAN1]
    gx, gy = goals[m, I[m, HEAD], 0], goals[m, I[m, HEAD], 1]
    if I[m, BEHAVIOR] == SFM:
        return _sfm(F, I, params, goals, objects, segments, m, neighbors, gather(I, objects, m, neighbors), dt)
    lo0, lo1, hi0, hi1 = velocity_range(F, m, dt)
    if I[m, KINEMATICS] == DIFF:
        c0, c1 = diff_dash(F[m, X], F[m, Y], F[m, THETA], gx, gy, F[m, VMAX0], F[m, VMAX1], F[m, GOAL_THRESHOLD],
                           F[m, ANGLE_TOLERANCE], F[m, ACC1], dt)
    else:
        c0, c1 = omni_dash(F[m, X], F[m, Y], F[m, THETA], gx, gy, F[m, VMAX0], F[m, VMAX1], F[m, GOAL_THRESHOLD])
    if I[m, REACTS] == 1 and params[m, 0] > 0.0 and robot_ahead(F, I, objects, m, params[m, 0]):
        c0, c1 = 0.0, 0.0
    return min(max(c0, lo0), hi0), min(max(c1, lo1), hi1)


@uncounted
def robot_ahead(F: np.ndarray, I: np.ndarray, objects: np.ndarray, m: int, distance: float) -> bool:  # noqa: E741
    """Whether the robot's disc stands within ``distance`` ahead of mover ``m``'s front, in its lane
    (its width and the robot's, and ``LANE_MARGIN`` either side): a ``dash`` mover yields to it."""
    dx, dy = objects[0, OX] - F[m, X], objects[0, OY] - F[m, Y]
    c, s = math.cos(F[m, THETA]), math.sin(F[m, THETA])
    ahead, side = dx * c + dy * s, abs(dy * c - dx * s)
    box = I[m, SHAPE] == BOX
    front = 0.5 * F[m, LENGTH] if box else F[m, RADIUS]
    half = 0.5 * F[m, WIDTH] if box else F[m, RADIUS]
    radius = objects[0, OR]
    return ahead > 0.0 and ahead - front - radius < distance and side < half + radius + LANE_MARGIN


@uncounted
def place_disc(objects, outlines, irsim, row, outline, x, y, theta) -> None:
    """Put an object's disc where its body is: its centre, or in an IR-SIM world the GEOS centroid of
    its polygon (the first ``outline`` rows of ``outlines``) placed at (x, y, theta)."""
    if irsim:
        objects[row, OX], objects[row, OY] = centroid(outlines[:outline], x, y, theta)
    else:
        objects[row, OX], objects[row, OY] = x, y


@uncounted
def move(F, I, objects, outlines, irsim, m, c0, c1, dt, circles, boxes, walls) -> None:  # noqa: E741
    """Apply a command to mover ``m`` for one step (clipped to its window; IR-SIM's kinematics); a
    sliding mover is kept out of the static ``circles``, ``boxes`` and ``walls`` (:mod:`common.motion.slide`)."""
    lo0, lo1, hi0, hi1 = velocity_range(F, m, dt)
    c0, c1 = min(max(c0, lo0), hi0), min(max(c1, lo1), hi1)
    theta = F[m, THETA]
    if I[m, KINEMATICS] == DIFF:
        x, y, theta = unicycle_euler((F[m, X], F[m, Y], theta), c0, c1, dt)
    else:
        dx, dy = omni_to_world(theta, c0, c1)
        x, y = F[m, X] + dx * dt, F[m, Y] + dy * dt
    vx, vy = world_velocity(I[m, KINEMATICS], theta, c0, c1)
    if I[m, SLIDES] == 1:
        travel = abs(x - F[m, X]) + abs(y - F[m, Y])  # at least the distance moved
        if travel < F[m, SLACK]:  # nothing within reach yet: the slide would leave the step as it is
            F[m, SLACK] -= travel
        else:
            sx, sy = slide_out(x, y, F[m, RADIUS], F[m, X], F[m, Y], circles, boxes, walls)
            if sx != x or sy != y:  # others see the velocity it moved with, not the one it was commanded
                x, y, vx, vy = sx, sy, (sx - F[m, X]) / dt, (sy - F[m, Y]) / dt
            F[m, SLACK] = slack(x, y, F[m, RADIUS], circles, boxes, walls)
    F[m, X], F[m, Y], F[m, THETA], F[m, V0], F[m, V1] = x, y, theta, c0, c1
    row = I[m, ROW]
    place_disc(objects, outlines[m], irsim, row, I[m, OUTLINE], x, y, theta)
    objects[row, OVX], objects[row, OVY] = vx, vy


@uncounted
def advance(F, I, params, goals, routes, objects, segments, outlines, irsim, dt, neighbors,  # noqa: E741
            circles, boxes, walls) -> None:
    """Every mover's step in order (none of them uses ``rvo``; the wanderers have drawn)."""
    for m in range(F.shape[0]):
        if prepare(F, I, goals, routes, objects, m):
            c0, c1 = command(F, I, params, goals, objects, segments, m, dt, neighbors)
            move(F, I, objects, outlines, irsim, m, c0, c1, dt, circles, boxes, walls)


@uncounted
def _touches_static(shape, x, y, theta, r, length, width, circles, boxes, segments, rings, ring_index) -> bool:
    """Whether a body (a circle of radius r, or a box of length and width at heading theta) touches
    the static geometry (see :func:`common.motion.table.static_contacts`)."""
    box = shape == BOX
    c, s = (math.cos(theta), math.sin(theta)) if box else (1.0, 0.0)  # a circle's heading is never read
    hl, hw = 0.5 * length, 0.5 * width
    for k in range(circles.shape[0]):
        if box:
            if box_distance(circles[k, 0], circles[k, 1], x, y, length, width, c, s) <= circles[k, 2]:
                return True
        elif hypot_excess(x - circles[k, 0], y - circles[k, 1], r + circles[k, 2]) <= 0.0:
            return True
    for k in range(boxes.shape[0]):
        bx, by, bc, bs, bhl, bhw = boxes[k, 0], boxes[k, 1], boxes[k, 2], boxes[k, 3], boxes[k, 4], boxes[k, 5]
        if box:
            if boxes_separation(x, y, c, s, hl, hw, bx, by, bc, bs, bhl, bhw) <= 0.0:
                return True
        elif box_distance(x, y, bx, by, 2.0 * bhl, 2.0 * bhw, bc, bs) <= r:
            return True
    reach = r + 1e-9  # the body's bounding circle (a box's half diagonal), and a margin for rounding
    for k in range(segments.shape[0]):
        x1, y1, x2, y2 = segments[k, 0], segments[k, 1], segments[k, 2], segments[k, 3]
        # A crowd's people stand clear of most walls most steps.
        if beyond_segment_bounds(x, y, x1, y1, x2, y2, reach):
            continue
        gap = segment_box_gap(x1, y1, x2, y2, x, y, c, s, hl, hw) if box else segment_distance(x, y, x1, y1,
                                                                                                       x2, y2) - r
        if gap <= 0.0:
            return True
    for k in range(ring_index.shape[0]):
        first, count = ring_index[k, 0], ring_index[k, 1]
        if point_in_polygon(x, y, rings[first:first + count]):
            return True
    return False


@uncounted
def bodies_touch(shape_a, xa, ya, ta, ra, la, wa, shape_b, xb, yb, tb, rb, lb, wb) -> bool:
    """Whether two bodies (a circle of radius r, or a box of length l and width w at heading t) touch."""
    if shape_a == BOX and shape_b == BOX:
        ca, sa, cb, sb = math.cos(ta), math.sin(ta), math.cos(tb), math.sin(tb)
        return boxes_separation(xa, ya, ca, sa, 0.5 * la, 0.5 * wa, xb, yb, cb, sb, 0.5 * lb, 0.5 * wb) <= 0.0
    if shape_a == BOX:
        return box_distance(xb, yb, xa, ya, la, wa, math.cos(ta), math.sin(ta)) <= rb
    if shape_b == BOX:
        return box_distance(xa, ya, xb, yb, lb, wb, math.cos(tb), math.sin(tb)) <= ra
    return hypot_excess(xa - xb, ya - yb, ra + rb) <= 0.0


@uncounted
def _touch(F, I, a, b) -> bool:  # noqa: E741
    # Bodies further apart along an axis than their bounding circles reach cannot touch: the check
    # spares a crowd's step most of its pairs' exact tests (the margin covers their rounding).
    reach = F[a, RADIUS] + F[b, RADIUS] + 1e-9
    if abs(F[a, X] - F[b, X]) > reach or abs(F[a, Y] - F[b, Y]) > reach:
        return False
    return bodies_touch(I[a, SHAPE], F[a, X], F[a, Y], F[a, THETA], F[a, RADIUS], F[a, LENGTH], F[a, WIDTH],
                        I[b, SHAPE], F[b, X], F[b, Y], F[b, THETA], F[b, RADIUS], F[b, LENGTH], F[b, WIDTH])


@uncounted
def settle(F, I, goals, robot, mode, circles, boxes, segments, rings, ring_index) -> int:  # noqa: E741
    """Judge every mover after the step: arrival at its goal (the queue moves on, or it has
    arrived), contact with the static geometry, the robot (``robot``: shape, x, y, heading,
    radius, length, width) or another mover, and the collision mode's stop; the first mover the
    robot touches (-1: none). Clears the step's plans."""
    n = F.shape[0]
    touched = -1
    for m in range(n):
        I[m, PLANNED] = 0
        head = I[m, HEAD]
        if hypot_excess(F[m, X] - goals[m, head, 0], F[m, Y] - goals[m, head, 1], F[m, GOAL_THRESHOLD]) < 0.0:
            if I[m, TAIL] - head == 1:
                I[m, ARRIVED] = 1
            else:
                I[m, HEAD], I[m, ARRIVED] = head + 1, 0
        else:
            I[m, ARRIVED] = 0
    for m in range(n):
        if I[m, DRIVEN] == 1:
            continue
        hits_robot = I[m, UNOBSTRUCTED] == 0 and bodies_touch(
            int(robot[0]), robot[1], robot[2], robot[3], robot[4], robot[5], robot[6],
            I[m, SHAPE], F[m, X], F[m, Y], F[m, THETA], F[m, RADIUS], F[m, LENGTH], F[m, WIDTH])
        if hits_robot and touched < 0:
            touched = m
        stops = mode == STOP or (mode == UNOBSTRUCTED_OBSTACLES and I[m, ROLE] == ROBOT)
        if not stops:
            continue
        colliding = hits_robot or _touches_static(I[m, SHAPE], F[m, X], F[m, Y], F[m, THETA], F[m, RADIUS], F[m, LENGTH],
                                                  F[m, WIDTH], circles, boxes, segments, rings, ring_index)
        for other in range(n):
            if colliding:
                break
            if other != m and I[other, UNOBSTRUCTED] == 0 and I[other, DRIVEN] == 0:
                colliding = _touch(F, I, m, other)
        I[m, STOPPED] = int(colliding)
    return touched


@kernel
def snapshot(F, I, objects, moving, circles, boxes, states, circle_rows, box_rows) -> None:  # noqa: E741
    """Write the movers' states (rows as :class:`~common.motion.movers.MoverStates` has them) and
    what a lidar sees of them: circles (x, y, r) and boxes (x, y, cos, sin, half length, half
    width). ``moving``, ``circles`` and ``boxes``: the table rows of the movers, of those a lidar sees
    as circles, and as boxes."""
    for k in range(moving.shape[0]):
        m = moving[k]
        row = I[m, ROW]
        box = I[m, SHAPE] == BOX
        states[k, 0], states[k, 1], states[k, 2] = F[m, X], F[m, Y], F[m, THETA]
        states[k, 3], states[k, 4], states[k, 5] = objects[row, OVX], objects[row, OVY], F[m, RADIUS]
        states[k, 6], states[k, 7] = (F[m, LENGTH], F[m, WIDTH]) if box else (0.0, 0.0)
    for k in range(circles.shape[0]):
        m = circles[k]
        circle_rows[k, 0], circle_rows[k, 1], circle_rows[k, 2] = F[m, X], F[m, Y], F[m, RADIUS]
    for k in range(boxes.shape[0]):
        m = boxes[k]
        box_rows[k, 0], box_rows[k, 1] = F[m, X], F[m, Y]
        box_rows[k, 2], box_rows[k, 3] = math.cos(F[m, THETA]), math.sin(F[m, THETA])
        box_rows[k, 4], box_rows[k, 5] = 0.5 * F[m, LENGTH], 0.5 * F[m, WIDTH]


@uncounted
def sync_robot(F, I, objects, outline, irsim, robot, x, y, yaw, v, w, lateral, stopped) -> None:  # noqa: E741
    """Where the controlled robot is and the command it moves with (forward ``v``, turn rate
    ``w``, sideways ``lateral``): its disc (row 0 of ``objects``), its body for contacts
    (``robot``; its footprint's centre ``robot[7]`` ahead of the pose) and its own row if it has
    one (the first)."""
    place_disc(objects, outline, irsim, 0, outline.shape[0], x, y, yaw)
    c, s = math.cos(yaw), math.sin(yaw)
    objects[0, OVX], objects[0, OVY] = v * c - lateral * s, v * s + lateral * c
    robot[1], robot[2], robot[3] = x + robot[7] * c, y + robot[7] * s, yaw
    if F.shape[0] > 0 and I[0, DRIVEN] == 1:
        F[0, X], F[0, Y], F[0, THETA], F[0, V0], F[0, V1] = x, y, yaw, v, w
        I[0, STOPPED] = 1 if stopped else 0


@kernel
def plan_step(F, I, params, goals, objects, segments, orca_velocity, members, inside, dt, neighbors,  # noqa: E741
              outline, irsim, robot, x, y, yaw, v, w, stopped) -> None:
    """Before an episode's first step: where the robot is, then the groups' plans."""
    sync_robot(F, I, objects, outline, irsim, robot, x, y, yaw, v, w, 0.0, stopped)
    if members.shape[0] > 0:
        plan_groups(F, I, params, goals, objects, segments, orca_velocity, members, inside, dt, neighbors)


@kernel
def finish_step(F, I, params, goals, routes, objects, segments, outlines, irsim, dt, neighbors, outline,  # noqa: E741
                robot, x, y, yaw, v, w, lateral, stopped, advanced, mode, circles, boxes, walls, rings, ring_index, moving,
                seen_circles, seen_boxes, states, circle_rows, box_rows, orca_velocity, members,
                inside) -> tuple[int, bool]:
    """The step after the robot moved: where it is now, every mover's step (unless ``advanced``
    already, by the caller), the judgement (:func:`settle`), the movers' states and lidar rows
    (:func:`snapshot`), and the groups' plans for the next step (from where everything is now:
    the snapshot the next step would plan from, one compiled call a step saved). The first mover
    (table row) the robot touches, or -1; and whether a wanderer arrived (the next step draws its
    goal first)."""
    sync_robot(F, I, objects, outline, irsim, robot, x, y, yaw, v, w, lateral, stopped)
    if not advanced:
        advance(F, I, params, goals, routes, objects, segments, outlines, irsim, dt, neighbors, circles, boxes, walls)
    touched = settle(F, I, goals, robot, mode, circles, boxes, walls, rings, ring_index)
    snapshot(F, I, objects, moving, seen_circles, seen_boxes, states, circle_rows, box_rows)
    if members.shape[0] > 0:
        plan_groups(F, I, params, goals, objects, segments, orca_velocity, members, inside, dt, neighbors)
    wanders = False
    for m in range(F.shape[0]):
        wanders = wanders or (I[m, WANDER] == 1 and I[m, ARRIVED] == 1 and I[m, STOPPED] == 0)
    return touched, wanders


# Where each array sits in the two buffers :class:`~common.motion.movers.Movers` packs
# (:mod:`common.motion.packing`) and :func:`finish_packed` unpacks: one list of names for both.
(PACKED_F, PACKED_PARAMS, PACKED_GOALS, PACKED_ROUTES, PACKED_OBJECTS, PACKED_SEGMENTS, PACKED_OUTLINES,
 PACKED_NEIGHBORS, PACKED_OUTLINE, PACKED_ROBOT, PACKED_CIRCLES, PACKED_BOXES, PACKED_WALLS, PACKED_RINGS,
 PACKED_STATES, PACKED_CIRCLE_ROWS, PACKED_BOX_ROWS) = range(17)
PACKED_I, PACKED_RING_INDEX, PACKED_MOVING, PACKED_SEEN_CIRCLES, PACKED_SEEN_BOXES, PACKED_MEMBERS = range(6)


@kernel
def finish_packed(floats, float_layout, ints, int_layout, orca_velocity, inside, irsim, dt, advanced, mode,
                  x, y, yaw, v, w, lateral, stopped) -> tuple[int, bool]:
    """:func:`finish_step` with its float64 and int64 arrays packed (:mod:`common.motion.packing`)
    at the ``PACKED_*`` positions: one call hands over six arrays instead of twenty-five."""
    f, fl, i, il = floats, float_layout, ints, int_layout
    return finish_step(
        view2(f, fl, PACKED_F), view2(i, il, PACKED_I), view2(f, fl, PACKED_PARAMS), view3(f, fl, PACKED_GOALS),
        view3(f, fl, PACKED_ROUTES), view2(f, fl, PACKED_OBJECTS), view2(f, fl, PACKED_SEGMENTS),
        view3(f, fl, PACKED_OUTLINES), irsim, dt, view2(f, fl, PACKED_NEIGHBORS), view2(f, fl, PACKED_OUTLINE),
        view1(f, fl, PACKED_ROBOT), x, y, yaw, v, w, lateral, stopped, advanced, mode, view2(f, fl, PACKED_CIRCLES),
        view2(f, fl, PACKED_BOXES), view2(f, fl, PACKED_WALLS), view2(f, fl, PACKED_RINGS),
        view2(i, il, PACKED_RING_INDEX), view1(i, il, PACKED_MOVING), view1(i, il, PACKED_SEEN_CIRCLES),
        view1(i, il, PACKED_SEEN_BOXES), view2(f, fl, PACKED_STATES), view2(f, fl, PACKED_CIRCLE_ROWS),
        view2(f, fl, PACKED_BOX_ROWS), orca_velocity, view2(i, il, PACKED_MEMBERS), inside)
