"""Reliability: one env shared by threads never hangs; states, sizes, integers and actions
out of range are clear ValueErrors; MuJoCo's instability warnings reach ``info``."""

import subprocess
import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest

import mjskill
from mjskill import _native
from conftest import ENV

# Each pair runs two threads on one shared object. The script runs in a subprocess with a
# timeout, so a deadlock (the interpreter hangs and ignores Ctrl-C) fails the test instead of
# hanging CI.
THREADS_SCRIPT = textwrap.dedent(
    """
    import pickle, sys, threading
    import numpy as np
    import mjskill

    def pair(name, f, g, n=60):
        errors = []
        def run(h):
            try:
                for _ in range(n):
                    h()
            except BaseException as e:  # noqa: BLE001
                errors.append(repr(e))
        ts = [threading.Thread(target=run, args=(h,), daemon=True) for h in (f, g)]
        for t in ts:
            t.start()
        for t in ts:
            t.join(60)
            if t.is_alive():
                print(f"{name}: HUNG", flush=True)
                sys.exit(3)
        if errors:
            print(f"{name}: {errors[0]}", flush=True)
            sys.exit(4)
        print(f"{name}: ok", flush=True)

    a = np.zeros(8, np.float32)
    e = mjskill.MjskillEnv("PickCube-v1", render_mode="rgb_array", max_episode_steps=10**6)
    e.reset(seed=0)
    pair("step+step", lambda: e.step(a), lambda: e.step(a), n=200)
    assert e.elapsed_steps == 400, e.elapsed_steps
    pair("step+reset", lambda: e.step(a), lambda: e.reset(seed=1))
    s = e.get_state()
    pair("step+set_state", lambda: e.step(a), lambda: e.set_state(s))
    sd = e.get_state_dict()
    pair("step+set_state_dict", lambda: e.step(a), lambda: e.set_state_dict(sd))
    pair("step+render", lambda: e.step(a), e.render, n=30)
    pair("step+pickle", lambda: e.step(a), lambda: pickle.loads(pickle.dumps(e)), n=30)
    pair("step+get_info", lambda: e.step(a), e.get_info)
    r = mjskill.MjskillEnv("PickCube-v1", obs_mode="rgbd", max_episode_steps=10**6)
    r.reset(seed=0)
    pair("rgbd step+get_obs", lambda: r.step(a), r.get_obs, n=30)
    v = mjskill.MjskillVectorEnv("PickCube-v1", num_envs=2, num_threads=2)
    v.reset(seed=0)
    va = np.zeros((2, 8), np.float32)
    pair("vector step+step", lambda: v.step(va), lambda: v.step(va), n=100)
    pair("vector step+reset", lambda: v.step(va), lambda: v.reset(seed=3))
    pair("vector step+autoreset", lambda: v.step(va), lambda: v.autoreset)
    print("all ok", flush=True)
    """
)


def test_one_env_shared_by_threads_never_hangs():
    try:
        p = subprocess.run(
            [sys.executable, "-c", THREADS_SCRIPT],
            capture_output=True,
            text=True,
            timeout=120,
        )
    except subprocess.TimeoutExpired as t:
        pytest.fail(f"threads sharing one env hung; output so far:\n{t.stdout}")
    assert p.returncode == 0 and "all ok" in p.stdout, p.stdout + p.stderr


def _env(**kw):
    env = mjskill.MjskillEnv("PickCube-v1", **kw)
    env.reset(seed=0)
    return env


@pytest.mark.parametrize(
    "bits", [0x7FF8000000000000, 0x7FF0000000000000, int(np.float64(1e300).view(np.uint64))]
)
def test_a_non_finite_or_huge_cached_gaussian_is_rejected(bits):
    env = _env()
    env.step(np.zeros(8, np.float32))
    before = env.get_state()
    s = env.get_state()
    s["numpy"]["gauss_bits"] = bits
    with pytest.raises(ValueError, match=f"gauss_bits = {bits:#018x} .*must be finite with"):
        env.set_state(s)
    assert env.get_state() == before
    obs, info = env.reset()
    assert np.isfinite(obs).all() and not info["is_obj_placed"]
    # The largest value the polar method yields is accepted.
    s["numpy"]["gauss_bits"] = int(np.float64(-12.008).view(np.uint64))
    env.set_state(s)
    obs, _ = env.reset()
    assert np.isfinite(obs).all()


def test_set_state_dict_rejects_controller_targets_beyond_float32():
    env = _env(control_mode="pd_joint_target_delta_pos")
    before = env.get_state()
    sd = env.get_state_dict()
    sd["controller"]["arm"]["target_qpos"] = [1e39] * 7
    with pytest.raises(ValueError, match=r"controller\.arm\.target_qpos\[0\] = .* is out of range"):
        env.set_state_dict(sd)
    assert env.get_state() == before
    # set_state rejects the same value.
    s = env.get_state()
    s["controller"][0] = 1e39
    with pytest.raises(ValueError, match="is out of range"):
        env.set_state(s)


