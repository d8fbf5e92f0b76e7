import functools
import json
import os
import subprocess
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import mjskill  # noqa: F401  (registers the envs)

ENV = "mjskill/PickCube-v1"
REPO = Path(__file__).resolve().parents[2]


def need(module):
    """Imports an optional test dependency; skips the test without it, except under CI
    (`CI` set), where a missing one is an error."""
    try:
        return __import__(module)
    except ImportError:
        if os.environ.get("CI"):
            raise
        pytest.skip(f"{module} is not installed")


@functools.cache
def _built_features(path: str) -> frozenset:
    r = subprocess.run([path, "features"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, f"`{path} features` failed: {r.stderr[-2000:]}"
    return frozenset(json.loads(r.stdout)["features"])


def mjskill_bin(*features: str) -> str:
    """The `mjskill` command line the tests run: $MJSKILL_BIN, else the checkout's
    target/release/mjskill. A test that needs optional Cargo features this binary was built
    without (the README's quick start builds `--no-default-features --features cli`) is
    skipped, naming them and the build that has them, as the Rust tests compile out. With
    MJSKILL_REQUIRE_FEATURES set (.ci/run's full run, with the default features' binary) a
    missing feature is a failure instead, so CI still runs every such test."""
    path = os.environ.get("MJSKILL_BIN", str(REPO / "target" / "release" / "mjskill"))
    assert Path(path).exists(), f"{path} missing: run `cargo build --release` first"
    missing = sorted(set(features) - _built_features(path))
    if missing:
        why = (f"{path} is built without the feature(s) {', '.join(missing)} "
               "(`cargo build --release` builds the default features, which have them)")
        if os.environ.get("MJSKILL_REQUIRE_FEATURES"):
            pytest.fail(f"{why}; MJSKILL_REQUIRE_FEATURES is set")
        pytest.skip(why)
    return path


@pytest.fixture
def rng():
    return np.random.default_rng(0)


def random_actions(space: gym.spaces.Box, steps: int, n: int | None = None, seed: int = 0):
    r = np.random.default_rng(seed)
    shape = (steps,) + ((n,) if n else ()) + space.shape
    return r.uniform(space.low, space.high, size=shape).astype(np.float32)
