"""Records ManiSkill 3 reference trajectories (format `mjskill-ref-traj/1`,
docs/reference-trajectories.md) of PushCube-v1, PullCube-v1, StackCube-v1 and LiftPegUpright-v1
with the Panda and the Fetch, of PushT-v1 with the panda_stick and of PegInsertionSide-v1 with
the panda_wristcam, and one reference camera state per pair for `tests/segmentation.rs`.

    MS_ASSET_DIR=/tmp/ms_assets /tmp/msmp/bin/python tests/data/maniskill/record_push_pull.py \
        [--pairs PushCube-v1:panda,...] [--images]

(`/tmp/msmp` is ManiSkill with numpy 1.26, which mplib's motion planner needs:
../shared/notes/maniskill-peer.md.) The shared reference files of the first three tasks were
made by a generator kept outside the project; this one follows the same recipe, as that
format's description gives it:

* 6 × 50 steps of uniform random actions in `pd_joint_delta_pos` (seeds 1000–1005),
  `rng = np.random.default_rng(seed * 7919 + 17)`, `a = rng.uniform(lo, hi)`;
* 2 × 50 steps of the smooth random walk in every other mode the robot offers among
  `pd_joint_pos`, `pd_ee_delta_pos`, `pd_ee_delta_pose`, `pd_joint_vel`,
  `pd_joint_target_delta_pos` (seeds 1100–1101);
* Panda and panda_wristcam only (the panda_stick has no fingers: its grasp contacts are
  recorded as zeros and its finger links as null): 4 motion-planning episodes in
  `pd_joint_pos` (seeds 1200–1203) with ManiSkill's own solutions (`solvePushCube` /
  `solvePullCube` / `solveStackCube` / `solveLiftPegUpright` / `solvePegInsertionSide`), run
  until the solution returns.

Every episode runs in a freshly made env (PhysX CPU keeps contact caches across resets). Each
snapshot holds what the format lists; floats are the shortest decimals of ManiSkill's float32
values; an info entry that is a vector (PegInsertionSide's `peg_head_pos_at_hole`) is a list of
them. PegInsertionSide-v1 reconfigures (draws a new peg and hole) on every reset. `--images`
also writes `tests/data/maniskill_images/<pair>/smooth_random_walk_pd_joint_pos_1100_035.npz`:
the sensor cameras' rgb, depth (mm) and segmentation after step 35 of that episode, rendered
in `rgb+depth+segmentation`, with the state dict that was rendered, and puts the pair's
segmentation id map (ManiSkill's `segmentation_id_map`, id → actor or link name) into
`tests/data/maniskill_images/segmentation_ids.json`.
"""

import argparse
import gzip
import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

import mani_skill
import mani_skill.envs  # noqa: F401  (registers the envs)

HERE = Path(__file__).resolve().parent
PAIRS = [
    (e, r)
    for e in ("PushCube-v1", "PullCube-v1", "StackCube-v1", "LiftPegUpright-v1")
    for r in ("panda", "fetch")
] + [
    ("StackCube-v1", "panda_wristcam"),
    ("PushT-v1", "panda_stick"),
    ("PegInsertionSide-v1", "panda_wristcam"),
]
# The env attribute of the actor whose grasp the task checks.
GRASP_ATTR = {"PushCube-v1": "obj", "PullCube-v1": "obj", "StackCube-v1": "cubeA",
              "LiftPegUpright-v1": "peg", "PushT-v1": "tee", "PegInsertionSide-v1": "peg"}
# The robots ManiSkill's motion-planning solutions drive.
MP_ROBOTS = ("panda", "panda_wristcam")
DEFAULT_MODE = "pd_joint_delta_pos"
WALK_MODES = ["pd_joint_pos", "pd_ee_delta_pos", "pd_ee_delta_pose", "pd_joint_vel",
              "pd_joint_target_delta_pos"]
SEEDS = {"random": [1000 + k for k in range(6)], "smooth": [1100, 1101],
         "motion_planning": [1200 + k for k in range(4)]}
STEPS = 50
IMAGE_STEP = 35


def f32(x):
    """Shortest decimal of a float32 as a JSON number (None for ±inf)."""
    x = np.float32(x)
    if not np.isfinite(x):
        return None
    return float(str(x))


def vec(t):
    a = t.detach().cpu().numpy() if isinstance(t, torch.Tensor) else np.asarray(t)
    return [f32(v) for v in a.reshape(-1)]


def batch0(t):
    return t[0] if isinstance(t, torch.Tensor) and t.ndim > 1 else t


def nested(d):
    """A state dict with the batch dimension dropped, as JSON lists."""
    if isinstance(d, dict):
        return {k: nested(v) for k, v in d.items()}
    return vec(batch0(d))


