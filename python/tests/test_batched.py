"""gym.make(id, num_envs=N): ManiSkill's batched env (per-env truncation, no autoreset,
partial resets), gymnasium's TimeLimit disarmed around it, and mjskill.ManiSkillVectorEnv
over it."""

import gymnasium as gym
import numpy as np
import pytest

import mjskill
from conftest import ENV, random_actions
from mjskill.batched import MjskillBatchedEnv


def make(n=3, **kw):
    kw.setdefault("array_backend", "numpy")
    kw.setdefault("num_threads", 2)
    return gym.make(ENV, num_envs=n, **kw)


def single(seed, **kw):
    env = gym.make(ENV, **kw)
    obs, _ = env.reset(seed=seed)
    return env, obs


def wrappers(env):
    out = []
    while isinstance(env, gym.Wrapper):
        out.append(type(env).__name__)
        env = env.env
    return out


def test_gym_make_num_envs_returns_the_batched_env():
    env = make(4)
    base = env.unwrapped
    assert isinstance(base, MjskillBatchedEnv) and isinstance(base, gym.Env)
    # No PassiveEnvChecker (it expects scalar rewards); the TimeLimit is disarmed (below).
    assert wrappers(env) == ["TimeLimit", "OrderEnforcing"]
    assert env.spec.max_episode_steps == 50 and base.max_episode_steps == 50
    assert base.num_envs == 4 and base.num_threads == 2 and base.reconfiguration_freq == 0
    assert env.action_space.shape == (4, 8) and env.observation_space.shape == (4, 42)
    assert base.single_action_space.shape == (8,)
    assert env.get_wrapper_attr("single_observation_space").shape == (42,)
    obs, info = env.reset(seed=0)
    assert obs.shape == (4, 42) and obs.dtype == np.float32
    assert info["success"].shape == (4,) and (info["elapsed_steps"] == 0).all()
    assert "_success" not in info  # ManiSkill's info has no gymnasium masks
    o, r, te, tr, info = env.step(env.action_space.sample())
    assert r.shape == te.shape == tr.shape == (4,) and r.dtype == np.float32
    assert te.dtype == tr.dtype == np.bool_
    assert (info["elapsed_steps"] == 1).all()
    # One env is still the plain single env with gymnasium's usual wrappers.
    one = gym.make(ENV, num_envs=1)
    assert isinstance(one.unwrapped, mjskill.MjskillEnv)
    assert wrappers(one) == ["TimeLimit", "OrderEnforcing", "PassiveEnvChecker"]
    assert one.spec.max_episode_steps == 50


def test_a_vector_info_value_is_one_array_per_env_as_maniskills():
    env = gym.make("mjskill/PegInsertionSide-v1", num_envs=3, array_backend="numpy")
    _, info = env.reset(seed=0, options={"reconfigure": True})
    assert info["reconfigure"] is True and info["success"].shape == (3,)
    a = env.action_space.sample()
    _, _, _, _, info = env.step(a)
    head = info["peg_head_pos_at_hole"]
    assert head.shape == (3, 3) and (head[:, 0] < -0.1).all()
    assert not any(k.startswith("peg_head_pos_at_hole[") for k in info)
    # Env i is the single env seeded 0 + i: row i is its vector.
    one = gym.make("mjskill/PegInsertionSide-v1")
    one.reset(seed=2)
    _, _, _, _, single = one.step(a[2])
    np.testing.assert_array_equal(head[2], single["peg_head_pos_at_hole"])


def test_gymnasium_time_limit_never_ends_all_envs_with_a_scalar():
    env = make(2)
    env.reset(seed=0)
    zeros = np.zeros((2, 8), np.float32)
    for k in range(60):
        _, _, te, tr, info = env.step(zeros)
        # Arrays every step, true per env from step 50 on (no env succeeds standing still).
        assert isinstance(tr, np.ndarray) and tr.shape == (2,), k
        assert list(tr) == [k + 1 >= 50] * 2 and not te.any(), k
    assert list(info["elapsed_steps"]) == [60, 60]
    # A TimeLimit added around it sets the limit too (the smallest one counts).
    short = gym.wrappers.TimeLimit(make(2), max_episode_steps=3)
    short.reset(seed=0)
    trs = [short.step(zeros)[3] for _ in range(4)]
    assert [list(t) for t in trs] == [[False] * 2, [False] * 2, [True] * 2, [True] * 2]


