"""The vectorised envs a stage trains in: its envs in the learner's process, or one process each."""

from __future__ import annotations

import copy
import multiprocessing
from typing import Callable

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv
from stable_baselines3.common.vec_env.base_vec_env import VecEnvStepReturn


class FreshInfoVecEnv(DummyVecEnv):
    """stable-baselines3's DummyVecEnv, returning each step's infos without deep-copying them.

    DummyVecEnv deep-copies its whole list of infos at every step, in case an env hands back the
    same dict twice. This project's envs build a new info dict (and a new observation) at every
    step and reset, so the only copy needed is the terminal observation's (an array, or the camera
    layout's dict of them), taken where an episode ends. The same observations, rewards, dones and
    infos as DummyVecEnv, and so the same trained weights, to the bit (``tests/test_vec_envs.py``);
    1.2–3.5% more env steps per CPU second for the main job's PPO in three runs
    (docs/benchmarks.md, ``ab_vec.py``)."""

    def step_wait(self) -> VecEnvStepReturn:
        for index, env in enumerate(self.envs):
            obs, self.buf_rews[index], terminated, truncated, info = env.step(self.actions[index])
            self.buf_infos[index] = info
            self.buf_dones[index] = done = terminated or truncated
            info["TimeLimit.truncated"] = truncated and not terminated  # stable-baselines3's key for a timeout
            if done:
                info["terminal_observation"] = copy.deepcopy(obs)  # an array, or a dict of them (camera)
                obs, self.reset_infos[index] = env.reset()
            self._save_obs(index, obs)
        return self._obs_from_buf(), np.copy(self.buf_rews), np.copy(self.buf_dones), list(self.buf_infos)


# What the fork server imports once for every env process it forks: without them each process
# imports torch (through stable-baselines3's Monitor) and flatland itself: 8 envs took 21-23 s to
# start, 6-7 s with them (docs/benchmarks.md). Not physics3d: importing pybullet prints a line on
# standard output, which `curriculum bench --json` keeps for its JSON.
FORK_SERVER_PRELOAD = ("__main__", "stable_baselines3.common.env_util", "flatland.env")


class PreloadedSubprocVecEnv(SubprocVecEnv):
    """stable-baselines3's SubprocVecEnv (a process per env), its processes forked from a server
    that has already imported the envs' modules, where the platform has a fork server.

    The server starts with the first such vec env of a Python process, and keeps its imports for
    the process's life: a later vec env's processes fork from it again."""

    def __init__(self, env_fns: list[Callable[[], gym.Env]], start_method: str | None = None) -> None:
        if start_method is None and "forkserver" in multiprocessing.get_all_start_methods():
            multiprocessing.set_forkserver_preload(list(FORK_SERVER_PRELOAD))
            start_method = "forkserver"
        super().__init__(env_fns, start_method)
