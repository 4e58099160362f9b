"""The PPO policy's direct layer calls and the runner's optimiser settings change speed, never numbers."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import PPO, SAC, TD3
from stable_baselines3.common.policies import ActorCriticPolicy, BaseModel

import flatland  # noqa: F401  (registers the env)
from common.curriculum.policy import NavActorCriticPolicy, use_optimizer_kernels

OBSERVATIONS = gym.spaces.Box(-1.0, 1.0, (43,), np.float32)
ACTIONS = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
BATCH = torch.as_tensor(np.random.default_rng(0).uniform(-1.0, 1.0, (8, 43)), dtype=torch.float32)


@pytest.fixture(autouse=True)
def _argument_checks_off():
    """As the runner trains: torch's distribution argument checks off, so the policy's own Gaussian runs."""
    checks = torch.distributions.Distribution._validate_args
    torch.distributions.Distribution.set_default_validate_args(False)
    yield
    torch.distributions.Distribution.set_default_validate_args(checks)


def _policy(space=OBSERVATIONS, **kwargs) -> NavActorCriticPolicy:
    torch.manual_seed(0)
    return NavActorCriticPolicy(space, ACTIONS, lambda _: 3e-4, **kwargs)


def _outputs(policy: NavActorCriticPolicy, forward, evaluate_actions, observations=BATCH) -> list[torch.Tensor]:
    """Actions, values and log-probabilities of a forward pass, then the values, log-probabilities,
    entropy and every parameter's gradient of evaluating those actions, each pass from the same seed."""
    policy.zero_grad()
    torch.manual_seed(1)
    actions, values, log_prob = forward(policy, observations)
    evaluated = [output for output in evaluate_actions(policy, observations, actions.detach()) if output is not None]
    sum(output.sum() for output in evaluated).backward()
    return [actions, values, log_prob, *evaluated, *(parameter.grad for parameter in policy.parameters())]


def _assert_as_stable_baselines3(policy: NavActorCriticPolicy, observations=BATCH) -> None:
    ours = _outputs(policy, NavActorCriticPolicy.forward, NavActorCriticPolicy.evaluate_actions, observations)
    theirs = _outputs(policy, ActorCriticPolicy.forward, ActorCriticPolicy.evaluate_actions, observations)
    assert len(ours) == len(theirs)
    for mine, reference in zip(ours, theirs):
        assert torch.equal(mine, reference)
    with torch.no_grad():
        deterministic = [NavActorCriticPolicy.forward(policy, observations, deterministic=True),
                         ActorCriticPolicy.forward(policy, observations, deterministic=True)]
    for mine, reference in zip(*deterministic):
        assert torch.equal(mine, reference)


@pytest.mark.parametrize("kwargs", [
    {"bounded_mean": True},
    {},
    {"activation_fn": torch.nn.ReLU, "net_arch": [32, 16, 8]},
    {"share_features_extractor": False, "net_arch": {"pi": [64, 64], "vf": [32]}},
    {"use_sde": True, "bounded_mean": True},
    {"use_sde": True},
])
def test_direct_layer_calls_give_stable_baselines3_s_own_numbers_and_gradients(kwargs):
    policy = _policy(**kwargs)
    assert policy._plain_layers() is not None, "the plain MLP must take the direct path, or this test compares nothing"
    assert policy._plain_gaussian() == (not kwargs.get("use_sde", False))  # gSDE's distribution is SB3's own
    _assert_as_stable_baselines3(policy)
    latent = policy.mlp_extractor.forward_actor(BaseModel.extract_features(policy, BATCH, policy.pi_features_extractor))
    assert torch.equal(policy.actor_latent(BATCH), latent)


def test_a_bounded_mean_under_gsde_keeps_the_distribution_s_centre_inside_the_bounds():
    policy = _policy(use_sde=True, bounded_mean=True)
    with torch.no_grad():
        policy.action_net.bias.fill_(5.0)
        distribution = policy.get_distribution(BATCH)
    assert torch.equal(distribution.distribution.mean, torch.tanh(policy.action_net(policy.actor_latent(BATCH))))
    assert distribution.distribution.mean.max() < 1.0


def test_a_hook_or_a_swapped_layer_is_seen_as_stable_baselines3_would_see_it():
    policy = _policy(bounded_mean=True)
    for layer in (policy.mlp_extractor.policy_net[0], policy.value_net, policy.action_net):
        handle = layer.register_forward_hook(lambda module, args, output: output * 0.5)
        assert policy._plain_layers() is None
        _assert_as_stable_baselines3(policy)
        handle.remove()
    global_handle = torch.nn.modules.module.register_module_forward_hook(lambda module, args, output: None)
    try:
        assert policy._plain_layers() is None
    finally:
        global_handle.remove()
    torch.manual_seed(2)
    policy.mlp_extractor.value_net[0] = torch.nn.Linear(43, 64)  # surgery after construction
    assert policy._plain_layers() is not None
    _assert_as_stable_baselines3(policy)


