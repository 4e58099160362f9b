"""Policy zips read back exactly as saved: the normaliser's arithmetic and fields, and weights or
statistics that do not fit the network refused in one line naming the file and its member."""

from __future__ import annotations

import io
import json
import pickle
import zipfile
from pathlib import Path
from typing import Callable

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

import flatland
from common.curriculum.policy import build_policy, load_policy, load_weights
from common.curriculum.policy_file import NORMALIZER, Normalizer, PolicyFile, save_policy
from common.errors import ConfigError
from common.scenario import LidarSpec, RobotProfile, Scenario

NAV7 = {"observation": "nav7", "goal_distance_scale": 10.0}
# Statistics where sqrt(var + eps) and sqrt(var) + eps differ by far more than rounding: a zero
# variance (sqrt(0 + 0.01) = 0.1 against 0.01) and clip and epsilon that cannot be mistaken for each other.
MEAN = np.array([0.0, 1.0, -2.0, 0.5, 0.0, 3.0, -1.0])
VAR = np.array([0.0, 0.04, 4.0, 1.0, 0.25, 9.0, 0.01])
CLIP, EPSILON, COUNT = 4.0, 0.01, 1234.0


def _normalizer() -> Normalizer:
    return Normalizer(MEAN.copy(), VAR.copy(), CLIP, EPSILON, COUNT)


def _model(algorithm: type = PPO):
    extra = {"n_steps": 64, "batch_size": 64} if algorithm is PPO else {"buffer_size": 100, "learning_starts": 10}
    return algorithm("MlpPolicy", gym.make("flatland/Nav-v0", world="open"), device="cpu", seed=0, **extra)


def _vec_normalize(**kwargs) -> VecNormalize:
    return VecNormalize(DummyVecEnv([lambda: gym.make("flatland/Nav-v0", world="open")]), **kwargs)


def _trained(algorithm: type = PPO):
    """A model after a few updates, so its optimiser holds per-parameter state (Adam's moments)."""
    model = _model(algorithm)
    model.learn(64 if algorithm is PPO else 20)
    return model


