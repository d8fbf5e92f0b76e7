"""The gymnasium env: registration, check_env, spaces, observations, state access, pickling."""

import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import mjskill
from conftest import ENV, random_actions


@pytest.mark.parametrize("gid,robot", mjskill.registered())
def test_check_env_on_every_registered_pair(gid, robot):
    env = gym.make(gid, robot_uids=robot, render_mode="rgb_array")
    assert isinstance(env.unwrapped, gym.Env)
    assert env.unwrapped.robot_uids == robot
    check_env(env.unwrapped, skip_render_check=False)
    frame = env.unwrapped.render()
    assert frame.dtype == np.uint8 and frame.shape == (512, 512, 3) and frame.std() > 1


def test_every_env_and_robot_is_registered():
    ids = {g for g, _ in mjskill.registered()}
    assert ids == {
        "mjskill/PickCube-v1",
        "mjskill/PickCubeSO100-v1",
        "mjskill/PickCubeWidowXAI-v1",
        "mjskill/PlaceSphere-v1",
        "mjskill/PokeCube-v1",
        "mjskill/PushCube-v1",
        "mjskill/PullCube-v1",
        "mjskill/StackCube-v1",
        "mjskill/LiftPegUpright-v1",
        "mjskill/PushT-v1",
        "mjskill/PegInsertionSide-v1",
    }
    assert ("mjskill/PickCube-v1", "xarm6_robotiq") in mjskill.registered()
    assert ("mjskill/PokeCube-v1", "fetch") in mjskill.registered()
    assert ("mjskill/PullCube-v1", "fetch") in mjskill.registered()
    assert ("mjskill/StackCube-v1", "fetch") in mjskill.registered()
    assert ("mjskill/LiftPegUpright-v1", "fetch") in mjskill.registered()
    assert ("mjskill/PushT-v1", "panda_stick") in mjskill.registered()
    assert ("mjskill/PegInsertionSide-v1", "panda_wristcam") in mjskill.registered()


def test_peg_insertion_side_reconfigures_and_reports_the_head_as_a_vector():
    env = gym.make("mjskill/PegInsertionSide-v1")
    obs, info = env.reset(seed=0)
    # Every reset rebuilds the scene, as upstream's; the shapes follow the seed.
    assert info["reconfigure"] is True
    half = obs[32:35].copy()
    assert 0.085 <= half[0] <= 0.125 and 0.015 <= half[1] == half[2] <= 0.025
    obs, info = env.reset(seed=1)
    assert not np.array_equal(obs[32:35], half)
    assert np.array_equal(env.reset(seed=0)[0][32:35], half)
    _, _, terminated, _, info = env.step(env.action_space.sample())
    head = info["peg_head_pos_at_hole"]
    assert isinstance(head, np.ndarray) and head.shape == (3,)
    assert head[0] < -0.1 and isinstance(info["success"], bool) and not terminated
    assert not any(k.startswith("peg_head_pos_at_hole[") for k in info)


def test_maniskill_keywords_and_rust_bounds():
    env = gym.make(
        ENV,
        robot_uids="panda",
        obs_mode="state",
        control_mode="pd_ee_delta_pose",
        reward_mode="normalized_dense",
        render_mode="rgb_array",
        max_episode_steps=7,
    )
    u = env.unwrapped
    assert (u.control_mode, u.reward_mode, u.obs_mode) == (
        "pd_ee_delta_pose",
        "normalized_dense",
        "state",
    )
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (7,), np.float32)
    assert env.observation_space.shape == (42,) and env.observation_space.dtype == np.float32
    spec = u._native.spec()
    np.testing.assert_array_equal(env.action_space.low, spec["action_low"])
    env.reset(seed=0)
    a = np.zeros(7, np.float32)
    flags = [env.step(a)[3] for _ in range(7)]
    assert flags == [False] * 6 + [True], "gym.make's max_episode_steps truncates"
    joint = gym.make(ENV, control_mode="pd_joint_pos")
    assert not np.all(joint.action_space.high == 1.0), "joint targets use the robot's limits"


