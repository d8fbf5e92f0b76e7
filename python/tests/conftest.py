import os

import gymnasium as gym
import numpy as np
import pytest

import mjskill  # noqa: F401  (registers the envs)

ENV = "mjskill/PickCube-v1"


def need(module):
    """Imports an optional test dependency; skips the test without it, except under CI
    (`CI` set), where a missing one is an error."""
    try:
        return __import__(module)
    except ImportError:
        if os.environ.get("CI"):
            raise
        pytest.skip(f"{module} is not installed")


@pytest.fixture
def rng():
    return np.random.default_rng(0)


def random_actions(space: gym.spaces.Box, steps: int, n: int | None = None, seed: int = 0):
    r = np.random.default_rng(seed)
    shape = (steps,) + ((n,) if n else ()) + space.shape
    return r.uniform(space.low, space.high, size=shape).astype(np.float32)
