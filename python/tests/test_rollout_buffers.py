"""Issue 42: the arrays given to native rollouts (GaussianMlp's weights and observations, the
rollout buffers) are checked before anything is copied or stepped: dtype, exact shape, C
order, size, writability and overlap (docs/limits.md). Every bad array is a TypeError or
ValueError naming it, never an abort, a PanicException or scrambled data; the vector env's
close(), the noise's step range and Ray's CPU check and timeout."""

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from mjskill import GaussianMlp, MjskillVectorEnv
from test_rollout import params as rollout_params

KW = dict(max_episode_steps=6)


def params(obs_dim, act_dim, seed=0, hidden=8):
    """test_rollout's seeded GaussianMlp arguments, with 8 hidden units."""
    return rollout_params(obs_dim, act_dim, seed=seed, hidden=hidden)


@pytest.fixture(scope="module")
def vec():
    return MjskillVectorEnv("PickCube-v1", num_envs=3, num_threads=2, **KW)


@pytest.fixture(scope="module")
def policy(vec):
    od = vec.single_observation_space.shape[0]
    ad = vec.single_action_space.shape[0]
    return GaussianMlp(**params(od, ad))


def run_python(code):
    """Runs ``code`` in a fresh interpreter: (returncode, stdout + stderr)."""
    p = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                       text=True, timeout=600)
    return p.returncode, p.stdout + p.stderr


# -- item 1: huge inputs never abort the interpreter ----------------------------------------

def test_huge_broadcast_inputs_are_value_errors_not_aborts():
    rc, out = run_python("""
        import numpy as np
        from mjskill import GaussianMlp
        p = GaussianMlp([(np.zeros((42, 4), np.float32), np.zeros(4, np.float32))],
                        np.zeros(42), np.ones(42))
        for what, call in [
            ("rows", lambda: p.mean(np.broadcast_to(np.float32(0), (2 * 10**9, 42)))),
            ("bias-only rows", lambda: GaussianMlp([(np.zeros((0, 3), np.float32),
                np.zeros(3, np.float32))], np.zeros(0), np.zeros(0)).mean(
                np.zeros((10**11, 0), np.float32))),
            ("weights", lambda: GaussianMlp([(np.broadcast_to(np.float32(0), (200000, 200000)),
                np.zeros(200000, np.float32))], np.zeros(200000), np.ones(200000))),
            ("obs_mean", lambda: GaussianMlp([(np.zeros((1, 1), np.float32),
                np.zeros(1, np.float32))], np.broadcast_to(0.0, (10**11,)), np.ones(1))),
        ]:
            try:
                call()
            except ValueError as e:
                print(what, "->", e)
            else:
                print(what, "-> accepted")
    """)
    assert rc == 0, out
    assert "accepted" not in out, out
    assert "rows -> observations have 2000000000 rows" in out, out
    assert "bias-only rows -> observations have 100000000000 rows" in out, out
    assert "more than the 16777216" in out, out


# -- item 2: Fortran order ------------------------------------------------------------------

def test_fortran_ordered_buffers_are_refused(vec, policy):
    buf = vec.rollout_buffers(3)
    buf["obs"] = np.asfortranarray(buf["obs"])
    with pytest.raises(ValueError, match="rollout buffer obs must be C-contiguous"):
        vec.rollout(policy, 0, buf)
    buf = vec.rollout_buffers(3)
    buf["rewards"] = np.asfortranarray(buf["rewards"])
    with pytest.raises(ValueError, match="rewards must be C-contiguous"):
        vec.rollout(policy, 0, buf)


# -- item 3: shapes -------------------------------------------------------------------------

def test_buffers_of_the_right_size_but_the_wrong_shape_are_refused(vec, policy):
    # An (N, T) rewards buffer of T = 4 steps for N = 3 envs (filled step-major before).
    buf = vec.rollout_buffers(4)
    buf["rewards"] = buf["rewards"].reshape(3, 4)
    with pytest.raises(ValueError, match=r"rewards has shape \[3, 4\], expected \[T, 3\]"):
        vec.rollout(policy, 0, buf)
    buf = vec.rollout_buffers(4)
    buf["obs"] = buf["obs"].reshape(4, -1)
    with pytest.raises(ValueError, match=r"rollout buffer obs has shape \[4, 126\], expected 3"):
        vec.rollout(policy, 0, buf)
    buf = vec.rollout_buffers(4)
    buf["actions"] = np.zeros((4, 4, 6), np.float32)
    with pytest.raises(ValueError, match=r"actions has shape \[4, 4, 6\], expected \[4, 3, 8\]"):
        vec.rollout(policy, 0, buf)


