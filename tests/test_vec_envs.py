"""The stage's VecEnvs: in process, DummyVecEnv's steps without its deep copy of the infos; in
subprocesses, forked with the envs' modules already imported."""

import copy
import subprocess
import sys

import numpy as np
import pytest
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv

from common.curriculum.policy import vec_env_class
from common.curriculum.vec_envs import FreshInfoVecEnv
from flatland.env import NavEnv

# Short episodes, so the 300 steps below cross several ends: timeouts, collisions and arrivals.
ENV_KWARGS = {"world": "cluttered", "observation": "lidar43_log", "max_steps": 40}


def _venv(cls):
    return make_vec_env(NavEnv, n_envs=4, seed=3, env_kwargs=ENV_KWARGS, vec_env_cls=cls)


def _assert_same_info(info: dict, other: dict, own_clocks: bool = False) -> None:
    """Equal keys and values (arrays element by element); with ``own_clocks``, Monitor's episode
    summaries compared by return and length only, as two envs' wall clocks differ."""
    assert info.keys() == other.keys()
    for key, value in info.items():
        if isinstance(value, np.ndarray):
            assert np.array_equal(value, other[key]), key
        elif key == "episode" and own_clocks:
            assert (value["r"], value["l"]) == (other[key]["r"], other[key]["l"])
        else:
            assert value == other[key], key


def test_a_dummy_stage_trains_in_the_fresh_info_env():
    assert vec_env_class("dummy") is FreshInfoVecEnv


def test_it_steps_as_dummy_vec_env_does_and_keeps_what_it_returned():
    ours, stock = _venv(FreshInfoVecEnv), _venv(DummyVecEnv)
    actions = np.random.default_rng(0).uniform(-1, 1, size=(300, 4, 2)).astype(np.float32)
    assert np.array_equal(ours.reset(), stock.reset())
    kept = []
    ends = {"terminal_observation": 0, "TimeLimit.truncated": 0}
    for action in actions:
        obs, rewards, dones, infos = ours.step(action)
        stock_obs, stock_rewards, stock_dones, stock_infos = stock.step(action)
        assert np.array_equal(obs, stock_obs) and np.array_equal(rewards, stock_rewards)
        assert np.array_equal(dones, stock_dones)
        for info, stock_info in zip(infos, stock_infos):
            _assert_same_info(info, stock_info, own_clocks=True)
            ends["terminal_observation"] += "terminal_observation" in info
            ends["TimeLimit.truncated"] += info["TimeLimit.truncated"]
        kept.append((infos, copy.deepcopy(infos)))
    assert ends["terminal_observation"] > ends["TimeLimit.truncated"] > 0  # timeouts and other ends both met
    # What a step returned is not changed by the steps after it (the buffers are refilled, not the infos).
    for infos, as_returned in kept:
        for info, original in zip(infos, as_returned, strict=True):
            _assert_same_info(info, original)
    ours.close()
    stock.close()


def test_a_terminal_observation_is_a_copy_of_the_env_s():
    venv = _venv(FreshInfoVecEnv)
    venv.reset()
    returned = []
    for env in venv.envs:
        step = env.step

        def recording_step(action, step=step):
            result = step(action)
            returned.append(result[0])
            return result

        env.step = recording_step
    for _ in range(60):
        infos = venv.step(np.ones((4, 2), dtype=np.float32))[3]
        for info in infos:
            if "terminal_observation" in info:
                assert all(info["terminal_observation"] is not obs for obs in returned)
                assert any(np.array_equal(info["terminal_observation"], obs) for obs in returned[-4:])
                return
    raise AssertionError("no episode ended in 60 steps")


def test_a_camera_env_s_terminal_observation_is_a_dict_as_dummy_vec_env_s():
    from physics3d.env import WarehouseNavEnv

    kwargs = {"world": "open", "camera": True, "max_steps": 2}
    ours, stock = (make_vec_env(WarehouseNavEnv, n_envs=1, seed=0, env_kwargs=kwargs, vec_env_cls=cls)
                   for cls in (FreshInfoVecEnv, DummyVecEnv))
    ours.reset()
    stock.reset()
    for _ in range(2):
        infos, stock_infos = ours.step(np.zeros((1, 2), np.float32))[3], stock.step(np.zeros((1, 2), np.float32))[3]
    terminal, stock_terminal = infos[0]["terminal_observation"], stock_infos[0]["terminal_observation"]
    assert isinstance(terminal, dict) and terminal.keys() == stock_terminal.keys() == {"state", "rgb", "depth"}
    assert all(np.array_equal(terminal[key], stock_terminal[key]) for key in terminal)
    ours.close()
    stock.close()


@pytest.mark.slow
def test_a_subprocess_stage_s_env_processes_start_with_flatland_already_imported(tmp_path):
    # A fresh interpreter: a fork server an earlier test started keeps the imports it started with.
    script = """
import sys

import gymnasium as gym

from common.curriculum.policy import vec_env_class


def probe():
    env = gym.make("CartPole-v1")  # an env that imports nothing of this project
    env.unwrapped.imported = "flatland.env" in sys.modules
    return env


if __name__ == "__main__":
    venv = vec_env_class("subproc")([probe, probe])
    print(venv.get_attr("imported"))
    venv.close()
"""
    path = tmp_path / "probe.py"
    path.write_text(script)
    result = subprocess.run([sys.executable, str(path)], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[True, True]"
