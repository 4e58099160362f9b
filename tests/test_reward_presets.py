"""The reward presets hold the documented weights: ``default`` as docs/envs.md gives it, the
tutorial presets as the two tutorials (../shared/seeds/) wrote their final rewards."""

from __future__ import annotations

import pytest

from common.rewards import Reward, StepContext, resolve_reward_spec

# docs/envs.md, "Presets": progress x10 (signed), goal x100, collision x-100, time x-0.05,
# proximity x-5 within 0.5 m.
DEFAULT = {
    "progress": {"weight": 10.0},
    "goal": {"weight": 100.0},
    "collision": {"weight": -100.0},
    "time": {"weight": -0.05},
    "proximity": {"weight": -5.0, "threshold": 0.5},
}
# The 2D tutorial's _compute_reward_v2: 10 x max(0, progress), -5 x (|w| - 0.8) above 0.8 rad/s,
# -5 within 0.3 m else -1 within 0.5 m, +100 at the goal.
TUTORIAL2D = {
    "progress": {"weight": 10.0, "positive_only": True},
    "spin": {"weight": -5.0, "threshold": 0.8},
    "proximity_bands": {"weight": -1.0, "bands": ((0.3, 5.0), (0.5, 1.0))},
    "goal": {"weight": 100.0},
}
# The 3D tutorial's step(): progress, 0.1 x alignment beyond 1 m, +50 goal, -10 collision, -0.01 a
# step, -0.1 stuck (20 steps under 0.05 m, beyond 1 m), -1 x (0.3 - nearest), -0.2 x (|w| - 2).
TUTORIAL3D = {
    "progress": {"weight": 1.0},
    "heading_alignment": {"weight": 0.1, "min_distance": 1.0},
    "goal": {"weight": 50.0},
    "collision": {"weight": -10.0},
    "time": {"weight": -0.01},
    "stuck": {"weight": -0.1, "window": 20, "threshold": 0.05, "min_distance": 1.0},
    "proximity": {"weight": -1.0, "threshold": 0.3},
    "spin": {"weight": -0.2, "threshold": 2.0},
}


def _as_tuples(value):
    return tuple(_as_tuples(v) for v in value) if isinstance(value, (list, tuple)) else value


@pytest.mark.parametrize("name, documented",
                         [("default", DEFAULT), ("tutorial2d", TUTORIAL2D), ("tutorial3d", TUTORIAL3D)])
def test_each_preset_holds_its_documented_terms_and_weights(name, documented):
    resolved = {term: {k: _as_tuples(v) for k, v in entry.items()} for term, entry in resolve_reward_spec(name).items()}
    assert resolved == documented


def test_a_crash_under_the_default_reward_costs_what_the_goal_pays():
    crash = StepContext(distance=2.0, prev_distance=2.0, heading_error=0.0, v=0.5, w=0.0, min_range=1.0,
                        collided=True, reached=False)
    total, shares = Reward("default")(crash)
    assert shares["collision"] == -100.0 and total == pytest.approx(-100.05)
    _, shares = Reward("default")(crash._replace(collided=False, reached=True))
    assert shares["goal"] == 100.0


@pytest.mark.parametrize("spec", [{"progress": 10**400}, {"proximity": {"weight": -1.0, "threshold": 10**400}}])
def test_an_integer_past_a_floats_range_is_refused_in_one_line(spec):
    from common.errors import ConfigError
    from common.rewards import resolve_reward_spec

    with pytest.raises(ConfigError, match="progress|threshold"):
        resolve_reward_spec(spec)
