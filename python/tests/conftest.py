import gymnasium as gym
import numpy as np
import pytest

import mjskill  # noqa: F401  (registers the envs)

ENV = "mjskill/PickCube-v1"


@pytest.fixture
def rng():
    return np.random.default_rng(0)


def random_actions(space: gym.spaces.Box, steps: int, n: int | None = None, seed: int = 0):
    r = np.random.default_rng(seed)
    shape = (steps,) + ((n,) if n else ()) + space.shape
    return r.uniform(space.low, space.high, size=shape).astype(np.float32)
