"""Moving obstacles from the lidar alone: blobs of a scan, tracked from scan to scan.

Each step the returns are put in the world frame by the odometry pose and split into blobs: runs
of consecutive beams whose returns lie within a gap of each other (``gap`` plus the beams'
spacing at that range). A blob no wider than ``max_radius`` is a candidate mover, summarised by a
disc (the mean of its returns and the farthest return from it, at least ``min_radius``: a blob
narrower than that is a body's near side, so its centre is pushed back along the line of sight);
a wider blob (a wall, a shelf) is static. Candidates are matched to the tracks of the previous
step (an optimal assignment of nearest neighbours within ``gate`` of each track's prediction),
each track's position and velocity follow a constant-velocity alpha-beta filter, and a track
unseen for ``max_misses`` steps is dropped.

A blob that moves is not necessarily a mover. The beams turn with the robot, so as it drives or
turns, the point where a beam meets a wall slides along the wall: a wall fragment (seen through
a gap, or at a grazing angle, where the hits lie further apart than the gap) moves at up to the
robot's speed, or range times turn rate. So a track counts as moving only with evidence that no
static world gives: a return where the beams of an earlier scan (``lag`` seconds back) on either
side of it went through and saw further. Where those two beams met one surface, the free range
is the chord between their returns, so a point sliding along a wall, which lies on that chord,
is no evidence, however far apart the returns; elsewhere it is the nearer of the two returns.
A person who stepped forward or sideways stands where the earlier beams saw free space. Only a
body narrower than the beams' spacing could have hidden between them, so the evidence is taken
where the spacing is below ``min_width``, or anywhere for a blob already in sight, without a
break, when the earlier scan was taken (it would have blocked one of its beams). A track with
no evidence within ``hold`` seconds, or slower than ``min_speed``, reports no velocity: its
returns are static obstacles.

Limits: one scan carries no velocity: the filter needs a few scans to converge and the evidence
``lag`` seconds of motion; a mover that is occluded is lost (a new track when it reappears); a
mover next to a wall merges into the wall's blob and counts as static, two movers close together
into one blob; a mover walking straight away stays in its own shadow, so it gives no evidence and
counts as static where it is; the centre is that of the visible side pushed back to
``min_radius``, not the body's. Velocities depend on the odometry: its drift over ``lag`` seconds
shows up as motion.
"""

from __future__ import annotations

import math
from collections import deque
from typing import NamedTuple

import numpy as np
from scipy.optimize import linear_sum_assignment

from common.controllers.base import LidarGeometry

_FAR = 1e6  # the cost of a pairing beyond the gate: never chosen over a feasible one


class Scene(NamedTuple):
    """What a scan shows: returns taken as standing still, and movers as discs with a velocity."""

    static: np.ndarray  # (N, 2) world points
    centres: np.ndarray  # (K, 2)
    velocities: np.ndarray  # (K, 2) m/s
    radii: np.ndarray  # (K,)

    def centres_at(self, times: np.ndarray) -> np.ndarray:
        """The movers' centres ``times`` seconds ahead at constant velocity: (T, K, 2)."""
        return self.centres[None] + np.asarray(times, float)[:, None, None] * self.velocities[None]


class _Scan(NamedTuple):
    """A scan kept as the reference for later evidence."""

    time: float
    origin: np.ndarray  # the sensor's world position
    yaw: float  # the robot's yaw
    ranges: np.ndarray
    points: np.ndarray  # (n, 2) world points of every beam, misses included
    links: np.ndarray  # (n,) whether beam i and beam i + 1 see one surface


def scan_links(points: np.ndarray, hit: np.ndarray, ranges: np.ndarray, spacing: float, gap: float,
               closed: bool) -> np.ndarray:
    """(n,) whether beams i and i + 1 (mod n when ``closed``) both hit and their returns lie within
    ``gap`` plus the beam spacing at the nearer range of each other."""
    following = np.roll(np.arange(len(ranges)), -1)
    apart = np.hypot(*(points[following] - points).T)
    links = hit & hit[following] & (apart < gap + spacing * np.minimum(ranges, ranges[following]))
    if not closed:
        links[-1] = False
    return links


def blobs(links: np.ndarray, hit: np.ndarray) -> list[np.ndarray]:
    """Beam indices of each blob: the runs of linked hits (one may wrap round a closed scan)."""
    n = len(links)
    if links.all():
        return [np.arange(n)]
    first = (int(np.argmin(links)) + 1) % n  # a blob starts after the first break
    order = np.roll(np.arange(n), -first)
    starts = np.flatnonzero(np.r_[True, ~links[order[:-1]]])
    return [run for run in np.split(order, starts[1:]) if hit[run[0]]]