def test_env_i_is_the_single_env_seeded_s_plus_i():
    env = make(3)
    obs, _ = env.reset(seed=40)
    acts = random_actions(env.unwrapped.single_action_space, 6, 3)
    refs = [single(40 + i) for i in range(3)]
    for i, (_, o) in enumerate(refs):
        np.testing.assert_array_equal(obs[i], o)
    for a in acts:
        obs, r, te, tr, _ = env.step(a)
        for i, (e, _) in enumerate(refs):
            o, ri, tei, _, _ = e.step(a[i])
            np.testing.assert_array_equal(obs[i], o)
            assert r[i] == np.float32(ri) and te[i] == tei


def test_each_env_truncates_on_its_own_and_keeps_stepping_until_reset():
    env = make(2, max_episode_steps=5)
    env.reset(seed=3)
    assert env.unwrapped.max_episode_steps == 5 and env.spec.max_episode_steps == 5
    ref, _ = single(4, max_episode_steps=1000)  # env 1, never truncated by gymnasium
    acts = random_actions(env.unwrapped.single_action_space, 9, 2, seed=1)
    for k in range(2):
        _, _, _, tr, _ = env.step(acts[k])
        ref.step(acts[k][1])
        assert not tr.any()
    # Env 0 restarts at step 2: its limit comes 2 steps after env 1's.
    obs, info = env.reset(options={"env_idx": [0]})
    assert list(info["elapsed_steps"]) == [0, 2]
    for k in range(2, 9):
        obs, _, _, tr, info = env.step(acts[k])
        o, *_ = ref.step(acts[k][1])
        assert list(tr) == [k - 1 >= 5, k + 1 >= 5], k
        assert info["elapsed_steps"][1] == k + 1
        # Past its limit env 1 is neither reset nor frozen: it is the single env stepping on.
        np.testing.assert_array_equal(obs[1], o)


def test_partial_reset_resets_only_the_given_envs():
    env = make(3)
    env.reset(seed=100)
    acts = random_actions(env.unwrapped.single_action_space, 3, 3, seed=2)
    for a in acts:
        before, *_ = env.step(a)
    # Indices, a bool mask or a torch tensor (below) select the envs; seed s gives env i s + i.
    obs, info = env.reset(seed=200, options={"env_idx": np.array([2])})
    _, ref = single(202)
    np.testing.assert_array_equal(obs[2], ref)
    np.testing.assert_array_equal(obs[:2], before[:2])
    assert list(info["elapsed_steps"]) == [3, 3, 0]
    obs, info = env.reset(options={"env_idx": np.array([True, False, False])})
    assert list(info["elapsed_steps"]) == [0, 3, 0]
    with pytest.raises(ValueError, match=r"env_idx 3 is out of range: the envs are 0..2"):
        env.reset(options={"env_idx": [3]})
    with pytest.raises(ValueError, match=r"boolean mask of shape \(2,\), expected \(3,\)"):
        env.reset(options={"env_idx": [True, False]})
    with pytest.raises(ValueError, match=r"unsupported reset options \['foo'\]; valid: env_idx"):
        env.reset(options={"foo": 1})


def test_bad_keywords_name_the_valid_choices():
    with pytest.raises(ValueError, match=r"unknown array_backend 'jax'; valid: torch, numpy"):
        make(2, array_backend="jax")
    with pytest.raises(ValueError, match=r"unknown sim_backend 'tpu'; valid: auto, cpu"):
        make(2, sim_backend="tpu")
    with pytest.raises(ValueError, match=r"unknown sim_backend 'tpu'"):
        gym.make(ENV, sim_backend="tpu")
    with pytest.raises(ValueError, match=r"reconfiguration_freq must be None or an int >= 0"):
        make(2, reconfiguration_freq=-1)
    with pytest.raises(TypeError, match="num_envs must be an int"):
        gym.make(ENV, num_envs="4")
    with pytest.raises(ValueError, match="num_envs 0 is out of range"):
        gym.make(ENV, num_envs=0)
    with pytest.raises(ValueError, match=r"array_backend, num_threads apply to the batched env"):
        gym.make(ENV, num_envs=1, num_threads=2, array_backend="numpy")
    with pytest.raises(ValueError, match="unknown robot"):
        make(2, robot_uids="ur5")
    # ManiSkill's keywords as its scripts pass them are accepted.
    env = make(2, sim_backend="physx_cuda", reconfiguration_freq=1, render_mode="rgb_array")
    env.reset(seed=0)
    with pytest.raises(RuntimeError, match="renders no human-camera frames"):
        env.render()
    with pytest.raises(ValueError, match=r"actions have shape \(8,\), expected \(num_envs"):
        env.step(np.zeros(8, np.float32))


