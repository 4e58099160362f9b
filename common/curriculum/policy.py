"""Trained policies: rebuilt from a policy zip's manifest and weights, and driven like a controller.

:func:`load_policy` reads ``policy.pth`` first (weights only; see :mod:`common.curriculum.policy_file`),
then checks that the network the manifest describes is no larger than those weights, counted from
the manifest alone (:func:`network_parameters`), and only then builds it and loads the weights
into it: the weights' tensors are the truth, and a manifest describing a network of gigabytes
beside small weights is refused before anything is allocated. A zip whose weights do not fit its
manifest is refused with a one-line :class:`ConfigError`. Resuming training and ``init_from``
load weights the same way into a model built from the curriculum's own hyperparameters.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch
from stable_baselines3.common.distributions import DiagGaussianDistribution, StateDependentNoiseDistribution
from stable_baselines3.common.policies import ActorCriticPolicy, BaseModel
from stable_baselines3.common.torch_layers import FlattenExtractor, MlpExtractor
from torch import nn
from torch.nn.modules.module import (_global_backward_hooks, _global_backward_pre_hooks, _global_forward_hooks,
                                     _global_forward_pre_hooks)

from common.actions import ACTION_SPACE
from common.curriculum.hyperparams import OPTIMIZER_KERNELS
from common.curriculum.policy_file import MANIFEST, Manifest, PolicyFile
from common.errors import ConfigError, quote
from common.files import size_text
from common.observations import make_layout
from common.policy_agent import PolicyAgent
from common.scenario import LidarSpec, RobotProfile

POLICY_WEIGHTS = "policy"  # policy.pth: the network's state dict
VARIABLES = "pytorch_variables"  # pytorch_variables.pth: e.g. SAC's entropy coefficient


def algorithm_class(name: str):
    """The stable-baselines3 class of an algorithm name."""
    from stable_baselines3 import PPO, SAC, TD3

    return {"ppo": PPO, "sac": SAC, "td3": TD3}[name]


def policy_class(algorithm: str):
    """The policy class a stage trains and a manifest rebuilds: stable-baselines3's MlpPolicy, and
    for PPO :class:`NavActorCriticPolicy` (the same network, able to bound its mean)."""
    return NavActorCriticPolicy if algorithm == "ppo" else algorithm_class(algorithm).policy_aliases["MlpPolicy"]


class NavActorCriticPolicy(ActorCriticPolicy):
    """PPO's MlpPolicy, and with ``bounded_mean`` its Gaussian's mean squashed into [-1, 1] by tanh.

    The action space clips what PPO samples. Its plain Gaussian mean can drift past a bound
    where every sample is clipped alike, so the gradient no longer tells it to come back: the
    deterministic action then stays at the bound (full speed beside an obstacle, or standing
    still where training's noise would have crept on; docs/training.md). A bounded mean keeps
    the distribution's centre inside the actions it can take. The network and its weights are
    SB3's own: only where the mean is read changes, and (:meth:`_plain_layers`) how its layers
    are called, which changes the time and not a bit of the result.
    """

    #: Whether the plain MLP's layers may be called directly and its Gaussian worked out without
    #: torch's ``Normal`` (:meth:`_plain_layers`, :meth:`_plain_gaussian`; False: always through
    #: stable-baselines3's module calls and distribution; the numbers are the same either way).
    direct_layer_calls = True

    def __init__(self, *args, bounded_mean: bool = False, **kwargs) -> None:
        self.bounded_mean = bounded_mean
        super().__init__(*args, **kwargs)
        from common.curriculum.hyperparams import activation_classes

        self._plain_types = frozenset((nn.Linear, *activation_classes().values()))

    def forward(self, obs: torch.Tensor, deterministic: bool = False) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        heads = self._direct_heads(obs)
        if heads is None:
            return super().forward(obs, deterministic)
        latent_pi, values = heads
        if self._plain_gaussian():
            mean, std = self._gaussian(latent_pi)
            actions = mean if deterministic else _gaussian_sample(mean, std)
            log_prob = _gaussian_log_prob(actions, mean, std)
        else:
            distribution = self._get_action_dist_from_latent(latent_pi)
            actions = distribution.get_actions(deterministic=deterministic)
            log_prob = distribution.log_prob(actions)
        return actions.reshape((-1, *self.action_space.shape)), values, log_prob

    def evaluate_actions(self, obs: torch.Tensor,
                         actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        heads = self._direct_heads(obs)
        if heads is None:
            return super().evaluate_actions(obs, actions)
        latent_pi, values = heads
        if self._plain_gaussian():
            mean, std = self._gaussian(latent_pi)
            return values, _gaussian_log_prob(actions, mean, std), _gaussian_entropy(std)
        distribution = self._get_action_dist_from_latent(latent_pi)
        return values, distribution.log_prob(actions), distribution.entropy()

    def _direct_heads(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor] | None:
        """The actor's latent code and the critic's values, the layers called directly
        (:meth:`_plain_layers`); None where stable-baselines3's own calls must run."""
        layers = self._plain_layers()
        if layers is None:
            return None
        features = _flat(obs)
        return _through(layers[0], features), _through(layers[1], features)

    def actor_latent(self, obs: torch.Tensor) -> torch.Tensor:
        """The actor's latent code (what its action reads), as stable-baselines3 computes it."""
        layers = self._plain_layers()
        if layers is None:
            return self.mlp_extractor.forward_actor(BaseModel.extract_features(self, obs, self.pi_features_extractor))
        return _through(layers[0], _flat(obs))

    def _plain_layers(self) -> tuple[tuple[nn.Module, ...], tuple[nn.Module, ...]] | None:
        """The actor's hidden layers and the critic's (ending in its value head), in order, where
        this is stable-baselines3's plain MLP as it is now: flat Box observations, flattening
        feature extractors, layers of ``nn.Linear`` and the activations a curriculum may name, a
        linear mean head, and no hook on any of them nor a global one. Then :meth:`forward`,
        :meth:`evaluate_actions` and :meth:`actor_latent` run the layers' own ``forward`` one
        after another, to the same bit as stable-baselines3: calling
        each module through ``nn.Module.__call__`` was 60% of the forward pass of a batch of eight,
        61 µs of 146, once per rollout step and minibatch. None otherwise (a custom extractor, a
        layer swapped in, a hook registered since construction): stable-baselines3's own calls run.
        Asked at every call: 5–7 µs in a slow hour of this machine."""
        if not self.direct_layer_calls:
            return None
        # Through _modules: nn.Module.__getattr__ would cost more than the rest of the check.
        own = self._modules
        mlp, pi_extractor, vf_extractor = own["mlp_extractor"], own["pi_features_extractor"], own["vf_features_extractor"]
        if (type(mlp) is not MlpExtractor or type(pi_extractor) is not FlattenExtractor
                or type(vf_extractor) is not FlattenExtractor or len(self.observation_space.shape) != 1):
            return None
        actor, critic = mlp._modules["policy_net"], mlp._modules["value_net"]
        actor_layers, critic_layers = tuple(actor._modules.values()), (*critic._modules.values(), own["value_net"])
        mean_head, plain = own["action_net"], self._plain_types
        if (any(type(layer) not in plain for layer in actor_layers + critic_layers) or type(mean_head) is not nn.Linear
                or _hooked((mlp, actor, critic, pi_extractor, vf_extractor, mean_head, *actor_layers, *critic_layers))):
            return None
        return actor_layers, critic_layers

    def mean_actions(self, latent_pi: torch.Tensor) -> torch.Tensor:
        """The Gaussian's mean, bounded where ``bounded_mean``: its deterministic action."""
        return self._bounded(self.action_net(latent_pi))

    def _bounded(self, mean: torch.Tensor) -> torch.Tensor:
        return torch.tanh(mean) if self.bounded_mean else mean

    def _plain_gaussian(self) -> bool:
        """Whether the actions are stable-baselines3's diagonal Gaussian (not gSDE, not another
        distribution): then :func:`_gaussian_log_prob` and :func:`_gaussian_entropy` give its
        numbers to the bit without building torch's ``Normal`` around them, which with SB3's
        bookkeeping took about 40% of a rollout step's forward pass for a batch of eight. Not while
        torch checks distributions' arguments (its default; the runner turns the checks off): then
        ``Normal`` is built, so a NaN mean or a zero deviation is refused as stable-baselines3 would."""
        return (type(self.action_dist) is DiagGaussianDistribution
                and not torch.distributions.Distribution._validate_args)

    def _gaussian(self, latent_pi: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The Gaussian's mean and standard deviation, as DiagGaussianDistribution makes them (the
        mean head called directly: :meth:`_plain_layers` has checked it is a plain layer)."""
        mean = self._bounded(self._modules["action_net"].forward(latent_pi))
        return mean, torch.ones_like(mean) * self.log_std.exp()

    def _get_action_dist_from_latent(self, latent_pi: torch.Tensor):
        if not self.bounded_mean:
            return super()._get_action_dist_from_latent(latent_pi)
        if isinstance(self.action_dist, StateDependentNoiseDistribution):  # gSDE: noise from the latent code
            return self.action_dist.proba_distribution(self.mean_actions(latent_pi), self.log_std, latent_pi)
        return self.action_dist.proba_distribution(self.mean_actions(latent_pi), self.log_std)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        return {**super()._get_constructor_parameters(), "bounded_mean": self.bounded_mean}


def _hooked(modules: tuple[nn.Module, ...]) -> bool:
    """Whether a forward or backward hook would run when any of ``modules`` is called."""
    return bool(_global_forward_hooks or _global_forward_pre_hooks or _global_backward_hooks
                or _global_backward_pre_hooks) or any(
        m._forward_hooks or m._forward_pre_hooks or m._backward_hooks or m._backward_pre_hooks for m in modules)


def _flat(obs: torch.Tensor) -> torch.Tensor:
    """What stable-baselines3's preprocessing of a Box and its FlattenExtractor make of ``obs``."""
    return obs.float().flatten(1)


# torch's Normal's constants, computed as it computes them.
_LOG_SQRT_2PI = math.log(math.sqrt(2 * math.pi))
_ENTROPY_CONSTANT = 0.5 + 0.5 * math.log(2 * math.pi)


def _gaussian_sample(mean: torch.Tensor, std: torch.Tensor) -> torch.Tensor:
    """Normal(mean, std).rsample(): the same draw from torch's generator, the same arithmetic."""
    return mean + torch.empty(mean.shape, dtype=mean.dtype, device=mean.device).normal_() * std


def _gaussian_log_prob(actions: torch.Tensor, mean: torch.Tensor, std: torch.Tensor) -> torch.Tensor:
    """Normal(mean, std).log_prob(actions) summed over the action's dimensions, in torch's own
    operations and order (so the same bits and gradients)."""
    return (-((actions - mean) ** 2) / (2 * std**2) - std.log() - _LOG_SQRT_2PI).sum(dim=1)


def _gaussian_entropy(std: torch.Tensor) -> torch.Tensor:
    """Normal(mean, std).entropy() summed over the action's dimensions, as torch computes it."""
    return (_ENTROPY_CONSTANT + torch.log(std)).sum(dim=1)


def _through(layers: tuple[nn.Module, ...], x: torch.Tensor) -> torch.Tensor:
    for layer in layers:
        x = layer.forward(x)
    return x


class DeterministicAction:
    """``policy.predict(observation, deterministic=True)[0]`` for one observation at a time, to the
    bit, 2.7-3.9 times as fast (``curriculum bench``'s ``agent_vs_torch_ppo`` and ``_sac``): the
    same layers on the same tensors and the same clipping or unscaling of the action,
    without stable-baselines3's per-call bookkeeping (every module switched to evaluation mode
    again, the observation's shape checks) and without the action distribution built only to read
    its mode, which for these policies is their mean (see :func:`mean_action`; where torch's
    argument checks are on, ``predict`` refuses a NaN mean that this passes on). A policy
    in training mode, or an observation of another shape, goes through ``predict`` itself."""

    def __init__(self, policy) -> None:
        self.policy = policy
        self.device = policy.device  # a property that walks the parameters on every call
        self.network = mean_action(policy) or (lambda tensor: policy._predict(tensor, deterministic=True))

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        policy = self.policy
        if policy.training or observation.shape != policy.observation_space.shape:
            return policy.predict(observation, deterministic=True)[0]
        with torch.no_grad():
            action = self.network(torch.as_tensor(observation, device=self.device)[None])
        action = action.cpu().numpy()[0]
        if policy.squash_output:
            return policy.unscale_action(action)
        return np.clip(action, policy.action_space.low, policy.action_space.high)


def mean_action(policy) -> Callable[[torch.Tensor], torch.Tensor] | None:
    """The layers that compute ``policy``'s deterministic action, skipping the distribution built
    around them: PPO's Gaussian mean (through tanh where ``bounded_mean``), SAC's squashed mean,
    TD3's actor. None where the mode is not that mean alone (gSDE, another distribution)."""
    from stable_baselines3.sac.policies import SACPolicy
    from stable_baselines3.td3.policies import TD3Policy

    # Exact types: a subclass may read its action elsewhere (every PPO policy here is a NavActorCriticPolicy).
    if type(policy) is NavActorCriticPolicy and type(policy.action_dist) is DiagGaussianDistribution:

        return lambda observations: policy.mean_actions(policy.actor_latent(observations))
    if type(policy) is SACPolicy and not policy.actor.use_sde:
        actor = policy.actor
        return lambda observations: torch.tanh(actor.mu(actor.latent_pi(
            actor.extract_features(observations, actor.features_extractor))))
    if type(policy) is TD3Policy:
        return policy.actor
    return None


def vec_env_class(name: str):
    """The VecEnv class of a stage's ``vec_env``: ``dummy`` (the envs in this process,
    :class:`~common.curriculum.vec_envs.FreshInfoVecEnv`) or ``subproc`` (a process per env,
    :class:`~common.curriculum.vec_envs.PreloadedSubprocVecEnv`)."""
    from common.curriculum.vec_envs import FreshInfoVecEnv, PreloadedSubprocVecEnv

    return {"dummy": FreshInfoVecEnv, "subproc": PreloadedSubprocVecEnv}[name]


def observation_space(manifest: Manifest):
    """The Box a policy of this manifest reads (its shape depends on the layout alone)."""
    return make_layout(manifest.observation, RobotProfile(), LidarSpec(), manifest.goal_distance_scale).space


DEFAULT_NET_ARCH = {"ppo": [64, 64], "sac": [256, 256], "td3": [400, 300]}  # SB3's MlpPolicy defaults
DEFAULT_N_CRITICS = 2


def _mlp(sizes: list[int]) -> int:
    """Parameters of a chain of Linear layers through ``sizes`` (weights and biases)."""
    return sum(a * b + b for a, b in zip(sizes, sizes[1:]))


def network_parameters(manifest: Manifest, source: str | Path | None = None) -> int:
    """How many parameters the policy network the manifest describes holds, counted without
    building it (stable-baselines3's MlpPolicy: tests check the count against built networks).

    A combination SB3 would refuse with an assertion or a TypeError is a one-line ConfigError.
    """
    kwargs = manifest.policy_kwargs
    algorithm, net_arch = manifest.algorithm, kwargs.net_arch
    field = f"{MANIFEST}: policy_kwargs"
    obs = int(observation_space(manifest).shape[0])
    act = int(ACTION_SPACE.shape[0])
    if refusal := kwargs.refused_by(algorithm):
        raise ConfigError(source, f"{field}.{refusal[0]}", refusal[1])
    if algorithm == "ppo":
        if net_arch is None:
            pi = vf = DEFAULT_NET_ARCH["ppo"]
        elif isinstance(net_arch, dict):
            pi, vf = net_arch.get("pi", []), net_arch.get("vf", [])
        else:
            pi = vf = net_arch
        latent_pi, latent_vf = (pi or [obs])[-1], (vf or [obs])[-1]
        log_std = latent_pi * act if manifest.use_sde else act
        return _mlp([obs, *pi]) + _mlp([obs, *vf]) + _mlp([latent_pi, act]) + _mlp([latent_vf, 1]) + log_std
    if net_arch is None:
        pi = qf = DEFAULT_NET_ARCH[algorithm]
    elif isinstance(net_arch, dict):
        if not {"pi", "qf"} <= net_arch.keys():
            raise ConfigError(source, f"{field}.net_arch", f"a {algorithm.upper()} network needs both pi and qf")
        pi, qf = net_arch["pi"], net_arch["qf"]
    else:
        pi = qf = net_arch
    critics = kwargs.n_critics or DEFAULT_N_CRITICS
    critic = critics * _mlp([obs + act, *qf, 1])
    latent = (pi or [obs])[-1]
    if algorithm == "sac":
        log_std = latent * act if manifest.use_sde else latent * act + act  # a parameter, or a Linear layer
        actor = _mlp([obs, *pi]) + _mlp([latent, act]) + log_std
        return actor + 2 * critic  # the critic and its target
    return 2 * _mlp([obs, *pi, act]) + 2 * critic  # TD3: the actor, the critic and their targets


def _tensor_bytes(state: Any) -> int:
    import torch

    if isinstance(state, dict):
        return sum(v.numel() * v.element_size() for v in state.values() if isinstance(v, torch.Tensor))
    return 0


def check_network(manifest: Manifest, state: Any, file: PolicyFile, name: str) -> None:
    """Refuse a manifest whose network would take more memory than the weights beside it hold
    (float32, as SB3 builds it), before anything is built: those weights could never fit it."""
    needed = 4 * network_parameters(manifest, file.path)
    held = _tensor_bytes(state)
    if needed > held:
        raise ConfigError(file.path, f"{name}.pth", f"the weights do not fit a {manifest.algorithm.upper()} policy "
                          f"of {size_text(needed)} of parameters, they hold {size_text(held)} (the manifest's "
                          f"policy_kwargs: {quote(manifest.policy_kwargs.model_dump(exclude_none=True))}); refused")


def build_policy(manifest: Manifest, device: str = "cpu", initialise: bool = True):
    """A fresh SB3 policy network shaped as the manifest says.

    ``initialise=False`` skips PPO's orthogonal initialisation (seconds for a large network),
    for a network whose every weight is about to be loaded.
    """
    kwargs: dict[str, Any] = manifest.policy_kwargs.to_sb3()
    if manifest.algorithm in ("ppo", "sac"):
        kwargs["use_sde"] = manifest.use_sde
    if manifest.algorithm == "ppo" and not initialise:
        kwargs["ortho_init"] = False
    policy = policy_class(manifest.algorithm)(observation_space(manifest), ACTION_SPACE, lambda _: 0.0, **kwargs)
    return policy.to(device)


def _load_module(module, state: Any, file: PolicyFile, name: str, what: str) -> None:
    try:
        module.load_state_dict(state, strict=True)
    except (RuntimeError, TypeError, ValueError, AttributeError):
        raise ConfigError(file.path, f"{name}.pth", f"the weights do not fit {what}; refused") from None


def _network_description(manifest: Manifest) -> str:
    net = manifest.policy_kwargs.model_dump(exclude_none=True) or "SB3's defaults"
    return f"a {manifest.algorithm.upper()} policy with policy_kwargs {net} (the manifest's)"


def load_policy(path: str | Path | PolicyFile, device: str = "cpu", name: str | None = None) -> PolicyAgent:
    """A :class:`PolicyAgent` from a policy zip, or one already opened (nothing in the zip is executed)."""
    file = path if isinstance(path, PolicyFile) else PolicyFile(path)
    path = file.path
    manifest = file.manifest
    state = file.tensors(f"{POLICY_WEIGHTS}.pth", device)
    check_network(manifest, state, file, POLICY_WEIGHTS)  # before anything is built
    normalizer = file.normalizer(observation_space(manifest).shape[0])
    file.close()  # the zip's bytes are not needed while the network is built
    policy = build_policy(manifest, device, initialise=False)  # strict loading below sets every weight
    _load_module(policy, state, file, POLICY_WEIGHTS, _network_description(manifest))
    del state
    policy.set_training_mode(False)
    if name is None:
        # A run's files are all called policy/best/last.zip: name those by curriculum and stage.
        stem = Path(path).stem
        extra = file.raw_manifest
        generic = stem in ("policy", "best", "last") and "curriculum" in extra and "stage" in extra
        name = f"{extra['curriculum']}/{extra['stage']}" if generic else stem
    return PolicyAgent(policy, manifest.observation, manifest.goal_distance_scale, normalizer, name=str(name),
                       action_mapping=manifest.action_mapping, max_steps=manifest.max_steps,
                       env_kwargs=manifest.env_kwargs, home=manifest.home,
                       tier=manifest.tier, predict=DeterministicAction(policy),
                       reopen=(load_policy, (str(path), device, str(name))))


def load_weights(model, path: str | Path, policy_only: bool) -> PolicyFile | None:
    """Load a zip's weights into a model built from the curriculum (resume, or ``init_from``).

    ``policy_only`` loads the network alone (a new stage starting from a trained policy; the zip
    may be any SB3 zip with matching weights). Otherwise the optimiser states, the extra torch
    variables and the step counters are restored too (resuming the same stage from its checkpoint).
    Returns the :class:`PolicyFile` when the zip is one of this project's (None for a foreign one).
    """
    file = PolicyFile(path, require_manifest=not policy_only)
    what = f"this stage's {type(model).__name__} network"
    states, variables = model._get_torch_save_params()
    for name in states if not policy_only else [POLICY_WEIGHTS]:
        target = _attribute(model, name)
        state = file.tensors(f"{name}.pth", model.device)
        if name == POLICY_WEIGHTS:
            if policy_only and file.manifest is not None:
                state = widened(state, file, int(model.observation_space.shape[0]))
            _load_module(target, state, file, name, what)
        else:
            try:
                target.load_state_dict(state)  # optimisers: the parameter counts are checked, not the shapes
                fits = _optimizer_state_fits(target)
            except (RuntimeError, TypeError, ValueError, KeyError, IndexError):
                fits = False
            if not fits:
                raise ConfigError(file.path, f"{name}.pth", f"the optimiser state does not fit {what}; refused")
    if policy_only:
        return file if file.manifest is not None else None
    saved = file.tensors(f"{VARIABLES}.pth", model.device) if variables else {}
    for name in variables:
        value = saved.get(name) if isinstance(saved, dict) else None
        target = _attribute(model, name)
        if value is None or getattr(value, "shape", None) != target.shape:
            raise ConfigError(file.path, f"{VARIABLES}.pth", f"{name} is missing or misshapen; refused")
        target.data.copy_(value)
    model.num_timesteps = file.manifest.timesteps
    model._n_updates = file.manifest.n_updates
    return file


# A layout that extends another (the same entries first, more after it): a policy trained on the
# shorter one starts a stage on the longer one, reading the new entries with zero weights.
EXTENDS = {"lidar79_motion": "lidar43_log"}


def widened(state: dict, file: PolicyFile, size: int) -> dict:
    """A policy's weights for an observation of ``size`` entries, if its own layout is one the
    stage's extends (``EXTENDS``): every first layer gets zero weights for the new entries, placed
    after the old ones and before anything a layer reads after the observation (a critic's action),
    so the policy acts and values as before until training finds a use for them. Otherwise the
    weights as they are (and a misfit is refused where they are loaded)."""
    old = int(observation_space(file.manifest).shape[0])
    if old == size or file.manifest.observation not in EXTENDS.values() or file.normalizer(old) is not None:
        return state
    grown = {}
    for key, tensor in state.items():
        if tensor.dim() == 2 and tensor.shape[1] in (old, old + ACTION_SPACE.shape[0]) and _reads_observation(key):
            zeros = tensor.new_zeros((tensor.shape[0], size - old))
            tensor = torch.cat([tensor[:, :old], zeros, tensor[:, old:]], dim=1)
        grown[key] = tensor
    return grown


def _reads_observation(key: str) -> bool:
    """Whether a weight is a first layer's: the one that reads the observation (SB3's names)."""
    return key.endswith(".0.weight") and any(part in key for part in ("latent_pi", "latent_vf", "qf", "mu", "policy_net",
                                                                       "value_net", "actor", "critic"))


def _optimizer_state_fits(optimizer) -> bool:
    """Whether each per-parameter tensor of a loaded optimiser state (Adam's moments, say) has its
    parameter's shape: torch's ``load_state_dict`` takes any shape, and the first update after a
    resume would then fail deep inside training."""
    for group in optimizer.param_groups:
        for parameter in group["params"]:
            for value in optimizer.state.get(parameter, {}).values():
                # Scalars (Adam's step count) belong to no parameter's shape.
                if hasattr(value, "shape") and value.dim() > 0 and value.shape != parameter.shape:
                    return False
    return True


def use_optimizer_kernels(model, kernels: str | None = "foreach") -> None:
    """Choose how a model's optimisers update their tensors (a stage's ``optimizer_kernels``).

    On CPU (elsewhere torch's own choice stands): ``foreach`` (the runner's default) makes one
    call per operation for all of a network's tensors (torch's default only on CUDA), the same
    arithmetic as torch's per-tensor loop, so the same weights as stable-baselines3 trains to the
    bit, and Adam's step 22% faster on PPO's two 64 × 64 networks (389 µs against 496).
    ``fused``: each tensor's whole Adam update in one pass, faster again (docs/training.md) but
    rounded differently, so the weights part from stable-baselines3's in their last bits. None
    hands the choice back to torch. Call it again after loading optimiser states, which bring
    back the saved settings (a model saved after ``fused`` training keeps it when loaded by
    stable-baselines3 alone)."""
    if kernels not in (*OPTIMIZER_KERNELS, None):
        raise ValueError(f"optimizer kernels {kernels!r}; allowed: {', '.join(OPTIMIZER_KERNELS)} or None")
    if model.device.type != "cpu":
        kernels = None  # also undoes a CPU run's setting that a loaded state brought back
    for name in model._get_torch_save_params()[0]:
        optimizer = _attribute(model, name)
        if isinstance(optimizer, torch.optim.Optimizer):
            for group in optimizer.param_groups:
                group["foreach"] = True if kernels == "foreach" else None
                group["fused"] = True if kernels == "fused" else None


def _attribute(model, dotted: str):
    target = model
    for part in dotted.split("."):
        target = getattr(target, part)
    return target
