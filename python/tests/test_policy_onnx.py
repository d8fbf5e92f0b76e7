"""examples/policy_onnx.py's edits (issue 48): floors refuse NaN, inf and malformed values,
in-place edits are written beside the target and renamed (a failed write leaves the input
whole), non-regular files are refused unread, duplicated metadata keys are refused, and a
floored file can be floored again, and ensembles, snaps and eases compute what they say. Needs
numpy and onnx only, but for ease's command line, which reads the observation layout and the
action's scale from the mjskill package."""

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "examples" / "policy_onnx.py"
WIDOWXAI = REPO / "models" / "policies" / "PickCube-v1__widowxai.onnx"

onnx = pytest.importorskip("onnx")


def load_module():
    spec = importlib.util.spec_from_file_location("policy_onnx_under_test", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def small_policy(path, act_dim=8, obs_dim=5):
    """A small MLP policy file (random weights) at ``path``."""
    P = load_module()
    r = np.random.default_rng(0)
    layers = [(r.normal(size=(obs_dim, 4)), r.normal(size=4)),
              (r.normal(size=(4, act_dim)), r.normal(size=act_dim))]
    meta = dict(env_id="PickCube-v1", robot_uids="widowxai", control_mode="pd_joint_pos",
                obs_mode="state", training_command="test")
    P.write_mlp_policy(path, layers, np.zeros(obs_dim), np.ones(obs_dim), meta, obs_clip=10.0)
    return path


def cli(*args, timeout=60):
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True,
                          text=True, timeout=timeout)


def leftovers(d):
    return sorted(p.name for p in Path(d).iterdir() if ".tmp" in p.name)


@pytest.mark.parametrize("action, message", [
    ("7:nan", "finite number"),
    ("7:inf", "finite number"),
    ("7:-inf", "finite number"),
    ("7:1e39", "float32's range"),
    ("7:0.5:1", "expected INDEX:LEAST"),
    ("seven:0.5", "expected INDEX:LEAST"),
    ("-1:0.5", "is negative"),
])
def test_floor_refuses_non_finite_and_malformed_values(tmp_path, action, message):
    src = small_policy(tmp_path / "in.onnx")
    before = src.read_bytes()
    r = cli("floor", src, tmp_path / "out.onnx", f"--action={action}")
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert message in r.stderr and action in r.stderr, r.stderr
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "out.onnx").exists()
    assert src.read_bytes() == before


def test_floor_refuses_an_index_given_twice(tmp_path):
    src = small_policy(tmp_path / "in.onnx")
    r = cli("floor", src, tmp_path / "out.onnx", "--action", "7:0.5", "--action", "7:0.25")
    assert r.returncode == 2 and "given twice" in r.stderr, r.stderr
    P = load_module()
    with pytest.raises(ValueError, match="finite"):
        P.floor_actions(src, tmp_path / "out.onnx", {7: float("nan")}, "note")
    assert not (tmp_path / "out.onnx").exists()


def test_an_in_place_edit_that_fails_to_write_leaves_the_input_whole(tmp_path, monkeypatch):
    src = small_policy(tmp_path / "policy.onnx")
    before = src.read_bytes()
    P = load_module()
    real_save = onnx.save

    def full_disk(model, path, *a, **k):
        real_save(model, path, *a, **k)
        with open(path, "r+b") as f:  # what a full disk leaves: the start of the file
            f.truncate(100)
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(onnx, "save", full_disk)
    for edit in (lambda: P.floor_actions(src, src, {7: 0.5}, "n"),
                 lambda: P.retarget(src, src, "PickCubeWidowXAI-v1", "n"),
                 lambda: P.hide_obs(src, src, [1], "n")):
        with pytest.raises(OSError, match="No space"):
            edit()
        assert src.read_bytes() == before
        assert leftovers(tmp_path) == []
    monkeypatch.setattr(onnx, "save", real_save)
    P.floor_actions(src, src, {7: 0.5}, "n")
    assert src.read_bytes() != before and leftovers(tmp_path) == []


def test_a_fifo_is_refused_never_read(tmp_path):
    fifo = tmp_path / "policy.onnx"
    os.mkfifo(fifo)
    r = cli("retarget", fifo, tmp_path / "out.onnx", "--env-id", "PickCube-v1", timeout=30)
    assert r.returncode == 1 and "FIFO" in r.stderr and str(fifo) in r.stderr, r.stderr
    assert "Traceback" not in r.stderr


