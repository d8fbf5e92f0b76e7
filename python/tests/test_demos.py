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
    ("damaged", "damaged or unreadable MCAP"),
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
