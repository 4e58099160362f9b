"""Matplotlib drawing of a flatland world: obstacles, movers, robot, lidar beams, goal, trajectory.

``rgb_array`` frames come from an off-screen Agg canvas (no display needed); ``human`` uses a
pyplot window. Static parts are drawn once; each frame only moves the robot, the movers (people
orange, forklifts and carts brown, other movers grey, each with its velocity over the next
second), the beams and the path.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Callable, NamedTuple, Sequence

import numpy as np
from matplotlib import patches
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from common.grid_maps import occupancy
from common.readings import Readings
from common.scenario import BoxObstacle, CircleObstacle, PolygonObstacle, Scenario, SegmentObstacle

if TYPE_CHECKING:
    from common.conditions import Conditions
    from common.evaluation import Episode


MOVER_COLOURS = {"person": "tab:orange", "forklift": "tab:brown", "cart": "tab:brown"}


def _obstacle_patch(obstacle) -> patches.Patch | None:
    style = dict(facecolor="0.35" if not obstacle.unobstructed else "0.8", edgecolor="0.1", linewidth=0.8)
    if isinstance(obstacle, CircleObstacle):
        return patches.Circle((obstacle.x, obstacle.y), obstacle.radius, **style)
    if isinstance(obstacle, BoxObstacle):
        return patches.Polygon(obstacle.corners(), closed=True, **style)
    if isinstance(obstacle, PolygonObstacle):
        return patches.Polygon(np.asarray(obstacle.vertices), closed=True, **style)
    return None


class Renderer:
    """Draws one scenario; call :meth:`draw` per step, then :meth:`frame` for pixels."""

    def __init__(self, scenario: Scenario, human: bool = False, size_inches: float = 5.0, dpi: int = 96,
                 goal_radius: float | None = None) -> None:
        self.scenario = scenario
        self.goal_radius = scenario.goal_threshold if goal_radius is None else goal_radius
        self.human = human
        if human:
            import matplotlib.pyplot as plt

            plt.ion()
            self.figure = plt.figure(figsize=(size_inches, size_inches), dpi=dpi)
        else:
            self.figure = Figure(figsize=(size_inches, size_inches), dpi=dpi)
            FigureCanvasAgg(self.figure)
        self.axes = self.figure.add_subplot(1, 1, 1)
        self._draw_static()
        style = {"facecolor": "tab:blue", "alpha": 0.8}
        self.robot_patches: list[patches.Patch] = [
            patches.Circle((0, 0), part.radius, **style) if part.radius is not None
            else patches.Polygon(np.asarray(part.vertices, dtype=float), closed=True, **style)
            for part in scenario.robot.outline]
        for patch in self.robot_patches:
            self.axes.add_patch(patch)
        (self.heading_line,) = self.axes.plot([], [], color="white", linewidth=1.5)
        (self.path_line,) = self.axes.plot([], [], color="tab:blue", linewidth=1.0, alpha=0.7)
        self.beams = LineCollection([], colors="tab:red", linewidths=0.5, alpha=0.5)
        self.axes.add_collection(self.beams)
        self.movers: list[patches.Patch] = []
        for obstacle in scenario.movers:
            colour = MOVER_COLOURS.get(obstacle.motion.label, "0.5")
            if isinstance(obstacle, CircleObstacle):
                patch: patches.Patch = patches.Circle((obstacle.x, obstacle.y), obstacle.radius, facecolor=colour,
                                                      edgecolor="0.1", linewidth=0.6, alpha=0.9)
            else:
                patch = patches.Polygon(obstacle.corners(), closed=True, facecolor=colour, edgecolor="0.1", alpha=0.9)
            self.axes.add_patch(patch)
            self.movers.append(patch)
        self.mover_arrows = LineCollection([], colors="0.1", linewidths=1.0)
        self.axes.add_collection(self.mover_arrows)
        self.title = self.axes.set_title("")

    def _draw_static(self) -> None:
        ax, world = self.axes, self.scenario.world
        x0, y0 = world.offset
        margin = 0.2
        ax.set_xlim(x0 - margin, x0 + world.width + margin)
        ax.set_ylim(y0 - margin, y0 + world.height + margin)
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        if world.walls:
            ax.add_patch(patches.Rectangle((x0, y0), world.width, world.height, fill=False, edgecolor="black", linewidth=2))
        if self.scenario.grid_map is not None:
            occupied = occupancy(self.scenario.grid_map, world.width, world.height)
            # Indexed [x, y]: transposed to rows of y, drawn from the bottom (origin "lower").
            ax.imshow(occupied.T, origin="lower", extent=(x0, x0 + world.width, y0, y0 + world.height),
                      cmap="Greys", vmin=0, vmax=1.25, interpolation="nearest")
        for obstacle in self.scenario.static_obstacles:
            patch = _obstacle_patch(obstacle)
            if patch is not None:
                ax.add_patch(patch)
            elif isinstance(obstacle, SegmentObstacle):
                pts = np.asarray(obstacle.points)
                ax.plot(pts[:, 0], pts[:, 1], color="0.1", linewidth=2)
        gx, gy = self.scenario.goal
        ax.add_patch(patches.Circle((gx, gy), self.goal_radius, facecolor="tab:green", alpha=0.4))
        ax.plot([gx], [gy], marker="*", color="tab:green", markersize=12)

    def draw(self, readings: Readings, trajectory: Sequence[tuple[float, float]] = (), caption: str = "") -> None:
        """Move the robot, its beams and its path to ``readings``."""
        x, y, yaw = readings.pose
        robot = self.scenario.robot
        c, s = math.cos(yaw), math.sin(yaw)
        rotation = np.array([[c, s], [-s, c]])
        reach = 0.0  # how far ahead the heading line reaches: the footprint's front
        for patch, part in zip(self.robot_patches, robot.outline):
            if part.radius is not None:
                patch.center = tuple(np.asarray(part.center) @ rotation + (x, y))
                reach = max(reach, part.center[0] + part.radius)
            else:
                local = np.asarray(part.vertices, dtype=float)
                patch.set_xy(local @ rotation + (x, y))
                reach = max(reach, float(local[:, 0].max()))
        self.heading_line.set_data([x, x + reach * math.cos(yaw)], [y, y + reach * math.sin(yaw)])
        lidar = self.scenario.lidar
        ox = x + math.cos(yaw) * lidar.offset[0] - math.sin(yaw) * lidar.offset[1]
        oy = y + math.sin(yaw) * lidar.offset[0] + math.cos(yaw) * lidar.offset[1]
        angles = yaw + lidar.offset[2] + lidar.beam_angles()
        ends = np.column_stack([ox + readings.lidar * np.cos(angles), oy + readings.lidar * np.sin(angles)])
        self.beams.set_segments([[(ox, oy), tuple(end)] for end in ends])
        if len(trajectory):
            path = np.asarray(trajectory)
            self.path_line.set_data(path[:, 0], path[:, 1])
        if readings.movers is not None:
            self._draw_movers(readings.movers.rows)
        self.title.set_text(caption or f"t = {readings.time:.1f} s" + ("  collision" if readings.collided else ""))
        if self.human:
            import matplotlib.pyplot as plt

            self.figure.canvas.draw_idle()
            plt.pause(0.001)

    def _draw_movers(self, rows: np.ndarray) -> None:
        for patch, (x, y, yaw, _, _, _, length, width) in zip(self.movers, rows):
            if isinstance(patch, patches.Circle):
                patch.center = (x, y)
            else:
                c, s = math.cos(yaw), math.sin(yaw)
                local = np.array([[length, width], [-length, width], [-length, -width], [length, -width]]) * 0.5
                patch.set_xy(local @ np.array([[c, s], [-s, c]]) + (x, y))
        self.mover_arrows.set_segments([[(x, y), (x + vx, y + vy)] for x, y, _, vx, vy, *_ in rows])

    def frame(self) -> np.ndarray:
        """The current picture as an (H, W, 3) uint8 array."""
        canvas = self.figure.canvas
        canvas.draw()
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()

    def close(self) -> None:
        if self.human:
            import matplotlib.pyplot as plt

            plt.close(self.figure)


def plot_odometry_drift(scenario: Scenario, true_path: Sequence, estimate: Sequence, path: str | Path) -> Path:
    """The true path against the wheel-odometry estimate, drawn over the world (the 2D tutorial's figure)."""
    renderer = Renderer(scenario)
    for patch in renderer.robot_patches:
        patch.set_visible(False)
    truth, guess = np.asarray(true_path), np.asarray(estimate)
    renderer.axes.plot(truth[:, 0], truth[:, 1], color="tab:blue", linewidth=1.5, label="true path")
    renderer.axes.plot(guess[:, 0], guess[:, 1], color="tab:orange", linewidth=1.5, linestyle="--", label="wheel odometry")
    drift = float(np.hypot(*(truth[-1] - guess[-1])))
    renderer.title.set_text(f"odometry drift {drift:.2f} m (encoder noise {scenario.robot.encoder_noise:g})")
    renderer.axes.legend(loc="upper right", fontsize=8)
    renderer.figure.savefig(path)
    return Path(path)


def save_gif(frames: Sequence[np.ndarray], path: str | Path, fps: float = 10.0) -> Path:
    """Write RGB frames as an animated GIF."""
    from PIL import Image

    if not frames:
        raise ValueError("no frames to write")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    images = [Image.fromarray(frame) for frame in frames]
    images[0].save(path, save_all=True, append_images=images[1:], duration=int(round(1000 / fps)), loop=0)
    return path


class RecordedEpisode(NamedTuple):
    """An agent's episode as a GIF, with its outcome and the true and odometry paths."""

    gif: Path
    episode: "Episode"
    true_path: list
    estimate: list


def record_agent(agent, scenario: Scenario, path: str | Path, tier: str = "flatland", seed: int = 0,
                 max_steps: int | None = None, every: int = 1, conditions: "Conditions | None" = None,
                 goal_radius: float | None = None) -> RecordedEpisode:
    """Drive one episode of any agent (controller or policy) and write it as a GIF seen from above,
    keeping every ``every``-th frame; either tier (the 3D one drawn in 2D), under ``conditions``,
    judged within ``goal_radius`` (default the scenario's)."""
    from common.conditions import Conditions
    from common.evaluation import run_episode

    scenario = (conditions or Conditions()).for_tier(tier).scenario(scenario)  # draw the robot that drives
    renderer = Renderer(scenario, goal_radius=goal_radius)
    frames, true_path, estimate = [], [], []

    def record(readings: Readings) -> None:
        true_path.append(readings.pose[:2])
        estimate.append(readings.odometry.pose[:2])
        if len(true_path) % every == 1 or every == 1:
            renderer.draw(readings, true_path, caption=f"{agent.name}  t = {readings.time:.1f} s")
            frames.append(renderer.frame())

    episode = run_episode(agent, scenario, tier, seed=seed, max_steps=max_steps, on_step=record, conditions=conditions,
                          goal_radius=goal_radius)
    return RecordedEpisode(save_gif(frames, path, fps=10 / every), episode, true_path, estimate)


def record_episode(env, act: Callable[[np.ndarray], np.ndarray], path: str | Path, seed: int | None = None,
                   every: int = 1) -> tuple[Path, dict]:
    """Run one episode of an ``rgb_array`` env with ``act(observation) -> action``; save it as a GIF.

    Returns the GIF's path and the last step's info.
    """
    observation, info = env.reset(seed=seed)
    frames = [env.render()]
    done, step = False, 0
    while not done:
        observation, _, terminated, truncated, info = env.step(act(observation))
        done = terminated or truncated
        step += 1
        if step % every == 0 or done:
            frames.append(env.render())
    return save_gif(frames, path, fps=env.metadata.get("render_fps", 10) / every), info
