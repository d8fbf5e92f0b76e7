"""Records ManiSkill 3's seeded initial states of PushCube-v1, PullCube-v1, StackCube-v1 and
LiftPegUpright-v1 (panda, fetch), PushT-v1 (panda_stick) and PegInsertionSide-v1
(panda_wristcam) into `<env_id>__<robot>.json` next to this script, for
`tests/push_pull_cube.rs`, `tests/stack_cube.rs`, `tests/lift_peg_upright.rs`,
`tests/push_t.rs` and the PegInsertionSide tests.

    MS_ASSET_DIR=/tmp/ms_assets /tmp/ms/bin/python tests/data/maniskill_initial/record.py [ENV_ID|ENV_ID:ROBOT ...]

With env ids or pairs, only those pairs are recorded (the others' files are left as they are).

Per pair, one env made as the reference trajectories were (`obs_mode="state"`,
`sim_backend="physx_cpu"`, `render_backend="none"` (PushT-v1: the default, as its goal is a
visual shape), default control mode, dense reward), reset
with every seed of `fit` (0–49) and `held_out` (1000–1049). Per seed: the flat `state`
observation, the actor poses `[x, y, z, qw, qx, qy, qz]`, `agent.tcp_pose` (the panda_stick has
none: its `agent.tcp.pose`), robot qpos, the
info flags and both dense rewards of the reset state (`compute_dense_reward(obs=None,
action=None, info)`, as ManiSkill returns no reward at reset). Floats are the shortest
decimals that round-trip to ManiSkill's float32 values.

PushT-v1 also gets `pseudo_render`: its `world_to_goal_trans` and, for 400 T poses drawn
around the goal (`np.random.default_rng(56)`: 20 anywhere in the spawn box with any yaw, 180
with xy within ±0.04 m of the goal's and yaw within ±0.4 rad of the goal's, 200 within
±0.008 m and ±0.04 rad, where success is decided), the pose as set
(float32 `[x, y, z, qw, qx, qy, qz]`) and `pseudo_render_intersection()` of it; and `links`:
the mass, inertia and centre-of-mass pose SAPIEN gives every robot link and the T.

PegInsertionSide-v1 (one env: it reconfigures on every reset, drawing the peg and the hole
anew) also gets, per seed, `peg_insertion`: `peg_half_sizes`, the `box_hole_offsets` position,
`box_hole_radii`, the raw `goal_pose`, `peg_head_pose`, `box_hole_pose` and `box_pose`
(float32 like the rest), and `peg_body`: the mass, inertia and centre-of-mass pose SAPIEN gives
the peg's rigid body, as float64 (`repr` of SAPIEN's values); its `info` holds every entry of
`evaluate()` (`peg_head_pos_at_hole` as 3 numbers); `links` as PushT-v1's (robot links only:
the panda_wristcam's camera link included); and `unseeded_after`: for seeds 0–4, after
`reset(seed=s)`, two `reset()` without a seed, each with the episode seed ManiSkill drew
(`_episode_seed`), the flat `state` observation and `peg_half_sizes`.
"""

import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import mani_skill
import mani_skill.envs  # noqa: F401  (registers the envs)

PAIRS = [
    (e, r)
    for e in ("PushCube-v1", "PullCube-v1", "StackCube-v1", "LiftPegUpright-v1")
    for r in ("panda", "fetch")
] + [
    ("StackCube-v1", "panda_wristcam"),
    ("PushT-v1", "panda_stick"),
    ("PegInsertionSide-v1", "panda_wristcam"),
]
# Poses of the pseudo-render check (PushT-v1).
RENDER_POSES, RENDER_ANYWHERE = 400, 20
SEEDS = {"fit": list(range(0, 50)), "held_out": list(range(1000, 1050))}
# PegInsertionSide-v1: the seeds followed by unseeded resets, and how many of those each.
UNSEEDED_AFTER, UNSEEDED_RESETS = list(range(0, 5)), 2


def f32(x):
    """Shortest decimal of a float32, as a JSON number."""
    return float(str(np.float32(x)))


def vec(t):
    a = t.detach().cpu().numpy() if hasattr(t, "detach") else np.asarray(t)
    return [f32(v) for v in a.reshape(-1)]


def layout(obs_dict, prefix=""):
    """`[key, start, end)` of every leaf of the flattened observation, in ManiSkill's order."""
    out, at = [], 0
    for k, v in obs_dict.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            sub = layout(v, key + ".")
            out += [(n, a + at, b + at) for n, a, b in sub]
            at += sub[-1][2] if sub else 0
        else:
            n = int(np.prod(v.shape[1:])) if v.ndim > 1 else 1
            out.append((key, at, at + n))
            at += n
    return out


def f64(x):
    """A float64 as a JSON number (float32 values widen exactly)."""
    return float(np.float64(x))


def info_value(v):
    """An info entry: a flag as a bool, a vector (PegInsertionSide's `peg_head_pos_at_hole`) in
    full."""
    return bool(v.item()) if v.numel() == 1 else vec(v)


def tcp_pose(agent):
    """`agent.tcp_pose`; the TCP link's pose for a robot without one (the panda_stick)."""
    return agent.tcp_pose if hasattr(agent, "tcp_pose") else agent.tcp.pose


