"""ORCA (common/motion/orca.py): RVO2's velocities bit for bit, and collision-free on its own.

The comparison drives pyrvo (RVO2's Python bindings) the way IR-SIM's ``orca`` group behaviour
does: every step each agent's preferred velocity (its speed toward its goal) and position are
set, ``do_step`` runs, and the new velocities are read back; positions advance outside, in
float64, by velocity * dt. The kernel gets the same float32 inputs, its previous outputs as the
current velocities, and must return the same float32 velocities at every step.

Start positions are random (or jittered) so no agent has two neighbours at exactly the same
distance: there RVO2's k-d tree and the kernel's loop may order them differently (the module's
docstring), and symmetric layouts (a perfect ring, a grid) do diverge.
"""

from __future__ import annotations

import numpy as np
import pytest

from common.motion.orca import orca_velocities, orca_velocities_counted
from tests.conftest import optional

DT = 0.1
STEPS = 300


class Crowd:
    """Agents' parameters (float32, as both sides hold them) and float64 starts and goals."""

    def __init__(self, starts, goals, radii, max_speeds, neighbor_dists, max_neighbors, time_horizons,
                 pref_factor=None):
        n = len(starts)
        self.starts, self.goals = np.asarray(starts, float), np.asarray(goals, float)
        full = lambda v: np.broadcast_to(np.asarray(v, np.float32), (n,)).copy()  # noqa: E731
        self.radii, self.max_speeds = full(radii), full(max_speeds)
        self.neighbor_dists, self.time_horizons = full(neighbor_dists), full(time_horizons)
        self.max_neighbors = np.broadcast_to(np.asarray(max_neighbors, np.int64), (n,)).copy()
        # Preferred speed over the maximum speed: above 1 the linear program must clip it.
        self.pref_speeds = self.max_speeds.astype(float) * (1.0 if pref_factor is None else np.asarray(pref_factor))

    def preferred(self, positions: np.ndarray) -> np.ndarray:
        """Toward the goal at the preferred speed, zero at the goal (IR-SIM's ``_pref_velocity``)."""
        delta = self.goals - positions
        norm = np.hypot(delta[:, 0], delta[:, 1])
        safe = np.where(norm < 1e-9, 1.0, norm)
        return np.where((norm < 1e-9)[:, None], 0.0, self.pref_speeds[:, None] * delta / safe[:, None])


def random_crowd(seed: int, n: int, spread: float = 1.5, pref_factor: float = 1.3) -> Crowd:
    rng = np.random.default_rng(seed)
    half = spread * np.sqrt(n)  # dense: radii up to 1.2 in about 9 m² per agent
    starts = rng.uniform(-half, half, (n, 2))
    goals = -starts + rng.normal(0.0, 0.5, (n, 2))  # through the centre: everyone meets there
    factor = np.where(rng.random(n) < 0.3, pref_factor, 1.0)
    return Crowd(starts, goals, rng.uniform(0.2, 1.2, n), rng.uniform(0.5, 3.0, n), rng.uniform(2.0, 15.0, n),
                 rng.integers(0, 11, n), rng.uniform(1.0, 20.0, n), factor)


def head_on_columns(seed: int) -> Crowd:
    """Two columns of five walking into each other along x, nearly in line."""
    rng = np.random.default_rng(seed)
    left = np.c_[np.full(5, -8.0), np.arange(5) * 1.5] + rng.normal(0.0, 0.01, (5, 2))
    right = np.c_[np.full(5, 8.0), np.arange(5) * 1.5] + rng.normal(0.0, 0.01, (5, 2))
    starts = np.vstack([left, right])
    goals = np.vstack([right, left])
    return Crowd(starts, goals, 0.5, 1.5, 10.0, 10, 5.0)


