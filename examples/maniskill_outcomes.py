"""Record ManiSkill 3's outcomes for fixed action sequences of every (env, robot) pair.

NEEDS A LOCAL MANISKILL 3 (and its motion planner, mplib). CI never runs this script; the
files it writes (tests/data/outcomes/*.json.gz) are what `tests/outcome.rs` and
`mjskill outcomes` replay in mjskill, without ManiSkill. docs/outcome-agreement.md has the
install and the exact commands.

Two sources of action sequences, both replayed open loop in ManiSkill (PhysX CPU, one
freshly made env per episode, `reset(seed=seed)` then the actions):

* solver: mjskill's scripted solver episodes, recorded with `mjskill rollout --policy solver`
  and exported with `mjskill export --format maniskill` (Fetch with
  `--control-mode pd_joint_pos`: ManiSkill cannot build Fetch's EE modes, so the exported
  actions are the joint targets mjskill's controller set; PushT-v1 and PegInsertionSide-v1
  too, whose solvers' absolute targets carry over where `pd_ee_delta_pose`'s deltas from the
  measured hand add up the two simulators' loaded-arm differences, docs/outcome-physics.md).
* motionplanning: ManiSkill's own motion-planning demos, made with
  `python -m mani_skill.examples.motionplanning.<panda|xarm6|so100>.run` (seeds 0..N-1,
  the SO100's from 9).

For every episode the file keeps the actions (float32, shortest round-trip decimals), every
boolean that the task's `evaluate()` returns after each step (as a string of 0/1, one
character per step), the final success and the final positions of the dynamic objects.

Usage (from the repository root; the Python must have ManiSkill, mplib and h5py, e.g. the
overlay venv of docs/outcome-agreement.md):

    cargo build --release --bin mjskill
    MS_ASSET_DIR=/tmp/ms_assets /tmp/msmp/bin/python examples/maniskill_outcomes.py \\
        --mjskill target/release/mjskill --work /tmp/outcomes_work --out tests/data/outcomes

Options: --episodes N (per pair, default 50), --solver-seed S (first solver seed, default 0;
demos use run.py's seeds, 0..N-1; the SO100's run.py starts at 9), --only solver|motionplanning,
--pairs ENV:ROBOT[,...], --reuse-env (one ManiSkill env per pair, reset per episode, as
replay_trajectory does; much faster), --reuse (keep demo h5 files already in --work).
Seeds 5000 and above are held out: do not record them.

`--trim FULL_DIR --keep N --out DIR` copies the first N episodes of every file (no ManiSkill
needed); the repository's tests/data/outcomes holds such copies of a 50-episode recording.

`--perturb SIGMA --files DIR` measures ManiSkill against itself (docs/outcome-physics.md): every
episode of every `pd_joint_pos` outcome file in DIR is replayed twice in freshly made envs, as
recorded and with N(0, SIGMA) rad added to the arm joints' targets of every step (seeded), and
one JSON line per file counts the episodes whose final success flips. It bounds the agreement
any simulator that is not PhysX bit for bit can reach on those action sequences.
"""

import argparse
import gzip
import json
import os
import subprocess
import sys
import time

import numpy as np

FORMAT = "mjskill-outcomes/1"
HELD_OUT_SEED = 5000

# (env id, robot, control mode the exported actions are in) of every scripted solver.
SOLVER_PAIRS = [
    ("PickCube-v1", "panda", None),
    ("PickCube-v1", "fetch", "pd_joint_pos"),
    ("PickCube-v1", "xarm6_robotiq", None),
    ("PickCube-v1", "so100", None),
    ("PickCube-v1", "widowxai", None),
    ("PickCubeSO100-v1", "so100", None),
    ("PickCubeWidowXAI-v1", "widowxai", None),
    ("PlaceSphere-v1", "panda", None),
    ("PlaceSphere-v1", "fetch", "pd_joint_pos"),
    ("PokeCube-v1", "panda", None),
    ("PokeCube-v1", "fetch", "pd_joint_pos"),
    ("PushCube-v1", "panda", None),
    ("PushCube-v1", "fetch", "pd_joint_pos"),
    ("PullCube-v1", "panda", None),
    ("PullCube-v1", "fetch", "pd_joint_pos"),
    ("StackCube-v1", "panda", None),
    ("StackCube-v1", "fetch", "pd_joint_pos"),
    ("StackCube-v1", "panda_wristcam", None),
    ("LiftPegUpright-v1", "panda", None),
    ("LiftPegUpright-v1", "fetch", "pd_joint_pos"),
    ("PegInsertionSide-v1", "panda_wristcam", "pd_joint_pos"),
    ("PushT-v1", "panda_stick", "pd_joint_pos"),
]

