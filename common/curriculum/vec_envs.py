"""The vectorised env a stage trains in when its envs share the learner's process."""

from __future__ import annotations

import copy

import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv
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
