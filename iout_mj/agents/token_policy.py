"""The general policy: an SB3 actor-critic whose parameters do not depend on K.

Node tokens (`mission.tokens`) are embedded by one shared MLP and mixed by masked
self-attention (`TokenAttention`); the context (global and AUV features, masked mean and max
of the nodes) gives each AUV a query, which scores every node for AET and for the uplink
(pointer-style logits: query-key dot products; padded nodes at -1e8, so they are never
chosen) and gives its heading and speed logits. The critic reads the context. SB3's PPO
trains it unchanged: the network is its `mlp_extractor`, its output the logits of the
`MultiDiscrete([H, S, K_max, K_max] * N)` action.

Speed: the nodes of a token observation are a prefix of its K_max rows, so a batch is sorted
by its number of nodes, cut into groups (`GROUP_ROWS` rows at least) and each group computed
on its own nodes only; the logits of the absent nodes are `MASKED_LOGIT`. The result is the
padded computation's (to float rounding) at the cost of the nodes present: a batch of K = 3 to
20 costs about a third of K_max = 30.
"""

from __future__ import annotations

import itertools
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.distributions import MultiCategoricalDistribution
from stable_baselines3.common.policies import ActorCriticPolicy
from torch import nn
from torch.nn import functional

from iout_mj.mission.tokens import GLOBAL_FEATURES, auv_features, node_features

MASKED_LOGIT = -1e8
GROUP_ROWS = 128
"""Fewest rows of a group of similar K in one pass (fewer groups below: small batches cost
more per call than per node)."""
MAX_GROUPS = 4


def _mlp(*sizes: int) -> nn.Sequential:
    layers: list[nn.Module] = []
    for a, b in itertools.pairwise(sizes):
        layers += [nn.Linear(a, b), nn.Tanh()]
    return nn.Sequential(*layers[:-1])


class TokenAttention(nn.Module):
    """Multi-head self-attention over node tokens with a key mask: `nn.MultiheadAttention`'s
    computation and parameters (the same state-dict keys), written with plain matrix products,
    which are about 1.4x faster than PyTorch's CPU attention kernels at these sizes
    (K <= 30, width 64)."""

    def __init__(self, width: int, num_heads: int):
        super().__init__()
        self.heads = num_heads
        self.in_proj_weight = nn.Parameter(torch.empty(3 * width, width))
        self.in_proj_bias = nn.Parameter(torch.zeros(3 * width))
        self.out_proj = nn.Linear(width, width)
        nn.init.xavier_uniform_(self.in_proj_weight)
        nn.init.zeros_(self.out_proj.bias)

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """x (B, K, w), mask (B, K) True where a node is: the attended tokens (B, K, w)."""
        b, k, w = x.shape
        d = w // self.heads
        qkv = functional.linear(x, self.in_proj_weight, self.in_proj_bias)
        q, key, v = qkv.view(b, k, 3, self.heads, d).permute(2, 0, 3, 1, 4).unbind(0)
        scores = (q * d**-0.5) @ key.transpose(-1, -2)  # (B, heads, K, K)
        scores = scores.masked_fill(~mask[:, None, None, :], MASKED_LOGIT)
        out = scores.softmax(-1) @ v  # (B, heads, K, d)
        return self.out_proj(out.transpose(1, 2).reshape(b, k, w))