def test_gym_make_of_its_spec_recreates_it():
    env = make(2, max_episode_steps=7)
    again = gym.make(env.spec)
    again.reset(seed=0)
    assert isinstance(again.unwrapped, MjskillBatchedEnv)
    assert again.unwrapped.max_episode_steps == 7 and again.unwrapped.num_envs == 2
    assert wrappers(again) == ["TimeLimit", "OrderEnforcing"]
    # make_vec still gives the native vector env (its entry point is unaffected).
    v = gym.make_vec(ENV, num_envs=2)
    assert isinstance(v, mjskill.MjskillVectorEnv)


def test_maniskill_vector_env_autoresets_in_the_same_step_with_final_obs_and_metrics():
    n, steps = 2, 4
    env = make(n, max_episode_steps=steps)
    vec = mjskill.ManiSkillVectorEnv(env, n, record_metrics=True)
    assert vec.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    assert vec.single_action_space.shape == (8,) and vec.num_envs == n
    # A twin batched env stepped by hand shows what the wrapper must return.
    twin = make(n, max_episode_steps=steps)
    obs, _ = vec.reset(seed=9)
    tobs, _ = twin.reset(seed=9)
    np.testing.assert_array_equal(obs, tobs)
    acts = random_actions(twin.unwrapped.single_action_space, steps, n, seed=5)
    ret = np.zeros(n, np.float32)
    for k, a in enumerate(acts):
        obs, r, te, tr, info = vec.step(a)
        tobs, tr_, *_ = twin.step(a)
        ret += tr_
        if k < steps - 1:
            np.testing.assert_array_equal(obs, tobs)
            assert "final_info" not in info
    # The last step truncated both: the returned obs start new episodes (unseeded resets),
    # the ended step's obs and metrics are in final_observation / final_info.
    assert tr.all() and info["_final_info"].all()
    np.testing.assert_array_equal(info["final_observation"], tobs)
    assert not np.array_equal(obs, tobs)
    tobs, _ = twin.reset(options={"env_idx": [0, 1]})
    np.testing.assert_array_equal(obs, tobs)
    ep = info["final_info"]["episode"]
    np.testing.assert_allclose(ep["return"], ret, rtol=1e-6)
    assert list(ep["episode_len"]) == [steps, steps]
    assert (info["elapsed_steps"] == 0).all()


def test_maniskill_vector_env_ignore_terminations_reports_success_at_end():
    env = make(2)
    vec = mjskill.ManiSkillVectorEnv(env, ignore_terminations=True, record_metrics=True)
    vec.reset(seed=0)
    _, _, te, _, info = vec.step(np.zeros((2, 8), np.float32))
    assert not te.any() and "success_at_end" in info["episode"]
    with pytest.raises(TypeError, match="wraps the batched env"):
        mjskill.ManiSkillVectorEnv(gym.make(ENV))


def test_torch_backend_gives_cpu_tensors_and_takes_tensor_actions():
    torch = pytest.importorskip("torch")
    env = gym.make(ENV, num_envs=2, num_threads=1)  # torch is the default, as in ManiSkill
    obs, info = env.reset(seed=1)
    assert isinstance(obs, torch.Tensor) and obs.shape == (2, 42) and obs.dtype == torch.float32
    assert env.unwrapped.device == torch.device("cpu")
    o, r, te, tr, info = env.step(torch.zeros(2, 8))
    assert r.dtype == torch.float32 and te.dtype == tr.dtype == torch.bool
    assert info["success"].dtype == torch.bool
    assert env.unwrapped.elapsed_steps.tolist() == [1, 1]
    ref = make(2, num_threads=1)
    ref.reset(seed=1)
    ro, *_ = ref.step(np.zeros((2, 8), np.float32))
    np.testing.assert_array_equal(o.numpy(), ro)
    vec = mjskill.ManiSkillVectorEnv(env, record_metrics=True)
    vec.reset(options={"env_idx": torch.tensor([1])})
    _, _, _, _, info = vec.step(torch.zeros(2, 8))
    assert isinstance(info["episode"]["return"], torch.Tensor)


