"""The installed wheel is self-contained and manylinux_2_28: its extension loads the libmujoco
bundled in the wheel (``mjskill.libs/``, MuJoCo 2.2.2 built for glibc 2.28 by
python/build_mujoco.sh), neither needs a glibc symbol newer than 2.28, the licences and the
robot models' notices ship with it, and its trajectories are the system libmujoco's bit for
bit. .ci/python-tests sets MJSKILL_WHEEL_TEST=1 after hiding the system libmujoco."""

import os
import re
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import mjskill
from conftest import REPO, need

sys.path.insert(0, str(REPO / "examples"))
import demos as demos_mod  # noqa: E402

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
    # Everything linked into the bundled libmujoco, each with its own licence.
    for name, words in [("libccd-LICENSE", "Redistribution"), ("lodepng-LICENSE", "Lode"),
                        ("qhull-COPYING.txt", "Qhull"), ("tinyxml2-LICENSE.txt", "warranty"),
                        ("tinyobjloader-LICENSE", "MIT"),
                        ("LLVM-libcxx-libcxxabi-libunwind-LICENSE.TXT", "LLVM Exceptions"),
                        ("zig-compiler_rt-LICENSE", "Permission is hereby granted")]:
        assert words in (lic / name).read_text(), name
    notices = sorted(p.relative_to(lic / "models").as_posix() for p in lic.glob("models/**/NOTICE"))
    assert "panda/visual/NOTICE" in notices, notices
    assert len(notices) == 6, notices


def _glibc_versions(path: Path) -> set[tuple[int, ...]]:
    out = subprocess.run(["objdump", "-T", str(path)], capture_output=True, text=True,
                         check=True).stdout
    return {tuple(map(int, v.split("."))) for v in re.findall(r"GLIBC_([0-9.]+)", out)}


def test_nothing_in_the_wheel_needs_a_glibc_newer_than_2_28():
    pkg = Path(mjskill.__file__).parent
    ext = next(pkg.glob("_native*.so"))
    libs = list((pkg.parent / "mjskill.libs").glob("libmujoco*"))
    assert len(libs) == 1, libs
    for f in (ext, libs[0]):
        versions = _glibc_versions(f)
        assert versions and max(versions) <= (2, 28), (f.name, sorted(versions)[-3:])
        needed = subprocess.run(["objdump", "-p", str(f)], capture_output=True, text=True,
                                check=True).stdout
        assert "libstdc++" not in needed, f.name


@pytest.mark.parametrize("env_id, robot, policy", [
    ("PickCube-v1", "panda", "solver"),
    ("PlaceSphere-v1", "fetch", "solver"),
    ("PickCubeSO100-v1", "so100", "solver"),
    ("PokeCube-v1", "panda", "random"),
])
def test_the_wheel_steps_as_the_system_libmujoco_bit_for_bit(env_id, robot, policy, tmp_path):
    """The command line, linked to Debian's libmujoco, records episodes; the wheel's env,
    on its own glibc 2.28 build of the same MuJoCo, replays their actions from the same seeds
    and must see every observation and reward bit for bit."""
    need("mcap")
    out = tmp_path / "run.mcap"
    r = subprocess.run([os.environ["MJSKILL_BIN"], "rollout", "--env", env_id, "--robot", robot,
                        "--policy", policy, "--episodes", "2", "--seed", "7", "--no-frame",
                        "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    d = demos_mod.load([str(out)], env_id, robot, None, keep_failed=True)
    assert len(d.episodes) == 2
    env = gym.make(f"mjskill/{env_id}", robot_uids=robot, control_mode=d.control_mode)
    for e in d.episodes:
        obs, _ = env.reset(seed=e.seed)
        for t, a in enumerate(e.actions):
            # The recording keeps each float32 exactly (the loader widens them to float64).
            np.testing.assert_array_equal(obs, e.obs[t].astype(np.float32),
                                          err_msg=f"seed {e.seed} step {t}")
            obs, reward, *_ = env.step(a)
            assert np.float32(reward) == np.float32(e.rewards[t]), (e.seed, t)
    env.close()
