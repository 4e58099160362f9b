"""A scenario's movers in the PyBullet warehouse, moved by the shared code of :mod:`common.motion`.

Each mover is a static body (mass 0) that :class:`MovingBodies` puts where
:class:`~common.motion.movers.Movers` says it is, once a control period, after the robot's
physics sub-steps: the order of flatland and IR-SIM (the robot moves, then the movers). Teleported
bodies rather than velocity-driven ones, because a driven body would be pushed by the robot and
slide on the floor, and its path would part from the 2D tier's; a moved static body follows the
shared code to the bit, and the robot still collides with it and the lidar and camera see it.
A mover that steps into the robot is found by Bullet's collision detection at the end of the period.
"""

from __future__ import annotations

import numpy as np
import pybullet as p

from common.motion.movers import Movers, MoverStates
from common.scenario import Scenario
from physics3d.warehouse import Warehouse


class MovingBodies:
    """The bodies of ``scenario``'s movers in ``client`` (built by the warehouse, tagged ``mover``)."""

    def __init__(self, scenario: Scenario, client: int, warehouse: Warehouse) -> None:
        self.client = client
        self.movers = Movers(scenario)
        by_obstacle = {tag.index: body for body, tag in warehouse.tags.items() if tag.kind == "mover"}
        table = self.movers.table
        rows = self.movers.rows
        self.bodies = [by_obstacle[int(table.obstacle_index[m])] for m in rows]
        self.heights = [0.5 * scenario.obstacles[int(table.obstacle_index[m])].height for m in rows]
        self.row_of = {body: k for k, body in enumerate(self.bodies)}  # a body's row in the states

    def reset(self, pose: tuple[float, float, float], rng: np.random.Generator) -> None:
        """Every mover back at its start (the robot at ``pose``; a goalless wanderer's first goal
        drawn from ``rng``)."""
        self.movers.reset(pose, rng)
        self._place()

    def finish(self, pose: tuple[float, float, float], v: float, w: float, rng: np.random.Generator) -> None:
        """The movers' step after the robot's: it is at ``pose``, moving at (v, w); then the bodies
        go where the movers are and Bullet's contacts are brought up to date."""
        self.movers.finish(pose, v, w, False, rng)
        self._place()
        p.performCollisionDetection(physicsClientId=self.client)

    def states(self) -> MoverStates:
        """The movers' poses, velocities and sizes now (:meth:`Movers.states`)."""
        return self.movers.states()

    def _place(self) -> None:
        rows = self.movers.states().rows
        for body, height, (x, y, yaw) in zip(self.bodies, self.heights, rows[:, :3]):
            p.resetBasePositionAndOrientation(body, (x, y, height), p.getQuaternionFromEuler((0.0, 0.0, yaw)),
                                              physicsClientId=self.client)