def test_bad_options_nan_and_bool_actions_are_clear_errors():
    env = make(4)
    with pytest.raises(TypeError, match="options must be a dict .* got list"):
        env.reset(seed=0, options=[1, 2])
    env.reset(seed=0)
    a = np.zeros(env.unwrapped.action_space.shape, np.float32)
    a[3, 5] = np.nan
    with pytest.raises(ValueError, match=r"\(env 3, action component 5\) is not finite"):
        env.step(a)
    with pytest.raises(TypeError, match="got dtype bool"):
        env.step(np.ones(env.unwrapped.action_space.shape, bool))
    env.step(np.zeros(env.unwrapped.action_space.shape, np.float32))


def test_close_twice_is_harmless_and_use_after_close_raises():
    env = make(2)
    env.reset(seed=0)
    env.close()
    env.close()
    base = env.unwrapped
    with pytest.raises(RuntimeError, match="is closed"):
        base.reset(seed=0)
    with pytest.raises(RuntimeError, match="is closed"):
        base.step(np.zeros(base.action_space.shape, np.float32))
    with pytest.raises(RuntimeError, match="renders no human-camera frames"):
        base.render()


def test_the_gymnasium_vector_env_gives_a_vector_info_value_as_one_array():
    env = mjskill.MjskillVectorEnv("PegInsertionSide-v1", num_envs=3)
    _, info = env.reset(seed=0, options={"reconfigure": True})
    assert info["peg_head_pos_at_hole"].shape == (3, 3)
    assert info["_peg_head_pos_at_hole"].shape == (3,) and info["_peg_head_pos_at_hole"].all()
    a = env.action_space.sample()
    _, _, _, _, info = env.step(a)
    assert not any(k.startswith(("peg_head_pos_at_hole[", "_peg_head_pos_at_hole[")) for k in info)
    # Env i is the single env seeded 0 + i: row i is its vector.
    one = gym.make("mjskill/PegInsertionSide-v1")
    one.reset(seed=1)
    _, _, _, _, single = one.step(a[1])
    np.testing.assert_array_equal(info["peg_head_pos_at_hole"][1], single["peg_head_pos_at_hole"])


def test_a_batch_keeps_each_envs_construction_shapes_as_maniskills_does():
    """ManiSkill's gym.make(num_envs=N) defaults to reconfiguration_freq 0: env i keeps the
    peg and hole of its construction seed 2022 + i until a reset asks for a redraw."""
    env = gym.make("mjskill/PegInsertionSide-v1", num_envs=2, array_backend="numpy")
    assert env.unwrapped.reconfiguration_freq == 0
    one = gym.make("mjskill/PegInsertionSide-v1")
    built = [one.reset(seed=2022 + i)[0][32:35] for i in range(2)]
    for seed in (5, 7):
        obs, info = env.reset(seed=seed)
        assert info["reconfigure"] is False
        for i in range(2):
            np.testing.assert_array_equal(obs[i][32:35], built[i])
    obs, info = env.reset(seed=5, options={"reconfigure": True})
    assert info["reconfigure"] is True
    np.testing.assert_array_equal(obs[1], one.reset(seed=6)[0])
    with pytest.raises(RuntimeError, match="partial reset and reconfigure"):
        env.reset(options={"env_idx": [0], "reconfigure": True})
    with pytest.raises(TypeError, match=r"options\['reconfigure'\] must be a bool, got 'yes'"):
        env.reset(options={"reconfigure": "yes"})
    # Asked for every reset, as ManiSkill's single env: redrawn from the seeds, and a partial
    # reset, which would be due to rebuild, is refused as ManiSkill refuses it.
    every = gym.make("mjskill/PegInsertionSide-v1", num_envs=2, reconfiguration_freq=1,
                     array_backend="numpy")
    obs, info = every.reset(seed=5)
    assert info["reconfigure"] is True
    np.testing.assert_array_equal(obs[1], one.reset(seed=6)[0])
    with pytest.raises(RuntimeError, match="partial reset and reconfigure"):
        every.reset(options={"env_idx": [1]})