class _Tracks(NamedTuple):
    """The tracks, one row each."""

    position: np.ndarray  # (K, 2)
    velocity: np.ndarray  # (K, 2)
    radius: np.ndarray  # (K,)
    misses: np.ndarray  # (K,) steps since last seen
    hits: np.ndarray  # (K,) scans it was seen in
    since: np.ndarray  # (K,) when its current unbroken run of sightings began, s
    evidence: np.ndarray  # (K,) when it last gave evidence of motion, s

    @classmethod
    def fresh(cls, centres: np.ndarray, radii: np.ndarray, time: float) -> "_Tracks":
        n = len(centres)
        return cls(centres.reshape(-1, 2).copy(), np.zeros((n, 2)), radii.copy(), np.zeros(n, int), np.ones(n, int),
                   np.full(n, time), np.full(n, -math.inf))

    def take(self, rows: np.ndarray) -> "_Tracks":
        return _Tracks(*(field[rows] for field in self))

    def join(self, other: "_Tracks") -> "_Tracks":
        return _Tracks(*(np.concatenate([a, b]) for a, b in zip(self, other)))


class ScanTracker:
    """Blobs of each scan, tracked with velocities (see the module).

    Args:
        lidar: the beams' geometry.
        gap: metres between returns of one blob, beyond the beam spacing at that range (0.25).
        max_radius: wider blobs are static structure, m (0.6: a forklift seen end on fits).
        min_radius: a blob's smallest radius, m (0.2: a person's).
        gate: furthest a blob may lie from a track's prediction and still be it, m (0.5).
        alpha, beta: the filter's gains on position and velocity (0.5, 0.15).
        max_misses: steps a track may go unseen before it is dropped (3).
        max_speed: the fastest believed velocity, m/s (2.5); faster estimates are scaled down.
        lag: how old the reference scan for evidence is, s (0.5).
        hold: how long evidence of motion lasts, s (1.0).
        tolerance: how much nearer than the reference's free range a return must be, m (0.1), plus
            half the beam spacing at its range where the reference's chord may cut a corner.
        min_width: the narrowest body, m (0.45): where the reference's beams lie further apart than
            this, a body could have hidden between them, so no evidence is taken there from a
            track that was not already seen, without a break, when the reference was scanned.
        min_hits: scans a track needs before it may report a velocity (3).
        min_speed: a track slower than this is static, m/s (0.2): what is left of a static
            blob's jitter, not a person's walk.
    """

    def __init__(self, lidar: LidarGeometry, gap: float = 0.25, max_radius: float = 0.6, min_radius: float = 0.2,
                 gate: float = 0.5, alpha: float = 0.5, beta: float = 0.15, max_misses: int = 3,
                 max_speed: float = 2.5, lag: float = 0.5, hold: float = 1.0, tolerance: float = 0.1,
                 min_width: float = 0.45, min_hits: int = 3, min_speed: float = 0.2) -> None:
        self.lidar = lidar
        self.gap, self.max_radius, self.min_radius, self.gate = gap, max_radius, min_radius, gate
        self.alpha, self.beta, self.max_misses, self.max_speed = alpha, beta, max_misses, max_speed
        self.lag, self.hold, self.tolerance, self.min_width = lag, hold, tolerance, min_width
        self.min_hits, self.min_speed = min_hits, min_speed
        self.spacing = lidar.spec.beam_spacing
        self.reset()

    def reset(self) -> None:
        """Forget every track and scan."""
        self.tracks = _Tracks.fresh(np.zeros((0, 2)), np.zeros(0), 0.0)
        self.history: deque[_Scan] = deque()
        self.time: float | None = None

    def update(self, ranges: np.ndarray, pose: tuple[float, float, float], time: float) -> Scene:
        """Take one scan at ``pose`` (odometry) and ``time`` (s); the scene as tracked so far."""
        scan = self._scan(ranges, pose, time)
        hit = ranges < self.lidar.spec.range_max
        runs = blobs(scan.links, hit)
        discs = [self._disc(scan.points[run], scan.origin) for run in runs]
        candidates = [k for k, (_, radius) in enumerate(discs) if radius <= self.max_radius]
        centres = np.array([discs[k][0] for k in candidates]).reshape(-1, 2)
        radii = np.array([discs[k][1] for k in candidates])
        dt = 0.0 if self.time is None else time - self.time
        self.time = time
        rows = self._associate(centres, radii, dt, time)
        reference = self._reference(time)
        tracks = self.tracks
        if reference is not None:
            for k, row in zip(candidates, rows):
                seen_then = time - tracks.since[row] >= self.lag
                if self._seen_through(scan.points[runs[k]], reference, seen_then).any():
                    tracks.evidence[row] = time
        self.history.append(scan)
        moving = np.zeros(len(tracks.position), bool)
        moving[rows] = ((tracks.hits[rows] >= self.min_hits) & (time - tracks.evidence[rows] <= self.hold)
                        & (np.hypot(*tracks.velocity[rows].T) >= self.min_speed))
        still = hit.copy()
        for k, row in zip(candidates, rows):
            still[runs[k]] = not moving[row]
        movers = tracks.take(moving)
        return Scene(scan.points[still], movers.position, movers.velocity, movers.radius)

    def _scan(self, ranges: np.ndarray, pose: tuple[float, float, float], time: float) -> _Scan:
        x, y, yaw = pose
        c, s = math.cos(yaw), math.sin(yaw)
        mx, my, _ = self.lidar.spec.offset
        origin = np.array([x + c * mx - s * my, y + s * mx + c * my])
        angles = yaw + self.lidar.relative_angles
        points = origin + ranges[:, None] * np.column_stack([np.cos(angles), np.sin(angles)])
        hit = ranges < self.lidar.spec.range_max
        links = scan_links(points, hit, ranges, self.spacing, self.gap, self.lidar.spec.full_circle)
        return _Scan(time, origin, yaw, np.asarray(ranges, float), points, links)

    def _disc(self, points: np.ndarray, origin: np.ndarray) -> tuple[np.ndarray, float]:
        """A blob's centre and radius: its returns' mean and the farthest return from it; narrower
        than ``min_radius``, its centre goes back along the line of sight (the blob is a body's near side)."""
        centre = points.mean(axis=0)
        radius = float(np.hypot(*(points - centre).T).max())
        if radius < self.min_radius:
            sight = centre - origin
            centre = centre + (self.min_radius - radius) * sight / max(float(np.hypot(*sight)), 1e-9)
            radius = self.min_radius
        return centre, radius

    def _associate(self, centres: np.ndarray, radii: np.ndarray, dt: float, time: float) -> list[int]:
        """Match the candidates to predicted tracks, filter, start and drop tracks; each candidate's track row."""
        t = self.tracks
        t.position[:] += dt * t.velocity
        rows = [-1] * len(centres)
        if len(t.position) and len(centres):
            cost = np.hypot(*(t.position[:, None] - centres[None]).transpose(2, 0, 1))
            pairs = zip(*linear_sum_assignment(np.where(cost <= self.gate, cost, _FAR)))
            for row, k in ((r, k) for r, k in pairs if cost[r, k] <= self.gate):
                residual = centres[k] - t.position[row]
                t.position[row] += self.alpha * residual
                if dt > 0.0:
                    t.velocity[row] += self.beta * residual / dt
                speed = float(np.hypot(*t.velocity[row]))
                if speed > self.max_speed:  # a wrong pairing, most likely: believe no more than this
                    t.velocity[row] *= self.max_speed / speed
                if t.misses[row] > 0:  # seen again after a break
                    t.since[row] = time
                t.radius[row], t.misses[row] = radii[k], -1
                t.hits[row] += 1
                rows[k] = row
        t.misses[:] += 1  # matched rows back to 0
        keep = np.flatnonzero(t.misses <= self.max_misses)
        renumber = {int(old): i for i, old in enumerate(keep)}
        rows = [renumber.get(row, -1) for row in rows]
        new = [k for k, row in enumerate(rows) if row < 0]
        self.tracks = t.take(keep).join(_Tracks.fresh(centres[new], radii[new], time))
        for i, k in enumerate(new):
            rows[k] = len(keep) + i
        return rows

    def _reference(self, time: float) -> _Scan | None:
        """The newest kept scan at least ``lag`` old (or the oldest, early on); older ones are dropped."""
        while len(self.history) > 1 and time - self.history[1].time >= self.lag:
            self.history.popleft()
        return self.history[0] if self.history else None

    def _seen_through(self, points: np.ndarray, reference: _Scan, seen_then: bool) -> np.ndarray:
        """Which ``points`` lie where the beams of ``reference`` on either side went through and saw
        further (``seen_then``: their blob was in sight when ``reference`` was scanned)."""
        spec, n = self.lidar.spec, len(reference.ranges)
        sight = points - reference.origin
        distance = np.hypot(*sight.T)
        first_angle = reference.yaw + self.lidar.relative_angles[0]
        position = ((np.arctan2(sight[:, 1], sight[:, 0]) - first_angle) % (2.0 * math.pi)) / self.spacing
        low = np.floor(position).astype(int)
        inside = low < (n if spec.full_circle else n - 1)  # between two beams of the field of view
        low = np.minimum(low, n - 1)
        high = (low + 1) % n
        ranges = reference.ranges
        linked = reference.links[low] & inside
        # Along one surface: where the ray crosses the chord between the two returns (a wall's
        # point lies on it, however far apart the returns).
        a, b = reference.points[low], reference.points[high]
        direction = sight / np.maximum(distance, 1e-9)[:, None]
        edge = b - a
        denominator = direction[:, 0] * edge[:, 1] - direction[:, 1] * edge[:, 0]
        offset = a - reference.origin
        crossing = (offset[:, 0] * edge[:, 1] - offset[:, 1] * edge[:, 0]) / np.where(denominator == 0.0, 1.0, denominator)
        nearer = np.minimum(ranges[low], ranges[high])
        free = np.where(linked & (denominator != 0.0), crossing, nearer)
        # A chord may cut off a convex corner by up to about half the beams' spacing there.
        slack = self.tolerance + np.where(linked, 0.5 * self.spacing * distance, 0.0)
        # Only where the beams lie closer together than any body is wide could nothing have hidden
        # between them; a body in sight then could not hide there either (it would have blocked a beam).
        narrow = seen_then | (distance * self.spacing < self.min_width)
        return inside & narrow & (distance < free - slack)
