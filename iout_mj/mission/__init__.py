"""The mission core: state, actions, rewards, observation and statistics, for every backend."""

from iout_mj.mission.actions import ACTION_FIELDS, ActionError, ActionMap
from iout_mj.mission.core import Mission
from iout_mj.mission.observation import (
    OBS_HIGH,
    OBS_LOW,
    OBSERVATION_DOC,
    OBSERVATION_LAYOUT,
    flatten_observation,
    observation_sizes,
)
from iout_mj.mission.rewards import REWARD_TERMS
from iout_mj.mission.state import MissionState

__all__ = [
    "ACTION_FIELDS",
    "OBSERVATION_DOC",
    "OBSERVATION_LAYOUT",
    "OBS_HIGH",
    "OBS_LOW",
    "REWARD_TERMS",
    "ActionError",
    "ActionMap",
    "Mission",
    "MissionState",
    "flatten_observation",
    "observation_sizes",
]