@pytest.fixture(scope="module")
def ppo_zip(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("ppo") / "policy.zip"
    return save_policy(_trained(PPO), path, {"algorithm": "ppo", **NAV7}, _normalizer())


def _rewrite(source: Path, target: Path, member: str, data: bytes) -> Path:
    with zipfile.ZipFile(source) as old, zipfile.ZipFile(target, "w") as new:
        for item in old.infolist():
            new.writestr(item.filename, data if item.filename == member else old.read(item))
    return target


def _tensors(path: Path, member: str) -> object:
    return torch.load(io.BytesIO(zipfile.ZipFile(path).read(member)), weights_only=True)


def _saved(value: object) -> bytes:
    buffer = io.BytesIO()
    torch.save(value, buffer)
    return buffer.getvalue()


def _assert_one_line_refusal(error: pytest.ExceptionInfo, path: Path, member: str, problem: str) -> None:
    message = str(error.value)
    assert message.startswith(f"{path}: {member}: ") and problem in message and "\n" not in message, message


# -- the normaliser ------------------------------------------------------------------------------


def test_the_normaliser_divides_by_the_root_of_variance_plus_epsilon_as_vecnormalize_does():
    venv = _vec_normalize(clip_obs=CLIP, epsilon=EPSILON)
    venv.obs_rms.mean, venv.obs_rms.var = MEAN.copy(), VAR.copy()
    observations = np.random.default_rng(0).uniform(-3.0, 3.0, (20, 7))
    expected = np.clip((observations - MEAN) / np.sqrt(VAR + EPSILON), -CLIP, CLIP)
    ours = np.array([_normalizer()(obs) for obs in observations])
    np.testing.assert_allclose(ours, expected, rtol=1e-6)
    np.testing.assert_allclose(ours, venv.normalize_obs(observations), rtol=1e-6)
    # The zero-variance entry: 0.05 off the mean is half a unit, not five.
    assert _normalizer()(MEAN + 0.05)[0] == pytest.approx(0.5)


def test_a_normaliser_taken_from_vecnormalize_keeps_each_field_and_restores_its_statistics():
    venv = _vec_normalize(clip_obs=CLIP, epsilon=EPSILON)
    venv.obs_rms.mean, venv.obs_rms.var, venv.obs_rms.count = MEAN.copy(), VAR.copy(), COUNT
    taken = Normalizer.from_vec_normalize(venv)
    assert (taken.clip, taken.epsilon, taken.count) == (CLIP, EPSILON, COUNT)
    assert np.array_equal(taken.mean, MEAN) and np.array_equal(taken.var, VAR)
    fresh = _vec_normalize()
    taken.apply_to(fresh)
    assert np.array_equal(fresh.obs_rms.mean, MEAN) and np.array_equal(fresh.obs_rms.var, VAR)
    assert fresh.obs_rms.count == COUNT


def test_a_saved_normaliser_loads_back_with_each_field_in_its_place(ppo_zip):
    loaded = PolicyFile(ppo_zip).normalizer(7)
    assert (loaded.clip, loaded.epsilon, loaded.count) == (CLIP, EPSILON, COUNT)
    assert np.array_equal(loaded.mean, MEAN) and np.array_equal(loaded.var, VAR)
    # The policy observes through it: the loaded agent normalises as the original does.
    agent = load_policy(ppo_zip)
    observation = np.linspace(-2.0, 2.0, 7)
    np.testing.assert_array_equal(agent.normalizer(observation), _normalizer()(observation))
    # Sent to another process (pickled), it is opened again from its file and normalises alike.
    reopened = pickle.loads(pickle.dumps(agent))
    np.testing.assert_array_equal(reopened.normalizer(observation), _normalizer()(observation))


def test_a_policy_crosses_to_another_process_with_what_was_set_on_it_since_it_was_opened(ppo_zip):
    agent = load_policy(ppo_zip)
    agent.name, agent.max_steps, agent.env_kwargs = "renamed", 77, {"lidar_noise": 0.02}
    reopened = pickle.loads(pickle.dumps(agent))
    assert (reopened.name, reopened.max_steps, reopened.env_kwargs) == ("renamed", 77, {"lidar_noise": 0.02})
    observation = np.linspace(-1.0, 1.0, 7).astype(np.float32)
    assert np.array_equal(reopened.predict(observation), agent.predict(observation))


def test_a_policy_built_in_memory_says_why_it_cannot_cross_to_another_process():
    from common.policy_agent import PolicyAgent

    agent = PolicyAgent(object(), "nav7", 10.0, name="in_training")
    with pytest.raises(TypeError, match="the policy 'in_training' was not opened from a file"):
        pickle.dumps(agent)


def test_a_policy_that_acts_nan_is_named_in_one_line():
    """A network that overflowed mid-episode raised the action mapping's ValueError, a traceback
    from `curriculum eval` that named no policy."""
    from common.policy_agent import PolicyAgent

    agent = PolicyAgent(object(), "nav7", 10.0, name="diverged", predict=lambda obs: np.array([np.nan, 0.0]))
    agent.bind(RobotProfile(), LidarSpec())
    agent.reset()
    readings = flatland.World(Scenario()).reset()
    with pytest.raises(ConfigError) as error:
        agent.act(readings, (8.0, 8.0))
    assert str(error.value).startswith("policy 'diverged': action array([nan, 0.]): expected finite numbers")
    assert "\n" not in str(error.value)


def _with_normalizer(change: Callable[[dict], None]) -> Callable[[Path, Path], Path]:
    def rewrite(source: Path, target: Path) -> Path:
        data = json.loads(zipfile.ZipFile(source).read(NORMALIZER))
        change(data)
        return _rewrite(source, target, NORMALIZER, json.dumps(data).encode())

    return rewrite


@pytest.mark.parametrize("case, change", [
    ("var too short", lambda d: d.update(var=d["var"][:-1])),
    ("var too long", lambda d: d.update(var=[*d["var"], 1.0])),
    ("mean too short", lambda d: d.update(mean=d["mean"][:-1])),
    ("var as a matrix", lambda d: d.update(var=[d["var"]])),
])
def test_normaliser_statistics_of_the_wrong_length_are_refused(ppo_zip, tmp_path, case, change):
    bad = _with_normalizer(change)(ppo_zip, tmp_path / "bad.zip")
    with pytest.raises(ConfigError) as error:
        PolicyFile(bad).normalizer(7)
    _assert_one_line_refusal(error, bad, NORMALIZER, "must hold 7 values each")
    with pytest.raises(ConfigError, match="must hold 7 values each"):
        load_policy(bad)


# -- weights that do not fit ---------------------------------------------------------------------


def _misshapen_weight(source: Path, target: Path) -> Path:
    """The zip with one tensor of its policy's weights given another shape (one more output)."""
    weights = _tensors(source, "policy.pth")
    weights["action_net.bias"] = torch.zeros(weights["action_net.bias"].shape[0] + 1)
    return _rewrite(source, target, "policy.pth", _saved(weights))


def test_a_policy_with_a_weight_of_the_wrong_shape_is_refused(ppo_zip, tmp_path):
    bad = _misshapen_weight(ppo_zip, tmp_path / "bad.zip")
    with pytest.raises(ConfigError) as error:
        load_policy(bad)
    _assert_one_line_refusal(error, bad, "policy.pth", "the weights do not fit")


@pytest.mark.parametrize("policy_only", [True, False], ids=["init_from", "resume"])
def test_loading_a_weight_of_the_wrong_shape_into_a_stage_is_refused(ppo_zip, tmp_path, policy_only):
    bad = _misshapen_weight(ppo_zip, tmp_path / "bad.zip")
    with pytest.raises(ConfigError) as error:
        load_weights(_model(PPO), bad, policy_only=policy_only)
    _assert_one_line_refusal(error, bad, "policy.pth", "the weights do not fit this stage's PPO network")


def test_the_weights_of_a_saved_policy_load_into_a_stage(ppo_zip):
    for policy_only in (True, False):
        model = _model(PPO)
        assert load_weights(model, ppo_zip, policy_only=policy_only) is not None
        saved = _tensors(ppo_zip, "policy.pth")
        assert all(torch.equal(model.policy.state_dict()[key], value) for key, value in saved.items())


def test_a_checkpoint_whose_optimiser_state_has_the_wrong_shape_is_refused_on_resume(ppo_zip, tmp_path):
    state = _tensors(ppo_zip, "policy.optimizer.pth")
    moments = state["state"][0]
    moments["exp_avg"] = torch.zeros(moments["exp_avg"].numel() + 1)
    bad = _rewrite(ppo_zip, tmp_path / "bad.zip", "policy.optimizer.pth", _saved(state))
    with pytest.raises(ConfigError) as error:
        load_weights(_model(PPO), bad, policy_only=False)
    _assert_one_line_refusal(error, bad, "policy.optimizer.pth", "the optimiser state does not fit")


def test_a_sac_checkpoint_whose_entropy_coefficient_has_the_wrong_shape_is_refused_on_resume(tmp_path):
    path = save_policy(_trained(SAC), tmp_path / "sac.zip", {"algorithm": "sac", **NAV7})
    load_weights(_model(SAC), path, policy_only=False)  # as saved, it loads
    variables = _tensors(path, "pytorch_variables.pth")
    variables["log_ent_coef"] = torch.zeros(2)
    bad = _rewrite(path, tmp_path / "bad.zip", "pytorch_variables.pth", _saved(variables))
    with pytest.raises(ConfigError) as error:
        load_weights(_model(SAC), bad, policy_only=False)
    _assert_one_line_refusal(error, bad, "pytorch_variables.pth", "log_ent_coef is missing or misshapen")


def test_a_bounded_mean_ppo_policy_acts_on_the_tanh_of_its_mean_and_loads_back_bounded(tmp_path):
    from common.curriculum.policy import policy_class

    env = gym.make("flatland/Nav-v0", world="open", observation="nav7")
    model = PPO(policy_class("ppo"), env, n_steps=64, batch_size=64, device="cpu", seed=0,
                policy_kwargs={"bounded_mean": True})
    with torch.no_grad():  # a mean far past the bounds: 3 and -4 before the tanh
        model.policy.action_net.weight.zero_()
        model.policy.action_net.bias.copy_(torch.tensor([3.0, -4.0]))
    observation = env.observation_space.sample()
    expected = np.tanh([3.0, -4.0]).astype(np.float32)
    assert np.allclose(model.predict(observation, deterministic=True)[0], expected, atol=1e-6)
    sampled = model.policy.get_distribution(torch.as_tensor(observation[None])).distribution
    assert np.allclose(sampled.mean.detach().numpy()[0], expected, atol=1e-6)  # training samples round it too
    path = save_policy(model, tmp_path / "bounded.zip", {"algorithm": "ppo", **NAV7})
    assert PolicyFile(path).manifest.policy_kwargs.bounded_mean is True
    agent = load_policy(path)
    assert np.allclose(agent.model.predict(observation, deterministic=True)[0], expected, atol=1e-6)
    # Unbounded, the same weights act at the bounds.
    plain = PPO(policy_class("ppo"), env, n_steps=64, batch_size=64, device="cpu", seed=0)
    plain.policy.load_state_dict(model.policy.state_dict())
    assert np.allclose(plain.predict(observation, deterministic=True)[0], [1.0, -1.0])


@pytest.mark.parametrize(("algorithm", "kwargs", "problem"), [
    ("sac", {"bounded_mean": True}, "bounded_mean: bounds a PPO policy's Gaussian mean; allowed: ppo (this stage's: sac)"),
    ("ppo", {"n_critics": 2}, "n_critics: a PPO policy has no critics to count; allowed: sac, td3 (this stage's: ppo)")])
def test_a_curriculum_refuses_policy_kwargs_its_algorithm_does_not_take(algorithm, kwargs, problem):
    # Without the check stable-baselines3 raises a TypeError when the stage starts training.
    from common.curriculum.schema import curriculum_from_mapping

    stage = {"name": "s", "scenarios": {"kind": "open"}, "algorithm": algorithm, "budget": 100,
             "eval": {"suite": "open"}, "hyperparams": {"policy_kwargs": kwargs}}
    with pytest.raises(ConfigError) as error:
        curriculum_from_mapping({"name": "c", "stages": [stage]}, "c.yaml")
    assert str(error.value) == f"c.yaml: stages.0.hyperparams.policy_kwargs.{problem}"


@pytest.mark.parametrize("name", ["stage1_2d_ppo", "curriculum_2d_ppo", "stage1_2d_sac", "stage1_2d_td3"])
def test_a_loaded_policy_acts_as_predict_does_for_every_observation(name):
    # The agent's own deterministic action skips stable-baselines3's per-call bookkeeping and the
    # action distribution; it must give predict's action to the bit: PPO's mean through tanh
    # (stage1_2d_ppo's is bounded) or clipped into the bounds (curriculum_2d_ppo's is not), SAC's
    # unscaled from its squashed mean, TD3's actor, and predict's own in training mode.
    agent = load_policy(Path(__file__).resolve().parents[1] / "curricula" / "policies" / f"{name}.zip")
    observations = np.random.default_rng(0).uniform(-3.0, 3.0, (500, agent.model.observation_space.shape[0]))
    observations = observations.astype(np.float32)
    for observation in observations:
        assert np.array_equal(agent.predict(observation), agent.model.predict(observation, deterministic=True)[0])
    agent.model.set_training_mode(True)
    assert np.array_equal(agent.predict(observations[0]), agent.model.predict(observations[0], deterministic=True)[0])


@pytest.mark.parametrize("algorithm", ["ppo", "sac"])
def test_a_gsde_policy_acts_through_predict_s_own_path(algorithm):
    # The policies the agent reads no mean layer from (gSDE's) act as predict does too.
    from common.curriculum.policy import DeterministicAction
    from common.curriculum.policy_file import Manifest

    manifest = Manifest.model_validate({"format": 2, "algorithm": algorithm, "observation": "lidar43_log",
                                        "goal_distance_scale": 10.0, "use_sde": True})
    policy = build_policy(manifest)
    policy.set_training_mode(False)
    observations = np.random.default_rng(1).uniform(-3.0, 3.0, (50, policy.observation_space.shape[0]))
    act = DeterministicAction(policy)
    for observation in observations.astype(np.float32):
        assert np.array_equal(act(observation), policy.predict(observation, deterministic=True)[0])
