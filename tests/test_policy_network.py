"""The PPO policy's direct layer calls and the runner's optimiser settings change speed, never numbers."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import PPO, SAC

import flatland  # noqa: F401  (registers the env)
from common.curriculum.policy import NavActorCriticPolicy, optimizers_step_together

OBSERVATIONS = gym.spaces.Box(-1.0, 1.0, (43,), np.float32)
ACTIONS = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)


def _policy(**kwargs) -> NavActorCriticPolicy:
    torch.manual_seed(0)
    return NavActorCriticPolicy(OBSERVATIONS, ACTIONS, lambda _: 3e-4, **kwargs)


@pytest.mark.parametrize("kwargs", [
    {"bounded_mean": True},
    {},
    {"activation_fn": torch.nn.ReLU, "net_arch": [32, 16, 8]},
    {"share_features_extractor": False, "net_arch": {"pi": [64, 64], "vf": [32]}},
])
def test_direct_layer_calls_give_stable_baselines3_s_actions_values_log_probs_and_gradients(kwargs):
    fast = _policy(**kwargs)
    assert fast._layers is not None, "the plain MLP must take the direct path, or this test compares nothing"
    stock = _policy(**kwargs)
    stock._layers = None  # stable-baselines3's own module calls
    observations = torch.as_tensor(np.random.default_rng(0).uniform(-1.0, 1.0, (8, 43)), dtype=torch.float32)
    outputs = []
    for policy in (fast, stock):
        torch.manual_seed(1)
        actions, values, log_prob = policy(observations)
        evaluated = policy.evaluate_actions(observations, actions.detach())
        loss = sum(output.sum() for output in evaluated)
        loss.backward()
        gradients = [parameter.grad for parameter in policy.parameters()]
        outputs.append([actions, values, log_prob, *evaluated, policy.actor_latent(observations), *gradients])
    for ours, theirs in zip(*outputs):
        assert torch.equal(ours, theirs)


def test_a_network_the_direct_path_does_not_know_goes_through_stable_baselines3():
    from stable_baselines3.common.torch_layers import CombinedExtractor

    space = gym.spaces.Dict({"state": OBSERVATIONS})
    policy = NavActorCriticPolicy(space, ACTIONS, lambda _: 3e-4, features_extractor_class=CombinedExtractor)
    assert policy._layers is None
    actions, values, _ = policy({"state": torch.zeros(3, 43)})
    assert actions.shape == (3, 2) and values.shape == (3, 1)


def _weights(model) -> torch.Tensor:
    return torch.cat([parameter.detach().flatten() for parameter in model.policy.parameters()])


@pytest.mark.parametrize("algorithm", [PPO, SAC])
def test_training_with_the_runner_s_settings_gives_the_same_weights_to_the_bit(algorithm):
    def trained(runner_settings: bool) -> tuple[torch.Tensor, torch.Tensor]:
        env = gym.make("flatland/Nav-v0", world="sparse", observation="lidar43_log")
        if algorithm is PPO:
            model = PPO(NavActorCriticPolicy, env, n_steps=256, batch_size=64, n_epochs=2, seed=0, device="cpu",
                        policy_kwargs={"bounded_mean": True})
        else:
            model = SAC("MlpPolicy", env, learning_starts=64, batch_size=32, seed=0, device="cpu",
                        policy_kwargs={"net_arch": [32, 32]})
        if runner_settings:
            optimizers_step_together(model)
            optimizers = [model.policy.optimizer] if algorithm is PPO else [model.actor.optimizer, model.critic.optimizer,
                                                                         model.ent_coef_optimizer]
            assert all(group["foreach"] for optimizer in optimizers for group in optimizer.param_groups)
        elif algorithm is PPO:
            model.policy._layers = None
        initial = _weights(model)
        model.learn(512)
        return initial, _weights(model)

    initial, fast = trained(True)
    assert not torch.equal(initial, fast)  # it trained
    assert torch.equal(fast, trained(False)[1])