def test_duplicated_metadata_keys_are_refused_not_merged(tmp_path):
    src = small_policy(tmp_path / "in.onnx")
    m = onnx.load(str(src))
    m.metadata_props.add(key="control_mode", value="pd_joint_delta_pos")
    onnx.save(m, str(src))
    for args in (["retarget", src, tmp_path / "out.onnx", "--env-id", "PickCube-v1"],
                 ["floor", src, tmp_path / "out.onnx", "--action", "7:0.5"],
                 ["hide", src, tmp_path / "out.onnx", "--obs", "1"]):
        r = cli(*args)
        assert r.returncode == 1 and "'control_mode' more than once" in r.stderr, r.stderr
        assert not (tmp_path / "out.onnx").exists()


def test_a_floored_file_floors_again(tmp_path):
    # The shipped WidowX AI policy was trained with --action-floor 7:-0.545.
    out = tmp_path / "refloored.onnx"
    r = cli("floor", WIDOWXAI, out, "--action", "7:-0.5", "--action", "6:0.1")
    assert r.returncode == 0, r.stderr
    from onnx import numpy_helper

    m = onnx.load(str(out))
    assert [n.op_type for n in m.graph.node].count("Max") == 1
    lo = {t.name: numpy_helper.to_array(t) for t in m.graph.initializer}["action_floor"]
    assert lo[7] == np.float32(-0.5) and lo[6] == np.float32(0.1)
    assert lo[0] == np.finfo(np.float32).min
    meta = {p.key: p.value for p in m.metadata_props}
    assert "7 >= -0.5" in meta["derived"] and "--action-floor" in meta["derived"]
    ort = pytest.importorskip("onnxruntime")
    s = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    x = np.random.default_rng(0).normal(0, 100, (256, s.get_inputs()[0].shape[1]))
    a = s.run(None, {s.get_inputs()[0].name: x.astype(np.float32)})[0]
    assert a[:, 7].min() >= -0.5 and a[:, 6].min() >= np.float32(0.1)


def test_a_residual_adds_raw_observation_entries_to_chosen_actions(tmp_path):
    """examples/imitate.py --relative-labels: ``action[k] = mlp(obs)[k] + obs[residual[k]]``
    for the entries with an index, the others the MLP's alone; the graph matches numpy's
    reference, and floors still apply to its output."""
    ort = pytest.importorskip("onnxruntime")
    P = load_module()
    r = np.random.default_rng(1)
    layers = [(r.normal(size=(6, 4)), r.normal(size=4)), (r.normal(size=(4, 3)), r.normal(size=3))]
    mean, std = r.normal(size=6), r.uniform(0.5, 2.0, size=6)
    meta = dict(env_id="PickCube-v1", robot_uids="so100", control_mode="pd_joint_pos",
                obs_mode="state", training_command="test")
    x = r.normal(0, 3, size=(16, 6)).astype(np.float32)
    residual = [4, None, 0]
    path = tmp_path / "res.onnx"
    P.write_mlp_policy(path, layers, mean, std, meta, obs_clip=10.0, residual=residual)
    s = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    got = s.run(None, {"obs": x})[0]
    plain = P.mlp_forward(x, layers, mean, std, 10.0)
    np.testing.assert_allclose(got, P.mlp_forward(x, layers, mean, std, 10.0, residual),
                               atol=1e-5)
    np.testing.assert_allclose(got[:, 0] - plain[:, 0], x[:, 4], atol=1e-5)
    np.testing.assert_allclose(got[:, 1], plain[:, 1], atol=1e-5)
    P.floor_actions(path, path, {1: 0.25}, "test")
    s = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    assert s.run(None, {"obs": x})[0][:, 1].min() >= 0.25
    for bad, message in (([4, None], "2 entries for 3"), ([6, None, 0], "out of range 0..5")):
        with pytest.raises(ValueError, match=message):
            P.write_mlp_policy(tmp_path / "bad.onnx", layers, mean, std, meta, residual=bad)


# -- issue 57: the edit's file keeps its mode, a symlink OUT is refused, long names work -------

def test_an_in_place_edit_keeps_the_files_mode(tmp_path):
    import stat

    src = small_policy(tmp_path / "policy.onnx")
    os.chmod(src, 0o640)  # group-private
    r = cli("hide", src, src, "--obs", "1")
    assert r.returncode == 0, r.stderr
    assert stat.S_IMODE(os.stat(src).st_mode) == 0o640
    # A new OUT gets a new file's mode: 0666 less the umask.
    mask = os.umask(0o022)
    os.umask(mask)
    r = cli("retarget", src, tmp_path / "new.onnx", "--env-id", "PickCubeWidowXAI-v1")
    assert r.returncode == 0, r.stderr
    assert stat.S_IMODE(os.stat(tmp_path / "new.onnx").st_mode) == 0o666 & ~mask
    assert leftovers(tmp_path) == []


