"""The installed wheel is self-contained: its extension loads the libmujoco bundled in the
wheel (``mjskill.libs/``), and MuJoCo's licence and the robot models' notices ship with it.
.ci/python-tests sets MJSKILL_WHEEL_TEST=1 after hiding the system libmujoco."""

import os
from pathlib import Path

import gymnasium as gym
import pytest

import mjskill

pytestmark = pytest.mark.skipif(
    os.environ.get("MJSKILL_WHEEL_TEST") != "1",
    reason="run by .ci/python-tests against the manylinux wheel",
)


def test_libmujoco_is_the_bundled_one():
    env = gym.make("mjskill/PickCube-v1")
    env.reset(seed=0)
    maps = Path("/proc/self/maps").read_text()
    loaded = {line.split()[-1] for line in maps.splitlines() if "libmujoco" in line}
    assert loaded, "libmujoco is not loaded"
    assert all("mjskill.libs" in p for p in loaded), loaded
    env.close()


def test_licences_and_notices_ship_in_the_wheel():
    lic = Path(mjskill.__file__).parent / "licenses"
    assert "Apache License" in (lic / "MuJoCo-LICENSE").read_text()
    assert "mujoco" in (lic / "MuJoCo-debian-copyright").read_text().lower()
    notices = sorted(p.relative_to(lic / "models").as_posix() for p in lic.glob("models/**/NOTICE"))
    assert "panda/visual/NOTICE" in notices, notices
    assert len(notices) == 6, notices
