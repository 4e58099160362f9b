"""A trained policy driven like a controller, whatever runs its network (torch or onnxruntime).

This module imports neither torch nor stable-baselines3: a robot running an exported policy
(:mod:`common.curriculum.onnx_policy`) needs only NumPy and onnxruntime besides this project's layouts.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from common.actions import ActionMapping
from common.drive import refuse_other_drives
from common.errors import ConfigError
from common.observations import ObservationLayout, make_layout
from common.readings import Readings
from common.route import Route
from common.scenario import LidarSpec, RobotProfile


# What a caller may set on an agent after opening it, carried with it to another process.
SETTINGS = ("name", "max_steps", "env_kwargs", "home", "tier", "normalizer", "action_mapping")


def _reopened(reopen: tuple[Callable[..., "PolicyAgent"], tuple], settings: dict) -> "PolicyAgent":
    agent = reopen[0](*reopen[1])
    for key, value in settings.items():
        setattr(agent, key, value)
    return agent


class PolicyAgent:
    """A trained policy driven like a controller: readings -> observation -> action -> (v, w).

    It builds its observations with the layout in its manifest, so evaluation in either tier
    sees what the policy saw in training. ``model`` is anything with SB3's ``predict``: a
    policy network or a whole algorithm; ``predict``, if given, computes the same deterministic
    action faster. ``max_steps`` is the episode length it trained with. ``reopen``, for a policy
    opened from a file, is how pickling sends it to another process (see ``__reduce__``).
    """

    def __init__(self, model, observation: str, goal_distance_scale: float,
                 normalizer: Callable[[np.ndarray], np.ndarray] | None = None, name: str = "policy",
                 action_mapping: str = "linear", max_steps: int | None = None, env_kwargs: dict | None = None,
                 home: tuple[str, str, int, int] | None = None,
                 predict: Callable[[np.ndarray], np.ndarray] | None = None, tier: str = "flatland",
                 reopen: tuple[Callable[..., "PolicyAgent"], tuple] | None = None) -> None:
        self.model, self.observation, self.goal_distance_scale = model, observation, goal_distance_scale
        self.predict = predict  # the deterministic action of one observation, if not model.predict's
        self.normalizer, self.name, self.action_mapping = normalizer, name, action_mapping
        self.max_steps = max_steps
        self.env_kwargs = dict(env_kwargs or {})  # what it trained with: its conditions are evaluated by default
        self.home = home  # (tier, suite, first seed, episodes) of its own test figure: its evaluation by default
        self.tier = tier  # where it trained last
        self.reopen = reopen  # (loader, arguments) that open it again from its file, in another process

    def __reduce__(self):
        # A policy crosses to a worker process as the recipe that opens its file (its network's
        # runtime, a torch module's faster path or an onnxruntime session, is built there afresh)
        # and the settings a caller may have changed since it was opened.
        if self.reopen is None:
            raise TypeError(f"the policy {self.name!r} was not opened from a file, so no other process can open it")
        return _reopened, (self.reopen, {key: getattr(self, key) for key in SETTINGS})

    @property
    def trained_conditions(self) -> dict:
        """The conditions it trained with: a policy that trained on the URDF robot (whose stage sets
        no ``robot``) meets that robot's 2D profile in flatland and IR-SIM, not the default circle."""
        given = self.env_kwargs
        if self.tier == "physics3d" and given.get("robot") is None and not given.get("robot_family"):
            return {**given, "robot": "physics3d"}
        return given

    def bind(self, robot: RobotProfile, lidar: LidarSpec, goal_threshold: float = 0.3) -> None:
        # Policy files hold a two-number (v, w) actor: they train and drive differential drives.
        refuse_other_drives(robot, f"the policy {self.name!r}")
        self.layout: ObservationLayout = make_layout(self.observation, robot, lidar, self.goal_distance_scale)
        self.mapping = ActionMapping(robot, self.action_mapping)

    def reset(self) -> None:
        self.layout.reset()  # a layout with memory (lidar79_motion) starts the episode afresh

    @property
    def reads_route(self) -> bool:
        """Whether its layout reads a route on the static map (``lidar51_route``)."""
        return self.layout.reads_route

    def follow(self, route: Route) -> None:
        """Drive along this episode's route (after :meth:`reset`; see :mod:`common.route`)."""
        self.layout.follow(route)

    def observe(self, readings: Readings, goal: tuple[float, float]) -> np.ndarray:
        obs = self.layout(readings, goal)
        return self.normalizer(obs) if self.normalizer is not None else obs

    def act(self, readings: Readings, goal: tuple[float, float]) -> tuple[float, float]:
        observation = self.observe(readings, goal)
        action = self.predict(observation) if self.predict is not None else \
            self.model.predict(observation, deterministic=True)[0]
        try:
            return self.mapping.to_velocity(action)
        except ValueError as error:  # a network that overflowed: the policy's fault, named, in one line
            raise ConfigError(None, f"policy {self.name!r}", f"{error}; its network gave no usable action for an "
                              "observation (damaged weights, or one far outside what it trained on)") from None