def test_a_network_the_direct_path_does_not_know_goes_through_stable_baselines3():
    from stable_baselines3.common.torch_layers import CombinedExtractor

    policy = _policy(gym.spaces.Dict({"state": OBSERVATIONS}), features_extractor_class=CombinedExtractor)
    assert policy._plain_layers() is None
    _assert_as_stable_baselines3(policy, {"state": BATCH})
    policy = _policy(bounded_mean=True)
    policy.direct_layer_calls = False
    assert policy._plain_layers() is None


def _weights(model) -> torch.Tensor:
    return torch.cat([parameter.detach().flatten() for parameter in model.policy.parameters()])


@pytest.mark.slow
@pytest.mark.parametrize("algorithm", [PPO, SAC])
def test_training_with_the_runner_s_settings_gives_the_same_weights_to_the_bit(algorithm):
    def trained(runner_settings: bool) -> tuple[torch.Tensor, torch.Tensor]:
        env = gym.make("flatland/Nav-v0", world="sparse", observation="lidar43_log")
        if algorithm is PPO:
            model = PPO(NavActorCriticPolicy, env, n_steps=256, batch_size=64, n_epochs=2, seed=0, device="cpu",
                        policy_kwargs={"bounded_mean": True})
            model.policy.direct_layer_calls = runner_settings
        else:
            model = SAC("MlpPolicy", env, learning_starts=64, batch_size=32, seed=0, device="cpu",
                        policy_kwargs={"net_arch": [32, 32]})
        if runner_settings:
            use_optimizer_kernels(model)
            assert all(group["foreach"] for optimizer in _optimizers(model) for group in optimizer.param_groups)
        initial = _weights(model)
        model.learn(512)
        return initial, _weights(model)

    initial, fast = trained(True)
    assert not torch.equal(initial, fast)  # it trained
    assert torch.equal(fast, trained(False)[1])


def _optimizers(model) -> list[torch.optim.Optimizer]:
    if isinstance(model, PPO):
        return [model.policy.optimizer]
    return [model.actor.optimizer, model.critic.optimizer] + ([model.ent_coef_optimizer] if isinstance(model, SAC) else [])


@pytest.mark.parametrize("algorithm", [PPO, SAC, TD3])
def test_fused_kernels_do_every_optimiser_s_updates(algorithm, monkeypatch):
    import torch.optim.adam as adam

    fused_calls: list[int] = []  # the id of the first tensor each fused update was given
    monkeypatch.setattr(adam, "_fused_adam", lambda params, *args, _fused=adam._fused_adam, **kwargs: (
        fused_calls.append(id(params[0])), _fused(params, *args, **kwargs))[1])
    env = gym.make("flatland/Nav-v0", world="sparse", observation="lidar43_log")
    model = (PPO("MlpPolicy", env, n_steps=64, batch_size=32, n_epochs=1, seed=0, device="cpu") if algorithm is PPO
             else algorithm("MlpPolicy", env, learning_starts=32, batch_size=16, seed=0, device="cpu",
                            policy_kwargs={"net_arch": [16, 16]}))
    steps: dict[int, int] = {}
    for optimizer in _optimizers(model):
        optimizer.register_step_post_hook(lambda opt, args, kwargs: steps.update({id(opt): steps.get(id(opt), 0) + 1}))
    use_optimizer_kernels(model, "fused")
    model.learn(64)
    assert len(steps) == len(_optimizers(model))  # every optimiser stepped
    assert len(fused_calls) == sum(steps.values())  # and each step was a fused one
    firsts = {id(group["params"][0]) for optimizer in _optimizers(model) for group in optimizer.param_groups}
    assert set(fused_calls) == firsts
    use_optimizer_kernels(model, None)  # torch's own choice again: its loop on CPU
    assert all(group["foreach"] is None and group["fused"] is None
               for optimizer in _optimizers(model) for group in optimizer.param_groups)
    fused, stepped = len(fused_calls), sum(steps.values())
    model.learn(64, reset_num_timesteps=False)
    assert sum(steps.values()) > stepped and len(fused_calls) == fused
    with pytest.raises(ValueError, match="allowed: foreach, fused or None"):
        use_optimizer_kernels(model, "together")


def test_with_torch_s_argument_checks_on_a_nan_mean_is_refused_as_stable_baselines3_refuses_it():
    policy = _policy(bounded_mean=True)
    with torch.no_grad():
        policy.action_net.bias.fill_(float("nan"))
    actions, _, _ = policy.forward(BATCH)  # checks off, as the runner trains: the envs refuse a NaN action
    assert torch.isnan(actions).all()
    torch.distributions.Distribution.set_default_validate_args(True)  # the fixture restores torch's setting
    with pytest.raises(ValueError, match="loc"):
        policy.forward(BATCH)