def info_json(info):
    out = {}
    for k, v in info.items():
        if isinstance(v, torch.Tensor) and v.numel() > 1:  # peg_head_pos_at_hole
            out[k] = vec(batch0(v))
            continue
        v = v.item() if isinstance(v, torch.Tensor) else v
        out[k] = v if isinstance(v, (bool, int)) else f32(v)
    return out


def layout(obs, prefix=""):
    out, at = [], 0
    for k, v in obs.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            sub = layout(v, key + ".")
            out += [[n, a + at, b + at] for n, a, b in sub]
            at += sub[-1][2] if sub else 0
        else:
            n = int(np.prod(v.shape[1:])) if v.ndim > 1 else 1
            out.append([key, at, at + n])
            at += n
    return out


def make(env_id, robot, mode, obs_mode="state", render=False):
    kwargs = dict(obs_mode=obs_mode, control_mode=mode, num_envs=1, render_mode=None,
                  sim_backend="physx_cpu", reward_mode="dense", robot_uids=robot)
    if not render and env_id != "PushT-v1":  # PushT's goal is a visual shape
        kwargs["render_backend"] = "none"
    return gym.make(env_id, **kwargs), kwargs


def snapshot(env, obs, info, t, action=None, reward=None, terminated=None, truncated=None):
    u = env.unwrapped
    if reward is None:
        reward = u.compute_dense_reward(obs=None, action=None, info=info)
    norm = u.compute_normalized_dense_reward(obs=None, action=None, info=info)
    scene, agent = u.scene, u.agent
    s = {"t": t}
    if action is not None:
        s["action"] = [f32(x) for x in np.asarray(action, np.float32)]
    s["reward_dense"] = f32(torch.as_tensor(reward).reshape(-1)[0])
    s["reward_normalized"] = f32(norm.reshape(-1)[0])
    if terminated is not None:
        s["terminated"] = bool(torch.as_tensor(terminated).reshape(-1)[0])
        s["truncated"] = bool(torch.as_tensor(truncated).reshape(-1)[0])
    s["info"] = info_json(info)
    s["actors"] = {a.name: vec(batch0(a.pose.raw_pose)) for a in scene.actors.values()}
    tcp = agent.tcp_pose if hasattr(agent, "tcp_pose") else agent.tcp.pose  # panda_stick
    s["tcp_pose"] = vec(batch0(tcp.raw_pose))
    s["robot_qpos"] = vec(batch0(agent.robot.get_qpos()))
    s["robot_qvel"] = vec(batch0(agent.robot.get_qvel()))
    s["grasp_contact"] = {
        f"finger{k}": vec(batch0(scene.get_pairwise_contact_forces(
            link, getattr(u, GRASP_ATTR[u.spec.id])))) if link is not None else [0.0] * 3
        for k, link in ((1, finger(agent, 1)), (2, finger(agent, 2)))
    }
    s["obs_state"] = vec(batch0(obs))
    s["state_dict"] = nested(u.get_state_dict())
    return s


def finger(agent, k):
    """The agent's k-th finger link (None for a robot without fingers: the panda_stick)."""
    return getattr(agent, f"finger{k}_link", None)


def controllers(env):
    ctrl = env.unwrapped.agent.controller
    out, at, abs_dims = {}, 0, []
    for name, c in ctrl.controllers.items():
        n = int(np.prod(c.single_action_space.shape))
        cfg = c.config
        cls = type(c).__name__
        walk_abs = (cls.startswith("PDJointPos") and not getattr(cfg, "use_delta", True)
                    and not getattr(cfg, "normalize_action", True))
        out[name] = {"cls": cls, "action_slice": [at, at + n],
                     "joints": [j.name for j in c.joints],
                     "smooth_walk_kind": "abs_joint_pos" if walk_abs else "walk"}
        if walk_abs:
            abs_dims += list(range(at, at + n))
        at += n
    return out, abs_dims


def run_actions(env_id, robot, mode, seed, source, action_fn):
    env, kwargs = make(env_id, robot, mode)
    obs, info = env.reset(seed=seed)
    initial = snapshot(env, obs, info, 0)
    steps = []
    state = action_fn(env, None)
    for t in range(1, STEPS + 1):
        a, state = action_fn(env, state)
        obs, r, term, trunc, info = env.step(a)
        steps.append(snapshot(env, obs, info, t, a, r, term, trunc))
    env.close()
    return {"source": source, "control_mode": mode, "seed": seed,
            "reset_kwargs": {"seed": seed},
            "action_rng": f"numpy.random.default_rng({seed} * 7919 + 17)",
            "initial": initial, "n_steps": len(steps),
            "final_success": bool(steps[-1]["info"]["success"]), "steps": steps}