# (env id, robot, ManiSkill's motion-planning module) of every motion-planning solution
# ManiSkill ships for mjskill's pairs (none for PokeCube, Fetch or WidowX AI).
DEMO_PAIRS = [
    ("PickCube-v1", "panda", "panda"),
    ("PlaceSphere-v1", "panda", "panda"),
    ("PickCube-v1", "xarm6_robotiq", "xarm6"),
    ("PickCubeSO100-v1", "so100", "so100"),
    ("PushCube-v1", "panda", "panda"),
    ("PullCube-v1", "panda", "panda"),
    ("StackCube-v1", "panda", "panda"),
]

# Envs whose robot is fixed by the env id (passing robot_uids again is a TypeError).
FIXED_ROBOT = {"PickCubeSO100-v1", "PickCubeWidowXAI-v1"}

# Arm joints at the front of each robot's pd_joint_pos action (the rest is gripper), for --perturb.
ARM_JOINTS = {"panda": 7, "panda_wristcam": 7, "panda_stick": 7, "fetch": 7, "xarm6_robotiq": 6, "so100": 5, "widowxai": 6}


def f32_text(x):
    """The shortest decimal that reads back as the same float32 (checked)."""
    f = np.float32(x)
    s = str(f)
    if np.float32(float(s)) != f or not np.isfinite(f):
        s = repr(float(f))
        assert np.float32(float(s)) == f, (x, s)
    return s


def dumps_actions(actions):
    rows = ("[" + ",".join(f32_text(v) for v in row) + "]" for row in actions)
    return "[" + ",".join(rows) + "]"


def run(cmd, **kw):
    print("+", " ".join(cmd), file=sys.stderr, flush=True)
    return subprocess.run(cmd, check=True, **kw)


def read_h5(h5_path):
    """(json, [(seed, actions float32 (T, A), recorded final success)]) of a trajectory file."""
    import h5py

    with open(h5_path[: -len(".h5")] + ".json") as f:
        meta = json.load(f)
    out = []
    with h5py.File(h5_path, "r") as h5:
        for ep in meta["episodes"]:
            g = h5[f"traj_{ep['episode_id']}"]
            seed = ep.get("episode_seed", ep.get("reset_kwargs", {}).get("seed"))
            actions = np.asarray(g["actions"][()], dtype=np.float32)
            success = bool(g["success"][()][-1]) if "success" in g else ep.get("success")
            out.append((int(seed), actions, success))
    return meta, out


_ENVS = {}


def maniskill_env(env_id, robot, mode):
    """A fresh single ManiSkill env (PhysX CPU, state observations, dense reward)."""
    import gymnasium as gym
    import mani_skill.envs  # noqa: F401 (registers the envs)

    kw = dict(
        obs_mode="state",
        control_mode=mode,
        num_envs=1,
        sim_backend="physx_cpu",
        reward_mode="dense",
    )
    # PushT-v1's table scene whitens the table's render shapes, which need a renderer.
    if env_id != "PushT-v1":
        kw["render_backend"] = "none"
    if env_id not in FIXED_ROBOT:
        kw["robot_uids"] = robot
    return gym.make(env_id, **kw)


