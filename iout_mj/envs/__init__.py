"""Adapters: the gymnasium env and the batched stable-baselines3 VecEnvs over both backends."""

from typing import Any

from iout_mj.envs.gym_env import BACKENDS, ENV_ID, MultiAUVEnv

__all__ = [
    "BACKENDS",
    "ENV_ID",
    "KinematicVecEnv",
    "MissionVecEnv",
    "MultiAUVEnv",
    "PhysicsVecEnv",
    "WarpVecEnv",
]
_VEC_ENVS = ("KinematicVecEnv", "MissionVecEnv", "PhysicsVecEnv", "WarpVecEnv")


def __getattr__(name: str) -> Any:
    # The VecEnvs import stable-baselines3 and torch (~150 MB): only when asked for, so that
    # `gymnasium.make` of one env stays light.
    if name in _VEC_ENVS:
        from iout_mj.envs import vec_env

        return getattr(vec_env, name)
    raise AttributeError(f"module 'iout_mj.envs' has no attribute {name!r}")