def uniform(seed):
    rng = np.random.default_rng(seed * 7919 + 17)

    def act(env, state):
        if state is None:
            return 0
        sp = env.action_space
        return rng.uniform(sp.low, sp.high).astype(np.float32), state

    return act


def smooth_walk(seed, abs_dims):
    """The smooth random walk of docs/reference-trajectories.md."""
    rng = np.random.default_rng(seed * 7919 + 17)

    def act(env, state):
        sp = env.action_space
        lo, hi = sp.low.astype(np.float64), sp.high.astype(np.float64)
        if state is None:
            w = np.where(np.isfinite(lo) & np.isfinite(hi), (lo + hi) / 2, 0.0)
            q = np.zeros_like(lo)
            ctrl = env.unwrapped.agent.controller
            at = 0
            for c in ctrl.controllers.values():
                n = int(np.prod(c.single_action_space.shape))
                if at in abs_dims:
                    q[at:at + n] = batch0(c.qpos).cpu().numpy()
                at += n
            return {"w": w, "d": np.zeros_like(lo), "q": q}
        r = rng.random(lo.shape[0])
        a = np.zeros_like(lo)
        for k in range(lo.shape[0]):
            if k in abs_dims:
                v = 0.1 * (2 * r[k] - 1)
                state["d"][k] = 0.8 * state["d"][k] + 0.2 * v
                state["q"][k] = np.clip(state["q"][k] + state["d"][k], lo[k], hi[k])
                a[k] = state["q"][k]
            else:
                u = lo[k] + (hi[k] - lo[k]) * r[k]
                state["w"][k] = np.clip(0.8 * state["w"][k] + 0.2 * u, lo[k], hi[k])
                a[k] = state["w"][k]
        return a.astype(np.float32), state

    return act


class Recorder(gym.Wrapper):
    """Records a snapshot after every step a motion-planning solution takes."""

    def __init__(self, env):
        super().__init__(env)
        self.initial, self.steps = None, []

    def reset(self, **kw):
        obs, info = self.env.reset(**kw)
        self.initial, self.steps = snapshot(self.env, obs, info, 0), []
        return obs, info

    def step(self, a):
        obs, r, term, trunc, info = self.env.step(a)
        t = len(self.steps) + 1
        self.steps.append(snapshot(self.env, obs, info, t, a, r, term, trunc))
        return obs, r, term, trunc, info


def motion_planning(env_id, robot, seed):
    from mani_skill.examples.motionplanning.panda.solutions import (
        solveLiftPegUpright, solvePegInsertionSide, solvePullCube, solvePushCube,
        solveStackCube)
    solve = {"PushCube-v1": solvePushCube, "PullCube-v1": solvePullCube,
             "StackCube-v1": solveStackCube, "LiftPegUpright-v1": solveLiftPegUpright,
             "PegInsertionSide-v1": solvePegInsertionSide}[env_id]
    env, _ = make(env_id, robot, "pd_joint_pos")
    rec = Recorder(env)
    res = solve(rec, seed=seed)
    ok = not (isinstance(res, int) and res == -1)
    env.close()
    return {"source": "motion_planning", "control_mode": "pd_joint_pos", "seed": seed,
            "reset_kwargs": {"seed": seed}, "action_rng": None, "initial": rec.initial,
            "n_steps": len(rec.steps),
            "final_success": bool(rec.steps[-1]["info"]["success"]) if rec.steps else False,
            "steps": rec.steps, "solution": solve.__module__, "planner_ok": ok}


