"""examples/ppo.py --demos: recordings and ManiSkill trajectory files read back as the
episodes they hold, and every bad file refused with a clear error before an env is built; with
torch, a run from demos trains in the demos' control mode and continues with --resume."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import REPO, mjskill_bin, need

PPO = REPO / "examples" / "ppo.py"
sys.path.insert(0, str(REPO / "examples"))
import demos as demos_mod  # noqa: E402

SMALL = ["--num-envs", "6", "--num-steps", "8", "--num-minibatches", "2", "--num-eval-envs",
         "2", "--eval-freq", "2", "--num-threads", "1", "--torch-threads", "1", "--hidden",
         "16", "16", "--bc-epochs", "2", "--critic-warmup-steps", "48"]


def rollout(out, *args):
    r = subprocess.run([mjskill_bin(), "rollout", "--out", str(out), "--no-frame", *args],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def demo_files(tmp_path_factory):
    need("mcap")
    d = tmp_path_factory.mktemp("demos")
    rollout(d / "solver.mcap", "--env", "PickCube-v1", "--policy", "solver", "--episodes", "3")
    rollout(d / "zero.mcap", "--env", "PickCube-v1", "--policy", "zero", "--episodes", "2",
            "--control-mode", "pd_ee_delta_pos")
    # The Fetch solver's episodes converted to pd_joint_pos as it runs (solvers/convert.rs).
    s = rollout(d / "fetch.mcap", "--env", "PokeCube-v1", "--robot", "fetch", "--policy",
                "solver", "--control-mode", "pd_joint_pos", "--episodes", "2")
    assert s["control_mode"] == "pd_joint_pos" and s["successes"] == 2, s
    return d


def ppo(*args, timeout=300):
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    return subprocess.run([sys.executable, str(PPO), *args], capture_output=True, text=True,
                          timeout=timeout, env=env)


def test_a_recording_reads_back_as_its_episodes_up_to_their_first_success(demo_files):
    d = demos_mod.load([str(demo_files / "solver.mcap")], "PickCube-v1", None, None)
    assert (d.robot, d.control_mode, d.obs_dim) == ("panda", "pd_ee_delta_pos", 42)
    assert len(d.episodes) == 3 and d.skipped_failed == 0
    for e in d.episodes:
        # The solver succeeds around step 21 of 50: the cloned steps stop there, the value
        # targets cover the whole episode.
        assert 10 < e.n_until_success < 40 and len(e.actions) == 50
        assert e.obs.shape == (50, 42) and e.actions.shape == (50, 4)
    assert d.obs.shape == (d.steps, 42) and d.actions.shape == (d.steps, 4)
    ret = d.returns(0.8)
    assert ret.shape == (150,) and np.all(np.isfinite(ret)) and ret.max() <= 1 / 0.2 + 1e-4
    # Failed episodes are left out and counted.
    both = demos_mod.load([str(demo_files / "solver.mcap"), str(demo_files / "zero.mcap")],
                          "PickCube-v1", None, None)
    assert len(both.episodes) == 3 and both.skipped_failed == 2


def test_an_export_to_maniskill_h5_reads_back_the_same_steps(demo_files, tmp_path):
    need("h5py")
    h5 = tmp_path / "traj.h5"
    r = subprocess.run([mjskill_bin("datasets"), "export", str(demo_files / "solver.mcap"), "--format",
                        "maniskill", "-o", str(h5), "--json", str(tmp_path / "traj.json")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    a = demos_mod.load([str(demo_files / "solver.mcap")], "PickCube-v1", None, None)
    b = demos_mod.load([str(h5)], "PickCube-v1", None, None)
    assert (b.robot, b.control_mode) == ("panda", "pd_ee_delta_pos")
    np.testing.assert_allclose(b.obs, a.obs, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(b.actions, a.actions)


def bad_h5_without_json(tmp_path):
    h5py = need("h5py")
    p = tmp_path / "lonely.h5"
    with h5py.File(p, "w") as f:
        f["traj_0/actions"] = np.zeros((3, 4), np.float32)
    return p


@pytest.mark.parametrize("case, message", [
    ("other_env", "episodes of PickCube-v1, but this run trains PokeCube-v1"),
    ("other_robot", "episodes of robot panda, but this run trains fetch"),
    ("other_mode", "ppo.py does not convert actions"),
    ("empty", "the file is empty"),
    ("damaged", "a damaged MCAP file, refused whole"),
    ("garbage", "neither an MCAP recording nor an HDF5 file"),
    ("failed_only", "no successful episode (2 failed"),
    ("missing", "cannot read it"),
    ("directory", "not a regular file"),
    ("h5_without_json", "its json"),
    ("mixed_envs", "episodes of PokeCube-v1, but this run trains PickCube-v1"),
])
def test_bad_demo_files_are_refused_before_any_env_is_built(demo_files, tmp_path, case,
                                                            message):
    solver = str(demo_files / "solver.mcap")
    args = {"other_env": ["--env-id", "PokeCube-v1", "--demos", solver],
            "other_robot": ["--robot", "fetch", "--demos", solver],
            "other_mode": ["--control-mode", "pd_joint_delta_pos", "--demos", solver],
            "failed_only": ["--demos", str(demo_files / "zero.mcap")],
            "missing": ["--demos", str(tmp_path / "nope.mcap")],
            "directory": ["--demos", str(tmp_path)],
            "mixed_envs": ["--demos", solver, str(demo_files / "fetch.mcap")]}.get(case)
    if case == "empty":
        (tmp_path / "e.mcap").write_bytes(b"")
        args = ["--demos", str(tmp_path / "e.mcap")]
    elif case == "damaged":
        data = (demo_files / "solver.mcap").read_bytes()
        cut = tmp_path / "cut.mcap"
        # The magic and a header, then garbage where the chunks were.
        cut.write_bytes(data[:200] + bytes(range(256)) * 40)
        args = ["--demos", str(cut)]
    elif case == "garbage":
        (tmp_path / "g.mcap").write_bytes(b"not a recording at all")
        args = ["--demos", str(tmp_path / "g.mcap")]
    elif case == "h5_without_json":
        args = ["--demos", str(bad_h5_without_json(tmp_path))]
    if case == "mixed_envs":
        args = ["--env-id", "PickCube-v1", *args]
        message = "episodes of PokeCube-v1, but this run trains PickCube-v1"
    r = ppo(*SMALL, "--out", str(tmp_path / "run"), *args)
    assert r.returncode == 1, (r.returncode, r.stderr[-2000:])
    assert message in r.stderr, r.stderr[-2000:]
    assert "Traceback" not in r.stderr
    # Refused before anything was built or written.
    assert "obs " not in r.stdout and not (tmp_path / "run" / "log.csv").exists()


def test_demo_settings_that_cannot_train_are_refused():
    r = ppo("--demos", "x.mcap", "--bc-coef", "nan")
    assert r.returncode == 2 and "--bc-coef nan must be a finite number" in r.stderr, \
        r.stderr[-2000:]
    r = ppo("--demos", "x.mcap", "--simulator", "maniskill")
    assert r.returncode == 2 and "--demos trains on mjskill" in r.stderr, r.stderr[-2000:]


def test_a_run_from_demos_trains_in_their_mode_and_resumes(demo_files, tmp_path):
    torch = pytest.importorskip("torch")
    onnx = need("onnx")
    out = tmp_path / "run"
    r = ppo(*SMALL, "--demos", str(demo_files / "solver.mcap"), "--total-timesteps", "96",
            "--out", str(out))
    assert r.returncode == 0, r.stderr[-3000:]
    assert "demos: 3 successful episodes" in r.stdout and "warm start" in r.stdout
    meta = {p.key: p.value for p in onnx.load(str(out / "policy.onnx")).metadata_props}
    # No --control-mode: the demos' mode.
    assert meta["control_mode"] == "pd_ee_delta_pos" and meta["robot_uids"] == "panda"
    assert "3 episodes" in meta["demos"] and "--demos" in meta["training_command"]
    assert meta["demos_command"].startswith("mjskill rollout "), meta["demos_command"]
    ck = torch.load(out / "checkpoint.pt", weights_only=True)
    assert int(ck["global_step"]) == 96
    # --resume keeps the demos (from the saved options) and continues without a second warm
    # start.
    r = ppo("--resume", str(out), "--total-timesteps", "192")
    assert r.returncode == 0, r.stderr[-3000:]
    assert "demos: 3 successful episodes" in r.stdout and "warm start" not in r.stdout
    assert int(torch.load(out / "checkpoint.pt", weights_only=True)["global_step"]) == 192


def test_evaluations_of_one_actor_are_repeatable(demo_files, tmp_path):
    """During the critic's warm-up the actor does not change, and every evaluation of it gives
    the same figures: the eval envs are made afresh each time, so the end of one evaluation
    (the last finger contacts, which the next reset's first observation reports) does not
    reach the next."""
    pytest.importorskip("torch")
    out = tmp_path / "run"
    r = ppo("--env-id", "PickCube-v1", "--demos", str(demo_files / "solver.mcap"),
            "--num-envs", "16", "--num-steps", "50", "--num-minibatches", "4",
            "--num-eval-envs", "16", "--eval-freq", "1", "--num-threads", "1",
            "--torch-threads", "1", "--bc-epochs", "5", "--critic-warmup-steps", "100000",
            "--reward-mode", "normalized_dense", "--total-timesteps", "3200", "--out", str(out))
    assert r.returncode == 0, r.stderr[-3000:]
    import csv

    with open(out / "log.csv", newline="") as f:
        evals = [(row["eval_success"], row["eval_return"]) for row in csv.DictReader(f)
                 if row["eval_success"] != ""]
    assert len(evals) == 5 and len(set(evals)) == 1, evals


# -- issue 57: demo files read with mjskill's own checks, every value checked, memory bounded
# by what a file holds, and every file opened checked ------------------------------------------

def info(path):
    """`mjskill info PATH`: (exit status, its JSON summary or None)."""
    r = subprocess.run([mjskill_bin(), "info", str(path)], capture_output=True, text=True,
                       timeout=60)
    return r.returncode, (json.loads(r.stdout) if r.returncode == 0 else None)


def rewrite(src, dst, edit=None):
    """Writes the recording ``src`` again as ``dst`` with the `mcap` package's writer (every
    CRC written), each /episode, /step and /episode_end message passed through
    ``edit(topic, message)``, which returns the message (a dict, or bytes written as they
    are)."""
    from mcap.records import Channel, Header, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader
    from mcap.writer import Writer

    with open(src, "rb") as f, open(dst, "wb") as out:
        w = Writer(out, chunk_size=1, enable_data_crcs=True)
        schemas, channels = {}, {}
        for rec in StreamReader(f).records:
            if isinstance(rec, Header):
                w.start(rec.profile, rec.library)
            elif isinstance(rec, Schema) and rec.id not in schemas:
                schemas[rec.id] = w.register_schema(rec.name, rec.encoding, rec.data)
            elif isinstance(rec, Channel) and rec.id not in channels:
                channels[rec.id] = (w.register_channel(rec.topic, rec.message_encoding,
                                                       schemas.get(rec.schema_id, 0),
                                                       rec.metadata), rec.topic)
            elif isinstance(rec, Message):
                cid, topic = channels[rec.channel_id]
                data = rec.data
                if edit is not None and topic in ("/episode", "/step", "/episode_end"):
                    m = edit(topic, json.loads(data))
                    data = m if isinstance(m, bytes) else json.dumps(m).encode()
                w.add_message(cid, rec.log_time, data, rec.publish_time, rec.sequence)
            elif isinstance(rec, Metadata):
                w.add_metadata(rec.name, rec.metadata)
        w.finish()
    return dst


def edit_step(episode, step, **changes):
    """An ``edit`` for :func:`rewrite`: ``changes`` applied to one /step message."""
    def edit(topic, m):
        if topic == "/step" and (m["episode"], m["step"]) == (episode, step):
            for k, v in changes.items():
                if k == "obs_entry":
                    m["obs"][v[0]] = v[1]
                elif k == "action_entry":
                    m["action"][v[0]] = v[1]
                else:
                    m[k] = v
        return m
    return edit


def test_every_flipped_bit_of_a_recording_is_refused_as_mjskill_info_refuses_it(demo_files,
                                                                                tmp_path):
    """One flipped bit anywhere in a closed recording: mjskill's reader finds it (a chunk,
    data-section or summary CRC, or the structure), and so does demos.py: never different
    data, never lost episodes."""
    data = (demo_files / "solver.mcap").read_bytes()
    rng = np.random.default_rng(57)
    accepted = []
    for k in range(120):
        pos, bit = int(rng.integers(len(data))), int(rng.integers(8))
        flipped = bytearray(data)
        flipped[pos] ^= 1 << bit
        p = tmp_path / "flip.mcap"
        p.write_bytes(bytes(flipped))
        try:
            demos_mod.load([str(p)], "PickCube-v1", None, None, keep_failed=True)
        except demos_mod.DemoError as e:
            assert str(p) in str(e)
            continue
        accepted.append((pos, bit, info(p)[0]))
    assert not accepted, f"flips read as data (offset, bit, mjskill info's status): {accepted}"


def test_a_cut_recording_keeps_its_finished_episodes_as_mjskill_info_does(demo_files,
                                                                         tmp_path):
    whole = demos_mod.load([str(demo_files / "solver.mcap")], "PickCube-v1", None, None)
    data = (demo_files / "solver.mcap").read_bytes()
    seen = set()
    for cut in np.linspace(8, len(data) - 1, 40).astype(int):
        p = tmp_path / "cut.mcap"
        p.write_bytes(data[:cut])
        status, summary = info(p)
        try:
            d = demos_mod.load([str(p)], "PickCube-v1", None, None)
        except demos_mod.DemoError as e:
            # Refused only where mjskill reads no finished episode either.
            assert status != 0 or summary["episodes"] == 0, (cut, summary, str(e))
            assert "cut short" in str(e) or "no successful episode" in str(e), (cut, str(e))
            continue
        assert status == 0 and len(d.episodes) == summary["episodes"] > 0, (cut, summary)
        assert d.notes and "cut short" in d.notes[0], d.notes
        seen.add(len(d.episodes))
        for a, b in zip(d.episodes, whole.episodes):
            np.testing.assert_array_equal(a.obs, b.obs)
            np.testing.assert_array_equal(a.actions, b.actions)
    assert seen >= {1, 2}, seen  # cuts inside the second and third episodes keep the others


@pytest.mark.parametrize("case, message", [
    ("null_reward", "episode 1 (seed 1), step 4: reward = nan is not finite"),
    ("inf_obs", "episode 0 (seed 0), step 2: obs[5] = inf is not finite"),
    ("huge_obs", "episode 0 (seed 0), step 3: obs[28] = 1e+300 is beyond float32's range"),
    ("action_out_of_box", "episode 2 (seed 2), step 1: action[0] = 50.0 is outside the "
                          "action space (entry 0: -1 .. 1)"),
    ("null_action", "episode 0 (seed 0), step 0: action[3] = nan is not finite"),
    ("bad_json", "the /step message in chunk"),
    ("json_array", "does not decode as mjskill writes it: not a JSON object"),
    ("short_action", "action has 3 values, not 4"),
])
def test_bad_values_in_a_recording_are_refused_naming_episode_step_and_value(
        demo_files, tmp_path, case, message):
    edit = {
        "null_reward": edit_step(1, 4, reward=None),
        "inf_obs": edit_step(0, 1, obs_entry=(5, 1e400)),
        "huge_obs": edit_step(0, 2, obs_entry=(28, 1e300)),
        "action_out_of_box": edit_step(2, 1, action_entry=(0, 50.0)),
        "null_action": edit_step(0, 0, action_entry=(3, None)),
        "short_action": edit_step(0, 3, action=[0.0, 0.0, 0.0]),
    }.get(case)
    if case in ("bad_json", "json_array"):
        def edit(topic, m):
            if topic == "/step" and (m["episode"], m["step"]) == (1, 2):
                return b'{"episode": 1, "step": 2, "action": [0.0' if case == "bad_json" \
                    else b"[1, 2]"
            return m
    p = rewrite(demo_files / "solver.mcap", tmp_path / f"{case}.mcap", edit)
    if case == "bad_json":
        message = "is not valid JSON"
    # With --reward-mode normalized_dense the rewards become the critic's targets.
    r = ppo(*SMALL, "--reward-mode", "normalized_dense", "--total-timesteps", "48",
            "--out", str(tmp_path / "run"),
            "--demos", str(p))
    assert r.returncode == 1, (r.returncode, r.stderr[-2000:])
    assert message in r.stderr and str(p) in r.stderr, r.stderr[-2000:]
    assert "Traceback" not in r.stderr and "metadata" not in r.stderr
    assert "obs " not in r.stdout and not (tmp_path / "run" / "log.csv").exists()


def h5_demo(tmp_path, name="t", episodes=1, steps=5, obs_dim=42, act_dim=4, json_info=None,
            edit=None):
    """A ManiSkill trajectory file (h5 and json) of PickCube-v1 with the Panda in
    pd_ee_delta_pos, successful episodes with state observations; ``edit(h5 file)`` changes
    it before it is closed. Returns the h5 path."""
    h5py = need("h5py")
    p = tmp_path / f"{name}.h5"
    with h5py.File(p, "w") as f:
        for k in range(episodes):
            g = f.create_group(f"traj_{k}")
            g["actions"] = np.zeros((steps, act_dim), np.float32)
            g["obs"] = np.zeros((steps + 1, obs_dim), np.float32)
            g["rewards"] = np.full(steps, 0.5, np.float32)
            g["success"] = np.arange(steps) == steps - 1
        if edit is not None:
            edit(f)
    info = json_info or {
        "env_info": {"env_id": "PickCube-v1",
                     "env_kwargs": {"robot_uids": "panda", "obs_mode": "state",
                                    "control_mode": "pd_ee_delta_pos"}},
        "episodes": [{"episode_id": k, "episode_seed": 100 + k,
                      "control_mode": "pd_ee_delta_pos", "elapsed_steps": steps}
                     for k in range(episodes)]}
    (tmp_path / f"{name}.json").write_text(json.dumps(info))
    return p


def set_value(key, index, value):
    def edit(f):
        a = f[f"traj_0/{key}"][()].astype(np.float64)
        a[index] = value
        del f[f"traj_0/{key}"]
        f[f"traj_0/{key}"] = a
    return edit


@pytest.mark.parametrize("case, message", [
    ("nan_reward", "traj_0 (seed 100), step 2: reward = nan is not finite"),
    ("huge_obs", "traj_0 (seed 100), step 1: obs[7] = 1e+300 is beyond float32's range"),
    ("action_out_of_box", "traj_0 (seed 100), step 3: action[2] = 50.0 is outside the action "
                          "space (entry 2: -1 .. 1)"),
    ("short_rewards", "traj_0 has 4 rewards for 5 actions (one per action)"),
    ("action_size", "actions of 5 values, but PickCube-v1 with panda in pd_ee_delta_pos takes 4"),
    ("env_kwargs_null", "env_info.env_kwargs is null, not an object"),
    ("listed_twice", "both list episode_id 0; each episode is listed once"),
    ("given_twice", "given twice; give each file once"),
])
def test_bad_values_in_an_h5_are_refused_before_any_env_is_built(tmp_path, case, message):
    kw = {}
    if case == "nan_reward":
        kw["edit"] = set_value("rewards", 2, np.nan)
    elif case == "huge_obs":
        kw["edit"] = set_value("obs", (1, 7), 1e300)
    elif case == "action_out_of_box":
        kw["edit"] = set_value("actions", (3, 2), 50.0)
    elif case == "short_rewards":
        def short(f):
            del f["traj_0/rewards"]
            f["traj_0/rewards"] = np.zeros(4, np.float32)
        kw["edit"] = short
    elif case == "action_size":
        kw["act_dim"] = 5
    elif case in ("env_kwargs_null", "listed_twice"):
        info = {"env_info": {"env_id": "PickCube-v1", "env_kwargs": None},
                "episodes": [{"episode_id": 0, "episode_seed": 100,
                              "control_mode": "pd_ee_delta_pos"}]}
        if case == "listed_twice":
            info["env_info"]["env_kwargs"] = {"robot_uids": "panda", "obs_mode": "state",
                                              "control_mode": "pd_ee_delta_pos"}
            info["episodes"].append(dict(info["episodes"][0]))
        kw["json_info"] = info
    p = h5_demo(tmp_path, **kw)
    files = [str(p)] * (2 if case == "given_twice" else 1)
    r = ppo(*SMALL, "--reward-mode", "normalized_dense", "--total-timesteps", "48",
            "--out", str(tmp_path / "run"),
            "--demos", *files)
    assert r.returncode == 1, (r.returncode, r.stderr[-2000:])
    assert message in r.stderr and str(p) in r.stderr, r.stderr[-2000:]
    assert "Traceback" not in r.stderr
    assert "obs " not in r.stdout and not (tmp_path / "run" / "log.csv").exists()
    # The same file without the damage trains (the checks refuse only what is wrong).
    if case == "nan_reward":
        good = h5_demo(tmp_path, "good")
        d = demos_mod.load([str(good)], None, None, None, spaces=demos_mod.mjskill_spaces)
        assert len(d.episodes) == 1 and d.returns(0.8).max() > 0


#: Runs demos.load on argv[1:] in a process whose peak memory it prints.
PEAK = """
import resource, sys
sys.path.insert(0, sys.argv[1])
import demos
try:
    demos.load(sys.argv[2:], None, None, None)
    print("loaded")