@pytest.mark.parametrize("n", [2**62, 10**6, 2**64])
def test_huge_num_envs_is_a_value_error(n):
    with pytest.raises(ValueError, match=f"num_envs {n} is out of range: 1..=16384"):
        gym.make_vec(ENV, num_envs=n, vectorization_mode="vector_entry_point")
    with pytest.raises(ValueError, match=f"num_envs {n} is out of range: 1..=16384"):
        _native.VecEnv("PickCube-v1", n)


@pytest.mark.parametrize(
    "kwargs,message",
    [
        ({"sim_freq": -1}, "sim_freq -1 is out of range: use a multiple of the control frequency"),
        ({"sim_freq": 2**40}, "sim_freq 1099511627776 is out of range"),
        ({"max_episode_steps": -2}, r"max_episode_steps -2 is out of range: .*1\.\.=4294967295"
                                    r"\), or -1 for no limit"),
        ({"max_episode_steps": 0}, r"max_episode_steps 0 is out of range"),
        ({"max_episode_steps": 2**32}, "max_episode_steps 4294967296 is out of range"),
    ],
)
def test_out_of_range_ints_are_value_errors_naming_argument_and_range(kwargs, message):
    with pytest.raises(ValueError, match=message):
        mjskill.MjskillEnv("PickCube-v1", **kwargs)
    with pytest.raises(ValueError, match=message):
        _native.VecEnv("PickCube-v1", 1, **kwargs)


def test_out_of_range_seeds_and_counts_are_value_errors():
    env = _env()
    for seed in (2**64, 2**64 - 1, 2**100):
        with pytest.raises(ValueError, match=f"seed {seed} is out of range: seeds are 32-bit, 0..=4294967295"):
            env.reset(seed=seed)
        with pytest.raises(ValueError, match=f"seed {seed} is out of range: seeds are 32-bit"):
            env._native.reset(seed)
    with pytest.raises(ValueError, match="seed -1 is out of range"):
        env._native.reset(-1)
    with pytest.raises(TypeError):
        env._native.reset(1.5)
    for name in ("num_envs", "num_threads"):
        kw = {"num_envs": 2, name: 2**64}
        with pytest.raises(ValueError, match=f"{name} {2**64} is out of range: 1..=16384"):
            mjskill.MjskillVectorEnv("PickCube-v1", **kw)
        with pytest.raises(ValueError, match=f"{name} {2**64} is out of range: 1..=16384"):
            _native.VecEnv("PickCube-v1", **kw)
    with pytest.raises(ValueError, match="seeds\\[1\\] 4294967296 is out of range"):
        _native.record_episodes("/nonexistent/x.mcap", "PickCube-v1", [0, 2**32], [])


def test_a_float64_action_beyond_float32_names_the_value_given():
    env = _env()
    a = np.zeros(8)
    a[3] = -1e39
    with pytest.raises(ValueError, match=r"action\[3\] = -1e\+39 is outside the float32 range"):
        env.step(a)
    assert env.elapsed_steps == 0
    v = mjskill.MjskillVectorEnv("PickCube-v1", num_envs=2)
    v.reset(seed=0)
    b = np.zeros((2, 8))
    b[1, 2] = 1e39
    with pytest.raises(ValueError, match=r"actions\[1, 2\] = 1e\+39 is outside the float32 range"):
        v.step(b)
    # The largest float32 itself is fine (the env clips it).
    a[3] = float(np.finfo(np.float32).max)
    env.step(a)


def test_mujoco_warnings_reach_python_info():
    env = _env()
    obs, r, te, tr, info = env.step(np.zeros(8, np.float32))
    assert "warnings" not in info
    sd = env.get_state_dict()
    art = sd["articulations"]["panda"]
    n = (len(art) - 13) // 2
    art[13 + n] = 1e9  # first joint's velocity: inside the ±1e10 bound, but MuJoCo resets
    env.set_state_dict(sd)
    obs, r, te, tr, info = env.step(np.zeros(8, np.float32))
    w = info["warnings"]
    assert w and set(w) <= {"BadQpos", "BadQvel", "BadQacc", "BadCtrl"}, w
    assert all(isinstance(c, int) and c > 0 for c in w.values()), w
    assert "warnings" not in env.reset(seed=0)[1], "a reset clears the warnings"


def test_mujoco_warnings_reach_python_vector_info():
    # Absolute joint targets 100× beyond the action space at one 0.05 s substep diverge.
    v = mjskill.MjskillVectorEnv(
        "PickCube-v1", num_envs=2, control_mode="pd_joint_pos", sim_freq=20, max_episode_steps=1000
    )
    v.reset(seed=0)
    rng = np.random.default_rng(0)
    lo, hi = v.single_action_space.low * 100, v.single_action_space.high * 100
    for _ in range(100):
        _, _, _, _, info = v.step(rng.uniform(lo, hi, size=(2, 8)).astype(np.float32))
        if "warnings" in info:
            break
    else:
        pytest.fail("no MuJoCo warning in 100 diverging steps")
    w, mask = info["warnings"], info["_warnings"]
    assert w.shape == (2,) and w.dtype == object and mask.dtype == bool and mask.any()
    for entry, has in zip(w, mask):
        assert (entry is not None) == has
        if has:
            assert entry and all(isinstance(c, int) and c > 0 for c in entry.values()), entry
    _, info = v.reset(seed=0)
    assert "warnings" not in info, "a reset clears the warnings"
