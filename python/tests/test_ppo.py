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
    (["--action-floor", "7:0.5", "--action-floor", "7:0.25"], "given twice"),
    (["--action-floor", "7:0.5:1"], "expected INDEX:LEAST"),
    (["--action-floor", "7:1e39"], "float32's range"),
    (["--action-floor", "7:nan"], "finite number"),
    # (--out /dev/null: a run that accepted the value would stop there, untrained.)
    (["--bc-obs-noise", "nan", "--out", "/dev/null"], "nan must be a finite number >= 0"),
    (["--bc-obs-noise", "-0.1", "--out", "/dev/null"], "-0.1 must be a finite number >= 0"),
    (["--bc-obs-noise", "inf", "--out", "/dev/null"], "inf must be a finite number >= 0"),
    (["--demo-logstd", "50", "--out", "/dev/null"], "50.0 is out of range: -7.0 .. 1.0"),
    (["--demo-logstd", "1e30", "--out", "/dev/null"], "is out of range: -7.0 .. 1.0"),
    (["--demo-logstd", "-100", "--out", "/dev/null"], "-100.0 is out of range: -7.0 .. 1.0"),
    (["--demo-logstd", "nan", "--out", "/dev/null"], "nan is out of range: -7.0 .. 1.0"),
    (["--out", "", "--total-timesteps", "10"], "argument --out: '' is empty; give a directory"),
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


def test_the_presets_give_the_measured_cpu_defaults_or_maniskills(monkeypatch):
    # torch's OpenMP threads sleep between parallel regions, unless the caller chose.
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    load_ppo_module()
    assert os.environ["OMP_WAIT_POLICY"] == "PASSIVE"
    monkeypatch.setenv("OMP_WAIT_POLICY", "ACTIVE")
    ppo = load_ppo_module()
    assert os.environ["OMP_WAIT_POLICY"] == "ACTIVE"
    cpu = ppo.parse_args(["--env-id", "PickCube-v1"], check=False)
    assert (cpu.preset, cpu.num_envs, cpu.num_steps, cpu.update_epochs, cpu.num_minibatches,
            cpu.eval_freq) == ("cpu", 128, 50, 4, 16, 10)
    ms = ppo.parse_args(["--env-id", "PickCube-v1", "--preset", "maniskill"], check=False)
    assert (ms.num_envs, ms.update_epochs, ms.num_minibatches, ms.eval_freq) == (1024, 8, 32, 25)
    # A task's own settings stay under either preset; an option given wins over both.
    poke = ppo.parse_args(["--env-id", "PokeCube-v1", "--num-envs", "64"], check=False)
    assert (poke.num_steps, poke.num_envs, poke.update_epochs, poke.num_eval_envs) == (20, 64, 8, 100)
    assert ppo.defaults("PokeCube-v1", "cpu")["control_mode"] == "pd_ee_delta_pose"
    # Native rollouts under the cpu preset; torch where native cannot run, and under
    # ManiSkill's preset.
    assert ppo.default_rollout(cpu) == "native"
    assert ppo.default_rollout(ms) == "torch"
    floor = ppo.parse_args(["--action-floor", "7:0.5"], check=False)
    assert ppo.default_rollout(floor) == "torch"
    assert ppo.default_rollout(ppo.parse_args(["--simulator", "maniskill"], check=False)) == "torch"
    r = run("--preset", "gpu")
    assert r.returncode == 2 and "invalid choice: 'gpu'" in r.stderr, r.stderr[-2000:]


def test_a_run_records_its_preset_and_an_older_run_resumes_with_maniskills(tmp_path):
    torch = pytest.importorskip("torch")
    out = tmp_path / "run"
    r = run(*SMALL, "--total-timesteps", str(BATCH), "--out", str(out))
    assert r.returncode == 0, r.stderr[-3000:]
    ckpt = torch.load(out / "checkpoint.pt", weights_only=True)
    assert ckpt["argv"][-4:] == ["--preset", "cpu", "--rollout", "native"], ckpt["argv"]
    assert "--preset cpu --rollout native" in ckpt["command"]
    # A checkpoint from before --preset existed: its run took ManiSkill's settings and torch
    # rollouts, and a resume keeps them (8 epochs, not the cpu preset's 4) and records them.
    ppo = load_ppo_module()
    ckpt["argv"] = ppo.without_option(ppo.without_option(ckpt["argv"], "--preset"), "--rollout")
    torch.save(ckpt, out / "checkpoint.pt")
    r = run("--resume", str(out), "--total-timesteps", str(2 * BATCH))
    assert r.returncode == 0, r.stderr[-3000:]
    assert "torch rollouts" in r.stdout, r.stdout[-2000:]
    last = torch.load(out / "checkpoint.pt", weights_only=True)
    assert last["argv"][-4:] == ["--preset", "maniskill", "--rollout", "torch"], last["argv"]
    r = run("--resume", str(out), "--preset", "cpu", "--total-timesteps", str(3 * BATCH))
    assert r.returncode != 0 and "--preset cannot change" in r.stderr, r.stderr[-2000:]


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
    assert not [p for p in out.iterdir() if ".tmp" in p.name]

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


