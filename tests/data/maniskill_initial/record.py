"""Records ManiSkill 3's seeded initial states of PushCube-v1, PullCube-v1, StackCube-v1 and
LiftPegUpright-v1 (panda, fetch) into `<env_id>__<robot>.json` next to this script, for
`tests/push_pull_cube.rs`, `tests/stack_cube.rs` and `tests/lift_peg_upright.rs`.

    MS_ASSET_DIR=/tmp/ms_assets /tmp/ms/bin/python tests/data/maniskill_initial/record.py [ENV_ID ...]

With env ids, only their pairs are recorded (the others' files are left as they are).

Per pair, one env made as the reference trajectories were (`obs_mode="state"`,
`sim_backend="physx_cpu"`, `render_backend="none"`, default control mode, dense reward), reset
with every seed of `fit` (0–49) and `held_out` (1000–1049). Per seed: the flat `state`
observation, the actor poses `[x, y, z, qw, qx, qy, qz]`, `agent.tcp_pose`, robot qpos, the
info flags and both dense rewards of the reset state (`compute_dense_reward(obs=None,
action=None, info)`, as ManiSkill returns no reward at reset). Floats are the shortest
decimals that round-trip to ManiSkill's float32 values.
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
]
SEEDS = {"fit": list(range(0, 50)), "held_out": list(range(1000, 1050))}


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


def record(env_id, robot):
    env = gym.make(env_id, robot_uids=robot, obs_mode="state", reward_mode="dense",
                   num_envs=1, sim_backend="physx_cpu", render_backend="none")
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
                "tcp_pose": vec(u.agent.tcp_pose.raw_pose),
                "robot_qpos": vec(u.agent.robot.get_qpos()),
                "info": {k: bool(v.item()) for k, v in info.items()
                         if k not in ("elapsed_steps", "reconfigure")},
                "reward_dense": f32(dense.item()),
                "reward_normalized": f32(norm.item()),
            }
    unflat = u.get_obs(unflattened=True)
    out = {
        "env_id": env_id,
        "robot": robot,
        "control_mode": u.control_mode,
        "versions": {"mani_skill": mani_skill.__version__, "python": sys.version.split()[0]},
        "obs_state_layout": layout(unflat),
        "seeds": SEEDS,
        "episodes": episodes,
    }
    env.close()
    path = Path(__file__).with_name(f"{env_id}__{robot}.json")
    path.write_text(json.dumps(out, separators=(",", ":")) + "\n")
    print(path, len(episodes), "seeds")


if __name__ == "__main__":
    only = set(sys.argv[1:])
    unknown = only - {e for e, _ in PAIRS}
    if unknown:
        sys.exit(f"unknown env ids {sorted(unknown)}; valid: {sorted({e for e, _ in PAIRS})}")
    for env_id, robot in PAIRS:
        if not only or env_id in only:
            record(env_id, robot)