def test_a_symlink_out_is_refused_and_left_as_it_is(tmp_path):
    """OUT a link: refused, naming its target (renaming the new file over OUT would replace
    the link, not edit the file it points to); the link and its target stay as they were."""
    real = small_policy(tmp_path / "real.onnx")
    before = real.read_bytes()
    link = tmp_path / "link.onnx"
    link.symlink_to(real)
    for args in (["hide", link, link, "--obs", "1"], ["floor", real, link, "--action", "7:0.5"]):
        r = cli(*args)
        assert r.returncode == 1, (args, r.stderr)
        assert f"{link} is a symbolic link" in r.stderr and str(real) in r.stderr, r.stderr
        assert "Traceback" not in r.stderr
        assert link.is_symlink() and real.read_bytes() == before
        assert leftovers(tmp_path) == []


@pytest.mark.parametrize("length", [246, 255])
def test_out_names_up_to_the_file_systems_limit_are_written(tmp_path, length):
    src = small_policy(tmp_path / "in.onnx")
    out = tmp_path / ("p" * (length - len(".onnx")) + ".onnx")
    r = cli("retarget", src, out, "--env-id", "PickCubeWidowXAI-v1")
    assert r.returncode == 0, r.stderr
    meta = {p.key: p.value for p in onnx.load(str(out)).metadata_props}
    assert meta["env_id"] == "PickCubeWidowXAI-v1" and leftovers(tmp_path) == []


def test_an_ensemble_is_the_mean_of_its_members_clipped_actions(tmp_path):
    """examples/policy_onnx.py ensemble: one graph that gives the mean of the members' actions,
    each clipped to the action bounds first (as a runtime clips a single file's), with an
    unbounded entry left as it is; the metadata lists each member's command and hides only
    what no member reads; members for another env are refused, naming the value."""
    ort = pytest.importorskip("onnxruntime")
    P = load_module()
    meta = dict(env_id="PickCube-v1", robot_uids="so100", control_mode="pd_joint_pos",
                obs_mode="state")
    members, layers_of = [], []
    for k, hidden in ((0, "1,2"), (1, "2,3")):
        r = np.random.default_rng(10 + k)
        layers = [(r.normal(size=(6, 4)), r.normal(size=4)),
                  (r.normal(size=(4, 3)), 3 * r.normal(size=3))]
        path = tmp_path / f"m{k}.onnx"
        P.write_mlp_policy(path, layers, np.zeros(6), np.ones(6),
                           dict(meta, training_command=f"python examples/imitate.py m{k}",
                                hidden_obs=hidden), obs_clip=10.0)
        members.append(path)
        layers_of.append(layers)
    low = np.array([-1.0, -np.inf, -0.5], np.float32)
    high = np.array([1.0, np.inf, 0.5], np.float32)
    out = tmp_path / "ens.onnx"
    P.ensemble(members, out, "test", low, high)
    x = np.random.default_rng(2).normal(0, 3, size=(64, 6)).astype(np.float32)
    want = np.mean([np.clip(P.mlp_forward(x, layers, np.zeros(6), np.ones(6), 10.0), low, high)
                    for layers in layers_of], axis=0)
    s = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    np.testing.assert_allclose(s.run(None, {"obs": x})[0], want, atol=1e-5)
    props = {p.key: p.value for p in onnx.load(str(out)).metadata_props}
    import json
    listed = [m["training_command"] for m in json.loads(props["ensemble_members"])]
    assert listed == ["python examples/imitate.py m0", "python examples/imitate.py m1"]
    assert props["hidden_obs"] == "2" and "test" in props["derived"]
    other = tmp_path / "other.onnx"
    P.write_mlp_policy(other, layers_of[0], np.zeros(6), np.ones(6),
                       dict(meta, env_id="PokeCube-v1", training_command="t"), obs_clip=10.0)
    with pytest.raises(ValueError, match="'PokeCube-v1'"):
        P.ensemble([members[0], other], tmp_path / "bad.onnx", "test")
    with pytest.raises(ValueError, match="at least two"):
        P.ensemble([members[0]], tmp_path / "bad.onnx", "test")