def test_seeded_reset_is_the_rust_initial_state():
    env = gym.make(ENV)
    a, _ = env.reset(seed=3)
    b, info = env.reset(seed=3)
    np.testing.assert_array_equal(a, b)
    assert info["elapsed_steps"] == 0 and info["reconfigure"] is False
    c, _ = env.reset(seed=4)
    assert not np.array_equal(a, c)
    native = mjskill._native.Env("PickCube-v1")
    np.testing.assert_array_equal(native.reset(3)[0], a)


def test_seed_and_actions_give_identical_trajectories():
    runs = []
    for _ in range(2):
        env = gym.make(ENV)
        obs, _ = env.reset(seed=11)
        traj = [obs]
        for a in random_actions(env.action_space, 30, seed=5):
            obs, r, te, tr, info = env.step(a)
            traj += [obs, np.float32(r), np.bool_(te), np.bool_(tr)]
        runs.append(traj)
    for x, y in zip(*runs):
        np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("mode", ["state_dict", "rgb", "depth", "rgbd"])
def test_dict_observations(mode):
    env = gym.make(ENV, obs_mode=mode)
    obs, _ = env.reset(seed=0)
    assert isinstance(env.observation_space, gym.spaces.Dict)
    assert env.observation_space.contains(obs), mode
    assert obs["agent"]["qpos"].shape == (9,)
    if mode == "state_dict":
        flat = gym.make(ENV).reset(seed=0)[0]
        parts = np.concatenate(
            [obs[g][k] for g in obs for k in obs[g]]
        )  # dict order is the flat layout's
        np.testing.assert_array_equal(np.sort(parts), np.sort(flat))
        return
    cam = obs["sensor_data"]["base_camera"]
    if mode in ("rgb", "rgbd"):
        assert cam["rgb"].dtype == np.uint8 and cam["rgb"].shape == (128, 128, 3)
        assert cam["rgb"].std() > 1, "a real image"
    else:
        assert "rgb" not in cam
    if mode in ("depth", "rgbd"):
        d = cam["depth"]
        assert d.dtype == np.float32 and d.shape == (128, 128, 1)
        assert 0.05 < np.median(d) < 5.0, "metres"
    obs2, *_ = env.step(env.action_space.sample())
    assert env.observation_space.contains(obs2)


def test_state_round_trip_is_bitwise():
    env = gym.make(ENV).unwrapped
    env.reset(seed=2)
    acts = random_actions(env.action_space, 20, seed=1)
    for a in acts[:10]:
        env.step(a)
    state = env.get_state()
    first = [env.step(a)[0] for a in acts[10:]]
    env.set_state(state)
    np.testing.assert_array_equal(env.get_obs(), env.get_obs())
    second = [env.step(a)[0] for a in acts[10:]]
    np.testing.assert_array_equal(np.stack(first), np.stack(second))


def test_state_dict_moves_the_cube():
    env = gym.make(ENV).unwrapped
    env.reset(seed=0)
    sd = env.get_state_dict()
    assert set(sd) >= {"actors", "articulations"}
    pose = np.asarray(sd["actors"]["cube"], np.float64)
    pose[0] += 0.05
    sd["actors"]["cube"] = pose  # numpy values are accepted
    env.set_state_dict(sd)
    got = np.asarray(env.get_state_dict()["actors"]["cube"])
    np.testing.assert_allclose(got[0], pose[0], atol=1e-9)


def test_pickled_env_continues_identically():
    env = gym.make(ENV).unwrapped
    env.reset(seed=9)
    acts = random_actions(env.action_space, 10, seed=3)
    for a in acts[:5]:
        env.step(a)
    clone = pickle.loads(pickle.dumps(env))
    for a in acts[5:]:
        o1, r1, *_ = env.step(a)
        o2, r2, *_ = clone.step(a)
        np.testing.assert_array_equal(o1, o2)
        assert r1 == r2


