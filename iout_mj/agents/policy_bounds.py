"""Bounds on the network a policy manifest describes, checked before anything is built.

A manifest gives its network as sizes (observation size, action levels, layer widths, K_max,
width); building it allocates every parameter. `check_network` bounds each size, then counts
the parameters the build would allocate from the layer shapes of SB3's `ActorCriticPolicy` and
of `TokenPolicy`, so a manifest asking for gigabytes is refused before a tensor exists.
"""

from __future__ import annotations

from typing import Any

from iout_mj.errors import PolicyFormatError
from iout_mj.mission.tokens import GLOBAL_FEATURES, auv_features, node_features, token_size
from iout_mj.schema import shown

MAX_OBSERVATION_SIZE = 1 << 16
MAX_ACTION_DIMS = 256
"""Entries of `action_nvec` (4 per AUV)."""
MAX_ACTION_LEVELS = 1 << 16
MAX_LAYERS = 16
MAX_WIDTH = 1 << 14
"""Widest hidden layer of an MLP policy, and the widest token network."""
MAX_K = 1 << 10
"""Largest K_max of a token policy."""
MAX_PARAMETERS = 1 << 24
"""Parameters a policy may allocate when built: 64 MiB of float32 (a shipped policy: 0.1 M)."""
SB3_DEFAULT_ARCH = [64, 64]
"""SB3's hidden layers (actor and critic) when `net_arch` is None."""
ATTENTION_HEADS = 4
"""`TokenNet`'s heads: its width must be a multiple."""


def _integer(value: Any, name: str, low: int, high: int, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise PolicyFormatError(
            f"{where}: {name} is {shown(value)}; accepted an integer in [{low}, {high}]"
        )
    return value


def _widths(value: Any, name: str, where: str) -> list[int]:
    if not isinstance(value, list) or len(value) > MAX_LAYERS:
        raise PolicyFormatError(
            f"{where}: {name} is {shown(value)}; accepted a list of at most {MAX_LAYERS} widths"
        )
    return [_integer(w, f"{name}[{i}]", 1, MAX_WIDTH, where) for i, w in enumerate(value)]


def _linear(n_in: int, n_out: int) -> int:
    """Parameters of `nn.Linear(n_in, n_out)`."""
    return n_in * n_out + n_out


def _mlp_chain(n_in: int, widths: list[int]) -> tuple[int, int]:
    """Parameters of a chain of linear layers, and its output size."""
    total = 0
    for width in widths:
        total, n_in = total + _linear(n_in, width), width
    return total, n_in


def mlp_parameters(observation_size: int, nvec: list[int], net_arch: Any, where: str) -> int:
    """Parameters of SB3's `ActorCriticPolicy` for a MultiDiscrete action: actor and critic
    MLPs (`net_arch` a list for both, or {"pi": [...], "vf": [...]}), action and value heads."""
    if net_arch is None:
        pi, vf = SB3_DEFAULT_ARCH, SB3_DEFAULT_ARCH
    elif isinstance(net_arch, dict) and set(net_arch) <= {"pi", "vf"}:
        pi = _widths(net_arch.get("pi", []), "net_arch.pi", where)
        vf = _widths(net_arch.get("vf", []), "net_arch.vf", where)
    else:
        pi = vf = _widths(net_arch, "net_arch", where)
    actor, latent_pi = _mlp_chain(observation_size, pi)
    critic, latent_vf = _mlp_chain(observation_size, vf)
    return actor + critic + _linear(latent_pi, sum(nvec)) + _linear(latent_vf, 1)


def token_parameters(n_auvs: int, k_max: int, heading: int, speed: int, width: int) -> int:
    """Parameters `TokenPolicy` allocates: its `TokenNet`, the value head, and the linear
    action head SB3 builds (then replaces by the identity) from the logits to the actions."""
    a, f, w = auv_features(n_auvs), node_features(n_auvs), width
    context_in = GLOBAL_FEATURES + n_auvs * a + 2 * w
    total = _linear(f, w) + _linear(w, w)  # node embedding
    total += 4 * w * w + 4 * w + 2 * w  # attention (in and out projections), layer norm
    total += _linear(context_in, 2 * w) + _linear(2 * w, w)  # context
    total += _linear(w + a + n_auvs, w) + _linear(w, w)  # query per AUV
    total += _linear(w, w) + _linear(w, heading + speed)  # motion logits
    total += 2 * _linear(w, 2 * w) + _linear(w, 1)  # keys, queries, value head
    logits = n_auvs * (heading + speed + 2 * k_max)
    return total + _linear(logits, logits)


def check_network(manifest: dict[str, Any], where: str) -> int:
    """Bound every size of the manifest's network and its parameter count, before anything is
    built; returns the count.

    Raises:
        PolicyFormatError: a size out of its range, or more than MAX_PARAMETERS parameters.
    """
    obs_size = _integer(
        manifest.get("observation_size"), "observation_size", 1, MAX_OBSERVATION_SIZE, where
    )
    nvec = manifest.get("action_nvec")
    if not isinstance(nvec, list) or not 1 <= len(nvec) <= MAX_ACTION_DIMS:
        raise PolicyFormatError(
            f"{where}: action_nvec is {shown(nvec)}; accepted a list of 1 to {MAX_ACTION_DIMS} "
            "action sizes"
        )
    for i, v in enumerate(nvec):
        _integer(v, f"action_nvec[{i}]", 1, MAX_ACTION_LEVELS, where)
    kind = manifest.get("policy", "mlp")
    if kind == "mlp":
        count = mlp_parameters(obs_size, nvec, manifest.get("net_arch"), where)
    elif kind == "tokens":
        count = _token_count(manifest, obs_size, nvec, where)
    else:
        raise PolicyFormatError(f"{where}: policy is {shown(kind)}; accepted 'mlp' or 'tokens'")
    if count > MAX_PARAMETERS:
        raise PolicyFormatError(
            f"{where}: the network would allocate {count:,} parameters; accepted at most "
            f"{MAX_PARAMETERS:,}"
        )
    return count


def _token_count(manifest: dict[str, Any], obs_size: int, nvec: list[int], where: str) -> int:
    k_max = _integer(manifest.get("k_max"), "k_max", 1, MAX_K, where)
    width = _integer(manifest.get("width"), "width", ATTENTION_HEADS, MAX_WIDTH, where)
    if width % ATTENTION_HEADS:
        raise PolicyFormatError(
            f"{where}: width is {width}; accepted a multiple of {ATTENTION_HEADS}"
        )
    n_auvs = len(nvec) // 4
    heading, speed = nvec[0], nvec[1]
    if nvec != [heading, speed, k_max, k_max] * n_auvs:
        raise PolicyFormatError(
            f"{where}: action_nvec {shown(nvec)} does not fit a token policy with k_max={k_max}: "
            "accepted [heading levels, speed levels, k_max, k_max] once per AUV"
        )
    if obs_size != token_size(n_auvs, k_max):
        raise PolicyFormatError(
            f"{where}: observation_size {obs_size}; a token policy for N={n_auvs}, "
            f"k_max={k_max} observes {token_size(n_auvs, k_max)}"
        )
    return token_parameters(n_auvs, k_max, heading, speed, width)