def record(env_id, robot):
    # PushT's goal is a visual shape: it cannot be built without a render backend.
    render = {} if env_id == "PushT-v1" else {"render_backend": "none"}
    env = gym.make(env_id, robot_uids=robot, obs_mode="state", reward_mode="dense",
                   num_envs=1, sim_backend="physx_cpu", **render)
    u = env.unwrapped
    episodes = {}
    for split, seeds in SEEDS.items():
        for seed in seeds:
            obs, info = env.reset(seed=seed)
            dense = u.compute_dense_reward(obs=None, action=None, info=info)
            norm = u.compute_normalized_dense_reward(obs=None, action=None, info=info)
            episodes[str(seed)] = {
                "obs_state": vec(obs),
                "actors": {a.name: vec(a.pose.raw_pose) for a in u.scene.actors.values()
                           if a.name != "ground"},
                "tcp_pose": vec(tcp_pose(u.agent).raw_pose),
                "robot_qpos": vec(u.agent.robot.get_qpos()),
                "info": {k: info_value(v) for k, v in info.items()
                         if k not in ("elapsed_steps", "reconfigure")},
                "reward_dense": f32(dense.item()),
                "reward_normalized": f32(norm.item()),
            }
            if env_id == "PegInsertionSide-v1":
                episodes[str(seed)].update(peg_insertion(u))
    unflat = u.get_obs(unflattened=True)
    extra = pseudo_render(u) if env_id == "PushT-v1" else {}
    if env_id == "PegInsertionSide-v1":
        extra = {"links": links(u.agent.robot.get_links()), "unseeded_after": unseeded(env)}
    out = {
        "env_id": env_id,
        "robot": robot,
        "control_mode": u.control_mode,
        "versions": {"mani_skill": mani_skill.__version__, "python": sys.version.split()[0]},
        "obs_state_layout": layout(unflat),
        "seeds": SEEDS,
        "episodes": episodes,
        **extra,
    }
    env.close()
    path = Path(__file__).with_name(f"{env_id}__{robot}.json")
    path.write_text(json.dumps(out, separators=(",", ":")) + "\n")
    print(path, len(episodes), "seeds")


def pseudo_render(u):
    """PushT's intersection of T poses around the goal, and SAPIEN's link inertias."""
    import torch
    from mani_skill.utils.structs import Pose

    rng = np.random.default_rng(56)
    goal = u.goal_offset.cpu().numpy().astype(np.float64)
    samples = []
    for k in range(RENDER_POSES):
        if k < RENDER_ANYWHERE:
            xy = goal + rng.uniform([-0.1, -0.1], [0.1, 0.2])
            yaw = rng.uniform(0, 2 * np.pi)
        else:
            near = k >= RENDER_POSES // 2
            d, a = (0.008, 0.04) if near else (0.04, 0.4)
            xy = goal + rng.uniform(-d, d, 2)
            yaw = u.goal_z_rot + rng.uniform(-a, a)
        p = torch.tensor([[xy[0], xy[1], 0.021]], dtype=torch.float32)
        q = torch.tensor([[np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]], dtype=torch.float32)
        u.tee.set_pose(Pose.create_from_pq(p=p, q=q))
        samples.append({"pose": vec(u.tee.pose.raw_pose),
                        "intersection": f32(u.pseudo_render_intersection().item())})
    return {"pseudo_render": {"world_to_goal": vec(u.world_to_goal_trans),
                              "samples": samples},
            "links": links(list(u.agent.robot.get_links()) + [u.tee])}


def links(objs):
    """The mass, inertia and centre-of-mass pose SAPIEN gives each link or actor (float32)."""
    out = {}
    for link in objs:
        body = link._bodies[0]
        c = body.cmass_local_pose
        out[link.name] = {"mass": f32(body.mass), "inertia": vec(body.inertia),
                          "cmass": vec(np.concatenate([c.p, c.q]))}
    return out


def peg_insertion(u):
    """PegInsertionSide's drawn sizes, hole and goal, the box's pose and the peg's rigid body."""
    body = u.peg._bodies[0]
    c = body.cmass_local_pose
    return {
        "peg_insertion": {
            "peg_half_sizes": vec(u.peg_half_sizes[0]),
            "box_hole_offsets": vec(u.box_hole_offsets.p[0]),
            "box_hole_radii": vec(u.box_hole_radii),
            "goal_pose": vec(u.goal_pose.raw_pose),
            "peg_head_pose": vec(u.peg_head_pose.raw_pose),
            "box_hole_pose": vec(u.box_hole_pose.raw_pose),
            "box_pose": vec(u.box.pose.raw_pose),
        },
        "peg_body": {"mass": f64(body.mass),
                     "inertia": [f64(v) for v in np.asarray(body.inertia).reshape(-1)],
                     "cmass": [f64(v) for v in np.concatenate([c.p, c.q])]},
    }


def unseeded(env):
    """What unseeded resets give after a seeded one: the episode seed drawn, the flat `state`
    observation and the peg's half sizes."""
    u = env.unwrapped
    out = {}
    for seed in UNSEEDED_AFTER:
        env.reset(seed=seed)
        resets = []
        for _ in range(UNSEEDED_RESETS):
            obs, _ = env.reset()
            resets.append({"episode_seed": int(u._episode_seed[0]), "obs_state": vec(obs),
                           "peg_half_sizes": vec(u.peg_half_sizes[0])})
        out[str(seed)] = resets
    return out


if __name__ == "__main__":
    only = set(sys.argv[1:])
    valid = {e for e, _ in PAIRS} | {f"{e}:{r}" for e, r in PAIRS}
    unknown = only - valid
    if unknown:
        sys.exit(f"unknown env ids or pairs {sorted(unknown)}; valid: {sorted(valid)}")
    for env_id, robot in PAIRS:
        if not only or env_id in only or f"{env_id}:{robot}" in only:
            record(env_id, robot)
