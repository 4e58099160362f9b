"""Draw docs/images/physics3d_movers.png: the `dwa` controller 5 s into warehouse_moving-eval-0 in
PyBullet, among people (purple) and forklifts (red); an overview and the chase camera at the same
moment. Run from the project root: python docs/images/physics3d_movers.py"""

from pathlib import Path

import gymnasium as gym
import numpy as np
from PIL import Image

import physics3d  # noqa: F401  (registers the env)
from common.controllers import make_controller
from common.generators import SUITES
from physics3d.render import ChaseCamera
from physics3d.robot import TEMPLATE
from physics3d.sensors import Camera

scenario = next(SUITES["warehouse_moving"].scenarios(count=1, template=TEMPLATE))
env = gym.make("physics3d/WarehouseNav-v0", world=scenario, observation="lidar43", render_mode="rgb_array")
env.reset(seed=0)
world = env.unwrapped.world
controller = make_controller("dwa")
controller.bind(world.scenario.robot, world.scenario.lidar)
controller.reset()
for _ in range(50):
    readings = world.step(*controller.act(world.readings, scenario.goal))
overview = Camera(world.client, 480, 360, fov=60.0, far=40.0).look_at((5.0, -4.0, 9.0), (5.0, 4.5, 0.0),
                                                                      segmentation=False)["rgb"]
chase = ChaseCamera(world, 480, 360, back=3.2, up=3.4, ahead=2.0).frame(readings)
Image.fromarray(np.concatenate([overview, chase], axis=1)).save(Path(__file__).with_suffix(".png"))
