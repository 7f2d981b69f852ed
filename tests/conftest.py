"""Shared fixtures."""

import numpy as np
import pytest

import iout_mj  # noqa: F401  (chooses the GL backend and registers the env first)
from iout_mj.config import Config, make_config


@pytest.fixture
def cfg() -> Config:
    return make_config(2, 7)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(0)