def test_torch_style_out_in_weights_are_refused_with_the_fix():
    w = np.zeros((16, 42), np.float32)  # torch's Linear(42, 16).weight: (out, in)
    with pytest.raises(ValueError, match=r"shape \(16, 42\), expected \(inputs, outputs\) = "
                                         r"\(42, 16\).*pass weight.T"):
        GaussianMlp([(w, np.zeros(16, np.float32))], np.zeros(42), np.ones(42))
    p = GaussianMlp([(np.ascontiguousarray(w.T), np.zeros(16, np.float32))], np.zeros(42),
                    np.ones(42))
    assert p.mean(np.zeros((2, 42), np.float32)).shape == (2, 16)


# -- item 4: overlap ------------------------------------------------------------------------

def test_overlapping_buffers_are_refused(vec, policy):
    buf = vec.rollout_buffers(2)
    t, n, od = buf["obs"].shape
    ad = buf["actions"].shape[2]
    raw = bytearray(4 * t * n * max(od, ad))
    buf["obs"] = np.frombuffer(raw, np.float32, t * n * od).reshape(t, n, od)
    buf["actions"] = np.frombuffer(raw, np.float32, t * n * ad).reshape(t, n, ad)
    with pytest.raises(ValueError, match="rollout buffers obs and actions overlap in memory"):
        vec.rollout(policy, 0, buf)
    # One array given twice: numpy's borrow tracking or the overlap check, a ValueError.
    buf = vec.rollout_buffers(2)
    buf["truncated"] = buf["terminated"]
    with pytest.raises(ValueError, match="terminated and truncated overlap|shares memory"):
        vec.rollout(policy, 0, buf)


# -- item 5: obs_dim 0 ----------------------------------------------------------------------

def test_a_bias_only_policy_gives_its_bias_and_rolls_out_envs_without_observations():
    bias = np.array([0.1, -0.2, 0.3, 0.0, 0.05, -0.05, 0.2, 0.1], np.float32)
    p = GaussianMlp([(np.zeros((0, 8), np.float32), bias)], np.zeros(0), np.zeros(0))
    np.testing.assert_array_equal(p.mean(np.zeros((3, 0), np.float32)), np.tile(bias, (3, 1)))
    vec = MjskillVectorEnv("PickCube-v1", num_envs=3, num_threads=2, obs_mode="none", **KW)
    buf = vec.rollout_buffers(4)
    assert buf["obs"].shape == (4, 3, 0)
    vec.rollout(p, 0, buf)
    np.testing.assert_array_equal(buf["actions"][0], np.tile(bias, (3, 1)))
    vec.rollout(p, 4, buf)  # still usable
    vec.step(np.zeros((3, 8), np.float32))


# -- item 6: read-only and borrowed buffers -------------------------------------------------

def test_read_only_buffers_are_value_errors_not_panics(vec, policy):
    buf = vec.rollout_buffers(2)
    buf["rewards"].setflags(write=False)
    with pytest.raises(ValueError, match="rollout buffer rewards is read-only"):
        vec.rollout(policy, 0, buf)
    buf = vec.rollout_buffers(2)
    buf["obs"] = np.broadcast_to(np.float32(0), buf["obs"].shape)
    with pytest.raises(ValueError, match="obs must be C-contiguous|obs is read-only"):
        vec.rollout(policy, 0, buf)
    try:
        vec.rollout(policy, 0, buf)
    except Exception as e:  # noqa: BLE001 - the point: `except Exception` catches it
        assert isinstance(e, ValueError)


def test_wrong_dtypes_name_the_array_and_the_dtype(vec, policy):
    buf = vec.rollout_buffers(2)
    buf["obs"] = buf["obs"].astype(np.float64)
    with pytest.raises(TypeError, match="rollout buffer obs has dtype float64, expected float32"):
        vec.rollout(policy, 0, buf)
    with pytest.raises(TypeError, match="observations has dtype float64, expected float32"):
        policy.mean(np.zeros((2, 42)))
    with pytest.raises(TypeError, match=r"layers\[0\] weights has dtype float64"):
        GaussianMlp([(np.zeros((42, 2)), np.zeros(2, np.float32))], np.zeros(42), np.ones(42))


