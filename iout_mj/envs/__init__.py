"""Adapters: the gymnasium env and the batched stable-baselines3 VecEnvs over both backends."""

from iout_mj.envs.gym_env import BACKENDS, ENV_ID, MultiAUVEnv
from iout_mj.envs.vec_env import KinematicVecEnv, MissionVecEnv, PhysicsVecEnv

__all__ = ["BACKENDS", "ENV_ID", "KinematicVecEnv", "MissionVecEnv", "MultiAUVEnv", "PhysicsVecEnv"]
