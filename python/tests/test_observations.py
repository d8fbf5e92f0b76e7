"""ManiSkill's visual obs modes: segmentation, `+` combinations, int16 depth, point clouds."""

import gymnasium as gym
import numpy as np
import pytest

import mjskill
from conftest import ENV


def make_vec(n, **kw):
    return gym.make_vec(ENV, num_envs=n, vectorization_mode="vector_entry_point", **kw)


def test_rgb_depth_segmentation_images_have_maniskills_dtypes_and_ids():
    env = gym.make(ENV, obs_mode="rgb+depth+segmentation")
    obs, _ = env.reset(seed=3)
    assert env.observation_space.contains(obs)
    cam = obs["sensor_data"]["base_camera"]
    assert cam["rgb"].dtype == np.uint8 and cam["rgb"].shape == (128, 128, 3)
    assert cam["depth"].dtype == np.float32 and cam["depth"].shape == (128, 128, 1)
    seg = cam["segmentation"]
    assert seg.dtype == np.int16 and seg.shape == (128, 128, 1)
    ids = env.unwrapped.segmentation_id_map
    assert ids[1] == "panda_link0" and "cube" in ids.values() and "ground" in ids.values()
    seen = {ids[i] for i in np.unique(seg)}
    assert {"table-workspace", "ground", "cube", "panda_hand"} <= seen
    assert "goal_site" not in seen, "hidden from sensor cameras"
    step = env.step(env.action_space.sample())[0]
    assert env.observation_space.contains(step)


def test_int16_depth_is_maniskills_millimetres():
    mm = gym.make(ENV, obs_mode="depth+segmentation", depth_dtype="int16")
    metres = gym.make(ENV, obs_mode="depth")
    a, _ = mm.reset(seed=1)
    b, _ = metres.reset(seed=1)
    assert mm.observation_space.contains(a)
    d = a["sensor_data"]["base_camera"]["depth"]
    assert d.dtype == np.int16
    want = np.trunc(b["sensor_data"]["base_camera"]["depth"] * np.float32(1000)).astype(np.int16)
    np.testing.assert_array_equal(d, want)
    with pytest.raises(ValueError, match="unknown depth_dtype 'mm'; valid: float32, int16"):
        gym.make(ENV, obs_mode="depth", depth_dtype="mm")


def test_obs_mode_parts_are_checked():
    with pytest.raises(ValueError, match='unknown obs mode part "normal" in "rgb\\+normal"'):
        gym.make(ENV, obs_mode="rgb+normal")
    env = gym.make(ENV, obs_mode="segmentation+rgb")
    assert env.unwrapped.obs_mode == "rgb+segmentation"


def test_point_cloud_fuses_the_cameras_in_the_world_frame():
    env = gym.make(ENV, robot_uids="fetch", obs_mode="pointcloud")
    obs, _ = env.reset(seed=2)
    assert env.observation_space.contains(obs)
    assert "sensor_data" not in obs
    pc = obs["pointcloud"]
    n = 3 * 128 * 128  # base_camera, fetch_head, fetch_hand
    assert pc["xyzw"].shape == (n, 4) and pc["xyzw"].dtype == np.float32
    assert pc["rgb"].shape == (n, 3) and pc["rgb"].dtype == np.uint8
    assert pc["segmentation"].shape == (n, 1) and pc["segmentation"].dtype == np.int16
    w = pc["xyzw"][:, 3]
    np.testing.assert_array_equal(w, (pc["segmentation"][:, 0] != 0).astype(np.float32))
    ids = {v: k for k, v in env.unwrapped.segmentation_id_map.items()}
    ground = pc["xyzw"][pc["segmentation"][:, 0] == ids["ground"]]
    assert len(ground) > 100 and np.allclose(ground[:, 2], -0.9196429, atol=2e-3)


def test_vector_env_stacks_segmentation_and_point_clouds():
    v = make_vec(2, obs_mode="pointcloud")
    obs, _ = v.reset(seed=5)
    assert v.observation_space.contains(obs)
    assert obs["pointcloud"]["xyzw"].shape == (2, 128 * 128, 4)
    single = gym.make(ENV, obs_mode="pointcloud")
    one, _ = single.reset(seed=6)
    for k in ("xyzw", "rgb", "segmentation"):
        np.testing.assert_array_equal(obs["pointcloud"][k][1], one["pointcloud"][k])
    v = make_vec(2, obs_mode="depth+segmentation", depth_dtype="int16")
    obs, _ = v.reset(seed=5)
    cam = obs["sensor_data"]["base_camera"]
    assert cam["depth"].dtype == np.int16 and cam["segmentation"].shape == (2, 128, 128, 1)
    assert v.observation_space.contains(obs)
    obs, *_ = v.step(v.action_space.sample())
    assert v.observation_space.contains(obs)
    assert v.segmentation_id_map == gym.make(ENV).unwrapped.segmentation_id_map
    assert isinstance(v, mjskill.MjskillVectorEnv)
