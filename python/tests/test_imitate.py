"""examples/imitate.py and noise-injected demonstrations: a recording of `mjskill rollout
--action-noise` reads back with the expert's labels beside the executed actions, a tiny cloning
run writes a policy file that `mjskill eval` runs, relative labels are folded back into the
file's absolute targets, and a stopped run continues with --resume. The torch tests skip
without torch, as test_ppo.py's do."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from conftest import need

REPO = Path(__file__).resolve().parents[2]
IMITATE = REPO / "examples" / "imitate.py"
sys.path.insert(0, str(REPO / "examples"))
import demos as demos_mod  # noqa: E402

#: Successes of the SO100's episodes under σ 0.04 (the fixture's so100_hard.mcap).
HARD = {}
#: A run small enough for a test.
SMALL = ["--hidden", "32", "32", "--batch-size", "64", "--num-eval-envs", "2", "--num-threads",
         "1", "--torch-threads", "1"]


def binary():
    """The `mjskill` command line of this checkout ($MJSKILL_BIN, else target/release)."""
    path = os.environ.get("MJSKILL_BIN", str(REPO / "target" / "release" / "mjskill"))
    assert Path(path).exists(), f"{path} missing: run `cargo build --release` first"
    return path


def rollout(out, *args):
    r = subprocess.run([binary(), "rollout", "--out", str(out), "--no-frame", *args],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def imitate(*args, timeout=300):
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    return subprocess.run([sys.executable, str(IMITATE), *args], capture_output=True,
                          text=True, timeout=timeout, env=env)


def log_rows(out):
    with open(out / "log.csv", newline="") as f:
        return list(csv.DictReader(f))


def metadata(path):
    onnx = need("onnx")
    return {p.key: p.value for p in onnx.load(str(path)).metadata_props}


@pytest.fixture(scope="module")
def demo_files(tmp_path_factory):
    need("mcap")
    d = tmp_path_factory.mktemp("noisy")
    s = rollout(d / "panda.mcap", "--env", "PickCube-v1", "--episodes", "3",
                "--action-noise", "arm=0.05,gripper=0")
    assert s["action_noise"] == [0.05, 0.05, 0.05, 0.0], s
    rollout(d / "plain.mcap", "--env", "PickCube-v1", "--episodes", "1")
    rollout(d / "xarm6.mcap", "--env", "PickCube-v1", "--robot", "xarm6_robotiq",
            "--episodes", "1")
    rollout(d / "so100.mcap", "--env", "PickCubeSO100-v1", "--episodes", "1",
            "--action-noise", "0.02")
    # Noise the SO100's solver does not always survive (it drops or misses the cube).
    s = rollout(d / "so100_hard.mcap", "--env", "PickCubeSO100-v1", "--episodes", "4",
                "--action-noise", "0.04")
    assert 0 < s["successes"] < 4, s
    HARD["successes"] = s["successes"]
    return d


def test_a_noisy_recording_reads_back_with_the_expert_labels(demo_files):
    d = demos_mod.load([str(demo_files / "panda.mcap")], None, None, None)
    assert (d.env_id, d.robot, d.control_mode) == ("PickCube-v1", "panda", "pd_ee_delta_pos")
    assert d.labelled == len(d.episodes) == 3
    for e in d.episodes:
        assert e.labels.shape == e.actions.shape == (50, 4)
        # The arm's entries were executed with noise (unless clipped at a bound), the
        # gripper's as labelled.
        moved = e.labels[:, :3] != e.actions[:, :3]
        assert np.all(moved | (np.abs(e.actions[:, :3]) == 1.0)) and moved.mean() > 0.8
        np.testing.assert_array_equal(e.labels[:, 3], e.actions[:, 3])
    assert d.all_labels.shape == d.all_obs.shape[:1] + (4,)
    assert not np.array_equal(d.labels, d.actions)
    # A recording without noise has no labels: its actions are the labels.
    plain = demos_mod.load([str(demo_files / "plain.mcap")], "PickCube-v1", None, None)
    assert plain.labelled == 0 and plain.episodes[0].labels is None
    np.testing.assert_array_equal(plain.labels, plain.actions)


def test_failed_episodes_are_kept_on_request(demo_files):
    path = str(demo_files / "so100_hard.mcap")
    ok = HARD["successes"]
    d = demos_mod.load([path], None, None, None)
    assert (len(d.episodes), d.skipped_failed, d.kept_failed) == (ok, 4 - ok, 0)
    d = demos_mod.load([path], None, None, None, keep_failed=True)
    assert (len(d.episodes), d.skipped_failed, d.kept_failed) == (4, 0, 4 - ok)
    assert d.all_labels.shape == (200, 6) and d.labelled == 4


def test_cloning_writes_a_policy_file_that_mjskill_eval_runs(demo_files, tmp_path):
    pytest.importorskip("torch")
    out = tmp_path / "run"
    r = imitate(*SMALL, "--demos", str(demo_files / "panda.mcap"), "--epochs", "3",
                "--eval-every", "2", "--out", str(out))
    assert r.returncode == 0, r.stderr[-3000:]
    assert "3 episodes (0 of them failed; 3 with expert labels)" in r.stdout, r.stdout[-2000:]
    rows = log_rows(out)
    assert [(x["epoch"], x["eval_success"] != "") for x in rows] == [
        ("1", False), ("2", False), ("2", True), ("3", False), ("3", True)], rows
    losses = [float(x["train_loss"]) for x in rows if x["train_loss"]]
    assert losses[-1] < losses[0], losses
    meta = metadata(out / "policy.onnx")
    assert (meta["env_id"], meta["robot_uids"], meta["control_mode"], meta["obs_mode"]) == (
        "PickCube-v1", "panda", "pd_ee_delta_pos", "state")
    assert "imitate.py" in meta["training_command"] and "--demos" in meta["training_command"]
    assert meta["algorithm"].startswith("behaviour cloning")
    assert meta["demos"].startswith("3 episodes (0 failed, 3 with expert labels), 150 steps")
    # The demos' own recording command (rollout keeps it, without --out, in the file).
    assert meta["demos_command"].startswith("mjskill rollout "), meta["demos_command"]
    assert "--action-noise arm=0.05,gripper=0" in meta["demos_command"]
    assert "--out" not in meta["demos_command"]
    assert (meta["expert_labels"], meta["env_steps"], meta["epochs"]) == ("150", "150", "3")
    assert meta["hidden_obs"] == "16,17"  # the Panda's finger velocities, as ppo.py hides them
    for name in ("policy.onnx", "best.onnx", "policy.pt", "best.pt", "checkpoint.pt"):
        assert (out / name).is_file(), name
    e = subprocess.run([binary(), "eval", "--policy", str(out / "policy.onnx"), "--episodes",
                        "2", "--seed", "10000"], capture_output=True, text=True, timeout=300)
    assert e.returncode == 0, e.stderr[-2000:]
    report = json.loads(e.stdout)
    assert (report["episodes"], report["control_mode"]) == (2, "pd_ee_delta_pos")


def test_relative_labels_are_folded_back_into_absolute_targets(demo_files, tmp_path):
    pytest.importorskip("torch")
    ort = need("onnxruntime")
    out = tmp_path / "run"
    so100 = str(demo_files / "so100.mcap")
    # One episode learned almost by heart: the file must give its absolute joint targets.
    r = imitate(*SMALL, "--demos", so100, "--relative-labels", "--epochs", "300",
                "--eval-every", "300", "--out", str(out))
    assert r.returncode == 0, r.stderr[-3000:]
    assert "relative labels on action entries [0, 1, 2, 3, 4, 5]" in r.stdout, r.stdout[-2000:]
    assert "relative" in metadata(out / "policy.onnx")["algorithm"]
    d = demos_mod.load([so100], None, None, None)
    obs, labels = d.all_obs, d.all_labels
    s = ort.InferenceSession(str(out / "policy.onnx"), providers=["CPUExecutionProvider"])
    got = s.run(None, {s.get_inputs()[0].name: obs})[0]
    err = np.abs(got - labels).mean()
    # A file that dropped the measured positions would miss by the targets' size (about a
    # radian); one that learned nothing would do no better than "stay where the joints are".
    stay = np.abs(labels - obs[:, :6]).mean()
    assert err < 0.1 * np.abs(labels).mean() and err < stay, (err, stay)
    e = subprocess.run([binary(), "eval", "--policy", str(out / "best.onnx"), "--episodes",
                        "1", "--seed", "10000"], capture_output=True, text=True, timeout=300)
    assert e.returncode == 0, e.stderr[-2000:]
    assert json.loads(e.stdout)["control_mode"] == "pd_joint_pos"


def test_absolute_gripper_keeps_the_gripper_labels_absolute(demo_files, tmp_path):
    """--absolute-gripper: the arm's labels relative, the jaw's as the expert gave them (a
    relative open-or-close label averages to "stay" where the expert lets go)."""
    pytest.importorskip("torch")
    out = tmp_path / "run"
    r = imitate(*SMALL, "--demos", str(demo_files / "so100.mcap"), "--relative-labels",
                "--absolute-gripper", "--epochs", "2", "--eval-every", "2", "--out", str(out))
    assert r.returncode == 0, r.stderr[-3000:]
    # The SO100's jaw is action entry 5.
    assert "relative labels on action entries [0, 1, 2, 3, 4]" in r.stdout, r.stdout[-2000:]
    assert "--absolute-gripper" in metadata(out / "policy.onnx")["training_command"]


def test_hidden_observation_entries_do_not_reach_the_policy(demo_files, tmp_path):
    """--hide-obs: the named entries are zeroed before the network (in the file too), and a
    hidden joint position's target is learned absolute, since the file cannot add back a
    position it does not read."""
    pytest.importorskip("torch")
    ort = need("onnxruntime")
    out = tmp_path / "run"
    # The SO100's shoulder pan: its position (entry 0) and velocity (entry 6).
    r = imitate(*SMALL, "--demos", str(demo_files / "so100.mcap"), "--relative-labels",
                "--hide-obs", "0", "6", "--epochs", "2", "--eval-every", "2", "--out", str(out))
    assert r.returncode == 0, r.stderr[-3000:]
    assert "relative labels on action entries [1, 2, 3, 4, 5]" in r.stdout, r.stdout[-2000:]
    # With the jaw's velocity (entry 11), which the policy never sees by default.
    assert metadata(out / "policy.onnx")["hidden_obs"] == "0,6,11"
    d = demos_mod.load([str(demo_files / "so100.mcap")], None, None, None)
    obs = d.all_obs[:20].copy()
    s = ort.InferenceSession(str(out / "policy.onnx"), providers=["CPUExecutionProvider"])
    name = s.get_inputs()[0].name
    before = s.run(None, {name: obs})[0]
    moved = obs.copy()
    moved[:, [0, 6]] += 0.3
    after = s.run(None, {name: moved})[0]
    np.testing.assert_array_equal(before, after)
    # A visible entry does reach it.
    moved[:, 1] += 0.3
    assert np.abs(s.run(None, {name: moved})[0] - before).max() > 1e-4


def test_a_hidden_entry_beyond_the_observation_is_refused(demo_files, tmp_path):
    pytest.importorskip("torch")  # the observation's size is measured on the env, after torch
    r = imitate(*SMALL, "--demos", str(demo_files / "so100.mcap"), "--hide-obs", "3", "999",
                "--out", str(tmp_path / "run"))
    assert r.returncode == 1, r.stderr[-2000:]
    assert "--hide-obs 999: PickCubeSO100-v1 with so100 in pd_joint_pos observes" in r.stderr, \
        r.stderr[-2000:]
    assert "Traceback" not in r.stderr


def test_relative_labels_in_a_mode_without_absolute_joint_targets_are_refused(demo_files,
                                                                               tmp_path):
    pytest.importorskip("torch")
    r = imitate(*SMALL, "--demos", str(demo_files / "panda.mcap"), "--relative-labels",
                "--out", str(tmp_path / "run"))
    assert r.returncode == 1, r.stderr[-2000:]
    assert "no action entry of panda in pd_ee_delta_pos is a joint's absolute" in r.stderr
    assert "Traceback" not in r.stderr


def test_a_stopped_cloning_run_continues_with_resume(demo_files, tmp_path):
    torch = pytest.importorskip("torch")
    out = tmp_path / "run"
    demos = str(demo_files / "panda.mcap")
    r = imitate(*SMALL, "--demos", demos, "--epochs", "2", "--eval-every", "1", "--out",
                str(out))
    assert r.returncode == 0, r.stderr[-3000:]
    first = torch.load(out / "checkpoint.pt", weights_only=True)
    assert int(first["epoch"]) == 3
    r = imitate("--resume", str(out), "--hidden", "8")
    assert r.returncode == 1 and "--hidden cannot change" in r.stderr, r.stderr[-2000:]
    r = imitate("--resume", str(out), "--epochs", "4")
    assert r.returncode == 0, r.stderr[-3000:]
    assert "resumed at epoch 3" in r.stdout, r.stdout[-2000:]
    last = torch.load(out / "checkpoint.pt", weights_only=True)
    assert (int(last["epoch"]), list(last["resumes"])) == (5, [2])
    assert last["command"] == first["command"]
    assert [int(x["epoch"]) for x in log_rows(out) if not x["eval_success"]] == [1, 2, 3, 4]
    assert not torch.equal(first["net"]["0.weight"], last["net"]["0.weight"])
    meta = metadata(out / "policy.onnx")
    assert meta["resumed"] == "2" and "--resume" in meta["resume_commands"]
    assert "--resume" not in meta["training_command"]


def test_dagger_rounds_label_the_policys_states_and_continue_with_resume(demo_files,
                                                                         tmp_path):
    torch = pytest.importorskip("torch")
    out = tmp_path / "run"
    demos = str(demo_files / "panda.mcap")
    dagger = ["--dagger-episodes", "2", "--dagger-epochs", "1", "--dagger-seed", "500"]
    r = imitate(*SMALL, "--demos", demos, "--epochs", "1", "--eval-every", "100",
                "--dagger-rounds", "1", *dagger, "--out", str(out))
    assert r.returncode == 0, r.stderr[-3000:]
    assert "DAgger round 1:" in r.stdout and "(seeds 500..)" in r.stdout, r.stdout[-2000:]
    first = torch.load(out / "checkpoint.pt", weights_only=True)
    states = len(first["dagger_obs"])
    # Two episodes of up to 50 steps, every visited state labelled by the expert.
    assert int(first["dagger_round"]) == 1 and 2 <= states <= 100
    assert first["dagger_labels"].shape == (states, 4)
    assert torch.all(first["dagger_labels"][:, 3].abs() == 1)  # the gripper: open or close
    meta = metadata(out / "policy.onnx")
    assert "then DAgger (1 rounds of 2 episodes" in meta["algorithm"], meta["algorithm"]
    demo_steps = 150
    assert int(meta["expert_labels"]) == demo_steps + states
    # The next round on resume, with the first round's data kept.
    r = imitate("--resume", str(out), "--dagger-rounds", "2")
    assert r.returncode == 0, r.stderr[-3000:]
    assert "DAgger round 2:" in r.stdout and "(seeds 502..)" in r.stdout, r.stdout[-2000:]
    last = torch.load(out / "checkpoint.pt", weights_only=True)
    assert int(last["dagger_round"]) == 2 and len(last["dagger_obs"]) > states
    assert torch.equal(last["dagger_obs"][:states], first["dagger_obs"])
    r = imitate("--resume", str(out), "--dagger-seed", "900")
    assert r.returncode == 1 and "--dagger-seed cannot change" in r.stderr, r.stderr[-2000:]


def test_a_dagger_round_runs_seeded_episodes_in_batches_as_single_envs_would():
    """collect_dagger on a vector env of 3 envs runs 5 episodes (two batches, the second
    short) as 3 single envs stepped alongside would: slot i runs seed 700 + i, then 703 + i,
    and between them steps on (resetting unseeded after its episode's end) until the batch's
    last live episode ends. A reset's first observation reports the last step's contacts, as
    in ManiSkill, so what a slot did before its second episode shows in that episode. The
    round records each live episode's states and the expert's labels, in seed order. With
    beta 1 the expert drives, so no policy is needed; the one given returns NaN, which the env
    would refuse had it been executed."""
    import imitate
    import mjskill  # noqa: F401 (registers the envs)

    gid, kw = "mjskill/PickCube-v1", dict(control_mode="pd_ee_delta_pos", obs_mode="state")
    slots = [gym.make(gid, **kw) for _ in range(3)]
    episodes = {}
    want_solved = 0
    for start in (0, 3):
        obs = [slot.reset(seed=700 + start + i)[0] for i, slot in enumerate(slots)]
        live = [start + i < 5 for i in range(3)]
        ended = [False] * 3
        for _ in range(50):
            for i, slot in enumerate(slots):
                if ended[i]:  # the vector env's next-step autoreset
                    obs[i], _ = slot.reset()
                    ended[i] = False
                    continue
                label = slot.unwrapped.expert_action()
                if live[i]:
                    episodes.setdefault(start + i, []).append((obs[i], label))
                obs[i], _, terminated, truncated, _ = slot.step(label)
                if terminated or truncated:
                    want_solved += live[i] and bool(terminated)
                    live[i], ended[i] = False, True
            if not any(live):
                break
    for slot in slots:
        slot.close()
    want = [pair for e in sorted(episodes) for pair in episodes[e]]

    def nan_policy(obs):
        return np.full((len(obs), 4), np.nan, np.float32)

    obs, labels, solved = imitate.collect_dagger(
        lambda: gym.make_vec(gid, num_envs=3, num_threads=2, **kw), nan_policy, 700, 5, 50,
        1.0, np.random.default_rng(0))
    assert obs.shape == (len(want), len(want[0][0])) and obs.dtype == np.float64
    assert np.array_equal(obs, np.array([o for o, _ in want], np.float64))
    assert np.array_equal(labels, np.array([label for _, label in want], np.float64))
    assert solved == want_solved >= 4


def test_dagger_needs_a_state_expert(demo_files, tmp_path):
    pytest.importorskip("torch")
    r = imitate("--demos", str(demo_files / "xarm6.mcap"), "--dagger-rounds", "1",
                "--out", str(tmp_path / "run"))
    assert r.returncode == 1, r.stderr[-2000:]
    assert ("--dagger-rounds 1: no state expert for PickCube-v1 with xarm6_robotiq"
            in r.stderr), r.stderr[-2000:]


def test_dagger_seeds_must_be_held_out_from_the_evaluation():
    r = imitate("--demos", "x.mcap", "--dagger-rounds", "2", "--dagger-seed", "10050",
                "--eval-seed", "10000")
    assert r.returncode == 2 and "overlap the evaluation's (10000..10099)" in r.stderr, \
        r.stderr[-2000:]


@pytest.mark.parametrize("args, message", [
    ([], "--demos is required"),
    (["--demos", "x.mcap", "--dagger-beta", "1.5"], "out of range: 0.0 .. 1.0 (a probability)"),
    (["--demos", "x.mcap", "--epochs", "0"], "0 is not a positive integer"),
    (["--demos", "x.mcap", "--learning-rate", "nan"], "must be a finite number"),
    (["--demos", "x.mcap", "--eval-seed", "-1"], "evaluation seeds must lie in"),
    (["--demos", "x.mcap", "--absolute-gripper"],
     "--absolute-gripper keeps the gripper's labels absolute under --relative-labels"),
])
def test_settings_that_cannot_train_are_refused(args, message):
    r = imitate(*args)
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    assert message in r.stderr, r.stderr[-2000:]


def test_an_evaluation_on_the_demos_seeds_is_refused(demo_files, tmp_path):
    r = imitate("--demos", str(demo_files / "panda.mcap"), "--eval-seed", "1",
                "--out", str(tmp_path / "run"))
    assert r.returncode == 1, r.stderr[-2000:]
    assert "evaluates on seeds the demos were recorded with (1, 2)" in r.stderr, r.stderr
    assert not (tmp_path / "run" / "log.csv").exists()


def test_an_empty_out_is_refused():
    """``--out ''`` is refused (it used to train into runs/...)."""
    r = imitate("--demos", "x.mcap", "--out", "")
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    assert "argument --out: '' is empty; give a directory" in r.stderr, r.stderr[-2000:]
