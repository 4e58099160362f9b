"""The social force model is IR-SIM's, term by term: the same velocity as IR-SIM's own class on
thousands of random agents (neighbours near and far, on the line, walls crossing the body)."""

from __future__ import annotations

import numpy as np
import pytest

from common.motion.sfm import PARAMETERS, desire, social_force_velocity
from tests.conftest import optional

optional("irsim")
from irsim.lib.algorithm.social_force_model import social_force_model  # noqa: E402

IRSIM_NAMES = {"neighbor_threshold": "neighbor_range"}


def _case(rng: np.random.Generator):
    params = dict(vmax=rng.uniform(0.5, 2.0), step_time=0.1, neighbor_threshold=rng.uniform(1.0, 10.0),
                  relaxation_time=rng.uniform(0.2, 1.0), force_factor_desired=rng.uniform(0.5, 2.0),
                  force_factor_social=rng.uniform(0.0, 10.0), force_factor_obstacle=rng.uniform(0.0, 10.0),
                  sigma_obstacle=rng.uniform(0.2, 1.0), lambda_importance=rng.uniform(0.0, 3.0),
                  gamma=rng.uniform(0.2, 1.0), n_angular=rng.uniform(0.5, 3.0), n_velocity=rng.uniform(0.5, 3.0),
                  safety_radius=rng.uniform(0.0, 0.3))
    state = [*rng.uniform(-3, 3, 2), *rng.uniform(-1.5, 1.5, 2), rng.uniform(0.2, 0.6), *rng.uniform(-2, 2, 2), 0.0]
    neighbors = np.column_stack([rng.uniform(-5, 5, (8, 2)), rng.uniform(-1.5, 1.5, (8, 2)), rng.uniform(0.2, 0.6, 8)])
    neighbors[0, :2] = state[:2]  # one exactly on the agent (skipped: no direction)
    neighbors[1, :2] = [state[0] + 1.0, state[1]]  # one straight ahead on the x axis
    segments = rng.uniform(-4, 4, (3, 4))
    segments[0] = [state[0] - 1, state[1], state[0] + 1, state[1]]  # a wall through the centre
    return params, state, neighbors, segments


def _irsim(params, state, neighbors, segments):
    kwargs = {IRSIM_NAMES.get(k, k): v for k, v in params.items()}
    x, y, reach = state[0], state[1], params["neighbor_threshold"]
    near = [list(n) for n in neighbors if (x - n[0]) ** 2 + (y - n[1]) ** 2 < reach ** 2]  # as IR-SIM's SFMVelocity
    vx_des, vy_des = state[5], state[6]
    norm = (vx_des * vx_des + vy_des * vy_des) ** 0.5
    state = list(state)
    if norm > 1e-9:
        state[5], state[6] = params["vmax"] * vx_des / norm, params["vmax"] * vy_des / norm
    return social_force_model(state=state, neighbor_list=near, line_obs_list=[list(s) for s in segments],
                              **kwargs).cal_vel()


@pytest.mark.parametrize("seed", range(5))
def test_the_velocity_is_irsims_to_the_last_bit(seed):
    rng = np.random.default_rng(seed)
    for _ in range(400):
        params, state, neighbors, segments = _case(rng)
        p = np.array([params[name] for name in PARAMETERS])
        desired = desire(state[5], state[6], params["vmax"], False)
        ours = social_force_velocity(*state[:5], *desired, neighbors, len(neighbors), segments, p)
        assert ours == tuple(_irsim(params, state, neighbors, segments))


def test_each_force_moves_the_agent():
    # Planted bugs dropped each term in turn (desired, social, obstacle) and this failed with the
    # bit-exact test above; here each term is seen to act on its own.
    params, state, neighbors, segments = _case(np.random.default_rng(9))
    p = np.array([params[name] for name in PARAMETERS])
    base = social_force_velocity(*state[:7], neighbors, len(neighbors), segments, p)
    for name in ("force_factor_desired", "force_factor_social", "force_factor_obstacle"):
        off = p.copy()
        off[PARAMETERS.index(name)] = 0.0
        assert social_force_velocity(*state[:7], neighbors, len(neighbors), segments, off) != base, name