except demos.DemoError as e:
    print("error:", e)
print("peak_mb", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024)
"""


def load_in_a_process(*paths, timeout=120, limit_gb=None):
    """demos.load on ``paths`` in a child process (address space limited to ``limit_gb`` if
    given): (its output, its peak memory in MB)."""
    def limit():
        import resource

        if limit_gb:
            resource.setrlimit(resource.RLIMIT_AS, (limit_gb << 30, limit_gb << 30))
    r = subprocess.run([sys.executable, "-c", PEAK, str(REPO / "examples"), *map(str, paths)],
                       capture_output=True, text=True, timeout=timeout, preexec_fn=limit)
    out = r.stdout + r.stderr
    peak = [int(line.split()[1]) for line in out.splitlines() if line.startswith("peak_mb")]
    return out, (peak[0] if peak else None)


def test_a_small_h5_declaring_millions_of_steps_is_refused_without_allocating_them(tmp_path):
    """5,000,000 steps declared in a few KB (compressed chunks never written: the fill
    value): refused from the declared size, before a byte of it is allocated."""
    def huge(f):
        del f["traj_0/actions"], f["traj_0/obs"], f["traj_0/rewards"], f["traj_0/success"]
        g = f["traj_0"]
        g.create_dataset("actions", (5_000_000, 4), np.float32, chunks=(65536, 4),
                         compression="gzip")
        g.create_dataset("obs", (5_000_001, 42), np.float32, chunks=(8192, 42),
                         compression="gzip")
        g.create_dataset("success", (5_000_000,), bool, chunks=(65536,), compression="gzip")
    p = h5_demo(tmp_path, edit=huge)
    assert p.stat().st_size < 64 << 10
    out, peak = load_in_a_process(p)
    assert "values read from this" in out and str(p) in out, out
    assert peak is not None and peak < 400, f"peak {peak} MB: {out}"


def test_the_json_beside_an_h5_is_checked_as_the_h5_is(tmp_path):
    """A FIFO there is refused, never waited on; a link to /dev/zero, never read; a json above
    the size read, refused."""
    p = h5_demo(tmp_path)
    j = tmp_path / "t.json"
    for kind, message in (("fifo", "is a FIFO, not a regular file"),
                          ("zero", "is a device, not a regular file"),
                          ("big", f"has {demos_mod.MAX_JSON_BYTES + 1} bytes, more than "
                                  f"the {demos_mod.MAX_JSON_BYTES} read")):
        j.unlink()
        if kind == "fifo":
            os.mkfifo(j)
        elif kind == "zero":
            j.symlink_to("/dev/zero")
        else:
            with open(j, "wb") as f:
                f.truncate(demos_mod.MAX_JSON_BYTES + 1)  # sparse: no disk used
        out, _ = load_in_a_process(p, timeout=60, limit_gb=4)
        assert f"its json: {j} {message}" in out, (kind, out)


def test_resume_finds_relative_demos_from_anywhere_and_refuses_replaced_ones(demo_files,
                                                                             tmp_path):
    """A run started with a relative --demos path resumes from another directory (the path is
    saved as an absolute one); a demo file replaced since the run started (other content
    under the same name) is refused, naming it."""
    pytest.importorskip("torch")
    work = tmp_path / "work"
    work.mkdir()
    (work / "demos.mcap").write_bytes((demo_files / "solver.mcap").read_bytes())
    out = tmp_path / "run"
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    r = subprocess.run([sys.executable, str(PPO), *SMALL, "--demos", "demos.mcap",
                        "--total-timesteps", "48", "--out", str(out)], cwd=work,
                       capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    r = ppo("--resume", str(out), "--total-timesteps", "96")  # from the tests' directory
    assert r.returncode == 0, r.stderr[-3000:]
    assert "demos: 3 successful episodes" in r.stdout and "warm start" not in r.stdout
    # Another recording under the same name: one action changed, still a valid file.
    rewrite(demo_files / "solver.mcap", work / "demos.mcap", edit_step(0, 0,
                                                                      action_entry=(0, 0.5)))
    demos_mod.load([str(work / "demos.mcap")], "PickCube-v1", None, None)
    r = ppo("--resume", str(out), "--total-timesteps", "144")
    assert r.returncode == 1, r.stderr[-3000:]
    assert "the demo files changed since the run started" in r.stderr, r.stderr[-3000:]
    assert str(work / "demos.mcap") in r.stderr and "Traceback" not in r.stderr
