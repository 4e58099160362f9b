"""``physics3d/WarehouseNav-v0``: drive the URDF robot to a goal through a PyBullet warehouse."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from common.errors import require_flag
from common.nav_env import NavigationEnv
from common.observations import ObservationLayout
from common.readings import Readings
from common.route import Route
from common.scenario import Scenario
from physics3d.render import ChaseCamera, GuiOverlay
from physics3d.world import World


class CameraLayout:
    """A vector layout plus the robot camera's images: ``{"state", "rgb", "depth"}``."""

    def __init__(self, state: ObservationLayout, width: int, height: int, far: float) -> None:
        self.state = state
        self.space = spaces.Dict({
            "state": state.space,
            "rgb": spaces.Box(0, 255, (height, width, 3), np.uint8),
            "depth": spaces.Box(0.0, far, (height, width, 1), np.float32),  # channel-last, as image spaces are
        })

    def reset(self) -> None:
        self.state.reset()

    @property
    def reads_route(self) -> bool:
        return self.state.reads_route

    def follow(self, route: Route) -> None:
        self.state.follow(route)

    def __call__(self, readings: Readings, goal: tuple[float, float]) -> dict[str, np.ndarray]:
        camera = readings.camera
        return {"state": self.state(readings, goal), "rgb": camera["rgb"], "depth": camera["depth"][..., np.newaxis]}


