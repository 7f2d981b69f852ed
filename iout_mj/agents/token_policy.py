"""The general policy: an SB3 actor-critic whose parameters do not depend on K.

Node tokens (`mission.tokens`) are embedded by one shared MLP and mixed by masked
self-attention; the context (global and AUV features, masked mean and max of the nodes) gives
each AUV a query, which scores every node for AET and for the uplink (pointer-style logits:
query-key dot products; padded nodes at -1e8, so they are never chosen) and gives its heading
and speed logits. The critic reads the context. SB3's PPO trains it unchanged: the network is
its `mlp_extractor`, its output the logits of the `MultiDiscrete([H, S, K_max, K_max] * N)`
action.
"""

from __future__ import annotations

import itertools
from typing import Any

import gymnasium as gym
import torch
from stable_baselines3.common.policies import ActorCriticPolicy
from torch import nn

from iout_mj.mission.tokens import GLOBAL_FEATURES, auv_features, node_features

MASKED_LOGIT = -1e8


def _mlp(*sizes: int) -> nn.Sequential:
    layers: list[nn.Module] = []
    for a, b in itertools.pairwise(sizes):
        layers += [nn.Linear(a, b), nn.Tanh()]
    return nn.Sequential(*layers[:-1])


class TokenNet(nn.Module):
    """Logits (B, N*(H+S+2 K_max)) and critic latent (B, width) from token observations."""

    def __init__(self, n_auvs: int, k_max: int, heading_levels: int, speed_levels: int, width: int):
        super().__init__()
        self.n, self.k_max, self.width = n_auvs, k_max, width
        self.h, self.s = heading_levels, speed_levels
        self.a_size, self.f_size = auv_features(n_auvs), node_features(n_auvs)
        self.node_in = _mlp(self.f_size, width, width)
        self.attention = nn.MultiheadAttention(width, num_heads=4, batch_first=True)
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
        glob, auvs, nodes, mask = self.split(obs)
        emb = self.node_in(nodes)
        mixed, _ = self.attention(emb, emb, emb, key_padding_mask=~mask, need_weights=False)
        emb = self.norm(emb + mixed) * mask[..., None]
        count = mask.sum(1, keepdim=True).clamp(min=1)
        mean = emb.sum(1) / count
        peak = emb.masked_fill(~mask[..., None], -1e4).amax(1)
        ctx = self.context(torch.cat([glob, auvs.flatten(1), mean, peak], -1))
        return ctx, auvs, emb, mask

    def actor(
        self, ctx: torch.Tensor, auvs: torch.Tensor, emb: torch.Tensor, mask: torch.Tensor
    ) -> torch.Tensor:
        b = ctx.shape[0]
        eye = torch.eye(self.n, device=ctx.device).expand(b, -1, -1)
        q = self.query(torch.cat([ctx[:, None].expand(-1, self.n, -1), auvs, eye], -1))
        motion = self.motion(q)  # (B, N, H+S)
        # pointer logits: a query per AUV and field against a key per node
        qa, qu = self.queries(q).chunk(2, -1)  # (B, N, w)
        ka, ku = self.keys(emb).chunk(2, -1)  # (B, K_max, w)
        scale = self.width**-0.5
        hidden = ~mask[:, None, :]
        aet = (qa @ ka.transpose(1, 2) * scale).masked_fill(hidden, MASKED_LOGIT)
        uplink = (qu @ ku.transpose(1, 2) * scale).masked_fill(hidden, MASKED_LOGIT)
        return torch.cat([motion, aet, uplink], -1).flatten(1)

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        ctx, auvs, emb, mask = self.encode(obs)
        return self.actor(ctx, auvs, emb, mask), ctx

    def forward_actor(self, obs: torch.Tensor) -> torch.Tensor:
        return self.forward(obs)[0]

    def forward_critic(self, obs: torch.Tensor) -> torch.Tensor:
        return self.encode(obs)[0]


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
        super()._build(lr_schedule)
        self.action_net = nn.Identity()  # the network's output is already the logits
        self.optimizer = self.optimizer_class(  # type: ignore[call-arg]
            self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs
        )

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(k_max=self.token_args["k_max"], width=self.token_args["width"])
        return data
