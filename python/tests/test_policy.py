"""Policy files in Python (mjskill.policy.OnnxPolicy, onnxruntime).

The policy tests need ``onnx`` (to make the file, examples/make_test_policy.py) and
``onnxruntime``; without them they are skipped, except in CI (``CI`` set), where .ci/setup
installs both and a missing one is a failure."""

import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import mjskill
from conftest import ENV, mjskill_bin, need

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "examples" / "make_test_policy.py"
sys.path.insert(0, str(ROOT / "examples"))


def make_policy(tmp_path, name, obs_dim, act_dim, *extra):
    need("onnx")
    out = tmp_path / name
    subprocess.run(
        [sys.executable, str(SCRIPT), "--obs-dim", str(obs_dim), "--act-dim", str(act_dim),
         "--env-id", "PickCube-v1", "--robot", "panda", "--control-mode", "pd_ee_delta_pos",
         "--out", str(out), "--weights-json", str(out.with_suffix(".json")), *extra],
        check=True,
    )
    return out


@pytest.fixture
def dims():
    env = gym.make(ENV, robot_uids="panda", control_mode="pd_ee_delta_pos")
    return env.observation_space.shape[0], env.action_space.shape[0]


def test_onnx_policy_matches_numpy_and_clips(tmp_path, dims):
    need("onnxruntime")
    from policy_onnx import mlp_forward

    from mjskill.policy import OnnxPolicy

    f = make_policy(tmp_path, "p.onnx", *dims, "--seed", "5")
    w = json.loads(f.with_suffix(".json").read_text())
    layers = [(np.array(l["w"]), np.array(l["b"])) for l in w["layers"]]
    policy = OnnxPolicy(f)
    assert (policy.env_id, policy.robot_uids, policy.control_mode) == (
        "PickCube-v1", "panda", "pd_ee_delta_pos")
    assert "make_test_policy.py" in policy.training_command
    env = policy.make_env()
    assert env.unwrapped.control_mode == "pd_ee_delta_pos"
    obs, _ = env.reset(seed=0)
    batch, clipped = [], 0
    for _ in range(20):
        a = policy(obs)
        want = mlp_forward(obs, layers, np.array(w["obs_mean"]), np.array(w["obs_std"]),
                           w["obs_clip"])
        clipped += int(np.sum((want < policy.low) | (want > policy.high)))
        np.testing.assert_allclose(a, np.clip(want, policy.low, policy.high), atol=1e-5)
        assert a.dtype == np.float32 and a.shape == (dims[1],)
        batch.append(obs)
        obs, *_ = env.step(a)
    assert clipped > 0
    # A batch gives the rows' actions.
    b = np.stack(batch)
    np.testing.assert_allclose(policy(b), np.stack([policy(o) for o in batch]), atol=1e-6)


def test_onnx_policy_agrees_with_the_cli(tmp_path, dims):
    """The same file run by onnxruntime in Python and by tract in `mjskill eval`."""
    need("onnxruntime")
    from mjskill.policy import OnnxPolicy

    f = make_policy(tmp_path, "cli.onnx", *dims)
    policy = OnnxPolicy(f)
    env = policy.make_env()
    returns = []
    for seed in (3, 4):
        obs, _ = env.reset(seed=seed)
        ret, done = 0.0, False
        while not done:
            obs, r, term, trunc, _ = env.step(policy(obs))
            ret += float(r)
            done = trunc  # as `mjskill eval`: episodes run to truncation
        returns.append(ret)
    exe = mjskill_bin("onnx")
    run = subprocess.run([exe, "eval", "--episodes", "2", "--seed", "3", "--policy", str(f)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    report = json.loads(run.stdout)
    assert report["robot"] == "panda" and report["control_mode"] == "pd_ee_delta_pos"
    # Two runtimes round differently in the last bits; the episodes stay within 1e-3.
    assert abs(report["mean_return"] - np.mean(returns)) < 1e-3, (report, returns)


def test_onnx_policy_errors_name_the_file(tmp_path, dims):
    need("onnxruntime")
    from mjskill.policy import OnnxPolicy

    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"not a model")
    with pytest.raises(ValueError, match="bad.onnx is not a valid ONNX model"):
        OnnxPolicy(bad)
    with pytest.raises(FileNotFoundError, match="cannot read policy file"):
        OnnxPolicy(tmp_path / "missing.onnx")
    wide = make_policy(tmp_path, "wide.onnx", dims[0] + 2, dims[1])
    with pytest.raises(ValueError, match=f"observations of {dims[0] + 2} values.*gives {dims[0]}"):
        OnnxPolicy(wide)
    out = make_policy(tmp_path, "out.onnx", dims[0], dims[1] + 1)
    with pytest.raises(ValueError, match=f"actions of {dims[1] + 1} values.*takes {dims[1]}"):
        OnnxPolicy(out)
    ok = make_policy(tmp_path, "ok.onnx", *dims)
    with pytest.raises(ValueError, match="robot_uids 'panda', but the env has 'fetch'"):
        OnnxPolicy(ok, env=gym.make(ENV, robot_uids="fetch"))
    with pytest.raises(ValueError, match="control_mode 'pd_ee_delta_pos', but 'pd_joint_pos'"):
        OnnxPolicy(ok).make_env(control_mode="pd_joint_pos")
    bare = make_policy(tmp_path, "bare.onnx", *dims, "--drop-meta", "env_id")
    with pytest.raises(ValueError, match="lacks the metadata_props env_id"):
        OnnxPolicy(bare)


def test_onnx_policy_runs_a_vector_env(tmp_path, dims):
    need("onnxruntime")
    from mjskill.policy import OnnxPolicy

    policy = OnnxPolicy(make_policy(tmp_path, "vec.onnx", *dims))
    v = policy.make_vec(3)
    obs, _ = v.reset(seed=0)
    a = policy(obs)
    assert a.shape == (3, dims[1])
    v.step(a)


def test_onnx_policy_runs_the_batched_env(tmp_path, dims):
    # gym.make(..., num_envs=N), ManiSkill's batched env (python/tests/test_batched.py).
    need("onnxruntime")
    from mjskill.policy import OnnxPolicy

    policy = OnnxPolicy(make_policy(tmp_path, "batched.onnx", *dims))
    env = policy.make_env(num_envs=3, array_backend="numpy")
    OnnxPolicy(policy.path, env=env)  # the wrapped batched env is checked per env
    obs, _ = env.reset(seed=0)
    a = policy(obs)
    assert a.shape == (3, dims[1])
    env.step(a)