def test_a_snapped_component_takes_its_bounds_at_the_threshold(tmp_path):
    """examples/policy_onnx.py snap: the snapped component is its upper bound where the graph's
    output reaches the threshold and its lower bound below it, in onnxruntime as in the
    reference; the others pass unchanged; the metadata records the snap; a file snapped
    before, an unbounded or out-of-range component and a bad threshold are refused, naming
    the value."""
    import json

    ort = pytest.importorskip("onnxruntime")
    P = load_module()
    src = small_policy(tmp_path / "p.onnx", act_dim=3, obs_dim=5)
    low = np.array([-np.inf, -1.0, -0.5], np.float32)
    high = np.array([np.inf, 1.0, 0.25], np.float32)
    out = tmp_path / "snap.onnx"
    P.snap_actions(src, out, {1: -0.5, 2: 0.1}, "test", low, high)
    x = np.random.default_rng(3).normal(0, 2, size=(256, 5)).astype(np.float32)
    raw = ort.InferenceSession(str(src), providers=["CPUExecutionProvider"]).run(None, {"obs": x})[0]
    got = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"]).run(None, {"obs": x})[0]
    np.testing.assert_array_equal(got[:, 0], raw[:, 0])
    np.testing.assert_array_equal(got[:, 1], np.where(raw[:, 1] < -0.5, -1.0, 1.0))
    np.testing.assert_array_equal(got[:, 2], np.where(raw[:, 2] < 0.1, -0.5, 0.25))
    # The random observations fall on both sides of both thresholds.
    assert 0 < (raw[:, 1] < -0.5).sum() < len(x) and 0 < (raw[:, 2] < 0.1).sum() < len(x)
    props = {p.key: p.value for p in onnx.load(str(out)).metadata_props}
    assert json.loads(props["action_snap"]) == {
        "1": {"threshold": -0.5, "low": -1.0, "high": 1.0},
        "2": {"threshold": np.float32(0.1).item(), "low": -0.5, "high": 0.25}}
    assert props["derived"].endswith("test")
    with pytest.raises(ValueError, match="snapped already"):
        P.snap_actions(out, tmp_path / "again.onnx", {1: 0.0}, "t", low, high)
    with pytest.raises(ValueError, match="component 0 is unbounded"):
        P.snap_actions(src, tmp_path / "bad.onnx", {0: 0.0}, "t", low, high)
    with pytest.raises(ValueError, match="action index 3 out of range"):
        P.snap_actions(src, tmp_path / "bad.onnx", {3: 0.0}, "t", low, high)
    with pytest.raises(ValueError, match="threshold must be a finite number"):
        P.snap_actions(src, tmp_path / "bad.onnx", {1: float("nan")}, "t", low, high)
    assert not (tmp_path / "bad.onnx").exists() and not (tmp_path / "again.onnx").exists()
    r = cli("snap", src, tmp_path / "cli.onnx", "--action", "1:x")
    assert r.returncode != 0 and "expected INDEX:THRESHOLD, e.g. 7:-0.75" in r.stderr
    r = cli("snap", src, tmp_path / "cli.onnx", "--action", "1:0", "--action", "1:0.5")
    assert r.returncode != 0 and "give each component one threshold" in r.stderr


