"""Native rollouts: PPO's actor (mjskill.GaussianMlp) evaluated on the vector env's threads,
T steps per call (MjskillVectorEnv.rollout), and the same rollouts sharded over Ray actors
(mjskill.ray.RayVectorEnv), bit for bit; examples/ppo.py's training on both."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import mjskill
from mjskill import GaussianMlp, MjskillVectorEnv

from rollout_case import KW, params, ppo_args, rollout

REPO = Path(__file__).resolve().parents[2]


def test_rollout_steps_with_the_clipped_sampled_actions():
    n, t = 3, 8
    vec = MjskillVectorEnv("PickCube-v1", num_envs=n, num_threads=2, **KW)
    ref = MjskillVectorEnv("PickCube-v1", num_envs=n, num_threads=1, **KW)
    obs_dim = vec.single_observation_space.shape[0]
    act_dim = vec.single_action_space.shape[0]
    p = params(obs_dim, act_dim)
    vec.reset(seed=3)
    obs, _ = ref.reset(seed=3)
    buf, last = rollout(vec, p, t)
    mean_policy = GaussianMlp(**{k: v for k, v in p.items() if k not in ("std", "seed")})
    low, high = vec.single_action_space.low, vec.single_action_space.high
    for s in range(t):
        np.testing.assert_array_equal(buf["obs"][s], obs)
        raw = buf["actions"][s]
        stepping = ~buf["autoreset"][s]
        if stepping.any():
            noise = (raw - mean_policy.mean(obs))[stepping]
            assert 0.05 < noise.std() < 0.6, "sampled with std 0.3 around the mean"
        obs, r, term, trunc, _ = ref.step(np.clip(raw, low, high))
        np.testing.assert_array_equal(buf["rewards"][s], r)
        np.testing.assert_array_equal(buf["terminated"][s], term)
        np.testing.assert_array_equal(buf["truncated"][s], trunc)
        np.testing.assert_array_equal(buf["autoreset"][s], ref.autoreset)
    np.testing.assert_array_equal(last, obs)
    # 6-step episodes: every env resets at step 6, the step after its truncation.
    assert buf["truncated"][5].all() and buf["autoreset"][6].all()
    assert buf["autoreset"].sum() == n
    assert (np.abs(buf["actions"]) > 1).any(), "some raw actions leave the bounds"


def test_rollout_rejects_bad_buffers_and_policies():
    vec = MjskillVectorEnv("PickCube-v1", num_envs=2, **KW)
    obs_dim = vec.single_observation_space.shape[0]
    act_dim = vec.single_action_space.shape[0]
    buf = vec.rollout_buffers(3)
    buf["actions"] = np.zeros((3, 2, act_dim // 2), np.float32)
    with pytest.raises(ValueError, match=r"rollout buffer actions has shape \[3, 2, 4\], "
                                         r"expected \[3, 2, 8\]"):
        vec.rollout(GaussianMlp(**params(obs_dim, act_dim)), 0, buf)
    buf["actions"] = np.zeros((3, 2, 2 * act_dim), np.float32)[:, :, ::2]
    with pytest.raises(ValueError, match="rollout buffer actions must be C-contiguous"):
        vec.rollout(GaussianMlp(**params(obs_dim, act_dim)), 0, buf)
    with pytest.raises(ValueError, match="maps 5 observations to 8 actions"):
        vec.rollout(GaussianMlp(**params(5, act_dim)), 0, vec.rollout_buffers(3))
    bad = params(obs_dim, act_dim)
    bad["obs_std"][4] = 0.0
    with pytest.raises(ValueError, match=r"obs_std\[4\] = 0"):
        GaussianMlp(**bad)
    visual = MjskillVectorEnv("PickCube-v1", num_envs=1, obs_mode="rgb", **KW)
    with pytest.raises(ValueError, match="flat observations"):
        visual.rollout_buffers(2)


@pytest.fixture(scope="module")
def local_ray():
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def test_ray_actors_that_cannot_fit_the_cluster_fail_at_once(local_ray):
    # Issue 42, item 11: 2 workers × 2 threads on ray.init(num_cpus=2) waited forever.
    from mjskill.ray import RayVectorEnv

    with pytest.raises(ValueError, match=r"workers × num_threads = 2 × 2 = 4 CPUs, but the "
                                         r"Ray cluster has 2"):
        RayVectorEnv("PickCube-v1", 4, workers=2, num_threads=2, **KW)
    with pytest.raises(ValueError, match="num_envs 0 is out of range"):
        RayVectorEnv("PickCube-v1", 0, workers=1, **KW)


def test_a_stopped_ray_actor_is_a_timeout_error_not_a_hang(local_ray):
    # Issue 42: a SIGSTOPped actor blocked RayVectorEnv.rollout forever.
    import signal

    import ray
    from mjskill.ray import RayVectorEnv

    remote = RayVectorEnv("PickCube-v1", 3, workers=2, timeout=5, **KW)
    remote.reset(seed=1)
    obs_dim = remote.single_observation_space.shape[0]
    act_dim = remote.single_action_space.shape[0]
    pid = ray.get(remote._actors[1].pid.remote())
    os.kill(pid, signal.SIGSTOP)
    try:
        with pytest.raises(TimeoutError, match=r"actor\(s\) \[1\] \(envs 2..2\) did not answer "
                                               r"rollout within 5 s"):
            remote.rollout(params(obs_dim, act_dim), 0, remote.rollout_buffers(2))
    finally:
        os.kill(pid, signal.SIGCONT)
        remote.close()


def test_ray_shards_roll_out_bit_for_bit_as_one_vector_env(local_ray):
    from mjskill.ray import RayVectorEnv

    n, t = 5, 7  # uneven shares: 3 + 2 envs
    local = MjskillVectorEnv("PickCube-v1", num_envs=n, num_threads=2, **KW)
    remote = RayVectorEnv("PickCube-v1", n, workers=2, **KW)
    assert remote.shares == [(0, 3), (3, 2)]
    # One node here: both actors on it (test_ray_cluster.py puts them on two).
    where = remote.nodes()
    assert len(where) == 2 and len({node for node, _ in where}) == 1, where
    obs_dim = local.single_observation_space.shape[0]
    act_dim = local.single_action_space.shape[0]
    np.testing.assert_array_equal(remote.reset(seed=9), local.reset(seed=9)[0])
    for it in range(2):
        p = params(obs_dim, act_dim, seed=it)
        a, last_a = rollout(local, p, t, first_step=it * t)
        b = remote.rollout_buffers(t)
        last_b = remote.rollout(p, it * t, b)
        for key in a:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
        np.testing.assert_array_equal(last_a, last_b)
    remote.close()


def test_ray_env_refuses_what_the_local_env_refuses_before_stepping(local_ray):
    # Issue 48: a bad buffer failed only after the actors had stepped (or not at all), reset
    # after close said "need at least one array to concatenate", timeout=inf overflowed.
    from mjskill.ray import RayVectorEnv

    remote = RayVectorEnv("PickCube-v1", 3, workers=2, timeout=float("inf"), **KW)
    assert remote.timeout is None
    obs_dim = remote.single_observation_space.shape[0]
    act_dim = remote.single_action_space.shape[0]
    p = params(obs_dim, act_dim)
    start = remote.reset(seed=3)
    good = remote.rollout_buffers(2)
    bad = [
        ({**good, "obs": good["obs"][:, :2]}, ValueError, r"buffers\['obs'\] is float32"),
        ({**good, "rewards": good["rewards"].astype(np.float64)}, ValueError, "float64"),
        ({**good, "actions": np.asfortranarray(good["actions"][:, :, :1].repeat(
            act_dim, 2))}, ValueError, "C-contiguous"),
        ({**good, "truncated": good["terminated"]}, ValueError, "share memory"),
        ({k: v for k, v in good.items() if k != "autoreset"}, ValueError, "lack autoreset"),
        ([], TypeError, "must be the dict"),
    ]
    for buffers, kind, match in bad:
        with pytest.raises(kind, match=match):
            remote.rollout(p, 0, buffers)
    with pytest.raises(ValueError, match="first_step"):
        remote.rollout(p, 2**48 - 1, good)
    # Nothing stepped: the envs are where the reset left them.
    local = MjskillVectorEnv("PickCube-v1", num_envs=3, num_threads=1, **KW)
    np.testing.assert_array_equal(start, local.reset(seed=3)[0])
    a, last_a = rollout(local, p, 2, first_step=0)
    np.testing.assert_array_equal(remote.rollout(p, 0, good), last_a)
    remote.close()
    with pytest.raises(RuntimeError, match="RayVectorEnv is closed"):
        remote.reset(seed=0)
    with pytest.raises(RuntimeError, match="RayVectorEnv is closed"):
        remote.rollout(p, 0, good)
    with pytest.raises(ValueError, match="timeout must be"):
        RayVectorEnv("PickCube-v1", 1, workers=1, timeout=float("nan"), **KW)
    with pytest.raises(TypeError, match="spread must be True or False, not 'yes'"):
        RayVectorEnv("PickCube-v1", 1, workers=1, spread="yes", **KW)


def ppo(tmp_path, name, *extra):
    out = tmp_path / name
    cmd = [sys.executable, str(REPO / "examples" / "ppo.py"), *ppo_args(out), *extra]
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}  # a local Ray
    subprocess.run(cmd, check=True, env=env, capture_output=True, timeout=600)
    return out


def test_ppo_learns_the_same_weights_with_ray_workers(tmp_path):
    torch = pytest.importorskip("torch")
    pytest.importorskip("ray")
    local = torch.load(ppo(tmp_path, "local") / "policy.pt", weights_only=False)
    remote = torch.load(ppo(tmp_path, "ray", "--ray-workers", "2") / "policy.pt",
                        weights_only=False)
    for part in ("actor", "critic"):
        for key, value in local[part].items():
            assert torch.equal(value, remote[part][key]), f"{part}.{key}"
    assert torch.equal(local["logstd"], remote["logstd"])
    np.testing.assert_array_equal(local["obs_mean"], remote["obs_mean"])
    assert mjskill.__version__
