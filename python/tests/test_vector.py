"""The native vector env: gymnasium 1.x VectorEnv, next-step autoreset, equality with single
envs and across thread counts."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, VectorEnv

import mjskill
from conftest import ENV, random_actions


def make_vec(n=3, t=1, **kw):
    return gym.make_vec(ENV, num_envs=n, vectorization_mode="vector_entry_point", num_threads=t, **kw)


def test_is_a_gymnasium_vector_env_with_next_step_autoreset():
    v = make_vec(4, 2)
    assert isinstance(v, VectorEnv) and isinstance(v, mjskill.MjskillVectorEnv)
    assert v.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert v.num_envs == 4 and v.num_threads == 2
    assert v.action_space.shape == (4, 8) and v.observation_space.shape == (4, 42)
    obs, info = v.reset(seed=0)
    assert obs.shape == (4, 42) and obs.dtype == np.float32
    assert info["success"].shape == (4,) and info["_success"].all()
    o, r, te, tr, info = v.step(v.action_space.sample())
    assert r.shape == te.shape == tr.shape == (4,)
    assert te.dtype == tr.dtype == np.bool_
    assert v.observation_space.contains(o)


def single_trajectory(seed, actions, steps_per_episode):
    """One env through gym.make: reset(seed), then an unseeded reset after each episode end —
    what the vector env does on the step after the end (its action is ignored there)."""
    env = gym.make(ENV, max_episode_steps=steps_per_episode)
    obs, _ = env.reset(seed=seed)
    out, done = [], False
    for a in actions:
        if done:
            obs, info = env.reset()
            r, te, tr = 0.0, False, False
            done = False
        else:
            obs, r, te, tr, info = env.step(a)
            done = te or tr
        out.append((obs, np.float32(r), te, tr, info["is_grasped"]))
    return out


def test_same_seed_and_actions_identical_in_single_and_vector_envs_and_thread_counts():
    n, steps, limit = 3, 25, 10
    acts = random_actions(gym.spaces.Box(-1, 1, (8,), np.float32), steps, n=n, seed=7)
    results = {}
    for t in (1, 2):
        v = make_vec(n, t, max_episode_steps=limit)
        v.reset(seed=100)
        rows = [v.step(a) for a in acts]
        results[t] = rows
    for (o1, r1, te1, tr1, i1), (o2, r2, te2, tr2, i2) in zip(results[1], results[2]):
        np.testing.assert_array_equal(o1, o2)
        np.testing.assert_array_equal(r1, r2)
        np.testing.assert_array_equal(te1 | tr1, te2 | tr2)
        np.testing.assert_array_equal(i1["is_grasped"], i2["is_grasped"])
    for i in range(n):
        single = single_trajectory(100 + i, acts[:, i], limit)
        for (o, r, te, tr, g), (vo, vr, vte, vtr, vi) in zip(single, results[2]):
            np.testing.assert_array_equal(o, vo[i])
            assert r == vr[i] and te == vte[i] and tr == vtr[i]
            assert g == vi["is_grasped"][i]
    truncs = np.array([row[3] for row in results[1]])
    assert truncs[limit - 1].all() and truncs[2 * limit].all(), "episodes of 10 steps + autoreset"


def test_final_observation_then_autoreset_ignores_the_action():
    v = make_vec(2, 1, max_episode_steps=5)
    obs, _ = v.reset(seed=1)
    zero = np.zeros((2, 8), np.float32)
    for _ in range(4):
        v.step(zero)
    final, r, te, tr, info = v.step(zero)
    assert tr.all() and not v.autoreset.any()
    assert "final_obs" not in info and "final_info" not in info, "next-step mode"
    ref = gym.make(ENV, max_episode_steps=5)
    ref.reset(seed=1)
    for _ in range(5):
        ref_final = ref.step(zero[0])[0]
    np.testing.assert_array_equal(final[0], ref_final)
    # The autoreset step: any action gives the same new first observation, reward 0.
    state = [v.step(np.full((2, 8), a, np.float32)) for a in (0.9,)][0]
    first, r, te, tr, _ = state
    assert v.autoreset.all()
    np.testing.assert_array_equal(r, np.zeros(2, np.float32))
    assert not te.any() and not tr.any()
    np.testing.assert_array_equal(first[0], ref.reset()[0])
    # The step after the autoreset acts again.
    nxt, *_ = v.step(np.full((2, 8), 0.9, np.float32))
    assert not v.autoreset.any() and not np.array_equal(nxt, first)


def test_vector_images_match_single_env_images():
    v = make_vec(2, 2, obs_mode="rgbd")
    obs, _ = v.reset(seed=3)
    cam = obs["sensor_data"]["base_camera"]
    assert cam["rgb"].shape == (2, 128, 128, 3) and cam["rgb"].dtype == np.uint8
    assert cam["depth"].shape == (2, 128, 128, 1) and cam["depth"].dtype == np.float32
    assert v.observation_space.contains(obs)
    single, _ = gym.make(ENV, obs_mode="rgbd").reset(seed=4)
    np.testing.assert_array_equal(cam["rgb"][1], single["sensor_data"]["base_camera"]["rgb"])
    np.testing.assert_array_equal(obs["agent"]["qpos"][1], single["agent"]["qpos"])


def test_reset_accepts_the_consecutive_seed_list():
    v = make_vec(3)
    a, _ = v.reset(seed=[4, 5, 6])
    b, _ = v.reset(seed=4)
    np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="s \\+ i"):
        v.reset(seed=[4, 9, 2])


def test_float64_and_list_actions_are_accepted():
    v = make_vec(2)
    v.reset(seed=0)
    a = np.full((2, 8), 0.25)
    o1, *_ = v.step(a)
    v.reset(seed=0)
    o2, *_ = v.step(a.tolist())
    np.testing.assert_array_equal(o1, o2)


def test_vector_env_refuses_pickling_instead_of_losing_its_state():
    import pickle

    with pytest.raises(TypeError, match="pickle"):
        pickle.dumps(make_vec(2))
