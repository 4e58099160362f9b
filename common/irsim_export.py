"""Write a scenario as an IR-SIM world mapping, so IR-SIM can run the very same world (benchmarks,
parity checks). Boundary walls, which IR-SIM lacks, become a closed ``linestring`` obstacle."""

from __future__ import annotations

import math
from typing import Any

from common.scenario import BoxObstacle, CircleObstacle, PolygonObstacle, Scenario

_ORIGIN = [0.0, 0.0, 0.0]


def _obstacle(obstacle) -> dict[str, Any]:
    if isinstance(obstacle, CircleObstacle):
        shape, state = {"name": "circle", "radius": obstacle.radius}, [obstacle.x, obstacle.y, 0.0]
    elif isinstance(obstacle, BoxObstacle):
        shape = {"name": "rectangle", "length": obstacle.length, "width": obstacle.width}
        state = [obstacle.x, obstacle.y, obstacle.yaw]
    elif isinstance(obstacle, PolygonObstacle):
        shape, state = {"name": "polygon", "vertices": [list(v) for v in obstacle.vertices]}, _ORIGIN
    else:
        shape, state = {"name": "linestring", "vertices": [list(p) for p in obstacle.points]}, _ORIGIN
    return {"shape": shape, "state": list(state), "unobstructed": obstacle.unobstructed}


def scenario_to_irsim(scenario: Scenario) -> dict[str, Any]:
    """The IR-SIM world mapping of a scenario (dump it with ``yaml.safe_dump``)."""
    world, robot, lidar = scenario.world, scenario.robot, scenario.lidar
    if robot.shape == "circle":
        shape = {"name": "circle", "radius": robot.radius}
    else:
        shape = {"name": "rectangle", "length": robot.length, "width": robot.width}
    robot_entry: dict[str, Any] = {
        "kinematics": {"name": "diff"},
        "shape": shape,
        "state": list(scenario.start),
        "goal": [*scenario.goal, 0.0],
        "goal_threshold": scenario.goal_threshold,
        "vel_min": [robot.v_min, robot.w_low],
        "vel_max": [robot.v_max, robot.w_max],
        "sensors": [{
            "name": "lidar2d", "range_min": lidar.range_min, "range_max": lidar.range_max,
            # IR-SIM spreads beams over linspace(-range/2, range/2): a full circle's evenly spaced
            # beams are that over 2π(n - 1)/n, the same directions.
            "angle_range": 2 * math.pi - lidar.beam_spacing if lidar.full_circle else lidar.angle_range,
            "number": lidar.beams, "offset": list(lidar.offset),
            "noise": lidar.noise_std > 0, "std": lidar.noise_std,
        }],
    }
    if math.isfinite(robot.accel_v) or math.isfinite(robot.accel_w):
        robot_entry["acce"] = [robot.accel_v, robot.accel_w]
    obstacles = [_obstacle(o) for o in scenario.obstacles]
    if world.walls:
        x0, y0 = world.offset
        x1, y1 = x0 + world.width, y0 + world.height
        ring = [[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]
        obstacles.append({"shape": {"name": "linestring", "vertices": ring}, "state": list(_ORIGIN)})
    return {
        "world": {"width": world.width, "height": world.height, "step_time": world.step_time,
                  "offset": list(world.offset), "collision_mode": "stop"},
        "robot": robot_entry,
        "obstacle": obstacles,
    }