def overlapping(seed: int) -> Crowd:
    """Twelve agents started inside each other, all heading through one point."""
    rng = np.random.default_rng(seed)
    starts = rng.normal(0.0, 0.6, (12, 2))
    angles = rng.uniform(0, 2 * np.pi, 12)
    return Crowd(starts, 6.0 * np.c_[np.cos(angles), np.sin(angles)], rng.uniform(0.3, 0.8, 12),
                 rng.uniform(0.5, 2.0, 12), 5.0, 6, 2.0, rng.uniform(1.0, 2.0, 12))


SCENARIOS = {
    "head-on pair": lambda: Crowd([[-5.0, 0.0], [5.0, 0.0]], [[5.0, 0.0], [-5.0, 0.0]], 0.5, 1.0, 10.0, 5, 5.0),
    "head-on columns": lambda: head_on_columns(1),
    "overlapping": lambda: overlapping(2),
    "crowd of 5": lambda: random_crowd(3, 5, spread=1.0),
    "crowd of 12": lambda: random_crowd(4, 12),
    "crowd of 30": lambda: random_crowd(5, 30),
    "crowd of 60": lambda: random_crowd(6, 60),
    "sparse crowd of 60": lambda: random_crowd(7, 60, spread=4.0, pref_factor=2.0),
}


def drive_both(crowd: Crowd, steps: int = STEPS) -> dict:
    """Run pyrvo and the kernel side by side, asserting equal velocities every step; what was exercised."""
    pyrvo = optional("pyrvo")
    n = len(crowd.starts)
    sim = pyrvo.RVOSimulator()
    sim.set_time_step(DT)
    for i in range(n):
        sim.add_agent(crowd.starts[i].tolist(), float(crowd.neighbor_dists[i]), int(crowd.max_neighbors[i]),
                      float(crowd.time_horizons[i]), float(crowd.time_horizons[i]), float(crowd.radii[i]),
                      float(crowd.max_speeds[i]))
    positions = crowd.starts.copy()
    velocities = np.zeros((n, 2), np.float32)  # RVO2's agents start at rest
    out, counted = np.empty((n, 2), np.float32), np.empty((n, 2), np.float32)
    seen = {"fallbacks": 0, "overlaps": 0, "over_max": 0}
    for step in range(steps):
        preferred = crowd.preferred(positions)
        for i in range(n):
            sim.set_agent_pref_velocity(i, preferred[i].tolist())
            sim.set_agent_position(i, positions[i].tolist())
        sim.do_step()
        expected = np.array([sim.get_agent_velocity(i).to_tuple() for i in range(n)], np.float32)

        args = (positions.astype(np.float32), velocities, preferred.astype(np.float32), crowd.radii, crowd.max_speeds,
                crowd.neighbor_dists, crowd.max_neighbors, crowd.time_horizons, np.float32(DT))
        orca_velocities(*args, out)
        assert np.array_equal(out, expected), (
            f"step {step}: agents {np.unique(np.argwhere(out != expected)[:, 0])} differ, "
            f"largest by {np.abs(out - expected).max()}")
        seen["fallbacks"] += orca_velocities_counted(*args, counted)
        assert np.array_equal(counted, out)

        # The collision branch ran if an agent overlaps its nearest other agent, which it holds as a neighbour.
        pos32 = args[0]
        dist_sq = ((pos32[:, None, :] - pos32[None, :, :]) ** 2).sum(-1)
        np.fill_diagonal(dist_sq, np.inf)
        nearest = dist_sq.argmin(1)
        near = dist_sq[np.arange(n), nearest]
        seen["overlaps"] += int(np.sum((near <= (crowd.radii + crowd.radii[nearest]) ** 2)
                                       & (near < crowd.neighbor_dists ** 2) & (crowd.max_neighbors > 0)))
        pref_speed = np.hypot(*preferred.astype(np.float32).T)
        seen["over_max"] += int(np.sum(pref_speed > crowd.max_speeds))

        velocities = out.copy()
        positions = positions + velocities.astype(np.float64) * DT
    return seen