def test_async_vector_env_of_gym_make_envs_matches_the_native_one():
    asy = gym.make_vec(ENV, num_envs=2, vectorization_mode="async")
    nat = gym.make_vec(ENV, num_envs=2, vectorization_mode="vector_entry_point")
    try:
        o1, _ = asy.reset(seed=[5, 6])
        o2, _ = nat.reset(seed=5)
        np.testing.assert_array_equal(o1, o2)
        for a in random_actions(asy.single_action_space, 8, n=2, seed=4):
            o1, r1, t1, u1, _ = asy.step(a)
            o2, r2, t2, u2, _ = nat.step(a)
            np.testing.assert_array_equal(o1, o2)
            np.testing.assert_array_equal(r1.astype(np.float32), r2)
    finally:
        asy.close()
        nat.close()


@pytest.mark.parametrize(
    "robot,expected",
    [("panda", (16, 17)), ("so100", (11,)), ("xarm6_robotiq", tuple(range(18, 24)))],
)
def test_gripper_qvel_obs_are_the_gripper_joints_velocities(robot, expected):
    env = gym.make(ENV, robot_uids=robot, obs_mode="state")
    vec = gym.make_vec(ENV, robot_uids=robot, num_envs=2, vectorization_mode="vector_entry_point")
    assert env.unwrapped.gripper_qvel_obs == expected == vec.unwrapped.gripper_qvel_obs
    # A gripper action (the last entry) from rest moves them.
    moved = 0.0
    for sign in (-1.0, 1.0):
        env.reset(seed=0)
        act = np.zeros(env.action_space.shape, np.float32)
        act[-1] = sign
        obs, *_ = env.step(act)
        moved = max(moved, np.abs(obs[list(expected)]).max())
    assert moved > 1e-3
    assert gym.make(ENV, obs_mode="rgb").unwrapped.gripper_qvel_obs == ()


def test_every_env_class_takes_the_native_keywords_with_the_native_defaults():
    # One declaration: the native module's ENV_KWARGS (Rust's EnvConfig::default()).
    import inspect

    from mjskill import _native

    kwargs = _native.ENV_KWARGS
    assert kwargs["robot_init_qpos_noise"] == 0.02 and kwargs["sim_freq"] == 100
    for cls in (mjskill.MjskillEnv, mjskill.MjskillVectorEnv, mjskill.MjskillBatchedEnv):
        params = inspect.signature(cls).parameters
        for name, default in kwargs.items():
            assert params[name].default == default, (cls.__name__, name)
    assert mjskill.MjskillEnv.metadata["render_fps"] == _native.CONTROL_FREQ == 20
    with pytest.raises(TypeError, match=r"Env\(\) got an unexpected keyword argument 'foo'"):
        _native.Env("PickCube-v1", foo=1)


def test_reconfiguration_freq_zero_keeps_the_construction_shapes_until_asked():
    env = gym.make("mjskill/PegInsertionSide-v1", reconfiguration_freq=0)
    assert env.unwrapped.reconfiguration_freq == 0
    every = gym.make("mjskill/PegInsertionSide-v1")
    assert every.unwrapped.reconfiguration_freq == 1
    built = every.reset(seed=2022)[0][32:35]
    obs, info = env.reset(seed=1)
    assert info["reconfigure"] is False
    np.testing.assert_array_equal(obs[32:35], built)
    obs, info = env.reset(seed=1, options={"reconfigure": True})
    assert info["reconfigure"] is True
    np.testing.assert_array_equal(obs, every.reset(seed=1)[0])
    with pytest.raises(ValueError, match=r"unsupported reset options \['env_idx'\]; valid: reconfigure"):
        env.reset(options={"env_idx": [0]})
    with pytest.raises(ValueError, match="reconfiguration_freq must be None or an int >= 0"):
        gym.make("mjskill/PegInsertionSide-v1", reconfiguration_freq=-2)