class WarehouseNavEnv(NavigationEnv):
    """
    ## Description
    The 3D tutorial's task: a differential-drive robot (``physics3d/assets/diff_drive.urdf``) must
    reach a goal through a PyBullet warehouse of shelves, pillars and crates, seeing it through a
    2D lidar (and optionally a camera). Physics runs at 240 Hz: the wheels are velocity-controlled
    joints, so the robot accelerates, slips and bumps. The world is a :class:`physics3d.World`
    (``env.unwrapped.world``), built from the same scenarios as ``flatland/Nav-v0`` (twin worlds).

    ## Action Space
    ``Box(-1, 1, (2,), float32)`` (finite values clipped into it; NaN, inf or another shape is a
    ``ValueError``): a[0] -> linear velocity v in [0, v_max] (forward only), a[1] ->
    angular velocity w in [-w_max, w_max], with the scenario's robot limits (the 3D robot's
    default: 0.5 m/s, 1.5 rad/s), held as wheel velocity targets for one control period.
    ``action_mapping="rectified"`` makes a[0] <= 0 a stop instead of spreading a[0] linearly.

    ## Observation Space
    ``observation="lidar43"`` (default, the 3D tutorial's 43 values), or any other layout of
    :data:`common.observations.LAYOUTS` (``"lidar43_log"``, ``"nav7"``, ``"lidar79_motion"``,
    ``"lidar49_robot"``, ``"lidar51_route"``: flatland's env describes each); normalised ``Box`` in
    [-1, 1]; the index tables are in :mod:`common.observations`. With ``camera=True`` a
    ``Dict``: ``"state"`` (that Box), ``"rgb"`` ``Box(0, 255, (240, 320, 3), uint8)`` and ``"depth"``
    ``Box(0, 20, (240, 320, 1), float32)`` in metres, from the camera above and behind the body.

    ## Rewards
    A weighted sum of named terms (:mod:`common.rewards`). ``reward="default"``: 10 x metres gained
    (signed: a loop nets nothing), +100 at the goal, -100 on a collision, -0.05 per step, -5 x
    (0.5 - d) within 0.5 m of an obstacle. ``"tutorial3d"`` is the 3D tutorial's final reward
    (progress, heading alignment beyond 1 m, +50 at the goal, -10 on a collision, -0.01 per step,
    -0.1 when stuck, -1 x (0.3 - d) within 0.3 m). ``info["reward_terms"]`` holds each term's share
    of the step's reward.

    ## Starting State
    The scenario's start pose, at rest on the floor. With a generator kind as ``world``, each
    reset draws a new scenario from the env's seeded generator around the 3D robot's template
    (``physics3d.robot.TEMPLATE``) and rebuilds the warehouse in the same physics client.

    ## Episode End
    Terminated when the goal is within ``goal_threshold`` (``info["is_success"]``) or the robot
    touches anything but the floor (``info["collided"]``: a crash is terminal, not a truncation).
    Truncated after ``max_steps`` steps (default 500).
    A step that arrives and touches at once is a success (``is_success`` and ``collided`` both
    true, as the evaluator counts it) and its reward holds both the goal and the collision terms.

    ## Arguments
    ``gymnasium.make("physics3d/WarehouseNav-v0", world="warehouse", observation="lidar43",
    reward="default", render_mode=None, max_steps=500, difficulty=0.5, goal_distance_scale=10.0,
    template=None, action_mapping="linear", camera=False, resample=False, goal_threshold=None, **conditions)``

    * ``world``: a :class:`Scenario`, a list of them, a generator kind (``open``, ``sparse``, ``cluttered``,
      ``warehouse``, ``trap``, ``passages``, ``crowd``, ``warehouse_moving``; not ``maze``, a grid map), a mix of kinds by
      weight, or the path of a scenario or IR-SIM world YAML (extruded to 3D).
    * ``render_mode``: ``None`` (headless), ``"human"`` (the PyBullet GUI with RGB, depth and
      segmentation previews, paced to real time) or ``"rgb_array"`` (a chase camera, 480 x 360).
    * ``difficulty``: 0 to 1, for generator kinds; ``template``: the robot, lidar and world size
      the generator uses (default ``physics3d.robot.TEMPLATE``).
    * ``camera``: add the camera images to the observation (true or false; a frame costs about
      28 ms of CPU headless: ``camera_fps`` in docs/benchmarks.md).
    * ``goal_threshold``: None (each scenario's goal radius), a radius in metres, or ``[low, high]``
      drawn per episode from the env's seed (``info["goal_threshold"]`` at reset).
    * ``resample``: redraw a random IR-SIM world file every episode instead of restoring its
      initial state; ``reset(options={"resample": True})`` redraws once.
    * ``**conditions``: the knobs of :mod:`common.conditions`, physics3d's defaults (the 3D robot
      with realistic imperfections) where unset; e.g. ``control_period`` (seconds per step, default
      the scenario's ``step_time``, 0.1 s: 24 physics sub-steps) or ``heading_source``.

    ## Example
    >>> import gymnasium as gym, physics3d
    >>> env = gym.make("physics3d/WarehouseNav-v0", world="warehouse")
    >>> observation, info = env.reset(seed=0)
    >>> observation, reward, terminated, truncated, info = env.step(env.action_space.sample())
    """

    tier = "physics3d"

    def __init__(self, world: Any = "warehouse", observation: str = "lidar43", reward: Any = "default",
                 template: Scenario | None = None, camera: bool = False, **kwargs: Any) -> None:
        require_flag("camera", camera)  # camera="false" turned the camera on
        self.camera = camera
        self._chase: ChaseCamera | None = None
        self._overlay: GuiOverlay | None = None
        self.world: World | None = None
        super().__init__(world=world, observation=observation, reward=reward, template=template, **kwargs)

    def _build_world(self, scenario: Scenario) -> World:
        # One physics client for the env's life: a new scenario is rebuilt in it (and a GUI stays open).
        if self.world is None:
            return World(scenario, conditions=self.conditions, gui=self.render_mode == "human", camera=self.camera)
        self.world.load(scenario)
        return self.world

    def _make_layout(self, scenario: Scenario) -> ObservationLayout | CameraLayout:
        layout = super()._make_layout(scenario)
        if not self.camera:
            return layout
        camera = self.world.camera
        return CameraLayout(layout, camera.width, camera.height, camera.far)

    def _draw(self) -> np.ndarray | None:
        if self.render_mode == "rgb_array":
            self._chase = self._chase or ChaseCamera(self.world)
            return self._chase.frame(self.readings)
        self._overlay = self._overlay or GuiOverlay(self.world)
        self._overlay.update(self.readings, self.trajectory)
        return None

    def close(self) -> None:
        if self.world is not None:
            self.world.close()
            self.world = None
        super().close()
