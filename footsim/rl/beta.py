"""A Beta action distribution for SB3's PPO (``agent=ppo_beta``), as in thesis 5.3.

The policy head outputs two numbers per action dimension; α = softplus(·) + 1 and
β = softplus(·) + 1 keep the density unimodal (α, β > 1).  Samples x ∈ (0, 1) are rescaled to
the action bounds, a = low + (high − low)·x, so actions never leave the box and need no
clipping.  The deterministic action is the **mode** (α − 1)/(α + β − 2) (thesis: "the mode of
the beta distribution is applied"), or with ``deterministic_action="mean"`` the mean α/(α + β),
which lies nearer the middle of the box than the mode (``agent.beta_action``).  Saved and loaded
like any SB3 model (the policy class is importable), so Beta policies also serve as
transfer-learning initialisations.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.distributions import Distribution
from stable_baselines3.common.policies import ActorCriticPolicy
from torch import nn
from torch.nn import functional as F

_EPS = 1e-6
DETERMINISTIC_ACTIONS = ("mode", "mean")


class BetaDistribution(Distribution):
    distribution: th.distributions.Beta  # set by proba_distribution()

    def __init__(self, action_dim: int, low: np.ndarray, high: np.ndarray, deterministic_action: str = "mode"):
        super().__init__()
        self.deterministic_action = deterministic_action
        self.action_dim = action_dim
        self.low = th.as_tensor(low, dtype=th.float32)
        self.scale = th.as_tensor(high - low, dtype=th.float32)

    @property
    def deterministic_action(self) -> str:
        """ "mode" or "mean": what :meth:`mode` returns (checked when set)."""
        return self._deterministic_action

    @deterministic_action.setter
    def deterministic_action(self, value: str) -> None:
        if value not in DETERMINISTIC_ACTIONS:
            raise ValueError(f"a Beta policy's deterministic action is one of {DETERMINISTIC_ACTIONS}, got {value!r}")
        self._deterministic_action = value

    def proba_distribution_net(self, latent_dim: int) -> nn.Module:
        return nn.Linear(latent_dim, 2 * self.action_dim)

    @staticmethod
    def concentrations(params: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        """α and β of the head's output (two numbers per action dimension)."""
        a, b = th.chunk(params, 2, dim=-1)
        return F.softplus(a) + 1.0, F.softplus(b) + 1.0

    def proba_distribution(self, params: th.Tensor) -> BetaDistribution:
        self.distribution = th.distributions.Beta(*self.concentrations(params))
        return self

    def _to_unit(self, actions: th.Tensor) -> th.Tensor:
        x = (actions - self.low.to(actions.device)) / self.scale.to(actions.device)
        return x.clamp(_EPS, 1.0 - _EPS)

    def _from_unit(self, x: th.Tensor) -> th.Tensor:
        return self.low.to(x.device) + self.scale.to(x.device) * x

    def log_prob(self, actions: th.Tensor) -> th.Tensor:
        # density of a = low + scale·x: p(a) = p(x) / scale per dimension
        log_p = self.distribution.log_prob(self._to_unit(actions)) - th.log(self.scale.to(actions.device))
        return log_p.sum(dim=-1)

    def entropy(self) -> th.Tensor:
        return (self.distribution.entropy() + th.log(self.scale.to(self.distribution.concentration1.device))).sum(
            dim=-1
        )

    def sample(self) -> th.Tensor:
        return self._from_unit(self.distribution.rsample().clamp(_EPS, 1.0 - _EPS))

    def _deterministic(self, alpha: th.Tensor, beta: th.Tensor) -> th.Tensor:
        mean = alpha / (alpha + beta)
        if self.deterministic_action == "mean":
            return self._from_unit(mean)
        # Where α + β − 2 rounds to 0 in float32, either α = β = 1 (both softplus terms underflow, head
        # outputs below about -17: the uniform density has no mode, take its mean, the middle) or one
        # of them is 1 + 2⁻²³ and the other 1, where the mode is the bound on the larger one's side.
        spread = alpha + beta - 2.0
        edge = th.where(alpha > beta, th.ones_like(mean), th.where(beta > alpha, th.zeros_like(mean), mean))
        return self._from_unit(th.where(spread > 0, (alpha - 1.0) / spread, edge))

    def mode(self) -> th.Tensor:
        """SB3's deterministic action: the mode, or the mean (``deterministic_action``)."""
        return self._deterministic(self.distribution.concentration1, self.distribution.concentration0)

    def mode_of(self, params: th.Tensor) -> th.Tensor:
        """The deterministic action of the head's output, without building the distribution."""
        return self._deterministic(*self.concentrations(params))

    def actions_from_params(self, params: th.Tensor, deterministic: bool = False) -> th.Tensor:
        self.proba_distribution(params)
        return self.get_actions(deterministic=deterministic)

    def log_prob_from_params(self, params: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        actions = self.actions_from_params(params)
        return actions, self.log_prob(actions)


class BetaActorCriticPolicy(ActorCriticPolicy):
    """SB3's actor-critic with a Beta action head (Box action spaces only); ``deterministic_action``
    ("mode" or "mean") is saved with the model."""

    def __init__(self, *args, deterministic_action: str = "mode", **kwargs):
        self.deterministic_action = deterministic_action  # _build, called by the base class, reads it
        super().__init__(*args, **kwargs)

    def _get_constructor_parameters(self) -> dict:
        return {**super()._get_constructor_parameters(), "deterministic_action": self.deterministic_action}

    def _build(self, lr_schedule) -> None:
        super()._build(lr_schedule)  # feature/MLP extractors, value net, initialisation
        if not isinstance(self.action_space, spaces.Box):
            raise ValueError(f"the Beta policy needs a bounded Box action space, got {self.action_space}")
        low, high = self.action_space.low, self.action_space.high
        if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
            raise ValueError("the Beta policy needs a bounded Box action space")
        self.action_dist = BetaDistribution(int(np.prod(self.action_space.shape)), low, high, self.deterministic_action)
        self.action_net = self.action_dist.proba_distribution_net(self.mlp_extractor.latent_dim_pi)
        if self.ortho_init:
            self.action_net.apply(partial(self.init_weights, gain=0.01))
        del self.log_std  # the Gaussian's parameter has no role here
        make_optimizer: Callable[..., th.optim.Optimizer] = self.optimizer_class  # an Optimizer subclass taking lr
        self.optimizer = make_optimizer(self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs)

    def _get_action_dist_from_latent(self, latent_pi: th.Tensor) -> Distribution:
        return self.action_dist.proba_distribution(self.action_net(latent_pi))