# -- run directories (issue 48): one writer, logs that lose nothing, checkpoints checked -----

def hold_in_another_process(run_dir):
    """A process that holds ``run_dir``'s lock (ppo.hold_run_dir) until killed."""
    code = ("import sys, time; sys.path.insert(0, sys.argv[1]); import ppo; "
            "f = ppo.hold_run_dir(sys.argv[2]); print('held', flush=True); time.sleep(300)")
    p = subprocess.Popen([sys.executable, "-c", code, str(PPO.parent), str(run_dir)],
                         stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "held"
    return p


def test_a_second_ppo_on_one_run_directory_is_refused_naming_the_holder(tmp_path):
    run_dir = tmp_path / "run"
    holder = hold_in_another_process(run_dir)
    try:
        # A new run, and a resume (before its checkpoint is even read), both refused.
        (run_dir / "checkpoint.pt").write_bytes(b"the holder's checkpoint")
        for args in (["--out", str(run_dir)], ["--resume", str(run_dir)]):
            r = run(*SMALL, *args) if args[0] == "--out" else run(*args)
            assert r.returncode == 1, (args, r.stderr[-2000:])
            assert f"pid {holder.pid}" in r.stderr and "in use" in r.stderr, r.stderr[-2000:]
            assert "Traceback" not in r.stderr
        assert (run_dir / "checkpoint.pt").read_bytes() == b"the holder's checkpoint"
    finally:
        holder.kill()
        holder.wait()
    # Once the holder is gone, the directory is free again (the lock goes with the process).
    ppo = load_ppo_module()
    f = ppo.hold_run_dir(str(run_dir))
    f.close()


def test_the_run_lock_never_writes_through_a_symlink(tmp_path):
    ppo = load_ppo_module()
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    victim = tmp_path / "victim.csv"
    victim.write_text("precious")
    (run_dir / ppo.RUN_LOCK).symlink_to(victim)
    with pytest.raises(SystemExit, match="symbolic link"):
        ppo.hold_run_dir(str(run_dir))
    assert victim.read_text() == "precious"


def dead_pid():
    """The pid of a process that has exited."""
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_the_cleanup_removes_only_the_temporary_files_of_dead_writers(tmp_path, monkeypatch):
    """hold_run_dir removes the temporary files (training.files.atomic_write's own
    ``.mjskill-PID-XXXXXXXX.tmp``) that runs killed while saving left, and nothing else:
    a user's ``results.tmp-PID``, a name with an impossible pid, a link."""
    ppo = load_ppo_module()
    dead = dead_pid()
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    removed = [f".mjskill-{dead}-0123abcd.tmp", f".mjskill-{dead}-ffffffff.tmp"]
    kept = [f".mjskill-{os.getpid()}-0123abcd.tmp",  # a live writer's
            f".mjskill-{dead}-0123abcd.tmp.bak", f".mjskill-{dead}-0123ABCD.tmp",
            ".mjskill-99999999999-0123abcd.tmp", f"results.tmp-{dead}",
            f"checkpoint.pt.tmp-{dead}", "x.tmp-99999999999999999999", "notes.tmp-x"]
    for name in removed + kept:
        (run_dir / name).write_text("x")
    (run_dir / f".mjskill-{dead}-aaaaaaaa.tmp").symlink_to(run_dir / "notes.tmp-x")
    kept.append(f".mjskill-{dead}-aaaaaaaa.tmp")
    ppo.hold_run_dir(str(run_dir)).close()
    left = sorted(p.name for p in run_dir.iterdir())
    assert left == sorted([ppo.RUN_LOCK, *kept]), left
    # --out . : the working directory's files are as safe.
    work = tmp_path / "work"
    work.mkdir()
    (work / f"thesis.tex.tmp-{dead}").write_text("chapter 1")
    monkeypatch.chdir(work)
    ppo.hold_run_dir(".").close()
    assert (work / f"thesis.tex.tmp-{dead}").read_text() == "chapter 1"


def test_atomic_write_never_writes_through_a_link_planted_at_a_temporary_name(tmp_path):
    """Links planted under the names a writer of this pid could pick (the old
    ``<file>.tmp-PID`` and ``.<file>.tmp-PID`` among them): their targets stay as they were,
    and the file is written."""
    ppo = load_ppo_module()
    victim = tmp_path / "victim.pt"
    victim.write_bytes(b"a precious checkpoint")
    target = tmp_path / "policy.onnx"
    for name in (f"policy.onnx.tmp-{os.getpid()}", f".policy.onnx.tmp-{os.getpid()}"):
        (tmp_path / name).symlink_to(victim)
    ppo.atomic_write(str(target), lambda tmp: Path(tmp).write_bytes(b"new policy"))
    assert victim.read_bytes() == b"a precious checkpoint"
    assert target.read_bytes() == b"new policy" and not target.is_symlink()


def test_temporary_files_are_created_exclusively_skipping_a_planted_name(tmp_path, monkeypatch):
    """training.files.temp_beside creates its file with O_EXCL | O_NOFOLLOW: a link (or any
    file) already under the name it draws is never opened; it draws another name."""
    sys.path.insert(0, str(PPO.parent))
    from training import files

    victim = tmp_path / "victim"
    victim.write_text("keep")
    first = tmp_path / f".mjskill-{os.getpid()}-aaaaaaaa.tmp"
    first.symlink_to(victim)
    tags = iter(["aaaaaaaa", "bbbbbbbb"])
    monkeypatch.setattr(files, "_tag", lambda: next(tags))
    files.atomic_write(str(tmp_path / "out.csv"), lambda t: Path(t).write_text("rows"))
    assert victim.read_text() == "keep" and first.is_symlink()
    assert (tmp_path / "out.csv").read_text() == "rows"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([first.name, "out.csv",
                                                                 "victim"])


def test_a_fifo_as_the_run_lock_is_a_clear_error(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    os.mkfifo(run_dir / ".run.lock")
    code = ("import sys; sys.path.insert(0, sys.argv[1]); import ppo; "
            "ppo.hold_run_dir(sys.argv[2])")
    r = subprocess.run([sys.executable, "-c", code, str(PPO.parent), str(run_dir)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 1, r.stderr[-2000:]
    assert "is a FIFO, not a regular file" in r.stderr and "Traceback" not in r.stderr, \
        r.stderr[-2000:]


def test_resume_refuses_another_out(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "checkpoint.pt").write_bytes(b"x")
    r = run("--resume", str(run_dir), "--out", str(tmp_path / "other"))
    assert r.returncode == 2 and "continues in its own directory" in r.stderr, r.stderr[-2000:]
    assert not (tmp_path / "other").exists()


def write_log(path, rows, tail=""):
    import csv as _csv

    with open(path, "w", newline="") as f:
        w = _csv.writer(f)
        w.writerow(load_ppo_module().LOG_HEADER)
        w.writerows(rows)
        f.write(tail)


def row(it, steps, eval_s=""):
    return [it, steps, "1.0", "0.5", "0.4", "" if eval_s != "" else 0.5, "", eval_s, "",
            "0.1", "0.1", "0.2", "0.0"]


def test_resume_keeps_the_counted_rows_and_drops_later_and_torn_ones(tmp_path):
    ppo = load_ppo_module()
    log_path = tmp_path / "log.csv"
    # Eval after 0 steps, iterations 1-2, eval after 96 steps (the checkpoint: continue at
    # iteration 3), then an iteration the kill cut off, and a torn row.
    counted = [row(0, 0, 0.0), row(1, 48), row(2, 96), row(2, 96, 0.5)]
    write_log(log_path, counted + [row(3, 144)], tail="4,192,1.2")
    log, writer = ppo.start_log(str(log_path), (3, 96))
    ppo.append_row(log, writer, row(3, 144))
    log.close()
    rows = log_rows(tmp_path)
    assert [(r["iteration"], r["env_steps"]) for r in rows] == [
        ("0", "0"), ("1", "48"), ("2", "96"), ("2", "96"), ("3", "144")]
    assert not [p for p in tmp_path.iterdir() if ".tmp" in p.name]
    # Nothing to drop: the log is appended to, not rewritten.
    ino = os.stat(log_path).st_ino
    log, writer = ppo.start_log(str(log_path), (4, 144))
    log.close()
    assert os.stat(log_path).st_ino == ino and len(log_rows(tmp_path)) == 5


def test_a_failing_resume_write_leaves_the_log_whole(tmp_path, monkeypatch):
    ppo = load_ppo_module()
    log_path = tmp_path / "log.csv"
    write_log(log_path, [row(i, 48 * i) for i in range(1, 60)] + [row(60, 2880)])
    before = log_path.read_bytes()

    def full_disk(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(ppo.os, "fsync", full_disk)
    with pytest.raises(OSError, match="No space"):
        ppo.start_log(str(log_path), (60, 59 * 48))  # the last row must go: a rewrite
    assert log_path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["log.csv"]


def test_log_rows_are_on_disk_before_the_checkpoint_that_counts_them(tmp_path):
    # SIGKILL right after each new checkpoint: the log holds every row the checkpoint
    # counts, and --resume continues from it with none lost.
    torch = pytest.importorskip("torch")
    pytest.importorskip("mjskill")
    out = tmp_path / "run"
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    p = subprocess.Popen([sys.executable, str(PPO), *SMALL, "--eval-freq", "1",
                          "--total-timesteps", str(10_000 * BATCH), "--out", str(out)],
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
    ckpt = out / "checkpoint.pt"
    deadline = time.time() + 240
    seen = None
    while time.time() < deadline:
        try:
            ino = os.stat(ckpt).st_ino
        except FileNotFoundError:
            ino = None
        if ino is not None and seen is not None and ino != seen:
            break  # the second checkpoint was just renamed into place
        seen = seen or ino
        time.sleep(0.001)
    p.kill()
    p.wait()
    last = torch.load(ckpt, weights_only=True)
    evals = [r for r in log_rows(out) if r["eval_success"] != ""]
    assert int(evals[-1]["env_steps"]) >= last["global_step"], (evals, last["global_step"])
    r = run("--resume", str(out), "--total-timesteps", str(last["global_step"] + 2 * BATCH))
    assert r.returncode == 0, r.stderr[-3000:]
    rows = log_rows(out)
    steps = [int(x["env_steps"]) for x in rows if x["eval_success"] != ""]
    assert last["global_step"] in steps and steps == sorted(steps), steps
    walls = [float(x["wall_time"]) for x in rows]
    assert walls == sorted(walls)


def test_a_damaged_or_foreign_checkpoint_is_a_clear_error(tmp_path):
    torch = pytest.importorskip("torch")
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    for content in (b"", b"PK\x03\x04 cut short", None):
        if content is None:
            torch.save({"argv": []}, run_dir / "checkpoint.pt")
        else:
            (run_dir / "checkpoint.pt").write_bytes(content)
        r = run("--resume", str(run_dir))
        assert r.returncode == 1, r.stderr[-2000:]
        assert "is not a checkpoint of examples/ppo.py" in r.stderr, r.stderr[-2000:]
        assert "Traceback" not in r.stderr and "weights_only" not in r.stderr


def test_resume_refuses_a_checkpoint_of_another_run(tmp_path):
    torch = pytest.importorskip("torch")
    pytest.importorskip("mjskill")
    a, b = tmp_path / "panda", tmp_path / "so100"
    for out, robot in ((a, "panda"), (b, "so100")):
        r = run(*SMALL, "--robot", robot, "--control-mode", "pd_joint_delta_pos",
                "--total-timesteps", str(BATCH), "--out", str(out))
        assert r.returncode == 0, r.stderr[-3000:]
    (a / "checkpoint.pt").write_bytes((b / "checkpoint.pt").read_bytes())
    before = (a / "log.csv").read_bytes()
    r = run("--resume", str(a))
    assert r.returncode == 1 and "checkpoint.pt is not this run's" in r.stderr, r.stderr[-3000:]
    assert (a / "log.csv").read_bytes() == before