def record(env_id, robot):
    env, _ = make(env_id, robot, DEFAULT_MODE)
    u = env.unwrapped
    supported = list(u.agent._controller_configs.keys())
    env.reset(seed=0)
    header = {
        "format": "mjskill-ref-traj/1", "set": "visible",
        "generator": "tests/data/maniskill/record_push_pull.py",
        "command": f"python tests/data/maniskill/record_push_pull.py --pairs {env_id}:{robot}",
        "env_id": env_id, "robot": robot,
        "versions": {"python": sys.version.split()[0], "mani_skill": mani_skill.__version__,
                     "torch": torch.__version__, "numpy": np.__version__,
                     "gymnasium": gym.__version__},
        "sim_backend": "physx_cpu", "obs_mode": "state", "reward_mode": "dense", "num_envs": 1,
        "env_class": type(u).__name__, "max_episode_steps": u.spec.max_episode_steps,
        "joint_names": [j.name for j in u.agent.robot.get_active_joints()],
        "robot_links": {f"finger{k}_link": getattr(finger(u.agent, k), "name", None)
                        for k in (1, 2)},
        "grasp_object": {"env_attr": GRASP_ATTR[env_id],
                         "actor_name": getattr(u, GRASP_ATTR[env_id]).name},
        "actor_body_types": {a.name: a.px_body_type for a in u.scene.actors.values()},
        "default_control_mode": DEFAULT_MODE,
        "control_modes_supported_by_robot": supported,
        "seeds": SEEDS,
    }
    env.close()
    modes, failures, episodes = {}, {}, []
    for mode in [DEFAULT_MODE] + [m for m in WALK_MODES if m in supported]:
        try:
            env, kwargs = make(env_id, robot, mode)
        except Exception as e:  # Fetch's EE modes fail to build in this ManiSkill
            failures[mode] = repr(e)
            continue
        obs, info = env.reset(seed=0)
        ctrls, abs_dims = controllers(env)
        sp = env.action_space
        modes[mode] = {
            "env_kwargs": kwargs,
            "action_space": {"low": vec(sp.low), "high": vec(sp.high),
                             "shape": list(sp.shape), "dtype": str(sp.dtype)},
            "controllers": ctrls, "smooth_walk_abs_dims": abs_dims,
            "obs_state_layout": layout(env.unwrapped.get_obs(unflattened=True)),
            "obs_state_dim": int(obs.shape[-1]),
        }
        env.close()
        if mode == DEFAULT_MODE:
            for seed in SEEDS["random"]:
                episodes.append(run_actions(env_id, robot, mode, seed, "uniform_random",
                                            uniform(seed)))
        else:
            for seed in SEEDS["smooth"]:
                episodes.append(run_actions(env_id, robot, mode, seed, "smooth_random_walk",
                                            smooth_walk(seed, abs_dims)))
    if robot in MP_ROBOTS:
        for seed in SEEDS["motion_planning"]:
            episodes.append(motion_planning(env_id, robot, seed))
    for k, e in enumerate(episodes):
        e["episode_index"] = k
    header.update({
        "control_modes_recorded": list(modes), "control_mode_failures": failures,
        "motion_planning_note": None if robot in MP_ROBOTS
        else "motion-planning episodes are recorded for the panda only",
        "control_modes": modes, "n_episodes": len(episodes),
        "n_steps": sum(e["n_steps"] for e in episodes), "episodes": episodes,
    })
    path = HERE / f"{env_id}__{robot}.json.gz"
    with open(path, "wb") as raw:
        with gzip.GzipFile(fileobj=raw, mode="wb", mtime=0, filename="") as gz:
            gz.write(json.dumps(header, separators=(",", ":")).encode())
    print(path, len(episodes), "episodes", header["n_steps"], "steps", "failed:", list(failures))


def image(env_id, robot):
    """The sensor images after step IMAGE_STEP of the first pd_joint_pos smooth walk."""
    mode, seed = "pd_joint_pos", SEEDS["smooth"][0]
    env, _ = make(env_id, robot, mode, obs_mode="rgb+depth+segmentation", render=True)
    env.reset(seed=seed)
    probe, _ = make(env_id, robot, mode)
    _, abs_dims = controllers(probe)
    probe.close()
    act = smooth_walk(seed, abs_dims)
    state = act(env, None)
    for _ in range(IMAGE_STEP):
        a, state = act(env, state)
        obs, *_ = env.step(a)
    arrays = {"state_json": np.array(json.dumps(nested(env.unwrapped.get_state_dict()))),
              "control_mode": np.array(mode)}
    for cam, data in obs["sensor_data"].items():
        arrays[f"{cam}_rgb"] = data["rgb"][0].cpu().numpy().astype(np.uint8)
        arrays[f"{cam}_depth"] = data["depth"][0].cpu().numpy().astype(np.int16)
        arrays[f"{cam}_segmentation"] = data["segmentation"][0].cpu().numpy().astype(np.int16)
    ids = {str(k): v.name for k, v in sorted(env.unwrapped.segmentation_id_map.items()) if k}
    env.close()
    ids_path = HERE.parent / "maniskill_images" / "segmentation_ids.json"
    maps = json.loads(ids_path.read_text())
    maps[f"{env_id}__{robot}"] = ids
    ids_path.write_text(json.dumps(dict(sorted(maps.items())), indent=1))
    out = HERE.parent / "maniskill_images" / f"{env_id}__{robot}"
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"smooth_random_walk_{mode}_{seed}_{IMAGE_STEP:03d}.npz"
    np.savez_compressed(path, **arrays)
    print(path, sorted(arrays))


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("--pairs", default=",".join(f"{e}:{r}" for e, r in PAIRS))
    p.add_argument("--images", action="store_true", help="only the reference camera states")
    args = p.parse_args()
    for pair in args.pairs.split(","):
        env_id, robot = pair.split(":")
        if args.images:
            image(env_id, robot)
        else:
            record(env_id, robot)