def replay(env_id, robot, mode, seed, actions, reuse=False, target_noise=None):
    """Replays `actions` open loop in a ManiSkill env: per-step boolean info flags, final
    success and the final positions of the dynamic actors. The env is made fresh for the
    episode, or with `reuse` made once per (env, robot, mode) and reset for every episode,
    as ManiSkill's replay_trajectory tool does (PhysX CPU keeps contact caches across
    resets, so the two can differ slightly). `target_noise` = (rng, sigma) adds N(0, sigma)
    to the arm joint targets the arm controller sets at every step (for end-effector modes,
    whose actions are not joint targets)."""
    import torch

    key = (env_id, robot, mode)
    if reuse and key in _ENVS:
        env = _ENVS[key]
    else:
        env = maniskill_env(env_id, robot, mode)
        if reuse:
            _ENVS[key] = env
    arm = getattr(env.unwrapped.agent.controller, "controllers", {}).get("arm")
    set_targets = arm.set_drive_targets if arm is not None else None
    if target_noise is not None:
        if arm is None:
            raise ValueError(f"{env_id} {robot} {mode}: no arm controller to perturb")
        noise_rng, sigma = target_noise

        def noisy(t):
            return set_targets(t + torch.as_tensor(noise_rng.normal(0.0, sigma, tuple(t.shape)),
                                                   dtype=t.dtype))

        arm.set_drive_targets = noisy
    try:
        env.reset(seed=seed)
        flags = {}
        info = {}
        for a in actions:
            _, _, _, _, info = env.step(torch.from_numpy(np.asarray(a, dtype=np.float32))[None])
            for k, v in info.items():
                if torch.is_tensor(v) and v.dtype == torch.bool:
                    flags.setdefault(k, []).append("1" if bool(v.reshape(-1)[0]) else "0")
        final = bool(info["success"].reshape(-1)[0]) if actions.shape[0] else False
        objects = {}
        u = env.unwrapped
        for name, actor in u.scene.actors.items():
            if getattr(actor, "px_body_type", None) == "dynamic":
                objects[name] = [float(f32_text(v)) for v in actor.pose.p.reshape(-1)[:3].tolist()]
        return {k: "".join(v) for k, v in flags.items()}, final, objects
    finally:
        if arm is not None:
            arm.set_drive_targets = set_targets
        if not reuse:
            env.close()


def versions():
    import importlib.metadata as md

    out = {"python": sys.version.split()[0]}
    for p in ["mani-skill-nightly", "mani-skill", "sapien", "torch", "numpy", "mplib", "gymnasium"]:
        try:
            out[p] = md.version(p)
        except md.PackageNotFoundError:
            pass
    return out


def write(out_dir, source, env_id, robot, mode, episodes, extra, reuse=False):
    os.makedirs(out_dir, exist_ok=True)
    name = f"{source}__{env_id}__{robot}.json.gz"
    keys = list(episodes[0]["flags"].keys()) if episodes else []
    head = {
        "format": FORMAT,
        "source": source,
        "env_id": env_id,
        "robot": robot,
        "control_mode": mode,
        "sim_backend": "physx_cpu",
        "replay": ("one env for all episodes (as replay_trajectory): reset(seed=seed), the actions"
                   if reuse else
                   "one freshly made env per episode: gym.make, reset(seed=seed), the actions"),
        "versions": versions(),
        "command": " ".join(["python"] + sys.argv),
        "flag_keys": keys,
        "n_episodes": len(episodes),
        "maniskill_successes": sum(e["final_success"] for e in episodes),
        **extra,
    }
    # Actions as shortest float32 decimals: hand-written JSON for the episodes.
    parts = []
    for e in episodes:
        fields = [f'"{k}":{json.dumps(v)}' for k, v in e.items() if k != "actions"]
        fields.append('"actions":' + dumps_actions(e["actions"]))
        parts.append("{" + ",".join(fields) + "}")
    text = json.dumps(head)[:-1] + ',"episodes":[' + ",\n".join(parts) + "]}\n"
    json.loads(text)
    path = os.path.join(out_dir, name)
    # mtime=0: the same content gives the same bytes.
    with open(path, "wb") as raw, gzip.GzipFile(fileobj=raw, mode="wb", mtime=0, filename="") as f:
        f.write(text.encode())
    print(f"{path}: {len(episodes)} episodes, ManiSkill successes {head['maniskill_successes']}, "
          f"{os.path.getsize(path)} bytes", file=sys.stderr, flush=True)


