"""One rule for policy files in Python and in the CLI (docs/limits.md#policy-files): the files
of tests/make_hostile_policy.py that ``mjskill eval --policy`` refuses are ``ValueError``s
naming the file in ``mjskill.policy.OnnxPolicy``, never a hang, an IndexError, a
UnicodeDecodeError or onnxruntime's own exceptions."""

import os
import subprocess
import sys
import threading
from pathlib import Path

import gymnasium as gym
import pytest

from conftest import ENV, need

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "tests" / "make_hostile_policy.py"


@pytest.fixture
def dims():
    env = gym.make(ENV, robot_uids="panda", control_mode="pd_ee_delta_pos")
    return env.observation_space.shape[0], env.action_space.shape[0]


def hostile(tmp_path, dims, kind, *extra):
    need("onnx")
    out = tmp_path / f"{kind}.onnx"
    subprocess.run(
        [sys.executable, str(SCRIPT), kind, "--obs-dim", str(dims[0]), "--act-dim",
         str(dims[1]), "--out", str(out), *extra],
        check=True,
    )
    return out


def refused(path, match):
    """OnnxPolicy(path) raises a ValueError naming the file and matching `match`, within
    60 s (a hang fails)."""
    from mjskill.policy import OnnxPolicy

    result = {}

    def run():
        try:
            OnnxPolicy(path)
            result["error"] = None
        except Exception as e:  # noqa: BLE001 - the type is what is checked
            result["error"] = e

    t = threading.Thread(target=run, daemon=True)
    t.start()
    t.join(60)
    assert not t.is_alive(), f"OnnxPolicy({path}) hangs"
    e = result["error"]
    assert isinstance(e, ValueError), repr(e)
    assert str(path) in str(e), str(e)
    assert match in str(e), str(e)


@pytest.mark.parametrize(
    "kind,extra,match",
    [
        ("dup-meta", ("--key", "control_mode"), '"control_mode" more than once'),
        ("dup-meta", ("--key", "env_id"), '"env_id" more than once'),
        ("int64-out", (), "f32"),
        ("bool-out", (), "f32"),
        ("rank3-out", (), "shape"),
        ("nan-mul-zero", (), "constant zero"),
        ("floor", ("--value", "nan", "--index", "2"), "holds NaN at index 2"),
        ("floor", ("--value", "inf"), "holds inf at index 0"),
        ("loop", ("--trip", str(10**15)), "Loop"),
        ("div-zero", (), "failed to run"),
        ("const-shape", ("--shape", "1000000000,1000000000"), "16777216 elements"),
        ("bad-utf8-meta", (), "not a valid ONNX model"),
    ],
)
def test_files_the_cli_refuses_are_value_errors(tmp_path, dims, kind, extra, match):
    need("onnxruntime")
    refused(hostile(tmp_path, dims, kind, *extra), match)


def test_non_regular_and_garbage_files_are_value_errors(tmp_path):
    need("onnxruntime")
    fifo = tmp_path / "fifo.onnx"
    os.mkfifo(fifo)
    refused(fifo, "a FIFO")
    zero = tmp_path / "zero.onnx"
    zero.symlink_to("/dev/zero")
    refused(zero, "a character device")
    garbage = tmp_path / "garbage.onnx"
    garbage.write_bytes(b"\x0a\x05\xff\xfe\xfd\xfc\xfb")
    refused(garbage, "not a valid ONNX model")


def test_a_valid_hostile_script_file_runs(tmp_path, dims):
    need("onnxruntime")
    from mjskill.policy import OnnxPolicy

    policy = OnnxPolicy(hostile(tmp_path, dims, "plain"))
    assert policy.control_mode == "pd_ee_delta_pos"