def test_an_eased_component_keeps_its_target_within_the_bound_near_the_goal(tmp_path):
    """examples/policy_onnx.py ease: where the observed vector is shorter than the radius, the
    eased component moves just far enough that ``obs[target] + scale · action`` stays within
    the bound (raised for a least bound, lowered for a most bound, the other way round for a
    negative scale), in onnxruntime as in the reference; elsewhere, and for the other
    components, the graph's action passes unchanged; the metadata records the bound; a file
    eased before and out-of-range entries are refused."""
    import json

    ort = pytest.importorskip("onnxruntime")
    P = load_module()
    src = small_policy(tmp_path / "p.onnx", act_dim=3, obs_dim=6)
    x = np.random.default_rng(4).normal(0, 1, size=(2048, 6)).astype(np.float32)
    d2 = (x[:, 3:5].astype(np.float64) ** 2).sum(axis=1)
    x = x[np.abs(d2 - 1.0) > 1e-3]  # off the radius, where float32 sums could tip either way
    close = (x[:, 3:5].astype(np.float64) ** 2).sum(axis=1) < 1.0
    raw = ort.InferenceSession(str(src), providers=["CPUExecutionProvider"]).run(None, {"obs": x})[0]
    for k, (scale, bound, most) in enumerate([(0.5, 0.2, False), (0.5, -0.3, True),
                                              (-0.25, 0.1, False)]):
        out = tmp_path / f"eased{k}.onnx"
        P.ease_actions(src, out, "test", 1, 0, scale, bound, (3, 5), 1.0, most, ("t:0", "v"))
        got = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"]).run(
            None, {"obs": x})[0]
        limit = (bound - x[:, 0].astype(np.float64)) / scale
        bounded = (np.maximum if (scale > 0) != most else np.minimum)(raw[:, 1], limit)
        np.testing.assert_allclose(got[:, 1], np.where(close, bounded, raw[:, 1]),
                                   rtol=1e-5, atol=1e-5)
        np.testing.assert_array_equal(got[:, [0, 2]], raw[:, [0, 2]])
        target = x[close, 0] + scale * got[close, 1].astype(np.float64)
        assert (target <= bound + 1e-5).all() if most else (target >= bound - 1e-5).all()
        # Near the goal some actions were moved and some already lay within the bound.
        moved = close & (np.abs(got[:, 1] - raw[:, 1]) > 1e-6)
        assert 0 < moved.sum() < close.sum(), (moved.sum(), close.sum())
        props = {p.key: p.value for p in onnx.load(str(out)).metadata_props}
        rec = json.loads(props["action_ease"])
        assert rec == {"action": 1, "target": 0, "scale": scale,
                       ("most" if most else "least"): np.float32(bound).item(),
                       "near": [3, 5], "radius": 1.0, "target_name": "t:0", "near_name": "v"}
        assert props["derived"].endswith("test")
    with pytest.raises(ValueError, match="eased already"):
        P.ease_actions(out, tmp_path / "again.onnx", "t", 1, 0, 0.5, 0.2, (3, 5), 1.0)
    with pytest.raises(ValueError, match="action index 3 out of range"):
        P.ease_actions(src, tmp_path / "bad.onnx", "t", 3, 0, 0.5, 0.2, (3, 5), 1.0)
    with pytest.raises(ValueError, match="must lie in 0..5"):
        P.ease_actions(src, tmp_path / "bad.onnx", "t", 1, 6, 0.5, 0.2, (3, 5), 1.0)
    with pytest.raises(ValueError, match="radius must be positive"):
        P.ease_actions(src, tmp_path / "bad.onnx", "t", 1, 0, 0.5, 0.2, (3, 5), 0.0)
    with pytest.raises(ValueError, match="the bound must be a finite float32"):
        P.ease_actions(src, tmp_path / "bad.onnx", "t", 1, 0, 0.5, float("nan"), (3, 5), 1.0)
    assert not (tmp_path / "bad.onnx").exists() and not (tmp_path / "again.onnx").exists()


def test_ease_reads_the_target_and_its_scale_from_the_files_env(tmp_path):
    """The command line names the target and the vector by the state observation's parts,
    which it resolves in the mjskill env the file names, and measures how far one unit of the
    action moves the target there (the SO100's jaw in ``pd_joint_target_delta_pos``: 0.2 rad);
    a part the observation lacks is refused naming the valid ones, and an action that does not
    move the target is refused."""
    import json

    src = REPO / "tests" / "data" / "policies" / "PickCubeSO100-v1__so100.onnx"
    out = tmp_path / "eased.onnx"
    args = ["--least", "-0.77", "--near", "extra/obj_to_goal_pos:0.01"]
    r = cli("ease", src, out, "--action", "5", "--target", "agent/controller/target_qpos:5",
            *args)
    assert r.returncode == 0, r.stderr
    rec = json.loads({p.key: p.value for p in onnx.load(str(out)).metadata_props}["action_ease"])
    assert rec["target"] == 17 and rec["near"] == [39, 42] and rec["action"] == 5
    assert abs(rec["scale"] - 0.2) < 1e-6 and rec["least"] == np.float32(-0.77).item()
    r = cli("ease", src, tmp_path / "bad.onnx", "--action", "5", "--target",
            "agent/target:5", *args)
    assert r.returncode != 0 and "no part 'agent/target'" in r.stderr
    assert "agent/controller/target_qpos" in r.stderr
    r = cli("ease", src, tmp_path / "bad.onnx", "--action", "0", "--target",
            "agent/controller/target_qpos:5", *args)
    assert r.returncode != 0 and "does not move observation entry 17" in r.stderr
    assert not (tmp_path / "bad.onnx").exists()
