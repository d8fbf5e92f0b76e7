"""examples/ppo.py as a user meets it: settings that cannot train are refused before anything
runs, files are replaced whole, a stopped run continues with --resume, and SIGTERM saves."""

import csv
import importlib.util
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PPO = REPO / "examples" / "ppo.py"
#: A run small enough for a test: 6 envs x 8 steps = 48 steps an iteration.
SMALL = ["--env-id", "PickCube-v1", "--num-envs", "6", "--num-steps", "8",
         "--num-minibatches", "2", "--num-eval-envs", "2", "--eval-freq", "2",
         "--num-threads", "1", "--torch-threads", "1", "--hidden", "16", "16"]
BATCH = 48


def run(*args, timeout=300):
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    return subprocess.run([sys.executable, str(PPO), *args], capture_output=True, text=True,
                          timeout=timeout, env=env)


@pytest.mark.parametrize("args, message", [
    (["--num-minibatches", "100000"], "leaves minibatches of fewer than 2 samples"),
    (["--num-envs", "4", "--num-steps", "2", "--num-minibatches", "8"],
     "at most 4"),
    (["--num-steps", "0"], "0 is not a positive integer"),
    (["--num-minibatches", "0"], "0 is not a positive integer"),
    (["--hidden", "0"], "0 is not a positive integer"),
    (["--update-epochs", "-1"], "-1 is not a positive integer"),
    (["--total-timesteps", "10"], "less than one iteration"),
    (["--learning-rate", "nan"], "must be a finite number"),
    (["--out", "/dev/null"], "exists and is not a directory"),
    (["--ray-workers", "-2"], "-2 is negative"),
    (["--resume", "/nonexistent/run"], "no checkpoint.pt there"),
    (["--action-floor", "seven"], "expected INDEX:LEAST"),
    (["--action-floor", "7:-0.5", "--rollout", "native"], "works with torch rollouts"),
])
def test_ppo_refuses_settings_that_cannot_train(args, message):
    r = run(*args)
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    assert message in r.stderr, r.stderr[-2000:]
    assert "Traceback" not in r.stderr


def test_ppo_refuses_an_out_that_is_a_file(tmp_path):
    f = tmp_path / "file"
    f.write_text("keep me")
    r = run("--out", str(f))
    assert r.returncode == 2 and "exists and is not a directory" in r.stderr, r.stderr[-2000:]
    assert f.read_text() == "keep me"


def load_ppo_module():
    spec = importlib.util.spec_from_file_location("ppo_under_test", PPO)
    mod = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(PPO.parent))
    try:
        spec.loader.exec_module(mod)
    finally:
        sys.path.remove(str(PPO.parent))
    return mod


def test_atomic_write_leaves_the_old_file_when_the_write_fails(tmp_path):
    ppo = load_ppo_module()
    target = tmp_path / "policy.onnx"
    target.write_bytes(b"the good policy")

    def crash(tmp):
        with open(tmp, "wb") as f:
            f.write(b"half a poli")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        ppo.atomic_write(str(target), crash)
    assert target.read_bytes() == b"the good policy"
    assert [p.name for p in tmp_path.iterdir()] == ["policy.onnx"]
    ppo.atomic_write(str(target), lambda tmp: Path(tmp).write_bytes(b"new"))
    assert target.read_bytes() == b"new"
    assert [p.name for p in tmp_path.iterdir()] == ["policy.onnx"]


def log_rows(out):
    with open(out / "log.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_ppo_resume_continues_a_stopped_run(tmp_path):
    torch = pytest.importorskip("torch")
    out = tmp_path / "run"
    # --device cpu: the learner's device path, as on a GPU (examples/ppo.py --device).
    r = run(*SMALL, "--total-timesteps", str(2 * BATCH), "--out", str(out), "--device", "cpu")
    assert r.returncode == 0, r.stderr[-3000:]
    assert "learner on cpu" in r.stdout
    first = torch.load(out / "checkpoint.pt", weights_only=True)
    assert (first["iteration"], first["global_step"]) == (3, 2 * BATCH)
    steps_before = max(int(s["step"]) for s in first["optimizer"]["state"].values())
    # The policy files and checkpoints load without pickled code.
    for name in ("policy.pt", "best.pt"):
        torch.load(out / name, weights_only=True)
    assert not [p for p in out.iterdir() if ".tmp-" in p.name]

    # A run-defining option cannot change.
    r = run("--resume", str(out), "--num-envs", "7")
    assert r.returncode != 0 and "--num-envs cannot change" in r.stderr, r.stderr[-2000:]

    r = run("--resume", str(out), "--total-timesteps", str(4 * BATCH))
    assert r.returncode == 0, r.stderr[-3000:]
    assert "resumed at iteration 3" in r.stdout, r.stdout[-2000:]
    last = torch.load(out / "checkpoint.pt", weights_only=True)
    assert (last["iteration"], last["global_step"]) == (5, 4 * BATCH)
    assert last["resumes"] == [2 * BATCH]
    assert last["command"] == first["command"]
    steps_after = max(int(s["step"]) for s in last["optimizer"]["state"].values())
    assert steps_after > steps_before  # Adam's state went on, not restarted
    rows = log_rows(out)
    train = [int(r["iteration"]) for r in rows if r["eval_success"] == ""]
    assert train == [1, 2, 3, 4], train
    walls = [float(r["wall_time"]) for r in rows]
    assert walls == sorted(walls)  # the clock continues from the stopped run's
    assert not torch.equal(first["actor"]["1.weight"], last["actor"]["1.weight"])
    import onnx

    meta = {p.key: p.value for p in onnx.load(out / "policy.onnx").metadata_props}
    assert meta["resumed"] == str(2 * BATCH)
    assert "--resume" in meta["resume_commands"] and "--total-timesteps 192" in meta["resume_commands"]
    assert meta["env_steps"] == str(4 * BATCH)
    assert "--resume" not in meta["training_command"]


def test_sigterm_ends_the_run_with_its_final_evaluation_and_saves(tmp_path):
    torch = pytest.importorskip("torch")
    out = tmp_path / "run"
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    p = subprocess.Popen([sys.executable, str(PPO), *SMALL, "--total-timesteps",
                          str(10_000 * BATCH), "--out", str(out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    deadline = time.time() + 240
    while time.time() < deadline:
        line = p.stdout.readline()
        if line.startswith("it 2/"):
            break
    p.send_signal(signal.SIGTERM)
    stdout, stderr = p.communicate(timeout=120)
    assert p.returncode == 0, stderr[-3000:]
    assert "stopping after this iteration" in stdout
    assert "final eval success" in stdout
    ckpt = torch.load(out / "checkpoint.pt", weights_only=True)
    assert ckpt["global_step"] < 10_000 * BATCH
    assert log_rows(out)[-1]["eval_success"] != ""


def test_action_floor_bounds_the_trained_files_actions(tmp_path):
    pytest.importorskip("torch")
    ort = pytest.importorskip("onnxruntime")
    import numpy as np

    out = tmp_path / "run"
    r = run(*SMALL, "--total-timesteps", str(2 * BATCH), "--out", str(out),
            "--action-floor", "7:0.25")
    assert r.returncode == 0, r.stderr[-3000:]
    s = ort.InferenceSession(str(out / "policy.onnx"), providers=["CPUExecutionProvider"])
    x = np.random.default_rng(0).normal(0, 100, (256, s.get_inputs()[0].shape[1]))
    a = s.run(None, {s.get_inputs()[0].name: x.astype(np.float32)})[0]
    assert a[:, 7].min() >= 0.25
    assert a[:, 0].min() < 0.25  # the other components are not floored