def _groups(counts: torch.Tensor) -> list[torch.Tensor]:
    """Row indices of a batch cut into groups of similar node counts (sorted)."""
    rows = counts.shape[0]
    n = max(1, min(MAX_GROUPS, rows // GROUP_ROWS))
    if n == 1:
        return [torch.arange(rows, device=counts.device)]
    return list(torch.argsort(counts, stable=True).tensor_split(n))


class TokenNet(nn.Module):
    """Logits (B, N*(H+S+2 K_max)) and critic latent (B, width) from token observations."""

    def __init__(self, n_auvs: int, k_max: int, heading_levels: int, speed_levels: int, width: int):
        super().__init__()
        self.n, self.k_max, self.width = n_auvs, k_max, width
        self.h, self.s = heading_levels, speed_levels
        self.a_size, self.f_size = auv_features(n_auvs), node_features(n_auvs)
        self.node_in = _mlp(self.f_size, width, width)
        self.attention = TokenAttention(width, num_heads=4)
        self.norm = nn.LayerNorm(width)
        glob = GLOBAL_FEATURES + n_auvs * self.a_size
        self.context = _mlp(glob + 2 * width, 2 * width, width)
        self.query = _mlp(width + self.a_size + n_auvs, width, width)
        self.motion = _mlp(width, width, heading_levels + speed_levels)
        self.keys = nn.Linear(width, 2 * width)
        self.queries = nn.Linear(width, 2 * width)
        self.latent_dim_pi = n_auvs * (heading_levels + speed_levels + 2 * k_max)
        self.latent_dim_vf = width
        for head in (self.motion[-1], self.queries):  # near-uniform first actions
            assert isinstance(head, nn.Linear)
            nn.init.orthogonal_(head.weight, gain=0.01)
            nn.init.zeros_(head.bias)

    def split(self, obs: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """(global, AUV tokens (B, N, A), node tokens (B, K_max, F), mask (B, K_max))."""
        g = GLOBAL_FEATURES
        a_end = g + self.n * self.a_size
        n_end = a_end + self.k_max * self.f_size
        auvs = obs[:, g:a_end].reshape(-1, self.n, self.a_size)
        nodes = obs[:, a_end:n_end].reshape(-1, self.k_max, self.f_size)
        return obs[:, :g], auvs, nodes, obs[:, n_end:] > 0.5

    def encode(self, obs: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """Context (B, w), AUV tokens, node embeddings (B, K, w) and mask (B, K), for the
        first K rows of every observation's nodes (K: the last row any of them holds)."""
        glob, auvs, nodes, mask = self.split(obs)
        k = int(mask.any(0).nonzero().max()) + 1 if bool(mask.any()) else 1
        nodes, mask = nodes[:, :k], mask[:, :k]
        emb = self.node_in(nodes)
        emb = self.norm(emb + self.attention(emb, mask)) * mask[..., None]
        count = mask.sum(1, keepdim=True).clamp(min=1)
        mean = emb.sum(1) / count
        peak = emb.masked_fill(~mask[..., None], -1e4).amax(1)
        ctx = self.context(torch.cat([glob, auvs.flatten(1), mean, peak], -1))
        return ctx, auvs, emb, mask

    def actor(
        self, ctx: torch.Tensor, auvs: torch.Tensor, emb: torch.Tensor, mask: torch.Tensor
    ) -> torch.Tensor:
        """Logits (B, N*(H+S+2 K_max)) from `encode`'s output (nodes past its K masked)."""
        b, k = mask.shape
        eye = torch.eye(self.n, device=ctx.device).expand(b, -1, -1)
        q = self.query(torch.cat([ctx[:, None].expand(-1, self.n, -1), auvs, eye], -1))
        motion = self.motion(q)  # (B, N, H+S)
        # pointer logits: a query per AUV and field against a key per node
        qa, qu = self.queries(q).chunk(2, -1)  # (B, N, w)
        ka, ku = self.keys(emb).chunk(2, -1)  # (B, K, w)
        scale = self.width**-0.5
        hidden = ~mask[:, None, :]
        aet = (qa @ ka.transpose(1, 2) * scale).masked_fill(hidden, MASKED_LOGIT)
        uplink = (qu @ ku.transpose(1, 2) * scale).masked_fill(hidden, MASKED_LOGIT)
        if k < self.k_max:
            pad = (0, self.k_max - k)
            aet, uplink = (functional.pad(x, pad, value=MASKED_LOGIT) for x in (aet, uplink))
        return torch.cat([motion, aet, uplink], -1).flatten(1)

    def _heads(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        ctx, auvs, emb, mask = self.encode(obs)
        return self.actor(ctx, auvs, emb, mask), ctx

    def _critic(self, obs: torch.Tensor) -> tuple[torch.Tensor]:
        return (self.encode(obs)[0],)

    def _by_groups(self, obs: torch.Tensor, fn: Any) -> tuple[torch.Tensor, ...]:
        """`fn` on groups of rows of similar node counts, its outputs in the rows' order."""
        groups = _groups(obs[:, -self.k_max :].sum(1))
        if len(groups) == 1:
            return fn(obs)
        parts = [fn(obs[rows]) for rows in groups]
        order = torch.argsort(torch.cat(groups))
        return tuple(torch.cat(outs)[order] for outs in zip(*parts, strict=True))

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self._by_groups(obs, self._heads)  # type: ignore[return-value]

    def forward_actor(self, obs: torch.Tensor) -> torch.Tensor:
        return self.forward(obs)[0]

    def forward_critic(self, obs: torch.Tensor) -> torch.Tensor:
        return self._by_groups(obs, self._critic)[0]


class PaddedMultiCategorical(MultiCategoricalDistribution):
    """SB3's MultiCategorical computed as one padded tensor (B, dims, max size): one
    log-softmax, one gather, one multinomial draw instead of one Categorical per action
    dimension (8 for N = 2). The same distribution; about 5 % of PPO's time on the general
    recipe."""

    def __init__(self, action_dims: list[int]):
        super().__init__(action_dims)
        size = max(action_dims)
        starts = np.cumsum([0, *action_dims[:-1]])
        padded = [
            [s + i if i < d else -1 for i in range(size)]
            for s, d in zip(starts, action_dims, strict=True)
        ]
        self._index = torch.tensor(padded)  # -1: a padding column of MASKED_LOGIT
        self.log_probs = torch.empty(0)

    def proba_distribution(self, action_logits: torch.Tensor) -> PaddedMultiCategorical:
        column = action_logits.new_full((action_logits.shape[0], 1), MASKED_LOGIT)
        logits = torch.cat([action_logits, column], 1)[:, self._index]
        self.log_probs = torch.log_softmax(logits, -1)  # (B, dims, max size)
        return self

    def log_prob(self, actions: torch.Tensor) -> torch.Tensor:
        return self.log_probs.gather(-1, actions.long()[..., None]).sum((1, 2))

    def entropy(self) -> torch.Tensor:
        return -(self.log_probs.exp() * self.log_probs).sum((1, 2))

    def sample(self) -> torch.Tensor:
        b, dims, size = self.log_probs.shape
        draws = torch.multinomial(self.log_probs.exp().reshape(b * dims, size), 1, True)
        return draws.reshape(b, dims)

    def mode(self) -> torch.Tensor:
        return self.log_probs.argmax(-1)


class TokenPolicy(ActorCriticPolicy):
    """SB3 actor-critic over token observations (`policy_kwargs`: k_max, width)."""

    def __init__(
        self,
        observation_space: gym.spaces.Box,
        action_space: gym.spaces.MultiDiscrete,
        lr_schedule: Any,
        k_max: int = 30,
        width: int = 64,
        **kwargs: Any,
    ):
        nvec = [int(v) for v in action_space.nvec]
        self.token_args = {
            "n_auvs": len(nvec) // 4,
            "k_max": k_max,
            "heading_levels": nvec[0],
            "speed_levels": nvec[1],
            "width": width,
        }
        kwargs.setdefault("ortho_init", False)
        super().__init__(observation_space, action_space, lr_schedule, **kwargs)

    def _build_mlp_extractor(self) -> None:
        self.mlp_extractor = TokenNet(**self.token_args)  # type: ignore[assignment]

    def _build(self, lr_schedule: Any) -> None:
        assert isinstance(self.action_space, gym.spaces.MultiDiscrete)
        self.action_dist = PaddedMultiCategorical([int(v) for v in self.action_space.nvec])
        super()._build(lr_schedule)
        self.action_net = nn.Identity()  # the network's output is already the logits
        self.optimizer = self.optimizer_class(  # type: ignore[call-arg]
            self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs
        )

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(k_max=self.token_args["k_max"], width=self.token_args["width"])
        return data