@pytest.mark.parametrize("name", SCENARIOS)
def test_velocities_are_rvo2s_bit_for_bit(name):
    seen = drive_both(SCENARIOS[name]())
    if name == "overlapping":
        assert seen["overlaps"] > 0, "no agent overlapped a neighbour: the collision branch did not run"
    if name.startswith("crowd of 60"):
        assert seen["fallbacks"] > 0, "linearProgram3 never ran"
    if name == "sparse crowd of 60":
        assert seen["over_max"] > 0, "no preferred velocity above the maximum speed"


def _step(positions, velocities, preferred, radii, max_speeds, neighbor_dists=10.0, max_neighbors=10,
          time_horizons=5.0):
    n = len(positions)
    full = lambda v, dtype=np.float32: np.full(n, v, dtype)  # noqa: E731
    out = np.empty((n, 2), np.float32)
    orca_velocities(positions.astype(np.float32), velocities.astype(np.float32), preferred.astype(np.float32),
                    full(radii), full(max_speeds), full(neighbor_dists), full(max_neighbors, np.int64),
                    full(time_horizons), np.float32(DT), out)
    return out


def test_two_agents_head_on_never_touch():
    positions = np.array([[-5.0, 0.0], [5.0, 0.0]])
    goals = positions[::-1].copy()
    velocities = np.zeros((2, 2), np.float32)
    closest = np.inf
    for _ in range(100):
        delta = goals - positions
        preferred = delta / np.maximum(np.hypot(*delta.T), 1e-9)[:, None]
        velocities = _step(positions, velocities, preferred, radii=0.5, max_speeds=1.0)
        positions = positions + velocities.astype(np.float64) * DT
        closest = min(closest, float(np.hypot(*(positions[0] - positions[1]))))
    assert closest > 1.0  # the sum of the radii
    assert positions[0, 0] > 4.0 and positions[1, 0] < -4.0, "they passed each other"


def test_a_lone_agent_takes_its_preferred_velocity_clipped_to_its_max_speed():
    positions, velocities = np.zeros((1, 2)), np.zeros((1, 2))
    slow = _step(positions, velocities, np.array([[0.3, -0.4]]), radii=0.5, max_speeds=1.0)
    assert np.array_equal(slow, np.array([[0.3, -0.4]], np.float32))
    fast = _step(positions, velocities, np.array([[3.0, 4.0]]), radii=0.5, max_speeds=2.0)
    np.testing.assert_allclose(fast, [[1.2, 1.6]], rtol=1e-6)
    # Far apart (beyond the neighbour distance) two agents ignore each other.
    pair = _step(np.array([[0.0, 0.0], [20.0, 0.0]]), np.zeros((2, 2)), np.array([[1.0, 0.0], [-1.0, 0.0]]),
                 radii=0.5, max_speeds=2.0)
    assert np.array_equal(pair, np.array([[1.0, 0.0], [-1.0, 0.0]], np.float32))


def test_inputs_are_left_unchanged_and_every_agent_sees_the_same_snapshot():
    rng = np.random.default_rng(0)
    n = 20
    arrays = [rng.uniform(-5, 5, (n, 2)).astype(np.float32), rng.uniform(-1, 1, (n, 2)).astype(np.float32),
              rng.uniform(-2, 2, (n, 2)).astype(np.float32), np.full(n, 0.4, np.float32), np.full(n, 1.5, np.float32),
              np.full(n, 6.0, np.float32), np.full(n, 8, np.int64), np.full(n, 3.0, np.float32)]
    copies = [a.copy() for a in arrays]
    out = np.empty((n, 2), np.float32)
    orca_velocities(*arrays, np.float32(DT), out)
    assert all(np.array_equal(a, c) for a, c in zip(arrays, copies))
    # Agent order does not matter: reversing the agents reverses the result (no agent saw a new velocity).
    reversed_out = np.empty_like(out)
    orca_velocities(*[a[::-1].copy() for a in arrays], np.float32(DT), reversed_out)
    assert np.array_equal(reversed_out[::-1], out)
