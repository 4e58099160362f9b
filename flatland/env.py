"""``flatland/Nav-v0``: drive a differential-drive robot to a goal in a 2D world."""

from __future__ import annotations

import numpy as np

from common.nav_env import NavigationEnv
from common.scenario import Scenario
from flatland.render import Renderer
from flatland.world import World


class NavEnv(NavigationEnv):
    """
    ## Description
    A differential-drive robot must reach a goal in a 2D world of static obstacles (circles, boxes,
    polygons, segments), seeing it through a 2D lidar, as in the 2D tutorial on IR-SIM. The world is
    a :class:`flatland.World` (``env.unwrapped.world``), built per episode from a scenario.

    ## Action Space
    ``Box(-1, 1, (2,), float32)`` (finite values clipped into it; NaN, inf or another shape is a
    ``ValueError``): a[0] -> linear velocity v in [0, v_max] (forward only), a[1] ->
    angular velocity w in [-w_max, w_max], with the scenario's robot limits (default 1 m/s, 1 rad/s).
    ``action_mapping="rectified"`` makes a[0] <= 0 a stop instead of spreading a[0] linearly.

    ## Observation Space
    ``observation="nav7"`` (default, the tutorial's 7 values), ``"lidar43"`` (36 lidar sectors),
    ``"lidar43_log"`` (the same sectors on a log range scale), ``"lidar79_motion"`` (and each
    sector's range rate, for movers), ``"lidar49_robot"`` (the sectors as clearance from the
    footprint, and the robot's size and limits) or ``"lidar51_route"`` (``lidar49_robot`` and where
    the route to the goal is 1 m on); normalised ``Box`` in [-1, 1]; the index tables are in
    :mod:`common.observations` and docs/envs.md.

    ## Rewards
    A weighted sum of named terms (:mod:`common.rewards`). ``reward="default"``: 10 x metres gained
    (signed: a loop nets nothing), +100 at the goal, -100 on a collision, -0.05 per step, -5 x
    (0.5 - d) within 0.5 m of an obstacle. ``"tutorial2d"`` is the tutorial's reward v2 (10 x metres
    gained, gains only, -5 x (|w| - 0.8) above 0.8 rad/s, -5 within 0.3 m and -1 within 0.5 m of an
    obstacle, +100 at the goal), which a robot driving in circles games. ``info["reward_terms"]``
    holds each term's share of the step's reward.

    ## Starting State
    The scenario's start pose, at rest. With a generator kind as ``world``, each reset draws a new
    scenario from the env's seeded generator.

    ## Episode End
    Terminated when the goal is within ``goal_threshold`` (``info["is_success"]``) or the robot
    touches an obstacle or wall (``info["collided"]``: a crash is terminal, not a truncation).
    Truncated after ``max_steps`` steps (default 500).
    A step that arrives and touches at once is a success (``is_success`` and ``collided`` both
    true, as the evaluator counts it) and its reward holds both the goal and the collision terms.

    ## Arguments
    ``gymnasium.make("flatland/Nav-v0", world="sparse", observation="nav7", reward="default",
    render_mode=None, max_steps=500, difficulty=0.5, goal_distance_scale=10.0, template=None,
    action_mapping="linear", resample=False, goal_threshold=None, **conditions)``

    * ``world``: a :class:`Scenario`, a list of them, a generator kind (``open``, ``sparse``, ``cluttered``,
      ``warehouse``, ``trap``, ``maze``, ``passages``, ``crowd``, ``warehouse_moving``), a mix of kinds by
      weight, or the path of a scenario or IR-SIM world YAML.
    * ``render_mode``: ``None``, ``"human"`` (a matplotlib window) or ``"rgb_array"``.
    * ``difficulty``: 0 to 1, for generator kinds; ``template``: the robot, lidar and world size
      the generator uses.
    * ``goal_threshold``: None (each scenario's goal radius), a radius in metres, or ``[low, high]``
      drawn per episode from the env's seed (``info["goal_threshold"]`` at reset).
    * ``resample``: redraw a random IR-SIM world file every episode instead of restoring its
      initial state; ``reset(options={"resample": True})`` redraws once.
    * ``**conditions``: the knobs of :mod:`common.conditions` (``robot``, ``robot_family``,
      ``lidar_beams``, ``lidar_noise``, ``odometry_noise``, ``action_delay``, ``motor_scale``,
      ``dynamics``), flatland's defaults
      (an ideal robot) where unset.

    ## Example
    >>> import gymnasium as gym, flatland
    >>> env = gym.make("flatland/Nav-v0", world="sparse")
    >>> observation, info = env.reset(seed=0)
    >>> observation, reward, terminated, truncated, info = env.step(env.action_space.sample())
    """

    def __init__(self, **kwargs) -> None:
        self._renderer: Renderer | None = None
        self.world: World | None = None  # built by the first scenario, then reused while it accepts the next
        super().__init__(**kwargs)

    def _build_world(self, scenario: Scenario) -> World:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self.world is not None and self.world.load(scenario):
            return self.world
        return World(scenario, conditions=self.conditions)

    def _draw(self) -> np.ndarray | None:
        if self._renderer is None:
            self._renderer = Renderer(self.scenario, human=self.render_mode == "human")
        self._renderer.draw(self.readings, self.trajectory)
        return self._renderer.frame() if self.render_mode == "rgb_array" else None

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        super().close()
