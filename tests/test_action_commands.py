"""An action is two finite numbers: a string ("05" is not the action (0, 5)), a bool or anything
else is refused with a clear error, at the mapping and at the env's step."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import flatland  # noqa: F401
from common.actions import ActionMapping
from common.scenario import RobotProfile

NOT_TWO_NUMBERS = [
    "05", b"05", "ab",  # sequences of two characters
    ["0.5", "1"], ("0", "5"), np.array(["0.5", "1"]), [0.1, "a"], np.array(["a", 1.0], dtype=object),
    [True, False], np.array([True, False]),
    [1 + 0j, 0.0], np.array([0.5 + 1j, 0.0]),
    [1.0, [2.0, 3.0]], {0: 0.5, 1: 1.0}, None, 0.5,
    [10**400, 0.0],  # an integer beyond any float
    # Non-finite floats in the arrays a policy gives (the fast path): a NaN let through corrupts the pose.
    np.array([np.nan, 0.0], dtype=np.float32), np.array([np.inf, 0.0]), np.array([0.0, -np.inf], dtype=np.float32),
]
TWO_NUMBERS = [
    (np.array([0.0, 1.0], dtype=np.float32), (0.5, 1.0)),
    (np.array([0, 1], dtype=np.int64), (0.5, 1.0)),
    (np.array([0.0, 1.0], dtype=object), (0.5, 1.0)),
    ([0.0, 1.0], (0.5, 1.0)),
    ((0, -1), (0.5, -1.0)),
    ([np.float32(1.0), np.int8(0)], (1.0, 0.0)),
    ([3.0, -7.0], (1.0, -1.0)),  # finite but out of range: clipped
]


@pytest.fixture(scope="module")
def mapping() -> ActionMapping:
    return ActionMapping(RobotProfile(v_max=1.0, w_max=1.0))


@pytest.mark.parametrize("action", NOT_TWO_NUMBERS, ids=repr)
def test_anything_but_two_numbers_is_refused(mapping, action):
    with pytest.raises(ValueError, match=r"^action .*: expected (shape \(2,\)|two numbers|finite numbers)"):
        mapping.to_velocity(action)


@pytest.mark.parametrize("action, velocity", TWO_NUMBERS, ids=lambda value: repr(value))
def test_two_finite_numbers_in_an_array_list_or_tuple_are_an_action(mapping, action, velocity):
    assert mapping.to_velocity(action) == pytest.approx(velocity)


def test_the_env_refuses_a_string_action_and_keeps_its_state():
    env = gym.make("flatland/Nav-v0", world="sparse")
    env.reset(seed=0)
    pose = env.unwrapped.readings.pose
    for action in ("05", ["0.5", "1"]):
        with pytest.raises(ValueError, match="action"):
            env.step(action)
    assert env.unwrapped.readings.pose == pose
    env.close()
