"""PPO training: the training config, the trainer, its callbacks and run folders."""

from iout_mj.training.config import PhaseConfig, TrainConfig
from iout_mj.training.trainer import HELD_OUT_SEED, new_model, train, vec_env

__all__ = ["HELD_OUT_SEED", "PhaseConfig", "TrainConfig", "new_model", "train", "vec_env"]
