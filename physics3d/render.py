"""Seeing the 3D world: a chase camera for ``rgb_array`` frames and the GUI overlay for ``human``.

The 3D tutorial's lesson: camera images and debug lines are what make a PyBullet GUI crawl (under
1 frame per second with everything drawn every step). So the overlay draws every tenth frame,
one lidar beam in ten, reuses its beam lines in place, and adds path segments that stay alive
instead of redrawing the path.
"""

from __future__ import annotations

import math
import time
from typing import Sequence

import numpy as np
import pybullet as p

from common.readings import Readings
from physics3d.sensors import Camera
from physics3d.world import World

DRAW_EVERY = 10  # frames between overlay updates
BEAM_STRIDE = 10  # draw one lidar beam in this many
_BEAM_COLOUR = (0.9, 0.1, 0.1)
_PATH_COLOUR = (0.1, 0.3, 0.9)
_GOAL_COLOUR = (0.1, 0.7, 0.1)


class ChaseCamera:
    """Frames from behind and above the robot, looking ahead of it (``rgb_array``)."""

    def __init__(self, world: World, width: int = 480, height: int = 360, back: float = 1.6, up: float = 1.3,
                 ahead: float = 1.0) -> None:
        self.world = world
        renderer = p.ER_BULLET_HARDWARE_OPENGL if world.gui else p.ER_TINY_RENDERER
        self.camera = Camera(world.client, width, height, fov=60.0, far=30.0, renderer=renderer)
        self.back, self.up, self.ahead = back, up, ahead

    def frame(self, readings: Readings) -> np.ndarray:
        """An RGB frame (H, W, 3) uint8 of the robot at its current pose."""
        x, y, yaw = readings.pose
        c, s = math.cos(yaw), math.sin(yaw)
        eye_x, eye_y = x - self.back * c, y - self.back * s
        world = self.world.scenario.world
        if world.walls:
            # Kept inside the walls: from behind one, a robot backed up to it was not in the frame.
            (x0, y0), margin = world.offset, 0.05
            eye_x = min(max(eye_x, x0 + margin), x0 + world.width - margin)
            eye_y = min(max(eye_y, y0 + margin), y0 + world.height - margin)
        eye = (eye_x, eye_y, self.up)
        target = (x + self.ahead * c, y + self.ahead * s, 0.1)
        return self.camera.look_at(eye, target, segmentation=False)["rgb"]


class GuiOverlay:
    """Throttled debug drawing in the PyBullet GUI, with the robot camera's buffer previews."""

    def __init__(self, world: World) -> None:
        self.world = world
        c = world.client
        for option in (p.COV_ENABLE_RGB_BUFFER_PREVIEW, p.COV_ENABLE_DEPTH_BUFFER_PREVIEW,
                       p.COV_ENABLE_SEGMENTATION_MARK_PREVIEW):
            p.configureDebugVisualizer(option, 1, physicsClientId=c)
        # Shadows cost a third of a frame on a software renderer (measured under Xvfb: 5.3 -> 6.5
        # steps/s); the warehouse reads as well without them.
        p.configureDebugVisualizer(p.COV_ENABLE_SHADOWS, 0, physicsClientId=c)
        # The previews show the last synthetic camera image; the world's own camera if it has one.
        self.camera = world.camera or Camera(c, renderer=p.ER_BULLET_HARDWARE_OPENGL)
        self.frames = 0
        self._beams: list[int] = []
        self._path_end: Sequence[float] | None = None
        self._last_time = time.perf_counter()

    def update(self, readings: Readings, trajectory: Sequence[tuple[float, float]]) -> None:
        """Draw (every ``DRAW_EVERY`` frames) and keep real time: one control period per frame."""
        if len(trajectory) <= 1:
            self._new_episode()
        if self.frames % DRAW_EVERY == 0:
            self._draw(readings, trajectory)
        self.frames += 1
        wait = self.world.period - (time.perf_counter() - self._last_time)
        if wait > 0.0:
            time.sleep(wait)
        self._last_time = time.perf_counter()

    def _new_episode(self) -> None:
        c = self.world.client
        p.removeAllUserDebugItems(physicsClientId=c)
        self._beams, self._path_end, self.frames = [], None, 0
        gx, gy = self.world.scenario.goal
        p.addUserDebugLine((gx, gy, 0.0), (gx, gy, 1.0), _GOAL_COLOUR, lineWidth=4, physicsClientId=c)
        p.addUserDebugText("goal", (gx, gy, 1.05), _GOAL_COLOUR, physicsClientId=c)

    def _draw(self, readings: Readings, trajectory: Sequence[tuple[float, float]]) -> None:
        world, c = self.world, self.world.client
        x, y, yaw = readings.pose
        position, _ = world.robot.link_pose()
        starts, ends = world.lidar.rays(x, y, position[2], yaw)
        fractions = readings.lidar / world.lidar.spec.range_max
        beams = range(0, len(fractions), BEAM_STRIDE)
        for k, beam in enumerate(beams):
            hit = starts[beam] + fractions[beam] * (ends[beam] - starts[beam])
            replace = self._beams[k] if k < len(self._beams) else -1
            item = p.addUserDebugLine(starts[beam], hit, _BEAM_COLOUR, lineWidth=1, replaceItemUniqueId=replace,
                                      physicsClientId=c)
            if replace == -1:
                self._beams.append(item)
        point = (trajectory[-1][0], trajectory[-1][1], 0.02)
        if self._path_end is not None:
            p.addUserDebugLine(self._path_end, point, _PATH_COLOUR, lineWidth=2, lifeTime=0, physicsClientId=c)
        self._path_end = point
        self.camera.from_mount(*world.robot.camera_pose())
        p.resetDebugVisualizerCamera(2.5, math.degrees(yaw) - 90.0, -35.0, (x, y, 0.1), physicsClientId=c)