def record_solvers(a, pairs):
    work = os.path.join(a.work, "solver")
    os.makedirs(work, exist_ok=True)
    version = subprocess.run([a.mjskill, "--version"], check=True, capture_output=True, text=True)
    for env_id, robot, convert in SOLVER_PAIRS:
        if pairs and (env_id, robot) not in pairs:
            continue
        stem = os.path.join(work, f"{env_id}__{robot}")
        run([a.mjskill, "rollout", "--env", env_id, "--robot", robot, "--policy", "solver",
             "--episodes", str(a.episodes), "--seed", str(a.solver_seed), "--out", stem + ".mcap",
             "--no-frame"], stdout=subprocess.DEVNULL)
        cmd = [a.mjskill, "export", stem + ".mcap", "--format", "maniskill", "-o", stem + ".h5"]
        if convert:
            cmd += ["--control-mode", convert]
        run(cmd, stdout=subprocess.DEVNULL)
        meta, eps = read_h5(stem + ".h5")
        mode = meta["env_info"]["env_kwargs"]["control_mode"]
        episodes = []
        t0 = time.time()
        for seed, actions, mj_success in eps:
            flags, final, objects = replay(env_id, robot, mode, seed, actions, a.reuse_env)
            episodes.append({"seed": seed, "steps": int(actions.shape[0]),
                             "mjskill_success_when_recorded": bool(mj_success),
                             "final_success": final, "flags": flags,
                             "final_objects": objects, "actions": actions})
        print(f"{env_id} {robot}: replayed {len(eps)} in {time.time() - t0:.0f} s", file=sys.stderr)
        write(a.out, "solver", env_id, robot, mode, episodes, {
            "mjskill_version": version.stdout.strip(),
            "mjskill_commands": [
                f"mjskill rollout --env {env_id} --robot {robot} --policy solver "
                f"--episodes {a.episodes} --seed {a.solver_seed} --out run.mcap",
                "mjskill export run.mcap --format maniskill -o run.h5"
                + (f" --control-mode {convert}" if convert else ""),
            ],
        }, a.reuse_env)


def record_demos(a, pairs):
    for env_id, robot, module in DEMO_PAIRS:
        if pairs and (env_id, robot) not in pairs:
            continue
        record_dir = os.path.join(a.work, "demos", module)
        h5 = os.path.join(record_dir, env_id, "motionplanning", "mp.h5")
        cmd = [sys.executable, "-m", f"mani_skill.examples.motionplanning.{module}.run",
               "-e", env_id, "-n", str(a.episodes), "-b", "cpu", "--record-dir", record_dir,
               "--traj-name", "mp"]
        if not (a.reuse and os.path.exists(h5)):
            run(cmd, stdout=subprocess.DEVNULL)
        meta, eps = read_h5(h5)
        mode = meta["env_info"]["env_kwargs"]["control_mode"]
        episodes = []
        t0 = time.time()
        for seed, actions, demo_success in eps:
            assert seed < HELD_OUT_SEED, seed
            flags, final, objects = replay(env_id, robot, mode, seed, actions, a.reuse_env)
            episodes.append({"seed": seed, "steps": int(actions.shape[0]),
                             "demo_success": bool(demo_success), "final_success": final,
                             "flags": flags, "final_objects": objects, "actions": actions})
        print(f"{env_id} {robot}: replayed {len(eps)} in {time.time() - t0:.0f} s", file=sys.stderr)
        write(a.out, "motionplanning", env_id, robot, mode, episodes, {
            "demo_command": "python " + " ".join(cmd[1:]),
            "demo_note": "demo_success is run.py's recorded success (one env reused for all "
                         "seeds); final_success and flags are the replay described by `replay`",
        }, a.reuse_env)


def trim(a):
    """Copies the first --keep episodes of every outcome file in --trim to --out (no
    ManiSkill needed): the small files the repository's tests replay."""
    for name in sorted(os.listdir(a.trim)):
        if not name.endswith(".json.gz"):
            continue
        with gzip.open(os.path.join(a.trim, name)) as f:
            d = json.load(f)
        assert d["format"] == FORMAT, name
        episodes = d.pop("episodes")[: a.keep]
        for e in episodes:
            e["actions"] = np.asarray(e["actions"], dtype=np.float32)
        extra = {k: v for k, v in d.items() if k not in (
            "format", "source", "env_id", "robot", "control_mode", "sim_backend", "replay",
            "flag_keys", "n_episodes", "maniskill_successes")}
        extra["trimmed_from"] = {"episodes": d["n_episodes"],
                                 "maniskill_successes": d["maniskill_successes"]}
        reuse = d["replay"].startswith("one env for all")
        write(a.out, d["source"], d["env_id"], d["robot"], d["control_mode"], episodes, extra,
              reuse)