# -- minor: the noise's step range, close() -------------------------------------------------

def test_first_step_beyond_the_noise_key_is_refused(vec, policy):
    buf = vec.rollout_buffers(2)
    for first in (2**48, 2**64 - 1, 2**64, -1):
        with pytest.raises(ValueError, match=f"first_step {first} is out of range: 0..2814749"):
            vec.rollout(policy, first, buf)
    with pytest.raises(ValueError, match="leave the policy's step range"):
        vec.rollout(policy, 2**48 - 1, buf)
    vec.rollout(policy, 2**48 - 2, buf)


def test_close_frees_the_vector_env():
    v = MjskillVectorEnv("PickCube-v1", num_envs=2, **KW)
    od = v.single_observation_space.shape[0]
    p = GaussianMlp(**params(od, 8))
    buf = v.rollout_buffers(2)
    v.close()
    assert v.closed
    for call in (lambda: v.step(np.zeros((2, 8), np.float32)), lambda: v.reset(seed=0),
                 lambda: v.rollout(p, 0, buf), lambda: v.autoreset):
        with pytest.raises(RuntimeError, match="is closed"):
            call()
    v.close()  # a second close does nothing


# -- minor: unclear messages ----------------------------------------------------------------

def test_an_empty_env_idx_resets_no_env():
    import gymnasium as gym

    env = gym.make("mjskill/PickCube-v1", num_envs=2, array_backend="numpy").unwrapped
    obs, _ = env.reset(seed=1)
    again, _ = env.reset(options={"env_idx": []})
    np.testing.assert_array_equal(again, obs)
    with pytest.raises(TypeError, match="env_idx must hold env indices"):
        env.reset(options={"env_idx": [0.5]})


def test_max_episode_steps_minus_one_means_no_limit_everywhere():
    # Issue 42: -1 was refused by make_vec, became 50 in the batched env and meant no limit
    # in the single env. It is gymnasium's "no time limit" in all of them now.
    import gymnasium as gym

    import mjskill

    unlimited = mjskill._native.UNLIMITED_EPISODE_STEPS
    single = gym.make("mjskill/PickCube-v1", max_episode_steps=-1)
    direct = mjskill.MjskillEnv("PickCube-v1", max_episode_steps=-1)
    for env in (single, direct):
        env.reset(seed=0)
        zero = np.zeros(env.action_space.shape, np.float32)
        assert not any(env.step(zero)[3] for _ in range(60))
    vec = gym.make_vec("mjskill/PickCube-v1", num_envs=2, vectorization_mode="vector_entry_point",
                       max_episode_steps=-1)
    assert vec.max_episode_steps == unlimited
    for made in (gym.make("mjskill/PickCube-v1", num_envs=2, array_backend="numpy",
                          max_episode_steps=-1),
                 mjskill.MjskillBatchedEnv(num_envs=2, array_backend="numpy",
                                           max_episode_steps=-1)):
        b = made.unwrapped
        b.reset(seed=0)
        assert b.max_episode_steps == unlimited
    default = gym.make("mjskill/PickCube-v1", num_envs=2, array_backend="numpy").unwrapped
    default.reset(seed=0)
    assert default.max_episode_steps == 50


def test_rendering_envs_beyond_an_address_space_limit_are_a_value_error_naming_num_envs():
    # Issue 42, item 10: 30 rgb envs under prlimit --as=2000000000 crashed with SIGSEGV in
    # Mesa. The memory check honours RLIMIT_AS now and names num_envs and the limit.
    import shutil

    if shutil.which("prlimit") is None:
        pytest.skip("no prlimit")
    code = textwrap.dedent("""
        import mjskill
        try:
            mjskill.MjskillVectorEnv("PickCube-v1", num_envs=30, obs_mode="rgb")
        except ValueError as e:
            print("ValueError:", e)
    """)
    p = subprocess.run(["prlimit", "--as=2000000000", sys.executable, "-c", code],
                       capture_output=True, text=True, timeout=600)
    out = p.stdout + p.stderr
    if "headless rendering is unavailable" in out:
        pytest.skip("no headless rendering here")
    assert p.returncode == 0, out
    assert "ValueError: num_envs 30 would need" in out and "RLIMIT_AS" in out, out