def perturb(a):
    """ManiSkill against itself: final-success flips under N(0, --perturb) arm-target noise."""
    rng = np.random.default_rng(0)
    for name in sorted(os.listdir(a.files)):
        if not name.endswith(".json.gz"):
            continue
        with gzip.open(os.path.join(a.files, name)) as f:
            d = json.load(f)
        n_arm = ARM_JOINTS.get(d["robot"])
        ee = d["control_mode"].startswith("pd_ee_delta")
        if not ee and (d["control_mode"] != "pd_joint_pos" or n_arm is None):
            print(f"{name}: skipped (perturbs pd_joint_pos files of {sorted(ARM_JOINTS)} and "
                  "pd_ee_delta_* files)", file=sys.stderr)
            continue
        replayed = perturbed = flips = 0
        for e in d["episodes"]:
            actions = np.asarray(e["actions"], dtype=np.float32)
            _, base, _ = replay(d["env_id"], d["robot"], d["control_mode"], e["seed"], actions)
            if ee:
                # The noise goes on the joint targets the EE controller computes.
                _, pert, _ = replay(d["env_id"], d["robot"], d["control_mode"], e["seed"],
                                    actions, target_noise=(rng, a.perturb))
            else:
                noisy = actions.copy()
                noisy[:, :n_arm] += rng.normal(0.0, a.perturb, noisy[:, :n_arm].shape)
                _, pert, _ = replay(d["env_id"], d["robot"], d["control_mode"], e["seed"], noisy)
            replayed += base
            perturbed += pert
            flips += base != pert
        print(json.dumps({"file": name, "sigma_rad": a.perturb, "episodes": len(d["episodes"]),
                          "replayed_successes": replayed, "perturbed_successes": perturbed,
                          "final_success_flips": flips}), flush=True)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--mjskill", default="target/release/mjskill")
    p.add_argument("--work", default="/tmp/outcomes_work")
    p.add_argument("--out", default="tests/data/outcomes")
    p.add_argument("--episodes", type=int, default=50)
    p.add_argument("--solver-seed", type=int, default=0)
    p.add_argument("--only", choices=["solver", "motionplanning"])
    p.add_argument("--pairs", help="ENV:ROBOT[,ENV:ROBOT...] (default: all)")
    p.add_argument("--reuse", action="store_true", help="reuse demo h5 files already in --work")
    p.add_argument("--reuse-env", action="store_true",
                   help="one ManiSkill env per pair, reset per episode (faster; as replay_trajectory)")
    p.add_argument("--trim", metavar="DIR",
                   help="copy the first --keep episodes of the outcome files in DIR to --out")
    p.add_argument("--keep", type=int, default=10)
    p.add_argument("--perturb", type=float, metavar="SIGMA",
                   help="replay the pd_joint_pos files in --files with N(0, SIGMA) rad on the arm "
                        "targets and count final-success flips (ManiSkill against itself)")
    p.add_argument("--files", default="tests/data/outcomes", help="outcome files for --perturb")
    a = p.parse_args()
    if a.trim:
        trim(a)
        return
    if a.perturb is not None:
        perturb(a)
        return
    last = max(a.solver_seed + a.episodes, a.episodes) - 1
    if last >= HELD_OUT_SEED:
        p.error(f"seeds up to {last}: seeds {HELD_OUT_SEED} and above are held out")
    pairs = {tuple(x.split(":")) for x in a.pairs.split(",")} if a.pairs else None
    if a.only in (None, "solver"):
        record_solvers(a, pairs)
    if a.only in (None, "motionplanning"):
        record_demos(a, pairs)


if __name__ == "__main__":
    main()
